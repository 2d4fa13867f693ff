//! The kinds of bad triangulation but huge-tiny: the splitting ones (fan, random, tjunction;
//! edges split consistently from both sides) and the moving ones (jitter, translate, twins).

use std::collections::HashMap;

use glam::{DVec2, DVec3};

use super::*;
use crate::geometry::sampling::{mix64, Rng};
use crate::geometry::tolerances::TIGHTER;
use crate::scene::Scene;

/// `fan`: k slivers from the vertex opposite the shortest edge, plus k - 1 in the strip along
/// that edge; the edge itself is not split, so neighbours see no new vertex.
pub(super) fn fan(scene: &Scene, k: usize) -> Out {
    let mut out = Out::default();
    for t in 0..scene.len() {
        let c = scene.corners(t);
        if k == 1 || scene.is_degenerate(t) {
            out.push(c, t, scene.area(t), true);
            continue;
        }
        let length = |i: usize| (c[(i + 1) % 3] - c[i]).length_squared();
        let e = (0..3)
            .min_by(|&i, &j| length(i).total_cmp(&length(j)))
            .unwrap_or(0);
        // (apex, b, c) is a cyclic rotation of the corners: the orientation is kept.
        let (apex, b, cc) = (c[(e + 2) % 3], c[e], c[(e + 1) % 3]);
        // Points on the line parallel to b-cc, a share `delta` of the way to the apex.
        let delta = 1.0 / (2 * k) as f64;
        let p: Vec<DVec3> = (0..=k)
            .map(|j| {
                if j == 0 {
                    b
                } else if j == k {
                    cc
                } else {
                    let on_edge = b + (cc - b) * (j as f64 / k as f64);
                    on_edge * (1.0 - delta) + apex * delta
                }
            })
            .collect();
        for j in 0..k {
            out.piece([apex, p[j], p[j + 1]], t);
        }
        // The strip between the edge b-cc and the chain p[1..k], fanned from b.
        for j in (1..k).rev() {
            let next = if j + 1 == k { cc } else { p[j + 1] };
            out.piece([b, next, p[j]], t);
        }
    }
    out
}

/// A point on the edge with canonical key `k` (its lower end `lo`, upper end `hi`) at parameter
/// `s` from `lo`: the same bits whichever triangle asks.
fn on_edge(lo: DVec3, hi: DVec3, s: f64) -> DVec3 {
    lo + (hi - lo) * s
}

/// A point added on edge `e` of a triangle: parameter `s` in (0, 1) from corner `e` to corner
/// `e + 1`, and its position.
type EdgePoint = (f64, DVec3);

/// A vertex of a triangle being split: barycentric weights of corners 1 and 2, position, and
/// (edge, parameter) when it was added on an edge.
type LocalVertex = (DVec2, DVec3, Option<(usize, f64)>);

