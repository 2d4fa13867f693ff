//! Visibility rays against the patches: an obvhs compressed wide BVH (CWBVH, 8 children per
//! node, at most 3 patches per leaf) over padded f32 boxes, with every
//! ray-triangle test done by the watertight test of Woop, Benthin and Wald (2013) in f64 on the
//! patch corners, so a ray through the shared edge or vertex of two triangles never slips
//! between them. Shared by the reference path tracer and the exact direct light.
//!
//! Distances are in the unit frame of [`crate::mesh::Patches`]; the self-intersection offset is
//! [`RAY_EPS`] (in `geometry.rs` with every other tolerance).

use std::sync::{Arc, Mutex};

use glam::DVec3;
use obvhs::aabb::Aabb;
use obvhs::cwbvh::{builder::build_cwbvh, CwBvh};
use obvhs::ray::{Ray, RayHit};
use obvhs::{Boundable, BvhBuildParams};

use crate::geometry::tolerances::{BOX_PAD, BOX_PAD_RELATIVE, RAY_EPS, RAY_T_SLACK};
use crate::geometry::Tri;
use crate::mesh::Patches;

// ---------------------------------------------------------------------------------------------
// Watertight ray-triangle intersection

/// A ray prepared for the watertight test of Woop, Benthin and Wald (2013), in f64.
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    org: DVec3,
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f64,
    sy: f64,
    sz: f64,
}

/// A ray-triangle hit: distance and barycentric weights of corners 0, 1, 2.
#[derive(Clone, Copy, Debug)]
pub struct TriHit {
    /// Distance along the ray, in units of the direction's length.
    pub t: f64,
    /// Barycentric weights of corners 0, 1, 2.
    pub bary: [f64; 3],
}

impl WatertightRay {
    /// Prepares the ray `org + t dir`.
    ///
    /// Precondition: `dir` is finite and not zero (its length is the unit of t).
    pub fn new(org: DVec3, dir: DVec3) -> WatertightRay {
        let abs = dir.abs();
        let kz = if abs.x >= abs.y && abs.x >= abs.z {
            0
        } else if abs.y >= abs.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        WatertightRay {
            org,
            kx,
            ky,
            kz,
            sx: dir[kx] / dir[kz],
            sy: dir[ky] / dir[kz],
            sz: 1.0 / dir[kz],
        }
    }

    /// Hit with `t_min < t < t_max`, either side of the triangle. Points exactly on an edge or a
    /// corner count as inside, and the edge functions of a shared edge are computed bit-identically
    /// (up to sign) by both triangles, so no ray slips between two triangles sharing an edge.
    pub fn intersect(&self, tri: &Tri, t_min: f64, t_max: f64) -> Option<TriHit> {
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let a = tri[0] - self.org;
        let b = tri[1] - self.org;
        let c = tri[2] - self.org;
        let ax = a[kx] - self.sx * a[kz];
        let ay = a[ky] - self.sy * a[kz];
        let bx = b[kx] - self.sx * b[kz];
        let by = b[ky] - self.sy * b[kz];
        let cx = c[kx] - self.sx * c[kz];
        let cy = c[ky] - self.sy * c[kz];
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let az = self.sz * a[kz];
        let bz = self.sz * b[kz];
        let cz = self.sz * c[kz];
        let t = (u * az + v * bz + w * cz) / det;
        if !(t > t_min && t < t_max) {
            return None;
        }
        let inv = 1.0 / det;
        Some(TriHit {
            t,
            bary: [u * inv, v * inv, w * inv],
        })
    }
}

// ---------------------------------------------------------------------------------------------
// BVH

/// A padded f32 box around one patch, for the BVH build.
struct PaddedBox {
    aabb: Aabb,
}

impl Boundable for PaddedBox {
    fn aabb(&self) -> Aabb {
        self.aabb
    }
}

fn padded_box(tri: &Tri) -> PaddedBox {
    let lo = tri[0].min(tri[1]).min(tri[2]).as_vec3a();
    let hi = tri[0].max(tri[1]).max(tri[2]).as_vec3a();
    let pad_lo = lo.abs() * BOX_PAD_RELATIVE + BOX_PAD;
    let pad_hi = hi.abs() * BOX_PAD_RELATIVE + BOX_PAD;
    PaddedBox {
        aabb: Aabb {
            min: lo - pad_lo,
            max: hi + pad_hi,
        },
    }
}

