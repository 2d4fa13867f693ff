//! Output files (CSV, PLY, JSON, PNG) and the rasterizer, on tiny scenes with fake solutions.

use std::io::BufRead;
use std::path::Path;

use antiradiance::mesh::{build_patches, Patches};
use antiradiance::output::render::{
    render_png, render_rgb, render_rgb_shaded, resolve_view, tone_map, CameraOptions, Raster,
    Shading, BACK_FACE_RGB,
};
use antiradiance::output::{
    read_triangles_csv, write_elements_csv, write_json, write_ply, write_triangles_csv,
    ELEMENTS_CSV_HEADER, TRIANGLES_CSV_HEADER,
};
use antiradiance::scene::Scene;
use antiradiance::solve::solution::{Solution, SolveStats};
use antiradiance::Error;
use glam::DVec3;

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

/// A square [-1, 1]^2 in the plane z = 0 facing +z (two triangles), plus optionally a degenerate
/// triangle and an emitter triangle far behind.
fn square_scene(extra: bool) -> Scene {
    let mut tris = vec![
        [v(-1., -1., 0.), v(1., -1., 0.), v(1., 1., 0.)],
        [v(-1., -1., 0.), v(1., 1., 0.), v(-1., 1., 0.)],
    ];
    let mut emission = vec![[0.0; 3], [0.0; 3]];
    if extra {
        tris.push([v(0., 0., -3.), v(1., 0., -3.), v(2., 0., -3.)]); // collinear: degenerate
        emission.push([0.0; 3]);
        tris.push([v(-1., -1., -4.), v(1., -1., -4.), v(0., 1., -4.)]);
        emission.push([5.0, 4.0, 3.0]);
    }
    let albedo = vec![[0.5; 3]; tris.len()];
    Scene::from_triangles(&tris, &albedo, &emission)
}

/// A fake solution: patch p gets (p+1) * (0.1, 0.2, 0.3) in normalized units.
fn fake_solution(patches: &Patches) -> Solution {
    let normalized: Vec<[f64; 3]> = (0..patches.len())
        .map(|p| {
            let k = (p + 1) as f64;
            [0.1 * k, 0.2 * k, 0.3 * k / 7.0]
        })
        .collect();
    Solution::from_normalized(patches, &normalized, SolveStats::default())
}

/// A solution with NaN and infinities written straight into it (bypassing sanitizing).
fn poisoned_solution(patches: &Patches) -> Solution {
    let mut s = fake_solution(patches);
    s.patch_radiance[0] = [f64::NAN, f64::INFINITY, -f64::INFINITY];
    s.triangle_radiance[0] = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY];
    s
}

fn no_nan_text(path: &Path) {
    let text = std::fs::read_to_string(path).unwrap().to_lowercase();
    assert!(!text.contains("nan"), "{}: contains NaN", path.display());
    assert!(!text.contains("inf"), "{}: contains inf", path.display());
}

fn dir_is_empty(dir: &Path) -> bool {
    std::fs::read_dir(dir).unwrap().next().is_none()
}

#[test]
fn csv_header_rows_and_round_trip() {
    let scene = square_scene(true);
    let patches = build_patches(&scene, Some(0.7)); // split the square into pieces
    assert!(patches.len() > scene.len());
    let solution = fake_solution(&patches);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tri.csv");
    write_triangles_csv(&path, &scene, &solution).unwrap();

    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], TRIANGLES_CSV_HEADER);
    assert_eq!(lines[0], "index,area,emissive,r,g,b");
    assert_eq!(lines.len(), scene.len() + 1);
    for (t, line) in lines[1..].iter().enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 6);
        assert_eq!(f[0].parse::<usize>().unwrap(), t);
        assert_eq!(f[1].parse::<f64>().unwrap(), scene.area(t));
        assert_eq!(f[2], if scene.is_emitter(t) { "1" } else { "0" });
    }
    assert_eq!(lines[4].split(',').nth(2), Some("1"));

    let back = read_triangles_csv(&path).unwrap();
    assert_eq!(back, solution.triangle_radiance, "bit-exact round trip");
    assert!(dir_is_empty_but(dir.path(), "tri.csv"));
}

