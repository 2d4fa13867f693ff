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
//!   the per-sweep state from elements x stored bins once the live bins are known;
//! - the pair cache and the Anderson history, which only buy speed, get what is left;
//! - the exact direct light ([`direct_light_bytes`]) is skipped when it does not fit;
//! - the dense solver ([`dense_bytes`]) refuses with [`Error::Memory`] when it does not fit.
//!
//! When the hierarchical model does not fit, [`Prepared::new`](crate::solve::hierarchical::Prepared::new)
//! coarsens it step by step: the pair cache off first, then epsilon doubled up to
//! [`MAX_COARSE_EPSILON`], then the split depth lowered by two down to 0, then two bins per side
//! fewer down to [`MIN_COARSE_BINS`] ([`coarser`]).
//! When even the coarsest model does not fit, the solve ends with [`Error::Memory`] before the
//! large arrays are allocated. What was coarsened is reported ([`MemoryStats`]).
//!
//! Sizes are in bytes; the suffixes of [`parse_size`] and the figures of
//! [`crate::solve::memory::format_bytes`] are powers of 1024.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use serde::Serialize;

use crate::error::Error;
use crate::hierarchy::links::ClusterLink;
use crate::hierarchy::Node;
use crate::solve::memory;
use crate::solve::SolverOptions;
use crate::transport::{Entry, PatchGeom};

/// The memory limit where the machine's physical memory is unknown (off Linux): 4 GiB.
pub const FALLBACK_MEMORY_LIMIT: u64 = 4 << 30;

/// Largest epsilon coarsening raises a model's epsilon to (mean bins; see
/// [`SolverOptions::epsilon`]).
pub const MAX_COARSE_EPSILON: f64 = 8.0;

/// The epsilon coarsening starts from for a model refined to element pairs (epsilon 0).
pub const FIRST_COARSE_EPSILON: f64 = 0.25;

/// Fewest bins per side coarsening lowers a model's bins to.
pub const MIN_COARSE_BINS: usize = 4;

/// Bins per side one coarsening step removes.
const BIN_STEP: usize = 2;

/// How much one coarsening step lowers the split depth ([`SolverOptions::split_depth`]), down
/// to 0 (the input mesh, no on-demand splits).
const SPLIT_STEP: u8 = 2;

/// Node pairs a task of the link traversal visits between two budget checks.
pub const CHECK_EVERY: usize = 4096;

/// Coupling entries per exact element pair assumed before they are computed (measured: 1.6 on
/// the office mesh at epsilon 8, 1.7 and 2.1 on the seed room at `accurate` and `default`, 2.3
/// on the bear, 2.9 on the Cornell box); the couplings are counted as they are computed.
pub const ENTRIES_PER_PAIR: u64 = 2;

/// Share of an estimate added for what it does not count (allocator slack, thread stacks and
/// per-thread buffers, small arrays): an estimate `e` must fit as `e + e / SLACK_DIVISOR +
/// SLACK_BYTES`.
const SLACK_DIVISOR: u64 = 8;

/// Bytes added to every estimate (see [`SLACK_DIVISOR`]).
const SLACK_BYTES: u64 = 16 << 20;

/// Bytes per patch of the shadow-ray scene (obvhs CWBVH, its build, the slot map).
const RAY_SCENE_BYTES_PER_PATCH: u64 = 256;

/// Bytes per emitter of the direct light's emitters and groups (geometry, boundary, hash maps of
/// the grouping).
const DIRECT_BYTES_PER_EMITTER: u64 = 1024;

/// Bytes per patch of the tree's build (obvhs BVH2 over the patches, freed once copied).
const TREE_BUILD_BYTES_PER_PATCH: u64 = 160;

/// Bytes per patch of a solution and of the solvers' per-patch arrays (radiance per patch and
/// per input triangle, sums, areas).
const SOLUTION_BYTES_PER_PATCH: u64 = 128;

