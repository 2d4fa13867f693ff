//! The iteration steps both solvers share: the change of a sweep, the convergence estimate, and
//! what happens at the end of every sweep ([`end_sweep`]).

use crate::geometry::tolerances::MAX_CONTRACTION;
use crate::mesh::Patches;
use crate::progress::Progress;
use crate::solve::health::{Damping, Guard};
use crate::solve::solution::SolveStats;

/// Tracks residuals across iterations and decides convergence.
///
/// The residual r_k = |B_k - B_(k-1)| / |B_k| underestimates the remaining error when the
/// iteration contracts slowly (albedo near 1): the remaining error is about r_k q / (1 - q) with
/// q the contraction ratio r_k / r_(k-1). Convergence is declared on that estimate.
#[derive(Clone, Debug, Default)]
pub struct Convergence {
    previous: Option<f64>,
    /// Contraction ratios of the last sweeps, newest last.
    ratios: Vec<f64>,
    /// Sweeps since the last extrapolation.
    since_extrapolation: usize,
    /// The contraction ratio at the last extrapolation: the error estimate of the sweep right
    /// after a jump uses it (that sweep's own ratio measures the jump, not the iteration).
    q_at_jump: Option<f64>,
    /// Last residual seen.
    pub residual: f64,
    /// Last estimate of the remaining relative error.
    pub error_estimate: f64,
    /// When set, the contraction ratio used for the error estimate is at least this (an
    /// accelerated iteration's residual ratios understate the plain iteration's, which is what
    /// turns a residual into an error: e = (I - T)^-1 f). The largest albedo bounds it.
    pub contraction_bound: Option<f64>,
    /// The solve started from a solution of the same scene moved by the change of its source
    /// (a warm-started relight): its light has bounced and its antiradiance cancels already, so
    /// convergence may be declared from the first sweep on instead of after [`MIN_SWEEPS`].
    pub warm: bool,
    /// The net change of the state over each of the last three windows of [`WINDOW_SWEEPS`]
    /// sweeps, newest last ([`Convergence::record_window`]).
    windows: Vec<f64>,
}

/// Sweeps over which [`Convergence::record_window`] measures the net change of the state.
pub const WINDOW_SWEEPS: usize = 4;

impl Convergence {
    /// Forgets the measured contraction ratios (the iteration changed: its sweeps are damped
    /// from now on, see [`crate::solve::health::DAMPING`]).
    pub fn restart(&mut self) {
        self.previous = None;
        self.ratios.clear();
        self.since_extrapolation = 0;
        self.q_at_jump = None;
        self.windows.clear();
    }

    /// Records the net relative change of the state over the last [`WINDOW_SWEEPS`] sweeps
    /// (`|x_k - x_(k-W)| / |x_k|`, the same norm as the residual), for the window estimate of
    /// [`Convergence::update`].
    ///
    /// Mixed sweeps (Anderson) converge faster than the residual's bound says: the residual
    /// times `1 / (1 - rho)` for the largest albedo is a bound for a residual in the plain
    /// sweep's slowest mode. b90_office two-sided: residuals falling from 4.7e-4 at its 29th
    /// sweep to 1.0e-4 at its 41st, where that bound let it stop, while the state of its 29th
    /// was 0.020% from a 70-sweep solve. An iteration that still moves does so over the window
    /// as well, so the window's net change, and how fast it shrinks, bound what is left.
    pub fn record_window(&mut self, net: f64) {
        if self.windows.len() == 3 {
            self.windows.remove(0);
        }
        self.windows.push(net);
    }

    /// The remaining error the windows say is left: the net change of the last window times
    /// `s / (1 - s)`, `s` the larger of the ratios of the last three windows' net changes (the
    /// rate at which the state itself has been settling; one lucky window does not decide).
    /// Before three windows were measured, `s` is the contraction bound to the power of the
    /// window ([`Convergence::contraction_bound`], else the sweep ratio `q`). `s` is at most
    /// [`MAX_CONTRACTION`]. `None` before a window was measured.
    ///
    /// The windows measure how fast the iterates converge, not the plain sweep's slowest
    /// mode: b90_office two-sided settles by 0.22, 0.30 and 0.34 a window from its 18th sweep
    /// on, where the largest albedo (0.90) allows 0.65.
    fn window_estimate(&self, q: f64) -> Option<f64> {
        let &net = self.windows.last()?;
        let s = if let [a, b, c] = self.windows[..] {
            (b / a).max(c / b)
        } else {
            self.contraction_bound
                .unwrap_or(q)
                .clamp(0.0, MAX_CONTRACTION)
                .powi(WINDOW_SWEEPS as i32)
        };
        let s = if s.is_finite() {
            s.clamp(0.0, MAX_CONTRACTION)
        } else {
            MAX_CONTRACTION
        };
        net.is_finite().then(|| net * s / (1.0 - s))
    }