/// The elements CSV of a solve that kept its elements (the Cornell box, whose triangles the
/// solver splits): every row's triangle exists, each triangle's elements tile it (their areas
/// sum to its own) and their area-weighted mean radiance is the triangle's result; a solve
/// that kept none writes its patches.
#[test]
fn elements_csv_tiles_each_triangle_with_its_mean() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell_box.obj");
    let scene = antiradiance::load(&path, &antiradiance::SceneOptions::default()).unwrap();
    let options = antiradiance::SolverOptions {
        keep_elements: true,
        ..antiradiance::SolverOptions::default()
    };
    let solved = antiradiance::solve(&scene, None, &options).unwrap();
    let elements = &solved.solution.elements;
    assert!(
        elements.len() > 2 * scene.len(),
        "{} elements",
        elements.len()
    );
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("elements.csv");
    write_elements_csv(&csv, &solved.patches, &solved.solution).unwrap();
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(ELEMENTS_CSV_HEADER));
    let (mut area, mut weighted) = (vec![0.0; scene.len()], vec![[0.0; 3]; scene.len()]);
    let mut rows = 0;
    for (k, line) in lines.enumerate() {
        let f: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        assert_eq!(f.len(), 15);
        assert_eq!(f[0] as usize, k);
        let t = f[1] as usize;
        let c: Vec<DVec3> = (0..3)
            .map(|i| v(f[2 + 3 * i], f[3 + 3 * i], f[4 + 3 * i]))
            .collect();
        let a = 0.5 * (c[1] - c[0]).cross(c[2] - c[0]).length();
        assert!(
            (a - f[11]).abs() <= 1e-9 * a.max(1.0),
            "row {k}: area {a} against {}",
            f[11]
        );
        area[t] += a;
        for ch in 0..3 {
            weighted[t][ch] += a * f[12 + ch];
        }
        rows += 1;
    }
    assert_eq!(rows, elements.len());
    for t in 0..scene.len() {
        let own = scene.area(t);
        assert!(
            (area[t] - own).abs() <= 1e-9 * own,
            "triangle {t}: {} against {own}",
            area[t]
        );
        let b = solved.solution.triangle_radiance[t];
        for ch in 0..3 {
            let mean = weighted[t][ch] / area[t];
            assert!(
                (mean - b[ch]).abs() <= 1e-9 * b[ch].abs().max(1e-12),
                "triangle {t}: {mean} against {}",
                b[ch]
            );
        }
    }
    // Without them, the patches.
    let plain = antiradiance::solve(&scene, None, &antiradiance::SolverOptions::default()).unwrap();
    assert!(plain.solution.elements.is_empty());
    write_elements_csv(&csv, &plain.patches, &plain.solution).unwrap();
    let rows = std::fs::read_to_string(&csv).unwrap().lines().count() - 1;
    assert_eq!(rows, plain.patches.len());
}

/// True when the directory holds exactly the one file named (no temporary left behind).
fn dir_is_empty_but(dir: &Path, name: &str) -> bool {
    let names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names == [name.to_string()]
}

#[test]
fn csv_round_trip_extreme_values() {
    let scene = square_scene(false);
    let patches = build_patches(&scene, None);
    let mut solution = fake_solution(&patches);
    solution.triangle_radiance = vec![[1e-300, 1.0 / 3.0, 6.02e23], [0.0, 123456.789, 5e-324]];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.csv");
    write_triangles_csv(&path, &scene, &solution).unwrap();
    assert_eq!(
        read_triangles_csv(&path).unwrap(),
        solution.triangle_radiance
    );
}

#[test]
fn csv_reader_reports_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.csv");
    std::fs::write(
        &path,
        "index,area,emissive,r,g,b\n0,1,0,1,2,3\n1,1,0,1,oops,3\n",
    )
    .unwrap();
    let err = read_triangles_csv(&path).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, Error::Parse { line: 3, .. }), "{msg}");
    assert!(msg.contains("bad.csv:3:") && msg.contains("oops"), "{msg}");
    assert!(!msg.contains('\n'));

    std::fs::write(&path, "index,area,emissive,r,g,b\n0,1,0,1,2\n").unwrap();
    let msg = read_triangles_csv(&path).unwrap_err().to_string();
    assert!(msg.contains("bad.csv:2:"), "{msg}");

    std::fs::write(&path, "index,area,emissive,r,g,b\n0,1,0,1,2,NaN\n").unwrap();
    let msg = read_triangles_csv(&path).unwrap_err().to_string();
    assert!(
        msg.contains("bad.csv:2:") && msg.contains("not finite"),
        "{msg}"
    );

    std::fs::write(&path, "index,area,emissive,r,g,b\n1,1,0,1,2,3\n").unwrap();
    let msg = read_triangles_csv(&path).unwrap_err().to_string();
    assert!(
        msg.contains("bad.csv:2:") && msg.contains("out of order"),
        "{msg}"
    );

    std::fs::write(&path, "").unwrap();
    let msg = read_triangles_csv(&path).unwrap_err().to_string();
    assert!(msg.contains("bad.csv") && msg.contains("empty"), "{msg}");

    std::fs::write(&path, "a,b,c\n").unwrap();
    let msg = read_triangles_csv(&path).unwrap_err().to_string();
    assert!(msg.contains("bad.csv:1:"), "{msg}");

    let missing = dir.path().join("missing.csv");
    let msg = read_triangles_csv(&missing).unwrap_err().to_string();
    assert!(msg.contains("missing.csv"), "{msg}");
}

