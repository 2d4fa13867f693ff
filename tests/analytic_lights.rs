//! Analytic lights against their closed forms: a point light over a plane gives I cos / r^2, a
//! sun E cos, a spot's cone edges fall where its angles say, a sky rho L, a plate's shadow is
//! dark; the antiradiance solvers and the reference path tracer agree with them.
#![allow(clippy::needless_range_loop)] // triangles index the expected and the solved values

mod common;

use std::f64::consts::PI;

use antiradiance::mesh::build_patches;
use antiradiance::progress::Progress;
use antiradiance::reference::{solve_reference, ReferenceOptions};
use antiradiance::scene::generated;
use antiradiance::scene::lights::{spot_falloff, Light};
use antiradiance::scene::Scene;
use antiradiance::solve::solution::Solution;
use antiradiance::solve::SolverKind;
use antiradiance::solve::SolverOptions;
use glam::DVec3;

const RHO: f64 = 0.5;

/// The square [-1, 1]^2 at height `y`, facing up (+y), split into 2 k^2 triangles.
fn floor(k: usize, y: f64, half: f64) -> Scene {
    let v = |x: f64, z: f64| DVec3::new(x * half, y, z * half);
    let (a, b, c, d) = (v(-1.0, -1.0), v(-1.0, 1.0), v(1.0, 1.0), v(1.0, -1.0));
    let s = Scene::from_triangles(&[[a, b, c], [a, c, d]], &[[RHO; 3]; 2], &[[0.0; 3]; 2]);
    generated::subdivide(&s, k)
}

/// The mean over the triangle of `f`, by the midpoint rule on n^2 sub-triangles.
fn mean_over(tri: [DVec3; 3], f: impl Fn(DVec3) -> f64) -> f64 {
    let n = 48;
    let mut sum = 0.0;
    let mut count = 0;
    for i in 0..n {
        for j in 0..n - i {
            // Upward sub-triangle (i, j) and, where it exists, the downward one.
            let p = |a: f64, b: f64| {
                let (u, v) = (a / n as f64, b / n as f64);
                tri[0] * (1.0 - u - v) + tri[1] * u + tri[2] * v
            };
            let (i, j) = (i as f64, j as f64);
            sum += f(p(i + 1.0 / 3.0, j + 1.0 / 3.0));
            count += 1;
            if i + j + 2.0 <= n as f64 {
                sum += f(p(i + 2.0 / 3.0, j + 2.0 / 3.0));
                count += 1;
            }
        }
    }
    sum / count as f64
}

fn point_irradiance(light: DVec3, intensity: f64, x: DVec3) -> f64 {
    let d = light - x;
    intensity * d.y.max(0.0) / d.length().powi(3)
}

fn solve(scene: &Scene, kind: SolverKind) -> Solution {
    solve_split(scene, kind, None)
}

fn solve_split(scene: &Scene, kind: SolverKind, max_edge: Option<f64>) -> Solution {
    let patches = build_patches(scene, max_edge);
    let solution = antiradiance::solve::run(
        kind,
        &patches,
        &SolverOptions::default(),
        &Progress::hidden(),
    )
    .unwrap();
    solution.stats.check("test").unwrap();
    solution
}

fn reference(scene: &Scene) -> Solution {
    reference_spp(scene, 64)
}

fn reference_spp(scene: &Scene, spp: usize) -> Solution {
    let patches = build_patches(scene, None);
    let options = ReferenceOptions {
        spp,
        ..ReferenceOptions::default()
    };
    solve_reference(
        &patches,
        &options,
        &antiradiance::progress::Progress::hidden(),
    )
}

/// Area-weighted relative L1 difference of channel 0.
fn relative(scene: &Scene, got: &[[f64; 3]], want: &[f64]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for t in 0..scene.len() {
        num += scene.area(t) * (got[t][0] - want[t]).abs();
        den += scene.area(t) * want[t];
    }
    num / den
}

#[test]
fn a_point_light_over_a_plane_gives_i_cos_over_r_squared() {
    let mut scene = floor(6, 0.0, 1.0);
    let at = DVec3::new(0.3, 0.8, -0.2);
    let intensity = 2.5;
    scene.lights.push(Light::Point {
        position: at,
        intensity: [intensity; 3],
    });
    let want: Vec<f64> = (0..scene.len())
        .map(|t| RHO / PI * mean_over(scene.corners(t), |x| point_irradiance(at, intensity, x)))
        .collect();
    for kind in [SolverKind::Hierarchical, SolverKind::Dense] {
        let got = solve(&scene, kind);
        for t in 0..scene.len() {
            let g = got.triangle_radiance[t][0];
            assert!(
                (g - want[t]).abs() <= 0.01 * want[t],
                "{kind:?} triangle {t}: {g} against the analytic {}",
                want[t]
            );
        }
    }
    let traced = reference(&scene);
    let err = relative(&scene, &traced.triangle_radiance, &want);
    assert!(err < 0.01, "path tracer {err} from the analytic values");
}

