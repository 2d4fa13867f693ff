//! The warnings of a solve: what did not fail but is less accurate than asked.

use crate::error::{Warning, WarningKind};
use crate::geometry::tolerances::MAX_CONTRACTION;
use crate::memory::format_bytes;
use crate::mesh::Patches;
use crate::solve::solution::{self, SolveStats};
use crate::solve::{budget, direct, SolverKind, SolverOptions};

/// The warnings of one antiradiance solve: memory limit ([`memory_warning`]), iteration cap
/// ([`cap_warning`]), skipped direct light ([`direct_light_warning`]), capped form-factor rows
/// ([`capped_rows_warning`]), much negative radiance ([`negative_warning`]) and radiance above
/// the bound ([`bound_warning`]). A failed solve is not warned about here: it is an error
/// ([`SolveStats::check`]). (Emitters just in front of a surface are solved apart by
/// [`crate::solve::run`]; [`covered_emitter_warning`] is for the relighter, which does not.)
pub fn solve_warnings(
    kind: SolverKind,
    stats: &SolveStats,
    options: &SolverOptions,
    patches: &Patches,
) -> Vec<Warning> {
    memory_warning(stats.memory.as_ref())
        .into_iter()
        .chain(cap_warning(kind.name(), stats, options, patches))
        .chain(direct_light_warning(stats, options))
        .chain(capped_rows_warning(kind.name(), stats))
        .chain(negative_warning(kind.name(), stats, options))
        .chain(bound_warning(kind.name(), stats))
        .collect()
}

/// Share of the emitted power (area times largest channel of emission) in covered emitters
/// above which [`covered_emitter_warning`] warns.
pub const COVERED_POWER: f64 = 0.01;

/// The warning for a solve that left emitters with a face (the front, or a two-sided
/// emitter's back) just in front of a surface, closer than
/// [`crate::solve::cavity::COVERED_GAP`] of their size (a luminaire's panel hung just under a
/// ceiling), in the scene, when they carry more than [`COVERED_POWER`] of the emitted power;
/// `None` otherwise, and when the solve solved their gaps on their own
/// ([`SolveStats::covered_emitters`], [`crate::solve::cavity`]: every solve but the
/// relighter's). The light such a face sends into the gap is trapped there; antiradiance
/// cancels it only approximately, so the rest of the scene comes out too bright: b90_office
/// two-sided, whose fluorescent panels hang 0.76 mm under its ceiling, 17.6% from its
/// path-traced reference (bias +17%) solved with the panels as given.
pub fn covered_emitter_warning(patches: &Patches, stats: &SolveStats) -> Option<Warning> {
    if stats.covered_emitters > 0 {
        return None;
    }
    let cavities = crate::solve::cavity::Cavities::find(patches)?;
    let power =
        |p: usize| patches.area[p] * patches.emission[p].iter().copied().fold(0.0, f64::max);
    let total: f64 = (0..patches.len())
        .filter(|&p| patches.active[p] && patches.is_emitter(p))
        .map(power)
        .sum();
    let share = cavities
        .trapped
        .iter()
        .map(|t| power(t.emitter as usize))
        .sum::<f64>()
        / total;
    (share > COVERED_POWER).then(|| {
        Warning::new(
            WarningKind::CoveredEmitter,
            format!(
                "{} ({:.0}% of the emitted power) face a surface closer than {:.0}% of their size: the light they send into that gap is trapped there, which antiradiance cancels only approximately, so the rest of the scene can come out too bright (solve the scene with the solve command, which solves such gaps on their own)",
                plural(cavities.len(), "emitting triangle", "emitting triangles"),
                100.0 * share,
                100.0 * crate::solve::cavity::COVERED_GAP
            ),
        )
    })
}

/// The warning for a solve whose largest B is above 1 + [`crate::solve::health::BOUND_WARNING`] times
/// the bound `E_max / (1 - rho_max)` (but not above 1 + [`crate::solve::health::BOUND_SLACK`], which
/// fails the solve); `None` otherwise.
pub fn bound_warning(solver: &str, stats: &SolveStats) -> Option<Warning> {
    let warn = |message: String| Warning::new(WarningKind::OverBound, message);
    let ratio = stats.largest_b_over_bound;
    (stats.failure.is_none() && ratio > 1.0 + crate::solve::health::BOUND_WARNING).then(|| {
        warn(format!(
            "the {solver} solver's largest radiance is {ratio:.3} times the bound E_max/(1 - rho_max) = {:.6} the emission and albedos allow: some patches are brighter than the light can make them (cluster links or antiradiance bins too coarse; a smaller SolverOptions::epsilon or more SolverOptions::bins usually lowers it)",
            stats.radiance_bound
        )
    )})
}

/// The warning for a solve that scaled form-factor rows down to 1 (a convex enclosure whose
/// rows summed above 1 + [`crate::solve::health::ROW_SUM_TOLERANCE`]; `None` when none was).
pub fn capped_rows_warning(solver: &str, stats: &SolveStats) -> Option<Warning> {
    let warn = |message: String| Warning::new(WarningKind::CappedRows, message);
    (stats.capped_rows > 0).then(|| {
        warn(format!(
            "the {solver} solver scaled {} down to 1: in this convex enclosure their form factors summed to up to {:.6} (more than 1 + {:.0e}, discretization error that 1/(1 - rho) would amplify)",
            plural(stats.capped_rows, "form-factor row", "form-factor rows"),
            stats.max_row_sum,
            crate::solve::health::ROW_SUM_TOLERANCE
        )
    )})
}