/// The default memory limit: half the machine's physical memory (`MemTotal` of `/proc/meminfo`
/// on Linux), [`FALLBACK_MEMORY_LIMIT`] where that is unknown.
pub fn default_memory_limit() -> u64 {
    memory::physical_memory_bytes().map_or(FALLBACK_MEMORY_LIMIT, |m| m / 2)
}

/// Parses a size in bytes: a whole number of bytes (`1000000`), or a number with a suffix `K`,
/// `M`, `G` or `T` (powers of 1024, optionally followed by `B` or `iB`, any case: `512M`, `4G`,
/// `4GB`, `1.5G`, `64KiB`). The size must be at least 1 byte and below 2^64.
pub fn parse_size(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let bad =
        || format!("'{text}' is not a size (bytes, or a number with K, M, G or T: 512M, 4G, 1.5G)");
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (number, suffix) = t.split_at(split);
    let suffix = suffix.trim().to_ascii_uppercase();
    let unit = suffix
        .strip_suffix("IB")
        .or_else(|| suffix.strip_suffix('B'))
        .unwrap_or(&suffix);
    let multiplier: u64 = match unit {
        "" => 1,
        "K" => 1 << 10,
        "M" => 1 << 20,
        "G" => 1 << 30,
        "T" => 1 << 40,
        _ => return Err(bad()),
    };
    // "iB" alone is no unit.
    if unit.is_empty() && suffix.contains('I') {
        return Err(bad());
    }
    if number.is_empty() || number.matches('.').count() > 1 {
        return Err(bad());
    }
    let bytes = if multiplier == 1 {
        number
            .parse::<u64>()
            .map_err(|_| format!("'{text}': a size in bytes must be a whole number"))?
    } else {
        let x: f64 = number.parse().map_err(|_| bad())?;
        let bytes = x * multiplier as f64;
        if !(bytes.is_finite() && bytes < u64::MAX as f64) {
            return Err(format!("'{text}' is too large"));
        }
        bytes as u64
    };
    if bytes == 0 {
        return Err(format!("'{text}': the size must be at least 1 byte"));
    }
    Ok(bytes)
}

/// What one solve may allocate: the limit on the process's resident memory, less what the
/// process already holds when the solve starts (the scene and its patches).
#[derive(Clone, Copy, Debug)]
pub struct Budget {
    /// The limit on the process's resident memory, bytes.
    pub limit: u64,
    /// Resident memory when the solve started, bytes (0 where it cannot be measured).
    pub base: u64,
}

impl Budget {
    /// The budget of a solve starting now under `limit` bytes.
    pub fn start(limit: u64) -> Budget {
        Budget {
            limit,
            base: memory::current_rss_bytes().unwrap_or(0),
        }
    }

    /// Bytes the solve may allocate (the limit less the resident memory at the start).
    pub fn available(&self) -> u64 {
        self.limit.saturating_sub(self.base)
    }

    /// True when an estimate of `bytes` fits, with the slack estimates need (see
    /// [`SLACK_DIVISOR`]).
    pub fn fits(&self, bytes: u64) -> bool {
        with_slack(bytes) <= self.available()
    }

    /// Bytes left for optional arrays (pair cache, acceleration history) once `committed`
    /// bytes are estimated, slack included.
    pub fn spare(&self, committed: u64) -> u64 {
        self.available().saturating_sub(with_slack(committed))
    }

    /// The one-line error for `what` whose estimate reached `bytes` (slack not included; a
    /// refinement stopped early counts what it had recorded) and does not fit, with `advice`
    /// (what to change) at the end.
    pub fn does_not_fit(&self, what: &str, bytes: u64, advice: &str) -> Error {
        let fmt = crate::solve::memory::format_bytes;
        let used = if self.base > 0 {
            format!(" beside the {} the process already holds", fmt(self.base))
        } else {
            String::new()
        };
        Error::Memory(format!(
            "does not fit the memory limit of {} (--memory-limit): {what} reached an estimated {}{used}; {advice}",
            fmt(self.limit),
            fmt(with_slack(bytes)),
        ))
    }
}

