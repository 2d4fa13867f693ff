//! The reference path tracer against analytic answers of the design note.

use std::time::Instant;

use antiradiance::geometry::Tri;
use antiradiance::mesh::{build_patches, Patches};
use antiradiance::progress::Progress;
use antiradiance::reference::{solve_reference, ReferenceOptions};
use antiradiance::scene::Scene;
use antiradiance::solve::solution::Solution;
use glam::DVec3;

/// Two triangles covering the planar quad a-b-c-d, ordered so their normal points along `facing`.
fn quad(a: DVec3, b: DVec3, c: DVec3, d: DVec3, facing: DVec3) -> [Tri; 2] {
    let n = (b - a).cross(c - a);
    if n.dot(facing) > 0.0 {
        [[a, b, c], [a, c, d]]
    } else {
        [[a, c, b], [a, d, c]]
    }
}

/// Axis-aligned square [x0, x1] x [y0, y1] at height z, facing `facing` (+Z or -Z).
fn square_z(x0: f64, x1: f64, y0: f64, y1: f64, z: f64, facing: DVec3) -> [Tri; 2] {
    quad(
        DVec3::new(x0, y0, z),
        DVec3::new(x1, y0, z),
        DVec3::new(x1, y1, z),
        DVec3::new(x0, y1, z),
        facing,
    )
}

/// A scene assembled from groups of triangles, each group with one albedo and one emission.
struct Builder {
    tris: Vec<Tri>,
    albedo: Vec<[f64; 3]>,
    emission: Vec<[f64; 3]>,
}

impl Builder {
    fn new() -> Builder {
        Builder {
            tris: Vec::new(),
            albedo: Vec::new(),
            emission: Vec::new(),
        }
    }

    /// Adds triangles; returns their index range.
    fn add(
        &mut self,
        tris: &[Tri],
        albedo: [f64; 3],
        emission: [f64; 3],
    ) -> std::ops::Range<usize> {
        let start = self.tris.len();
        for t in tris {
            self.tris.push(*t);
            self.albedo.push(albedo);
            self.emission.push(emission);
        }
        start..self.tris.len()
    }

    fn patches(&self) -> Patches {
        let scene = Scene::from_triangles(&self.tris, &self.albedo, &self.emission);
        build_patches(&scene, None)
    }
}

fn solve(patches: &Patches, spp: usize, seed: u64) -> Solution {
    let options = ReferenceOptions {
        spp,
        seed,
        ..ReferenceOptions::default()
    };
    solve_reference(patches, &options, &Progress::hidden())
}

/// Area-weighted mean of channel `c` of the triangle radiance over `range`.
fn mean_b(patches: &Patches, sol: &Solution, range: std::ops::Range<usize>, c: usize) -> f64 {
    let mut num = 0.0;
    let mut den = 0.0;
    for t in range {
        let a = patches.area[t];
        num += a * sol.triangle_radiance[t][c];
        den += a;
    }
    num / den
}

/// The closed unit cube [0,1]^3 made of 12 triangles whose normals point inside.
fn inward_cube() -> Vec<Tri> {
    let p = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    let mut tris = Vec::new();
    // (quad corners, inward normal)
    let faces = [
        (
            [p(0., 0., 0.), p(1., 0., 0.), p(1., 1., 0.), p(0., 1., 0.)],
            DVec3::Z,
        ),
        (
            [p(0., 0., 1.), p(1., 0., 1.), p(1., 1., 1.), p(0., 1., 1.)],
            -DVec3::Z,
        ),
        (
            [p(0., 0., 0.), p(1., 0., 0.), p(1., 0., 1.), p(0., 0., 1.)],
            DVec3::Y,
        ),
        (
            [p(0., 1., 0.), p(1., 1., 0.), p(1., 1., 1.), p(0., 1., 1.)],
            -DVec3::Y,
        ),
        (
            [p(0., 0., 0.), p(0., 1., 0.), p(0., 1., 1.), p(0., 0., 1.)],
            DVec3::X,
        ),
        (
            [p(1., 0., 0.), p(1., 1., 0.), p(1., 1., 1.), p(1., 0., 1.)],
            -DVec3::X,
        ),
    ];
    for (q, n) in faces {
        tris.extend(quad(q[0], q[1], q[2], q[3], n));
    }
    tris
}

/// Furnace: every triangle of a closed box emits E and reflects rho, so B = E / (1 - rho).
fn furnace(emission: [f64; 3], rho: [f64; 3], spp: usize) {
    let start = Instant::now();
    let mut b = Builder::new();
    b.add(&inward_cube(), rho, emission);
    let patches = b.patches();
    for t in 0..patches.len() {
        // The cube really faces inwards.
        let to_centre = DVec3::splat(0.0) - patches.centroid[t];
        assert!(patches.normal[t].dot(to_centre) > 0.0);
    }
    let sol = solve(&patches, spp, 1);
    let mut worst = 0.0f64;
    for (t, bt) in sol.triangle_radiance.iter().enumerate() {
        for c in 0..3 {
            let want = emission[c] / (1.0 - rho[c]);
            let rel = (bt[c] - want).abs() / want;
            worst = worst.max(rel);
            assert!(
                rel < 0.005,
                "triangle {t} channel {c}: B = {} want {want} (rel err {rel:.4})",
                bt[c]
            );
        }
    }
    eprintln!(
        "furnace E={emission:?} rho={rho:?} spp={spp}: worst rel err {worst:.5} in {:.2?}",
        start.elapsed()
    );
}