/// A minimal ASCII PLY reader for the test: header elements/properties and the data rows.
struct Ply {
    elements: Vec<(String, usize, Vec<String>)>,
    vertices: Vec<Vec<f64>>,
    faces: Vec<Vec<f64>>,
}

fn read_ply(path: &Path) -> Ply {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut lines = file.lines().map(|l| l.unwrap());
    assert_eq!(lines.next().unwrap(), "ply");
    assert_eq!(lines.next().unwrap(), "format ascii 1.0");
    let mut elements: Vec<(String, usize, Vec<String>)> = Vec::new();
    for line in lines.by_ref() {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w[0] {
            "comment" => {}
            "element" => elements.push((w[1].to_string(), w[2].parse().unwrap(), vec![])),
            "property" => elements.last_mut().unwrap().2.push(w[1..].join(" ")),
            "end_header" => break,
            other => panic!("unexpected header line {other}"),
        }
    }
    let parse = |l: String| -> Vec<f64> {
        l.split_whitespace()
            .map(|x| x.parse::<f64>().unwrap())
            .collect()
    };
    let vertices: Vec<Vec<f64>> = lines.by_ref().take(elements[0].1).map(parse).collect();
    let faces: Vec<Vec<f64>> = lines.by_ref().take(elements[1].1).map(parse).collect();
    assert!(lines.next().is_none(), "trailing data after the faces");
    Ply {
        elements,
        vertices,
        faces,
    }
}

#[test]
fn ply_header_counts_and_contents() {
    let scene = square_scene(true).transformed(3.0, v(100.0, -5.0, 2.0));
    let patches = build_patches(&scene, Some(1.5));
    let solution = fake_solution(&patches);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mesh.ply");
    write_ply(&path, &patches, &solution, 1.0).unwrap();
    let ply = read_ply(&path);

    assert_eq!(ply.elements.len(), 2);
    let (ref vname, vcount, ref vprops) = ply.elements[0];
    assert_eq!(vname, "vertex");
    assert_eq!(
        vprops,
        &[
            "double x",
            "double y",
            "double z",
            "uchar red",
            "uchar green",
            "uchar blue"
        ]
    );
    let (ref fname, fcount, ref fprops) = ply.elements[1];
    assert_eq!(fname, "face");
    assert_eq!(
        fcount,
        patches.len(),
        "one face per patch, degenerate ones included"
    );
    assert_eq!(
        fprops,
        &[
            "list uchar int vertex_indices",
            "float radiance_r",
            "float radiance_g",
            "float radiance_b"
        ]
    );
    assert_eq!(ply.vertices.len(), vcount);
    assert_eq!(ply.faces.len(), fcount);
    // Shared corners are welded: fewer vertices than 3 per patch, but at least the unique ones.
    assert!(vcount < 3 * patches.len());

    let (lo, hi) = scene.bounds();
    for vert in &ply.vertices {
        assert_eq!(vert.len(), 6);
        let p = v(vert[0], vert[1], vert[2]);
        assert!(
            p.cmpge(lo - 1e-9).all() && p.cmple(hi + 1e-9).all(),
            "world coordinates"
        );
        assert!(vert[3..]
            .iter()
            .all(|&c| (0.0..=255.0).contains(&c) && c.fract() == 0.0));
    }
    for (p, face) in ply.faces.iter().enumerate() {
        assert_eq!(face.len(), 7);
        assert_eq!(face[0], 3.0);
        for k in 0..3 {
            let idx = face[1 + k] as usize;
            assert!(idx < vcount);
            // Each corner is at the patch's world position.
            let want = patches.frame.world_from_unit(patches.corners[p][k]);
            let got = v(
                ply.vertices[idx][0],
                ply.vertices[idx][1],
                ply.vertices[idx][2],
            );
            assert!((want - got).length() < 1e-9 * want.length().max(1.0));
        }
        for c in 0..3 {
            let want = solution.patch_radiance[p][c] as f32;
            assert_eq!(face[4 + c] as f32, want, "raw B as float");
        }
    }
    // A degenerate patch has three distinct vertex indices (no collapsed face).
    for (p, face) in ply.faces.iter().enumerate() {
        let ids = [face[1], face[2], face[3]];
        assert!(
            ids[0] != ids[1] && ids[1] != ids[2] && ids[0] != ids[2],
            "face {p}"
        );
    }
}

