//! The dense antiradiance solver: every ordered pair of patches is a link.
//!
//! Far pairs are streamed: their couplings are recomputed in every sweep, receiver by receiver, so
//! nothing of size n^2 is ever stored and a 20k-triangle scene runs on any machine. Near pairs
//! ([`is_near`]), whose couplings need quadrature, are few per receiver: they
//! are computed once and cached. It is the oracle for the
//! hierarchical solver (which uses the very same [`couple`] on its finest links).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use rayon::prelude::*;

use crate::error::Result;
use crate::geometry::bins::Bins;
use crate::mesh::Patches;
use crate::progress::Progress;
use crate::solve::budget::{self, Budget, MemoryStats};
use crate::solve::convergence::{damp_if_damped, end_sweep, start_damping};
use crate::solve::health::{self, Guard};
use crate::solve::model;
use crate::solve::solution::{Solution, SolveStats};
use crate::solve::{
    change_ratio, change_sums, finish, source_and_albedo_max, Convergence, SolverOptions,
};
use crate::transport::{
    couple, gather_entries, is_near, Coupling, CouplingParams, Entry, PatchGeom, Receiver,
};

/// A receiver's cached near pairs: (sender, coupling).
type NearList = Vec<(u32, Coupling)>;

/// Solves the scene with the dense solver. Preconditions: `options.validate()` passed.
///
/// Jacobi iteration: each sweep computes every receiver's B and antiradiance bins from the
/// previous sweep's values, until the estimated remaining error is under `options.tol` or the
/// iteration cap is reached (then `stats.converged` is false). Every sweep is checked by a
/// [`Guard`] (NaN or infinity, growth, radiance beyond the bound) and the result by
/// [`finish`]; a solve that fails stops there with `stats.failure` set ([`crate::solve::health`]). In
/// a convex enclosure a receiver's form-factor row above 1 + [`health::ROW_SUM_TOLERANCE`] is
/// scaled down to 1 (`stats.capped_rows`).
///
/// Errors: [`crate::Error::Memory`] when its arrays ([`budget::dense_bytes`]) or its cached near
/// pairs (counted while they are computed) do not fit the memory limit
/// ([`SolverOptions::memory_limit_bytes`]): the dense solver is the oracle and is never
/// coarsened.
pub fn solve_dense(
    patches: &Patches,
    options: &SolverOptions,
    progress: &Progress,
) -> Result<Solution> {
    // The oracle solves two-sided patches as the back-to-back pairs of one-sided patches they
    // are equivalent to.
    Solution::of_one_sided_faces(patches, |p| solve_one_sided(p, options, progress))
}