/// How far behind a ray's origin (unit frame) the BVH traversal starts it. obvhs 0.4's box
/// test culls every box the ray leaves within 1e-4 of its origin (`cwbvh::node::EPSILON`), so
/// a surface nearer than that (0.7 mm in a 7 m office: a mat on a floor, the coplanar twin of
/// a wall behind a back ray's origin) was never tested, and rays passed through it. Started this far back, every box within reach of the origin is
/// tested; the f64 test still takes hits from the true origin only (`RAY_EPS < t`).
const BVH_ORIGIN_BACK: f64 = 2e-4;

/// The origin the BVH traversal starts `org + t dir` (unit `dir`) from: [`BVH_ORIGIN_BACK`]
/// behind it, so its distances are the ray's plus `BVH_ORIGIN_BACK`.
fn bvh_origin(org: DVec3, dir: DVec3) -> glam::Vec3A {
    (org - dir * BVH_ORIGIN_BACK).as_vec3a()
}

/// An f32 distance bound at least as large as the f64 distance `t`, for BVH culling.
fn conservative_f32(t: f64) -> f32 {
    (t * (1.0 + RAY_T_SLACK) + RAY_T_SLACK) as f32
}

/// Closest hit of a ray: patch index, distance, point on the patch.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Index of the patch hit.
    pub patch: usize,
    /// Distance along the (unit) ray direction, unit frame.
    pub t: f64,
    /// The point hit, unit frame.
    pub point: DVec3,
}

/// A BVH over some patches' boxes: what a [`RayScene`] traverses, shareable between ray scenes
/// of the same patches.
struct RayBvh {
    /// None when no patch is active.
    bvh: Option<CwBvh>,
    /// Patch index of each BVH primitive slot (already mapped through `primitive_indices`).
    slot_patch: Vec<u32>,
}

impl RayBvh {
    /// The BVH over the boxes of the patches `corners` whose `active` flag is set.
    fn build(corners: &[Tri], active: &[bool]) -> RayBvh {
        let active: Vec<u32> = (0..corners.len())
            .filter(|&p| active[p])
            .map(|p| p as u32)
            .collect();
        if active.is_empty() {
            return RayBvh {
                bvh: None,
                slot_patch: Vec::new(),
            };
        }
        let boxes: Vec<PaddedBox> = active
            .iter()
            .map(|&p| padded_box(&corners[p as usize]))
            .collect();
        let mut build_time = std::time::Duration::ZERO;
        let bvh = build_cwbvh(&boxes, BvhBuildParams::medium_build(), &mut build_time);
        let slot_patch = bvh
            .primitive_indices
            .iter()
            .map(|&i| active[i as usize])
            .collect();
        RayBvh {
            bvh: Some(bvh),
            slot_patch,
        }
    }
}

/// A ray BVH kept for later ray scenes of the same patches ([`RayScene::of`]): a solve's
/// thin-cavity search, back exposure, exact direct light and analytic lights trace against
/// one BVH instead of building one each (0.13-0.16 s each at 258k patches). Clones share it.
#[derive(Clone, Default)]
pub struct RayCache(Arc<Mutex<Option<KeyedBvh>>>);

/// A ray BVH with the key of the boxes it was built over ([`boxes_key`]).
type KeyedBvh = (u64, Arc<RayBvh>);

impl std::fmt::Debug for RayCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("RayCache")
    }
}

/// A key of what a ray BVH depends on: every patch's active flag and the box of its corners
/// (a patch turned around, its corners in another order, keeps its key).
fn boxes_key(corners: &[Tri], active: &[bool]) -> u64 {
    let mix = |h: u64, x: u64| (h ^ x).wrapping_mul(0x0100_0000_01b3).rotate_left(29);
    let mut h = mix(0xcbf2_9ce4_8422_2325, corners.len() as u64);
    for (tri, &on) in corners.iter().zip(active) {
        h = mix(h, u64::from(on));
        let lo = tri[0].min(tri[1]).min(tri[2]);
        let hi = tri[0].max(tri[1]).max(tri[2]);
        for x in [lo.x, lo.y, lo.z, hi.x, hi.y, hi.z] {
            h = mix(h, x.to_bits());
        }
    }
    h
}