#[test]
fn ply_vertex_colour_is_tone_mapped_area_weighted_mean() {
    // Two coplanar triangles with different B share the diagonal: its vertices get the mean.
    let scene = square_scene(false);
    let patches = build_patches(&scene, None);
    let solution = Solution::from_normalized(
        &patches,
        &[[0.2, 0.2, 0.2], [0.6, 0.6, 0.6]],
        SolveStats::default(),
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.ply");
    write_ply(&path, &patches, &solution, 1.0).unwrap();
    let ply = read_ply(&path);
    assert_eq!(
        ply.vertices.len(),
        4,
        "the square's four corners are welded"
    );
    let colour_at = |x: f64, y: f64| -> [u8; 3] {
        let vert = ply
            .vertices
            .iter()
            // World coordinates come back through the unit frame's grid (`UNIT_FRAME_GRID`
            // of the scene's diameter).
            .find(|q| (q[0] - x).abs() < 1e-9 && (q[1] - y).abs() < 1e-9)
            .unwrap();
        [vert[3] as u8, vert[4] as u8, vert[5] as u8]
    };
    assert_eq!(colour_at(-1.0, -1.0), tone_map([0.4; 3], 1.0)); // shared, equal areas
    assert_eq!(colour_at(1.0, 1.0), tone_map([0.4; 3], 1.0));
    assert_eq!(colour_at(1.0, -1.0), tone_map([0.2; 3], 1.0)); // only the first triangle
    assert_eq!(colour_at(-1.0, 1.0), tone_map([0.6; 3], 1.0));
}

#[test]
fn json_is_pretty_and_parses_back() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.json");
    let value = serde_json::json!({"iterations": 3, "residual": 1.5e-7, "ok": true});
    write_json(&path, &value).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("\n  \"iterations\": 3"), "{text}");
    assert!(text.ends_with('\n'));
    let back: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(back, value);
}

#[test]
fn tone_map_basics() {
    assert_eq!(tone_map([0.0; 3], 1.0), [0, 0, 0]);
    assert_eq!(tone_map([1.0; 3], 1.0), [255, 255, 255]);
    assert_eq!(tone_map([50.0, -1.0, f64::NAN], 1.0), [255, 0, 0]);
    assert_eq!(tone_map([0.5; 3], 2.0), [255, 255, 255]);
    // sRGB: linear 0.2158 is 128/255 after the transfer curve.
    assert_eq!(tone_map([0.2158; 3], 1.0), [128, 128, 128]);
}

/// Camera on +z looking at the square at the origin; the square spans about 43% of the height.
fn front_camera() -> CameraOptions {
    CameraOptions {
        eye: Some(v(0.0, 0.0, 5.0)),
        target: Some(v(0.0, 0.0, 0.0)),
        width: 80,
        height: 60,
        ..CameraOptions::default()
    }
}

fn pixel(img: &[u8], width: u32, x: u32, y: u32) -> [u8; 3] {
    let i = 3 * (y * width + x) as usize;
    [img[i], img[i + 1], img[i + 2]]
}

