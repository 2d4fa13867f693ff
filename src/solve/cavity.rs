//! Thin cavities in front of emitter faces: a luminaire's panel hung just under a ceiling.
//!
//! An emitter face (its front, or a two-sided emitter's back) that faces a surface (its
//! *cover*) closer than [`COVERED_GAP`] of the emitter's size sends its light into a gap that
//! keeps it: the face and the part of the cover over it see almost only each other. Solved
//! with the rest of the scene, that light, many times the room's, lights the cover's elements,
//! and antiradiance has to cancel it for everything outside the gap, which it does only
//! approximately: b90_office two-sided (fluorescent panels 0.76 mm under its ceiling, their
//! backs toward it) came out 17.6% from its path-traced reference, every surface too bright
//! (walls +41%); a plain room with one such panel 21%, and 36% with the panel one-sided facing
//! up into the ceiling (the room lit by the leak, its path tracer's nearly black).
//!
//! Such a gap is solved on its own instead, as two parallel plates (the gap is at most 2% of
//! the emitter's size, so what leaves it at the edges is of that order): the cover's covered
//! part and the emitter's face have, per channel,
//!
//! ```text
//! B_cover = rho_c E / (1 - rho_c rho_e),    B_face = E + rho_e B_cover
//! ```
//!
//! with `E` the emitter's emission, `rho_e` its albedo and `rho_c` the cover's (0 where the
//! cover turns a one-sided back to the gap: it absorbs). The rest of the scene is solved
//! without that face ([`Cavities::opened`]: a back-covered emitter one-sided, a front-covered
//! two-sided one turned around and one-sided, a front-covered one-sided one black). After the
//! solve the face gets `B_face`, and the cover's face toward the gap the area-weighted mean of
//! `B_cover` over its covered part and its solved radiance over the rest: a path tracer's
//! per-triangle estimate averages over the whole triangle, hidden part included.
//!
//! Only [`crate::solve::run`] does this (the `solve` command, [`crate::solve()`]); the
//! relighter solves such emitters as given
//! ([`crate::solve::warnings::covered_emitter_warning`] names them for a solve that did not).

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::raytrace::RayScene;
use crate::mesh::Patches;
use crate::solve::solution::{sanitize, Solution};

/// How close a surface in front of an emitter face makes a cavity, as a share of the
/// emitter's size (the square root of its area).
pub const COVERED_GAP: f64 = 0.02;

/// Points per emitter face whose rays straight out of it must all meet a surface that does not
/// emit within the gap for the face to count as covered (a 4 x 4 grid over the triangle); each
/// point stands for an equal share of the emitter's area on the surface it meets.
const COVER_POINTS_SIDE: usize = 4;

/// A surface in front of a covered emitter face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cover {
    /// The covering patch.
    pub patch: u32,
    /// Share of the emitter's area over it, in (0, 1].
    pub share: f64,
    /// Its front faces the gap (else its back does).
    pub front: bool,
}

/// An emitter with a covered face, and what covers it.
#[derive(Clone, Debug, PartialEq)]
pub struct Trapped {
    /// The emitting patch.
    pub emitter: u32,
    /// The covers of its front, when its front is covered.
    pub front: Option<Vec<Cover>>,
    /// The covers of its back, when it is two-sided and its back is covered.
    pub back: Option<Vec<Cover>>,
}

impl Trapped {
    /// Its front is covered and it is two-sided (in `patches`, those it was found in) with a
    /// free back: it is solved turned around, one-sided (its back becomes the solved front).
    fn turned(&self, patches: &Patches) -> bool {
        self.front.is_some() && self.back.is_none() && patches.is_two_sided(self.emitter as usize)
    }
}

/// The emitters of a scene with a face just in front of a surface, and what covers them.
#[derive(Clone, Debug, Default)]
pub struct Cavities {
    /// The emitters with a covered face.
    pub trapped: Vec<Trapped>,
}

