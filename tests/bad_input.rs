//! Bad and borderline scene files: every failure is one line naming the file (and the line where
//! known), never a panic; borderline files load with warnings. The last tests run the CLI binary.

use std::path::{Path, PathBuf};
use std::process::Command;

use antiradiance::scene::{load_obj, Scene, SceneOptions};
use antiradiance::Error;

/// One good triangle, facing +z.
const GOOD: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";

fn write(dir: &Path, name: &str, content: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, content).unwrap();
    path
}

fn load(path: &Path) -> antiradiance::Result<Scene> {
    load_obj(path, &SceneOptions::default())
}

/// Asserts `result` is an error whose message is one line naming `file` (and `file:line:` when
/// `line` is given); returns the message.
fn assert_error(result: antiradiance::Result<Scene>, file: &str, line: Option<usize>) -> String {
    let err = match result {
        Ok(scene) => panic!(
            "expected an error about {file}, got {} triangles",
            scene.len()
        ),
        Err(e) => e,
    };
    let msg = err.to_string();
    assert!(!msg.contains('\n'), "not one line: {msg:?}");
    assert!(!msg.trim().is_empty());
    assert!(msg.contains(file), "message does not name {file}: {msg}");
    if let Some(line) = line {
        assert!(
            msg.contains(&format!("{file}:{line}:")),
            "message does not give {file}:{line}: {msg}"
        );
    }
    msg
}

/// Writes `content` as `name` in a fresh directory and expects the loader to reject it.
fn reject(name: &str, content: &str, line: Option<usize>) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), name, content);
    assert_error(load(&path), name, line)
}

/// Writes an OBJ using `scene.mtl` with the given MTL text and expects the MTL to be blamed.
fn reject_mtl(mtl: &str, line: usize) -> String {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "scene.mtl", mtl);
    let obj = format!("mtllib scene.mtl\nusemtl a\n{GOOD}");
    let path = write(dir.path(), "room.obj", obj);
    assert_error(load(&path), "scene.mtl", Some(line))
}

/// The scene's warnings that contain `text`, as `file:line: message` lines.
fn warnings_containing(scene: &Scene, text: &str) -> Vec<String> {
    (scene.warnings.iter())
        .filter(|w| w.contains(text))
        .map(|w| w.to_string())
        .collect()
}

fn load_ok(name: &str, obj: &str, mtl: Option<&str>) -> Scene {
    let dir = tempfile::tempdir().unwrap();
    if let Some(mtl) = mtl {
        write(dir.path(), "m.mtl", mtl);
    }
    let path = write(dir.path(), name, obj);
    load(&path).unwrap_or_else(|e| panic!("{name} should load: {e}"))
}

// ---- files that cannot be read ---------------------------------------------------------------

#[test]
fn missing_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nowhere.obj");
    assert_error(load(&path), "nowhere.obj", None);
}

#[test]
fn directory_instead_of_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("folder.obj");
    std::fs::create_dir(&path).unwrap();
    assert_error(load(&path), "folder.obj", None);
}

#[test]
fn empty_and_faceless_files() {
    reject("empty.obj", "", None);
    reject("blank.obj", "\n\n   \n# only a comment\n", None);
    reject("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n", None);
}

#[test]
fn binary_file() {
    let dir = tempfile::tempdir().unwrap();
    // Deterministic pseudo-random bytes, with NULs.
    let mut x: u32 = 12345;
    let bytes: Vec<u8> = (0..4096)
        .map(|i| {
            x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
            if i % 97 == 0 {
                0
            } else {
                (x >> 16) as u8
            }
        })
        .collect();
    let path = write(dir.path(), "noise.obj", &bytes);
    assert_error(load(&path), "noise.obj", None);
}