/// An estimate with its slack (see [`SLACK_DIVISOR`]).
fn with_slack(bytes: u64) -> u64 {
    bytes
        .saturating_add(bytes / SLACK_DIVISOR)
        .saturating_add(SLACK_BYTES)
}

/// Counts of a hierarchical model, exact or partial, from which its memory is estimated
/// ([`HierarchicalCosts::bytes`]). `None` fields are estimated from the others.
#[derive(Clone, Copy, Debug, Default)]
pub struct ModelCounts {
    /// Patches of the scene.
    pub patches: u64,
    /// Tree nodes.
    pub nodes: u64,
    /// Elements (leaf triangles after on-demand splits).
    pub elements: u64,
    /// Cluster links.
    pub cluster_links: u64,
    /// Exact element pairs.
    pub exact_pairs: u64,
    /// Coupling entries of the exact pairs; `None`: [`ENTRIES_PER_PAIR`] per pair.
    pub entries: Option<u64>,
    /// Stored antiradiance slots (live bins); `None`: half of every element's bins.
    pub slots: Option<u64>,
    /// Normal groups of the sender nodes; `None`: one per element.
    pub groups: Option<u64>,
}

/// Bytes per counted item of a hierarchical model with a given bin count and channel count.
#[derive(Clone, Copy, Debug)]
pub struct HierarchicalCosts {
    /// Direction bins (all of them, `bins_per_side^2`).
    bins: u64,
    /// Colour channels of the sweep state (1 for a grey scene, else 3).
    channels: u64,
}

impl HierarchicalCosts {
    /// The costs of a model with `bins_per_side`^2 bins solved in `channels` channels.
    pub fn new(bins_per_side: usize, channels: usize) -> HierarchicalCosts {
        HierarchicalCosts {
            bins: (bins_per_side * bins_per_side) as u64,
            channels: channels as u64,
        }
    }

    /// Estimated peak bytes of a hierarchical solve with these counts, without the optional
    /// pair cache and acceleration history: the larger of the peak of link refinement (tree,
    /// cluster-link keys becoming links, exact couplings and their assembly) and the peak of
    /// the sweeps (tree, links, element arrays, sender groups, stored bins, state, link
    /// intensities, solution).
    pub fn bytes(&self, c: &ModelCounts) -> u64 {
        let (nb, ch) = (self.bins, self.channels);
        let words = nb.div_ceil(64);
        let n = c.elements;
        let entries = c
            .entries
            .unwrap_or(c.exact_pairs.saturating_mul(ENTRIES_PER_PAIR));
        let slots = c.slots.unwrap_or(n.saturating_mul(nb.div_ceil(2)));
        let groups = c.groups.unwrap_or(n);
        let tree = c.nodes * size_of::<Node>() as u64;
        let link = size_of::<ClusterLink>() as u64;
        let entry = size_of::<Entry>() as u64;
        // Exact links as held: sender and entry start per link, entries.
        let exact = c.exact_pairs * 8 + entries * entry;
        // The couplings as computed, per receiver (senders, entry counts, entries, in vectors
        // grown by doubling); once copied into the final arrays they are freed, but the allocator
        // keeps such small blocks resident (measured on the office mesh: 1.04 GB of rows for
        // 0.68 GB of final arrays, and the resident memory stayed up).
        let rows = exact + exact / 2;
        // Refinement: keys (8 bytes) becoming links, the exact pairs, their rows and the final
        // arrays, receiver geometry.
        let refine = tree
            + c.cluster_links * (8 + link)
            + c.exact_pairs * 8
            + rows
            + exact
            + n * (size_of::<PatchGeom>() as u64 + 12)
            + c.nodes * 4;
        // Sweeps: links, the rows the allocator kept, per-element arrays (area, normal, centroid, albedo, patch, element
        // node, emission and albedo in the state's channels, change sums, live-bin mask and
        // start, RGB radiance of the result and of the returned state), groups and their
        // per-sweep sums, live-bin masks, radiance (two copies and the returned state) and
        // antiradiance slots (two copies and the returned state), link intensities, solution.
        let links = c.cluster_links * link + c.nodes * 4 + exact + n * 4;
        let elements = n * (88 + 16 * ch + 24 + 8 * words + 4 + 48);
        let group = groups * (36 + 12 + 24 * (1 + nb) + 8 * ch * (1 + nb)) + n * 4;
        let state = slots * 4 * ch * 3 + n * 8 * ch * 2;
        let sweeps = tree
            + links
            + rows
            + elements
            + group
            + c.nodes * words * 8
            + state
            + c.cluster_links * 8 * ch
            + c.patches * SOLUTION_BYTES_PER_PATCH;
        refine.max(sweeps)
    }

