//! The hierarchical solver's iteration: the sweeps of one solve in `C` colour channels, from
//! its start (cold, warm or going on) through acceleration to the solution and the state the
//! next solve starts from.

use super::*;
use crate::solve::MIN_SWEEPS;

/// Where a solve starts: the per-element source and albedo in `C` channels, the state the
/// sweeps start from, and how it relates to the warm state given.
struct Start<const C: usize> {
    emission: Vec<[f64; C]>,
    emission_back: Vec<[f64; C]>,
    albedo: Vec<[f64; C]>,
    radiance: Vec<[f64; C]>,
    radiance_back: Vec<[f64; C]>,
    anti: Vec<[f32; C]>,
    /// The warm state belongs to this scene.
    matched: bool,
    /// It was solved for this very source.
    same_source: bool,
    /// It was solved for a source of this length.
    same_source_len: bool,
}

/// The state two sweeps back (radiance, back faces' radiance, antiradiance slots), for the
/// two-sweep extrapolation.
type TwoBack<const C: usize> = (Vec<[f64; C]>, Vec<[f64; C]>, Vec<[f32; C]>);

/// `x += k (x - from)` over the whole state: radiance, back faces' radiance, antiradiance.
#[allow(clippy::type_complexity)]
fn extrapolate_state<const C: usize>(
    (radiance, radiance_back, anti): (&mut [[f64; C]], &mut [[f64; C]], &mut [[f32; C]]),
    (from_radiance, from_back, from_anti): (&[[f64; C]], &[[f64; C]], &[[f32; C]]),
    k: f64,
) {
    extrapolate(radiance, from_radiance, k);
    extrapolate(radiance_back, from_back, k);
    extrapolate(anti, from_anti, k);
}

/// The per-sweep sums of the senders and the links' intensities, kept between sweeps.
struct Scratch<const C: usize> {
    group_b: Vec<[f64; C]>,
    group_b_back: Vec<[f64; C]>,
    group_a: Vec<[f64; C]>,
    intensity: Vec<[f32; C]>,
    field_sums: FieldSums<C>,
}

impl<const C: usize> Scratch<C> {
    /// Zeroed sums for the sender groups, the back faces' groups (when some element is
    /// two-sided), every bin of the groups and the fields of `prepared`, with the links'
    /// `intensity` array.
    fn new(prepared: &Prepared, intensity: Vec<[f32; C]>) -> Self {
        let groups = prepared.groups.normal.len();
        let backs = !prepared.elem_two.is_empty();
        Scratch {
            group_b: vec![[0.0f64; C]; groups],
            group_b_back: vec![[0.0f64; C]; if backs { groups } else { 0 }],
            group_a: vec![[0.0f64; C]; groups * prepared.bins.len()],
            intensity,
            field_sums: FieldSums::new(&prepared.fields),
        }
    }
}

/// The state a window of [`crate::solve::convergence::WINDOW_SWEEPS`] sweeps started from
/// (radiance of the fronts, then of the back faces, f32), for the net change
/// [`Convergence::record_window`] takes.
#[derive(Default)]
struct Window<const C: usize> {
    start: Vec<[f32; C]>,
    sweeps: usize,
}

impl<const C: usize> Window<C> {
    /// Counts a sweep whose output is `radiance` and `radiance_back` (per element, empty when
    /// no element is two-sided); every [`crate::solve::convergence::WINDOW_SWEEPS`] sweeps
    /// returns the net relative change since the window's start, area-weighted L1 as the
    /// sweeps' own change, and starts the next window there.
    fn sweep(
        &mut self,
        (radiance, radiance_back): (&[[f64; C]], &[[f64; C]]),
        area: &[f64],
    ) -> Option<f64> {
        let state = radiance.iter().chain(radiance_back);
        let areas = area.iter().chain(area.iter().take(radiance_back.len()));
        if self.start.is_empty() {
            self.start = state.map(|b| b.map(|x| x as f32)).collect();
            self.sweeps = 0;
            return None;
        }
        self.sweeps += 1;
        if self.sweeps < crate::solve::convergence::WINDOW_SWEEPS {
            return None;
        }
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for ((b, start), &a) in state.zip(self.start.iter_mut()).zip(areas) {
            for c in 0..C {
                num += a * (b[c] - f64::from(start[c])).abs();
                den += a * b[c].abs();
            }
            *start = b.map(|x| x as f32);
        }
        self.sweeps = 0;
        Some(change_ratio(num, den))
    }
}