#[test]
fn png_lit_square_in_front_of_camera() {
    let scene = square_scene(false);
    let patches = build_patches(&scene, None);
    let solution = Solution::from_normalized(
        &patches,
        &[[0.5, 0.25, 0.1], [0.5, 0.25, 0.1]],
        SolveStats::default(),
    );
    let camera = front_camera();
    let img = render_rgb(&patches, &solution, &camera);
    assert_eq!(img.len(), 80 * 60 * 3);
    // Projected half size: 30 px * tan(atan(1/5)) / tan(25 deg) = 12.9 px around (40, 30).
    for (x, y) in [(40, 30), (30, 20), (50, 40), (29, 40)] {
        let p = pixel(&img, 80, x, y);
        assert!(
            p[0] > 0 && p[0] > p[1] && p[1] > p[2],
            "({x},{y}) lit: {p:?}"
        );
    }
    for (x, y) in [(0, 0), (79, 59), (40, 5), (40, 55), (20, 30), (60, 30)] {
        assert_eq!(pixel(&img, 80, x, y), [0, 0, 0], "({x},{y}) background");
    }
    // Auto exposure: uniform radiance maps to 0.8 at the 95th percentile (red channel).
    let want = tone_map(
        [0.5, 0.25, 0.1],
        0.8 / (0.2126 * 0.5 + 0.7152 * 0.25 + 0.0722 * 0.1),
    );
    assert_eq!(pixel(&img, 80, 40, 30), want);
    // Coverage matches the projected area: (2 * 12.9)^2 ~ 665 pixels.
    let covered = img.chunks(3).filter(|p| p != &[0, 0, 0]).count();
    assert!((600..=730).contains(&covered), "{covered}");

    // Fixed exposure.
    let fixed = render_rgb(
        &patches,
        &solution,
        &CameraOptions {
            exposure: Some(1.0),
            ..camera.clone()
        },
    );
    assert_eq!(pixel(&fixed, 80, 40, 30), tone_map([0.5, 0.25, 0.1], 1.0));

    // The PNG file: right size, same pixels.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("img.png");
    render_png(&path, &patches, &solution, &camera).unwrap();
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (80, 60));
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    assert_eq!(&buf[..info.buffer_size()], &img[..]);
    assert!(dir_is_empty_but(dir.path(), "img.png"));
}

/// A raster made once shades any solution as a fresh flat render does (the colours it keeps per
/// patch are per call), and shows a two-sided patch seen from behind in its back face's B.
#[test]
fn one_raster_shades_every_frame_as_a_fresh_render() {
    let scene = square_scene(false);
    let mut patches = build_patches(&scene, None);
    // The first triangle two-sided: seen from behind it shows its back face's radiance, the
    // second its back side in dark grey.
    patches.two_sided = vec![true, false];
    let behind = CameraOptions {
        eye: Some(v(0.0, 0.0, -5.0)),
        ..front_camera()
    };
    for camera in [front_camera(), behind] {
        let raster = Raster::new(&patches, &camera);
        for k in [1.0, 3.0] {
            let mut solution = Solution::from_normalized(
                &patches,
                &[[0.5 * k, 0.25, 0.1], [0.2, 0.4 * k, 0.1]],
                SolveStats::default(),
            );
            solution.patch_radiance_back = vec![[0.1, 0.2 * k, 0.3], [0.0; 3]];
            for exposure in [None, Some(2.0)] {
                let fresh = render_rgb(
                    &patches,
                    &solution,
                    &CameraOptions {
                        exposure,
                        ..camera.clone()
                    },
                );
                assert_eq!(
                    raster.rgb(&patches, &solution, exposure),
                    fresh,
                    "k {k}, {exposure:?}"
                );
            }
            let img = raster.rgb(&patches, &solution, Some(1.0));
            let colours: Vec<[u8; 3]> = img.chunks(3).map(|p| [p[0], p[1], p[2]]).collect();
            let (back, grey) = (
                tone_map(solution.patch_radiance_back[0], 1.0),
                colours.contains(&BACK_FACE_RGB),
            );
            if camera.eye == Some(v(0.0, 0.0, -5.0)) {
                assert!(colours.contains(&back) && grey, "from behind: {back:?}");
            } else {
                assert!(!grey && colours.contains(&tone_map(solution.patch_radiance[1], 1.0)));
            }
        }
    }
}