/// Splits triangle `corners` by inserting `edge_points[e]` (points on its edges, see
/// [`EdgePoint`]) and then the interior points `interior` (barycentric weights of corners 1 and
/// 2), one at a time: an edge point splits the triangle on its piece of the edge in two, an
/// interior point the triangle containing it in three. An interior point that would make a
/// triangle smaller than `min_share` of the whole is left out. Orientation is kept; the
/// pieces cover the triangle exactly.
fn split_triangle(
    corners: [DVec3; 3],
    edge_points: &[Vec<EdgePoint>; 3],
    interior: &[(f64, f64)],
    min_share: f64,
) -> Vec<[DVec3; 3]> {
    // Local vertices: (barycentric weights of corners 1 and 2, position, (edge, parameter)).
    let unit = [
        DVec2::new(0.0, 0.0),
        DVec2::new(1.0, 0.0),
        DVec2::new(0.0, 1.0),
    ];
    let mut local: Vec<LocalVertex> = (0..3).map(|i| (unit[i], corners[i], None)).collect();
    let mut tris: Vec<[usize; 3]> = vec![[0, 1, 2]];
    // Parameter of local vertex `v` along edge `e`, when it lies on it.
    let param = |local: &[LocalVertex], v: usize, e: usize| {
        if v < 3 {
            if v == e {
                Some(0.0)
            } else if v == (e + 1) % 3 {
                Some(1.0)
            } else {
                None
            }
        } else {
            local[v].2.filter(|&(edge, _)| edge == e).map(|(_, s)| s)
        }
    };
    for (e, points) in edge_points.iter().enumerate() {
        for &(s, pos) in points {
            let at = unit[e].lerp(unit[(e + 1) % 3], s);
            let found = tris.iter().enumerate().find_map(|(i, tri)| {
                (0..3).find_map(|r| {
                    let (u, v) = (tri[r], tri[(r + 1) % 3]);
                    match (param(&local, u, e), param(&local, v, e)) {
                        (Some(su), Some(sv)) if su < s && s < sv => Some((i, r)),
                        _ => None,
                    }
                })
            });
            let Some((i, r)) = found else { continue };
            let tri = tris[i];
            let (u, v, w) = (tri[r], tri[(r + 1) % 3], tri[(r + 2) % 3]);
            local.push((at, pos, Some((e, s))));
            let p = local.len() - 1;
            tris[i] = [u, p, w];
            tris.push([p, v, w]);
        }
    }
    let cross = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - a);
    for &(w1, w2) in interior {
        let q = DVec2::new(w1, w2);
        let found = tris.iter().position(|tri| {
            let [a, b, c] = tri.map(|v| local[v].0);
            cross(a, b, q) > 0.0 && cross(b, c, q) > 0.0 && cross(c, a, q) > 0.0
        });
        let Some(i) = found else { continue };
        let [a, b, c] = tris[i];
        let (pa, pb, pc) = (local[a].0, local[b].0, local[c].0);
        // Twice the area of the whole triangle in these coordinates is 1.
        if [cross(pa, pb, q), cross(pb, pc, q), cross(pc, pa, q)]
            .iter()
            .any(|&x| x < min_share)
        {
            continue;
        }
        let pos = corners[0] * (1.0 - w1 - w2) + corners[1] * w1 + corners[2] * w2;
        local.push((q, pos, None));
        let p = local.len() - 1;
        tris[i] = [a, b, p];
        tris.push([b, c, p]);
        tris.push([c, a, p]);
    }
    tris.iter().map(|tri| tri.map(|v| local[v].1)).collect()
}

/// The edge points of triangle `t` given per undirected edge as parameters from the edge's
/// lower end.
fn edge_points_of(
    scene: &Scene,
    t: usize,
    points: &HashMap<EdgeKey, Vec<(usize, f64)>>,
) -> [Vec<EdgePoint>; 3] {
    let c = scene.corners(t);
    std::array::from_fn(|e| {
        let (a, b) = (c[e], c[(e + 1) % 3]);
        let k = edge_key(a, b);
        let forward = point_key(a) <= point_key(b);
        let (lo, hi) = if forward { (a, b) } else { (b, a) };
        let mut list: Vec<EdgePoint> = points
            .get(&k)
            .map(|l| {
                l.iter()
                    .filter(|&&(side, _)| side == usize::MAX || side == t)
                    .map(|&(_, s)| {
                        let pos = on_edge(lo, hi, s);
                        (if forward { s } else { 1.0 - s }, pos)
                    })
                    .collect()
            })
            .unwrap_or_default();
        list.sort_by(|x, y| x.0.total_cmp(&y.0));
        list
    })
}

