//! What a hierarchical model will hold, estimated from its counts before it is allocated, and the
//! meter the link refinement checks as it goes ([`LinkBudget`], [`Meter`]): the refinement stops
//! with [`OverBudget`] as soon as the estimate of the finished model exceeds the budget.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use crate::hierarchy::Node;
use crate::memory::Budget;
use crate::transport::{Entry, PatchGeom};

/// Bytes of one [`crate::hierarchy::links::ClusterLink`] (checked where it is defined, so the
/// estimate follows the type without this module depending on the links).
pub const CLUSTER_LINK_BYTES: u64 = 12;

/// Node pairs a task of the link traversal visits between two budget checks.
pub const CHECK_EVERY: usize = 4096;
/// Coupling entries per exact element pair assumed before they are computed (measured: 1.6 on
/// the office mesh at epsilon 8, 1.7 and 2.1 on the seed room at `accurate` and `default`, 2.3
/// on the bear, 2.9 on the Cornell box); the couplings are counted as they are computed.
pub const ENTRIES_PER_PAIR: u64 = 2;
/// Bytes per patch of the tree's build (obvhs BVH2 over the patches, freed once copied).
pub const TREE_BUILD_BYTES_PER_PATCH: u64 = 160;
/// Bytes per patch of a solution and of the solvers' per-patch arrays (radiance per patch and
/// per input triangle, sums, areas).
pub const SOLUTION_BYTES_PER_PATCH: u64 = 128;
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
    /// Normal groups of the sender nodes; `None`: the costs' share per element
    /// ([`HierarchicalCosts::with_group_share`], else one per element).
    pub groups: Option<u64>,
}

/// Bytes per counted item of a hierarchical model with a given bin count and channel count.
#[derive(Clone, Copy, Debug)]
pub struct HierarchicalCosts {
    /// Direction bins (all of them, `bins_per_side^2`).
    bins: u64,
    /// Colour channels of the sweep state (1 for a grey scene, else 3).
    channels: u64,
    /// Sender normal groups per element assumed while the groups are not known
    /// ([`ModelCounts::groups`] `None`); 1 unless set by [`HierarchicalCosts::with_group_share`].
    groups_per_element: f64,
}

impl HierarchicalCosts {
    /// The costs of a model with `bins_per_side`^2 bins solved in `channels` channels.
    pub fn new(bins_per_side: usize, channels: usize) -> HierarchicalCosts {
        HierarchicalCosts {
            bins: (bins_per_side * bins_per_side) as u64,
            channels: channels as u64,
            groups_per_element: 1.0,
        }
    }

    /// These costs with `share` sender normal groups per element assumed until the groups are
    /// known (measured on the tree before its links are refined: on-demand splits only add
    /// coplanar pieces, which form fewer groups per element). A share that is not finite and
    /// positive leaves the assumption at 1.
    pub fn with_group_share(self, share: f64) -> HierarchicalCosts {
        HierarchicalCosts {
            groups_per_element: if share.is_finite() && share > 0.0 {
                share
            } else {
                1.0
            },
            ..self
        }
    }

    /// Colour channels of the sweep state.
    pub fn channels(&self) -> u64 {
        self.channels
    }

