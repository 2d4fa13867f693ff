//! The health of a solve: what both solvers watch while they sweep, the thresholds (all of them
//! here), and the failure a solve reports instead of a wrong answer.
//!
//! An antiradiance iteration can amplify instead of contract: on scenes where many surfaces
//! stand behind one another (each triangle doubled by a reversed twin, Venetian blinds, a fan
//! of slivers) the binning error of antiradiance is multiplied by every layer it has to cancel,
//! and the sweep operator's spectral radius can exceed 1. Radiance then grows geometrically,
//! the f32 antiradiance overflows, and `inf - inf` turns the residual into NaN. Every check below
//! exists to stop that from being reported as a converged solution:
//!
//! - **non-finite values**: a NaN or infinity in the radiance, the antiradiance or the residual
//!   of a sweep stops the solve at once ([`FailureKind::NonFinite`]);
//! - **growth**: the change a sweep makes, measured against a fixed mass (the largest mass the
//!   emission and albedos allow, [`Guard::new`]), grew [`GROWTH_SWEEPS`] sweeps in a row or to
//!   [`GROWTH_FACTOR`] times its smallest value so far ([`FailureKind::Growing`]). The relative
//!   residual `|B_k - B_(k-1)| / |B_k|` cannot show this: under geometric growth by a factor
//!   `lambda` per sweep it settles at `1 - 1/lambda`, a constant;
//! - **the maximum principle**: with one-sided Lambertian surfaces, `B <= E_max / (1 - rho_max)`
//!   for every triangle, E_max the largest source radiance and rho_max the largest albedo
//!   ([`radiance_bound`]). A sweep whose largest |B| exceeds [`DIVERGED_BOUND_FACTOR`] times the
//!   bound stops the solve; the result of a finished solve may exceed it by [`BOUND_SLACK`]
//!   ([`FailureKind::OverBound`]);
//! - **negative mass**: a result whose negative area-weighted radiance is above
//!   [`NEGATIVE_LIMIT`] of the positive has failed ([`FailureKind::NegativeMass`]); above
//!   [`NEGATIVE_WARNING`] the command line warns;
//! - **form-factor rows**: a receiver's unoccluded form factors may sum above 1 wherever one
//!   surface stands behind another (a floor sees the wall and the box in front of it: the
//!   Cornell box reaches 1.57 (hierarchical, exact links) and 1.66 (dense) in a correct solve,
//!   its back-to-back twin 3.95 / 4.20), so a row above 1 is not by itself amplification and is
//!   reported (`SolveStats::max_row_sum`); a first sweep's row above [`DAMP_ROW_SUM`] damps the
//!   antiradiance from the start ([`Guard::note_rows`]). In a convex enclosure no surface hides another
//!   and the unoccluded rows are the visible ones: there the dense solver, whose couplings are
//!   exact, scales a row above 1 + [`ROW_SUM_TOLERANCE`] down to 1 (a recovery, counted in
//!   `SolveStats::capped_rows` and warned about). The hierarchical solver does not: its cluster
//!   links give rows that scatter on both sides of 1 (0.85 to 1.30 over the elements of the
//!   furnace split to 0.1 at the `fast` preset, area-weighted mean 1.005) while B stays within
//!   0.9% of the exact 2, the errors averaging out; capping only the rows above 1 measured
//!   worse (design-note error 0.55% -> 1.05%, and 0.04% -> 0.36% at the `default` preset).
//!
//! With exact direct light the sweeps solve for the reflected light only, so during the sweeps
//! E_max is the largest reflected direct radiance; the result `B = E + R` is checked against the
//! emission's own bound.

use serde::Serialize;

use crate::geometry::tolerances::MAX_CONTRACTION;

/// How far above 1 a receiver's form-factor row may sum, in a convex enclosure, before the
/// dense solver scales it down to 1. Its rows there are within 1e-8 of 1 on the 12-triangle
/// furnace and reach 1 + 1.1e-4 / 3.4e-4 on the furnace split to 0.2 / 0.1 (far senders are
/// integrated at the receiver's centroid only); 1e-3 leaves those alone and catches a real
/// overshoot before 1 / (1 - rho) multiplies it (at albedo 0.999 a row 1e-3 above 1 doubles B;
/// a receiver quadrature mixed per sender once gave 1 + 6.4e-4 and B 53% high).
pub const ROW_SUM_TOLERANCE: f64 = 1e-3;

/// How far a finished solve's largest |B| may exceed the bound `E_max / (1 - rho_max)` of its
/// source, as a fraction of it. The bound holds exactly for the model; antiradiance
/// approximates it with binned cancellation, which may leak light, and cluster links' form
/// factors scatter around the exact ones. Measured on the shipped scenes, the seed room,
/// generated rooms with tables, blinds and slivers, open plates, and their back-to-back twins,
/// at 4 to 16 bins and every preset: results that are right to the eye reach 1.22 times the
/// bound (the furnace split to 0.05 at the `fast` preset: patches 22% too bright, per triangle
/// 1.2%) and 1.21 (the reflected light of the blinds with exact direct light); the seed room's
/// twin with two-sided antiradiance 1.49 (with 11% negative mass; warned about). Twice the
/// bound is far beyond any of them: the blinds at 16 bins converged to 8.6 times it (the lowest
/// slats at 0.5 to 0.997 where the light is 1 and 12 bins give at most 0.059, two others at
/// -0.5 and -0.58), and failed.
pub const BOUND_SLACK: f64 = 1.0;

/// Above 1 + this times the bound (and up to 1 + [`BOUND_SLACK`]), the command line warns that
/// some patches are brighter than the light allows: 10% is above what the exact couplings of
/// the dense solver give on the scenes above (at most the bound itself, in the furnace).
pub const BOUND_WARNING: f64 = 0.1;

/// During the sweeps, a largest |B| above this many times the bound stops the solve at once.
/// Sweeps may exceed the bound for a while: the first ones spread light before antiradiance has
/// cancelled it, and Anderson mixing, which can solve the system even where plain sweeps
/// amplify, makes excursions on the way. Measured on the scenes above: up to 216 times the bound
/// (the blinds at 12 bins, which then converged to half of it, 474 sweeps) and 135 (the blinds
/// at the `accurate` preset); diverging solves passed 10,000 after 12 (dense) to 128 sweeps, or
/// were caught by the growth checks, their values still far from overflow (f32: 3e38).
pub const DIVERGED_BOUND_FACTOR: f64 = 1e4;