#[test]
fn a_latin1_file_is_read_with_a_warning() {
    // Not UTF-8 but no NUL: names and comments in Latin-1, as some exporters write them; the
    // material name matches between the OBJ and the MTL file.
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "m.mtl",
        b"# caf\xe9\nnewmtl b\xfcro\nKd 0.25 0.5 0.125\n",
    );
    let path = write(
        dir.path(),
        "latin1.obj",
        [
            b"mtllib m.mtl\n# caf\xe9\nusemtl b\xfcro\n".as_slice(),
            GOOD.as_bytes(),
        ]
        .concat(),
    );
    let scene = load(&path).unwrap();
    assert_eq!(scene.albedo[0], [0.25, 0.5, 0.125]);
    assert_eq!(scene.material_name(0), Some("b\u{fc}ro"));
    let encoding = warnings_containing(&scene, "Latin-1");
    assert_eq!(encoding.len(), 2, "{encoding:?}");
    assert!(encoding[0].contains("latin1.obj:2:"), "{encoding:?}");
    assert!(encoding[1].contains("m.mtl:1:"), "{encoding:?}");
}

// ---- malformed OBJ lines ---------------------------------------------------------------------

#[test]
fn malformed_numbers() {
    reject(
        "abc.obj",
        "v 0 0 0\nv 1.0 abc 2\nv 0 1 0\nf 1 2 3\n",
        Some(2),
    );
    reject("short.obj", "v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", Some(2));
    reject(
        "comma.obj",
        "v 0 0 0\nv 1,5 0 0\nv 0 1 0\nf 1 2 3\n",
        Some(2),
    );
    reject(
        "face.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 two 3\n",
        Some(4),
    );
}

#[test]
fn face_index_out_of_range() {
    let v = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    reject("big.obj", &format!("{v}f 1 2 99\n"), Some(4));
    reject("zero.obj", &format!("{v}f 0 1 2\n"), Some(4));
    reject("negative.obj", &format!("{v}f -1 -2 -4\n"), Some(4));
    reject("two.obj", &format!("{v}f 1 2\n"), Some(4));
    // A relative index counts only the vertices read so far.
    reject(
        "early.obj",
        "v 0 0 0\nf -1 -2 -3\nv 1 0 0\nv 0 1 0\n",
        Some(2),
    );
}

#[test]
fn non_finite_coordinates() {
    for (name, word) in [
        ("nan.obj", "nan"),
        ("nan2.obj", "NaN"),
        ("inf.obj", "inf"),
        ("minf.obj", "-inf"),
        ("infinity.obj", "infinity"),
        ("huge.obj", "1e999"),
    ] {
        let msg = reject(
            name,
            &format!("v 0 0 0\nv 1 0 0\nv 0 {word} 0\nf 1 2 3\n"),
            Some(3),
        );
        assert!(msg.contains(word), "{msg}");
    }
}

#[test]
fn homogeneous_vertices() {
    // `v x y z w` divides by w; w = 0 or a non-number is an error on that line.
    reject("w0.obj", "v 0 0 0\nv 1 0 0 0\nv 0 1 0\nf 1 2 3\n", Some(2));
    reject(
        "wabc.obj",
        "v 0 0 0\nv 1 0 0 abc\nv 0 1 0\nf 1 2 3\n",
        Some(2),
    );
    reject(
        "five.obj",
        "v 0 0 0\nv 1 0 0 1 1\nv 0 1 0\nf 1 2 3\n",
        Some(2),
    );
    let scene = load_ok("w2.obj", "v 0 0 0\nv 2 0 0 2\nv 0 1 0\nf 1 2 3\n", None);
    assert_eq!(scene.corners(0)[1].x, 1.0);
    // Vertex colours are ignored.
    let scene = load_ok(
        "rgb.obj",
        "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 1 2 3\n",
        None,
    );
    assert_eq!(scene.corners(0)[1].x, 1.0);
}

// ---- malformed MTL lines ---------------------------------------------------------------------

#[test]
fn short_colour_lines_in_mtl() {
    // tobj 4.0.5 panics on short colour lines; the scanner must stop them first.
    reject_mtl("newmtl a\nKd 0.5 0.5 0.5\nKe 1 2\n", 3);
    reject_mtl("newmtl a\nKd\n", 2);
    reject_mtl("newmtl a\nKd 0.5 x 0.5\n", 2);
    reject_mtl("newmtl a\nKe 1 nan 1\n", 2);
    reject_mtl("newmtl a\nKd spectral white.rfl\n", 2);
}

