//! Coplanar patches that overlap facing the same way: the same surface given twice.
//!
//! CAD and modelling exports often hold a surface twice over part of its area: a ceiling
//! polygon and a partition's cap in the same plane, a door leaf flush with its wall, two
//! triangulations of one floor. Where two such patches overlap, a ray meets one of them (which
//! one, the order of a tie decides), so the region sends its light, and blocks, once. Solved as
//! two surfaces, it sends twice: the MGF hospital floor's rooms with such a double floor and
//! ceiling came out 10-20% too bright.
//!
//! [`visible_shares`] gives each overlapped patch the share of its area that shows, the mean
//! over the patch of `1 / k(x)`, `k` the number of such patches at `x`: each of two layers shows
//! half of their overlap; an emitter shows whole. The solvers weigh what a patch sends (its
//! radiance, its antiradiance, its emission) by that share; what it receives, and the
//! radiance it reports, are its own. Identical triangles are not overlaps here: they are one triangle
//! ([`crate::scene::Scene::duplicates`]).

use std::collections::HashMap;

use glam::{DVec2, DVec3};

use crate::geometry::longest_edge;
use crate::geometry::polygon::{triangle_overlap_area, PlaneFrame};
use crate::geometry::tolerances::{plane_tol, GROUP_NORMAL_TOLERANCE};
use crate::mesh::Patches;

/// Smallest overlap, as a share of the smaller patch's area, that counts: patches that share
/// an edge meet in an area of 0, which float noise makes about 1e-12.
pub const OVERLAP_MIN_SHARE: f64 = 1e-3;

/// Sample points per side of the barycentric grid on which a patch's visible share is
/// measured (`OVERLAP_SAMPLES^2` points, one in each triangle of a regular subdivision): the share
/// is exact to about `1 / OVERLAP_SAMPLES^2` of the patch's area.
const OVERLAP_SAMPLES: usize = 8;

/// Step of the normal components in the plane key (unit normals).
const NORMAL_STEP: f64 = 0.05;

/// Shift of the normal components' steps, as a share of a step (see `plane_keys`).
const NORMAL_SHIFT: f64 = 0.3;

/// Step of the plane offset in the plane key (unit frame, scene diameter 1).
const OFFSET_STEP: f64 = 1e-3;

/// Members of a plane bucket up to which every pair is tested; larger buckets are split by a
/// grid in the plane first.
const BRUTE_FORCE_MAX: usize = 32;

/// Per patch, the share of its area that shows (see the module doc): 1 for a patch no other
/// active patch overlaps, `1/2` for one wholly under one other, 1 for an emitter (a shadow ray
/// aimed at it is not stopped by a surface in its plane, so it lights the scene whole). Empty
/// when no two active patches overlap (the common case: nothing to weigh). Cost: about linear
/// in the number of patches (patches are bucketed by plane, then by a grid in their plane).
pub fn visible_shares(patches: &Patches) -> Vec<f64> {
    visible_shares_of(patches, &|p| patches.is_two_sided(p))
}

/// [`visible_shares`] with patch `p` taken as two-sided when `two_sided(p)` (left as it is):
/// [`crate::solve::run`] decides on the faces as it solves them (closed objects turned out)
/// but takes a surface's two-sidedness as given, before it darkens one of its faces.
pub fn visible_shares_of(
    patches: &Patches,
    two_sided: &(dyn Fn(usize) -> bool + Sync),
) -> Vec<f64> {
    let partners = overlapping_partners(patches, two_sided);
    if partners.iter().all(Vec::is_empty) {
        return Vec::new();
    }
    let mut shares = vec![1.0; patches.len()];
    for (p, others) in partners.iter().enumerate() {
        // An emitter shows whole: a shadow ray aimed at it passes a coplanar surface at its own
        // distance, in any path tracer (so two emitters in one place both light the scene).
        if !others.is_empty() && !patches.is_emitter(p) {
            shares[p] = share_of(patches, p, others);
        }
    }
    shares
}

