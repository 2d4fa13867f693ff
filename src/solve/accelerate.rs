//! Anderson acceleration of a fixed-point iteration `x = G(x)` (Walker & Ni 2011, "Anderson
//! acceleration for fixed-point iterations"): instead of the plain sweep `x_(k+1) = G(x_k)`, take
//! the combination of the last few sweeps' outputs whose residuals `f = G(x) - x` cancel best.
//! For a linear `G` (the antiradiance sweep) this is a Krylov method: it removes several slowly
//! decaying modes at once, where the tail extrapolation of [`crate::solve::Convergence`] removes
//! one.
//!
//! Vectors are flat `f64` slices with a weight per entry (the inner product is `sum w u v`). The
//! history of differences is kept in f32: the differences are formed in f64 and only then
//! rounded, so their relative precision (1e-7) is far below any solver tolerance, and the
//! history takes half the memory.

use std::collections::VecDeque;

/// Anderson mixing with a history of at most `depth` differences.
#[derive(Clone, Debug)]
pub struct Anderson {
    depth: usize,
    weight: Vec<f64>,
    /// Differences of residuals `f_k - f_(k-1)`, newest last.
    df: VecDeque<Vec<f32>>,
    /// Differences of sweep outputs `G_k - G_(k-1)`, newest last.
    dg: VecDeque<Vec<f32>>,
    /// The previous residual and sweep output.
    f_prev: Option<Vec<f64>>,
    g_prev: Vec<f64>,
}

impl Anderson {
    /// Mixing over vectors of `weight.len()` entries with the given non-negative weights,
    /// remembering at most `depth` (1..=8 useful; 0 means plain sweeps) past differences.
    pub fn new(depth: usize, weight: Vec<f64>) -> Anderson {
        Anderson {
            depth,
            weight,
            df: VecDeque::new(),
            dg: VecDeque::new(),
            f_prev: None,
            g_prev: Vec::new(),
        }
    }

    /// Bytes the history holds at its fullest.
    pub fn bytes(n: usize, depth: usize) -> u64 {
        (n as u64) * (4 * 2 * depth as u64 + 8 * 3)
    }

    /// Forgets the history (the next step is a plain sweep).
    pub fn restart(&mut self) {
        self.df.clear();
        self.dg.clear();
        self.f_prev = None;
    }

    /// The next iterate from the current one `x` and its sweep output `g = G(x)`, written into
    /// `x`. Plain sweep (`x = g`) on the first call, after a restart, or when the least-squares
    /// problem is degenerate.
    ///
    /// # Panics
    /// When `x` and `g` do not have the weights' length.
    pub fn step(&mut self, x: &mut [f64], g: &[f64]) {
        let n = self.weight.len();
        assert!(x.len() == n && g.len() == n, "vector length");
        if self.depth == 0 {
            x.copy_from_slice(g);
            return;
        }
        let f: Vec<f64> = g.iter().zip(x.iter()).map(|(g, x)| g - x).collect();
        if let Some(f_prev) = self.f_prev.take() {
            let df: Vec<f32> = f.iter().zip(&f_prev).map(|(a, b)| (a - b) as f32).collect();
            let dg: Vec<f32> = g
                .iter()
                .zip(&self.g_prev)
                .map(|(a, b)| (a - b) as f32)
                .collect();
            if self.df.len() == self.depth {
                self.df.pop_front();
                self.dg.pop_front();
            }
            self.df.push_back(df);
            self.dg.push_back(dg);
        }
        self.f_prev = Some(f.clone());
        self.g_prev.clear();
        self.g_prev.extend_from_slice(g);
        x.copy_from_slice(g);
        let m = self.df.len();
        if m == 0 {
            return;
        }
        // Normal equations of min |f - dF gamma|_w, with a little Tikhonov regularization.
        let w = &self.weight;
        let dot = |u: &[f32], v: &[f32]| -> f64 {
            u.iter()
                .zip(v)
                .zip(w)
                .map(|((&a, &b), w)| w * a as f64 * b as f64)
                .sum::<f64>()
        };
        let dot_f = |u: &[f32], v: &[f64]| -> f64 {
            u.iter()
                .zip(v)
                .zip(w)
                .map(|((&a, b), w)| w * a as f64 * b)
                .sum::<f64>()
        };
        let mut a = vec![0.0f64; m * m];
        let mut rhs = vec![0.0f64; m];
        for i in 0..m {
            for j in 0..=i {
                let v = dot(&self.df[i], &self.df[j]);
                a[i * m + j] = v;
                a[j * m + i] = v;
            }
            rhs[i] = dot_f(&self.df[i], &f);
        }
        let trace: f64 = (0..m).map(|i| a[i * m + i]).sum();
        if !(trace > 0.0 && trace.is_finite()) {
            self.restart();
            return;
        }
        for i in 0..m {
            a[i * m + i] += 1e-12 * trace;
        }
        let Some(gamma) = solve_small(&mut a, &mut rhs, m) else {
            self.restart();
            return;
        };
        if gamma.iter().any(|g| !g.is_finite() || g.abs() > 1e3) {
            self.restart();
            return;
        }
        for (k, gk) in gamma.iter().enumerate() {
            for (xi, &d) in x.iter_mut().zip(&self.dg[k]) {
                *xi -= gk * d as f64;
            }
        }
    }
}