/// A raster of an empty picture shades to nothing and refuses to write a PNG (one error, no
/// file), as does one given an invalid exposure.
#[test]
fn an_empty_raster_writes_no_file() {
    let scene = square_scene(false);
    let patches = build_patches(&scene, None);
    let solution = fake_solution(&patches);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.png");
    let empty = Raster::new(
        &patches,
        &CameraOptions {
            width: 0,
            ..front_camera()
        },
    );
    assert!(empty.rgb(&patches, &solution, None).is_empty());
    assert!(empty.write_png(&path, &patches, &solution, None).is_err());
    let raster = Raster::new(&patches, &front_camera());
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let err = raster
            .write_png(&path, &patches, &solution, Some(bad))
            .unwrap_err();
        assert!(matches!(err, Error::Parameter(_)), "{err}");
    }
    assert!(!path.exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn back_side_is_dark_grey_and_smooth_shading_interpolates() {
    let scene = square_scene(false);
    let patches = build_patches(&scene, None);
    let solution = fake_solution(&patches);
    let behind = CameraOptions {
        eye: Some(v(0.0, 0.0, -5.0)),
        ..front_camera()
    };
    let img = render_rgb(&patches, &solution, &behind);
    assert_eq!(pixel(&img, 80, 40, 30), BACK_FACE_RGB);
    assert_eq!(pixel(&img, 80, 0, 0), [0, 0, 0]);

    // Smooth: two triangles with different B, the pixel colours vary continuously across the
    // diagonal instead of jumping.
    let camera = CameraOptions {
        exposure: Some(1.0),
        ..front_camera()
    };
    let flat = render_rgb_shaded(&patches, &solution, &camera, Shading::Flat);
    let smooth = render_rgb_shaded(&patches, &solution, &camera, Shading::Smooth);
    let distinct = |img: &[u8]| {
        let mut c: Vec<[u8; 3]> = img
            .chunks(3)
            .map(|p| [p[0], p[1], p[2]])
            .filter(|p| p != &[0, 0, 0])
            .collect();
        c.sort();
        c.dedup();
        c.len()
    };
    assert_eq!(distinct(&flat), 2);
    assert!(distinct(&smooth) > 5);
}

#[test]
fn auto_framing_sees_the_scene_and_enters_closed_rooms() {
    // Open scene: the square is fully in view from outside, and front-facing.
    let scene = square_scene(false).transformed(10.0, v(1e3, 2e3, -3e3));
    let patches = build_patches(&scene, None);
    let solution = fake_solution(&patches);
    let camera = CameraOptions {
        width: 64,
        height: 48,
        ..CameraOptions::default()
    };
    let (eye, target) = resolve_view(&patches, &camera);
    assert!(eye.z > target.z, "outside view from the +z side");
    let img = render_rgb(&patches, &solution, &camera);
    let lit = img.chunks(3).filter(|p| p != &[0, 0, 0]).count();
    let grey = img.chunks(3).filter(|p| p == &BACK_FACE_RGB).count();
    assert!(lit > 100 && grey == 0, "lit {lit} grey {grey}");
    // Nothing touches the border: the whole scene fits.
    for x in 0..64 {
        assert_eq!(pixel(&img, 64, x, 0), [0, 0, 0]);
        assert_eq!(pixel(&img, 64, x, 47), [0, 0, 0]);
    }

    // A closed box with inward normals (a room): the camera moves inside and sees front sides.
    let room = room_scene();
    let patches = build_patches(&room, None);
    let solution = fake_solution(&patches);
    let (eye, _) = resolve_view(&patches, &camera);
    let (lo, hi) = room.bounds();
    assert!(
        eye.cmpgt(lo).all() && eye.cmplt(hi).all(),
        "eye {eye} inside the room"
    );
    let img = render_rgb(&patches, &solution, &camera);
    let black = img.chunks(3).filter(|p| p == &[0, 0, 0]).count();
    let grey = img.chunks(3).filter(|p| p == &BACK_FACE_RGB).count();
    assert_eq!(black, 0, "inside a closed room every pixel shows a wall");
    assert_eq!(grey, 0);
}

/// A room open on the side away from the default outside view (as the Cornell box has no front
/// wall, at -z): from outside the camera sees the back of the closed side, so it goes in, and
/// looks in through the opening, so the picture is walls, not the black outside seen through it.
#[test]
fn auto_framing_looks_into_a_room_through_its_opening() {
    let room = room_scene();
    {
        let open_z = 0.0;
        let kept: Vec<usize> = (0..room.len())
            .filter(|&t| !room.corners(t).iter().all(|c| c.z == open_z))
            .collect();
        assert_eq!(kept.len(), room.len() - 2);
        let tris: Vec<[DVec3; 3]> = kept.iter().map(|&t| room.corners(t)).collect();
        let albedo: Vec<[f64; 3]> = kept.iter().map(|&t| room.albedo[t]).collect();
        let emission: Vec<[f64; 3]> = kept.iter().map(|&t| room.emission[t]).collect();
        let open = Scene::from_triangles(&tris, &albedo, &emission);
        let patches = build_patches(&open, None);
        let camera = CameraOptions {
            width: 64,
            height: 48,
            ..CameraOptions::default()
        };
        let img = render_rgb(&patches, &fake_solution(&patches), &camera);
        let black = img.chunks(3).filter(|p| p == &[0, 0, 0]).count();
        assert!(
            black * 20 < 64 * 48,
            "open at z = {open_z}: {black} of {} pixels show the outside",
            64 * 48
        );
    }
}

#[test]
fn auto_framing_stays_outside_a_closed_object() {
    // The same box with outward normals (a brick, not a room): viewed from outside.
    let room = room_scene();
    let tris: Vec<[DVec3; 3]> = (0..room.len())
        .map(|t| {
            let [a, b, c] = room.corners(t);
            [a, c, b]
        })
        .collect();
    let brick = Scene::from_triangles(&tris, &room.albedo, &room.emission);
    let patches = build_patches(&brick, None);
    let camera = CameraOptions {
        width: 64,
        height: 48,
        ..CameraOptions::default()
    };
    let (eye, _) = resolve_view(&patches, &camera);
    let (lo, hi) = brick.bounds();
    assert!(
        !(eye.cmpgt(lo).all() && eye.cmplt(hi).all()),
        "eye {eye} outside"
    );
    let img = render_rgb(&patches, &fake_solution(&patches), &camera);
    assert!(img.chunks(3).all(|p| p != BACK_FACE_RGB));
    assert!(
        img.chunks(3).any(|p| p == [0, 0, 0]),
        "background visible around it"
    );
}

/// A 4 x 3 x 5 box whose 12 triangles face inwards; the ceiling emits.
fn room_scene() -> Scene {
    let (x, y, z) = (4.0, 3.0, 5.0);
    let c = |i: usize| {
        v(
            x * (i & 1) as f64,
            y * ((i >> 1) & 1) as f64,
            z * ((i >> 2) & 1) as f64,
        )
    };
    // Quads given counter-clockwise as seen from inside.
    let quads = [
        [4, 5, 1, 0], // floor y=0, normal +y
        [3, 7, 6, 2], // ceiling y=Y, normal -y
        [2, 6, 4, 0], // x=0, normal +x
        [5, 7, 3, 1], // x=X, normal -x
        [1, 3, 2, 0], // z=0, normal +z
        [6, 7, 5, 4], // z=Z, normal -z
    ];
    let mut tris = Vec::new();
    let mut emission = Vec::new();
    for (k, q) in quads.iter().enumerate() {
        tris.push([c(q[0]), c(q[1]), c(q[2])]);
        tris.push([c(q[0]), c(q[2]), c(q[3])]);
        let e = if k == 1 { [1.0; 3] } else { [0.0; 3] };
        emission.extend([e, e]);
    }
    let albedo = vec![[0.5; 3]; tris.len()];
    let scene = Scene::from_triangles(&tris, &albedo, &emission);
    // The normals really face inwards.
    let centre = v(x / 2.0, y / 2.0, z / 2.0);
    for t in 0..scene.len() {
        let [a, b, cc] = scene.corners(t);
        assert!((b - a).cross(cc - a).dot(centre - a) > 0.0, "triangle {t}");
    }
    scene
}

#[test]
fn writing_into_a_missing_directory_fails_cleanly() {
    let scene = square_scene(false);
    let patches = build_patches(&scene, None);
    let solution = fake_solution(&patches);
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no_such_dir");
    let camera = front_camera();
    let results: Vec<(std::path::PathBuf, antiradiance::Result<()>)> = vec![
        {
            let p = missing.join("a.csv");
            let r = write_triangles_csv(&p, &scene, &solution);
            (p, r)
        },
        {
            let p = missing.join("a.ply");
            let r = write_ply(&p, &patches, &solution, 1.0);
            (p, r)
        },
        {
            let p = missing.join("a.json");
            let r = write_json(&p, &serde_json::json!({"a": 1}));
            (p, r)
        },
        {
            let p = missing.join("a.png");
            let r = render_png(&p, &patches, &solution, &camera);
            (p, r)
        },
    ];
    for (p, r) in results {
        let err = r.expect_err("writing into a missing directory must fail");
        let msg = err.to_string();
        assert!(matches!(err, Error::Io { .. }), "{msg}");
        assert!(msg.contains(&p.display().to_string()), "{msg}");
        assert!(!msg.contains('\n'), "{msg}");
        assert!(!p.exists());
    }
    assert!(!missing.exists());
    assert!(dir_is_empty(dir.path()));
}

#[test]
fn failed_write_keeps_the_old_file_and_leaves_no_temporary() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("keep.json");
    std::fs::write(&path, "old").unwrap();
    // A writer that fails half-way: the target keeps its old content.
    let err = antiradiance::output::write_atomic(&path, |w| {
        use std::io::Write;
        w.write_all(b"partial")?;
        Err(std::io::Error::other("disk full"))
    })
    .unwrap_err();
    assert!(err.to_string().contains("keep.json") && err.to_string().contains("disk full"));
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
    assert!(dir_is_empty_but(dir.path(), "keep.json"));
    // A directory as the target is an error, not a panic.
    assert!(write_json(dir.path(), &serde_json::json!(1)).is_err());
}

