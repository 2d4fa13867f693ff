//! Time per relight: one warm-started re-solve of a prepared scene after its lights changed by
//! one step of a 30-frame sweep (the animation of `antiradiance relight`, emitters away from the
//! spot at 10%), at the default and the fast preset. Tree and links are built once, outside the
//! measurement.
//!
//! Scene: the seed room (`../shared/meshes/room_radiosity_small.obj`, `--emit-above 3.65
//! --albedo 0.75`) when present, otherwise a generated Cornell box of similar size (10,350
//! triangles).
//!
//! Run: `cargo bench --bench relight` (a few minutes: each sample is one relight).

use std::path::Path;
use std::time::Duration;

use antiradiance::scene::generated;
use antiradiance::scene::{load_obj, Scene, SceneOptions};
use antiradiance::solve::relight::{emitter_centroids, sweep_weights, Relighter};
use antiradiance::solve::SolverOptions;
use criterion::{criterion_group, criterion_main, Criterion};

/// Frames of the sweep one relight steps through.
const SWEEP_FRAMES: usize = 30;
/// Bands of emitters precomputed as lights for the mixing benchmark.
const BANDS: usize = 8;
/// Emission kept by emitters far from the spot.
const DIM: f64 = 0.1;

/// The seed room when present, else a generated scene of room size; with its name.
fn bench_scene() -> (String, Scene) {
    let room = Path::new("../shared/meshes/room_radiosity_small.obj");
    if room.exists() {
        let options = SceneOptions {
            emit_above: Some(3.65),
            default_albedo: 0.75,
            ..SceneOptions::default()
        };
        match load_obj(room, &options) {
            Ok(scene) => return ("room".to_string(), scene),
            Err(e) => eprintln!("cannot load the room ({e}); using a generated Cornell box"),
        }
    } else {
        eprintln!(
            "{} not present; using a generated Cornell box of room size",
            room.display()
        );
    }
    let scene = generated::subdivided_cornell_box(9_264);
    (format!("cornell{}", scene.len()), scene)
}

/// The scene's emission in frame `frame` of the sweep.
fn sweep_emission(scene: &Scene, frame: usize) -> Vec<[f64; 3]> {
    let (emitters, centroids) = emitter_centroids(scene);
    let weights = sweep_weights(&centroids, frame, SWEEP_FRAMES, DIM);
    let mut emission = scene.emission.clone();
    for (&t, w) in emitters.iter().zip(weights) {
        emission[t] = scene.emission[t].map(|x| x * w);
    }
    emission
}

fn relight(c: &mut Criterion) {
    let (name, scene) = bench_scene();
    // Two neighbouring frames in the middle of the sweep; each relight steps to the other one.
    let frames = [
        sweep_emission(&scene, SWEEP_FRAMES / 2),
        sweep_emission(&scene, SWEEP_FRAMES / 2 + 1),
    ];
    let mut group = c.benchmark_group(format!("relight/{name}/{}", scene.len()));
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(20));
    for (preset, options) in [
        ("default", SolverOptions::default_preset()),
        ("fast", SolverOptions::fast()),
    ] {
        let mut relighter = match Relighter::new(&scene, None, &options) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("skipping the {preset} preset: {e}");
                continue;
            }
        };
        eprintln!(
            "{name}, {preset} preset: tree and links built once in {:.2} s ({} links)",
            relighter.build_seconds(),
            relighter.prepared().links.len()
        );
        // Converge on the first frame so every measured relight is a warm-started step.
        relighter.relight(&frames[0]).expect("valid emission");
        let mut next = 1;
        group.bench_function(format!("{preset}_preset_sweep_step"), |b| {
            b.iter(|| {
                let relit = relighter.relight(&frames[next]).expect("valid emission");
                next = 1 - next;
                relit.solution.stats.iterations
            })
        });
        // Relighting by precomputed lights: the emitters cut into BANDS bands, each solved once,
        // then every relight is a linear combination (no sweep).
        // The relighter's emission is the last frame's: restore the scene's own first.
        relighter
            .set_emission(&scene.emission)
            .expect("valid emission");
        let (emitters, centroids) = emitter_centroids(&scene);
        let centres = relighter
            .add_band_lights(&emitters, &centroids, BANDS)
            .expect("valid bands");
        let mixes: Vec<Vec<[f64; 3]>> = [SWEEP_FRAMES / 2, SWEEP_FRAMES / 2 + 1]
            .iter()
            .map(|&frame| {
                sweep_weights(&centres, frame, SWEEP_FRAMES, DIM)
                    .iter()
                    .map(|&w| [w; 3])
                    .collect()
            })
            .collect();
        let mut next = 0;
        group.bench_function(
            format!("{preset}_preset_mix_{}_lights", centres.len()),
            |b| {
                b.iter(|| {
                    let relit = relighter.mix(&mixes[next]).expect("valid intensities");
                    next = 1 - next;
                    relit.solution.triangle_radiance.len()
                })
            },
        );
    }
    group.finish();
}

criterion_group!(benches, relight);
criterion_main!(benches);