    /// Records a residual; returns true when the estimated remaining error is under `tol`.
    pub fn update(&mut self, residual: f64, tol: f64) -> bool {
        self.residual = residual;
        let q = match self.previous {
            Some(p) if p > 0.0 => residual / p,
            _ => self.q_at_jump.unwrap_or(0.9),
        };
        if self.previous.is_some() {
            // As measured: a sweep that did not contract must not pass for a slow contraction.
            self.ratios.push(q);
        }
        self.since_extrapolation += 1;
        self.previous = Some(residual);
        let q = self.estimate_ratio(q);
        self.error_estimate = if residual == 0.0 {
            0.0
        } else {
            residual * q.max(0.0) / (1.0 - q.max(0.0)) + residual
        };
        // The window's estimate where it is the smaller, never below this sweep's own change:
        // the error left in the sweep's output by a sweep that contracts by half (`r q / (1 -
        // q)` at q = 0.5; the solve returns the output, whose error is q times its input's).
        if let Some(window) = self.window_estimate(q) {
            self.error_estimate = self.error_estimate.min(window.max(residual));
        }
        self.error_estimate < tol
    }

    /// The contraction ratio the error estimate takes for a measured ratio `q`: at least
    /// [`Convergence::contraction_bound`], at most [`MAX_CONTRACTION`].
    fn estimate_ratio(&self, q: f64) -> f64 {
        q.max(self.contraction_bound.unwrap_or(0.0))
            .min(MAX_CONTRACTION)
    }

    /// Sweeps still needed to reach `tol`, predicted from the last sweep's contraction ratio
    /// `q`: the residual `r` shrinks by `q` a sweep and the solve stops once `r / (1 - q')` is
    /// under `tol` (`q'` the ratio [`Convergence::update`]'s estimate takes for `q`,
    /// `estimate_ratio`). `None` before two residuals, or when the last sweep did not
    /// contract (`q` not in (0, 1)).
    pub fn sweeps_left(&self, tol: f64) -> Option<f64> {
        let &q = self.ratios.last()?;
        if !(q > 0.0 && q < 1.0) {
            return None;
        }
        if !(self.residual > 0.0) {
            return Some(0.0);
        }
        let target = tol * (1.0 - self.estimate_ratio(q));
        Some(((target / self.residual).ln() / q.ln()).max(0.0))
    }

    /// Records the residual of sweep `iteration` (1-based); true when the solve should stop:
    /// the estimated remaining error is under `tol` and at least [`MIN_SWEEPS`] sweeps ran (the
    /// first ones only propagate emission: light must bounce once and antiradiance must have had
    /// a sweep to cancel it; from the first sweep on when [`Convergence::warm`]).
    pub fn sweep_done(&mut self, iteration: usize, residual: f64, tol: f64) -> bool {
        self.update(residual, tol) && (self.warm || iteration >= MIN_SWEEPS)
    }
}

