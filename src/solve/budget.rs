//! The memory budget of a solve: the limit ([`SolverOptions::memory_limit_bytes`]), what each
//! part of a solve will hold (estimated from counts before it is allocated), and the steps by
//! which a hierarchical model that does not fit is coarsened.
//!
//! Every solver asks here before its large allocations:
//!
//! - the hierarchical solver's link traversal ([`crate::hierarchy::links::refine`]) counts the cluster links
//!   and exact pairs it records and stops with [`OverBudget`] as soon as the estimate of what the
//!   finished model will hold ([`HierarchicalCosts::bytes`]) exceeds the budget (checked per
//!   round and every [`CHECK_EVERY`] node pairs of each parallel task); the exact couplings are
//!   estimated from the exact pair count before they are computed and counted while they are;
//!   the per-sweep state from elements x stored bins once the live bins are known (until the
//!   links are known, the sender groups per element are those of the tree before refinement);
//! - the Anderson history is part of the fit while a coarser model remains ([`coarser`]): a
//!   model fits only with its history beside it (b90_office two-sided at 3 GB had fitted at
//!   epsilon 8 without it, and its damped sweeps diverged at sweep 82; with it the pair cache
//!   is left out and it converges in 23 sweeps). The coarsest model fits without it, and its
//!   solve extrapolates instead;
//! - the pair cache and the field links' cached terms, which only buy speed, get what the
//!   model, its fields' per-sweep sums and the history leave;
//! - the exact direct light ([`direct_light_bytes`]) is skipped when it does not fit beside the
//!   model without the solve's state ([`HierarchicalCosts::state_bytes`]), which is allocated
//!   once the direct light is freed, with the Anderson history and the direct light's result:
//!   the estimate counts the larger of the two;
//! - the dense solver ([`dense_bytes`]) refuses with [`crate::Error::Memory`] when it does not fit.
//!
//! When the hierarchical model does not fit, [`Prepared::new`](crate::solve::hierarchical::Prepared::new)
//! coarsens it step by step, each step refining the links again on the same tree (its splits
//! undone): the pair cache off first, then epsilon doubled up to
//! [`MAX_COARSE_EPSILON`], then two bins per side fewer down to [`MID_COARSE_BINS`], the split
//! depth lowered by two down to [`MID_COARSE_SPLIT_DEPTH`], the bins down to
//! [`MIN_COARSE_BINS`] and the split depth down to 0 ([`coarser`]).
//! After refinements that did not fit, a model is kept only when the solve's state and history
//! fit beside the resident memory measured then: the allocator keeps what those refinements
//! freed, and the solve's large arrays do not reuse it.
//! When even the coarsest model does not fit, the solve ends with [`crate::Error::Memory`] before the
//! large arrays are allocated. What was coarsened is reported ([`MemoryStats`]).
//!
//! Sizes are in bytes; the suffixes of [`parse_size`] and the figures of
//! [`crate::memory::format_bytes`] are powers of 1024.

use serde::Serialize;

pub use crate::hierarchy::cost::{
    HierarchicalCosts, LinkBudget, Meter, ModelCounts, OverBudget, CHECK_EVERY, ENTRIES_PER_PAIR,
    SOLUTION_BYTES_PER_PATCH,
};
pub use crate::memory::{default_memory_limit, parse_size, Budget, FALLBACK_MEMORY_LIMIT};
use crate::solve::SolverOptions;
use crate::transport::{Entry, PatchGeom};

/// Largest epsilon coarsening raises a model's epsilon to (mean bins; see
/// [`SolverOptions::epsilon`]).
pub const MAX_COARSE_EPSILON: f64 = 8.0;

/// The epsilon coarsening starts from for a model refined to element pairs (epsilon 0).
pub const FIRST_COARSE_EPSILON: f64 = 0.25;

/// Fewest bins per side coarsening lowers a model's bins to.
pub const MIN_COARSE_BINS: usize = 4;

/// Bins per side coarsening lowers a model's bins to before it lowers the split depth.
pub const MID_COARSE_BINS: usize = 6;