/// Consecutive sweeps whose change grew (each by more than 1%, to more than twice the smallest
/// change so far) that mark a divergence. A contracting iteration's change shrinks by about
/// rho_max per sweep; the first sweeps and Anderson's mixing can make it rise for a few sweeps
/// (up to 6 in a row on the scenes above, in solves that converged or stayed bounded), a
/// diverging plain sweep rises every sweep (the dense solver on the blinds: 12 in a row by
/// sweep 18, when its largest B was 44 times the bound).
pub const GROWTH_SWEEPS: usize = 12;

/// A sweep's change this many times the smallest change so far marks a divergence. On the
/// scenes above a solve that converged had at most 204 times its minimum (Anderson mixing on
/// the blinds at 12 bins); diverging ones passed 10,000.
pub const GROWTH_FACTOR: f64 = 1e4;

/// Consecutive sweeps whose change grew after which a solver damps its sweeps one stage further
/// ([`Damping`], by [`DAMPING`]; see [`Guard::wants_damping`]). Below [`GROWTH_SWEEPS`], so that
/// a recoverable solve is damped before it would be failed.
pub const DAMP_AFTER_RISING: usize = 4;

/// Sweeps without a new smallest change after which a solver damps its sweeps (see
/// [`DAMP_AFTER_RISING`]). A converging iteration, plain or mixed, makes a new smallest change
/// every sweep or two; one that has not for 4 sweeps oscillates. b90_office (default preset,
/// Anderson mixing) stalls from its 13th sweep: damped after 17 it converges at 30 sweeps, after
/// 21 (at 8) it took 35, to the same answer (0.003% apart). The generated office takes 69
/// sweeps either way; the seed room, bear in a room, classroom and the boxes are never damped.
pub const DAMP_AFTER_STALLING: usize = 4;

/// A first sweep whose largest form-factor row sum is above this damps the antiradiance from
/// its second sweep on ([`Guard::note_rows`]), without waiting for a stall. A row sum `R` means
/// a receiver sees `R` times the form factor one layer could give it, unoccluded: antiradiance
/// must cancel the other `R - 1`, and the oscillation its binning error drives grows with them
/// ([`DAMPING`]). Measured (first-sweep row sums; sweeps undamped -> damped from the second):
/// b90_office 8.25, 26 -> 14 sweeps, 64 -> 42 s, the same answer to 0.009%; at the `fast`
/// preset 3.95, 26 -> 13 sweeps, 12.0 -> 6.7 s; the generated office with Venetian blinds
/// 16.2, 59 -> 50 sweeps. Between 2.5 and 3 rows do not tell which scenes stall: the generated
/// classroom (2.77) converges undamped in 9 sweeps at the `default` preset (damped: 10) but
/// stalls at `accurate` (2.76: damped after its 21st, 26 sweeps; damped from the second, 12),
/// and the Venetian blinds of `tests/divergence.rs` (2.50) take 29 / 33 sweeps undamped and
/// 39 / 53 damped, their open plates (2.99) 20 / 17 and 11 / 16. Well below: the seed room
/// (0.69 to 0.73 at every preset), the bear in a room (1.12 to 1.50), the Cornell box (1.33 to
/// 2.01) and its mesh-quality variants (up to 1.76), the boxes of 1k to 1M triangles (0.67 to
/// 1.18); damped from the second sweep they would each pay a sweep or two (the room 6 -> 8,
/// the bear 7 -> 8).
pub const DAMP_ROW_SUM: f64 = 3.0;

/// Sweeps over which the smallest change must fall by [`SLOW_PROGRESS`] unless it fell on every
/// one of them, else a solver damps its sweeps (see [`DAMP_AFTER_RISING`]): an oscillation that
/// Anderson mixing only slowly wears down sets a new minimum now and then, so
/// [`DAMP_AFTER_STALLING`] alone does not see it. b90_office with near senders spread over bins
/// piece by piece (`transport::refine_piece`, faint pairs' too): new minima every 1 to 5
/// sweeps from 1.1e-2 at sweep 12 to 2.0e-3 at sweep 36, damped after 41, 55 sweeps in all;
/// with this rule damped after 14, 27 sweeps, the same answer (0.002% apart). A steady
/// contraction, however slow (a plain sweep at high albedo), sets a new minimum every sweep
/// and is not damped.
pub const SLOW_WINDOW: usize = 6;

/// See [`SLOW_WINDOW`]: the smallest change must fall below this fraction of what it was
/// [`SLOW_WINDOW`] sweeps before.
pub const SLOW_PROGRESS: f64 = 0.5;

/// Weight of a damped sweep's output: the next state of what is damped ([`Damping`]) is
/// `x + DAMPING * (G(x) - x)`.
///
/// The damped sweep has the same fixed point as the plain one (the same answer). Damping every
/// value maps an eigenvalue `l` of the plain sweep to `1 - DAMPING * (1 - l)`. A plain sweep
/// whose antiradiance makes an eigenvalue below -1 (an oscillation that grows every other
/// sweep: a desk under a reversed top, near parallel slats blocking at both sides) diverges;
/// damped by 0.5 it contracts for every eigenvalue in (-3, 1), at the cost of slower
/// convergence of the slow positive modes (a closed room's light level), which is why the
/// antiradiance alone is damped first. 0.85 (every value damped) took the generated office 67
/// -> 57 sweeps at the `fast` preset and left b90_office at 27: not kept.
pub const DAMPING: f64 = 0.5;

/// What a solve damps ([`Guard::wants_damping`] moves it one stage at a time, never back).
///
/// The oscillations damping stops come from antiradiance (a surface blocking at both sides
/// subtracts, a sweep later, the light that made its antiradiance): the radiance alone is a
/// non-negative operator whose eigenvalues lie in (-1, 1) when no row sum exceeds 1. So the
/// first stage damps the antiradiance only and leaves the radiance's slow positive modes (a
/// closed room's light level) at full speed; only a solve that stalls again damps both.
/// Measured against damping both at once (`antiradiance scene office`, Venetian blinds,
/// `fast` preset: 67 -> 49 sweeps, default preset 106 -> 104 with its radiance damped too
/// after 50; b90_office 27 -> 25 sweeps, the same answer within 0.005%).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Damping {
    /// Plain sweeps.
    Plain,
    /// The antiradiance is damped by [`DAMPING`], the radiance written as swept.
    Antiradiance,
    /// Radiance and antiradiance are damped by [`DAMPING`].
    All,
}

/// Changes below this fraction of the bound's mass are rounding noise (the antiradiance is f32,
/// 6e-8 relative) and never count as growth: a solve asked for a tolerance near the rounding
/// floor may see its change fluctuate there.
pub const GROWTH_FLOOR: f64 = 1e-6;

