//! `antiradiance scene` and the generators behind it (`generated::in_room`, `generated::under_light`):
//! the written scenes load back with the expected triangles, materials and lights, the object
//! stands on the floor of a closed room, and bad input is one `error:` line naming the file.
//!
//! Every test runs on meshes generated here; the one test on the seed meshes
//! (`../shared/meshes`) skips when they are absent.

use std::path::{Path, PathBuf};

use antiradiance::output::read_triangles_csv;
use antiradiance::scene::generated::{
    self, cornell_box, furnace_box, in_room, light_above, room_around, subdivided_cornell_box,
    under_light, write_obj, LIGHT_TRIANGLES, ROOM_FLOOR_ALBEDO, ROOM_TRIANGLES, ROOM_WALL_ALBEDO,
};
use antiradiance::scene::{load_obj, Scene, SceneOptions};
use antiradiance::Error;
use glam::DVec3;

mod common;
use common::{assert_closed, run, s, stderr};

fn load(path: &Path) -> Scene {
    let scene = load_obj(path, &SceneOptions::default()).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    scene
}

fn normal(scene: &Scene, t: usize) -> DVec3 {
    let [a, b, c] = scene.corners(t);
    (b - a).cross(c - a).normalize()
}

fn centroid(scene: &Scene, t: usize) -> DVec3 {
    let [a, b, c] = scene.corners(t);
    (a + b + c) / 3.0
}

/// A closed unit cube facing outward (the furnace box turned inside out), albedo 0.5, no
/// emitter, scaled by 2 and moved to (5, -3, 1): a small object away from the origin.
fn cube_object() -> Scene {
    let mut cube = furnace_box(0.0, 0.5).transformed(2.0, DVec3::new(5.0, -3.0, 1.0));
    for tri in &mut cube.triangles {
        tri.swap(1, 2);
    }
    cube
}

/// Writes `scene` as `name`.obj (+ .mtl) into `dir`; returns the OBJ path.
fn write_mesh(dir: &Path, name: &str, scene: &Scene) -> PathBuf {
    let path = dir.join(format!("{name}.obj"));
    write_obj(scene, &path, "test mesh").unwrap();
    path
}

/// The first `object.len()` triangles of `scene` are `object`'s, bit for bit, with the same
/// materials (names included, `object` for the unnamed).
fn assert_object_kept(object: &Scene, scene: &Scene) {
    for t in 0..object.len() {
        assert_eq!(object.corners(t), scene.corners(t), "corners of {t}");
        assert_eq!(object.albedo[t], scene.albedo[t], "albedo of {t}");
        assert_eq!(object.emission[t], scene.emission[t], "emission of {t}");
        let expected = object
            .material_name(t)
            .unwrap_or(generated::OBJECT_MATERIAL);
        assert_eq!(scene.material_name(t), Some(expected), "material of {t}");
    }
}