/// `random`: 0-2 random points per edge (shared by both sides), `points` random interior
/// points per triangle.
pub(super) fn random(scene: &Scene, points: usize, seed: u64) -> Out {
    let edges = Edges::of(scene, true);
    let mut on: HashMap<EdgeKey, Vec<(usize, f64)>> = HashMap::new();
    for (i, k) in edges.order.iter().enumerate() {
        let mut rng = Rng::new(seed ^ 0x5eed_ed6e, i as u64);
        let count = rng.below(3) as usize;
        let mut s: Vec<f64> = (0..count).map(|_| 0.1 + 0.8 * rng.next_f64()).collect();
        s.sort_by(f64::total_cmp);
        s.dedup_by(|a, b| (*a - *b).abs() < 0.05);
        on.insert(*k, s.into_iter().map(|s| (usize::MAX, s)).collect());
    }
    let mut out = Out::default();
    for t in 0..scene.len() {
        let c = scene.corners(t);
        if scene.is_degenerate(t) {
            out.push(c, t, 0.0, true);
            continue;
        }
        let mut rng = Rng::new(seed, t as u64);
        let interior: Vec<(f64, f64)> = (0..points)
            .map(|_| {
                // Uniform over the triangle.
                let (u1, u2) = (rng.next_f64(), rng.next_f64());
                let r = u1.sqrt();
                (u2 * r, r - u2 * r)
            })
            .collect();
        for piece in split_triangle(c, &edge_points_of(scene, t, &on), &interior, 1e-3) {
            out.piece(piece, t);
        }
    }
    out
}

/// `tjunction`: a share of the edges shared by exactly two triangles gets a point on one side.
pub(super) fn tjunction(scene: &Scene, share: f64, seed: u64) -> Out {
    let edges = Edges::of(scene, true);
    let mut on: HashMap<EdgeKey, Vec<(usize, f64)>> = HashMap::new();
    for (i, k) in edges.order.iter().enumerate() {
        let sides = &edges.on[k];
        if sides.len() != 2 {
            continue;
        }
        let mut rng = Rng::new(seed ^ 0x7_1c7, i as u64);
        if rng.next_f64() >= share {
            continue;
        }
        let side = sides[rng.below(2) as usize].0;
        let s = 0.3 + 0.4 * rng.next_f64();
        on.insert(*k, vec![(side, s)]);
    }
    let mut out = Out::default();
    for t in 0..scene.len() {
        let c = scene.corners(t);
        if scene.is_degenerate(t) {
            out.push(c, t, 0.0, true);
            continue;
        }
        let points = edge_points_of(scene, t, &on);
        if points.iter().all(Vec::is_empty) {
            out.push(c, t, scene.area(t), true);
            continue;
        }
        for piece in split_triangle(c, &points, &[], 0.0) {
            out.piece(piece, t);
        }
    }
    out
}

/// `jitter`: every distinct vertex moved by a random vector of length at most `distance`,
/// drawn from its own position's bits (so shared vertices move together).
pub(super) fn jitter(scene: &Scene, distance: f64, seed: u64) -> Out {
    let mut moved: HashMap<[u64; 3], DVec3> = HashMap::new();
    let mut out = Out::default();
    for t in 0..scene.len() {
        let c = scene.corners(t).map(|p| {
            *moved.entry(point_key(p)).or_insert_with(|| {
                let k = point_key(p);
                let index = mix64(k[0]) ^ mix64(k[1] ^ 0x9e37_79b9) ^ mix64(k[2] ^ 0x7f4a_7c15);
                let mut rng = Rng::new(seed, index);
                // Uniform in the ball, by rejection; a hair inside so that rounding p + d
                // never moves p by more than `distance`.
                let d = loop {
                    let d = DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64()) * 2.0
                        - DVec3::ONE;
                    if d.length_squared() <= 1.0 {
                        break d;
                    }
                };
                let moved = p + d * (distance * TIGHTER);
                if (moved - p).length() <= distance {
                    moved
                } else {
                    p
                }
            })
        });
        out.push(c, t, scene.area(t), true);
    }
    out
}

/// `translate`: every vertex plus (a, a, a).
pub(super) fn translate(scene: &Scene, a: f64) -> Out {
    let offset = DVec3::splat(a);
    let mut out = Out::default();
    for t in 0..scene.len() {
        out.push(scene.corners(t).map(|p| p + offset), t, scene.area(t), true);
    }
    out
}

/// `twins`: the triangles, then their reversed copies.
pub(super) fn twins(scene: &Scene) -> Out {
    let mut out = Out::default();
    for t in 0..scene.len() {
        out.push(scene.corners(t), t, scene.area(t), true);
    }
    for t in 0..scene.len() {
        let [a, b, c] = scene.corners(t);
        out.push([a, c, b], t, scene.area(t), false);
    }
    out
}