/// Negative radiance mass (area weighted, before clamping) above this fraction of the positive
/// mass fails the solve: half the light cancelled into negative radiance is no longer a
/// binning error at a shadow's edge (at most 0.42% on the scenes of docs/stability.md, 2.4% on
/// the generated blinds) but a broken cancellation (generated open plates doubled back to back
/// at 16 bins: 73%).
pub const NEGATIVE_LIMIT: f64 = 0.5;

/// Negative radiance mass above this fraction of the positive makes the command line warn:
/// twice the largest fraction measured on one-sided scenes that converged (2.4%, Venetian
/// blinds at 16 bins), met by back-to-back twins with two-sided antiradiance (11% to 18%).
pub const NEGATIVE_WARNING: f64 = 0.05;

/// How far below zero a projected sweep lets an element's antiradiance go, as a share of the
/// bound, where the element's row is shallow ([`OPEN_FLOOR_ROW`]); deeper rows keep the floor
/// at 0 ([`Projection::apply_anti`]).
///
/// The exact antiradiance is never negative, but the binned model's own fixed point is: where
/// a bin's cancellation overshoots (a sender seen through a coarse bin that also holds a
/// nearer blocker), the light the receiver passes on in that bin comes out slightly negative,
/// and behind the receiver it gives back what the overshoot took. Clamped at 0 it cannot, and
/// every damped interior came out dark (measured against path-traced references,
/// design-note error and bias): the MGF classroom (9,253 triangles) 2.58% (-1.28%),
/// b90_office 1.51% (-1.07%). With 2% of the bound below zero at shallow rows: 2.40% (-0.73%)
/// and 1.21% (-0.34%), the same 14 sweeps each; the MGF office `graz.mgf` 2.49% (-1.10%),
/// 12 sweeps, unchanged; the MGF hospital floor, the one measured scene it moved away from its
/// reference, 5.74% (+1.28%) -> 5.98% (+2.41%) against 32,768 spp. (Measured before surfaces
/// given twice sent by what shows of them, `crate::mesh::overlap`: the hospital floor is now
/// at 4.46% (+0.62%), b90_office at 1.22% (-0.44%).) The values needed are small: the
/// classroom at 100% of the bound, 2.35% (-0.49%). The same 2% at every element stalled b90_office's Venetian blinds (59
/// sweeps to converge instead of 14).
pub const ANTI_FLOOR_SHARE: f64 = 0.02;

/// The deepest form-factor row (over an element's exact couplings, the near field where
/// surfaces stack: every coupling in the dense solver, the exact links in the hierarchical
/// one) at which a projected sweep lets the element's antiradiance go below zero
/// ([`ANTI_FLOOR_SHARE`]). Deeper rows stack surfaces that antiradiance cancels layer by layer,
/// where a negative value feeds the oscillation damping holds (Venetian blinds). Measured
/// (b90_office; the MGF classroom; the generated office with blinds, which has no reference):
/// up to rows of 1.0, 13 sweeps 1.23% (bias -0.52%); 2.46% (-0.96%); 41 sweeps as with the
/// floor at 0. Up to 1.5: 14 sweeps 1.21% (-0.34%); 2.40% (-0.73%); 57 sweeps, 0.22% from the
/// answer with the floor at 0. Up to 2.0: 14 sweeps 1.14% (-0.19%); 2.36% (-0.58%). Up to 2.5:
/// b90_office 59 sweeps. 1.5 leaves a margin below the stall for scenes not measured.
pub const OPEN_FLOOR_ROW: f64 = 1.5;

/// The box a recovering solve's sweeps are projected onto: every radiance clamped into
/// `floor..=ceiling` as the sweep writes it, every antiradiance bin into `floor..=ceiling` or,
/// at an element with a shallow row, `anti_floor..=ceiling` ([`Projection::apply_anti`]).
///
/// The exact solution lies in the box `0 <= B <= bound` and `0 <= A <= bound` (radiance and
/// antiradiance are both radiances, the antiradiance of a bin the light that arrives in it, and
/// no surface is brighter than the bound); the binned model's lies in it but for small
/// negative antiradiance where a bin's cancellation overshoots ([`ANTI_FLOOR_SHARE`]), so the
/// projection leaves it where it is. A damped
/// solve ([`Guard::damped`]) is projected from then on ([`Projection::of`]): damping contracts
/// the oscillating modes of antiradiance that blocks at both sides, the projection keeps the
/// modes that damping cannot (an eigenvalue above 1 or below -3: deep stacks of surfaces
/// blocking at both sides, such as Venetian blinds in a one-sided export of a two-sided model)
/// from growing without end while the rest of the scene converges. A result whose sweep had to
/// clamp a value far beyond the bound is still a failure ([`Guard::sweep`] sees the values
/// before the clamp; [`end_sweep`](crate::solve::convergence::end_sweep) checks the converged
/// sweep against 1 + [`BOUND_SLACK`]).
///
/// Measured on `../shared/meshes/b90_office.obj` (one-sided, 22,428 triangles, Venetian
/// blinds): plain and damped sweeps diverged at sweep 18 (1.9e5 times the bound); projected
/// from the sweep damping starts (7), the solve converges in 31 sweeps, 4.3% from the
/// path-traced reference (8,192 spp; bias +1.5%; docs/stability.md).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projection {
    /// Smallest value written (0, or `-inf` when not projecting).
    pub floor: f64,
    /// Largest value written (the bound, or `+inf` when not projecting).
    pub ceiling: f64,
    /// Smallest antiradiance written at an element whose row is at most [`OPEN_FLOOR_ROW`]
    /// (`-ANTI_FLOOR_SHARE` times the bound, or `-inf` when not projecting).
    pub anti_floor: f64,
}

impl Projection {
    /// No projection: every value is written as computed.
    pub const NONE: Projection = Projection {
        floor: f64::NEG_INFINITY,
        ceiling: f64::INFINITY,
        anti_floor: f64::NEG_INFINITY,
    };

    /// The projection of a solve with `bound` (`None`: none applies, as for unoccluded
    /// radiosity) whose sweeps are `damped`: onto `0..=bound` once damped (antiradiance at
    /// shallow rows from `-ANTI_FLOOR_SHARE * bound` while the floor is `open`), none before.
    pub fn of(bound: Option<f64>, damped: bool, open: bool) -> Projection {
        match bound {
            Some(b) if damped && b > 0.0 && b.is_finite() => Projection {
                floor: 0.0,
                ceiling: b,
                anti_floor: if open { -ANTI_FLOOR_SHARE * b } else { 0.0 },
            },
            _ => Projection::NONE,
        }
    }