#[test]
fn a_single_colour_value_is_grey_and_unused_colours_are_not_read() {
    // The MTL format's g and b default to r; `Ka`, `Ks` and `Tf` do not enter the model.
    let scene = load_ok(
        "grey.obj",
        &format!("mtllib m.mtl\nusemtl a\n{GOOD}"),
        Some("newmtl a\nKa 0.5\nKs\nTf spectral glass.rfl\nKd 0.25\nKe 2\n"),
    );
    assert_eq!(scene.albedo[0], [0.25; 3]);
    assert_eq!(scene.emission[0], [2.0; 3]);
}

#[test]
fn albedo_out_of_range() {
    reject_mtl("newmtl a\nKd 1.2 0.5 0.5\n", 2);
    reject_mtl("newmtl a\nKd 0.5 -0.1 0.5\n", 2);
}

#[test]
fn a_transparent_material_is_opaque_with_a_warning() {
    let scene = load_ok(
        "glass.obj",
        &format!("mtllib m.mtl\nusemtl glass\n{GOOD}"),
        Some("newmtl wall\nd 1.0\nKd 0.5 0.5 0.5\nnewmtl glass\nKd 0.1 0.1 0.1\nd 0.25\n"),
    );
    assert_eq!(scene.albedo[0], [0.1; 3]);
    let transparent = warnings_containing(&scene, "transparency");
    assert_eq!(transparent.len(), 1, "{transparent:?}");
    assert!(
        transparent[0].contains("m.mtl:6:") && transparent[0].contains("'glass'"),
        "{transparent:?}"
    );
}

#[test]
fn a_white_albedo_of_one_is_lowered_with_a_warning() {
    // Exporters write white as Kd 1 1 1; the model needs albedo below 1.
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "scene.mtl",
        "newmtl grey\nKd 0.5 0.5 0.5\n# white\nnewmtl white\nKd 1 1.0 0.3\n",
    );
    let path = write(
        dir.path(),
        "room.obj",
        format!("mtllib scene.mtl\nusemtl white\n{GOOD}"),
    );
    let scene = load(&path).unwrap();
    let max = antiradiance::scene::ALBEDO_MAX;
    assert!(
        scene.albedo.iter().all(|&a| a == [max, max, 0.3]),
        "{:?}",
        scene.albedo
    );
    let lowered = warnings_containing(&scene, "lowered");
    assert_eq!(lowered.len(), 1, "{lowered:?}");
    assert!(
        lowered[0].contains("scene.mtl:5:") && lowered[0].contains("'white'"),
        "{lowered:?}"
    );
}

#[test]
fn negative_emission() {
    let msg = reject_mtl("newmtl a\nKd 0.5 0.5 0.5\nKe -1 0 0\n", 3);
    assert!(msg.contains("emission"), "{msg}");
}

#[test]
fn binary_mtl() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "scene.mtl", b"newmtl a\n\x00\x01\x02Kd");
    let path = write(dir.path(), "room.obj", format!("mtllib scene.mtl\n{GOOD}"));
    assert_error(load(&path), "scene.mtl", None);
}

#[test]
fn other_bad_mtl_lines_do_not_lose_the_materials() {
    // Lines we do not use must not make tobj drop the whole MTL (and with it every Kd/Ke).
    let scene = load_ok(
        "extra.obj",
        &format!("mtllib m.mtl\nusemtl a\n{GOOD}"),
        Some("newmtl a\nNs abc\nillum x\nd\nmap_Kd\nKd 0.25 0.5 0.125\nKe 1 2 3\n"),
    );
    assert_eq!(scene.albedo[0], [0.25, 0.5, 0.125]);
    assert_eq!(scene.emission[0], [1.0, 2.0, 3.0]);
}

// ---- geometry that leaves nothing to solve ---------------------------------------------------

#[test]
fn only_degenerate_triangles() {
    reject(
        "collinear.obj",
        "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\nf 1 1 2\n",
        None,
    );
}