/// The mean of `1 / (1 + covering partners)` over the sample points of patch `p`.
fn share_of(patches: &Patches, p: usize, others: &[u32]) -> f64 {
    let frame = PlaneFrame::new(DVec3::ZERO, patches.normal[p]);
    let [a, b, c] = patches.corners[p];
    let others: Vec<[DVec2; 3]> = others
        .iter()
        .map(|&q| flat_triangle(&frame, &patches.corners[q as usize]))
        .collect();
    let n = OVERLAP_SAMPLES;
    let mut sum = 0.0;
    let mut count = 0usize;
    // One point in each of the n^2 sub-triangles of the barycentric grid, upright (i, j),
    // (i+1, j), (i, j+1) and inverted (i+1, j), (i, j+1), (i+1, j+1), at offsets no simple
    // ratio makes: centroids would lie on the diagonals of squares split the other way.
    let (s, t) = (0.2947, 0.3561);
    let point = |u: f64, v: f64| a + (b - a) * (u / n as f64) + (c - a) * (v / n as f64);
    for i in 0..n {
        for j in 0..n - i {
            let upright = point(i as f64 + s, j as f64 + t);
            let inverted = (i + j + 1 < n).then(|| point(i as f64 + 1.0 - t, j as f64 + 1.0 - s));
            for x in std::iter::once(upright).chain(inverted) {
                let x2 = frame.flat(x);
                let k = others.iter().filter(|t| contains(t, x2)).count();
                sum += 1.0 / (1 + k) as f64;
                count += 1;
            }
        }
    }
    sum / count as f64
}

/// For each patch, the active patches that overlap it coplanar and facing the same way (by at
/// least [`OVERLAP_MIN_SHARE`] of the smaller one's area). Plane buckets are searched in
/// parallel; a pair found in two buckets (a patch near a bucket's edge is in both) is kept once.
fn overlapping_partners(
    patches: &Patches,
    two_sided: &(dyn Fn(usize) -> bool + Sync),
) -> Vec<Vec<u32>> {
    use rayon::prelude::*;
    let mut buckets: HashMap<[i64; 4], Vec<u32>> = HashMap::new();
    for p in 0..patches.len() {
        if !patches.active[p] || patches.area[p] <= 0.0 {
            continue;
        }
        for key in plane_keys(patches, p) {
            buckets.entry(key).or_default().push(p as u32);
        }
    }
    let buckets: Vec<Vec<u32>> = buckets.into_values().filter(|m| m.len() > 1).collect();
    let found: Vec<(u32, u32)> = buckets
        .par_iter()
        .flat_map_iter(|members| {
            candidate_pairs(patches, members)
                .into_iter()
                .filter(|&(p, q)| overlap(patches, p as usize, q as usize, two_sided))
                .map(|(p, q)| (p.min(q), p.max(q)))
        })
        .collect();
    let mut partners = vec![Vec::new(); patches.len()];
    for (p, q) in found {
        partners[p as usize].push(q);
        partners[q as usize].push(p);
    }
    for list in &mut partners {
        list.sort_unstable();
        list.dedup();
    }
    partners
}

/// The plane buckets patch `p` goes in: its normal's components and its plane's offset
/// quantized, and the neighbouring step too where a value lies within its tolerance of a step's
/// edge (so that two patches within tolerance of each other share a bucket). The normal's steps
/// are shifted by [`NORMAL_SHIFT`] of a step so that the components of common directions (0,
/// 1/2, 1/sqrt(3), 1/sqrt(2), sqrt(3)/2, 1) lie well inside a step: an axis-aligned wall
/// goes in one bucket, not four.
fn plane_keys(patches: &Patches, p: usize) -> Vec<[i64; 4]> {
    let n = patches.normal[p];
    let offset = n.dot(patches.centroid[p]);
    let size = longest_edge(&patches.corners[p]);
    let values = [
        (n.x, NORMAL_STEP, NORMAL_SHIFT, GROUP_NORMAL_TOLERANCE),
        (n.y, NORMAL_STEP, NORMAL_SHIFT, GROUP_NORMAL_TOLERANCE),
        (n.z, NORMAL_STEP, NORMAL_SHIFT, GROUP_NORMAL_TOLERANCE),
        (offset, OFFSET_STEP, 0.0, 2.0 * plane_tol(size)),
    ];
    let mut keys = vec![[0i64; 4]];
    for (axis, &(x, step, shift, tol)) in values.iter().enumerate() {
        let u = x / step + shift;
        let cell = u.floor();
        let mut cells = vec![cell as i64];
        if (u - cell) * step < tol {
            cells.push(cell as i64 - 1);
        }
        if (cell + 1.0 - u) * step < tol {
            cells.push(cell as i64 + 1);
        }
        let mut next = Vec::with_capacity(keys.len() * cells.len());
        for k in &keys {
            for &c in &cells {
                let mut k = *k;
                k[axis] = c;
                next.push(k);
            }
        }
        keys = next;
    }
    keys
}