#[test]
fn a_sun_gives_e_cos_theta() {
    let mut scene = floor(3, 0.0, 1.0);
    let direction = DVec3::new(-1.0, -2.0, -0.5);
    let e = 3.0;
    scene.lights.push(Light::Sun {
        direction,
        irradiance: [e, 2.0 * e, 0.0],
    });
    let cos = 2.0 / direction.length();
    let want = RHO / PI * e * cos;
    let got = solve(&scene, SolverKind::Hierarchical);
    let traced = reference(&scene);
    for t in 0..scene.len() {
        for (name, b) in [
            ("antiradiance", got.triangle_radiance[t]),
            ("path tracer", traced.triangle_radiance[t]),
        ] {
            assert!(
                (b[0] - want).abs() <= 0.01 * want,
                "{name} triangle {t}: {} vs {want}",
                b[0]
            );
            assert!(
                (b[1] - 2.0 * want).abs() <= 0.02 * want,
                "{name} triangle {t} green: {}",
                b[1]
            );
            assert_eq!(b[2], 0.0);
        }
    }
    // From below the horizon the sun lights nothing.
    let mut below = floor(1, 0.0, 1.0);
    below.lights.push(Light::Sun {
        direction: DVec3::new(0.0, 1.0, 0.0),
        irradiance: [1.0; 3],
    });
    let dark = solve(&below, SolverKind::Hierarchical);
    assert!(dark.triangle_radiance.iter().all(|b| b[0] == 0.0));
}

#[test]
fn a_spot_lights_inside_its_inner_cone_and_nothing_outside_its_outer_cone() {
    let mut scene = floor(16, 0.0, 1.0);
    let at = DVec3::new(0.0, 1.0, 0.0);
    let (inner, outer) = (20f64.to_radians(), 30f64.to_radians());
    scene.lights.push(Light::Spot {
        position: at,
        direction: DVec3::new(0.0, -1.0, 0.0),
        intensity: [1.0; 3],
        inner,
        outer,
    });
    let got = solve(&scene, SolverKind::Hierarchical);
    let angle = |p: DVec3| (DVec3::new(p.x, 0.0, p.z).length()).atan2(1.0);
    let (mut inside, mut outside, mut between) = (0, 0, 0);
    for t in 0..scene.len() {
        let c = scene.corners(t);
        let b = got.triangle_radiance[t][0];
        let full = RHO / PI * mean_over(c, |x| point_irradiance(at, 1.0, x));
        let spot = RHO / PI
            * mean_over(c, |x| {
                let w = (x - at).normalize();
                point_irradiance(at, 1.0, x) * spot_falloff(-w.y, inner, outer)
            });
        if c.iter().all(|&p| angle(p) < inner) {
            inside += 1;
            assert!(
                (b - full).abs() <= 0.01 * full,
                "triangle {t} inside the inner cone: {b} vs {full}"
            );
        } else if c.iter().all(|&p| angle(p) > outer) {
            outside += 1;
            assert_eq!(b, 0.0, "triangle {t} outside the outer cone");
        } else {
            between += 1;
            assert!(
                b >= 0.0 && b < full,
                "triangle {t} on the cone's edge: {b}, full {full}"
            );
            assert!(
                (b - spot).abs() <= 0.02 * full,
                "triangle {t} falloff: {b} vs {spot}"
            );
        }
    }
    assert!(
        inside > 10 && outside > 100 && between > 10,
        "{inside} {outside} {between}"
    );
}

#[test]
fn a_plate_casts_a_dark_shadow_from_a_point_light() {
    // Floor of 0.25 cells; a plate [-0.25, 0.25]^2 at height 0.5 facing up; light at height 1:
    // the shadow is exactly [-0.5, 0.5]^2, on cell boundaries.
    let floor = floor(8, 0.0, 1.0);
    let plate = floor_plate();
    let mut corners: Vec<[DVec3; 3]> = (0..floor.len()).map(|t| floor.corners(t)).collect();
    corners.extend(plate);
    let n = corners.len();
    let mut scene = Scene::from_triangles(&corners, &vec![[RHO; 3]; n], &vec![[0.0; 3]; n]);
    let at = DVec3::new(0.0, 1.0, 0.0);
    scene.lights.push(Light::Point {
        position: at,
        intensity: [1.0; 3],
    });
    let got = solve(&scene, SolverKind::Hierarchical);
    let traced = reference(&scene);
    let (mut dark, mut lit) = (0, 0);
    for t in 0..floor.len() {
        let c = scene.corners(t);
        let centroid = (c[0] + c[1] + c[2]) / 3.0;
        let full = RHO / PI * mean_over(c, |x| point_irradiance(at, 1.0, x));
        for (name, b) in [
            ("antiradiance", got.triangle_radiance[t][0]),
            ("path tracer", traced.triangle_radiance[t][0]),
        ] {
            if centroid.x.abs() < 0.5 && centroid.z.abs() < 0.5 {
                assert!(
                    b <= 1e-6 * full,
                    "{name}: floor triangle {t} in the shadow has {b}"
                );
            } else {
                assert!(
                    (b - full).abs() <= 0.01 * full,
                    "{name}: lit floor triangle {t}: {b} vs {full}"
                );
            }
        }
        if centroid.x.abs() < 0.5 && centroid.z.abs() < 0.5 {
            dark += 1;
        } else {
            lit += 1;
        }
    }
    assert_eq!(dark, 32);
    assert_eq!(lit, 96);
}