// ---- options ---------------------------------------------------------------------------------

#[test]
fn options_out_of_range() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "good.obj", GOOD);
    let bad = [
        SceneOptions {
            default_albedo: 1.0,
            ..SceneOptions::default()
        },
        SceneOptions {
            default_albedo: -0.5,
            ..SceneOptions::default()
        },
        SceneOptions {
            default_albedo: f64::NAN,
            ..SceneOptions::default()
        },
        SceneOptions {
            emission: -1.0,
            ..SceneOptions::default()
        },
        SceneOptions {
            emission: f64::INFINITY,
            ..SceneOptions::default()
        },
        SceneOptions {
            emit_above: Some(f64::NAN),
            ..SceneOptions::default()
        },
    ];
    for options in &bad {
        match load_obj(&path, options) {
            Err(Error::Parameter(msg)) => assert!(!msg.contains('\n')),
            other => panic!("{options:?}: expected Error::Parameter, got {other:?}"),
        }
    }
    assert!(load_obj(&path, &SceneOptions::default()).is_ok());
}

// ---- borderline files that load ----------------------------------------------------------------

#[test]
fn missing_mtl_is_a_warning() {
    let scene = load_ok(
        "nomtl.obj",
        &format!("mtllib absent.mtl\nusemtl red\n{GOOD}"),
        None,
    );
    assert_eq!(scene.len(), 1);
    assert_eq!(scene.albedo[0], [0.75; 3]);
    assert!(
        scene.warnings.iter().any(|w| w.contains("absent.mtl")),
        "{:?}",
        scene.warnings
    );
}

#[test]
fn undefined_material_is_a_warning() {
    let scene = load_ok(
        "undef.obj",
        &format!("mtllib m.mtl\nusemtl nosuch\n{GOOD}"),
        Some("newmtl a\nKd 0.5 0.5 0.5\nKe 1 1 1\n"),
    );
    assert_eq!(scene.albedo[0], [0.75; 3]);
    assert!(
        scene.warnings.iter().any(|w| w.contains("nosuch")),
        "{:?}",
        scene.warnings
    );
}

#[test]
fn no_emitter_is_a_warning() {
    let scene = load_ok("dark.obj", GOOD, None);
    assert_eq!(scene.len(), 1);
    assert_eq!(scene.emitter_count(), 0);
    assert!(!scene.warnings.is_empty());
    assert!(scene.warnings.iter().all(|w| !w.contains("\n")));
}

#[test]
fn zero_area_triangles_keep_their_place() {
    let scene = load_ok(
        "mixed.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\nf 3 3 3\nf 1 3 2\n",
        None,
    );
    assert_eq!(scene.len(), 4);
    assert_eq!(scene.degenerate_count(), 2);
    assert!(!scene.is_degenerate(0));
    assert!(scene.is_degenerate(1));
    assert!(scene.is_degenerate(2));
    assert!(!scene.is_degenerate(3));
}

#[test]
fn polygons_are_fan_triangulated_in_file_order() {
    let scene = load_ok(
        "poly.obj",
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 3 1 0\nv 3 2 0\nv 2 3 0\nv 1 2 0\n\
         f 1 2 3 4\nf 5 6 7 8 9\nf 1 2 4\n",
        None,
    );
    assert_eq!(scene.len(), 2 + 3 + 1);
    let p = |x: f64, y: f64| glam::DVec3::new(x, y, 0.0);
    let expected = [
        [p(0., 0.), p(1., 0.), p(1., 1.)],
        [p(0., 0.), p(1., 1.), p(0., 1.)],
        [p(2., 0.), p(3., 1.), p(3., 2.)],
        [p(2., 0.), p(3., 2.), p(2., 3.)],
        [p(2., 0.), p(2., 3.), p(1., 2.)],
        [p(0., 0.), p(1., 0.), p(0., 1.)],
    ];
    for (t, tri) in expected.iter().enumerate() {
        assert_eq!(&scene.corners(t), tri, "triangle {t}");
    }
}

