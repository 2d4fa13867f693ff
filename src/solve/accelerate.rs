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

use crate::geometry::tolerances::ANDERSON_REGULARIZATION;
use rayon::prelude::*;

/// Entries per parallel piece of the inner products (fixed, so the sums are formed in the same
/// order whatever the thread count: results do not depend on scheduling).
const CHUNK: usize = 1 << 14;

/// Anderson mixing with a history of at most `depth` differences.
#[derive(Clone, Debug)]
pub struct Anderson {
    depth: usize,
    weight: Vec<f64>,
    /// Differences of residuals `f_k - f_(k-1)`, newest last, each pair scaled so that its
    /// residual difference has unit norm (the mixing is scale free; a history kept from another
    /// solve, whose differences were much smaller, stays usable).
    df: VecDeque<Vec<f32>>,
    /// Differences of sweep outputs `G_k - G_(k-1)`, scaled as their `df`.
    dg: VecDeque<Vec<f32>>,
    /// Inner products of the stored `df`, row by row (`gram[i][j] = <df_i, df_j>`).
    gram: VecDeque<Vec<f64>>,
    /// The previous residual (`None` on the first step and after [`Anderson::new_source`]) and
    /// sweep output.
    f_prev: Option<Vec<f64>>,
    g_prev: Vec<f64>,
    /// The current residual (scratch).
    f: Vec<f64>,
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
            gram: VecDeque::new(),
            f_prev: None,
            g_prev: Vec::new(),
            f: Vec::new(),
        }
    }

    /// Bytes the history holds at its fullest: two f32 differences per remembered sweep and
    /// four f64 vectors (weights, residual, previous residual, previous output).
    pub fn bytes(n: usize, depth: usize) -> u64 {
        (n as u64) * (4 * 2 * depth as u64 + 8 * 4)
    }

    /// Entries of the vectors it mixes.
    pub fn len(&self) -> usize {
        self.weight.len()
    }

    /// True when it mixes vectors of no entries.
    pub fn is_empty(&self) -> bool {
        self.weight.is_empty()
    }

    /// Differences currently remembered.
    pub fn history(&self) -> usize {
        self.df.len()
    }

    /// Forgets the history (the next step is a plain sweep).
    pub fn restart(&mut self) {
        self.df.clear();
        self.dg.clear();
        self.gram.clear();
        self.f_prev = None;
    }

    /// Goes on with the iteration of another constant term, `G'(x) = G(x) + c` (the same linear
    /// sweep with another source): the remembered differences stay exact for `G'`
    /// (`G'(x) - G'(y) = G(x) - G(y)`), so they are kept, and the next step already mixes
    /// them; only the last residual, which belongs to `G`, is dropped. A relight with the
    /// history of the previous solve's slow modes removes them from its first step on.
    ///
    /// (Moving the last residual by `c` instead, so that the next step adds one more
    /// difference, was measured worse on the seed room: with one sweep per relight the
    /// history then fills with the relights' own, nearly parallel, changes and loses the
    /// previous solve's slow modes.)
    pub fn new_source(&mut self) {
        self.f_prev = None;
    }

    /// The weighted inner product `sum w u v`, summed in fixed pieces.
    fn dot<U, V>(&self, u: &[U], v: &[V]) -> f64
    where
        U: Copy + Into<f64> + Sync,
        V: Copy + Into<f64> + Sync,
    {
        self.weight
            .par_chunks(CHUNK)
            .zip(u.par_chunks(CHUNK))
            .zip(v.par_chunks(CHUNK))
            .map(|((w, u), v)| {
                w.iter()
                    .zip(u)
                    .zip(v)
                    .map(|((w, &a), &b)| w * a.into() * b.into())
                    .sum::<f64>()
            })
            .collect::<Vec<f64>>()
            .iter()
            .sum()
    }

    /// Remembers the difference between the residual `f` and output `g` of this step and those
    /// of the previous one (scaled to a unit residual difference; skipped when there is none).
    fn remember(&mut self, f_prev: &[f64], g: &[f64]) {
        // The norm of the residual difference, formed in f64.
        let norm = self
            .weight
            .par_chunks(CHUNK)
            .zip(self.f.par_chunks(CHUNK))
            .zip(f_prev.par_chunks(CHUNK))
            .map(|((w, f), fp)| {
                w.iter()
                    .zip(f)
                    .zip(fp)
                    .map(|((w, a), b)| w * (a - b) * (a - b))
                    .sum::<f64>()
            })
            .collect::<Vec<f64>>()
            .iter()
            .sum::<f64>()
            .sqrt();
        if !(norm > 0.0 && norm.is_finite()) {
            return;
        }
        let (mut df, mut dg) = if self.df.len() == self.depth {
            self.gram.pop_front();
            for row in self.gram.iter_mut() {
                row.remove(0);
            }
            (
                self.df.pop_front().expect("full"),
                self.dg.pop_front().expect("full"),
            )
        } else {
            (vec![0.0; self.len()], vec![0.0; self.len()])
        };
        let k = 1.0 / norm;
        df.par_iter_mut()
            .zip(dg.par_iter_mut())
            .zip(self.f.par_iter().zip(f_prev.par_iter()))
            .zip(g.par_iter().zip(self.g_prev.par_iter()))
            .for_each(|(((df, dg), (f, fp)), (g, gp))| {
                *df = ((f - fp) * k) as f32;
                *dg = ((g - gp) * k) as f32;
            });
        let row: Vec<f64> = self
            .df
            .iter()
            .map(|old| self.dot(old, &df))
            .chain(std::iter::once(self.dot(&df, &df)))
            .collect();
        for (old, &v) in self.gram.iter_mut().zip(&row) {
            old.push(v);
        }
        self.gram.push_back(row);
        self.df.push_back(df);
        self.dg.push_back(dg);
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
        let mut f = std::mem::take(&mut self.f);
        f.resize(n, 0.0);
        f.par_iter_mut()
            .zip(g.par_iter().zip(x.par_iter()))
            .for_each(|(f, (g, x))| *f = g - x);
        self.f = f;
        if let Some(f_prev) = self.f_prev.take() {
            self.remember(&f_prev, g);
            self.f_prev = Some(f_prev);
        }
        // The residual becomes the previous one (its buffer reused).
        let mut f_prev = self.f_prev.take().unwrap_or_default();
        std::mem::swap(&mut f_prev, &mut self.f);
        self.f_prev = Some(f_prev);
        self.g_prev.clear();
        self.g_prev.extend_from_slice(g);
        x.copy_from_slice(g);
        let m = self.df.len();
        if m == 0 {
            return;
        }
        // Normal equations of min |f - dF gamma|_w, with a little Tikhonov regularization.
        let f = self.f_prev.as_deref().expect("just set");
        let mut rhs: Vec<f64> = self.df.iter().map(|df| self.dot(df, f)).collect();
        let mut a = vec![0.0f64; m * m];
        for i in 0..m {
            a[i * m..(i + 1) * m].copy_from_slice(&self.gram[i]);
        }
        let trace: f64 = (0..m).map(|i| a[i * m + i]).sum();
        if !(trace > 0.0 && trace.is_finite()) {
            self.restart();
            return;
        }
        for i in 0..m {
            a[i * m + i] += ANDERSON_REGULARIZATION * trace;
        }
        let Some(gamma) = solve_small(&mut a, &mut rhs, m) else {
            self.restart();
            return;
        };
        // The differences have unit norm: a coefficient far beyond the residual's own norm
        // is a wild extrapolation from nearly dependent differences.
        let f_norm = self.dot(f, f).sqrt();
        if gamma
            .iter()
            .any(|g| !g.is_finite() || g.abs() > 1e3 * f_norm)
        {
            self.restart();
            return;
        }
        let dg = &self.dg;
        x.par_chunks_mut(CHUNK).enumerate().for_each(|(chunk, xs)| {
            let (start, len) = (chunk * CHUNK, xs.len());
            for (k, gk) in gamma.iter().enumerate() {
                for (xi, &d) in xs.iter_mut().zip(&dg[k][start..start + len]) {
                    *xi -= gk * d as f64;
                }
            }
        });
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

    /// The same linear map with a new constant term: a history kept from the first solve
    /// ([`Anderson::new_source`]) reaches the new fixed point in fewer steps than a fresh one
    /// started from the same point, and at the same answer.
    #[test]
    fn a_kept_history_solves_a_new_source_faster() {
        let n = 40;
        // A slow mode (the mean, 0.97) over fast local ones, as in a bright closed room.
        let t = |x: &[f64]| -> Vec<f64> {
            let mean = x.iter().sum::<f64>() / n as f64;
            (0..n)
                .map(|i| 0.97 * mean + 0.2 * (x[i] - mean) + 0.05 * (x[(i + 1) % n] - mean))
                .collect()
        };
        let b1: Vec<f64> = (0..n).map(|i| 1.0 + (i % 7) as f64).collect();
        let b2: Vec<f64> = (0..n).map(|i| if i % 3 == 0 { 4.0 } else { 0.5 }).collect();
        let g =
            |x: &[f64], b: &[f64]| -> Vec<f64> { t(x).iter().zip(b).map(|(a, b)| a + b).collect() };
        let residual = |x: &[f64], b: &[f64]| -> f64 {
            let gx = g(x, b);
            gx.iter().zip(x).map(|(a, b)| (a - b).abs()).sum::<f64>()
                / gx.iter().map(|a| a.abs()).sum::<f64>()
        };
        let run = |acc: &mut Anderson, x: &mut Vec<f64>, b: &[f64]| -> usize {
            for k in 1..=500 {
                let gx = g(x, b);
                acc.step(x, &gx);
                if residual(x, b) < 1e-10 {
                    return k;
                }
            }
            usize::MAX
        };
        let mut kept = Anderson::new(4, vec![1.0; n]);
        let mut x1 = vec![0.0; n];
        assert!(run(&mut kept, &mut x1, &b1) < 100);
        assert!(kept.history() > 0);
        let mut fresh = Anderson::new(4, vec![1.0; n]);
        let mut x_fresh = x1.clone();
        let fresh_steps = run(&mut fresh, &mut x_fresh, &b2);
        kept.new_source();
        let mut x_kept = x1.clone();
        let kept_steps = run(&mut kept, &mut x_kept, &b2);
        assert!(
            kept_steps < fresh_steps,
            "kept history: {kept_steps} steps, fresh: {fresh_steps}"
        );
        for (a, b) in x_kept.iter().zip(&x_fresh) {
            assert!((a - b).abs() < 1e-7 * a.abs().max(1.0), "{a} vs {b}");
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