/// [`solve_dense`] of patches that are all one-sided.
fn solve_one_sided(
    patches: &Patches,
    options: &SolverOptions,
    progress: &Progress,
) -> Result<Solution> {
    let bins = Bins::new(options.bins);
    let nb = bins.len();
    let n = patches.len();
    let params = options.coupling();
    let back = crate::solve::model::back_blocking(patches, options);
    let budget = Budget::start(options.memory_limit());
    let estimate = budget::dense_bytes(n as u64, options.bins, options.near_quadrature);
    let refuse = |bytes: u64| {
        budget.does_not_fit(
            &format!(
                "the dense solver for {n} patches and {0}x{0} bins",
                options.bins
            ),
            bytes,
            "use the hierarchical solver (SolverKind::Hierarchical) or raise SolverOptions::memory_limit_bytes",
        )
    };
    if !budget.fits(estimate) {
        return Err(refuse(estimate));
    }
    let geoms: Vec<Option<PatchGeom>> = (0..n)
        .map(|p| {
            patches.active[p].then(|| {
                PatchGeom::new(patches.corners[p], patches.normal[p]).blocking_back(back[p])
            })
        })
        .collect();
    let active: Vec<usize> = (0..n).filter(|&p| patches.active[p]).collect();

    let emission = &patches.emission_and_source();
    let mut radiance: Vec<[f64; 3]> = emission.clone();
    let mut anti = vec![[0.0f32; 3]; n * nb];
    let mut next_radiance = radiance.clone();
    let mut next_anti = anti.clone();
    let mut stats = SolveStats {
        solver_bytes: ((anti.len() * 2) * 12 + n * 48 * 2) as u64,
        ..SolveStats::default()
    };
    let mut convergence = Convergence::default();
    let (mut guard, bound) = sweep_guard(patches, options, emission, &active);
    // In a convex enclosure the unoccluded rows are the visible ones and may be capped at 1.
    let convex = model::patches_convex(patches);

    let near = NearPairs::compute(&geoms, &active, &bins, &params, &budget, estimate);
    if near.over {
        return Err(refuse(estimate + near.bytes));
    }
    stats.solver_bytes += near
        .lists
        .iter()
        .map(|l| (l.len() * std::mem::size_of::<(u32, Coupling)>()) as u64)
        .sum::<u64>();
    let dense = Dense {
        patches,
        options,
        bins: &bins,
        params: &params,
        back: &back,
        geoms: &geoms,
        active: &active,
        emission,
        convex,
        near: &near,
    };

    for iteration in 1..=options.max_iterations {
        let projection = guard.projection();
        let sweep = dense.sweep(
            projection,
            (&radiance, &anti),
            (&mut next_radiance, &mut next_anti),
        );
        if iteration == 1 {
            stats.max_row_sum = sweep.iter().map(|r| r.row).fold(0.0, f64::max);
            guard.note_rows(stats.max_row_sum);
            stats.links = sweep.iter().map(|r| r.links).sum();
            stats.capped_rows = sweep.iter().filter(|r| r.capped).count();
        }
        let largest = sweep.iter().map(|r| r.largest).fold(0.0, f64::max);
        let finite = sweep.iter().all(|r| r.finite);

        let (num, den) = change_sums(patches, &radiance, &next_radiance);
        let change = change_ratio(num, den);
        std::mem::swap(&mut radiance, &mut next_radiance);
        std::mem::swap(&mut anti, &mut next_anti);
        if end_sweep(
            iteration,
            change,
            num,
            largest,
            finite,
            options.tol,
            &mut guard,
            &mut convergence,
            &mut stats,
            progress,
        ) {
            break;
        }
        start_damping(iteration, &mut guard, &mut convergence, &mut stats);
        damp_if_damped(
            &guard,
            &mut [(&mut radiance, &next_radiance)],
            (&mut anti, &next_anti),
        );
    }
    stats.residual = convergence.residual;
    stats.elements = active.len();
    stats.memory = Some(memory_stats(&budget, estimate + near.bytes, options.bins));
    Ok(finish(
        patches,
        radiance,
        stats,
        options.clamp_negative,
        options.antiradiance.then_some(bound),
    ))
}

/// The memory figures of a dense solve: its estimate and the measured peak (it is never
/// coarsened).
fn memory_stats(budget: &Budget, estimate_bytes: u64, bins: usize) -> MemoryStats {
    MemoryStats {
        limit_bytes: budget.limit,
        base_bytes: budget.base,
        estimate_bytes,
        peak_bytes: crate::memory::peak_rss_bytes(),
        coarsened: Vec::new(),
        attempts: 0,
        epsilon: 0.0,
        bins,
        split_depth: 0,
        discarded_seconds: 0.0,
    }
}

