//! The CAD-like polygon builder of the interiors: planar polygons fan-triangulated from their
//! first vertex, a share of them reversed, boxes, cylinders and big wall rectangles.

use std::path::PathBuf;

use glam::DVec3;

use super::{cos_sin_turn, v, Interior, REVERSED_SHARE};
use crate::geometry::sampling::Rng;
use crate::scene::Scene;

/// A material: name, albedo (`Kd`), emitted radiance (`Ke`).
pub(super) type Material = (&'static str, [f64; 3], [f64; 3]);

/// Collects polygons, triangulates them as an exporter does and builds the scene.
pub(super) struct Cad {
    pub(super) tris: Vec<[DVec3; 3]>,
    pub(super) material: Vec<u32>,
    pub(super) reversed: Vec<bool>,
    pub(super) materials: Vec<Material>,
    pub(super) rng: Rng,
    pub(super) polygons: usize,
    pub(super) reversed_polygons: usize,
}

impl Cad {
    pub(super) fn new(seed: u64) -> Cad {
        Cad {
            tris: Vec::new(),
            material: Vec::new(),
            reversed: Vec::new(),
            materials: Vec::new(),
            rng: Rng::new(seed, 0x1_a7e0_fcad),
            polygons: 0,
            reversed_polygons: 0,
        }
    }

    /// The index of material `m`, added on first use.
    pub(super) fn mat(&mut self, m: Material) -> u32 {
        match self.materials.iter().position(|x| x.0 == m.0) {
            Some(i) => i as u32,
            None => {
                self.materials.push(m);
                (self.materials.len() - 1) as u32
            }
        }
    }

    /// Adds a planar polygon (vertices in order around it) whose surface faces `facing`,
    /// fan-triangulated from its first vertex. The vertex order is reversed (the first vertex
    /// kept) so that the front faces `facing`, and then once more for a share
    /// [`REVERSED_SHARE`] of the non-emitting polygons. The fan must be valid: every other
    /// vertex visible from the first, none on an edge next to it.
    pub(super) fn polygon(&mut self, pts: &[DVec3], facing: DVec3, m: Material) {
        let m = self.mat(m);
        let mut p: Vec<DVec3> = pts.to_vec();
        let mut n = DVec3::ZERO;
        for i in 1..p.len() - 1 {
            n += (p[i] - p[0]).cross(p[i + 1] - p[0]);
        }
        if n.dot(facing) < 0.0 {
            p[1..].reverse();
        }
        let emits = self.materials[m as usize].2.iter().any(|&e| e > 0.0);
        let draw = self.rng.next_f64();
        let reverse = !emits && draw < REVERSED_SHARE;
        if reverse {
            p[1..].reverse();
            self.reversed_polygons += 1;
        }
        self.polygons += 1;
        for i in 1..p.len() - 1 {
            self.tris.push([p[0], p[i], p[i + 1]]);
            self.material.push(m);
            self.reversed.push(reverse);
        }
    }

    /// An axis-aligned box from `lo` to `hi`, six faces facing outward.
    pub(super) fn block(&mut self, lo: DVec3, hi: DVec3, m: Material) {
        let c = (lo + hi) * 0.5;
        let h = (hi - lo) * 0.5;
        self.slab(c, [v(h.x, 0.0, 0.0), v(0.0, h.y, 0.0), v(0.0, 0.0, h.z)], m);
    }

    /// A box centred at `c` with half-extent vectors `a` (three orthogonal), faces outward.
    pub(super) fn slab(&mut self, c: DVec3, a: [DVec3; 3], m: Material) {
        for axis in 0..3 {
            let (d, e, f) = (a[axis], a[(axis + 1) % 3], a[(axis + 2) % 3]);
            for sign in [1.0, -1.0] {
                let centre = c + d * sign;
                self.polygon(
                    &[
                        centre - e - f,
                        centre + e - f,
                        centre + e + f,
                        centre - e + f,
                    ],
                    d * sign,
                    m,
                );
            }
        }
    }

    /// A cylinder along coordinate axis `axis` (0, 1, 2) from `base` for `length`, of `sides`
    /// side quads facing outward, with end caps (n-gons, fanned) when `caps`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn cylinder(
        &mut self,
        axis: usize,
        base: DVec3,
        length: f64,
        radius: f64,
        sides: usize,
        caps: bool,
        m: Material,
    ) {
        let mut e = [DVec3::ZERO; 3];
        for (k, e) in e.iter_mut().enumerate() {
            e[(axis + k) % 3] = 1.0;
        }
        let (along, e1, e2) = (e[0], e[1], e[2]);
        let ring: Vec<DVec3> = (0..sides)
            .map(|i| {
                let (c, s) = cos_sin_turn(i, sides);
                (e1 * c + e2 * s) * radius
            })
            .collect();
        let top = base + along * length;
        for i in 0..sides {
            let (a, b) = (ring[i], ring[(i + 1) % sides]);
            self.polygon(&[base + a, base + b, top + b, top + a], a + b, m);
        }
        if caps {
            let bottom: Vec<DVec3> = ring.iter().map(|&r| base + r).collect();
            let upper: Vec<DVec3> = ring.iter().map(|&r| top + r).collect();
            self.polygon(&bottom, -along, m);
            self.polygon(&upper, along, m);
        }
    }

    /// The open side of a cylinder facing inward (its inside), for lamp shades.
    pub(super) fn cylinder_inside(
        &mut self,
        base: DVec3,
        length: f64,
        radius: f64,
        sides: usize,
        m: Material,
    ) {
        let top = base + v(0.0, length, 0.0);
        for i in 0..sides {
            let (c0, s0) = cos_sin_turn(i, sides);
            let (c1, s1) = cos_sin_turn(i + 1, sides);
            let (a, b) = (v(s0, 0.0, c0) * radius, v(s1, 0.0, c1) * radius);
            self.polygon(&[base + a, base + b, top + b, top + a], -(a + b), m);
        }
    }

    /// A wall, floor or ceiling rectangle as one polygon: corners `a`, `b`, `c`, `d` in order
    /// around it, with `extra` more vertices spread over each of the two edges away from `a`
    /// (`b`-`c` and `c`-`d`, at uneven spacing), so its fan from `a` is a spray of slivers.
    pub(super) fn big_rectangle(
        &mut self,
        [a, b, c, d]: [DVec3; 4],
        extra: usize,
        facing: DVec3,
        m: Material,
    ) {
        let mut pts = vec![a, b];
        let spread = |i: usize| {
            // Uneven but fixed: the squares of i / (extra + 1), pulled towards even spacing.
            let t = i as f64 / (extra + 1) as f64;
            0.5 * (t + t * t)
        };
        for i in 1..=extra {
            pts.push(b + (c - b) * spread(i));
        }
        pts.push(c);
        for i in 1..=extra {
            pts.push(c + (d - c) * spread(i));
        }
        pts.push(d);
        self.polygon(&pts, facing, m);
    }

    pub(super) fn build(self) -> Interior {
        let mut scene = Scene {
            material_names: self.materials.iter().map(|m| m.0.to_string()).collect(),
            path: PathBuf::new(),
            ..Scene::default()
        };
        for (t, tri) in self.tris.iter().enumerate() {
            let base = scene.positions.len() as u32;
            scene.positions.extend_from_slice(tri);
            scene.triangles.push([base, base + 1, base + 2]);
            let (_, kd, ke) = self.materials[self.material[t] as usize];
            scene.albedo.push(kd);
            scene.emission.push(ke);
            scene.material.push(Some(self.material[t]));
        }
        Interior {
            scene,
            polygons: self.polygons,
            reversed_polygons: self.reversed_polygons,
            reversed: self.reversed,
        }
    }
}