impl Convergence {
    /// The factor `q / (1 - q)` by which to extrapolate the last sweep's change (`x += k (x_k -
    /// x_(k-1))`, the geometric tail of a linear iteration contracting by `q`), when the
    /// contraction ratio has settled: the last three ratios agree within 2% and lie in (0.05,
    /// [`MAX_CONTRACTION`]), closely enough to know the jump ([`JUMP_SPREAD`]), and three sweeps
    /// have passed since the last extrapolation. `None` otherwise.
    ///
    /// The tail of a Jacobi iteration is dominated by one slowly decaying mode (for a closed
    /// room, the overall light level), so one extrapolation removes most of what many sweeps
    /// would: at albedo 0.75, about half the sweeps; near albedo 1, nearly all of them.
    ///
    /// Ratios that alternate between two values are not settled here: the change then carries
    /// a mode that changes sign from sweep to sweep, which a jump along the last change
    /// amplifies (taking the geometric mean of consecutive pairs as settled, within 5%, took
    /// the 4M-triangle box from 13 sweeps to 30); [`Convergence::two_sweep_factor`] jumps
    /// over two sweeps instead.
    pub fn extrapolation_factor(&mut self) -> Option<f64> {
        if self.since_extrapolation < 3 || self.ratios.len() < 3 {
            return None;
        }
        let last = &self.ratios[self.ratios.len() - 3..];
        let q = last[2];
        let settled = last.iter().all(|r| (r - q).abs() <= 0.02 * q);
        if !(settled && q > 0.05 && q < MAX_CONTRACTION && known_jump(last, q)) {
            return None;
        }
        Some(self.jump(q, q))
    }

    /// Records a jump by `q / (1 - q)` of an iteration contracting by `q_sweep` per sweep, and
    /// returns that factor: the ratios start again, and the sweep after the jump estimates its
    /// error with `q_sweep` (its change is not a contraction ratio of the plain iteration).
    fn jump(&mut self, q: f64, q_sweep: f64) -> f64 {
        self.since_extrapolation = 0;
        self.previous = None;
        self.q_at_jump = Some(q_sweep);
        self.ratios.clear();
        q / (1.0 - q)
    }

    /// The factor `q2 / (1 - q2)` by which to extrapolate the change over the last two sweeps
    /// (`x += k (x_k - x_(k-2))`) when the two-sweep contraction has settled: the products of
    /// the last four ratios' consecutive pairs agree within [`TWO_SWEEP_SETTLED`] and `q2` lies in (0.05^2,
    /// [`MAX_CONTRACTION`]), closely enough to know the jump ([`JUMP_SPREAD`]), and four sweeps
    /// have passed since the last extrapolation. `None` otherwise.
    ///
    /// Over two sweeps a mode that changes sign (ratio -q) decays as one that does not (ratio
    /// q): both are q^2, and the jump removes both, where the one-sweep jump of
    /// [`Convergence::extrapolation_factor`] amplifies the first. Ratios alternating between
    /// two values are this case; the 258k-triangle Cornell box's alternate between 0.49 and
    /// 0.53.
    pub fn two_sweep_factor(&mut self) -> Option<f64> {
        let n = self.ratios.len();
        if self.since_extrapolation < 4 || n < 4 {
            return None;
        }
        let r = &self.ratios[n - 4..];
        let pairs = [r[0] * r[1], r[1] * r[2], r[2] * r[3]];
        let q2 = pairs[2];
        let settled = pairs
            .iter()
            .all(|p| (p - q2).abs() <= TWO_SWEEP_SETTLED * q2);
        // Every sweep contracted: a growing sweep (ratio 1.2) beside a shrinking one is not a
        // steady two-sweep contraction, and ratios held at the cap would jump by 1/(1 - 0.9998).
        let contracting = r.iter().all(|&q| q < MAX_CONTRACTION);
        if !(settled
            && contracting
            && q2 > 0.0025
            && q2 < MAX_CONTRACTION
            && known_jump(&pairs, q2))
        {
            return None;
        }
        Some(self.jump(q2, q2.sqrt()))
    }
}

/// Largest spread of the settled ratios about `q`, as a fraction of `1 - q`, at which a jump
/// by `q / (1 - q)` is taken ([`Convergence::extrapolation_factor`],
/// [`Convergence::two_sweep_factor`]); every ratio must also be below 1.
///
/// When `q` moves by `d`, the jump's factor moves by `d / (q (1 - q))` of itself, so ratios
/// settled within 2% pin it down at 0.5 (to 4%) but not at 0.99 (to 200%): there the same
/// ratios are as well a stall or a slow growth that a projected sweep holds (ratios about 1,
/// some above), and a jump throws the state far off. b90_office two-sided without Anderson
/// mixing (at a 3 GB limit) plateaued at changes of about 7e-3 and jumped at ratios just under
/// 1 thirteen times, most jumps followed by a change of 0.5 to 2.3, until it was failed as
/// diverged at sweep 330; without those jumps it is failed at sweep 82 (its damped sweeps do
/// not converge: Anderson mixing does, docs/stability.md). A steady contraction, however slow
/// (ratios of 0.99 within 1e-4), still jumps.
pub const JUMP_SPREAD: f64 = 0.25;