/// Going on from `resume`: Anderson's history when it has the state's length
/// (`going_on.1`), and, when going on with the same source (`going_on.0`), its convergence
/// estimate, health guard and counts. Returns the first sweep's number and the history.
fn resumed<const C: usize>(
    resume: Option<Resume>,
    (same_source, state_len): (bool, usize),
    (convergence, guard, stats): (&mut Convergence, &mut Guard, &mut SolveStats),
) -> (usize, Option<Anderson>) {
    let Some(r) = resume else {
        return (1, None);
    };
    let kept = r.anderson.filter(|a| a.len() == state_len);
    if !same_source {
        return (1, kept);
    }
    *convergence = r.convergence;
    *guard = r.guard;
    stats.max_row_sum = r.max_row_sum;
    stats.extrapolations = r.extrapolations;
    stats.damped_after = r.damped_after;
    stats.radiance_damped_after = r.radiance_damped_after;
    stats.floor_closed_after = r.floor_closed_after;
    (r.sweeps + 1, kept)
}

/// Out of time: the next sweep, as long as the one started at `sweep_start`, would end after
/// the deadline.
fn out_of_time(deadline: Option<Instant>, sweep_start: Instant) -> bool {
    deadline.is_some_and(|deadline| {
        let now = Instant::now();
        now + (now - sweep_start) > deadline
    })
}