/// The [`Guard`] of the dense sweeps and the bound on B it checks (maximum principle; not for
/// unoccluded radiosity): changes are measured against the mass `sum a E / (1 - rho_max)`.
fn sweep_guard(
    patches: &Patches,
    options: &SolverOptions,
    emission: &[[f64; 3]],
    active: &[usize],
) -> (Guard, f64) {
    let (source_max, rho_max) = source_and_albedo_max(patches);
    let bound = health::radiance_bound(source_max, rho_max);
    let emitted: f64 = active
        .iter()
        .map(|&p| patches.area[p] * emission[p].iter().map(|x| x.abs()).sum::<f64>())
        .sum();
    let reference_mass = health::geometric_sum(emitted, rho_max);
    let guard = Guard::new(
        options.antiradiance.then_some(bound),
        reference_mass,
        patches.emission_scale,
    );
    (guard, bound)
}

/// The near pairs, computed once: per receiver its [`Receiver`] (its quadrature fixed by its
/// nearest exchanging sender: one set of points per receiver) and its (sender, coupling) list.
struct NearPairs {
    receivers: Vec<Option<Receiver>>,
    lists: Vec<NearList>,
    /// Bytes of the lists, counted as they are made.
    bytes: u64,
    /// True when they went past the budget: the rest were skipped and the solve is refused.
    over: bool,
}

impl NearPairs {
    fn compute(
        geoms: &[Option<PatchGeom>],
        active: &[usize],
        bins: &Bins,
        params: &CouplingParams,
        budget: &Budget,
        estimate: u64,
    ) -> NearPairs {
        let near_bytes = AtomicU64::new(0);
        let over = AtomicBool::new(false);
        let (receivers, lists): (Vec<Option<Receiver>>, Vec<NearList>) = geoms
            .par_iter()
            .enumerate()
            .map(|(r, rg)| {
                let Some(rg) = rg else {
                    return (None, Vec::new());
                };
                if over.load(Ordering::Relaxed) {
                    return (None, Vec::new());
                }
                let near_senders: Vec<usize> = active
                    .iter()
                    .copied()
                    .filter(|&s| {
                        let sg = geoms[s].as_ref().expect("active patches have geometry");
                        s != r && is_near(rg, sg, bins, params)
                    })
                    .collect();
                let receiver = Receiver::for_senders(
                    *rg,
                    near_senders.iter().filter_map(|&s| geoms[s].as_ref()),
                    params,
                );
                let mut list = Vec::new();
                let mut coupling = Coupling::new();
                for s in near_senders {
                    let sg = geoms[s].as_ref().expect("active patches have geometry");
                    couple(&receiver, sg, bins, params, &mut coupling);
                    if !coupling.is_empty() {
                        list.push((s as u32, coupling.clone()));
                    }
                }
                let bytes: u64 = list
                    .iter()
                    .map(|(_, c)| budget::dense_near_pair_bytes(c.len()))
                    .sum();
                let held = near_bytes.fetch_add(bytes, Ordering::Relaxed) + bytes;
                if !budget.fits(estimate + held) {
                    over.store(true, Ordering::Relaxed);
                }
                (Some(receiver), list)
            })
            .unzip();
        NearPairs {
            receivers,
            lists,
            bytes: near_bytes.into_inner(),
            over: over.into_inner(),
        }
    }
}

/// What every dense sweep reads: the scene, the options and the cached near pairs.
struct Dense<'a> {
    patches: &'a Patches,
    options: &'a SolverOptions,
    bins: &'a Bins,
    params: &'a CouplingParams,
    back: &'a [bool],
    geoms: &'a [Option<PatchGeom>],
    active: &'a [usize],
    emission: &'a [[f64; 3]],
    /// True in a convex enclosure, where a form-factor row above 1 is scaled to 1.
    convex: bool,
    near: &'a NearPairs,
}