/// Pairs of `members` (one plane bucket) whose bounds in the plane overlap: every pair of a
/// small bucket, else the pairs that share a cell of a grid whose cells are about the members'
/// median size (a member larger than 8 cells a side is paired with every member it bounds).
fn candidate_pairs(patches: &Patches, members: &[u32]) -> Vec<(u32, u32)> {
    let frame = PlaneFrame::new(DVec3::ZERO, patches.normal[members[0] as usize]);
    let bounds: Vec<(DVec2, DVec2)> = members
        .iter()
        .map(|&p| {
            let t = flat_triangle(&frame, &patches.corners[p as usize]);
            (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]))
        })
        .collect();
    let apart = |i: usize, j: usize| {
        let (lo_i, hi_i) = bounds[i];
        let (lo_j, hi_j) = bounds[j];
        lo_i.x > hi_j.x || lo_j.x > hi_i.x || lo_i.y > hi_j.y || lo_j.y > hi_i.y
    };
    let mut pairs = Vec::new();
    let m = members.len();
    if m <= BRUTE_FORCE_MAX {
        for i in 0..m {
            for j in i + 1..m {
                if !apart(i, j) {
                    pairs.push((members[i], members[j]));
                }
            }
        }
        return pairs;
    }
    let mut sizes: Vec<f64> = bounds
        .iter()
        .map(|(lo, hi)| (*hi - *lo).max_element())
        .collect();
    sizes.sort_by(f64::total_cmp);
    let cell = sizes[m / 2].max(1e-12);
    let cell_of = |x: f64| (x / cell).floor() as i64;
    let mut grid: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
    let mut is_large = vec![false; m];
    // Each member's lowest cell, for taking a pair in one of the cells it shares only.
    let mut first = vec![(0i64, 0i64); m];
    for (i, (lo, hi)) in bounds.iter().enumerate() {
        let (x0, x1, y0, y1) = (cell_of(lo.x), cell_of(hi.x), cell_of(lo.y), cell_of(hi.y));
        first[i] = (x0, y0);
        if x1 - x0 > 8 || y1 - y0 > 8 {
            is_large[i] = true;
            continue;
        }
        for x in x0..=x1 {
            for y in y0..=y1 {
                grid.entry((x, y)).or_default().push(i);
            }
        }
    }
    for (&(x, y), cell) in &grid {
        for (a, &i) in cell.iter().enumerate() {
            for &j in &cell[a + 1..] {
                // The first cell both lie in: the pair is taken there and nowhere else.
                let shared = (first[i].0.max(first[j].0), first[i].1.max(first[j].1));
                if shared == (x, y) && !apart(i, j) {
                    pairs.push((members[i], members[j]));
                }
            }
        }
    }
    for i in (0..m).filter(|&i| is_large[i]) {
        // Two large members: the pair once, from the first of them.
        for j in (0..m).filter(|&j| j != i && !(is_large[j] && j < i)) {
            if !apart(i, j) {
                pairs.push((members[i], members[j]));
            }
        }
    }
    pairs
}