fn floor_plate() -> Vec<[DVec3; 3]> {
    let p = floor(1, 0.5, 0.25);
    (0..p.len()).map(|t| p.corners(t)).collect()
}

#[test]
fn a_sky_over_an_open_plane_gives_rho_l_and_less_under_a_roof() {
    let mut scene = floor(2, 0.0, 1.0);
    scene.lights.push(Light::Sky {
        radiance: [0.8, 0.4, 0.2],
    });
    let got = solve(&scene, SolverKind::Hierarchical);
    let traced = reference(&scene);
    for t in 0..scene.len() {
        for b in [got.triangle_radiance[t], traced.triangle_radiance[t]] {
            for (c, l) in [0.8, 0.4, 0.2].iter().enumerate() {
                assert!((b[c] - RHO * l).abs() <= 1e-9, "triangle {t}: {b:?}");
            }
        }
    }
    // A roof facing down over part of it takes sky away (and sends nothing: it is unlit).
    let mut corners: Vec<[DVec3; 3]> = (0..scene.len()).map(|t| scene.corners(t)).collect();
    let roof = floor(1, 0.3, 0.5);
    for t in 0..roof.len() {
        let [a, b, c] = roof.corners(t);
        corners.push([a, c, b]);
    }
    let n = corners.len();
    let mut roofed = Scene::from_triangles(&corners, &vec![[RHO; 3]; n], &vec![[0.0; 3]; n]);
    roofed.lights = scene.lights.clone();
    // Pieces of at most 0.25: constant radiance per piece is then close to the truth.
    let got = solve_split(&roofed, SolverKind::Hierarchical, Some(0.25));
    let traced = reference_spp(&roofed, 4096);
    for t in 0..scene.len() {
        let (a, r) = (got.triangle_radiance[t][0], traced.triangle_radiance[t][0]);
        assert!(a < RHO * 0.8 && a > 0.0, "triangle {t} under the roof: {a}");
        assert!(
            (a - r).abs() <= 0.05 * r,
            "triangle {t}: antiradiance {a}, path tracer {r}"
        );
    }
}

#[test]
fn lights_from_the_command_line_match_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let scene = floor(2, 0.0, 1.0);
    let obj = dir.path().join("floor.obj");
    generated::write_obj(&scene, &obj, "floor").unwrap();
    let csv = dir.path().join("floor.csv");
    let o = common::run(&[
        "solve",
        common::s(&obj),
        "--light",
        "point:0.3,0.8,-0.2:2.5,2.5,2.5",
        "--light",
        "sun:-1,-2,-0.5:3,3,3",
        "--triangles",
        common::s(&csv),
        "-q",
    ]);
    assert!(o.status.success(), "{}", common::stderr(&o));
    let text = std::fs::read_to_string(&csv).unwrap();
    let at = DVec3::new(0.3, 0.8, -0.2);
    let sun = RHO / PI * 3.0 * 2.0 / DVec3::new(-1.0, -2.0, -0.5).length();
    for (t, line) in text.lines().skip(1).enumerate() {
        let r: f64 = line.split(',').nth(3).unwrap().parse().unwrap();
        let want = RHO / PI * mean_over(scene.corners(t), |x| point_irradiance(at, 2.5, x)) + sun;
        assert!(
            (r - want).abs() <= 0.01 * want,
            "triangle {t}: {r} vs {want}"
        );
    }
    // A malformed light is one line and exit code 2.
    let o = common::run(&["solve", common::s(&obj), "--light", "point:1,2:1,1,1"]);
    assert_eq!(o.status.code(), Some(2));
    let err = common::stderr(&o);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("--light"), "{err}");
}

/// A point light in the Cornell box (its area light turned off) against the path tracer is
/// as accurate as the box lit by its area light: each piece of a patch gets its own direct
/// light from the point light, and the pieces near it are split. With one value per patch, the
/// point-lit box was 4.0% from the path tracer and the area-lit one 1.3% (docs/gltf.md).
#[test]
fn a_point_lit_cornell_box_is_as_accurate_as_the_area_lit_one() {
    let area_lit = generated::cornell_box();
    let mut point_lit = area_lit.clone();
    for e in point_lit.emission.iter_mut() {
        *e = [0.0; 3];
    }
    point_lit.lights.push(Light::Point {
        position: DVec3::new(278.0, 400.0, 279.0),
        intensity: [5e4; 3],
    });
    let error = |scene: &Scene| {
        let got = solve(scene, SolverKind::Hierarchical);
        let truth = reference_spp(scene, 16384);
        antiradiance::solve::solution::error_against(scene, &got, &truth)
    };
    let (point, area) = (error(&point_lit), error(&area_lit));
    eprintln!(
        "cornell box against the path tracer: point-lit {:.3}%, area-lit {:.3}%",
        100.0 * point,
        100.0 * area
    );
    assert!(
        point <= area + 0.0025 && point < 0.015,
        "point-lit {point}, area-lit {area}"
    );
}