#[test]
fn furnace_grey_albedo_half() {
    furnace([1.0; 3], [0.5; 3], 20_000);
}

#[test]
fn furnace_rgb_albedo_08() {
    furnace([1.0, 0.5, 0.25], [0.8; 3], 20_000);
}

#[test]
fn furnace_rgb_albedo_per_channel() {
    furnace([1.0, 0.5, 0.25], [0.8, 0.5, 0.2], 20_000);
}

/// Parallel unit squares at distance 1: F = 0.19982.
#[test]
fn parallel_squares_form_factor() {
    let start = Instant::now();
    let mut b = Builder::new();
    let a = b.add(&square_z(0., 1., 0., 1., 0., DVec3::Z), [0.5; 3], [0.0; 3]);
    b.add(&square_z(0., 1., 0., 1., 1., -DVec3::Z), [0.0; 3], [1.0; 3]);
    let patches = b.patches();
    let sol = solve(&patches, 200_000, 1);
    for c in 0..3 {
        let f = mean_b(&patches, &sol, a.clone(), c) / 0.5;
        let rel = (f - 0.19982).abs() / 0.19982;
        assert!(rel < 0.01, "channel {c}: F = {f} (rel err {rel:.4})");
        if c == 0 {
            eprintln!(
                "parallel squares: F = {f:.5} (rel err {rel:.5}) in {:.2?}",
                start.elapsed()
            );
        }
    }
}

/// Perpendicular unit squares sharing an edge: F = 0.20004.
#[test]
fn perpendicular_squares_form_factor() {
    let start = Instant::now();
    let mut b = Builder::new();
    // Receiver in the plane z = 0 facing +Z, emitter in the plane y = 0 facing +Y; shared edge
    // along the x axis.
    let a = b.add(&square_z(0., 1., 0., 1., 0., DVec3::Z), [0.5; 3], [0.0; 3]);
    let p = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    let wall = quad(
        p(0., 0., 0.),
        p(1., 0., 0.),
        p(1., 0., 1.),
        p(0., 0., 1.),
        DVec3::Y,
    );
    b.add(&wall, [0.0; 3], [1.0; 3]);
    let patches = b.patches();
    let sol = solve(&patches, 200_000, 1);
    let f = mean_b(&patches, &sol, a, 1) / 0.5;
    let rel = (f - 0.20004).abs() / 0.20004;
    eprintln!(
        "perpendicular squares: F = {f:.5} (rel err {rel:.5}) in {:.2?}",
        start.elapsed()
    );
    assert!(rel < 0.01, "F = {f} (rel err {rel:.4})");
}

/// A square whose back side faces the light stays exactly black, and so does a square lit by
/// the back of a one-sided emitter.
#[test]
fn one_sided_surfaces() {
    // Receiver at z = 0 facing -Z (away from the emitter at z = 1 facing -Z).
    let mut b = Builder::new();
    let r = b.add(&square_z(0., 1., 0., 1., 0., -DVec3::Z), [0.7; 3], [0.0; 3]);
    b.add(&square_z(0., 1., 0., 1., 1., -DVec3::Z), [0.5; 3], [1.0; 3]);
    let patches = b.patches();
    let sol = solve(&patches, 256, 1);
    for t in r {
        assert_eq!(
            sol.triangle_radiance[t], [0.0; 3],
            "back-lit triangle {t} not black"
        );
    }

    // Receiver facing +Z towards an emitter that faces away (+Z): the emitter's back is black.
    let mut b = Builder::new();
    let r = b.add(&square_z(0., 1., 0., 1., 0., DVec3::Z), [0.7; 3], [0.0; 3]);
    let e = b.add(&square_z(0., 1., 0., 1., 1., DVec3::Z), [0.5; 3], [1.0; 3]);
    let patches = b.patches();
    let sol = solve(&patches, 256, 1);
    for t in r {
        assert_eq!(
            sol.triangle_radiance[t], [0.0; 3],
            "triangle {t} lit by a back side"
        );
    }
    for t in e {
        assert_eq!(
            sol.triangle_radiance[t], [1.0; 3],
            "emitter {t} sees nothing, B = E"
        );
    }

    // Control: the same receiver facing the emitter's front is lit (F = 0.19982).
    let mut b = Builder::new();
    let r = b.add(&square_z(0., 1., 0., 1., 0., DVec3::Z), [0.7; 3], [0.0; 3]);
    b.add(&square_z(0., 1., 0., 1., 1., -DVec3::Z), [0.0; 3], [1.0; 3]);
    let patches = b.patches();
    let sol = solve(&patches, 4096, 1);
    let f = mean_b(&patches, &sol, r, 0) / 0.7;
    assert!((f - 0.19982).abs() < 0.02 * 0.19982, "F = {f}");
}