    /// Bytes of the tree alone for `patches` patches (before any link: the nodes of a binary
    /// tree over them and its build), the least a hierarchical solve needs.
    pub fn tree_bytes(patches: u64) -> u64 {
        patches * (2 * size_of::<Node>() as u64 + TREE_BUILD_BYTES_PER_PATCH)
    }
}

/// Why a link refinement stopped before it finished: the estimate of the model it was building
/// exceeded the budget.
#[derive(Clone, Copy, Debug)]
pub struct OverBudget {
    /// The estimate when it stopped (bytes, without slack).
    pub estimate: u64,
}

/// The budget of one link refinement: the costs of the model being refined and the bytes it may
/// take.
#[derive(Clone, Copy, Debug)]
pub struct LinkBudget {
    /// Bytes per counted item.
    pub costs: HierarchicalCosts,
    /// The budget of the solve.
    pub budget: Budget,
    /// Patches of the scene.
    pub patches: u64,
}

impl LinkBudget {
    /// No limit (tests and benches that refine links on their own).
    pub fn unlimited(bins_per_side: usize) -> LinkBudget {
        LinkBudget {
            costs: HierarchicalCosts::new(bins_per_side, 3),
            budget: Budget {
                limit: u64::MAX,
                base: 0,
            },
            patches: 0,
        }
    }

    /// `Ok` with the estimate when a model of `counts` fits, else the [`OverBudget`] outcome.
    pub fn check(&self, counts: &ModelCounts) -> Result<u64, OverBudget> {
        let counts = ModelCounts {
            patches: self.patches,
            ..*counts
        };
        let estimate = self.costs.bytes(&counts);
        if self.budget.fits(estimate) {
            Ok(estimate)
        } else {
            Err(OverBudget { estimate })
        }
    }
}

/// Counts what the parallel tasks of one traversal round (or of the exact couplings) record, on
/// top of what earlier rounds hold, and says when their estimate exceeds the budget. Once over,
/// it stays over: every task then stops.
#[derive(Debug)]
pub struct Meter<'a> {
    budget: &'a LinkBudget,
    base: ModelCounts,
    cluster_links: AtomicU64,
    exact_pairs: AtomicU64,
    entries: AtomicU64,
    /// Exact pairs whose entries `entries` counts (the rest are estimated).
    coupled: AtomicU64,
    over: AtomicBool,
    estimate: AtomicU64,
}

