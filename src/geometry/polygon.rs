//! Triangulation of a scene file's polygons: a convex polygon as a fan from its first corner
//! (what OBJ readers do), a concave one by ear clipping, so that its triangles cover the
//! polygon and nothing outside it.
//!
//! A fan is right only for a convex polygon. Fanned, an L-shaped floor gains a triangle across
//! its notch and a wall with a doorway cut into its outline covers the doorway twice (once
//! with each orientation, which the solver would take as two surfaces), so concave polygons
//! are ear-clipped in the polygon's plane.
//!
//! Also the 2-D tools of a plane that mesh code shares: [`PlaneFrame`] (coordinates in a
//! plane) and [`triangle_overlap_area`] (where two flat triangles overlap).

use glam::{DVec2, DVec3};

use crate::geometry::tolerances::EAR_TOLERANCE;

/// Most corners of a concave polygon that [`triangulate`] ear-clips (the clipping costs up to
/// the square of the corners); a larger one is fanned and counted as not clipped.
pub const MAX_EAR_CLIPPED_CORNERS: usize = 4096;

/// How a polygon was triangulated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Triangulated {
    /// A triangle, or a convex polygon fanned from its first corner.
    Fan,
    /// A concave polygon, ear-clipped.
    EarClipped,
    /// A concave polygon that could not be ear-clipped (it crosses itself, or has more than
    /// [`MAX_EAR_CLIPPED_CORNERS`] corners): fanned from its first corner, so its triangles
    /// may cover area outside it.
    NotSimple,
}

/// The `n - 2` triangles of polygon `corners` (`n >= 3`), as indices into `corners`, each
/// turning the way the polygon does (its front stays its front), and how they were made.
///
/// A polygon whose corners all turn one way in its plane (convex, collinear corners allowed)
/// is fanned from corner 0: `(0, i, i + 1)`. Otherwise its corners are projected on the plane
/// of its Newell normal and ear-clipped: an ear is a corner that turns the polygon's way and
/// whose triangle holds no other remaining corner (corners at the ear's own positions, as the
/// two ends of a seam cut into a hole, do not count). Collinear corners are clipped last.
///
/// # Panics
/// Never; fewer than 3 corners give no triangles.
pub fn triangulate(corners: &[DVec3]) -> (Vec<[usize; 3]>, Triangulated) {
    let n = corners.len();
    let fan = || -> Vec<[usize; 3]> { (1..n.saturating_sub(1)).map(|i| [0, i, i + 1]).collect() };
    if n <= 3 {
        return (fan(), Triangulated::Fan);
    }
    let Some(points) = projected(corners) else {
        return (fan(), Triangulated::Fan);
    };
    let tol = ear_tolerance(&points);
    let turn = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - b);
    if (0..n).all(|i| turn(points[i], points[(i + 1) % n], points[(i + 2) % n]) >= -tol) {
        return (fan(), Triangulated::Fan);
    }
    if n > MAX_EAR_CLIPPED_CORNERS {
        return (fan(), Triangulated::NotSimple);
    }
    match ear_clip(&points) {
        Some(triangles) => (triangles, Triangulated::EarClipped),
        None => (fan(), Triangulated::NotSimple),
    }
}

/// The corners in 2-D coordinates of their plane ([`PlaneFrame`] of the Newell normal, so that
/// the polygon runs counter-clockwise); `None` when the polygon has no area.
fn projected(corners: &[DVec3]) -> Option<Vec<DVec2>> {
    let n = corners.len();
    let origin = corners[0];
    let normal = (0..n).fold(DVec3::ZERO, |acc, i| {
        acc + (corners[i] - origin).cross(corners[(i + 1) % n] - origin)
    });
    let unit = normal.try_normalize()?;
    let frame = PlaneFrame::new(origin, unit);
    Some(corners.iter().map(|&p| frame.flat(p)).collect())
}