impl Dense<'_> {
    /// One Jacobi sweep: every receiver gathers from every active sender, from `radiance` and
    /// `anti` into `next_radiance` and `next_anti`, each value written through `projection`.
    fn sweep(
        &self,
        projection: health::Projection,
        (radiance, anti): (&[[f64; 3]], &[[f32; 3]]),
        (next_radiance, next_anti): (&mut [[f64; 3]], &mut [[f32; 3]]),
    ) -> Vec<ReceiverSweep> {
        let nb = self.bins.len();
        next_radiance
            .par_iter_mut()
            .zip(next_anti.par_chunks_mut(nb))
            .enumerate()
            .map(|(r, (b_out, a_out))| self.gather(r, projection, (radiance, anti), b_out, a_out))
            .collect()
    }

    /// Receiver `r`'s B and antiradiance bins (`b_out`, `a_out`): its cached near pairs, then
    /// every far sender coupled anew.
    fn gather(
        &self,
        r: usize,
        projection: health::Projection,
        (radiance, anti): (&[[f64; 3]], &[[f32; 3]]),
        b_out: &mut [f64; 3],
        a_out: &mut [[f32; 3]],
    ) -> ReceiverSweep {
        let (options, params, bins) = (self.options, self.params, self.bins);
        let (emission, back) = (self.emission, self.back);
        let nb = bins.len();
        let Some(receiver) = &self.near.receivers[r] else {
            *b_out = emission[r];
            a_out.fill([0.0; 3]);
            return ReceiverSweep {
                largest: emission[r].iter().fold(0.0, |m, x| m.max(x.abs())),
                finite: true,
                ..ReceiverSweep::default()
            };
        };
        let mut h = [0.0f64; 3];
        let mut a_acc = vec![[0.0f64; 3]; nb];
        let mut coupling = Coupling::new();
        let mut row = 0.0;
        let mut links = 0u64;
        let mut gather = |s: usize, entries: &[Entry]| {
            links += 1;
            // What a patch sends is weighed by the share of it that shows.
            let w = self.patches.visible_share(s);
            row += w * gather_entries(
                entries,
                radiance[s].map(|x| w * x),
                |bin| anti[s * nb + bin].map(|x| w * f64::from(x)),
                options.antiradiance,
                params.two_sided || back[s],
                &mut h,
                &mut a_acc,
            );
        };
        for (s, entries) in &self.near.lists[r] {
            gather(*s as usize, entries);
        }
        for &s in self.active {
            let sg = self.geoms[s]
                .as_ref()
                .expect("active patches have geometry");
            if s == r || is_near(&receiver.geom, sg, bins, params) {
                continue;
            }
            couple(receiver, sg, bins, params, &mut coupling);
            if !coupling.is_empty() {
                gather(s, &coupling);
            }
        }
        // A row above 1 in a convex enclosure is discretization error: scale it to 1.
        let capped = self.convex && row > 1.0 + health::ROW_SUM_TOLERANCE;
        let scale = if capped { 1.0 / row } else { 1.0 };
        let mut largest = 0.0f64;
        let mut finite = true;
        // The largest |B| and finiteness are of the values before the projection.
        for c in 0..3 {
            let b = emission[r][c] + self.patches.albedo[r][c] * (scale * h[c]);
            largest = largest.max(b.abs());
            finite &= b.is_finite();
            b_out[c] = projection.apply(b);
        }
        for (dst, src) in a_out.iter_mut().zip(&a_acc) {
            *dst = if options.antiradiance {
                src.map(|x| projection.apply_anti(x, row) as f32)
            } else {
                [0.0; 3]
            };
            finite &= src.iter().all(|x| x.is_finite()) && dst.iter().all(|x| x.is_finite());
        }
        ReceiverSweep {
            row,
            links,
            capped,
            largest,
            finite,
        }
    }
}

/// What one receiver's gather in a dense sweep reports (`Default` is for fields left unset).
#[derive(Clone, Copy, Debug, Default)]
struct ReceiverSweep {
    /// Its form-factor row sum (before capping).
    row: f64,
    /// Senders it exchanged with.
    links: u64,
    /// True when its row was scaled down to 1.
    capped: bool,
    /// Its largest |B| over the channels.
    largest: f64,
    /// True when every value it wrote is finite.
    finite: bool,
}
