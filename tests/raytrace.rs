//! The watertight ray test over the wide BVH on a fan of triangles in a tilted plane: rays aimed
//! at shared vertices and edges never slip through, rays aimed just outside never hit. The fan
//! is built as patches (the unit frame the solvers trace in), so these tests sit above the mesh
//! stage rather than next to the ray tracer.

use std::f64::consts::PI;

use antiradiance::geometry::raytrace::RayScene;
use antiradiance::geometry::sampling::Rng;
use antiradiance::geometry::Tri;
use antiradiance::mesh::{build_patches, Patches};
use antiradiance::scene::Scene;
use glam::DVec3;
use obvhs::ray::Ray;

/// A fan of `m` triangles around `center` in a tilted plane, counter-clockwise.
fn fan(m: usize) -> (Vec<Tri>, DVec3, Vec<DVec3>) {
    let center = DVec3::new(0.013, -0.027, 0.031);
    let u = DVec3::new(0.8, 0.35, -0.2).normalize();
    let v = u.cross(DVec3::new(0.1, 0.3, 0.9)).normalize();
    let rim: Vec<DVec3> = (0..m)
        .map(|i| {
            // Irregular angles and radii so no edge is axis-aligned.
            let a = 2.0 * PI * (i as f64 + 0.3 * ((i * 7 % 5) as f64 / 5.0)) / m as f64;
            let r = 0.3 + 0.1 * ((i * 3 % 4) as f64 / 4.0);
            center + u * (r * a.cos()) + v * (r * a.sin())
        })
        .collect();
    let tris = (0..m).map(|i| [center, rim[i], rim[(i + 1) % m]]).collect();
    (tris, center, rim)
}

fn fan_patches(tris: &[Tri]) -> Patches {
    let n = tris.len();
    let scene = Scene::from_triangles(tris, &vec![[0.5; 3]; n], &vec![[0.0; 3]; n]);
    build_patches(&scene, None)
}

#[test]
fn watertight_fan_edges_and_vertices_never_missed() {
    let m = 9;
    let (tris, center, rim) = fan(m);
    let patches = fan_patches(&tris);
    let scene = RayScene::new(&patches.corners, &patches.active);
    // The fan in the unit frame (build_patches moved and scaled it).
    let frame = patches.frame;
    let c = frame.unit_from_world(center);
    let rim: Vec<DVec3> = rim.iter().map(|&p| frame.unit_from_world(p)).collect();
    let n = patches.normal[0];
    let mut rng = Rng::new(7, 0);
    let mut rays = 0;
    let mut f32_misses = 0;
    for trial in 0..400 {
        // Targets: the centre vertex (shared by all m triangles) and points on the m shared
        // spokes. (Rim vertices lie on the fan's outer boundary, where a ray rounded by
        // 1e-17 may legitimately pass outside, so they are not targets.)
        let i = trial % m;
        let s = 0.99 * rng.next_f64();
        let target = if trial % 4 == 0 {
            c
        } else {
            c + (rim[i] - c) * s
        };
        for side in [1.0, -1.0] {
            // Origins on both sides, at various angles (never in the plane).
            let off = DVec3::new(
                rng.next_f64() - 0.5,
                rng.next_f64() - 0.5,
                rng.next_f64() - 0.5,
            ) * 0.8;
            let org = target + n * (side * (0.05 + 0.4 * rng.next_f64())) + off;
            if (org - target).dot(n) * side <= 0.0 {
                continue;
            }
            let dir = (target - org).normalize();
            rays += 1;
            let hit = scene.closest(org, dir, usize::MAX);
            assert!(
                hit.is_some(),
                "ray {org:?} -> {target:?} slipped through the fan"
            );
            let hit = hit.unwrap();
            assert!(
                (hit.point - target).length() < 1e-9,
                "hit far from the target"
            );
            // For information: obvhs' own f32 test.
            let hit_f32 = patches.corners.iter().any(|t| {
                let tri = obvhs::triangle::Triangle {
                    v0: t[0].as_vec3a(),
                    v1: t[1].as_vec3a(),
                    v2: t[2].as_vec3a(),
                };
                let ray = Ray::new_inf(org.as_vec3a(), dir.as_vec3a());
                tri.intersect(&ray).is_finite()
            });
            if !hit_f32 {
                f32_misses += 1;
            }
        }
    }
    assert!(rays > 600, "{rays}");
    eprintln!("watertight: {rays} rays, f32 Moller-Trumbore missed {f32_misses}");
}

#[test]
fn watertight_rejects_points_outside() {
    // Negative control: rays aimed just outside the fan's rim miss it.
    let (tris, center, rim) = fan(7);
    let patches = fan_patches(&tris);
    let scene = RayScene::new(&patches.corners, &patches.active);
    let frame = patches.frame;
    let c = frame.unit_from_world(center);
    let n = patches.normal[0];
    for (i, &r) in rim.iter().enumerate() {
        let r = frame.unit_from_world(r);
        let target = c + (r - c) * 1.001;
        let org = target + n * 0.3 + DVec3::new(0.01, 0.02, -0.01) * i as f64;
        let dir = (target - org).normalize();
        assert!(scene.closest(org, dir, usize::MAX).is_none());
    }
}