/// Area of the intersection of 2-D triangle `a` with the counter-clockwise triangle `b`
/// (Sutherland-Hodgman, on the stack: a triangle clipped by three half-planes has at most 6
/// corners); 0 when `a` runs clockwise.
pub fn triangle_overlap_area(a: &[DVec2; 3], b: &[DVec2; 3]) -> f64 {
    let mut poly = [DVec2::ZERO; 9];
    poly[..3].copy_from_slice(a);
    let mut len = 3;
    for i in 0..3 {
        let (p0, p1) = (b[i], b[(i + 1) % 3]);
        let side = |x: DVec2| (p1 - p0).perp_dot(x - p0);
        let mut out = [DVec2::ZERO; 9];
        let mut n = 0;
        for k in 0..len {
            let (u, v) = (poly[k], poly[(k + 1) % len]);
            let (su, sv) = (side(u), side(v));
            if su >= 0.0 && n < out.len() {
                out[n] = u;
                n += 1;
            }
            if (su >= 0.0) != (sv >= 0.0) && n < out.len() {
                out[n] = u + (v - u) * (su / (su - sv));
                n += 1;
            }
        }
        poly = out;
        len = n;
        if len < 3 {
            return 0.0;
        }
    }
    let mut twice = 0.0;
    for k in 0..len {
        twice += poly[k].perp_dot(poly[(k + 1) % len]);
    }
    (twice * 0.5).max(0.0)
}

/// A frame of the plane through `origin` with unit normal `n`: 2-D coordinates,
/// counter-clockwise seen from the side `n` points to.
pub struct PlaneFrame {
    /// The point of the plane at 2-D coordinates (0, 0).
    pub origin: DVec3,
    u: DVec3,
    v: DVec3,
}

impl PlaneFrame {
    /// The frame of the plane through `origin` with unit normal `n`.
    pub fn new(origin: DVec3, n: DVec3) -> PlaneFrame {
        let across = if n.x.abs() < 0.6 { DVec3::X } else { DVec3::Y };
        let u = across.cross(n).normalize();
        let v = n.cross(u);
        PlaneFrame { origin, u, v }
    }

    /// The 2-D coordinates of `p` (projected on the plane along its normal).
    pub fn flat(&self, p: DVec3) -> DVec2 {
        let d = p - self.origin;
        DVec2::new(d.dot(self.u), d.dot(self.v))
    }
}

/// The tolerance of [`ear_clip`] for `points`: [`EAR_TOLERANCE`] times their largest distance
/// from the origin, squared.
fn ear_tolerance(points: &[DVec2]) -> f64 {
    let scale = points.iter().fold(0.0f64, |m, q| m.max(q.length()));
    EAR_TOLERANCE * scale * scale
}