/// An occluder between an emitter and a receiver casts a shadow, whichever side faces the light
/// (a one-sided surface seen from behind absorbs, it does not let light through). The receiver
/// lies in the occluder's umbra (every line from it to the emitter crosses the occluder, some of
/// them through the occluder's diagonal edge), so it is exactly black.
#[test]
fn occluder_casts_shadow() {
    let start = Instant::now();
    let receiver_b = |occluder_facing: Option<DVec3>| {
        let mut b = Builder::new();
        b.add(&square_z(0., 1., 0., 1., 1., -DVec3::Z), [0.0; 3], [1.0; 3]);
        let r = b.add(
            &square_z(0.4, 0.6, 0.4, 0.6, 0., DVec3::Z),
            [0.5; 3],
            [0.0; 3],
        );
        if let Some(facing) = occluder_facing {
            b.add(
                &square_z(0.2, 0.8, 0.2, 0.8, 0.5, facing),
                [0.5; 3],
                [0.0; 3],
            );
        }
        let patches = b.patches();
        let sol = solve(&patches, 4096, 3);
        for bt in &sol.triangle_radiance {
            assert!(bt.iter().all(|x| x.is_finite() && *x >= 0.0));
        }
        (0..3)
            .map(|c| mean_b(&patches, &sol, r.clone(), c))
            .collect::<Vec<f64>>()
    };
    let open = receiver_b(None);
    let front_to_light = receiver_b(Some(DVec3::Z));
    let back_to_light = receiver_b(Some(-DVec3::Z));
    eprintln!(
        "occluder: receiver B open {:.5}, occluder front to the light {:.5}, back to the light \
         {:.5} in {:.2?}",
        open[0],
        front_to_light[0],
        back_to_light[0],
        start.elapsed()
    );
    // Open: the receiver sees the whole emitter (point form factor ~0.24 at its centre).
    assert!((open[0] / 0.5 - 0.2394).abs() < 0.03, "{open:?}");
    assert_eq!(front_to_light, vec![0.0; 3]);
    assert_eq!(back_to_light, vec![0.0; 3]);
}

/// Same seed: bit-identical results; another seed: different noise, same answer.
#[test]
fn reproducible_with_seed() {
    let mut b = Builder::new();
    b.add(&inward_cube()[..10], [0.6, 0.5, 0.4], [0.0; 3]);
    b.add(&inward_cube()[10..], [0.2; 3], [1.0, 0.8, 0.6]);
    let patches = b.patches();
    let one = solve(&patches, 512, 42);
    let two = solve(&patches, 512, 42);
    let bits = |s: &Solution| -> Vec<u64> {
        s.patch_radiance
            .iter()
            .flat_map(|b| b.iter().map(|x| x.to_bits()))
            .collect()
    };
    assert_eq!(bits(&one), bits(&two));
    let other = solve(&patches, 512, 43);
    assert_ne!(bits(&one), bits(&other));
    assert_eq!(one.stats.iterations, 512);
    assert!(one.stats.converged);
    for (x, y) in one.patch_radiance.iter().zip(&other.patch_radiance) {
        for c in 0..3 {
            assert!(x[c].is_finite() && x[c] > 0.0);
            assert!((x[c] - y[c]).abs() < 0.2 * x[c], "{x:?} vs {y:?}");
        }
    }
}

/// Zero-area triangles keep B = E; results scale with the emission and ignore the scene's size.
#[test]
fn degenerate_and_scale() {
    let mut b = Builder::new();
    let a = b.add(&square_z(0., 1., 0., 1., 0., DVec3::Z), [0.5; 3], [0.0; 3]);
    b.add(&square_z(0., 1., 0., 1., 1., -DVec3::Z), [0.0; 3], [3.0; 3]);
    let p = DVec3::new(0.5, 0.5, 0.5);
    let degenerate = b.add(
        &[[p, p + DVec3::X * 0.1, p + DVec3::X * 0.2]],
        [0.5; 3],
        [0.25; 3],
    );
    let patches = b.patches();
    let sol = solve(&patches, 1024, 5);
    for t in degenerate {
        assert_eq!(sol.triangle_radiance[t], [0.25; 3]);
    }
    // Emission 3 instead of 1: B scales by 3.
    let f = mean_b(&patches, &sol, a.clone(), 0) / 0.5 / 3.0;
    assert!((f - 0.19982).abs() < 0.03 * 0.19982, "F = {f}");

    // The same scene 1000 times larger and moved far away: same answer, same noise.
    let scene = Scene::from_triangles(&b.tris, &b.albedo, &b.emission)
        .transformed(1000.0, DVec3::new(5e3, -2e3, 7e3));
    let big = build_patches(&scene, None);
    let sol_big = solve(&big, 1024, 5);
    let f_big = mean_b(&big, &sol_big, a, 0) / 0.5 / 3.0;
    eprintln!("scale: F = {f} vs {f_big} for the scene x1000");
    assert!((f - f_big).abs() < 1e-3 * f, "{f} vs {f_big}");
}