/// The active patches with a BVH over them, for closest-hit and shadow rays.
pub struct RayScene<'a> {
    /// Every patch's corners (unit frame); only the active ones are in the BVH.
    corners: &'a [Tri],
    bvh: Arc<RayBvh>,
}

impl<'a> RayScene<'a> {
    /// Builds the BVH over the patches `corners` whose `active` flag is set (unit frame, as
    /// [`crate::mesh::build_patches`] makes them). Inactive (zero-area) patches never block.
    /// For a [`Patches`], [`RayScene::of`] reuses the BVH of an earlier ray scene.
    pub fn new(corners: &'a [Tri], active: &[bool]) -> RayScene<'a> {
        RayScene {
            corners,
            bvh: Arc::new(RayBvh::build(corners, active)),
        }
    }

    /// [`RayScene::new`] of the active patches of `patches`, with the BVH kept in
    /// `patches.ray_cache` (shared by its clones): built by the first ray scene of these
    /// patches, reused by the next ones while every patch's box and active flag are the same.
    pub fn of(patches: &'a Patches) -> RayScene<'a> {
        let (corners, active) = (&patches.corners, &patches.active);
        let key = boxes_key(corners, active);
        let mut cached = patches
            .ray_cache
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let bvh = match cached.as_ref() {
            Some((k, bvh)) if *k == key => Arc::clone(bvh),
            _ => {
                let bvh = Arc::new(RayBvh::build(corners, active));
                *cached = Some((key, Arc::clone(&bvh)));
                bvh
            }
        };
        RayScene { corners, bvh }
    }

    /// Closest hit along `org + t dir` (unit `dir`), `RAY_EPS < t`, ignoring patch `skip`.
    pub fn closest(&self, org: DVec3, dir: DVec3, skip: usize) -> Option<Hit> {
        let bvh = self.bvh.bvh.as_ref()?;
        let wt = WatertightRay::new(org, dir);
        let ray = Ray::new(bvh_origin(org, dir), dir.as_vec3a(), 0.0, f32::INFINITY);
        let mut best: Option<(usize, TriHit)> = None;
        let mut best_t = f64::INFINITY;
        let mut ray_hit = RayHit::none();
        bvh.ray_traverse(ray, &mut ray_hit, |_, slot| {
            let patch = self.bvh.slot_patch[slot] as usize;
            if patch == skip {
                return f32::INFINITY;
            }
            match wt.intersect(&self.corners[patch], RAY_EPS, best_t) {
                Some(h) => {
                    best_t = h.t;
                    best = Some((patch, h));
                    conservative_f32(h.t + BVH_ORIGIN_BACK)
                }
                None => f32::INFINITY,
            }
        });
        best.map(|(patch, h)| {
            let tri = &self.corners[patch];
            Hit {
                patch,
                t: h.t,
                point: tri[0] * h.bary[0] + tri[1] * h.bary[1] + tri[2] * h.bary[2],
            }
        })
    }

    /// True when nothing but patches `skip_a` and `skip_b` blocks `org + t dir` for
    /// `RAY_EPS < t < dist - RAY_EPS` (unit `dir`). Back sides block too.
    pub fn visible(&self, org: DVec3, dir: DVec3, dist: f64, skip_a: usize, skip_b: usize) -> bool {
        let Some(bvh) = self.bvh.bvh.as_ref() else {
            return true;
        };
        let t_max = dist - RAY_EPS;
        if t_max <= RAY_EPS {
            return true;
        }
        let wt = WatertightRay::new(org, dir);
        let ray = Ray::new(
            bvh_origin(org, dir),
            dir.as_vec3a(),
            0.0,
            conservative_f32(t_max + BVH_ORIGIN_BACK),
        );
        bvh.ray_traverse_miss(ray, |_, slot| {
            let patch = self.bvh.slot_patch[slot] as usize;
            if patch == skip_a || patch == skip_b {
                return f32::INFINITY;
            }
            if wt.intersect(&self.corners[patch], RAY_EPS, t_max).is_some() {
                0.0
            } else {
                f32::INFINITY
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_surface_just_in_front_of_a_ray_origin_is_hit() {
        // A unit square at z = 0 and a parallel one at z = g, g down to 1e-6 of the scene
        // (well under obvhs' box-test epsilon of 1e-4): rays from just above the first square
        // (its own patches skipped) must meet the second, in closest-hit and shadow tests
        // alike, at any angle.
        let (a, b, c, d) = (DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y);
        for g in [1e-3, 1e-4, 3e-5, 1e-6] {
            let up = DVec3::Z * g;
            let corners = vec![
                [a, b, c],
                [a, c, d],
                [a + up, c + up, b + up],
                [a + up, d + up, c + up],
            ];
            let scene = RayScene::new(&corners, &[true; 4]);
            let mut rng = crate::geometry::sampling::Rng::new(3, 0);
            for _ in 0..500 {
                let x = DVec3::new(
                    0.05 + 0.9 * rng.next_f64(),
                    0.05 + 0.9 * rng.next_f64(),
                    0.0,
                );
                let dir = DVec3::new(rng.next_f64() - 0.5, rng.next_f64() - 0.5, 1.0).normalize();
                let hit = scene.closest(x, dir, 0);
                let through = x + dir * (g / dir.z);
                let inside = through.x > 1e-9
                    && through.x < 1.0 - 1e-9
                    && through.y > 1e-9
                    && through.y < 1.0 - 1e-9;
                if !inside {
                    continue;
                }
                assert!(
                    hit.is_some_and(|h| h.patch >= 2),
                    "gap {g}: missed from {x:?} along {dir:?}"
                );
                assert!(
                    !scene.visible(x, dir, 2.0 * g / dir.z, 0, 1),
                    "gap {g}: seen through"
                );
            }
        }
    }

    #[test]
    fn ray_scenes_of_the_same_patches_share_one_bvh_until_a_box_changes() {
        let scene = crate::scene::generated::cornell_box();
        let mut patches = crate::mesh::build_patches(&scene, None);
        let bvh = |p: &Patches| Arc::clone(&RayScene::of(p).bvh);
        let first = bvh(&patches);
        assert!(Arc::ptr_eq(&first, &bvh(&patches)));
        // A clone shares the BVH; a patch turned around keeps its box.
        let mut turned = patches.clone();
        turned.turn_around(3);
        assert!(Arc::ptr_eq(&first, &bvh(&turned)));
        // A moved corner or a patch made inactive is a new BVH, which hits what a fresh one
        // hits.
        patches.corners[3][0] += DVec3::splat(1e-3);
        let moved = bvh(&patches);
        assert!(!Arc::ptr_eq(&first, &moved));
        patches.active[5] = false;
        assert!(!Arc::ptr_eq(&moved, &bvh(&patches)));
        let (cached, fresh) = (
            RayScene::of(&patches),
            RayScene::new(&patches.corners, &patches.active),
        );
        let mut rng = crate::geometry::sampling::Rng::new(7, 0);
        for _ in 0..2000 {
            let org = DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64()) * 0.8 + 0.1;
            let dir = (DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64()) - 0.5)
                .normalize_or(DVec3::Y);
            let (a, b) = (
                cached.closest(org, dir, usize::MAX),
                fresh.closest(org, dir, usize::MAX),
            );
            assert_eq!(a.map(|h| (h.patch, h.t)), b.map(|h| (h.patch, h.t)));
        }
    }

    #[test]
    fn watertight_exact_shared_edge_axis_aligned() {
        // Two triangles sharing the diagonal of a unit square; rays straight down at points of the
        // diagonal that are exactly representable.
        let a = DVec3::new(0.0, 0.0, 0.0);
        let b = DVec3::new(1.0, 0.0, 0.0);
        let c = DVec3::new(1.0, 1.0, 0.0);
        let d = DVec3::new(0.0, 1.0, 0.0);
        let t1 = [a, b, c];
        let t2 = [a, c, d];
        for i in 0..=64 {
            let s = i as f64 / 64.0;
            let org = DVec3::new(s, s, 1.0);
            let ray = WatertightRay::new(org, -DVec3::Z);
            let h1 = ray.intersect(&t1, 0.0, f64::INFINITY);
            let h2 = ray.intersect(&t2, 0.0, f64::INFINITY);
            assert!(h1.is_some() || h2.is_some(), "miss at s = {s}");
            for h in [h1, h2].into_iter().flatten() {
                assert_eq!(h.t, 1.0);
            }
        }
    }
}