/// Ear clipping of the simple polygon `points`, given counter-clockwise: `n - 2` triangles as
/// index triples, each counter-clockwise. An ear is a corner turning left (by more than the
/// tolerance, [`EAR_TOLERANCE`] of the polygon's extent squared) whose triangle holds no
/// other remaining corner, on its edges included (corners at the ear's own positions, the two
/// ends of a seam cut into a hole, do not count); the search for the next ear starts where the
/// last one was cut. When only collinear corners are left, they are clipped (triangles of no
/// area). `None` when the polygon turns clockwise or crosses itself (no ear left).
pub fn ear_clip(points: &[DVec2]) -> Option<Vec<[usize; 3]>> {
    let n = points.len();
    let area2: f64 = (0..n)
        .map(|i| points[i].perp_dot(points[(i + 1) % n]))
        .sum();
    if n < 3 || !(area2 > 0.0) {
        return None;
    }
    let tol = ear_tolerance(points);
    let cross =
        |a: usize, b: usize, c: usize| (points[b] - points[a]).perp_dot(points[c] - points[a]);
    let mut ring: Vec<usize> = (0..n).collect();
    let mut triangles = Vec::with_capacity(n - 2);
    let mut from = 0;
    while ring.len() > 3 {
        let m = ring.len();
        let corners = |j: usize| (ring[(j + m - 1) % m], ring[j], ring[(j + 1) % m]);
        let is_ear = |j: usize| {
            let (a, b, c) = corners(j);
            if cross(a, b, c) <= tol {
                return false;
            }
            let (pa, pb, pc) = (points[a], points[b], points[c]);
            ring.iter().all(|&q| {
                let p = points[q];
                q == a
                    || q == b
                    || q == c
                    || p == pa
                    || p == pb
                    || p == pc
                    || cross(a, b, q) < -tol
                    || cross(b, c, q) < -tol
                    || cross(c, a, q) < -tol
            })
        };
        let collinear = |j: usize| {
            let (a, b, c) = corners(j);
            cross(a, b, c).abs() <= tol
        };
        let steps = || (0..m).map(|step| (from + step) % m);
        let ear = steps()
            .find(|&j| is_ear(j))
            .or_else(|| steps().find(|&j| collinear(j)))?;
        let (a, b, c) = corners(ear);
        triangles.push([a, b, c]);
        ring.remove(ear);
        from = ear % ring.len();
    }
    triangles.push([ring[0], ring[1], ring[2]]);
    Some(triangles)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overlap_area_of_two_triangles() {
        let t = [DVec2::ZERO, DVec2::X, DVec2::Y];
        assert!((triangle_overlap_area(&t, &t) - 0.5).abs() < 1e-15);
        let moved = t.map(|v| v + DVec2::new(0.5, 0.0));
        assert!((triangle_overlap_area(&t, &moved) - 0.125).abs() < 1e-15);
        let apart = t.map(|v| v + DVec2::new(2.0, 0.0));
        assert_eq!(triangle_overlap_area(&t, &apart), 0.0);
    }

    fn area(corners: &[DVec3], tris: &[[usize; 3]]) -> (f64, DVec3) {
        let mut total = 0.0;
        let mut normal = DVec3::ZERO;
        for t in tris {
            let n = (corners[t[1]] - corners[t[0]]).cross(corners[t[2]] - corners[t[0]]);
            total += 0.5 * n.length();
            normal += n;
        }
        (total, normal)
    }

    fn xy(points: &[(f64, f64)]) -> Vec<DVec3> {
        points.iter().map(|&(x, y)| DVec3::new(x, y, 0.0)).collect()
    }

    #[test]
    fn a_convex_polygon_is_fanned_from_its_first_corner() {
        let square = xy(&[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]);
        assert_eq!(
            triangulate(&square),
            (vec![[0, 1, 2], [0, 2, 3]], Triangulated::Fan)
        );
        // Collinear corners keep the fan.
        let with_midpoint = xy(&[(0.0, 0.0), (0.5, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]);
        assert_eq!(triangulate(&with_midpoint).1, Triangulated::Fan);
    }

    #[test]
    fn an_l_shaped_polygon_is_ear_clipped_to_its_own_area() {
        // Area 3; the fan from corner 0 = (2, 1) would cover the notch.
        let l = xy(&[
            (2.0, 1.0),
            (1.0, 1.0),
            (1.0, 2.0),
            (0.0, 2.0),
            (0.0, 0.0),
            (2.0, 0.0),
        ]);
        let (tris, how) = triangulate(&l);
        assert_eq!(how, Triangulated::EarClipped);
        assert_eq!(tris.len(), 4);
        let (a, n) = area(&l, &tris);
        assert!((a - 3.0).abs() < 1e-12, "area {a}");
        // Every triangle faces the polygon's way (+z: counter-clockwise in x, y).
        assert!((n.z - 6.0).abs() < 1e-12 && n.z > 0.0);
        let (fan_area, _) = area(&l, &(1..5).map(|i| [0, i, i + 1]).collect::<Vec<_>>());
        assert!(fan_area > 3.0 + 1e-9, "the fan would have been {fan_area}");
    }

    #[test]
    fn a_clockwise_concave_polygon_keeps_its_orientation_in_any_plane() {
        // The L above, reversed (facing -z), then stood up in the y-z plane facing -x.
        let l: Vec<DVec3> = [
            (2.0, 1.0),
            (1.0, 1.0),
            (1.0, 2.0),
            (0.0, 2.0),
            (0.0, 0.0),
            (2.0, 0.0),
        ]
        .iter()
        .rev()
        .map(|&(u, v)| DVec3::new(0.3, u, v))
        .collect();
        let (tris, how) = triangulate(&l);
        assert_eq!(how, Triangulated::EarClipped);
        let (a, n) = area(&l, &tris);
        assert!((a - 3.0).abs() < 1e-12);
        let newell = (0..l.len()).fold(DVec3::ZERO, |acc, i| {
            acc + (l[i] - l[0]).cross(l[(i + 1) % l.len()] - l[0])
        });
        assert!(n.dot(newell) > 0.0 && (n.length() - newell.length()).abs() < 1e-12);
    }

    #[test]
    fn a_wall_with_a_doorway_cut_along_a_seam_is_clipped_around_the_hole() {
        // A 4 x 3 wall with a 1 x 1 hole, the hole joined to the outline by a seam
        // (the seam's two corners repeat positions): area 12 - 1 = 11.
        let wall = xy(&[
            (0.0, 0.0),
            (4.0, 0.0),
            (4.0, 3.0),
            (2.0, 3.0),
            (2.0, 2.0),
            (2.5, 2.0),
            (2.5, 1.0),
            (1.5, 1.0),
            (1.5, 2.0),
            (2.0, 2.0),
            (2.0, 3.0),
            (0.0, 3.0),
        ]);
        assert_ear_clipped_to(&wall, 11.0);
    }

    /// Asserts that `polygon` is ear-clipped into `n - 2` triangles of total area `expected`.
    fn assert_ear_clipped_to(polygon: &[DVec3], expected: f64) {
        let (tris, how) = triangulate(polygon);
        assert_eq!(how, Triangulated::EarClipped);
        assert_eq!(tris.len(), polygon.len() - 2);
        let (a, _) = area(polygon, &tris);
        assert!((a - expected).abs() < 1e-9, "area {a}, expected {expected}");
    }

    #[test]
    fn a_comb_of_many_teeth_is_clipped_exactly() {
        // 50 teeth of width 1 and height 2 on a 100 x 1 base: area 100 + 50 * 2.
        let mut points = vec![(0.0, 0.0), (100.0, 0.0)];
        for t in (0..50).rev() {
            let x = 2.0 * t as f64;
            points.extend([(x + 2.0, 1.0), (x + 1.0, 1.0), (x + 1.0, 3.0), (x, 3.0)]);
        }
        points.dedup();
        assert_ear_clipped_to(&xy(&points), 200.0);
    }

    #[test]
    fn a_polygon_that_crosses_itself_still_gives_its_triangle_count() {
        let bowtie = xy(&[(0.0, 0.0), (2.0, 2.0), (2.0, 0.0), (0.0, 1.0)]);
        assert_eq!(triangulate(&bowtie).0.len(), 2);
    }

    #[test]
    fn a_concave_polygon_of_too_many_corners_is_fanned_and_flagged() {
        // A star: corners alternately at radius 1 and 0.5.
        let n = MAX_EAR_CLIPPED_CORNERS + 2;
        let star: Vec<DVec3> = (0..n)
            .map(|i| {
                let (s, c) = (std::f64::consts::TAU * i as f64 / n as f64).sin_cos();
                let r = if i % 2 == 0 { 1.0 } else { 0.5 };
                DVec3::new(r * c, r * s, 0.0)
            })
            .collect();
        let (tris, how) = triangulate(&star);
        assert_eq!((tris.len(), how), (n - 2, Triangulated::NotSimple));
    }

    #[test]
    fn a_polygon_without_area_is_fanned() {
        let line = xy(&[(0.0, 0.0), (1.0, 0.0), (2.0, 0.0), (3.0, 0.0)]);
        assert_eq!(
            triangulate(&line),
            (vec![[0, 1, 2], [0, 2, 3]], Triangulated::Fan)
        );
    }
}
