//! The huge-tiny variant: a flat region re-triangulated from its outline (few huge triangles)
//! beside an object split into many tiny ones, and the region-merging it needs.

use super::*;
use crate::error::{Error, Result};
use crate::scene::Scene;
use glam::{DVec2, DVec3};
use std::collections::HashMap;

use crate::geometry::polygon::PlaneFrame;
use crate::geometry::tolerances::{
    VARIANT_AREA_MATCH, VARIANT_COLLINEAR, VARIANT_OVERLAP, VARIANT_PLANE, VARIANT_SAME_NORMAL,
};
use crate::union_find::UnionFind;

/// The same material: index, albedo and emission bit for bit.
pub(super) fn same_material(scene: &Scene, a: usize, b: usize) -> bool {
    material_of(scene, a) == material_of(scene, b)
        && scene.albedo[a].map(f64::to_bits) == scene.albedo[b].map(f64::to_bits)
        && scene.emission[a].map(f64::to_bits) == scene.emission[b].map(f64::to_bits)
}

pub(super) fn unit_normal(c: &[DVec3; 3]) -> DVec3 {
    (c[1] - c[0]).cross(c[2] - c[0]).normalize_or_zero()
}

/// A flat region re-triangulated from its outline: the new triangles (3D, counter-clockwise
/// seen from the front) and, for each, the 2D coordinates of its corners in the region's plane.
pub(super) struct Merged {
    pub(super) tris: Vec<[DVec3; 3]>,
    pub(super) flat: Vec<[DVec2; 3]>,
}

pub(super) fn flat_area(t: &[DVec2; 3]) -> f64 {
    0.5 * (t[1] - t[0]).perp_dot(t[2] - t[0])
}

/// Tries to re-triangulate `region` (triangles of one plane) from its outline: one boundary
/// loop, exactly collinear outline vertices dropped, ear clipping. `None` when the region is
/// not a simple polygon (holes, touching loops, inconsistent orientation) or the new
/// triangles do not cover exactly its area.
pub(super) fn merge_region(scene: &Scene, region: &[usize], frame: &PlaneFrame) -> Option<Merged> {
    let mut directed: HashMap<EdgeKey, usize> = HashMap::new();
    let mut position: HashMap<[u64; 3], DVec3> = HashMap::new();
    for &t in region {
        let c = scene.corners(t);
        for e in 0..3 {
            let (a, b) = (c[e], c[(e + 1) % 3]);
            position.insert(point_key(a), a);
            *directed.entry((point_key(a), point_key(b))).or_default() += 1;
        }
    }
    if directed.values().any(|&n| n > 1) {
        return None;
    }
    let mut next: HashMap<[u64; 3], [u64; 3]> = HashMap::new();
    let mut start = None;
    for &t in region {
        let c = scene.corners(t);
        for e in 0..3 {
            let (a, b) = (point_key(c[e]), point_key(c[(e + 1) % 3]));
            if !directed.contains_key(&(b, a)) {
                if next.insert(a, b).is_some() {
                    return None;
                }
                start.get_or_insert(a);
            }
        }
    }
    let start = start?;
    let mut outline = vec![start];
    let mut at = start;
    loop {
        at = *next.get(&at)?;
        if at == start {
            break;
        }
        outline.push(at);
        if outline.len() > next.len() {
            return None;
        }
    }
    if outline.len() != next.len() || outline.len() > 4000 {
        return None;
    }
    let mut points: Vec<DVec3> = outline.iter().map(|k| position[k]).collect();
    // Drop outline vertices exactly on the line through their neighbours (to rounding).
    let mut changed = true;
    while changed && points.len() > 3 {
        changed = false;
        let m = points.len();
        for i in 0..m {
            let (a, b, c) = (points[(i + m - 1) % m], points[i], points[(i + 1) % m]);
            let (d1, d2) = (b - a, c - b);
            if d1.cross(d2).length() <= VARIANT_COLLINEAR * d1.length() * d2.length()
                && d1.dot(d2) > 0.0
            {
                points.remove(i);
                changed = true;
                break;
            }
        }
    }
    let flat: Vec<DVec2> = points.iter().map(|&p| frame.flat(p)).collect();
    let ears = crate::geometry::polygon::ear_clip(&flat)?;
    let merged = Merged {
        tris: ears.iter().map(|e| e.map(|i| points[i])).collect(),
        flat: ears.iter().map(|e| e.map(|i| flat[i])).collect(),
    };
    let region_area: f64 = region
        .iter()
        .map(|&t| flat_area(&scene.corners(t).map(|p| frame.flat(p))))
        .sum();
    let merged_area: f64 = merged.flat.iter().map(flat_area).sum();
    let all_positive = merged.flat.iter().all(|t| flat_area(t) > 0.0);
    (all_positive && (merged_area - region_area).abs() <= VARIANT_AREA_MATCH * region_area)
        .then_some(merged)
}