#[test]
fn bad_parameters_are_errors_not_files() {
    let scene = square_scene(false);
    let patches = build_patches(&scene, None);
    let solution = fake_solution(&patches);
    let dir = tempfile::tempdir().unwrap();
    let png_path = dir.path().join("x.png");
    for camera in [
        CameraOptions {
            width: 0,
            ..front_camera()
        },
        CameraOptions {
            fov_deg: 180.0,
            ..front_camera()
        },
        CameraOptions {
            exposure: Some(f64::NAN),
            ..front_camera()
        },
        CameraOptions {
            eye: Some(v(0.0, 0.0, 0.0)),
            ..front_camera()
        },
    ] {
        let err = render_png(&png_path, &patches, &solution, &camera).unwrap_err();
        assert!(matches!(err, Error::Parameter(_)), "{err}");
    }
    assert!(write_ply(&dir.path().join("x.ply"), &patches, &solution, 0.0).is_err());
    let mut short = solution.clone();
    short.triangle_radiance.pop();
    assert!(write_triangles_csv(&dir.path().join("x.csv"), &scene, &short).is_err());
    assert!(dir_is_empty(dir.path()));
}

#[test]
fn no_nan_in_any_output() {
    let scene = square_scene(true);
    let patches = build_patches(&scene, None);
    let solution = poisoned_solution(&patches);
    let dir = tempfile::tempdir().unwrap();

    let csv = dir.path().join("t.csv");
    write_triangles_csv(&csv, &scene, &solution).unwrap();
    no_nan_text(&csv);
    let back = read_triangles_csv(&csv).unwrap();
    assert_eq!(back[0], [0.0; 3]);
    assert_eq!(back[1], solution.triangle_radiance[1]);

    let ply = dir.path().join("t.ply");
    write_ply(&ply, &patches, &solution, 1.0).unwrap();
    no_nan_text(&ply);
    let parsed = read_ply(&ply);
    assert!(parsed.faces.iter().flatten().all(|x| x.is_finite()));
    assert_eq!(&parsed.faces[0][4..], &[0.0, 0.0, 0.0]);

    let json = dir.path().join("t.json");
    write_json(
        &json,
        &serde_json::json!({"b": solution.triangle_radiance[1]}),
    )
    .unwrap();
    no_nan_text(&json);

    // The renderer survives NaN radiance and auto exposure stays finite.
    let img = render_rgb(&patches, &solution, &front_camera());
    assert_eq!(img.len(), 80 * 60 * 3);
    let smooth = render_rgb_shaded(&patches, &solution, &front_camera(), Shading::Smooth);
    assert_eq!(smooth.len(), img.len());
    // Everything NaN: the image is still well defined (lit geometry black, background black).
    let mut all_nan = solution.clone();
    for b in &mut all_nan.patch_radiance {
        *b = [f64::NAN; 3];
    }
    let img = render_rgb(&patches, &all_nan, &front_camera());
    assert!(img.iter().all(|&c| c == 0));
    render_png(
        &dir.path().join("t.png"),
        &patches,
        &all_nan,
        &front_camera(),
    )
    .unwrap();
}
