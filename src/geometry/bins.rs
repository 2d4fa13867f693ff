//! Direction bins: an octahedral map of R x R cells partitioning the sphere, each cell's solid
//! angle known. A bin is indexed by the direction of travel `w` of the light it holds.

use glam::{DVec2, DVec3};

/// Octahedral direction bins over the whole sphere.
#[derive(Clone, Debug)]
pub struct Bins {
    /// Cells per side of the octahedral square; R * R bins in all.
    pub res: usize,
    /// Solid angle of each bin, sr; sums to 4 pi.
    pub solid_angle: Vec<f64>,
    /// Unit direction at each bin's centre.
    pub center: Vec<DVec3>,
    /// Largest bin solid angle, sr.
    pub max_solid_angle: f64,
    /// Smallest bin solid angle, sr.
    pub min_solid_angle: f64,
}

/// Maps a unit direction to the octahedral square [-1, 1]^2.
pub fn oct_encode(w: DVec3) -> DVec2 {
    let l1 = w.x.abs() + w.y.abs() + w.z.abs();
    if !(l1 > 0.0) {
        return DVec2::ZERO;
    }
    let p = DVec2::new(w.x / l1, w.y / l1);
    if w.z >= 0.0 {
        p
    } else {
        DVec2::new(
            (1.0 - p.y.abs()) * p.x.signum(),
            (1.0 - p.x.abs()) * p.y.signum(),
        )
    }
}

/// Maps a point of the octahedral square [-1, 1]^2 back to a unit direction.
pub fn oct_decode(p: DVec2) -> DVec3 {
    let z = 1.0 - p.x.abs() - p.y.abs();
    let (x, y) = if z >= 0.0 {
        (p.x, p.y)
    } else {
        (
            (1.0 - p.y.abs()) * p.x.signum(),
            (1.0 - p.x.abs()) * p.y.signum(),
        )
    };
    DVec3::new(x, y, z).normalize()
}

fn spherical_triangle_area(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let num = a.dot(b.cross(c)).abs();
    let den = 1.0 + a.dot(b) + a.dot(c) + b.dot(c);
    2.0 * num.atan2(den)
}

impl Bins {
    /// Builds an R x R octahedral layout. `res` in 1..=64; 8 (64 bins) is the default.
    ///
    /// # Panics
    /// If `res` is 0.
    pub fn new(res: usize) -> Bins {
        assert!(res > 0, "bin resolution must be positive");
        let n = res * res;
        let mut solid_angle = vec![0.0; n];
        let mut center = vec![DVec3::Z; n];
        // Each cell is split into s x s sub-cells, each into two triangles whose corners are mapped
        // to the sphere; their exact spherical areas sum to the cell's solid angle (up to the
        // sub-cells that straddle the octahedron's fold, which are tiny).
        let s = (64 / res).max(4);
        let cell = 2.0 / res as f64;
        let sub = cell / s as f64;
        for iy in 0..res {
            for ix in 0..res {
                let d = iy * res + ix;
                let x0 = -1.0 + ix as f64 * cell;
                let y0 = -1.0 + iy as f64 * cell;
                center[d] = oct_decode(DVec2::new(x0 + 0.5 * cell, y0 + 0.5 * cell));
                let mut total = 0.0;
                for sy in 0..s {
                    for sx in 0..s {
                        let u0 = x0 + sx as f64 * sub;
                        let v0 = y0 + sy as f64 * sub;
                        let p00 = oct_decode(DVec2::new(u0, v0));
                        let p10 = oct_decode(DVec2::new(u0 + sub, v0));
                        let p01 = oct_decode(DVec2::new(u0, v0 + sub));
                        let p11 = oct_decode(DVec2::new(u0 + sub, v0 + sub));
                        total += spherical_triangle_area(p00, p10, p11);
                        total += spherical_triangle_area(p00, p11, p01);
                    }
                }
                solid_angle[d] = total;
            }
        }
        let sum: f64 = solid_angle.iter().sum();
        let norm = 4.0 * std::f64::consts::PI / sum;
        for w in &mut solid_angle {
            *w *= norm;
        }
        let max_solid_angle = solid_angle.iter().cloned().fold(0.0, f64::max);
        let min_solid_angle = solid_angle.iter().cloned().fold(f64::INFINITY, f64::min);
        Bins {
            res,
            solid_angle,
            center,
            max_solid_angle,
            min_solid_angle,
        }
    }

    /// Number of bins (R * R).
    pub fn len(&self) -> usize {
        self.res * self.res
    }

    /// Always false: a layout has at least one bin.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The bin holding light that travels along `w` (any length; zero maps to a fixed bin).
    pub fn bin_of(&self, w: DVec3) -> usize {
        let p = oct_encode(w);
        let r = self.res as f64;
        let ix = (((p.x + 1.0) * 0.5 * r) as usize).min(self.res - 1);
        let iy = (((p.y + 1.0) * 0.5 * r) as usize).min(self.res - 1);
        iy * self.res + ix
    }

    /// Mean bin solid angle, 4 pi / (R * R).
    pub fn mean_solid_angle(&self) -> f64 {
        4.0 * std::f64::consts::PI / self.len() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encode_decode_roundtrip() {
        for i in 0..200 {
            let t = i as f64 * 0.731;
            let w =
                DVec3::new(t.sin() * (t * 0.3).cos(), (t * 1.7).cos(), (t * 0.9).sin()).normalize();
            let back = oct_decode(oct_encode(w));
            assert!((back - w).length() < 1e-9, "{w} -> {back}");
        }
    }

    #[test]
    fn solid_angles_partition_sphere() {
        for res in [2, 4, 8, 16] {
            let bins = Bins::new(res);
            // Monte Carlo check: the fraction of uniform directions landing in each bin matches.
            let mut counts = vec![0usize; bins.len()];
            let n = 400_000;
            let mut state = 12345u64;
            let mut rnd = || {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (state >> 11) as f64 / (1u64 << 53) as f64
            };
            for _ in 0..n {
                let z = 1.0 - 2.0 * rnd();
                let phi = 2.0 * std::f64::consts::PI * rnd();
                let r = (1.0 - z * z).sqrt();
                counts[bins.bin_of(DVec3::new(r * phi.cos(), r * phi.sin(), z))] += 1;
            }
            for (d, &count) in counts.iter().enumerate() {
                let expect = bins.solid_angle[d] / (4.0 * std::f64::consts::PI);
                let got = count as f64 / n as f64;
                let sigma = (expect / n as f64).sqrt();
                assert!(
                    (got - expect).abs() < 5.0 * sigma + 1e-4,
                    "res {res} bin {d}: {got} vs {expect}"
                );
            }
            assert!(bins.max_solid_angle / bins.min_solid_angle < 4.0);
        }
    }
}