/// Checks a scene made by `in_room(object)`: the object kept, the room closed and facing in,
/// the object standing on its floor at the room's centre, one downward light in the ceiling.
fn check_room(object: &Scene, scene: &Scene) {
    let n = object.len();
    assert_eq!(scene.len(), n + ROOM_TRIANGLES);
    assert_object_kept(object, scene);
    let room = room_around(object).unwrap();
    let (lo, hi) = object.bounds();
    let (room_lo, room_hi) = scene.bounds();
    assert_eq!((room_lo, room_hi), (room.min, room.max));
    // Standing on the floor (exactly), centred, inside.
    assert_eq!(
        lo.y, room.min.y,
        "the object's lowest point is on the floor"
    );
    let (c, rc) = ((lo + hi) * 0.5, (room.min + room.max) * 0.5);
    assert!(
        (c.x - rc.x).abs() <= 1e-12 * (1.0 + c.x.abs()),
        "{c} vs {rc}"
    );
    assert!(
        (c.z - rc.z).abs() <= 1e-12 * (1.0 + c.z.abs()),
        "{c} vs {rc}"
    );
    assert!(lo.cmpgt(room.min - DVec3::Y).all() && hi.cmplt(room.max).all());
    assert!((room.max.y - room.min.y) > 1.5 * (hi.y - lo.y));
    // The room: closed, every triangle facing the inside, grey materials.
    assert_closed(scene, n..scene.len(), "the room around the mesh");
    let mut emitters = 0;
    for t in n..scene.len() {
        let inward = rc - centroid(scene, t);
        let nt = normal(scene, t);
        assert!(nt.dot(inward) > 0.0, "room triangle {t} faces out");
        let zeros = nt.to_array().iter().filter(|&&x| x == 0.0).count();
        assert_eq!(zeros, 2, "room triangle {t} is axis-aligned");
        let name = scene.material_name(t).unwrap();
        if scene.is_emitter(t) {
            emitters += 1;
            assert_eq!(name, "room_light");
            assert!(nt.y < 0.0);
            assert!(centroid(scene, t).y == room.max.y);
            for p in scene.corners(t) {
                assert!(p.x >= room.light_min.x && p.x <= room.light_max.x);
                assert!(p.z >= room.light_min.z && p.z <= room.light_max.z);
            }
        } else if nt.y > 0.0 {
            assert_eq!(name, "room_floor");
            assert_eq!(scene.albedo[t], [ROOM_FLOOR_ALBEDO; 3]);
            assert_eq!(centroid(scene, t).y, room.min.y);
        } else {
            assert!(name == "room_wall" || name == "room_ceiling", "{name}");
            assert_eq!(scene.albedo[t], [ROOM_WALL_ALBEDO; 3]);
        }
    }
    assert_eq!(emitters, 2);
}

#[test]
fn in_room_keeps_the_object_on_the_floor_of_a_closed_room() {
    let cube = cube_object();
    let scene = in_room(&cube, 10.0).unwrap();
    check_room(&cube, &scene);
    assert_eq!(scene.emitter_count(), 2);
    // A Cornell box (named materials, its own light) as the object.
    let tmp = tempfile::tempdir().unwrap();
    let cb = load(&write_mesh(tmp.path(), "cb", &cornell_box()));
    let scene = in_room(&cb, 3.0).unwrap();
    check_room(&cb, &scene);
    assert_eq!(
        scene.emitter_count(),
        2 + 2,
        "the object's own light still emits"
    );
}

#[test]
fn under_light_adds_one_downward_light_above_the_mesh() {
    let cube = cube_object();
    let scene = under_light(&cube, 5.0).unwrap();
    assert_eq!(scene.len(), cube.len() + LIGHT_TRIANGLES);
    assert_object_kept(&cube, &scene);
    let (lo, hi) = cube.bounds();
    let (a, c) = light_above(&cube).unwrap();
    // Cube of side 2: light 1 x 1 (half the footprint), 1.5 * 2 above the top.
    assert_eq!(a.y, hi.y + 3.0);
    assert_eq!(c - a, DVec3::new(1.0, 0.0, 1.0));
    assert_eq!((a + c).x * 0.5, (lo + hi).x * 0.5);
    for t in cube.len()..scene.len() {
        assert!(scene.is_emitter(t));
        assert_eq!(scene.emission[t], [5.0; 3]);
        assert_eq!(normal(&scene, t), DVec3::NEG_Y);
        assert_eq!(scene.material_name(t), Some("light"));
    }
    assert_eq!(scene.emitter_count(), LIGHT_TRIANGLES);
    // A flat mesh still gets a light at a distance, never a sliver.
    let flat = Scene::from_triangles(
        &[[
            DVec3::ZERO,
            DVec3::new(4.0, 0.0, 0.0),
            DVec3::new(0.0, 0.0, 1.0),
        ]],
        &[[0.5; 3]],
        &[[0.0; 3]],
    );
    let (a, c) = light_above(&flat).unwrap();
    assert!(a.y > 0.5 && c.x - a.x == 2.0 && c.z - a.z >= 0.4);
}

#[test]
fn generators_reject_bad_parameters() {
    let cube = cube_object();
    for radiance in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(in_room(&cube, radiance), Err(Error::Parameter(_))));
        assert!(matches!(
            under_light(&cube, radiance),
            Err(Error::Parameter(_))
        ));
    }
    let point = Scene::from_triangles(&[[DVec3::ONE; 3]], &[[0.5; 3]], &[[0.0; 3]]);
    assert!(matches!(in_room(&point, 1.0), Err(Error::Parameter(_))));
    assert!(matches!(under_light(&point, 1.0), Err(Error::Parameter(_))));
    assert!(matches!(
        in_room(&Scene::default(), 1.0),
        Err(Error::Parameter(_))
    ));
}