    /// `x` clamped into the box (NaN stays NaN, so that the guard sees it).
    #[inline]
    pub fn apply(&self, x: f64) -> f64 {
        x.clamp(self.floor, self.ceiling)
    }

    /// Antiradiance `x` of an element whose form-factor row over its exact couplings is `row`,
    /// clamped into the box: from `anti_floor` when `row` is at most [`OPEN_FLOOR_ROW`], from
    /// `floor` above it (NaN stays NaN).
    #[inline]
    pub fn apply_anti(&self, x: f64, row: f64) -> f64 {
        let floor = if row <= OPEN_FLOOR_ROW {
            self.anti_floor
        } else {
            self.floor
        };
        x.clamp(floor, self.ceiling)
    }
}

/// The bound `source_max / (1 - rho_max)` on every B (maximum principle: with one-sided
/// Lambertian surfaces, B = E + rho H and H is at most the largest B): [`geometric_sum`].
pub fn radiance_bound(source_max: f64, rho_max: f64) -> f64 {
    geometric_sum(source_max, rho_max)
}

/// `first / (1 - rho_max)`, the sum of `first * rho_max^k` over every bounce `k >= 0`: the
/// radiance bound, and the light mass both solvers measure their changes against. `rho_max`
/// is capped at [`MAX_CONTRACTION`] so that the sum stays finite.
pub fn geometric_sum(first: f64, rho_max: f64) -> f64 {
    first / (1.0 - rho_max.clamp(0.0, MAX_CONTRACTION))
}

/// Which check a failed solve failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FailureKind {
    /// A NaN or infinity appeared in the radiance, the antiradiance or the residual.
    NonFinite,
    /// The change per sweep grew [`GROWTH_SWEEPS`] sweeps in a row or to [`GROWTH_FACTOR`]
    /// times its minimum: the iteration amplifies.
    Growing,
    /// The largest |B| exceeded the bound: [`DIVERGED_BOUND_FACTOR`] times it during the
    /// sweeps, or 1 + [`BOUND_SLACK`] times it in the result.
    OverBound,
    /// Negative radiance mass above [`NEGATIVE_LIMIT`] of the positive in the result.
    NegativeMass,
}

/// Why a solve failed, with the figures that show it. A solve that carries one has
/// `converged == false`, and its radiance is not a solution of the scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SolveFailure {
    /// The check that failed.
    pub kind: FailureKind,
    /// The sweep (1-based) at which it was detected (for the result's checks, the last sweep).
    pub sweep: usize,
    /// True when it was found in the finished result rather than during the sweeps.
    pub in_result: bool,
    /// Relative residual of that sweep (may be NaN or infinite: it is what diverged).
    pub residual: f64,
    /// The change of that sweep over the smallest change so far.
    pub change_over_min: f64,
    /// Consecutive sweeps the change had grown.
    pub growing_sweeps: usize,
    /// Largest |B| of that sweep over the bound `E_max / (1 - rho_max)` (0 when no bound
    /// applies).
    pub largest_b_over_bound: f64,
    /// The bound, in the scene's radiance units (0 when none applies).
    pub bound: f64,
    /// Negative over positive radiance mass of the result (0 when the solve stopped early).
    pub negative_fraction: f64,
    /// Largest form-factor row sum of the solve.
    pub max_row_sum: f64,
}

impl std::fmt::Display for SolveFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let at = if self.in_result {
            format!("in the result after {} sweeps", self.sweep)
        } else {
            format!("at sweep {}", self.sweep)
        };
        // The source is what the sweeps solve for: the emission, or with exact direct light the
        // reflected direct light.
        let source = "largest source radiance";
        let (ratio, bound) = (number(self.largest_b_over_bound), number(self.bound));
        match self.kind {
            FailureKind::NonFinite => write!(f, "a NaN or infinite value appeared {at}")?,
            FailureKind::Growing if self.growing_sweeps >= GROWTH_SWEEPS => write!(
                f,
                "diverged {at}: the change per sweep grew {} sweeps in a row, to {} times its minimum",
                self.growing_sweeps,
                number(self.change_over_min)
            )?,
            FailureKind::Growing => write!(
                f,
                "diverged {at}: the change per sweep rose to {} times its minimum",
                number(self.change_over_min)
            )?,
            FailureKind::OverBound => write!(
                f,
                "{} {at}: the largest radiance is {ratio} times its bound ({source})/(1 - largest albedo) = {bound}, more than the {} allowed{}",
                if self.in_result {
                    "out of bounds"
                } else {
                    "diverged"
                },
                if self.in_result {
                    1.0 + BOUND_SLACK
                } else {
                    DIVERGED_BOUND_FACTOR
                },
                if self.in_result { "" } else { " during the sweeps" }
            )?,
            FailureKind::NegativeMass => write!(
                f,
                "negative radiance is {:.1}% of the positive mass {at}, more than the {}% allowed",
                100.0 * self.negative_fraction,
                100.0 * NEGATIVE_LIMIT
            )?,
        }
        write!(f, " (residual {}", number(self.residual))?;
        if self.kind != FailureKind::OverBound && self.bound > 0.0 {
            write!(
                f,
                ", largest radiance {ratio} times its bound ({source})/(1 - largest albedo) = {bound}"
            )?;
        }
        write!(f, ", max form-factor row sum {})", number(self.max_row_sum))
    }
}

/// A figure for a message: 4 decimals (trailing zeros dropped) within 1e-3..1e5, else 4
/// significant digits in exponent form.
fn number(x: f64) -> String {
    if x == 0.0 || (1e-3..1e5).contains(&x.abs()) {
        let text = format!("{x:.4}");
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{x:.3e}")
    }
}

/// Watches the sweeps of one solve for non-finite values, growth and radiance beyond the bound.
#[derive(Clone, Debug)]
pub struct Guard {
    /// The bound on |B| in the solver's units, when one applies.
    bound: Option<f64>,
    /// Factor from the solver's units to the scene's (for the figures of a failure).
    scale: f64,
    /// Mass the change of a sweep is measured against.
    reference_mass: f64,
    /// Smallest change so far (fraction of `reference_mass`).
    min_change: f64,
    /// Change of the previous sweep.
    previous_change: Option<f64>,
    /// Consecutive sweeps whose change grew.
    rising: usize,
    /// Largest |B| over the bound in the last sweep.
    pub largest_over_bound: f64,
    /// What the solver damps ([`Guard::wants_damping`]).
    damping: Damping,
    /// Sweeps since the change last reached a new minimum.
    since_min: usize,
    /// The smallest change so far after each sweep (since the last damping).
    minima: Vec<f64>,
    /// The first sweep's largest row sum was above [`DAMP_ROW_SUM`] ([`Guard::note_rows`]).
    deep_rows: bool,
    /// Damped antiradiance may still go below 0 at shallow rows ([`ANTI_FLOOR_SHARE`]): true
    /// until damped sweeps stall with it ([`Guard::wants_damping`]).
    floor_open: bool,
}