/// Split depth coarsening lowers a model's to before it lowers the bins below
/// [`MID_COARSE_BINS`].
pub const MID_COARSE_SPLIT_DEPTH: u8 = 2;

/// Bins per side one coarsening step removes.
const BIN_STEP: usize = 2;

/// How much one coarsening step lowers the split depth ([`SolverOptions::split_depth`]), down
/// to 0 (the input mesh, no on-demand splits).
const SPLIT_STEP: u8 = 2;

/// Bytes per patch of the shadow-ray scene (obvhs CWBVH, its build, the slot map).
const RAY_SCENE_BYTES_PER_PATCH: u64 = 256;

/// Bytes per emitter of the direct light's emitters and groups (geometry, boundary, hash maps of
/// the grouping).
const DIRECT_BYTES_PER_EMITTER: u64 = 1024;

/// The next coarser hierarchical model after `options` and what changed (`"epsilon 1 -> 2"`,
/// `"bins 8x8 -> 6x6"`, `"split depth 4 -> 2"`), or `None` when it is the coarsest: epsilon
/// doubles (from 0 to [`FIRST_COARSE_EPSILON`]) up to [`MAX_COARSE_EPSILON`]; then the bins
/// per side go down by two to [`MID_COARSE_BINS`], the split depth by two to
/// [`MID_COARSE_SPLIT_DEPTH`], the bins to [`MIN_COARSE_BINS`] and the split depth to 0. A
/// value already beyond those limits is left as it is.
///
/// The order is the one that lost least accuracy for the memory it saved, measured at epsilon
/// 8 against path-traced references (docs/performance.md, "Memory budget"): from 8x8 bins and
/// split depth 4, 6x6 bins saved 19% of b90_office's estimate and 14% of the generated
/// classroom's, at 2.73% -> 2.67% and 1.44% -> 1.84% from their references; split depth 2
/// saved 6% and 27%, at 3.06% and 1.96%; split depth 0, the input mesh, 15% and 49%, at 3.65%
/// and 5.66%: the large triangles beside small objects lose the resolution their shadows need.
pub fn coarser(options: &SolverOptions) -> Option<(SolverOptions, String)> {
    let mut next = options.clone();
    if options.epsilon < MAX_COARSE_EPSILON {
        next.epsilon = if options.epsilon > 0.0 {
            (2.0 * options.epsilon).min(MAX_COARSE_EPSILON)
        } else {
            FIRST_COARSE_EPSILON
        };
        let step = format!("epsilon {} -> {}", options.epsilon, next.epsilon);
        return Some((next, step));
    }
    let bins_to = |floor: usize, next: &mut SolverOptions| {
        (options.bins > floor).then(|| {
            next.bins = options.bins.saturating_sub(BIN_STEP).max(floor);
            format!("bins {0}x{0} -> {1}x{1}", options.bins, next.bins)
        })
    };
    let split_to = |floor: u8, next: &mut SolverOptions| {
        (options.split_depth > floor).then(|| {
            next.split_depth = options.split_depth.saturating_sub(SPLIT_STEP).max(floor);
            format!(
                "split depth {} -> {}",
                options.split_depth, next.split_depth
            )
        })
    };
    let step = bins_to(MID_COARSE_BINS, &mut next)
        .or_else(|| split_to(MID_COARSE_SPLIT_DEPTH, &mut next))
        .or_else(|| bins_to(MIN_COARSE_BINS, &mut next))
        .or_else(|| split_to(0, &mut next))?;
    Some((next, step))
}