impl Cavities {
    /// The emitters of `patches` with a face (the front, or a two-sided emitter's back) that
    /// faces a surface that does not emit closer than [`COVERED_GAP`] of their size, at every
    /// one of a grid of points; `None` when there are none.
    pub fn find(patches: &Patches) -> Option<Cavities> {
        let emitters: Vec<usize> = (0..patches.len())
            .filter(|&p| patches.active[p] && patches.is_emitter(p))
            .collect();
        if emitters.is_empty() {
            return None;
        }
        let scene = RayScene::of(patches);
        let trapped: Vec<Trapped> = emitters
            .par_iter()
            .filter_map(|&p| {
                let n = patches.normal[p];
                let front = covers_of(patches, &scene, p, n);
                let back = if patches.is_two_sided(p) {
                    covers_of(patches, &scene, p, -n)
                } else {
                    None
                };
                (front.is_some() || back.is_some()).then_some(Trapped {
                    emitter: p as u32,
                    front,
                    back,
                })
            })
            .collect();
        (!trapped.is_empty()).then_some(Cavities { trapped })
    }

    /// The number of emitters with a covered face.
    pub fn len(&self) -> usize {
        self.trapped.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.trapped.is_empty()
    }

    /// `patches` as the rest of the scene is solved: an emitter whose back alone is covered
    /// one-sided; one whose front alone is covered, two-sided, turned around and one-sided
    /// (its back's light goes out); one with no face that sends light out black and dark.
    pub fn opened(&self, patches: &Patches) -> Patches {
        let mut out = patches.clone();
        for t in &self.trapped {
            let p = t.emitter as usize;
            if let Some(two) = out.two_sided.get_mut(p) {
                *two = false;
            }
            if t.turned(patches) {
                out.turn_around(p);
            } else if t.front.is_some() {
                out.blacken(p);
            }
        }
        out.forget_two_sided_if_none();
        out
    }

    /// Gives the emitters' covered faces and their covers' faces toward the gaps their
    /// radiance (see the [module](self)), and a turned emitter's back the radiance solved for
    /// it, in `solution`, solved on [`Cavities::opened`] of `patches`. Call before
    /// [`Solution::settle_inactive`], which remakes the per-triangle values.
    pub fn fill(&self, solution: &mut Solution, patches: &Patches) {
        let n = patches.len();
        if solution.patch_radiance.len() != n {
            return;
        }
        solution.patch_radiance_back.resize(n, [0.0; 3]);
        // Per cover and face (front, back): covered area and the area-weighted B_cover.
        let mut area = vec![[0.0f64; 2]; n];
        let mut sum = vec![[[0.0f64; 3]; 2]; n];
        for t in &self.trapped {
            let e = t.emitter as usize;
            let emission = patches.emission[e].map(|x| x * patches.emission_scale);
            let rho_e = patches.albedo[e];
            if t.turned(patches) {
                solution.patch_radiance_back[e] = solution.patch_radiance[e];
            }
            for (covers, face) in [(&t.front, 0), (&t.back, 1)] {
                let Some(covers) = covers else {
                    continue;
                };
                let mut gap_face = [0.0f64; 3];
                for &Cover {
                    patch: q,
                    share,
                    front,
                } in covers
                {
                    let q = q as usize;
                    let reflects = front || patches.is_two_sided(q);
                    let rho_c = if reflects {
                        patches.albedo[q]
                    } else {
                        [0.0; 3]
                    };
                    let cover: [f64; 3] = std::array::from_fn(|c| {
                        rho_c[c] * emission[c] / (1.0 - rho_c[c] * rho_e[c]).max(1e-9)
                    });
                    for c in 0..3 {
                        gap_face[c] += share * (emission[c] + rho_e[c] * cover[c]);
                    }
                    if reflects {
                        let cover_face = usize::from(!front);
                        let a = share * patches.area[e];
                        area[q][cover_face] += a;
                        for c in 0..3 {
                            sum[q][cover_face][c] += a * cover[c];
                        }
                    }
                }
                let solved = if face == 0 {
                    &mut solution.patch_radiance[e]
                } else {
                    &mut solution.patch_radiance_back[e]
                };
                *solved = gap_face.map(sanitize);
            }
        }
        for q in 0..n {
            for face in 0..2 {
                if area[q][face] <= 0.0 {
                    continue;
                }
                let f = (area[q][face] / patches.area[q]).min(1.0);
                let gap: [f64; 3] = std::array::from_fn(|c| sum[q][face][c] / area[q][face]);
                let solved = if face == 0 {
                    &mut solution.patch_radiance[q]
                } else {
                    &mut solution.patch_radiance_back[q]
                };
                for c in 0..3 {
                    solved[c] = sanitize((1.0 - f) * solved[c] + f * gap[c]);
                }
            }
        }
    }
}

