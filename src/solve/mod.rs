//! Stage 6: the solvers. Options and presets ([`options`]), the shared iteration steps, the
//! dense oracle ([`dense`]), the hierarchical solver ([`hierarchical`]), exact direct light
//! ([`direct`]), relighting ([`relight`]), health checks, the memory budget and what every
//! solver returns ([`solution`]).

pub mod accelerate;
pub mod budget;
pub mod cavity;
pub mod convergence;
pub mod dense;
pub mod direct;
pub mod health;
pub mod hierarchical;
pub mod model;
pub mod options;
pub mod relight;
pub mod sealed;
pub mod solution;
pub mod warnings;

pub use convergence::{change_ratio, change_sums, relative_change, Convergence, MIN_SWEEPS};
pub use options::*;
pub use solution::{emission_bound, finish, source_and_albedo_max};

use serde::Serialize;

use crate::error::Result;
use crate::mesh::Patches;
use crate::progress::Progress;
use solution::Solution;

/// Which antiradiance solver to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum SolverKind {
    /// Clustered links, O(n log n) (the default).
    Hierarchical,
    /// Every pair of patches (the oracle).
    Dense,
}

impl SolverKind {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            SolverKind::Hierarchical => "hierarchical",
            SolverKind::Dense => "dense",
        }
    }
}

/// A named set of solver parameters (`SolverOptions::preset`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Preset {
    /// 6 x 6 bins, coarse links, looser tolerance.
    Fast,
    /// 8 x 8 bins, balanced.
    Default,
    /// 12 x 12 bins, fine links, tight tolerance.
    Accurate,
}

impl Preset {
    /// Every preset, fastest first.
    pub const ALL: [Preset; 3] = [Preset::Fast, Preset::Default, Preset::Accurate];

    /// The preset's options.
    pub const fn options(self) -> SolverOptions {
        match self {
            Preset::Fast => SolverOptions::fast(),
            Preset::Default => SolverOptions::default_preset(),
            Preset::Accurate => SolverOptions::accurate(),
        }
    }

    /// The preset named `name` (`fast`, `default`, `accurate`, any case), if any.
    pub fn from_name(name: &str) -> Option<Preset> {
        Preset::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(name))
    }

    /// The preset's name.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Fast => "fast",
            Preset::Default => "default",
            Preset::Accurate => "accurate",
        }
    }
}

/// Solves `patches` with the `kind` solver, with exact direct light when
/// `options.direct_light` is set ([`direct`]). Precondition: `options.validate()` passed.
///
/// Errors: [`crate::Error::Memory`] when the solve does not fit `options.memory_limit_bytes` (see
/// [`crate::solve::budget`]).
///
/// A scene in which nothing emits and that has no analytic light ([`Patches::is_dark`]) is
/// answered without a solve: radiance 0 everywhere, `stats.iterations` 0, converged.
pub fn run(
    kind: SolverKind,
    patches: &Patches,
    options: &SolverOptions,
    progress: &Progress,
) -> Result<Solution> {
    // Nothing emits and there is no analytic light: B = 0 is the answer (the only one,
    // every albedo being below 1), and no model is built for it.
    if patches.is_dark() {
        return Ok(Solution::dark(patches));
    }
    // Two-sided emitters just in front of a surface: their gaps are solved on their own, the
    // rest of the scene with them one-sided (see `cavity`).
    let cavities = if options.antiradiance {
        cavity::Cavities::find(patches)
    } else {
        None
    };
    let opened = cavities.as_ref().map(|c| c.opened(patches));
    let patches_in = patches;
    let patches = opened.as_ref().unwrap_or(patches_in);
    // Closed objects with a dark inside are solved facing out (see `mesh::closed`), when
    // backs exposed to light are blocked (the handling of files as found).
    let as_found = options.antiradiance && options.block_exposed_backs && !options.two_sided;
    let outward = if as_found {
        patches.closed_objects_outward()
    } else {
        None
    };
    let solved = outward.as_ref().map_or(patches, |(p, _)| p);
    // Faces the light does not reach are solved dark, when backs are handled as found too
    // (see `sealed`).
    let sealed = if as_found {
        sealed::blackened(solved)
    } else {
        None
    };
    let solved_before_sealing = solved;
    let (mut sealed_patches, sealed) = match sealed {
        Some((p, what)) => (Some(p), Some(what)),
        None => (None, None),
    };
    // Coplanar patches facing the same way that overlap send by the share of them that shows
    // (see `mesh::overlap`), decided on the faces as solved (closed objects turned out), a
    // surface two-sided as given left as it is, also where the steps above made one of its
    // faces dark (the MGF office two-sided, its sealed slab faces weighed: 5.15% -> 7.86% rms
    // from its references). The shares go onto the sealed copy where there is one, not a copy
    // of it.
    let shares = crate::mesh::overlap::visible_shares_of(
        sealed_patches.as_ref().unwrap_or(solved_before_sealing),
        &|p| patches.is_two_sided(p),
    );
    let overlapped = (!shares.is_empty()).then(|| {
        let mut out = sealed_patches
            .take()
            .unwrap_or_else(|| solved_before_sealing.clone());
        out.visible_shares = shares;
        out
    });
    let solved = (overlapped.as_ref())
        .or(sealed_patches.as_ref())
        .unwrap_or(solved_before_sealing);
    let solution = match (kind, options.direct_light) {
        (SolverKind::Dense, false) => dense::solve_dense(solved, options, progress),
        (SolverKind::Hierarchical, false) => {
            hierarchical::solve_hierarchical(solved, options, progress)
        }
        (SolverKind::Dense, true) => direct::solve_dense_direct(solved, options, progress),
        (SolverKind::Hierarchical, true) => {
            direct::solve_hierarchical_direct(solved, options, progress)
        }
    };
    let mut solution = solution?;
    if let Some(shown) = &overlapped {
        solution.stats.overlap = Some(solution::OverlapStats::of(shown));
    }
    // Inner first: the sealed faces were decided on the patches turned outward.
    if let Some(what) = &sealed {
        solution.restore_outward(
            &crate::mesh::closed::Outward {
                turned_two_sided: what.turned_two_sided.clone(),
                ..Default::default()
            },
            solved_before_sealing,
        );
        if let Some(model) = solution.stats.model.as_mut() {
            model.sealed_patches = what.faces;
        }
    }
    if let Some((_, turned)) = &outward {
        solution.restore_outward(turned, patches);
        if let Some(model) = solution.stats.model.as_mut() {
            model.closed_dark_objects = turned.objects;
            model.turned_outward_patches = turned.turned;
        }
    }
    if let Some(cavities) = &cavities {
        cavities.fill(&mut solution, patches_in);
        solution.stats.covered_emitters = cavities.len() as u64;
    }
    // Degenerate and duplicate triangles' patches get the values the model fixes for them,
    // whatever the solver left there.
    solution.settle_inactive(patches_in);
    Ok(solution)
}