/// Solves the `m x m` system `a x = b` by Gaussian elimination with partial pivoting; `None`
/// when singular.
fn solve_small(a: &mut [f64], b: &mut [f64], m: usize) -> Option<Vec<f64>> {
    for col in 0..m {
        let pivot = (col..m).max_by(|&i, &j| {
            a[i * m + col]
                .abs()
                .partial_cmp(&a[j * m + col].abs())
                .unwrap_or(std::cmp::Ordering::Equal)
        })?;
        if !(a[pivot * m + col].abs() > 0.0) {
            return None;
        }
        if pivot != col {
            for k in 0..m {
                a.swap(col * m + k, pivot * m + k);
            }
            b.swap(col, pivot);
        }
        for row in col + 1..m {
            let factor = a[row * m + col] / a[col * m + col];
            for k in col..m {
                a[row * m + k] -= factor * a[col * m + k];
            }
            b[row] -= factor * b[col];
        }
    }
    let mut x = vec![0.0; m];
    for row in (0..m).rev() {
        let s: f64 = (row + 1..m).map(|k| a[row * m + k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row * m + row];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A linear fixed point `x = T x + b` with two slow modes: Anderson reaches it in far fewer
    /// steps than plain sweeps, and to the same answer.
    #[test]
    fn anderson_beats_plain_sweeps_on_a_linear_fixed_point() {
        let n = 6;
        // Block-diagonal T: eigenvalues 0.95, 0.9 (slow), and faster ones.
        let t = |x: &[f64]| -> Vec<f64> {
            vec![
                0.95 * x[0] + 0.01 * x[1],
                0.9 * x[1],
                0.5 * x[2] + 0.2 * x[3],
                0.3 * x[3],
                0.1 * x[4],
                0.6 * x[5] + 0.1 * x[0],
            ]
        };
        let b = [1.0, 2.0, 0.5, 1.0, 3.0, 0.2];
        let g = |x: &[f64]| -> Vec<f64> { t(x).iter().zip(&b).map(|(a, b)| a + b).collect() };
        let residual =
            |x: &[f64]| -> f64 { g(x).iter().zip(x).map(|(a, b)| (a - b).abs()).sum::<f64>() };
        let steps_to = |depth: usize| -> (usize, Vec<f64>) {
            let mut acc = Anderson::new(depth, vec![1.0; n]);
            let mut x = vec![0.0; n];
            for k in 1..=2000 {
                let gx = g(&x);
                acc.step(&mut x, &gx);
                if residual(&x) < 1e-10 {
                    return (k, x);
                }
            }
            (usize::MAX, x)
        };
        let (plain, x_plain) = steps_to(0);
        let (anderson, x_anderson) = steps_to(3);
        assert!(plain > 300, "plain sweeps: {plain}");
        assert!(
            anderson * 5 < plain,
            "Anderson: {anderson} steps, plain sweeps: {plain}"
        );
        for (a, b) in x_plain.iter().zip(&x_anderson) {
            assert!((a - b).abs() < 1e-8 * a.abs().max(1.0), "{a} vs {b}");
        }
    }

    #[test]
    fn small_systems_solve_and_singular_ones_do_not() {
        let mut a = vec![2.0, 1.0, 1.0, 3.0];
        let mut b = vec![3.0, 5.0];
        let x = solve_small(&mut a, &mut b, 2).unwrap();
        assert!(
            (x[0] - 0.8).abs() < 1e-12 && (x[1] - 1.4).abs() < 1e-12,
            "{x:?}"
        );
        let mut a = vec![1.0, 2.0, 2.0, 4.0];
        let mut b = vec![1.0, 2.0];
        assert!(solve_small(&mut a, &mut b, 2).is_none());
    }
}