impl<'a> Meter<'a> {
    /// A meter over `base` (the counts already held; with `entries: Some(_)` the coupling phase,
    /// whose not yet coupled pairs are estimated at [`ENTRIES_PER_PAIR`]).
    pub fn new(budget: &'a LinkBudget, base: ModelCounts) -> Meter<'a> {
        Meter {
            budget,
            base,
            cluster_links: AtomicU64::new(0),
            exact_pairs: AtomicU64::new(0),
            entries: AtomicU64::new(0),
            coupled: AtomicU64::new(0),
            over: AtomicBool::new(false),
            estimate: AtomicU64::new(0),
        }
    }

    /// Adds what a task recorded since its last call (cluster links, exact pairs; coupled exact
    /// pairs and their entries) and checks the estimate: false once it is over the budget.
    pub fn add(&self, cluster_links: u64, exact_pairs: u64, coupled: u64, entries: u64) -> bool {
        if self.is_over() {
            return false;
        }
        let c = self
            .cluster_links
            .fetch_add(cluster_links, Ordering::Relaxed)
            + cluster_links;
        let e = self.exact_pairs.fetch_add(exact_pairs, Ordering::Relaxed) + exact_pairs;
        let k = self.coupled.fetch_add(coupled, Ordering::Relaxed) + coupled;
        let x = self.entries.fetch_add(entries, Ordering::Relaxed) + entries;
        let exact = self.base.exact_pairs + e;
        let counts = ModelCounts {
            cluster_links: self.base.cluster_links + c,
            exact_pairs: exact,
            entries: self
                .base
                .entries
                .map(|e0| e0 + x + exact.saturating_sub(k) * ENTRIES_PER_PAIR),
            ..self.base
        };
        match self.budget.check(&counts) {
            Ok(_) => true,
            Err(over) => {
                self.estimate.store(over.estimate, Ordering::Relaxed);
                self.over.store(true, Ordering::Relaxed);
                false
            }
        }
    }

    /// True once the estimate went over the budget.
    pub fn is_over(&self) -> bool {
        self.over.load(Ordering::Relaxed)
    }

    /// The outcome when [`Meter::is_over`].
    pub fn over_budget(&self) -> OverBudget {
        OverBudget {
            estimate: self.estimate.load(Ordering::Relaxed),
        }
    }
}

/// The next coarser hierarchical model after `options` and what changed (`"epsilon 1 -> 2"`,
/// `"split depth 4 -> 2"`, `"bins 8x8 -> 6x6"`), or `None` when it is the coarsest: epsilon
/// doubles (from 0 to [`FIRST_COARSE_EPSILON`]) up to [`MAX_COARSE_EPSILON`], then the split
/// depth goes down by two to 0, then the bins per side go down by two to [`MIN_COARSE_BINS`].
/// A value already beyond those limits is left as it is.
///
/// Splits come before bins: the bins set the directional resolution of every shadow, the
/// on-demand splits only refine large triangles next to small ones, and on a mesh of slivers
/// they are what multiplies the exact pairs (the office mesh at epsilon 8: 38M cluster links
/// and 17M exact pairs at split depth 4, 0.4M and 7.2M at depth 0).
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
    if options.split_depth > 0 {
        next.split_depth = options.split_depth.saturating_sub(SPLIT_STEP);
        let step = format!(
            "split depth {} -> {}",
            options.split_depth, next.split_depth
        );
        return Some((next, step));
    }
    if options.bins > MIN_COARSE_BINS {
        next.bins = options.bins.saturating_sub(BIN_STEP).max(MIN_COARSE_BINS);
        let step = format!("bins {0}x{0} -> {1}x{1}", options.bins, next.bins);
        return Some((next, step));
    }
    None
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
/// receiver its element, its unoccluded light from each emitter group that lights it (at most
/// `groups`, at most `emitters` when `None`), its shadow-ray weight and its source.
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

    #[test]
    fn coarsening_doubles_epsilon_then_lowers_bins() {
        let mut options = SolverOptions::default();
        let mut steps = Vec::new();
        while let Some((next, step)) = coarser(&options) {
            steps.push(step);
            options = next;
        }
        assert_eq!(
            steps,
            [
                "epsilon 1 -> 2",
                "epsilon 2 -> 4",
                "epsilon 4 -> 8",
                "split depth 4 -> 2",
                "split depth 2 -> 0",
                "bins 8x8 -> 6x6",
                "bins 6x6 -> 4x4"
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
        match memory::physical_memory_bytes() {
            Some(total) => assert_eq!(limit, total / 2),
            None => assert_eq!(limit, FALLBACK_MEMORY_LIMIT),
        }
    }
}