impl Guard {
    /// A guard for a solve whose |B| is bounded by `bound` (`None`: no bound applies, as for
    /// unoccluded radiosity, or the scene has no light) and whose sweep changes are measured
    /// against `reference_mass`, the area-weighted mass of the bound over the scene (sum over
    /// elements and channels of a |source| / (1 - rho_max)). A zero mass disables the growth
    /// checks (nothing is lit). `scale` converts the solver's radiance units to the scene's
    /// (the patches' emission scale); a failure reports its bound in scene units.
    pub fn new(bound: Option<f64>, reference_mass: f64, scale: f64) -> Guard {
        Guard {
            bound: bound.filter(|b| *b > 0.0 && b.is_finite()),
            scale,
            reference_mass,
            min_change: f64::INFINITY,
            previous_change: None,
            rising: 0,
            largest_over_bound: 0.0,
            damping: Damping::Plain,
            since_min: 0,
            minima: Vec::new(),
            deep_rows: false,
            floor_open: true,
        }
    }

    /// Takes the largest form-factor row sum of a solve's first sweep: above [`DAMP_ROW_SUM`],
    /// [`Guard::wants_damping`] damps the antiradiance at once.
    pub fn note_rows(&mut self, max_row_sum: f64) {
        self.deep_rows = max_row_sum > DAMP_ROW_SUM;
    }

    /// True when the first sweep's largest row sum was above [`DAMP_ROW_SUM`]
    /// ([`Guard::note_rows`]): the antiradiance is damped from the second sweep, and the solve
    /// has many sweeps ahead.
    pub fn deep_rows(&self) -> bool {
        self.deep_rows
    }

    /// Checks sweep `sweep` (1-based): its relative `residual`, the area-weighted L1 mass of
    /// the change it made (`change`, same units and channel sum as `reference_mass`), its
    /// largest |B| (`largest`) and whether every value it wrote was finite (`finite`).
    /// Returns the failure, if any; figures not known here (bound in scene units, row sums,
    /// negative mass) are left 0 for the caller to fill in.
    pub fn sweep(
        &mut self,
        sweep: usize,
        residual: f64,
        change: f64,
        largest: f64,
        finite: bool,
    ) -> Option<SolveFailure> {
        self.largest_over_bound = match self.bound {
            Some(b) => largest / b,
            None => 0.0,
        };
        let ratio = self.largest_over_bound;
        if !(finite && residual.is_finite() && change.is_finite() && largest.is_finite()) {
            let mut f = self.failure(sweep, residual, FailureKind::NonFinite);
            f.largest_b_over_bound = sanitize_ratio(ratio);
            return Some(f);
        }
        if ratio > DIVERGED_BOUND_FACTOR {
            let mut f = self.failure(sweep, residual, FailureKind::OverBound);
            f.largest_b_over_bound = ratio;
            return Some(f);
        }
        if self.reference_mass > 0.0 {
            let c = change / self.reference_mass;
            match self.previous_change {
                Some(p) if c > 1.01 * p && c > GROWTH_FLOOR => self.rising += 1,
                _ => self.rising = 0,
            }
            self.previous_change = Some(c);
            let over_min = if self.min_change > 0.0 {
                c / self.min_change
            } else {
                0.0
            };
            let growing = (self.rising >= GROWTH_SWEEPS && over_min > 2.0)
                || (c > GROWTH_FLOOR && self.min_change.is_finite() && over_min > GROWTH_FACTOR);
            if growing {
                let mut f = self.failure(sweep, residual, FailureKind::Growing);
                f.change_over_min = if self.min_change.is_finite() {
                    over_min
                } else {
                    1.0
                };
                f.growing_sweeps = self.rising;
                f.largest_b_over_bound = ratio;
                return Some(f);
            }
            if c < self.min_change {
                self.min_change = c;
                self.since_min = 0;
            } else {
                self.since_min += 1;
            }
            self.minima.push(self.min_change);
        }
        None
    }
}

impl Guard {
    /// True when the change has grown [`DAMP_AFTER_RISING`] sweeps in a row, has not reached a
    /// new minimum for [`DAMP_AFTER_STALLING`] sweeps (an oscillation that neither grows nor
    /// decays) or has made slow and unsteady progress ([`SLOW_WINDOW`]), or (for the first
    /// stage only) the first sweep's rows were deeper than [`DAMP_ROW_SUM`], and the sweeps are not
    /// yet damped as far as they go: the solver should damp one stage further from now on
    /// ([`Damping`], [`DAMPING`]; damped antiradiance first closes its floor at 0
    /// everywhere, [`Guard::floor_open`], and only then damps the radiance too). At most three
    /// times per solve. The growth record starts again, so a
    /// fully damped solve that still grows fails [`GROWTH_SWEEPS`] sweeps later.
    pub fn wants_damping(&mut self) -> bool {
        // Slow and not steady: over the window the minimum fell by less than SLOW_PROGRESS and
        // some sweep set no new one (a steady slow contraction, high albedo without mixing, sets
        // one every sweep and would only be slowed further by damping).
        let k = self.minima.len();
        let slow = k > SLOW_WINDOW && {
            let window = &self.minima[k - 1 - SLOW_WINDOW..];
            let new_minima = window.windows(2).filter(|w| w[1] < w[0]).count();
            window[SLOW_WINDOW] > SLOW_PROGRESS * window[0] && new_minima < SLOW_WINDOW
        };
        let stuck = self.rising >= DAMP_AFTER_RISING || self.since_min >= DAMP_AFTER_STALLING;
        // Rows deep enough that antiradiance cancels several layers damp it from the start.
        let deep = self.deep_rows;
        // The slow rule moves plain sweeps only: damped antiradiance wears an oscillation down
        // unevenly (new minima every one to three sweeps on Venetian blinds), which it would
        // take for a stall.
        let next = match self.damping {
            Damping::Plain if stuck || slow || deep => Damping::Antiradiance,
            Damping::Antiradiance if stuck && self.floor_open => {
                self.floor_open = false;
                Damping::Antiradiance
            }
            Damping::Antiradiance if stuck => Damping::All,
            _ => return false,
        };
        self.damping = next;
        self.rising = 0;
        self.since_min = 0;
        self.min_change = f64::INFINITY;
        self.previous_change = None;
        self.minima.clear();
        true
    }