/// `huge-tiny`: the largest flat region merged, the object nearest to it split into at least
/// `tiny` triangles.
pub(super) fn huge_tiny(scene: &Scene, tiny: usize) -> Result<(Out, String)> {
    let n = scene.len();
    let (lo, hi) = scene.bounds();
    let diameter = (hi - lo).length();
    let tol = VARIANT_PLANE * diameter;
    let normals: Vec<DVec3> = (0..n).map(|t| unit_normal(&scene.corners(t))).collect();
    let live: Vec<bool> = (0..n).map(|t| !scene.is_degenerate(t)).collect();

    let regions = flat_regions(scene, &normals, &live, tol);
    let huge = choose_region(scene, &regions, &normals, &live, tol)?;
    let in_region: Vec<bool> = {
        let mut v = vec![false; n];
        for &t in &huge.region {
            v[t] = true;
        }
        v
    };
    let nearest = nearest_object(scene, &live, &in_region, &huge, tol);
    let (object, k) = match nearest {
        Some(o) => {
            let k = ((tiny as f64 / o.len() as f64).sqrt().ceil() as usize).max(2);
            (o, k)
        }
        None => (Vec::new(), 1),
    };
    let in_object: HashMap<usize, usize> =
        object.iter().enumerate().map(|(i, &t)| (t, i)).collect();
    let pieces = if object.is_empty() {
        Scene::default()
    } else {
        let corners: Vec<[DVec3; 3]> = object.iter().map(|&t| scene.corners(t)).collect();
        let zero = vec![[0.0; 3]; object.len()];
        crate::scene::generated::subdivide(&Scene::from_triangles(&corners, &zero, &zero), k)
    };
    let rows = merged_rows(scene, &huge);

    let mut out = Out::default();
    let mut region_done = false;
    for (t, &in_region) in in_region.iter().enumerate() {
        if in_region {
            if !region_done {
                region_done = true;
                for (m, tri) in huge.merged.tris.iter().enumerate() {
                    let v = out.tris.len() as u32;
                    let source = rows[m].first().map(|r| r.0).unwrap_or(t);
                    out.tris.push(*tri);
                    out.source.push(source as u32);
                    for &(original, area) in &rows[m] {
                        out.rows.push(MapRow {
                            variant: v,
                            original: original as u32,
                            area,
                            same_side: true,
                        });
                    }
                }
            }
        } else if let Some(&i) = in_object.get(&t) {
            for p in i * k * k..(i + 1) * k * k {
                out.piece(pieces.corners(p), t);
            }
        } else {
            out.push(scene.corners(t), t, scene.area(t), true);
        }
    }
    let note = format!(
        "huge-tiny: a flat region of {} triangles (area {}) as {} triangles, an object of {} triangles as {} (k = {k})",
        huge.region.len(),
        huge.area,
        huge.merged.tris.len(),
        object.len(),
        object.len() * k * k
    );
    Ok((out, note))
}

/// The flat regions of a scene: edge neighbours in the same plane (within `tol`), of the same
/// material, with opposite edge directions; reflecting regions first (the huge triangle should
/// receive light), then by area, largest first.
fn flat_regions(scene: &Scene, normals: &[DVec3], live: &[bool], tol: f64) -> Vec<Vec<usize>> {
    let n = scene.len();
    let edges = Edges::of(scene, true);
    let mut sets = UnionFind::new(n);
    for k in &edges.order {
        let sides = &edges.on[k];
        if sides.len() != 2 {
            continue;
        }
        let ((t1, e1), (t2, e2)) = (sides[0], sides[1]);
        let (c1, c2) = (scene.corners(t1), scene.corners(t2));
        let opposite = point_key(c1[e1]) == point_key(c2[(e2 + 1) % 3]);
        let far = c2[(e2 + 2) % 3];
        if opposite
            && same_material(scene, t1, t2)
            && normals[t1].dot(normals[t2]) >= 1.0 - VARIANT_SAME_NORMAL
            && (far - c1[0]).dot(normals[t1]).abs() <= tol
        {
            sets.union(t1, t2);
        }
    }
    let mut regions = sets.groups((0..n).filter(|&t| live[t]));
    let region_area = |r: &Vec<usize>| r.iter().map(|&t| scene.area(t)).sum::<f64>();
    let emits = |r: &Vec<usize>| scene.is_emitter(r[0]);
    regions.sort_by(|a, b| {
        emits(a)
            .cmp(&emits(b))
            .then(region_area(b).total_cmp(&region_area(a)))
    });
    regions
}

/// The flat region that becomes huge triangles: its triangles, plane, merged triangulation
/// and area.
struct HugeRegion {
    region: Vec<usize>,
    frame: PlaneFrame,
    normal: DVec3,
    merged: Merged,
    area: f64,
}