/// The rays of the cover test of patch `p`'s face toward `axis` (its normal or the
/// opposite): the gap ([`COVERED_GAP`] of the patch's size), the direction, and the
/// [`COVER_POINTS_SIDE`] x [`COVER_POINTS_SIDE`] grid points on the triangle.
fn cover_rays(patches: &Patches, p: usize, axis: DVec3) -> (f64, DVec3, Vec<DVec3>) {
    let tri = &patches.corners[p];
    let gap = COVERED_GAP * patches.area[p].sqrt();
    // Tilted off the normal by 0.01 rad: a ray exactly along an axis can slip past a flat box
    // of the BVH.
    let dir: DVec3 = (axis + 0.01 * (tri[1] - tri[0]).normalize()).normalize();
    let side = COVER_POINTS_SIDE;
    let points = (0..side * side)
        .map(|k| {
            let (i, j) = (k / side, k % side);
            let (u1, u2) = (
                (i as f64 + 0.5) / side as f64,
                (j as f64 + 0.5) / side as f64,
            );
            crate::geometry::sampling::point_on_triangle(tri, u1, u2)
        })
        .collect();
    (gap, dir, points)
}

/// The covers of emitter `p`'s face toward `axis` (its normal or the opposite), when every one
/// of its grid points' rays along `axis` meets a surface that does not emit within the gap;
/// `None` otherwise.
fn covers_of(patches: &Patches, scene: &RayScene, p: usize, axis: DVec3) -> Option<Vec<Cover>> {
    let (gap, dir, points) = cover_rays(patches, p, axis);
    let share = 1.0 / points.len() as f64;
    let mut covers: Vec<Cover> = Vec::new();
    for x in points {
        let hit = scene.closest(x, dir, p)?;
        if hit.t >= gap || patches.is_emitter(hit.patch) {
            return None;
        }
        let front = patches.normal[hit.patch].dot(dir) < 0.0;
        let patch = hit.patch as u32;
        match covers
            .iter_mut()
            .find(|c| c.patch == patch && c.front == front)
        {
            Some(c) => c.share += share,
            None => covers.push(Cover {
                patch,
                share,
                front,
            }),
        }
    }
    Some(covers)
}