    /// True when the solve damps its sweeps at all ([`Self::wants_damping`] said so once):
    /// its antiradiance is damped and its sweeps are projected ([`Projection`]).
    pub fn damped(&self) -> bool {
        self.damping != Damping::Plain
    }

    /// What the solve damps now.
    pub fn damping(&self) -> Damping {
        self.damping
    }

    /// Holds damped antiradiance at 0 everywhere from now on ([`Guard::floor_open`] false): for
    /// a solve whose exact rows do not measure where surfaces stack. At the `fast` preset
    /// (`LinkParams::faint_links`: faint pairs whose spheres overlap are cluster links) the
    /// open floor gained nothing and cost sweeps (b90_office 11 -> 29 sweeps, 4.31% -> 4.34%
    /// from its reference, and the generated office 14 -> 37, each once its sweeps had stalled
    /// with it open, [`Guard::wants_damping`]; the MGF office 6 -> 8, 14.4% -> 14.2%).
    pub fn close_floor(&mut self) {
        self.floor_open = false;
    }

    /// True while damped antiradiance may go below 0 at shallow rows ([`ANTI_FLOOR_SHARE`],
    /// [`OPEN_FLOOR_ROW`]); false once damped sweeps stalled with it: a stack of surfaces the
    /// exact rows do not show (coupled by cluster links, as faint pairs are with
    /// `LinkParams::faint_links`) can oscillate through it, and the floor of 0 holds that.
    pub fn floor_open(&self) -> bool {
        self.floor_open
    }

    /// The failure of a converged sweep `sweep` that was projected and had to clamp a value
    /// beyond 1 + [`BOUND_SLACK`] times the bound (its largest |B| before the clamp, as
    /// [`Guard::sweep`] saw it): the projection held a mode that amplifies, and the values it
    /// wrote are not a solution. `None` when it was not projected or stayed within the slack.
    pub fn clamped_failure(&self, sweep: usize, residual: f64) -> Option<SolveFailure> {
        let projected = self.projection() != Projection::NONE;
        (projected && self.largest_over_bound > 1.0 + BOUND_SLACK).then(|| SolveFailure {
            in_result: true,
            largest_b_over_bound: self.largest_over_bound,
            ..self.failure(sweep, residual, FailureKind::OverBound)
        })
    }

    /// A failure of `kind` found at sweep `sweep` with relative `residual`, during the sweeps,
    /// with the bound in scene units; the other figures 0 for the caller to fill in.
    fn failure(&self, sweep: usize, residual: f64, kind: FailureKind) -> SolveFailure {
        SolveFailure {
            kind,
            sweep,
            in_result: false,
            residual,
            change_over_min: 0.0,
            growing_sweeps: 0,
            largest_b_over_bound: 0.0,
            bound: self.bound.map_or(0.0, |b| b * self.scale),
            negative_fraction: 0.0,
            max_row_sum: 0.0,
        }
    }

    /// The projection of the next sweep ([`Projection::of`] this guard's bound, once damped).
    pub fn projection(&self) -> Projection {
        Projection::of(self.bound, self.damped(), self.floor_open)
    }
}

/// Damps one sweep in place: `next = previous + DAMPING * (next - previous)`, per value.
pub fn damp<const N: usize, T>(next: &mut [[T; N]], previous: &[[T; N]])
where
    T: Copy + Into<f64> + FromF64,
{
    for (x, p) in next.iter_mut().zip(previous) {
        for c in 0..N {
            let (xv, pv): (f64, f64) = (x[c].into(), p[c].into());
            x[c] = T::from_f64(pv + DAMPING * (xv - pv));
        }
    }
}

/// Conversion back from f64 for [`damp`] and the extrapolation of the hierarchical sweeps
/// (radiance is f64, antiradiance f32).
pub trait FromF64 {
    /// The value nearest `x`.
    fn from_f64(x: f64) -> Self;
}

impl FromF64 for f64 {
    fn from_f64(x: f64) -> f64 {
        x
    }
}

impl FromF64 for f32 {
    fn from_f64(x: f64) -> f32 {
        x as f32
    }
}