#[test]
fn material_names_are_kept_and_made_unique() {
    // An object whose material is called `room_floor`: the room's floor gets another name, and
    // the written file keeps both apart.
    let mut cube = cube_object();
    cube.material_names = vec!["room_floor".into()];
    cube.material = vec![Some(0); cube.len()];
    let scene = in_room(&cube, 1.0).unwrap();
    assert_eq!(scene.material_name(0), Some("room_floor"));
    assert_eq!(scene.material_name(cube.len()), Some("room_floor_2"));
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("named.obj");
    write_obj(&scene, &path, "names").unwrap();
    let back = load(&path);
    for t in 0..scene.len() {
        assert_eq!(back.material_name(t), scene.material_name(t), "{t}");
        assert_eq!(back.corners(t), scene.corners(t));
    }
    // Atomic writes leave nothing else behind.
    let mut names: Vec<String> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["named.mtl", "named.obj"]);
}

#[test]
fn cli_cornell_box_writes_the_shipped_file_and_the_subdivided_box() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("cornell_box.obj");
    let o = run(&["scene", "cornell-box", "--out", s(&out), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(o.stderr.is_empty());
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    for ext in ["obj", "mtl"] {
        assert_eq!(
            std::fs::read(out.with_extension(ext)).unwrap(),
            std::fs::read(shipped.join(format!("cornell_box.{ext}"))).unwrap(),
            "cornell_box.{ext}"
        );
    }
    let out = tmp.path().join("cb1000.obj");
    let o = run(&[
        "scene",
        "cornell-box",
        "--triangles",
        "1000",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("1150 triangles"), "{}", stderr(&o));
    let back = load(&out);
    let expected = subdivided_cornell_box(1000);
    assert_eq!(back.len(), 1150);
    for t in 0..back.len() {
        assert_eq!(back.corners(t), expected.corners(t));
        assert_eq!(back.emission[t], expected.emission[t]);
    }
    let o = run(&["scene", "cornell-box", "--triangles", "0", "--out", s(&out)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).starts_with("error: ") && stderr(&o).lines().count() == 1);
}

#[test]
fn cli_in_room_and_under_light_write_scenes_that_solve_with_default_options() {
    let tmp = tempfile::tempdir().unwrap();
    let cube = cube_object();
    let mesh = write_mesh(tmp.path(), "cube", &cube);
    let mesh_scene = load_obj(&mesh, &SceneOptions::default()).unwrap();
    for (kind, extra) in [
        ("in-room", ROOM_TRIANGLES),
        ("under-light", LIGHT_TRIANGLES),
    ] {
        let out = tmp.path().join(format!("{kind}.obj"));
        let o = run(&["scene", kind, s(&mesh), "--out", s(&out)]);
        assert!(o.status.success(), "{kind}: {}", stderr(&o));
        assert!(!stderr(&o).contains("warning"), "{kind}: {}", stderr(&o));
        let back = load(&out);
        assert_eq!(back.len(), cube.len() + extra, "{kind}");
        assert_eq!(back.emitter_count(), 2, "{kind}");
        if kind == "in-room" {
            check_room(&mesh_scene, &back);
        }
        // Default options: no --emit-above, no warning, finite positive radiance.
        let csv = tmp.path().join(format!("{kind}.csv"));
        let o = run(&["solve", s(&out), "--triangles", s(&csv), "--quiet"]);
        assert!(o.status.success(), "{kind}: {}", stderr(&o));
        assert!(o.stderr.is_empty(), "{kind}: {}", stderr(&o));
        let rows = read_triangles_csv(&csv).unwrap();
        assert_eq!(rows.len(), back.len());
        let lit = rows
            .iter()
            .filter(|r| r.iter().all(|&b| b.is_finite() && b >= 0.0))
            .count();
        assert_eq!(lit, rows.len(), "{kind}: finite, non-negative radiance");
        // The cube's top (facing the light) is lit.
        let top = (0..cube.len())
            .find(|&t| normal(&back, t) == DVec3::Y)
            .unwrap();
        assert!(rows[top][0] > 0.0, "{kind}");
    }
}

#[test]
fn cli_bad_input_is_one_error_line_naming_the_file_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out.obj");
    let missing = tmp.path().join("missing.obj");
    let malformed = tmp.path().join("malformed.obj");
    std::fs::write(&malformed, "v 0 0 0\nv 1 x 0\nv 0 0 1\nf 1 2 3\n").unwrap();
    let good = write_mesh(tmp.path(), "good", &cube_object());
    let cases: Vec<(Vec<&str>, String)> = vec![
        (
            vec!["scene", "in-room", s(&missing), "--out", s(&out)],
            s(&missing).to_string(),
        ),
        (
            vec!["scene", "under-light", s(&malformed), "--out", s(&out)],
            format!("{}:2:", s(&malformed)),
        ),
        (
            vec!["scene", "in-room", s(&good), "--out", s(&good)],
            s(&good).to_string(),
        ),
        (
            vec!["scene", "in-room", s(&good), "--out", "/no/such/dir/x.obj"],
            "/no/such/dir/x.obj".to_string(),
        ),
        (
            vec!["scene", "in-room", s(&good), "--out", "x.mtl"],
            "x.mtl".to_string(),
        ),
        (
            vec![
                "scene",
                "under-light",
                s(&good),
                "--light-radiance",
                "0",
                "--out",
                s(&out),
            ],
            "--light-radiance".to_string(),
        ),
        (
            vec![
                "scene",
                "in-room",
                s(&good),
                "--albedo",
                "1",
                "--out",
                s(&out),
            ],
            "--albedo".to_string(),
        ),
    ];
    let before = std::fs::read(&good).unwrap();
    for (args, named) in cases {
        let o = run(&args);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(
            err.starts_with("error: ") && err.contains(&named),
            "{args:?}: {err}"
        );
        assert!(
            !out.exists() && !out.with_extension("mtl").exists(),
            "{args:?}"
        );
    }
    assert_eq!(
        std::fs::read(&good).unwrap(),
        before,
        "the mesh is untouched"
    );
    // A malformed command line is exit code 2.
    let o = run(&["scene", "in-room", s(&good)]);
    assert_eq!(o.status.code(), Some(2));
}

/// The seed meshes, when present: the legoBrick's plane faces up (towards the light), and both
/// generated scenes (bear in a room, legoBrick under a light) are written as documented.
#[test]
fn seed_meshes_bear_in_room_and_lego_under_light() {
    let meshes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes");
    let (bear, lego) = (meshes.join("bear.obj"), meshes.join("legoBrick.obj"));
    if !bear.is_file() || !lego.is_file() {
        eprintln!("skipped: {} is not there", meshes.display());
        return;
    }
    let tmp = tempfile::tempdir().unwrap();

    let lego_mesh = load_obj(&lego, &SceneOptions::default()).unwrap();
    // "o Plane" is the file's first polygon, a quad: triangles 0 and 1, facing +y, at y = 0,
    // while the brick's bottom is at y = -0.042 (it sinks slightly into the plane).
    for t in 0..2 {
        assert_eq!(normal(&lego_mesh, t), DVec3::Y, "plane triangle {t}");
        assert!(lego_mesh.corners(t).iter().all(|p| p.y == 0.0));
    }
    assert!(lego_mesh.bounds().0.y < 0.0);
    let out = tmp.path().join("lego_light.obj");
    let o = run(&["scene", "under-light", s(&lego), "--out", s(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let scene = load(&out);
    assert_eq!(scene.len(), lego_mesh.len() + LIGHT_TRIANGLES);
    assert_eq!(scene.emitter_count(), LIGHT_TRIANGLES);

    let bear_mesh = load_obj(&bear, &SceneOptions::default()).unwrap();
    let out = tmp.path().join("bear_room.obj");
    let o = run(&["scene", "in-room", s(&bear), "--out", s(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let scene = load(&out);
    check_room(&bear_mesh, &scene);
}