/// True when `ratios` (contraction ratios, or products of two, settled at `q`) all contract
/// and spread by at most [`JUMP_SPREAD`] times `1 - q` about `q`: a jump by `q / (1 - q)` is
/// then known to about a quarter of itself where this bound is the tighter one (q above about
/// 0.93; below, the 2% agreement of the ratios is).
fn known_jump(ratios: &[f64], q: f64) -> bool {
    ratios
        .iter()
        .all(|&r| r < 1.0 && (r - q).abs() <= JUMP_SPREAD * (1.0 - q))
}

/// Relative spread within which the products of consecutive contraction ratios count as
/// settled for a two-sweep jump ([`Convergence::two_sweep_factor`]). The 258k-triangle Cornell
/// box's products drift up by about 2% a sweep as its slowest mode emerges: at 2% they never
/// settled (11 sweeps); at 5% one jump after its 8th sweep ended the solve at 9, 0.010% from
/// the converged answer; at 8% the jump comes after the 7th and the solve ends at 8, 0.020%
/// from it (11 plain sweeps: 0.023%; the tolerance asks 0.1%). At 8% the 1M box is unchanged
/// (8 sweeps, 0.026%) and b90_office at a 2 GB limit takes 27 sweeps instead of 28, its error
/// against the path tracer unchanged (3.25%). Jumping with a ratio a little low leaves a
/// little of the tail; the sweeps after it remove the rest, and the sweep after a jump
/// estimates its error with the jump's ratio.
pub const TWO_SWEEP_SETTLED: f64 = 0.08;

/// Fewest sweeps before convergence may be declared.
pub const MIN_SWEEPS: usize = 3;

/// Area-weighted relative L1 change between two radiance vectors (NaN when the new vector is
/// not finite, never 0 for a change that overflowed).
pub fn relative_change(patches: &Patches, old: &[[f64; 3]], new: &[[f64; 3]]) -> f64 {
    let (num, den) = change_sums(patches, old, new);
    change_ratio(num, den)
}

/// The area-weighted L1 norms `(sum a |new - old|, sum a |new|)` over patches and RGB channels.
pub fn change_sums(patches: &Patches, old: &[[f64; 3]], new: &[[f64; 3]]) -> (f64, f64) {
    let mut num = 0.0;
    let mut den = 0.0;
    for p in 0..patches.len() {
        let a = patches.area[p];
        for c in 0..3 {
            num += a * (new[p][c] - old[p][c]).abs();
            den += a * new[p][c].abs();
        }
    }
    (num, den)
}