/// The first of the 50 first `regions` that is flat within `tol` and merges into a simple
/// polygon; when none does (every large region has holes), the largest triangle by itself.
fn choose_region(
    scene: &Scene,
    regions: &[Vec<usize>],
    normals: &[DVec3],
    live: &[bool],
    tol: f64,
) -> Result<HugeRegion> {
    for region in regions.iter().take(50) {
        let area = region.iter().map(|&t| scene.area(t)).sum::<f64>();
        let normal = region
            .iter()
            .map(|&t| normals[t] * scene.area(t))
            .sum::<DVec3>()
            .normalize_or_zero();
        let origin = scene.corners(region[0])[0];
        let flat_enough = region.iter().all(|&t| {
            scene
                .corners(t)
                .iter()
                .all(|p| (*p - origin).dot(normal).abs() <= tol)
        });
        if normal == DVec3::ZERO || !flat_enough {
            continue;
        }
        let frame = PlaneFrame::new(origin, normal);
        if let Some(merged) = merge_region(scene, region, &frame) {
            return Ok(HugeRegion {
                region: region.clone(),
                frame,
                normal,
                merged,
                area,
            });
        }
    }
    let t = (0..scene.len())
        .filter(|&t| live[t])
        .max_by(|&a, &b| scene.area(a).total_cmp(&scene.area(b)))
        .ok_or_else(|| Error::Parameter("variant: every triangle is degenerate".into()))?;
    let c = scene.corners(t);
    let frame = PlaneFrame::new(c[0], normals[t]);
    let merged = Merged {
        tris: vec![c],
        flat: vec![c.map(|p| frame.flat(p))],
    };
    Ok(HugeRegion {
        region: vec![t],
        frame,
        normal: normals[t],
        merged,
        area: scene.area(t),
    })
}

/// The object to split into tiny triangles: of the objects (the triangles outside the region,
/// connected through shared vertices) at most half the region's size, if there are any (else
/// all), the nearest to the region's plane (touching, within `tol`, counts as 0), then the
/// smallest by area.
fn nearest_object(
    scene: &Scene,
    live: &[bool],
    in_region: &[bool],
    huge: &HugeRegion,
    tol: f64,
) -> Option<Vec<usize>> {
    let n = scene.len();
    let mut by_vertex: HashMap<[u64; 3], usize> = HashMap::new();
    let mut objects = UnionFind::new(n);
    for t in (0..n).filter(|&t| live[t] && !in_region[t]) {
        for p in scene.corners(t) {
            let first = *by_vertex.entry(point_key(p)).or_insert(t);
            objects.union(first, t);
        }
    }
    let objects = objects.groups((0..n).filter(|&t| live[t] && !in_region[t]));
    let extent = |tris: &[usize]| {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for p in tris.iter().flat_map(|&t| scene.corners(t)) {
            lo = lo.min(p);
            hi = hi.max(p);
        }
        (hi - lo).length()
    };
    let region_extent = extent(&huge.region);
    let small: Vec<&Vec<usize>> = objects
        .iter()
        .filter(|o| extent(o) <= 0.5 * region_extent)
        .collect();
    let candidates = if small.is_empty() {
        objects.iter().collect()
    } else {
        small
    };
    let rank = |o: &Vec<usize>| {
        let d = o
            .iter()
            .flat_map(|&t| scene.corners(t))
            .map(|p| (p - huge.frame.origin).dot(huge.normal).abs())
            .fold(f64::INFINITY, f64::min);
        let d = if d <= tol { 0.0 } else { d };
        (d, o.iter().map(|&t| scene.area(t)).sum::<f64>())
    };
    candidates
        .into_iter()
        .min_by(|a, b| {
            let (ra, rb) = (rank(a), rank(b));
            ra.0.total_cmp(&rb.0).then(ra.1.total_cmp(&rb.1))
        })
        .cloned()
}

/// Per merged triangle, which original triangles of the region it covers and how much: the
/// 2D overlaps in the plane, scaled so that each original's rows sum to its own area.
fn merged_rows(scene: &Scene, huge: &HugeRegion) -> Vec<Vec<(usize, f64)>> {
    let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); huge.merged.tris.len()];
    for &t in &huge.region {
        let flat = scene.corners(t).map(|p| huge.frame.flat(p));
        let (fmin, fmax) = (
            flat[0].min(flat[1]).min(flat[2]),
            flat[0].max(flat[1]).max(flat[2]),
        );
        let mut overlaps: Vec<(usize, f64)> = Vec::new();
        for (m, tri) in huge.merged.flat.iter().enumerate() {
            let (tmin, tmax) = (
                tri[0].min(tri[1]).min(tri[2]),
                tri[0].max(tri[1]).max(tri[2]),
            );
            if tmin.x > fmax.x || tmin.y > fmax.y || tmax.x < fmin.x || tmax.y < fmin.y {
                continue;
            }
            let a = crate::geometry::polygon::triangle_overlap_area(&flat, tri);
            if a > VARIANT_OVERLAP * flat_area(&flat).abs() {
                overlaps.push((m, a));
            }
        }
        let total: f64 = overlaps.iter().map(|o| o.1).sum();
        for (m, a) in overlaps {
            rows[m].push((t, a * scene.area(t) / total));
        }
    }
    rows
}