/// True when patches `p` and `q` face the same way in one plane (normals within
/// [`GROUP_NORMAL_TOLERANCE`], every corner of each within [`plane_tol`] of the other's plane)
/// and overlap by at least [`OVERLAP_MIN_SHARE`] of the smaller one's area, both one-sided.
///
/// Two-sided patches are left as they are (a share weighs both faces, and one face may be
/// covered and the other not); `crate::solve::run` takes two-sidedness as given, before it
/// darkens any face ([`visible_shares_of`]). The MGF office solved `--two-sided` (its walls
/// slabs whose faces meet and overlap in their planes) against its two-sided path-traced
/// reference, over both faces: 8.1% (bias -0.2%) as given; 9.1% (-6.6%) with its two-sided
/// patches facing the same way weighed (the room side of the walls darker, the light going
/// into the slabs).
///
/// Each share is spread over its whole patch: in total a partly covered patch sends and blocks
/// what shows of it. Measured and not taken: cutting partly covered patches along the overlaps'
/// edges, each piece weighed exactly. The hospital floor 4.46% either way, the corridor 1.58% ->
/// 1.44%, but the MGF office 2.49% -> 2.57% (14 sweeps instead of 12, 9.5% more links) and
/// b90_office 1.22% -> 1.25% from their references.
fn overlap(
    patches: &Patches,
    p: usize,
    q: usize,
    two_sided: &(dyn Fn(usize) -> bool + Sync),
) -> bool {
    // Two-sided patches are left as they are (see below).
    if two_sided(p) || two_sided(q) {
        return false;
    }
    let (np, nq) = (patches.normal[p], patches.normal[q]);
    if (np - nq).length() > GROUP_NORMAL_TOLERANCE {
        return false;
    }
    let (tp, tq) = (&patches.corners[p], &patches.corners[q]);
    let tol = plane_tol(longest_edge(tp).max(longest_edge(tq)));
    let off = |t: &[DVec3; 3], n: DVec3, o: DVec3| t.iter().all(|v| n.dot(*v - o).abs() <= tol);
    if !(off(tq, np, tp[0]) && off(tp, nq, tq[0])) {
        return false;
    }
    let frame = PlaneFrame::new(DVec3::ZERO, np);
    let (a, b) = (flat_triangle(&frame, tp), flat_triangle(&frame, tq));
    let least = OVERLAP_MIN_SHARE * patches.area[p].min(patches.area[q]);
    // Neighbours edge to edge (most candidates) are apart along their shared edge.
    if separated(&a, &b, least) {
        return false;
    }
    triangle_overlap_area(&a, &b) >= least
}

/// True when an edge of either counter-clockwise triangle has the other wholly outside it or
/// within a band of it whose area along the edge is under `slack` (so no overlap of area
/// `slack` or more is possible across it).
fn separated(a: &[DVec2; 3], b: &[DVec2; 3], slack: f64) -> bool {
    let outside = |t: &[DVec2; 3], u: &[DVec2; 3]| {
        (0..3).any(|i| {
            let (p0, p1) = (t[i], t[(i + 1) % 3]);
            let edge = p1 - p0;
            let length = edge.length();
            // Signed distance times length; inside is positive.
            let deepest = u
                .iter()
                .map(|&x| edge.perp_dot(x - p0))
                .fold(f64::NEG_INFINITY, f64::max);
            // The overlap lies within `deepest / length` of this edge, along at most the longer
            // of the two triangles' extents: under `slack` when deepest is small enough.
            let extent = (u[1] - u[0])
                .length()
                .max((u[2] - u[1]).length())
                .max((u[0] - u[2]).length())
                .max(length);
            deepest <= 0.0 || (length > 0.0 && deepest / length * extent < slack)
        })
    };
    outside(a, b) || outside(b, a)
}

/// The 2-D coordinates of triangle `t` in `frame` (a frame of a plane it lies in, within
/// tolerance), counter-clockwise.
fn flat_triangle(frame: &PlaneFrame, t: &[DVec3; 3]) -> [DVec2; 3] {
    let [a, b, c] = t.map(|v| frame.flat(v));
    if (b - a).perp_dot(c - a) < 0.0 {
        [a, c, b]
    } else {
        [a, b, c]
    }
}