/// The relative change `num / den`: 0 when nothing is lit (`den == 0`), NaN when either sum is
/// not finite (an overflowed sweep must not read as "no change").
pub fn change_ratio(num: f64, den: f64) -> f64 {
    if !(num.is_finite() && den.is_finite()) {
        f64::NAN
    } else if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// After a sweep that did not stop the solve, the same in both solvers: when the health `guard`
/// asks for damping from now on (the sweeps' change kept growing or stalled), records
/// `iteration` for the step it took (`stats.damped_after`, `floor_closed_after` or
/// `radiance_damped_after`), restarts the `convergence` estimate (the iteration changed) and
/// returns true, so the caller restarts whatever else measured the old iteration.
pub fn start_damping(
    iteration: usize,
    guard: &mut Guard,
    convergence: &mut Convergence,
    stats: &mut SolveStats,
) -> bool {
    // A floor closed before any damping (`Guard::close_floor`) is not a step of this one.
    let floor_was_open = guard.floor_open();
    if !guard.wants_damping() {
        return false;
    }
    match guard.damping() {
        Damping::All => stats.radiance_damped_after = Some(iteration),
        _ if floor_was_open && !guard.floor_open() => stats.floor_closed_after = Some(iteration),
        _ => stats.damped_after = Some(iteration),
    }
    convergence.restart();
    true
}

/// A state array a sweep just wrote, beside the one it read ([`damp_if_damped`]).
pub type Swept<'a, T, const N: usize> = (&'a mut [[T; N]], &'a [[T; N]]);

/// Damps the state a sweep just wrote (each radiance array of `radiance` and `anti`, against
/// the state it read beside it) as far as the solve is damped ([`start_damping`],
/// [`Damping`], [`crate::solve::health::damp`]): the antiradiance once it is damped at all,
/// the radiance (the fronts', and the back faces' in the hierarchical solver) once it damps
/// everything; leaves it as it is before. The same in both solvers.
pub fn damp_if_damped<const N: usize>(
    guard: &Guard,
    radiance: &mut [Swept<'_, f64, N>],
    (anti, previous_anti): Swept<'_, f32, N>,
) {
    if guard.damped() {
        crate::solve::health::damp(anti, previous_anti);
    }
    if guard.damping() == Damping::All {
        for (radiance, previous) in radiance.iter_mut() {
            crate::solve::health::damp(radiance, previous);
        }
    }
}

/// The end of sweep `iteration` (1-based), the same in both solvers: counts it, records its
/// change in `stats.sweep_changes`, shows its
/// `change` on the progress bar, asks the health `guard` (`num` the change's numerator,
/// `largest` the largest |B|, `finite` whether every value is finite) and then `convergence`
/// (against `tol`). True when the solve stops here: it failed (`stats.failure` is set) or
/// converged (`stats.converged`).
#[allow(clippy::too_many_arguments)]
pub fn end_sweep(
    iteration: usize,
    change: f64,
    num: f64,
    largest: f64,
    finite: bool,
    tol: f64,
    guard: &mut Guard,
    convergence: &mut Convergence,
    stats: &mut SolveStats,
    progress: &Progress,
) -> bool {
    stats.iterations = iteration;
    stats.sweep_changes.push(change);
    progress.inc(1);
    progress.message(format!("residual {change:.2e}"));
    if let Some(failure) = guard.sweep(iteration, change, num, largest, finite) {
        convergence.residual = change;
        stats.failure = Some(failure);
        return true;
    }
    if convergence.sweep_done(iteration, change, tol) {
        match guard.clamped_failure(iteration, change) {
            Some(failure) => stats.failure = Some(failure),
            None => stats.converged = true,
        }
        return true;
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each damping step is recorded as the one it is, also for a guard whose floor was closed
    /// from the start (faint pairs as cluster links): its first step damps the antiradiance.
    #[test]
    fn start_damping_records_each_step() {
        for closed_from_start in [false, true] {
            let mut guard = Guard::new(Some(4.0), 1.0, 1.0);
            if closed_from_start {
                guard.close_floor();
            }
            let (mut convergence, mut stats) = (Convergence::default(), SolveStats::default());
            assert!(guard.sweep(1, 0.5, 0.5, 1.0, true).is_none());
            guard.note_rows(crate::solve::health::DAMP_ROW_SUM * 2.0);
            assert!(start_damping(1, &mut guard, &mut convergence, &mut stats));
            assert_eq!(stats.damped_after, Some(1), "closed {closed_from_start}");
            assert_eq!(stats.floor_closed_after, None);
            let mut sweep = 2;
            let mut stall = |guard: &mut Guard, stats: &mut SolveStats| loop {
                assert!(guard.sweep(sweep, 0.01, 0.01, 1.0, true).is_none());
                sweep += 1;
                if start_damping(sweep - 1, guard, &mut convergence, stats) {
                    return sweep - 1;
                }
                assert!(sweep < 100, "no damping step");
            };
            let next = stall(&mut guard, &mut stats);
            if closed_from_start {
                assert_eq!(stats.radiance_damped_after, Some(next));
                assert_eq!(stats.floor_closed_after, None);
            } else {
                assert_eq!(stats.floor_closed_after, Some(next));
                assert_eq!(stats.radiance_damped_after, None);
                let last = stall(&mut guard, &mut stats);
                assert_eq!(stats.radiance_damped_after, Some(last));
            }
            assert_eq!(stats.damped_after, Some(1));
        }
    }

    /// Residuals shrinking by a steady ratio: after three, `sweeps_left` predicts the sweeps
    /// [`Convergence::update`] then takes to stop, within one; with a contraction bound above
    /// the ratio (mixed sweeps), more of them.
    #[test]
    fn sweeps_left_predicts_a_steady_contraction() {
        for (q, tol, bound) in [(0.5, 1e-3, None), (0.9, 1e-4, None), (0.4, 1e-3, Some(0.8))] {
            let mut c = Convergence {
                contraction_bound: bound,
                ..Convergence::default()
            };
            let mut r = 0.3;
            for _ in 0..3 {
                c.update(r, tol);
                r *= q;
            }
            let Some(predicted) = c.sweeps_left(tol) else {
                panic!("no prediction at q = {q}");
            };
            let mut taken = 0;
            while !c.update(r, tol) {
                r *= q;
                taken += 1;
            }
            assert!(
                (predicted - taken as f64).abs() <= 1.0,
                "q {q}, tol {tol}, bound {bound:?}: predicted {predicted}, took {taken}"
            );
        }
        // A sweep that grew predicts nothing.
        let mut c = Convergence::default();
        c.update(0.1, 1e-3);
        c.update(0.2, 1e-3);
        assert_eq!(c.sweeps_left(1e-3), None);
    }

    /// The jumps a solve would make over `sweeps` residuals starting at 1, each the one before
    /// times `steps` in turn: (sweep, over two sweeps?, factor), the one-sweep jump tried first
    /// as the solver does.
    fn jumps(steps: &[f64], sweeps: usize) -> Vec<(usize, bool, f64)> {
        let mut c = Convergence::default();
        let mut r = 1.0;
        let mut jumps = Vec::new();
        for k in 0..sweeps {
            c.update(r, 1e-9);
            if let Some(f) = c.extrapolation_factor() {
                jumps.push((k, false, f));
            } else if let Some(f) = c.two_sweep_factor() {
                jumps.push((k, true, f));
            }
            r *= steps[k % steps.len()];
        }
        jumps
    }

    /// Mixed sweeps near the answer: residuals that jitter between 3e-4 and 2e-4 (a sweep ratio
    /// about 1, an estimate 10x the residual or more at the contraction bound 0.9). A state
    /// that wanders by that much each sweep but whose net change over a window is 3e-5 has
    /// converged at a tolerance of 1e-3; one that drifts by the residual every sweep in one
    /// direction (net change 4 residuals) has not.
    #[test]
    fn a_state_that_no_longer_moves_over_a_window_has_converged() {
        let tol = 1e-3;
        for (net, converges) in [(3e-5, true), (4.0 * 3e-4, false)] {
            let mut c = Convergence {
                contraction_bound: Some(0.9),
                ..Convergence::default()
            };
            for k in 0..2 * WINDOW_SWEEPS {
                assert!(!c.update(if k % 2 == 0 { 3e-4 } else { 2e-4 }, tol));
            }
            c.record_window(net);
            assert_eq!(c.update(3e-4, tol), converges, "net change {net}");
            // The estimate is never below the sweep's own change.
            assert!(c.error_estimate >= 3e-4);
        }
    }

    /// Three windows whose net changes shrank by 0.9 and 0.5: the larger ratio makes the
    /// estimate (one lucky window does not decide); with fewer windows the contraction bound's
    /// power does.
    #[test]
    fn the_slower_of_the_last_window_ratios_makes_the_estimate() {
        let mut c = Convergence {
            contraction_bound: Some(0.5),
            ..Convergence::default()
        };
        // Residuals that no longer fall: the sweep ratio 1 says nothing is known.
        c.update(1e-4, 1e-3);
        for net in [2e-3, 1.8e-3, 9e-4] {
            c.record_window(net);
        }
        c.update(1e-4, 1e-3);
        // s = 0.9: 9e-4 * 0.9 / 0.1 = 8.1e-3 (with the last ratio alone, 0.5: 9e-4).
        assert!(
            (c.error_estimate - 8.1e-3).abs() < 1e-9,
            "{}",
            c.error_estimate
        );
        // After a restart, one window: the bound 0.5^4, 9e-4 / 15 = 6e-5, below the residual.
        c.restart();
        c.update(1e-4, 1e-3);
        c.record_window(9e-4);
        c.update(1e-4, 1e-3);
        assert!(
            (c.error_estimate - 1e-4).abs() < 1e-12,
            "{}",
            c.error_estimate
        );
    }

    /// Residuals that grow (by 1.2 a sweep, or by turns 0.5 and 1.9, whose two-sweep products
    /// agree at 0.95) are not a contraction: no jump of either kind. (With the ratios held at the
    /// cap the growing ones passed for a two-sweep contraction of 0.9998 and jumped by 4999.)
    #[test]
    fn growing_residuals_never_extrapolate() {
        for steps in [&[1.2][..], &[0.5, 1.9]] {
            assert_eq!(jumps(steps, 12), [], "{steps:?}");
        }
    }

    /// Residuals that stall about a level (ratios 1.005, 0.99, 0.995, 1.0 in turn, each within
    /// 2% of the last: a projected sweep holding a slowly growing mode) never jump; a contraction
    /// as slow but steady (0.99 every sweep) jumps by 99. Before [`JUMP_SPREAD`] the stall jumped
    /// by 199 after three sweeps.
    #[test]
    fn a_stall_near_ratio_one_does_not_extrapolate() {
        let stall = [1.005, 0.99, 0.995, 1.0];
        for k in 0..stall.len() {
            let window: Vec<f64> = stall.iter().cycle().skip(k).take(3).copied().collect();
            assert!(window
                .iter()
                .all(|r| (r - window[2]).abs() <= 0.02 * window[2]));
        }
        assert_eq!(jumps(&stall, 40), []);
        let steady = jumps(&[0.99], 6);
        assert_eq!(steady.len(), 1, "{steady:?}");
        assert!((steady[0].2 - 99.0).abs() < 1e-6, "{steady:?}");
    }

    /// Residuals contracting by a steady 0.5: one jump once three ratios agree, by q / (1 - q).
    #[test]
    fn a_steady_contraction_extrapolates() {
        assert_eq!(jumps(&[0.5], 6), [(3, false, 1.0)]);
    }

    /// Residuals contracting by 0.5 and 0.4 in turn: no jump over one sweep, one over two
    /// sweeps (by 0.2 / 0.8) once the products of consecutive ratios agree.
    #[test]
    fn an_alternating_contraction_extrapolates_over_two_sweeps() {
        let jumps = jumps(&[0.5, 0.4], 8);
        assert_eq!(jumps.len(), 1, "{jumps:?}");
        assert_eq!(jumps[0].0, 4);
        assert!(jumps[0].1, "{jumps:?}");
        assert!((jumps[0].2 - 0.25).abs() < 1e-12, "{jumps:?}");
    }

    /// A linear iteration with a mode that decays and one that changes sign (eigenvalues 0.6
    /// and -0.55): the two-sweep jumps reach the fixed point in fewer sweeps than plain
    /// sweeps.
    #[test]
    fn two_sweep_jumps_remove_a_mode_that_changes_sign() {
        let lambda = [0.6, -0.55];
        let fixed = lambda.map(|l| 1.0 / (1.0 - l));
        let sweep = |x: [f64; 2]| [lambda[0] * x[0] + 1.0, lambda[1] * x[1] + 1.0];
        let error = |x: [f64; 2]| (x[0] - fixed[0]).abs() + (x[1] - fixed[1]).abs();
        let change = |a: [f64; 2], b: [f64; 2]| {
            ((a[0] - b[0]).abs() + (a[1] - b[1]).abs()) / (a[0].abs() + a[1].abs())
        };
        let solve = |jumps: bool| {
            let mut c = Convergence::default();
            let (mut x1, mut x) = ([0.0; 2], sweep([0.0; 2]));
            for k in 1..60 {
                if error(x) < 1e-9 {
                    return k;
                }
                let next = sweep(x);
                let r = change(next, x);
                c.update(r, 1e-12);
                let x2 = x1;
                (x1, x) = (x, next);
                if jumps {
                    if let Some(f) = c.two_sweep_factor() {
                        x = [0, 1].map(|i| x[i] + f * (x[i] - x2[i]));
                    }
                }
            }
            60
        };
        let (plain, jumping) = (solve(false), solve(true));
        assert!(
            jumping < plain,
            "with jumps {jumping} sweeps, plain {plain}"
        );
    }
}