    /// Estimated peak bytes of a hierarchical solve with these counts, without the optional
    /// pair cache and acceleration history: the larger of the peak of link refinement (tree,
    /// cluster-link keys becoming links, exact couplings and their assembly) and the peak of
    /// the sweeps (tree, links, element arrays, sender groups, stored bins, state, link
    /// intensities, solution).
    pub fn bytes(&self, c: &ModelCounts) -> u64 {
        let words = self.bins.div_ceil(64);
        let n = c.elements;
        let entries = c
            .entries
            .unwrap_or(c.exact_pairs.saturating_mul(ENTRIES_PER_PAIR));
        let groups = self.groups(c);
        let tree = c.nodes * size_of::<Node>() as u64;
        let link = CLUSTER_LINK_BYTES;
        let entry = size_of::<Entry>() as u64;
        // Exact links as held: sender and entry start per link, entries.
        let exact = c.exact_pairs * 8 + entries * entry;
        // The couplings as computed, per receiver (senders, entry counts, entries, in vectors
        // grown by doubling); once copied into the final arrays they are freed, but an allocator
        // keeps such small blocks resident (measured on the office mesh: 1.04 GB of rows for
        // 0.68 GB of final arrays, and the resident memory stayed up).
        let rows = exact + exact / 2;
        // What of them stays resident through the sweeps: nothing where the allocator hands
        // freed blocks back ([`crate::memory::RELEASES_FREED`]: the solver releases them once
        // the links are built).
        let rows_kept = if crate::memory::RELEASES_FREED {
            0
        } else {
            rows
        };
        // Refinement: keys (8 bytes) becoming links, the exact pairs, their rows and the final
        // arrays, receiver geometry.
        let refine = tree
            + c.cluster_links * (8 + link)
            + c.exact_pairs * 8
            + rows
            + exact
            + n * (size_of::<PatchGeom>() as u64 + 12)
            + c.nodes * 4;
        // Sweeps: what the model holds (links, the rows an allocator kept, per-element arrays:
        // area, normal, centroid, albedo, patch, element node, live-bin mask and start; groups,
        // live-bin masks, solution) and the solve's state ([`HierarchicalCosts::state_bytes`]).
        let links = c.cluster_links * link + c.nodes * (4 + 16) + exact + n * 4;
        let elements = n * (88 + 24 + 8 * words + 4);
        let group = groups * 48 + n * 4;
        let held = tree
            + links
            + rows_kept
            + elements
            + group
            + c.nodes * words * 8
            + c.patches * SOLUTION_BYTES_PER_PATCH;
        refine.max(held + self.state_bytes(c))
    }

    /// The sender normal groups of `c`: as counted, else the assumed share per element.
    fn groups(&self, c: &ModelCounts) -> u64 {
        c.groups
            .unwrap_or((c.elements as f64 * self.groups_per_element).ceil() as u64)
    }

    /// The part of [`HierarchicalCosts::bytes`] that a solve allocates when it starts and frees
    /// when it ends (what the exact direct light, computed before, does not share the memory
    /// with): per element its emission and albedo in the state's channels, change sums and RGB
    /// radiance of the result and of the returned state; per group its per-sweep sums of B
    /// (front and back faces) and of every bin; radiance (two copies and the returned state) and
    /// antiradiance slots (two copies and the returned state); link intensities.
    pub fn state_bytes(&self, c: &ModelCounts) -> u64 {
        let (nb, ch) = (self.bins, self.channels);
        let n = c.elements;
        let slots = c.slots.unwrap_or(n.saturating_mul(nb.div_ceil(2)));
        let groups = self.groups(c);
        n * (16 * ch + 48)
            + groups * 8 * ch * (2 + nb)
            + slots * 4 * ch * 3
            + n * 8 * ch * 2
            + c.cluster_links * 4 * ch
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
    /// Bytes per element that the solve would have added beside the model (its fields'
    /// per-sweep sums, the Anderson history, the exact direct light's result, the solved
    /// elements when they are kept) when the model was refused only once built, with them
    /// beside it; 0 when the refinement itself stopped. The next attempt's refinement counts
    /// them ([`LinkBudget::reserve_per_element`]).
    pub solve_bytes_per_element: u64,
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
    /// Bytes per element counted beside the model while it is refined: what the solve adds once
    /// it is built (fields' sums, Anderson history, direct light's result), as measured on an
    /// earlier attempt that was refused for them ([`OverBudget::solve_bytes_per_element`]), so
    /// that a refinement which cannot fit beside them stops while it refines instead of being
    /// refused once built. 0 when no attempt measured them.
    pub reserve_per_element: u64,
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
            reserve_per_element: 0,
        }
    }

    /// `Ok` with the estimate when a model of `counts` fits beside its reserve
    /// ([`LinkBudget::reserve_per_element`] per element), else the [`OverBudget`] outcome.
    pub fn check(&self, counts: &ModelCounts) -> Result<u64, OverBudget> {
        let counts = ModelCounts {
            patches: self.patches,
            ..*counts
        };
        let estimate =
            self.costs.bytes(&counts) + self.reserve_per_element.saturating_mul(counts.elements);
        if self.budget.fits(estimate) {
            Ok(estimate)
        } else {
            Err(OverBudget {
                estimate,
                solve_bytes_per_element: 0,
            })
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
            solve_bytes_per_element: 0,
        }
    }
}