/// The warning for a solve whose negative radiance mass is above
/// [`crate::solve::health::NEGATIVE_WARNING`] of the positive (but not above
/// [`crate::solve::health::NEGATIVE_LIMIT`], which fails the solve); `None` otherwise.
pub fn negative_warning(
    solver: &str,
    stats: &SolveStats,
    options: &SolverOptions,
) -> Option<Warning> {
    let warn = |message: String| Warning::new(WarningKind::NegativeRadiance, message);
    (stats.failure.is_none() && stats.negative_fraction > crate::solve::health::NEGATIVE_WARNING).then(|| {
        warn(format!(
            "the {solver} solver's negative radiance is {:.1}% of the positive mass (more than {:.0}%): antiradiance cancelled more light than it should{}; more SolverOptions::bins usually lowers it",
            100.0 * stats.negative_fraction,
            100.0 * crate::solve::health::NEGATIVE_WARNING,
            if options.two_sided {
                ", which two-sided antiradiance does where surfaces are doubled back to back"
            } else {
                ""
            }
        )
    )})
}

/// The warning for a solve that was changed to fit its memory limit (`None` when nothing was):
/// the limit, what was coarsened, and the estimate of the model solved.
pub fn memory_warning(memory: Option<&budget::MemoryStats>) -> Option<Warning> {
    let warn = |message: String| Warning::new(WarningKind::Memory, message);
    let m = memory?;
    if m.coarsened.is_empty() {
        return None;
    }
    Some(warn(format!(
        "the model was coarsened to fit the memory limit of {} (SolverOptions::memory_limit_bytes): {}; its estimate is {} beside the {} in use before the solve; the result is less accurate than asked",
        format_bytes(m.limit_bytes),
        m.coarsened.join(", "),
        format_bytes(m.estimate_bytes),
        format_bytes(m.base_bytes)
    )))
}

/// The warning for a solve that was asked for exact direct light but skipped it because the
/// scene's emitters were over [`direct::DIRECT_LIGHT_BUDGET`] (`None` otherwise; a direct light
/// skipped to fit the memory limit is in [`memory_warning`]).
pub fn direct_light_warning(stats: &SolveStats, options: &SolverOptions) -> Option<Warning> {
    let warn = |message: String| Warning::new(WarningKind::DirectLightSkipped, message);
    let for_memory = stats
        .memory
        .as_ref()
        .is_some_and(|m| m.coarsened.iter().any(|c| c == direct::DIRECT_LIGHT_OFF));
    (options.direct_light && stats.direct_light_skipped && !for_memory).then(|| {
        warn(format!(
            "exact direct light skipped: receivers x emitter groups is over {:.0e}; antiradiance carried every bounce (SolverOptions::direct_light = false silences this)",
            direct::DIRECT_LIGHT_BUDGET as f64,
        )
    )})
}

/// The warning for a solve that stopped at the iteration cap (`None` when it converged or
/// diverged): the
/// solver, the iterations, the last residual against the tolerance and, since the residual
/// underestimates the remaining error when the iteration contracts slowly, an estimate of that
/// error and of the iterations still needed, taking the contraction per sweep to be the highest
/// albedo of the scene (exact for a closed box of one albedo, an upper bound otherwise).
pub fn cap_warning(
    solver: &str,
    stats: &SolveStats,
    options: &SolverOptions,
    patches: &Patches,
) -> Option<Warning> {
    let warn = |message: String| Warning::new(WarningKind::IterationCap, message);
    if stats.converged || stats.failure.is_some() {
        return None;
    }
    let rho = (0..patches.len())
        .filter(|&p| patches.active[p])
        .flat_map(|p| patches.albedo[p])
        .fold(0.0f64, f64::max)
        .min(MAX_CONTRACTION);
    let r = solution::sanitize(stats.residual);
    let mut text = format!(
        "the {solver} solver stopped at the iteration cap ({} iterations) without converging: last residual {r:.2e}, tolerance {:.1e}; the result is not the converged solution",
        stats.iterations, options.tol
    );
    if rho > 0.0 && r > 0.0 {
        let remaining = r * rho / (1.0 - rho);
        let more = ((options.tol * (1.0 - rho) / (r * rho)).ln() / rho.ln()).ceil();
        text += &format!(
            " (its remaining error may be as large as {:.2}% of B: residual x rho/(1 - rho) with the highest albedo rho = {rho})",
            100.0 * remaining
        );
        if more.is_finite() && more > 0.0 {
            text += &format!(
                "; raise SolverOptions::max_iterations (to about {} at this rate)",
                stats.iterations as f64 + more
            );
        } else {
            text += "; raise SolverOptions::max_iterations or SolverOptions::tol";
        }
    } else {
        text += "; raise SolverOptions::max_iterations or SolverOptions::tol";
    }
    Some(warn(text))
}

/// `n` and the noun in singular or plural (`plural(2, "row", "rows")`).
fn plural(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}
