//! Seeded random streams and the sampling maps shared by the path tracer, the exact direct
//! light and the sealed-face test: uniform points on triangles, cosine-weighted directions,
//! choices by weight.

use std::f64::consts::PI;

use glam::DVec3;

use crate::geometry::Tri;

/// SplitMix64 finalizer: a bijective 64-bit mix.
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A small SplitMix64 generator; one stream per patch (or element), so results do not depend
/// on thread scheduling.
pub struct Rng {
    state: u64,
}

impl Rng {
    /// The stream of patch (or element) `index` under `seed`.
    pub fn new(seed: u64, index: u64) -> Rng {
        Rng {
            state: mix64(seed ^ mix64(index.wrapping_add(0x632b_e59b_d9b4_e019))),
        }
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        mix64(self.state)
    }

    /// Uniform in [0, 1), 53 bits.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in 0..n (n > 0), by rejection (no modulo bias).
    pub fn below(&mut self, n: u64) -> u64 {
        let zone = u64::MAX - u64::MAX % n;
        loop {
            let x = self.next_u64();
            if x < zone {
                return x % n;
            }
        }
    }
}

/// Uniform point on a triangle from (u1, u2) in [0, 1)^2 (continuous map, keeps stratification).
pub fn point_on_triangle(tri: &Tri, u1: f64, u2: f64) -> DVec3 {
    let s = u1.sqrt();
    let b0 = 1.0 - s;
    let b1 = u2 * s;
    let b2 = s - b1;
    tri[0] * b0 + tri[1] * b1 + tri[2] * b2
}

/// Cosine-weighted direction about unit normal `n` from (u1, u2) in [0, 1)^2.
pub fn cosine_direction(n: DVec3, u1: f64, u2: f64) -> DVec3 {
    // Orthonormal basis of Duff et al. (2017).
    let sign = 1.0f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t = DVec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let s = DVec3::new(b, sign + n.y * n.y * a, -n.y);
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let z = (1.0 - u1).max(0.0).sqrt();
    (t * (r * phi.cos()) + s * (r * phi.sin()) + n * z).normalize_or_zero()
}

/// The cumulative distribution of `weights` (not all 0, finite), the last entry exactly 1.
pub fn cumulative(weights: impl Iterator<Item = f64>) -> Vec<f64> {
    let weights: Vec<f64> = weights.collect();
    let total: f64 = weights.iter().sum();
    let mut cdf: Vec<f64> = weights
        .iter()
        .scan(0.0, |acc, w| {
            *acc += w / total;
            Some(*acc)
        })
        .collect();
    if let Some(last) = cdf.last_mut() {
        *last = 1.0;
    }
    cdf
}

/// The entry of `cdf` (from [`cumulative`]) whose interval holds `u` in [0, 1).
pub fn interval_of(cdf: &[f64], u: f64) -> usize {
    cdf.partition_point(|&c| c <= u).min(cdf.len() - 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sampling_maps_stay_in_domain() {
        let tri = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let n = DVec3::new(0.3, -0.5, 0.8).normalize();
        let mut rng = Rng::new(3, 4);
        for _ in 0..1000 {
            let (u1, u2) = (rng.next_f64(), rng.next_f64());
            assert!((0.0..1.0).contains(&u1));
            let p = point_on_triangle(&tri, u1, u2);
            assert!(p.x >= 0.0 && p.y >= 0.0 && p.x + p.y <= 1.0 + 1e-15 && p.z == 0.0);
            let d = cosine_direction(n, u1, u2);
            assert!((d.length() - 1.0).abs() < 1e-12 && d.dot(n) > 0.0);
            assert!(rng.below(7) < 7);
        }
    }
}