#[test]
fn emit_above_rule() {
    let dir = tempfile::tempdir().unwrap();
    let obj = "v 0 3 0\nv 1 3 0\nv 0 3 1\nv 0 2 0\nv 0 1 0\nv 1 1 0\nv 0 1 1\n\
               f 1 3 2\nf 1 2 4\nf 5 6 7\nf 1 3 2\n";
    let path = write(dir.path(), "room.obj", obj);
    let options = SceneOptions {
        emit_above: Some(2.0),
        emission: 5.0,
        ..SceneOptions::default()
    };
    let scene = load_obj(&path, &options).unwrap();
    // All three vertices strictly above y = 2: emits; a vertex at y = 2 or below: does not.
    assert_eq!(scene.emission[0], [5.0; 3]);
    assert_eq!(scene.emission[1], [0.0; 3]);
    assert_eq!(scene.emission[2], [0.0; 3]);
    assert_eq!(scene.emission[3], [5.0; 3]);
    assert_eq!(scene.emitter_count(), 2);
    // The last face repeats the first: the only warning (it is solved once).
    assert_eq!(scene.warnings.len(), 1, "{:?}", scene.warnings);
    assert!(
        scene.warnings[0].contains("1 triangle repeats an earlier triangle")
            && scene.warnings[0].contains("triangle 3 repeats 0"),
        "{:?}",
        scene.warnings
    );
}

#[test]
fn negative_relative_indices() {
    let scene = load_ok(
        "relative.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 5 5 5\nf -4 -3 -1\nf 1 -2 -1\n",
        None,
    );
    let p = glam::DVec3::new;
    assert_eq!(scene.len(), 3);
    assert_eq!(
        scene.corners(0),
        [p(0., 0., 0.), p(1., 0., 0.), p(0., 1., 0.)]
    );
    assert_eq!(
        scene.corners(1),
        [p(0., 0., 0.), p(1., 0., 0.), p(5., 5., 5.)]
    );
    assert_eq!(
        scene.corners(2),
        [p(0., 0., 0.), p(0., 1., 0.), p(5., 5., 5.)]
    );
}

#[test]
fn texture_and_normal_references_are_ignored() {
    let scene = load_ok(
        "uv.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nvt nonsense\n\
         f 1/1/1 2/9/1 3//1\nf 1//7 2// 3/1\nl 1 2\np 1\n",
        None,
    );
    assert_eq!(scene.len(), 2);
}

#[test]
fn materials_comments_tabs_and_line_endings() {
    // Inline comments, tabs as separators, CRLF line endings, a byte-order mark, materials that
    // switch inside one object and persist across groups.
    let obj = "\u{feff}v 0 0 0 # origin\r\nmtllib\tm.mtl\r\nv 1 0 0\r\nv 0 1 0\r\n\
               o first\r\nusemtl\tred\r\nf 1 2 3 # red\r\ng second\r\nf 1 3 2\r\n\
               usemtl light\r\nf\t1\t2\t3\r\n";
    let mtl =
        "newmtl red\r\nKd 0.5 0.1 0.1 # reddish\r\n\r\nnewmtl\tlight\r\nKd 0 0 0\r\nKe\t4 4 4\r\n";
    let scene = load_ok("styles.obj", obj, Some(mtl));
    assert_eq!(scene.len(), 3);
    assert_eq!(scene.albedo[0], [0.5, 0.1, 0.1]);
    assert_eq!(scene.albedo[1], [0.5, 0.1, 0.1]);
    assert_eq!(scene.albedo[2], [0.0; 3]);
    assert_eq!(scene.emission[2], [4.0; 3]);
    // The light repeats the first red face (same corners, same orientation): the only warning,
    // and it says the copies' materials differ.
    assert_eq!(scene.warnings.len(), 1, "{:?}", scene.warnings);
    assert!(
        scene.warnings[0].contains("triangle 2 repeats 0")
            && scene.warnings[0].contains("other materials"),
        "{:?}",
        scene.warnings
    );
}