impl Prepared {
    /// [`Prepared::solve_from`] in `C` colour channels (1 or 3).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn solve_channels<const C: usize>(
        &mut self,
        patches: &Patches,
        elem_source: &[[f64; 3]],
        warm: Option<&ElementState>,
        resume: Option<Resume>,
        deadline: Option<Instant>,
        progress: &Progress,
    ) -> (Solution, ElementState) {
        let t0 = Instant::now();
        let options = &self.options;
        let n = self.element_count();
        let live = &self.live;
        let slots = live.slots();
        let backs = self.elem_two.len();
        let Start {
            emission,
            emission_back,
            albedo,
            mut radiance,
            mut radiance_back,
            mut anti,
            matched,
            same_source,
            same_source_len,
        } = self.start_state::<C>(elem_source, warm);
        let resume = resume.filter(|_| matched);
        let (resume, going_on) = match resume {
            Some(r) if same_source => (Some(r), true),
            other => (other, false),
        };
        let mut next_radiance = radiance.clone();
        let mut next_radiance_back = radiance_back.clone();
        let mut next_anti = anti.clone();
        let mut intensity = vec![[0.0f32; C]; self.links.cluster.len()];
        let mut stats = self.model_stats::<C>();
        let mut convergence = Convergence::default();
        convergence.warm = matched && same_source_len;
        let (bound, mut guard, rho_max) =
            self.health_start(patches, (&emission, &emission_back), &albedo);
        let (first, kept_anderson) = resumed::<C>(
            resume,
            (going_on, state_len_of::<C>(n + backs, slots)),
            (&mut convergence, &mut guard, &mut stats),
        );
        let mut memory = self.memory.clone();
        let mut anderson = self.accelerate::<C>(
            (kept_anderson, going_on, false),
            rho_max,
            (&mut stats, &mut convergence),
            &mut memory,
        );
        let earlier =
            self.kept_states(warm, (matched && same_source_len, same_source), &mut memory);
        let mut two_back = self.two_sweep_copy(
            anderson.is_none(),
            &mut memory,
            &radiance,
            &radiance_back,
            &anti,
        );
        let (mut x_flat, mut g_flat) = (Vec::new(), Vec::new());
        let mut scratch = Scratch::new(self, std::mem::take(&mut intensity));
        let mut sources = Sources {
            emission: &emission,
            emission_back: &emission_back,
            albedo: &albedo,
            projection: guard.projection(),
        };

        // Mixed sweeps also measure their net change over windows of sweeps
        // ([`Convergence::record_window`]).
        let mut window = anderson.is_some().then(Window::<C>::default);
        let mut last = first - 1;
        let (tol, max_iterations) = (options.tol, options.max_iterations);
        for iteration in first..first + max_iterations {
            let sweep_start = Instant::now();
            last = iteration;
            sources.projection = guard.projection();
            let sums = self.sweep_once(
                &sources,
                &mut scratch,
                (&radiance, &radiance_back, &anti),
                (&mut next_radiance, &mut next_radiance_back, &mut next_anti),
            );
            if iteration == first && !going_on {
                stats.max_row_sum = sums.max_row;
                guard.note_rows(sums.max_row);
            }
            let change = change_ratio(sums.num, sums.den);
            std::mem::swap(&mut radiance, &mut next_radiance);
            std::mem::swap(&mut radiance_back, &mut next_radiance_back);
            std::mem::swap(&mut anti, &mut next_anti);
            if let Some(net) = window
                .as_mut()
                .and_then(|w| w.sweep((&radiance, &radiance_back), &self.elem_area))
            {
                convergence.record_window(net);
            }
            if end_sweep(
                iteration,
                change,
                sums.num,
                sums.largest,
                sums.finite,
                tol,
                &mut guard,
                &mut convergence,
                &mut stats,
                progress,
            ) {
                break;
            }
            if start_damping(iteration, &mut guard, &mut convergence, &mut stats) {
                if let Some(acc) = anderson.as_mut() {
                    acc.restart();
                }
                if let Some(w) = window.as_mut() {
                    w.start.clear();
                }
            }
            // Deep rows: the damped sweeps may still amplify a mode that only mixing settles, so
            // a solve whose history was over its own budget takes it now, within the limit.
            if iteration == first
                && guard.deep_rows()
                && anderson.is_none()
                && self.over_own_history_budget(self.history_bytes(C))
            {
                anderson = self.accelerate::<C>(
                    (None, going_on, true),
                    rho_max,
                    (&mut stats, &mut convergence),
                    &mut memory,
                );
                if anderson.is_some() {
                    two_back = None;
                    window = Some(Window::default());
                }
            }
            if self.settle_sweep(
                (&guard, anderson.as_mut(), &mut convergence),
                (&mut radiance, &mut radiance_back, &mut anti),
                (&next_radiance, &next_radiance_back, &next_anti),
                two_back.as_ref(),
                (&mut x_flat, &mut g_flat),
            ) {
                stats.extrapolations += 1;
            }
            // The state before this sweep's is two sweeps back from the next one; the next sweep
            // writes every entry of `next_*`, so the buffers trade places instead of copying.
            if let Some((b, b_back, a)) = two_back.as_mut() {
                std::mem::swap(b, &mut next_radiance);
                std::mem::swap(b_back, &mut next_radiance_back);
                std::mem::swap(a, &mut next_anti);
            }
            let swept = iteration + 1 - first;
            let long = |left: f64| left >= LATE_PAIR_CACHE_SWEEPS as f64;
            if swept == LATE_PAIR_CACHE_SWEEPS
                || (swept == 1 && guard.deep_rows())
                || (swept == MIN_SWEEPS && convergence.sweeps_left(tol).is_some_and(long))
            {
                self.late_pair_cache(&mut memory);
            }
            if out_of_time(deadline, sweep_start) {
                break;
            }
        }
        stats.iterations = last + 1 - first;
        stats.residual = convergence.residual;
        // The sweeps' buffers go before the result is assembled, so that they do not add to its
        // peak (at 1M triangles the link intensities alone are hundreds of MB).
        drop((scratch, two_back, x_flat, g_flat, window));
        drop((next_radiance, next_radiance_back, next_anti));

        self.finish_channels(
            patches,
            elem_source,
            t0,
            (radiance, radiance_back, anti),
            (stats, memory, bound),
            (anderson, convergence, guard, last, earlier),
        )
    }

    /// The state the next sweep starts from, after a sweep that did not end the solve:
    /// damped towards the sweep's output when the guard damps, then mixed by
    /// [`Self::mix_step`]. Returns true when it extrapolated.
    #[allow(clippy::type_complexity)]
    fn settle_sweep<const C: usize>(
        &self,
        (guard, anderson, convergence): (&Guard, Option<&mut Anderson>, &mut Convergence),
        (radiance, radiance_back, anti): (
            &mut Vec<[f64; C]>,
            &mut Vec<[f64; C]>,
            &mut Vec<[f32; C]>,
        ),
        (next_radiance, next_radiance_back, next_anti): (&[[f64; C]], &[[f64; C]], &[[f32; C]]),
        two_back: Option<&TwoBack<C>>,
        flat: (&mut Vec<f64>, &mut Vec<f64>),
    ) -> bool {
        damp_if_damped(
            guard,
            &mut [
                (radiance, next_radiance),
                (radiance_back, next_radiance_back),
            ],
            (anti, next_anti),
        );
        self.mix_step(
            anderson,
            convergence,
            (radiance, radiance_back, anti),
            (next_radiance, next_radiance_back, next_anti),
            two_back,
            flat,
        )
    }

    /// A copy of the state for the two-sweep extrapolation
    /// ([`Convergence::two_sweep_factor`]) when the sweeps are not mixed by Anderson
    /// (`plain`) and the copy fits what the memory limit leaves (it is then counted in
    /// `memory`'s estimate).
    fn two_sweep_copy<const C: usize>(
        &self,
        plain: bool,
        memory: &mut MemoryStats,
        radiance: &[[f64; C]],
        radiance_back: &[[f64; C]],
        anti: &[[f32; C]],
    ) -> Option<TwoBack<C>> {
        let bytes = (std::mem::size_of_val(radiance)
            + std::mem::size_of_val(radiance_back)
            + std::mem::size_of_val(anti)) as u64;
        if !plain || bytes > self.budget.spare(memory.estimate_bytes) {
            return None;
        }
        memory.estimate_bytes += bytes;
        Some((radiance.to_vec(), radiance_back.to_vec(), anti.to_vec()))
    }

    /// The earlier states the state of a solve warm-started from `warm` keeps
    /// ([`ElementState`]'s `earlier`): `warm`'s own when the solve goes on with the same
    /// source, `warm` itself and its most recent earlier ones when the source changed
    /// (`usable`: `warm` belongs to this scene and was solved for a source of this length),
    /// none otherwise; the most recent first, as many as fit what the memory limit leaves
    /// beside `memory`'s estimate, which then counts them.
    fn kept_states(
        &self,
        warm: Option<&ElementState>,
        (usable, same_source): (bool, bool),
        memory: &mut MemoryStats,
    ) -> Vec<std::sync::Arc<ElementState>> {
        let Some(w) = warm.filter(|_| usable) else {
            return Vec::new();
        };
        let budget = &self.budget;
        let mut fits = |bytes: u64| {
            let fits = bytes <= budget.spare(memory.estimate_bytes);
            if fits {
                memory.estimate_bytes += bytes;
            }
            fits
        };
        let mut kept = Vec::new();
        // A new source keeps the warm state itself first (copied only when it fits).
        if !same_source {
            if !fits(w.bytes()) {
                return kept;
            }
            kept.push(std::sync::Arc::new(w.without_history()));
        }
        for state in w
            .earlier
            .iter()
            .take((WARM_BASES - 1).saturating_sub(kept.len()))
        {
            if !fits(state.bytes()) {
                break;
            }
            kept.push(std::sync::Arc::clone(state));
        }
        kept
    }

    /// Builds the pair cache of a solve without one (its factors did not fit
    /// [`crate::solve::SolverOptions::pair_cache_mb`]) that has run [`LATE_PAIR_CACHE_SWEEPS`]
    /// sweeps, or [`MIN_SWEEPS`] whose contraction predicts at least as many more
    /// ([`Convergence::sweeps_left`]), when it fits what the memory limit leaves beside
    /// `memory`'s estimate, which then counts it. The cache turns each later sweep's gather
    /// into a stream; a solve that needs this many sweeps has many left to save on.
    fn late_pair_cache(&mut self, memory: &mut MemoryStats) {
        if self.pairs.is_some() || self.options.pair_cache_mb == 0 {
            return;
        }
        let spare = self.budget.spare(memory.estimate_bytes);
        if let Ok(cache) = PairCache::build(&*self, spare) {
            memory.estimate_bytes += cache.bytes();
            self.pairs = Some(cache);
        }
    }

    /// The state the next sweep starts from, after the sweep from `(radiance, ..)` gave
    /// `next`: Anderson's mix of the last sweeps' outputs, else (once the sweeps contract at a
    /// steady ratio) a jump over the geometric tail. Returns true when it extrapolated.
    #[allow(clippy::type_complexity)]
    fn mix_step<const C: usize>(
        &self,
        anderson: Option<&mut Anderson>,
        convergence: &mut Convergence,
        (radiance, radiance_back, anti): (
            &mut Vec<[f64; C]>,
            &mut Vec<[f64; C]>,
            &mut Vec<[f32; C]>,
        ),
        (next_radiance, next_radiance_back, next_anti): (&[[f64; C]], &[[f64; C]], &[[f32; C]]),
        two_back: Option<&TwoBack<C>>,
        (x_flat, g_flat): (&mut Vec<f64>, &mut Vec<f64>),
    ) -> bool {
        match anderson {
            // Anderson: the next state mixes the last sweeps' outputs.
            Some(acc) => {
                pack((next_radiance, next_radiance_back), next_anti, x_flat);
                pack((radiance, radiance_back), anti, g_flat);
                acc.step(x_flat, g_flat);
                unpack(x_flat, (radiance, radiance_back), anti);
            }
            // Else, once the sweeps contract at a steady ratio, jump over the geometric tail.
            None => {
                let state = (
                    radiance.as_mut_slice(),
                    radiance_back.as_mut_slice(),
                    anti.as_mut_slice(),
                );
                if let Some(k) = convergence.extrapolation_factor() {
                    extrapolate_state(state, (next_radiance, next_radiance_back, next_anti), k);
                    return true;
                }
                // Else over the last two sweeps, when their contraction has settled.
                if let Some((b, b_back, a)) = two_back {
                    if let Some(k) = convergence.two_sweep_factor() {
                        extrapolate_state(state, (b, b_back, a), k);
                        return true;
                    }
                }
            }
        }
        false
    }

    /// A solve's statistics as they start: links, the solver's bytes and what the model
    /// stores, in `C` channels.
    fn model_stats<const C: usize>(&self) -> SolveStats {
        let (n, nb, slots) = (self.element_count(), self.bins.len(), self.live.slots());
        // Three channels and every bin of every element, against what this solve stores.
        let full_bytes = 2 * (n as u64 * 24 + (n * nb) as u64 * 12);
        let used_bytes = self.state_bytes(C as u64);
        SolveStats {
            links: self.links.len() as u64,
            solver_bytes: self.static_bytes() + used_bytes,
            model: Some(ModelStats {
                channels: C,
                antiradiance: self.use_anti,
                convex_enclosure: self.convex,
                back_blocking_patches: self.back_blocking_patches,
                anti_bins_stored: slots as u64,
                anti_bins_full: (n * nb) as u64,
                bytes_saved: full_bytes.saturating_sub(used_bytes),
                ..ModelStats::default()
            }),
            ..SolveStats::default()
        }
    }

    /// The sources of `elem_source` in `C` channels and the state the sweeps start from: `warm`
    /// when it belongs to this scene (moved by the change of its source when that changed),
    /// else the source itself.
    fn start_state<const C: usize>(
        &self,
        elem_source: &[[f64; 3]],
        warm: Option<&ElementState>,
    ) -> Start<C> {
        let n = self.element_count();
        let slots = self.live.slots();
        // Back faces: dense per element (0 for one-sided ones) when some element is two-sided.
        let backs = self.elem_two.len();
        let dense_back = |faces: &[[f64; 3]]| -> Vec<[f64; C]> {
            let mut back = vec![[0.0; C]; backs];
            for (&e, &s) in self.back_faces.iter().zip(&faces[n..]) {
                back[e as usize] = channels_of(s);
            }
            back
        };
        let emission: Vec<[f64; C]> = elem_source[..n].iter().map(|&s| channels_of(s)).collect();
        let emission_back = dense_back(elem_source);
        let albedo: Vec<[f64; C]> = self.elem_albedo.iter().map(|&a| channels_of(a)).collect();
        // A warm start that belongs to this scene: the same source goes on with its iteration;
        // another one moves each element's radiance by the change of its source.
        let warm = (warm.and_then(|w| w.to_channels::<C>(n, backs, slots)))
            .zip(warm)
            .map(|(values, w)| (w, values));
        let matched = warm.is_some();
        let faces = elem_source.len();
        let same_source_len = warm.as_ref().is_some_and(|(w, _)| w.source.len() == faces);
        let same_source = warm.as_ref().is_some_and(|(w, _)| w.source == elem_source);
        let (radiance, radiance_back, anti) = match warm {
            Some((w, (mut radiance, mut radiance_back, mut anti))) => {
                if !same_source && w.source.len() == faces {
                    // The old states combined per channel by the least-squares factors that
                    // bring their sources closest to the new one (exact when the new source is
                    // a combination of theirs; one state alone is scaled), then moved by what
                    // that leaves of the change.
                    let mut bases = vec![(w.source.as_slice(), None)];
                    for e in &w.earlier {
                        if e.source.len() == faces {
                            if let Some(values) = e.to_channels::<C>(n, backs, slots) {
                                bases.push((e.source.as_slice(), Some(values)));
                            }
                        }
                    }
                    let old: Vec<Vec<[f64; C]>> = bases
                        .iter()
                        .map(|(source, _)| source[..n].iter().map(|&s| channels_of(s)).collect())
                        .collect();
                    let old_back: Vec<Vec<[f64; C]>> =
                        bases.iter().map(|(source, _)| dense_back(source)).collect();
                    let old_refs: Vec<&[[f64; C]]> = old.iter().map(Vec::as_slice).collect();
                    let k = warm_factors(&emission, &old_refs, &self.elem_area);
                    let k0 = k[0];
                    let fronts = radiance.iter_mut().zip(emission.iter().zip(&old[0]));
                    let back_faces = radiance_back
                        .iter_mut()
                        .zip(emission_back.iter().zip(&old_back[0]));
                    for (b, (new, old)) in fronts.chain(back_faces) {
                        for c in 0..C {
                            b[c] = k0[c] * b[c] + new[c] - k0[c] * old[c];
                        }
                    }
                    for a in anti.iter_mut() {
                        for c in 0..C {
                            a[c] = (k0[c] * a[c] as f64) as f32;
                        }
                    }
                    // The older states' shares (0 where they were left out).
                    let older = bases.iter().zip(&k).zip(old.iter().zip(&old_back)).skip(1);
                    for (((_, values), k), (old, old_back)) in older {
                        let Some((b_i, b_back_i, a_i)) = values else {
                            continue;
                        };
                        if k.iter().all(|&x| x == 0.0) {
                            continue;
                        }
                        let fronts = radiance.iter_mut().zip(b_i.iter().zip(old.iter()));
                        let back_faces = radiance_back
                            .iter_mut()
                            .zip(b_back_i.iter().zip(old_back.iter()));
                        for (b, (b_i, s_i)) in fronts.chain(back_faces) {
                            for c in 0..C {
                                b[c] += k[c] * (b_i[c] - s_i[c]);
                            }
                        }
                        for (a, a_i) in anti.iter_mut().zip(a_i.iter()) {
                            for c in 0..C {
                                a[c] = (a[c] as f64 + k[c] * a_i[c] as f64) as f32;
                            }
                        }
                    }
                }
                (radiance, radiance_back, anti)
            }
            None => (
                emission.clone(),
                emission_back.clone(),
                vec![[0.0f32; C]; slots],
            ),
        };
        Start {
            emission,
            emission_back,
            albedo,
            radiance,
            radiance_back,
            anti,
            matched,
            same_source,
            same_source_len,
        }
    }

    /// The bound on B of a solve of this source (the maximum principle; `None` for unoccluded
    /// radiosity), its health guard, and the largest albedo.
    fn health_start<const C: usize>(
        &self,
        patches: &Patches,
        (emission, emission_back): (&[[f64; C]], &[[f64; C]]),
        albedo: &[[f64; C]],
    ) -> (Option<f64>, Guard, f64) {
        let options = &self.options;
        // The bound on B (maximum principle; not for unoccluded radiosity) and the mass the
        // sweeps' changes are measured against.
        let rho_max = albedo
            .iter()
            .flat_map(|a| a.iter().copied())
            .fold(0.0f64, f64::max);
        let source_max = emission
            .iter()
            .chain(emission_back)
            .flat_map(|s| s.iter().map(|x| x.abs()))
            .fold(0.0f64, f64::max);
        let emitted: f64 = emission
            .iter()
            .zip(&self.elem_area)
            .chain(emission_back.iter().zip(&self.elem_area))
            .map(|(s, &a)| a * s.iter().map(|x| x.abs()).sum::<f64>())
            .sum();
        let reference_mass = health::geometric_sum(emitted, rho_max);
        let bound = options
            .antiradiance
            .then(|| health::radiance_bound(source_max, rho_max));
        let mut guard = Guard::new(bound, reference_mass, patches.emission_scale);
        // Faint pairs as cluster links take the near field of small things out of the exact
        // rows, which then do not show where surfaces stack.
        if options.faint_links {
            guard.close_floor();
        }
        (bound, guard, rho_max)
    }

    /// The acceleration of one solve ([`Self::acceleration`]) and the memory figures with it:
    /// records the choice in `stats`, and with Anderson mixing takes the largest albedo
    /// `rho_max` as the contraction bound of `convergence` (restarting the extrapolation count
    /// unless the solve goes on from a previous one).
    fn accelerate<const C: usize>(
        &self,
        (kept_anderson, going_on, deep): (Option<Anderson>, bool, bool),
        rho_max: f64,
        (stats, convergence): (&mut SolveStats, &mut Convergence),
        memory: &mut MemoryStats,
    ) -> Option<Anderson> {
        let (anderson, acceleration) =
            self.acceleration::<C>(kept_anderson, (going_on, deep), memory);
        stats.acceleration = acceleration;
        if anderson.is_some() {
            convergence.contraction_bound = Some(rho_max);
            if !going_on {
                stats.extrapolations = 0;
            }
        }
        anderson
    }

    /// Anderson acceleration for a solve (`kept` the previous solve's history, reset to a new
    /// source unless `going_on`), or why not, as `stats.acceleration` says it; its history is
    /// added to `memory`'s estimate, or its absence to what was coarsened. A solve whose first
    /// sweep found `deep` rows ([`crate::solve::health::Guard::deep_rows`]) takes it whatever
    /// [`ACCELERATION_BUDGET_BYTES`] says, within the memory limit.
    fn acceleration<const C: usize>(
        &self,
        kept_anderson: Option<Anderson>,
        (going_on, deep): (bool, bool),
        memory: &mut MemoryStats,
    ) -> (Option<Anderson>, String) {
        let (options, live) = (&self.options, &self.live);
        let (n, nb, slots) = (self.element_count(), self.bins.len(), live.slots());
        let backs = self.elem_two.len();
        // Anderson acceleration when its history (and the flat copies of the state it mixes)
        // fits its own budget and what the model leaves of the memory limit; its residuals
        // shrink faster than the plain sweep's contraction, so the remaining error is estimated
        // with the largest albedo as the contraction bound instead.
        let state_len = state_len_of::<C>(n + backs, slots);
        let depth = options.acceleration_depth;
        let history = self.history_bytes(C);
        let mb = |bytes: u64| bytes.div_ceil(1 << 20);
        let off = if depth == 0 {
            Some("acceleration_depth 0".to_string())
        } else if self.over_own_history_budget(history) && !deep {
            Some(format!(
                "Anderson history of {} MB over its {} MB budget",
                mb(history),
                mb(self.acceleration_budget)
            ))
        } else if history > self.budget.spare(self.sweep_bytes) {
            memory.coarsened.push("Anderson acceleration off".into());
            Some(format!(
                "Anderson history of {} MB over what the memory limit leaves",
                mb(history)
            ))
        } else {
            // The history lives through the sweeps, after the exact direct light is freed.
            memory.estimate_bytes = memory.estimate_bytes.max(self.sweep_bytes + history);
            None
        };
        let accelerate = off.is_none();
        let acceleration = match off {
            None => "anderson".into(),
            Some(why) => format!("extrapolation ({why})"),
        };
        let anderson = accelerate.then(|| {
            if let Some(mut kept) = kept_anderson {
                if !going_on {
                    kept.new_source();
                }
                return kept;
            }
            let mut weight = Vec::with_capacity(state_len);
            for &a in self.elem_area.iter().chain(&self.elem_area[..backs]) {
                weight.extend(std::iter::repeat_n(a, C));
            }
            for e in 0..n {
                let w = self.elem_area[e] / nb as f64;
                let k = (live.start[e + 1] - live.start[e]) as usize * C;
                weight.extend(std::iter::repeat_n(w, k));
            }
            Anderson::new(depth, weight)
        });
        (anderson, acceleration)
    }

    /// True when Anderson mixing is on and a history of `bytes` is over its own budget
    /// ([`ACCELERATION_BUDGET_BYTES`]), which only a solve with deep rows may exceed.
    fn over_own_history_budget(&self, bytes: u64) -> bool {
        self.options.acceleration_depth > 0 && bytes > self.acceleration_budget
    }

    /// Bytes of the Anderson history of a solve in `channels` channels at
    /// [`SolverOptions::acceleration_depth`]: the history itself
    /// ([`Anderson::bytes`]), the two flat copies of the state it mixes (f64 each) and the
    /// start of the convergence window.
    pub(super) fn history_bytes(&self, channels: usize) -> u64 {
        self.history_bytes_with(self.live.slots(), channels)
    }

    /// [`Self::history_bytes`] with `slots` stored bins.
    pub(super) fn history_bytes_with(&self, slots: usize, channels: usize) -> u64 {
        let (n, backs) = (self.element_count(), self.elem_two.len());
        let state_len = (n + backs + slots) * channels;
        Anderson::bytes(state_len, self.options.acceleration_depth)
            + 16 * state_len as u64
            + ((n + backs) * channels * size_of::<f32>()) as u64
    }

    /// [`Self::history_bytes_with`] when a solve would allocate that history, 0 when Anderson
    /// mixing is off by its own settings ([`SolverOptions::acceleration_depth`] 0, or a history
    /// over [`ACCELERATION_BUDGET_BYTES`]; see [`Self::acceleration`]).
    pub(super) fn planned_history_bytes(&self, slots: usize, channels: usize) -> u64 {
        let bytes = self.history_bytes_with(slots, channels);
        if self.options.acceleration_depth > 0 && !self.over_own_history_budget(bytes) {
            bytes
        } else {
            0
        }
    }

    /// One Jacobi sweep from the state `from` into `to`: sender summaries, pull, gather.
    /// Returns the sweep's sums.
    #[allow(clippy::type_complexity)]
    fn sweep_once<const C: usize>(
        &self,
        sources: &Sources<C>,
        scratch: &mut Scratch<C>,
        (radiance, radiance_back, anti): (&[[f64; C]], &[[f64; C]], &[[f32; C]]),
        (next_radiance, next_radiance_back, next_anti): (
            &mut [[f64; C]],
            &mut [[f64; C]],
            &mut [[f32; C]],
        ),
    ) -> SweepSums {
        let (live, links, groups) = (&self.live, &self.links, &self.groups);
        let (n, nb, backs) = (self.element_count(), self.bins.len(), self.elem_two.len());
        let (pairs, send_area) = (self.pairs.as_ref(), self.send_area());
        let ctx = self.sweep_context();
        let Scratch {
            group_b,
            group_b_back,
            group_a,
            intensity,
            field_sums,
        } = scratch;
        // 1. Sender summaries: per normal group of every large node, the area-weighted sums of
        //    B and of each antiradiance bin (bottom-up, children before parents).
        groups.accumulate(
            (radiance, radiance_back),
            anti,
            live,
            send_area,
            nb,
            (group_b, group_b_back),
            group_a,
        );

        // 2. Pull: the radiant intensity every cluster link's sender sends along the link.
        intensity
            .par_iter_mut()
            .zip(links.cluster.par_iter())
            .for_each(|(out, l)| {
                *out = ctx.pull(
                    l,
                    groups,
                    (group_b, group_b_back),
                    group_a,
                    (radiance, radiance_back),
                    anti,
                );
            });

        // 2b. Fields: the links gathered at their receiver node, summed once per node.
        ctx.sum_fields(&self.fields, links, intensity, field_sums);

        // 3. Gather per element: exact links, then the cluster links into it and its ancestors,
        //    each with the element's own direction and distance from the link's sender (the
        //    antiradiance goes to the link's bin, the one its sender reads when it passes it on).
        //    Only the element's stored bins are kept.
        let anti_out = split_by_start(next_anti, &live.start);
        let mut back_out: Vec<Option<&mut [f64; C]>> = if backs > 0 {
            next_radiance_back.iter_mut().map(Some).collect()
        } else {
            (0..n).map(|_| None).collect()
        };
        let state = SweepState {
            links,
            pairs,
            intensity,
            radiance,
            radiance_back,
            anti,
            field_sums,
        };
        let change_parts: Vec<SweepSums> = next_radiance
            .par_iter_mut()
            .zip(anti_out.into_par_iter())
            .zip(back_out.par_iter_mut())
            .enumerate()
            .map_init(
                || vec![[0.0f64; C]; 2 * nb],
                |a_acc, (e, ((b_out, a_out), back_out))| {
                    ctx.gather_element(
                        e,
                        (sources, &state),
                        a_acc,
                        (b_out, a_out, back_out.as_deref_mut()),
                    )
                },
            )
            .collect();

        let sums = change_parts
            .iter()
            .fold(SweepSums::default(), |acc, p| acc.add(*p));
        sums
    }

    /// The solution and the state of a finished solve: elements to patches, the statistics
    /// and health checks of the result, the state to warm-start from.
    #[allow(clippy::type_complexity)]
    fn finish_channels<const C: usize>(
        &mut self,
        patches: &Patches,
        elem_source: &[[f64; 3]],
        t0: Instant,
        (radiance, radiance_back, anti): (Vec<[f64; C]>, Vec<[f64; C]>, Vec<[f32; C]>),
        (mut stats, mut memory, bound): (SolveStats, MemoryStats, Option<f64>),
        (anderson, convergence, guard, last, earlier): (
            Option<Anderson>,
            Convergence,
            Guard,
            usize,
            Vec<std::sync::Arc<ElementState>>,
        ),
    ) -> (Solution, ElementState) {
        let (options, elem_area) = (&self.options, &self.elem_area);
        let (n, backs) = (self.element_count(), self.elem_two.len());
        // Elements -> patches (area-weighted mean, RGB); patches without elements (inactive) get
        // 0 here and their emission from `solve_with_emission`.
        let radiance_rgb: Vec<[f64; 3]> = radiance.iter().map(|&b| rgb_of(b)).collect();
        let radiance_back_rgb: Vec<[f64; 3]> = radiance_back.iter().map(|&b| rgb_of(b)).collect();
        let means = |values: &[[f64; 3]]| -> Vec<[f64; 3]> {
            crate::mesh::patch_means(
                patches.len(),
                (0..values.len()).map(|e| (self.elem_patch[e] as usize, elem_area[e], values[e])),
            )
            .into_iter()
            .map(|m| m.unwrap_or([0.0; 3]))
            .collect()
        };
        let patch_radiance = means(&radiance_rgb);
        let patch_radiance_back = if backs > 0 {
            means(&radiance_back_rgb)
        } else {
            Vec::new()
        };
        self.timings.iterate = t0.elapsed().as_secs_f64();
        stats.stage_seconds = Some(self.timings.clone());
        stats.link_stats = Some(crate::solve::solution::LinkReport {
            cluster_links: self.links.cluster.len() as u64,
            exact_links: self.links.exact_sender.len() as u64,
            refinement: self.links.stats.clone(),
        });
        stats.elements = n;
        (stats.element_link_pairs, stats.pull_terms) = self.sweep_work();
        (stats.field_links, stats.field_evaluations) = (self.fields.links, self.fields.evaluations);
        stats.pushed_links = self.fields.pushed;
        memory.peak_bytes = crate::memory::peak_rss_bytes();
        stats.memory = Some(memory);
        // The result is checked against the bound of this solve's source (with exact direct
        // light, the reflected direct light: a tighter bound than the emission's).
        let solution = crate::solve::solution::finish_sides(
            patches,
            patch_radiance,
            patch_radiance_back,
            stats,
            options.clamp_negative,
            bound,
        );
        let resume = Resume {
            anderson,
            convergence,
            guard,
            sweeps: last,
            max_row_sum: solution.stats.max_row_sum,
            extrapolations: solution.stats.extrapolations,
            damped_after: solution.stats.damped_after,
            radiance_damped_after: solution.stats.radiance_damped_after,
            floor_closed_after: solution.stats.floor_closed_after,
        };
        let state = ElementState {
            radiance: radiance_rgb,
            radiance_back: radiance_back_rgb,
            anti: anti.iter().flatten().copied().collect(),
            channels: C,
            source: elem_source.to_vec(),
            resume: Some(Box::new(resume)),
            earlier,
        };
        (solution, state)
    }
}