/// True when `x` lies inside the counter-clockwise triangle `t` (its edges excluded).
fn contains(t: &[DVec2; 3], x: DVec2) -> bool {
    (0..3).all(|i| (t[(i + 1) % 3] - t[i]).perp_dot(x - t[i]) > 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::build_patches;
    use crate::scene::Scene;

    /// A unit square at `x0` in the plane z = `z` facing +z, as two triangles, split along the
    /// diagonal `(0,0)-(1,1)` or `(1,0)-(0,1)`.
    fn square(z: f64, x0: f64, diagonal: bool) -> [[DVec3; 3]; 2] {
        let v = |x: f64, y: f64| DVec3::new(x0 + x, y, z);
        let (a, b, c, d) = (v(0.0, 0.0), v(1.0, 0.0), v(1.0, 1.0), v(0.0, 1.0));
        if diagonal {
            [[a, b, c], [a, c, d]]
        } else {
            [[a, b, d], [b, c, d]]
        }
    }

    /// Per input triangle, the area-weighted mean visible share of its patches (empty when
    /// nothing overlaps), with `emitting` triangles emitting.
    fn shares_with(tris: &[[DVec3; 3]], emitting: &[usize]) -> Vec<f64> {
        let n = tris.len();
        let mut emission = vec![[0.0; 3]; n];
        for &t in emitting {
            emission[t] = [1.0; 3];
        }
        let scene = Scene::from_triangles(tris, &vec![[0.5; 3]; n], &emission);
        let patches = build_patches(&scene, None);
        let shares = visible_shares(&patches);
        if shares.is_empty() {
            return shares;
        }
        (0..n)
            .map(|t| {
                let ps = patches.first[t] as usize..patches.first[t + 1] as usize;
                let area: f64 = ps.clone().map(|p| patches.area[p]).sum();
                ps.map(|p| patches.area[p] * shares[p]).sum::<f64>() / area
            })
            .collect()
    }

    fn shares_of(tris: &[[DVec3; 3]]) -> Vec<f64> {
        shares_with(tris, &[])
    }

    /// A triangle far off the squares' plane, so that no scene here is flat.
    fn far() -> [DVec3; 3] {
        [
            DVec3::new(3.0, 3.0, 3.0),
            DVec3::new(4.0, 3.0, 3.0),
            DVec3::new(3.0, 4.0, 3.0),
        ]
    }

    #[test]
    fn a_square_given_twice_shows_half_of_each() {
        let mut tris = square(0.0, 0.0, true).to_vec();
        tris.extend(square(0.0, 0.0, false));
        tris.push(far());
        let shares = shares_of(&tris);
        assert_eq!(shares.len(), 5);
        for (p, share) in shares.iter().take(4).enumerate() {
            assert!((share - 0.5).abs() < 1e-12, "{p}: {share}");
        }
        assert_eq!(shares[4], 1.0);
    }

    #[test]
    fn three_layers_show_a_third_each() {
        let mut tris = Vec::new();
        for z in [0.0, 1e-9, -1e-9] {
            tris.extend(square(z, 0.0, true));
        }
        tris.push(far());
        let shares = shares_of(&tris);
        for (p, share) in shares.iter().take(6).enumerate() {
            assert!((share - 1.0 / 3.0).abs() < 1e-12, "{p}: {share}");
        }
    }

    #[test]
    fn neighbours_edge_to_edge_and_layers_apart_do_not_overlap() {
        let mut tris = square(0.0, 0.0, true).to_vec();
        tris.extend(square(0.0, 1.0, false));
        // The same square a little above: parallel, not coplanar.
        tris.extend(square(0.01, 0.0, false));
        tris.push(far());
        assert!(shares_of(&tris).is_empty());
    }

    #[test]
    fn a_half_overlap_and_an_opposite_face() {
        let mut tris = square(0.0, 0.0, true).to_vec();
        // Shifted by half: it overlaps the first square's strip 0.5 <= x <= 1.
        tris.extend(square(0.0, 0.5, false));
        // Inside the first square, facing down: back to back, not facing the same way.
        let v = |x: f64, y: f64| DVec3::new(x, y, 0.0);
        tris.push([v(0.2, 0.1), v(0.9, 0.8), v(0.9, 0.1)]);
        tris.push(far());
        let shares = shares_of(&tris);
        // Half of each square is covered twice: the area-weighted mean share of each square
        // is 1 - 0.5 / 2 = 0.75, to the sampling's resolution.
        let mean = |ts: [usize; 2]| ts.iter().map(|&t| shares[t]).sum::<f64>() / 2.0;
        assert!((mean([0, 1]) - 0.75).abs() < 0.03, "{shares:?}");
        assert!((mean([2, 3]) - 0.75).abs() < 0.03, "{shares:?}");
        assert!(
            (shares[4] - 1.0).abs() < 1e-12,
            "a back face is not an overlap"
        );
    }

    #[test]
    fn an_emitter_shows_whole_over_a_surface() {
        let tris: Vec<[DVec3; 3]> = [square(0.0, 0.0, true), square(0.0, 0.0, false)]
            .concat()
            .into_iter()
            .chain([far()])
            .collect();
        let shares = shares_with(&tris, &[2, 3]);
        for (t, expected) in [0.5, 0.5, 1.0, 1.0].into_iter().enumerate() {
            assert!((shares[t] - expected).abs() < 1e-12, "{t}: {shares:?}");
        }
    }
}