/// True when patch `p`'s face toward `axis` (its normal or the opposite) is covered as an
/// emitter's face is for [`Cavities::find`]: every one of its grid points' rays along `axis`
/// meets a surface that does not emit within [`COVERED_GAP`] of its size. Such a face sees
/// almost only its cover: what reaches it enters the gap at its edges (`solve::sealed` solves
/// it dark). Each point's ray is first tested for any surface within the gap, and the face is
/// not covered at its first point with none.
pub fn covered(patches: &Patches, scene: &RayScene, p: usize, axis: DVec3) -> bool {
    let (gap, dir, points) = cover_rays(patches, p, axis);
    points.into_iter().all(|x| {
        !scene.visible(x, dir, gap, p, p)
            && scene
                .closest(x, dir, p)
                .is_some_and(|hit| hit.t < gap && !patches.is_emitter(hit.patch))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;
    use glam::DVec3;

    /// A 1 x 1 panel (emission 2, albedo 0.5, two-sided when `panel_two_sided`) facing down
    /// `gap` under a 3 x 3 ceiling of albedo 0.8 facing down (`ceiling_faces_gap`) or up,
    /// one-sided.
    fn panel_under(gap: f64, ceiling_faces_gap: bool, panel_two_sided: bool) -> Patches {
        let v = DVec3::new;
        let quad = |q: [DVec3; 4]| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]];
        let mut ceiling = [
            v(-1.5, 1.0, -1.5),
            v(-1.5, 1.0, 1.5),
            v(1.5, 1.0, 1.5),
            v(1.5, 1.0, -1.5),
        ];
        if ceiling_faces_gap {
            ceiling.reverse();
        }
        let y = 1.0 - gap;
        let panel = [
            v(-0.5, y, -0.5),
            v(0.5, y, -0.5),
            v(0.5, y, 0.5),
            v(-0.5, y, 0.5),
        ];
        let tris: Vec<[DVec3; 3]> = quad(ceiling).into_iter().chain(quad(panel)).collect();
        let albedo = [[0.8; 3], [0.8; 3], [0.5; 3], [0.5; 3]];
        let emission = [[0.0; 3], [0.0; 3], [2.0; 3], [2.0; 3]];
        let mut scene = Scene::from_triangles(&tris, &albedo, &emission);
        scene.two_sided = vec![false, false, panel_two_sided, panel_two_sided];
        crate::mesh::build_patches(&scene, None)
    }

    /// A solution of [`panel_under`]'s patches: ceiling 0.1, panel 2 (scene units).
    fn solved() -> Solution {
        Solution {
            patch_radiance: vec![[0.1; 3], [0.1; 3], [2.0; 3], [2.0; 3]],
            ..Solution::default()
        }
    }

    #[test]
    fn panel_under_a_ceiling_facing_it_gets_the_parallel_plates_radiance() {
        let patches = panel_under(0.001, true, true);
        let cavities = Cavities::find(&patches).expect("covered");
        assert_eq!(cavities.len(), 2);
        assert!(!cavities.opened(&patches).has_two_sided());
        let mut solution = solved();
        cavities.fill(&mut solution, &patches);
        let cover = 0.8 * 2.0 / (1.0 - 0.8 * 0.5);
        let back = 2.0 + 0.5 * cover;
        for p in [2, 3] {
            assert!((solution.patch_radiance_back[p][0] - back).abs() < 1e-9);
        }
        // The ceiling is 9 m2, a ninth of it over the panel.
        let ceiling = (solution.patch_radiance[0][0] + solution.patch_radiance[1][0]) * 4.5;
        let expected = 8.0 * 0.1 + cover;
        assert!((ceiling - expected).abs() < 1e-9, "{ceiling} vs {expected}");
    }

    #[test]
    fn a_one_sided_back_over_the_gap_absorbs() {
        let patches = panel_under(0.001, false, true);
        let cavities = Cavities::find(&patches).expect("covered");
        let mut solution = solved();
        cavities.fill(&mut solution, &patches);
        for p in [2, 3] {
            assert!((solution.patch_radiance_back[p][0] - 2.0).abs() < 1e-9);
        }
        assert_eq!(solution.patch_radiance[0], [0.1; 3]);
        assert_eq!(solution.patch_radiance_back[0], [0.0; 3]);
    }

    #[test]
    fn a_one_sided_panel_facing_the_ceiling_sends_its_light_into_the_gap_only() {
        let mut patches = panel_under(0.001, true, false);
        for p in [2, 3] {
            patches.turn_around(p);
        }
        let cavities = Cavities::find(&patches).expect("covered");
        assert_eq!(cavities.len(), 2);
        assert!(cavities.trapped.iter().all(|t| t.front.is_some()));
        let opened = cavities.opened(&patches);
        assert_eq!(opened.emission[2], [0.0; 3], "no light of it gets out");
        let mut solution = solved();
        cavities.fill(&mut solution, &patches);
        let cover = 0.8 * 2.0 / (1.0 - 0.8 * 0.5);
        assert!((solution.patch_radiance[2][0] - (2.0 + 0.5 * cover)).abs() < 1e-9);
        let ceiling = (solution.patch_radiance[0][0] + solution.patch_radiance[1][0]) * 4.5;
        assert!((ceiling - (8.0 * 0.1 + cover)).abs() < 1e-9);
    }

    #[test]
    fn a_panel_far_from_the_ceiling_or_one_sided_is_not_covered() {
        assert!(Cavities::find(&panel_under(0.3, true, true)).is_none());
        assert!(Cavities::find(&panel_under(0.001, true, false)).is_none());
    }
}