/// What a solve's memory budget did, for the report's `stats.memory`.
#[derive(Clone, Debug, Default, Serialize)]
pub struct MemoryStats {
    /// The limit on the process's resident memory, bytes ([`SolverOptions::memory_limit_bytes`]).
    pub limit_bytes: u64,
    /// Resident memory of the process when the solve started (scene, patches), bytes; counted
    /// against the limit (0 where it cannot be measured).
    pub base_bytes: u64,
    /// Estimated peak of the solve above `base_bytes` for the model solved, bytes (slack not
    /// included).
    pub estimate_bytes: u64,
    /// The process's peak resident memory when the solve ended (`VmHWM`), bytes; `None` off
    /// Linux.
    pub peak_bytes: Option<u64>,
    /// What was changed to fit, in order (`"epsilon 1 -> 2"`, `"split depth 4 -> 2"`, `"bins
    /// 8x8 -> 6x6"`, `"pair cache off"`, `"exact direct light off"`, `"Anderson acceleration
    /// off"`); empty when the solve fitted as asked.
    pub coarsened: Vec<String>,
    /// Link refinements run: 1 when the first model fitted, one more per coarsening of epsilon
    /// or bins (0 for the dense solver).
    pub attempts: u32,
    /// Epsilon of the model solved.
    pub epsilon: f64,
    /// Bins per side of the model solved.
    pub bins: usize,
    /// Split depth of the model solved (0 for the dense solver).
    pub split_depth: u8,
    /// Seconds spent on the refinements that did not fit (the solve's `stage_seconds` are
    /// those of the model solved).
    pub discarded_seconds: f64,
}

/// Estimated bytes of the exact direct light for `patches` patches, `emitters` emitting patches
/// and `receivers` receiving elements: the shadow-ray scene and the emitter groups, then per
/// receiver its element, its unoccluded light from each emitter group that lights it (`groups`
/// per receiver: [`crate::solve::direct::DirectLight::lights_per_receiver`], or every emitter
/// when `None`), its shadow-ray weight and its source.
pub fn direct_light_bytes(patches: u64, emitters: u64, receivers: u64, groups: Option<u64>) -> u64 {
    let groups = groups.unwrap_or(emitters);
    patches * RAY_SCENE_BYTES_PER_PATCH
        + emitters * DIRECT_BYTES_PER_EMITTER
        + receivers * (112 + 48 + 8 + 24 + groups.saturating_mul(16))
        + patches * SOLUTION_BYTES_PER_PATCH
}

/// Estimated bytes of the dense solver for `patches` patches, `bins_per_side`^2 bins and
/// receivers of up to `quadrature`^2 points, before its near pairs (counted as they are
/// computed, [`dense_near_pair_bytes`]): radiance and antiradiance (two copies each), patch
/// geometry, receivers with their points, solution.
pub fn dense_bytes(patches: u64, bins_per_side: usize, quadrature: usize) -> u64 {
    let nb = (bins_per_side * bins_per_side) as u64;
    let q2 = (quadrature * quadrature) as u64;
    let receiver = 256 + q2 * 25 + q2.div_ceil(4) * 96;
    patches * (2 * 24 + 2 * 12 * nb + size_of::<Option<PatchGeom>>() as u64 + 8 + receiver)
        + patches * SOLUTION_BYTES_PER_PATCH
}