#[test]
fn faces_before_their_vertices_across_materials() {
    // Positive indices may point forward (the whole file's vertices count), even when a later
    // `usemtl` splits the faces into several groups.
    let obj = "mtllib m.mtl\nusemtl a\nf 1 2 3\nusemtl b\nf 1 3 2\nv 0 0 0\nv 1 0 0\nv 0 1 0\n";
    let mtl = "newmtl a\nKd 0.1 0.2 0.3\nKe 1 1 1\nnewmtl b\nKd 0.4 0.5 0.6\n";
    let scene = load_ok("forward.obj", obj, Some(mtl));
    assert_eq!(scene.len(), 2);
    assert_eq!(scene.albedo[0], [0.1, 0.2, 0.3]);
    assert_eq!(scene.albedo[1], [0.4, 0.5, 0.6]);
}

#[test]
fn several_material_libraries() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "a.mtl", "newmtl a\nKd 0.1 0.1 0.1\nKe 1 1 1\n");
    write(dir.path(), "b.mtl", "newmtl b\nKd 0.2 0.2 0.2\n");
    let obj =
        "mtllib a.mtl b.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\nusemtl b\nf 1 3 2\n";
    let path = write(dir.path(), "two.obj", obj);
    let scene = load(&path).unwrap();
    assert_eq!(scene.albedo[0], [0.1; 3]);
    assert_eq!(scene.albedo[1], [0.2; 3]);
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
}

// ---- the CLI ---------------------------------------------------------------------------------

/// Runs `antiradiance solve BAD --triangles OUT.csv`; expects a non-zero exit, exactly one line
/// on stderr starting with `error:` and naming `file`, and no output file.
fn cli_rejects(bad: &Path, file: &str) {
    let out_dir = tempfile::tempdir().unwrap();
    let out = out_dir.path().join("OUT.csv");
    let output = Command::new(env!("CARGO_BIN_EXE_antiradiance"))
        .arg("solve")
        .arg(bad)
        .arg("--triangles")
        .arg(&out)
        .output()
        .expect("run the antiradiance binary");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        !output.status.success(),
        "{file}: exit status {:?}, stderr {stderr:?}",
        output.status
    );
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(
        lines.len(),
        1,
        "{file}: stderr must be one line: {stderr:?}"
    );
    assert!(lines[0].starts_with("error:"), "{file}: {stderr:?}");
    assert!(lines[0].contains(file), "{file}: {stderr:?}");
    assert!(!out.exists(), "{file}: OUT.csv was created");
}

#[test]
fn cli_missing_file() {
    let dir = tempfile::tempdir().unwrap();
    cli_rejects(&dir.path().join("BAD.obj"), "BAD.obj");
}

#[test]
fn cli_malformed_vertex() {
    let dir = tempfile::tempdir().unwrap();
    let bad = write(
        dir.path(),
        "BAD.obj",
        "v 0 0 0\nv 1.0 abc 2\nv 0 1 0\nf 1 2 3\n",
    );
    cli_rejects(&bad, "BAD.obj:2:");
}

#[test]
fn cli_short_kd_does_not_panic() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "BAD.mtl", "newmtl a\nKd 0.5 0.5\n");
    let bad = write(
        dir.path(),
        "BAD.obj",
        format!("mtllib BAD.mtl\nusemtl a\n{GOOD}"),
    );
    cli_rejects(&bad, "BAD.mtl:2:");
}

#[test]
fn cli_binary_and_directory() {
    let dir = tempfile::tempdir().unwrap();
    let bad = write(dir.path(), "BAD.obj", b"\x00\x01\x02\x03binary\x00");
    cli_rejects(&bad, "BAD.obj");
    let folder = dir.path().join("FOLDER.obj");
    std::fs::create_dir(&folder).unwrap();
    cli_rejects(&folder, "FOLDER.obj");
}

#[test]
fn cli_only_degenerate_triangles() {
    let dir = tempfile::tempdir().unwrap();
    let bad = write(
        dir.path(),
        "BAD.obj",
        "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n",
    );
    cli_rejects(&bad, "BAD.obj");
}