/// A ratio for a report: non-finite becomes `f64::MAX` (it is still "far beyond").
fn sanitize_ratio(x: f64) -> f64 {
    if x.is_finite() {
        x
    } else {
        f64::MAX
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_engages_once_damped_and_only_with_a_bound() {
        assert_eq!(Projection::of(Some(4.0), false, true), Projection::NONE);
        assert_eq!(Projection::of(None, true, true), Projection::NONE);
        assert_eq!(
            Projection::of(Some(f64::INFINITY), true, true),
            Projection::NONE
        );
        let p = Projection::of(Some(4.0), true, true);
        assert_eq!((p.apply(-1.0), p.apply(2.5), p.apply(9.0)), (0.0, 2.5, 4.0));
        assert!(p.apply(f64::NAN).is_nan(), "NaN must reach the guard");
        assert_eq!(Projection::NONE.apply(-1e30), -1e30);
        // Antiradiance at a shallow row may go a little below zero, at a deep one not at all.
        let shallow = |x| p.apply_anti(x, OPEN_FLOOR_ROW);
        let deep = |x| p.apply_anti(x, OPEN_FLOOR_ROW * 1.01);
        let below = -ANTI_FLOOR_SHARE * 4.0;
        assert_eq!(
            (shallow(-1.0), shallow(below / 2.0), shallow(9.0)),
            (below, below / 2.0, 4.0)
        );
        assert_eq!((deep(-1.0), deep(below / 2.0), deep(2.5)), (0.0, 0.0, 2.5));
        assert!(shallow(f64::NAN).is_nan() && deep(f64::NAN).is_nan());
        assert_eq!(Projection::NONE.apply_anti(-1e30, 0.0), -1e30);
        assert_eq!(Projection::NONE.apply_anti(-1e30, 10.0), -1e30);
        // A guard projects from the sweep after it asked for damping.
        let mut guard = Guard::new(Some(4.0), 1.0, 1.0);
        assert_eq!(guard.projection(), Projection::NONE);
        let mut change = 0.1;
        for k in 1..=DAMP_AFTER_RISING + 1 {
            assert!(guard.sweep(k, 0.05, change, 1.0, true).is_none());
            change *= 1.5;
        }
        assert!(guard.wants_damping());
        assert_eq!(guard.projection(), p);
    }

    #[test]
    fn a_converged_projected_sweep_that_clamped_far_beyond_the_bound_fails() {
        let mut guard = Guard::new(Some(4.0), 1.0, 2.0);
        guard.damping = Damping::Antiradiance;
        // Within the slack: 2 x the bound before the clamp.
        assert!(guard.sweep(9, 1e-5, 1e-5, 8.0, true).is_none());
        assert!(guard.clamped_failure(9, 1e-5).is_none());
        // Beyond it.
        assert!(guard.sweep(10, 1e-5, 1e-5, 8.5, true).is_none());
        let f = guard
            .clamped_failure(10, 1e-5)
            .expect("clamped beyond the slack");
        assert_eq!(
            (f.kind, f.in_result, f.sweep),
            (FailureKind::OverBound, true, 10)
        );
        assert_eq!(f.bound, 8.0, "the bound in scene units");
        // Not projected: the result's own check judges it.
        let mut plain = Guard::new(Some(4.0), 1.0, 1.0);
        assert!(plain.sweep(1, 1e-5, 1e-5, 100.0, true).is_none());
        assert!(plain.clamped_failure(1, 1e-5).is_none());
    }

    /// A geometric sequence of changes with ratio `q` per sweep, fed to a fresh guard; the first
    /// failure and the sweep it came at.
    fn feed(q: f64, sweeps: usize, bound: Option<f64>) -> Option<SolveFailure> {
        let mut guard = Guard::new(bound, 1.0, 1.0);
        let mut change = 0.1;
        for k in 1..=sweeps {
            if let Some(f) = guard.sweep(k, 0.05, change, 1.0, true) {
                return Some(f);
            }
            change *= q;
        }
        None
    }

    /// True when a fresh guard fed `changes` asks for damping at some sweep.
    fn damps(changes: &[f64]) -> bool {
        let mut guard = Guard::new(None, 1.0, 1.0);
        changes.iter().enumerate().any(|(k, &c)| {
            assert!(guard.sweep(k + 1, 0.05, c, 1.0, true).is_none());
            guard.wants_damping()
        })
    }

    #[test]
    fn a_slow_oscillation_is_damped_and_a_steady_slow_contraction_is_not() {
        // b90_office's changes before it was damped: a new minimum every few sweeps, but the
        // minimum no longer halving in 6 sweeps (never 4 sweeps without one).
        let oscillating = [
            4.2e-1, 1.9e-1, 1.4e-1, 9.7e-2, 5.6e-2, 4.4e-2, 3.1e-2, 1.9e-2, 1.8e-2, 1.5e-2, 1.3e-2,
            1.1e-2, 1.09e-2, 1.2e-2, 1.3e-2, 1.0e-2, 9.9e-3, 9.4e-3,
        ];
        assert!(damps(&oscillating));
        assert!(!damps(&oscillating[..13]), "still halving every 6 sweeps");
        // A steady contraction at 0.95 per sweep sets a new minimum every sweep.
        let steady: Vec<f64> = (0..300).map(|k| 0.1 * 0.95f64.powi(k)).collect();
        assert!(!damps(&steady));
    }

    #[test]
    fn damping_takes_the_antiradiance_then_its_floor_then_the_radiance() {
        let mut guard = Guard::new(Some(4.0), 1.0, 1.0);
        let mut sweep = 0;
        let mut feed = |guard: &mut Guard, changes: &[f64]| {
            changes.iter().any(|&c| {
                sweep += 1;
                assert!(guard.sweep(sweep, 0.05, c, 1.0, true).is_none());
                guard.wants_damping()
            })
        };
        assert_eq!(guard.damping(), Damping::Plain);
        // Growing 4 sweeps in a row: the antiradiance is damped.
        assert!(feed(&mut guard, &[1e-2, 1.1e-2, 1.2e-2, 1.3e-2, 1.4e-2]));
        assert_eq!(guard.damping(), Damping::Antiradiance);
        assert!(guard.damped());
        // An uneven decay that halves more slowly than every 6 sweeps, with a new minimum at
        // least every 3: the slow rule does not move a damped solve on.
        let uneven = [
            1e-2, 9e-3, 9.5e-3, 8.5e-3, 8.8e-3, 8.2e-3, 8.0e-3, 8.3e-3, 7.9e-3, 7.8e-3, 7.9e-3,
            7.5e-3,
        ];
        assert!(!feed(&mut guard, &uneven));
        assert_eq!(guard.damping(), Damping::Antiradiance);
        // A stall of 4 sweeps without a new minimum: the antiradiance's floor closes at 0.
        assert!(feed(&mut guard, &[7.6e-3, 7.7e-3, 7.6e-3, 7.8e-3, 7.7e-3]));
        assert_eq!(guard.damping(), Damping::Antiradiance);
        assert!(!guard.floor_open());
        // Another: the radiance is damped too.
        assert!(feed(&mut guard, &[7.6e-3, 7.7e-3, 7.6e-3, 7.8e-3, 7.7e-3]));
        assert_eq!(guard.damping(), Damping::All);
        // Nothing further: a fully damped solve that still grows is left to fail.
        assert!(!feed(
            &mut guard,
            &[8e-3, 9e-3, 1e-2, 1.1e-2, 1.2e-2, 1.3e-2]
        ));
        assert_eq!(guard.damping(), Damping::All);
    }

    #[test]
    fn deep_rows_damp_the_antiradiance_after_the_first_sweep_and_nothing_more() {
        for (row, damped) in [(DAMP_ROW_SUM * 0.99, false), (DAMP_ROW_SUM * 1.01, true)] {
            let mut guard = Guard::new(Some(4.0), 1.0, 1.0);
            assert!(guard.sweep(1, 0.5, 0.5, 1.0, true).is_none());
            guard.note_rows(row);
            assert_eq!(guard.wants_damping(), damped, "row sum {row}");
            // A steady contraction afterwards moves it no further (the radiance is not damped).
            for (k, c) in [0.25, 0.12, 0.06, 0.03].into_iter().enumerate() {
                assert!(guard.sweep(k + 2, c, c, 1.0, true).is_none());
                assert!(!guard.wants_damping(), "row sum {row}, sweep {}", k + 2);
            }
            let want = if damped {
                Damping::Antiradiance
            } else {
                Damping::Plain
            };
            assert_eq!(guard.damping(), want);
        }
    }

    /// Damped sweeps that stall with the floor open below 0 close it first (the antiradiance
    /// then held at 0 everywhere), and only a second stall damps the radiance as well.
    #[test]
    fn a_stalled_open_floor_closes_before_the_radiance_is_damped() {
        let mut guard = Guard::new(Some(4.0), 1.0, 1.0);
        assert!(guard.sweep(1, 0.5, 0.5, 1.0, true).is_none());
        guard.note_rows(DAMP_ROW_SUM * 2.0);
        assert!(guard.wants_damping());
        let open = guard.projection();
        assert!(guard.floor_open() && open.apply_anti(-1.0, 1.0) < 0.0);
        let mut sweep = 2;
        let mut stall = |guard: &mut Guard| {
            // The same change sweep after sweep: no new minimum.
            for _ in 0..=DAMP_AFTER_STALLING {
                assert!(guard.sweep(sweep, 0.01, 0.01, 1.0, true).is_none());
                sweep += 1;
            }
            guard.wants_damping()
        };
        assert!(stall(&mut guard));
        assert_eq!(guard.damping(), Damping::Antiradiance);
        assert!(!guard.floor_open());
        assert_eq!(guard.projection().apply_anti(-1.0, 1.0), 0.0);
        assert!(stall(&mut guard));
        assert_eq!(guard.damping(), Damping::All);
        assert!(!stall(&mut guard), "no stage is left");
    }

    #[test]
    fn a_contracting_sequence_passes() {
        assert_eq!(feed(0.75, 200, Some(4.0)), None);
        assert_eq!(feed(0.999, 2000, Some(4.0)), None);
    }

    #[test]
    fn a_growing_sequence_fails_after_the_growth_sweeps() {
        let f = feed(1.2, 100, None).expect("growth is detected");
        assert_eq!(f.kind, FailureKind::Growing);
        // The first sweep has no predecessor, so the run of growth is complete one sweep later.
        assert_eq!(f.sweep, GROWTH_SWEEPS + 1);
        assert_eq!(f.growing_sweeps, GROWTH_SWEEPS);
        assert!((f.change_over_min - 1.2f64.powi(GROWTH_SWEEPS as i32)).abs() < 1e-9);
    }

    #[test]
    fn a_slow_growth_fails_once_it_has_doubled() {
        // 4% per sweep: the run is long enough after 12 sweeps, the change doubled after 18.
        let f = feed(1.04, 100, None).expect("growth is detected");
        assert_eq!(f.kind, FailureKind::Growing);
        assert_eq!(f.sweep, 19);
        assert!(f.change_over_min > 2.0 && f.change_over_min < 2.1);
    }

    #[test]
    fn a_change_far_above_its_minimum_fails_even_without_a_run() {
        let mut guard = Guard::new(None, 1.0, 1.0);
        let changes = [1e-1, 1e-2, 1e-3, 1e-4, 5e-6, 2e-1];
        let mut failure = None;
        for (k, &c) in changes.iter().enumerate() {
            failure = guard.sweep(k + 1, 0.01, c, 1.0, true);
            if failure.is_some() {
                break;
            }
        }
        let f = failure.expect("a jump of 40000x over the minimum is detected");
        assert_eq!(f.kind, FailureKind::Growing);
        assert_eq!(f.sweep, 6);
        assert!(
            (f.change_over_min - 40000.0).abs() < 1e-6,
            "{}",
            f.change_over_min
        );
    }

    #[test]
    fn bumps_and_noise_below_the_floor_pass() {
        let mut guard = Guard::new(Some(1.0), 1.0, 1.0);
        // Three rises in a row, then contraction: no failure.
        let mut c = 1e-2;
        for k in 1..=40 {
            c *= if (3..6).contains(&k) { 1.5 } else { 0.6 };
            assert_eq!(guard.sweep(k, 0.01, c, 0.5, true), None, "sweep {k}");
        }
        // Rounding noise far below the floor rising and jumping: no failure.
        let mut guard = Guard::new(Some(1.0), 1.0, 1.0);
        for k in 1..=40 {
            let c = 1e-12 * (1.0 + k as f64);
            assert_eq!(guard.sweep(k, 1e-12, c, 0.5, true), None, "sweep {k}");
        }
    }

    #[test]
    fn nan_and_infinity_fail_at_once() {
        for (residual, change, largest, finite) in [
            (f64::NAN, 0.1, 1.0, true),
            (0.1, f64::INFINITY, 1.0, true),
            (0.1, 0.1, f64::INFINITY, true),
            (0.1, 0.1, 1.0, false),
        ] {
            let mut guard = Guard::new(Some(2.0), 1.0, 1.0);
            let f = guard
                .sweep(3, residual, change, largest, finite)
                .expect("non-finite values are detected");
            assert_eq!(f.kind, FailureKind::NonFinite);
            assert_eq!(f.sweep, 3);
        }
    }

    #[test]
    fn radiance_far_beyond_the_bound_fails() {
        let mut guard = Guard::new(Some(4.0), 1.0, 1.0);
        assert_eq!(guard.sweep(1, 0.5, 0.1, 4.0 * 1.9, true), None);
        let f = guard
            .sweep(2, 0.5, 0.09, 4.0 * DIVERGED_BOUND_FACTOR * 1.01, true)
            .expect("beyond the bound");
        assert_eq!(f.kind, FailureKind::OverBound);
        assert!((f.largest_b_over_bound - DIVERGED_BOUND_FACTOR * 1.01).abs() < 1e-9);
        // No bound: no such check.
        let mut guard = Guard::new(None, 1.0, 1.0);
        assert_eq!(guard.sweep(1, 0.5, 0.1, 1e30, true), None);
    }

    #[test]
    fn the_bound_is_the_maximum_principle() {
        assert_eq!(radiance_bound(1.0, 0.75), 4.0);
        assert_eq!(radiance_bound(2.0, 0.0), 2.0);
        assert!(radiance_bound(1.0, 1.0).is_finite());
    }

    #[test]
    fn the_failure_reads_as_one_line() {
        let f = SolveFailure {
            kind: FailureKind::NonFinite,
            sweep: 47,
            in_result: false,
            residual: f64::NAN,
            change_over_min: 0.0,
            growing_sweeps: 0,
            largest_b_over_bound: 2.2e36,
            bound: 4.0,
            negative_fraction: 0.0,
            max_row_sum: 8.28,
        };
        let text = f.to_string();
        assert!(!text.contains('\n'));
        assert!(text.contains("sweep 47"), "{text}");
        assert!(text.contains("8.28"), "{text}");
        assert!(text.contains("2.200e36") && text.contains("= 4,"), "{text}");
        assert!(text.contains("residual NaN"), "{text}");
    }
}
