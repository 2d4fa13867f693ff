//! Loading a 1M-triangle `.glb`: the figure of docs/gltf.md. Ignored by default (it writes a
//! 48 MB file); run with `cargo test --release --test gltf_load_time -- --ignored --nocapture`.

use antiradiance::output::gltf::write_scene_glb;
use antiradiance::scene::generated;
use antiradiance::scene::{load_scene, SceneOptions};

#[test]
#[ignore]
fn a_million_triangle_glb_loads() {
    let dir = tempfile::tempdir().unwrap();
    let scene = generated::subdivided_cornell_box(1_000_000);
    let path = dir.path().join("big.glb");
    write_scene_glb(&path, &scene).unwrap();
    for _ in 0..3 {
        let start = std::time::Instant::now();
        let loaded = load_scene(&path, &SceneOptions::default()).unwrap();
        let seconds = start.elapsed().as_secs_f64();
        assert_eq!(loaded.len(), scene.len());
        println!("loaded {} triangles in {seconds:.2} s", loaded.len());
    }
}