/// Bytes of one cached near pair of the dense solver with `entries` coupling entries.
pub fn dense_near_pair_bytes(entries: usize) -> u64 {
    let inline = size_of::<(u32, crate::transport::Coupling)>() as u64;
    let spilled = if entries > 4 {
        (entries * size_of::<Entry>()) as u64
    } else {
        0
    };
    inline + spilled
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_size("1000000"), Ok(1_000_000));
        assert_eq!(parse_size("512M"), Ok(512 << 20));
        assert_eq!(parse_size("4G"), Ok(4 << 30));
        assert_eq!(parse_size("4GB"), Ok(4 << 30));
        assert_eq!(parse_size("4gib"), Ok(4 << 30));
        assert_eq!(parse_size("1.5G"), Ok(3 << 29));
        assert_eq!(parse_size(" 64 KiB "), Ok(64 << 10));
        assert_eq!(parse_size("2T"), Ok(2 << 40));
        assert_eq!(parse_size("12B"), Ok(12));
        for bad in [
            "",
            "G",
            "-1G",
            "1.5",
            "0",
            "0M",
            "abc",
            "4X",
            "4 G B",
            "1e3M",
            "1..2G",
            "nanG",
            "99999999999T",
            "iB",
            "5iB",
        ] {
            assert!(parse_size(bad).is_err(), "{bad:?} accepted");
        }
        let message = parse_size("4X").unwrap_err();
        assert!(
            !message.contains('\n') && message.contains("4X"),
            "{message}"
        );
    }

    /// Every coarsening step from `options` to the coarsest model.
    fn steps_from(mut options: SolverOptions) -> Vec<String> {
        let mut steps = Vec::new();
        while let Some((next, step)) = coarser(&options) {
            steps.push(step);
            options = next;
        }
        steps
    }

    #[test]
    fn coarsening_doubles_epsilon_then_lowers_bins_and_splits_in_turn() {
        assert_eq!(
            steps_from(SolverOptions::default()),
            [
                "epsilon 1 -> 2",
                "epsilon 2 -> 4",
                "epsilon 4 -> 8",
                "bins 8x8 -> 6x6",
                "split depth 4 -> 2",
                "bins 6x6 -> 4x4",
                "split depth 2 -> 0",
            ]
        );
        // The accurate preset's 12x12 bins come down to 6x6 first; odd values keep their step.
        assert_eq!(
            steps_from(SolverOptions {
                epsilon: 8.0,
                bins: 12,
                split_depth: 5,
                ..SolverOptions::default()
            }),
            [
                "bins 12x12 -> 10x10",
                "bins 10x10 -> 8x8",
                "bins 8x8 -> 6x6",
                "split depth 5 -> 3",
                "split depth 3 -> 2",
                "bins 6x6 -> 4x4",
                "split depth 2 -> 0",
            ]
        );
        let exact = SolverOptions {
            epsilon: 0.0,
            bins: 3,
            split_depth: 0,
            ..SolverOptions::default()
        };
        let (next, _) = coarser(&exact).expect("epsilon 0 can be coarsened");
        assert_eq!(next.epsilon, FIRST_COARSE_EPSILON);
        let coarsest = SolverOptions {
            epsilon: 10.0,
            bins: 3,
            split_depth: 0,
            ..SolverOptions::default()
        };
        assert!(coarser(&coarsest).is_none());
    }

    #[test]
    fn estimates_grow_with_what_they_count() {
        let costs = HierarchicalCosts::new(8, 3);
        let base = ModelCounts {
            patches: 1000,
            nodes: 2000,
            elements: 1000,
            ..ModelCounts::default()
        };
        let small = costs.bytes(&base);
        for more in [
            ModelCounts {
                cluster_links: 1_000_000,
                ..base
            },
            ModelCounts {
                exact_pairs: 1_000_000,
                ..base
            },
            ModelCounts {
                elements: 100_000,
                ..base
            },
        ] {
            assert!(costs.bytes(&more) > small + 10_000_000);
        }
        // Fewer bins and one channel cost less.
        let links = ModelCounts {
            cluster_links: 1_000_000,
            ..base
        };
        assert!(HierarchicalCosts::new(4, 1).bytes(&links) < costs.bytes(&links));
    }

    #[test]
    fn a_meter_stays_over_once_over() {
        let budget = LinkBudget {
            costs: HierarchicalCosts::new(8, 1),
            budget: Budget {
                limit: 100 << 20,
                base: 0,
            },
            patches: 10,
            reserve_per_element: 0,
        };
        let meter = Meter::new(&budget, ModelCounts::default());
        assert!(meter.add(1000, 10, 0, 0));
        assert!(!meter.is_over());
        assert!(!meter.add(10_000_000, 0, 0, 0));
        assert!(meter.is_over());
        assert!(!meter.add(0, 0, 0, 0));
        assert!(meter.over_budget().estimate > 100 << 20);
    }

    #[test]
    fn default_limit_is_half_the_machine() {
        let limit = default_memory_limit();
        match crate::memory::physical_memory_bytes() {
            Some(total) => assert_eq!(limit, total / 2),
            None => assert_eq!(limit, FALLBACK_MEMORY_LIMIT),
        }
    }
}
