//! Solving a [`Relighter`]'s current lighting: warm-started, progressively within a frame
//! budget, or from scratch as the converged reference.

use std::time::{Duration, Instant};

use super::{Lighting, Relighter, Relit, REFERENCE_TOLERANCE_FACTOR, RESCALE_FACTOR};
use crate::error::Result;
use crate::progress::Progress;
use crate::solve::hierarchical::ElementState;
use crate::solve::solution::Solution;

impl Relighter {
    /// The largest emission channel of any triangle, or direct radiance of any patch from
    /// `source` (the analytic lights'), scene units.
    pub(super) fn brightest(&self, source: &[[f64; 3]]) -> f64 {
        self.emission
            .iter()
            .chain(source)
            .flat_map(|e| e.iter().copied())
            .fold(0.0f64, f64::max)
    }

    /// Sets the patches' emission, source and lights to the current ones over the current
    /// normalization scale (`source`: the analytic lights' direct light per face of the
    /// solver, scene units, or empty; the patches get its mean over their faces, front and
    /// back).
    pub(super) fn sync_patches(&mut self, source: &[[f64; 3]], lighting: Lighting) {
        let scale = self.patches.emission_scale;
        for (p, &t) in self.patches.parent.iter().enumerate() {
            self.patches.emission[p] = self.emission[t as usize].map(|x| x / scale);
        }
        let (front, back) = self
            .prepared
            .patch_means_of_faces(source, self.patches.len());
        self.patches.source = front.iter().map(|s| s.map(|x| x / scale)).collect();
        if self.patches.has_two_sided() {
            self.patches.source_back = back.iter().map(|s| s.map(|x| x / scale)).collect();
        }
        self.patches.lights = match lighting {
            Lighting::All => self
                .analytic
                .iter()
                .map(|a| a.light.to_unit(&self.patches.frame, scale))
                .collect(),
            Lighting::EmissionOnly => Vec::new(),
        };
    }

    /// Sets the patches to the current lighting at the current normalization scale (after a
    /// solve of other lighting), tracing the shadow rays of lights that moved.
    pub(super) fn resync(&mut self) {
        self.update_light_sources();
        let source = self.light_source(Lighting::All);
        self.sync_patches(&source, Lighting::All);
    }

    /// Forgets the last solution: the next solve starts from the emission, as a from-scratch
    /// solve would (same links, so the same answer up to the tolerance).
    pub fn forget_warm_start(&mut self) {
        self.warm = None;
        self.last = None;
    }

    /// Solves for the current lighting, warm-started from the previous solve when there is
    /// one; with [`Relighter::frame_budget`] set, only the sweeps that fit it (progressive
    /// relighting: call again to go on). Returns a solution in every case (the lighting was
    /// checked when it was set; no NaN reaches the solution), but one whose solve failed its
    /// health checks carries `solution.stats.failure` with `converged == false`
    /// ([`crate::solve::health`]; check it with
    /// [`crate::solve::solution::SolveStats::check`]): its radiance is not a solution, and the
    /// next solve starts cold rather than from it. When nothing changed since a converged
    /// solve, that solution is returned again (0 iterations).
    pub fn solve(&mut self, progress: &Progress) -> Relit {
        let start = Instant::now();
        let budget = self.frame_budget;
        let warm = self.warm.take();
        let last = self.last.take();
        let (relit, state) =
            self.solve_lighting(warm, last, budget, Lighting::All, start, progress);
        // A failed solve's state is not worth starting from.
        if relit.solution.stats.failure.is_none() {
            self.warm = state;
            self.last = relit
                .solution
                .stats
                .converged
                .then(|| relit.solution.clone());
        }
        relit
    }

    /// One solve of `lighting` from `warm` (`last`: its converged solution, if any), within
    /// `budget` from `start`; returns the relight and the state to go on from.
    pub(super) fn solve_lighting(
        &mut self,
        warm: Option<ElementState>,
        last: Option<Solution>,
        budget: Option<Duration>,
        lighting: Lighting,
        start: Instant,
        progress: &Progress,
    ) -> (Relit, Option<ElementState>) {
        let direct_seconds = match lighting {
            Lighting::All => self.update_light_sources(),
            Lighting::EmissionOnly => 0.0,
        };
        let source = self.light_source(lighting);
        let brightest = self.brightest(&source);
        let scale = self.patches.emission_scale;
        // Without a warm state the normalization is free: use the brightest emission, exactly
        // as a from-scratch solve does. With one, keep its scale unless the lights drifted by
        // more than RESCALE_FACTOR (then the old state is not worth keeping anyway).
        let mut warm = warm;
        if brightest > 0.0
            && (warm.is_none()
                || brightest > scale * RESCALE_FACTOR
                || brightest < scale / RESCALE_FACTOR)
        {
            self.patches.emission_scale = brightest;
            warm = None;
        }
        self.sync_patches(&source, lighting);
        // The emission per patch, the analytic lights' direct light per face.
        let mut elem_source = self
            .prepared
            .element_source_sides(&self.patches.emission, &self.patches.emission_back());
        let scale = self.patches.emission_scale;
        crate::mesh::lights::add_into(
            &mut elem_source,
            source.iter().map(|l| l.map(|x| x / scale)),
        );
        // Nothing changed since a converged solve: its solution stands.
        if let (Some(w), Some(solution)) = (&warm, last) {
            if w.source() == elem_source.as_slice() {
                let mut solution = solution;
                solution.stats.iterations = 0;
                let relit = Relit {
                    solution,
                    warm_started: true,
                    seconds: start.elapsed().as_secs_f64(),
                    direct_seconds,
                };
                return (relit, warm);
            }
        }
        let warm_started = warm.is_some();
        let deadline = budget
            .map(|b| start + b.saturating_sub(Duration::from_secs_f64(self.tail_seconds.min(1e6))));
        let solver_start = Instant::now();
        let (solution, state) =
            self.prepared
                .resume_with_source(&self.patches, &elem_source, warm, deadline, progress);
        let sweeps_done = solution
            .stats
            .stage_seconds
            .as_ref()
            .map_or(0.0, |t| t.iterate);
        self.tail_seconds = (solver_start.elapsed().as_secs_f64() - sweeps_done).max(0.0);
        let relit = Relit {
            solution,
            warm_started,
            seconds: start.elapsed().as_secs_f64(),
            direct_seconds,
        };
        (relit, Some(state))
    }

    /// A from-scratch solve of the current lighting to [`REFERENCE_TOLERANCE_FACTOR`] times the
    /// solver's tolerance, without a time budget: the converged answer a relight (in
    /// particular a progressive one) is measured against. The warm state and the next solve
    /// are left as they were.
    pub fn converged(&mut self, progress: &Progress) -> Relit {
        let start = Instant::now();
        let scale = self.patches.emission_scale;
        let tail = self.tail_seconds;
        let tol = self.prepared.options.tol;
        self.prepared.options.tol = tol * REFERENCE_TOLERANCE_FACTOR;
        let (relit, _) = self.solve_lighting(None, None, None, Lighting::All, start, progress);
        self.prepared.options.tol = tol;
        self.patches.emission_scale = scale;
        self.tail_seconds = tail;
        self.resync();
        relit
    }

    /// Sets the emission of every input triangle ([`Relighter::set_emission`]) and solves
    /// (without a progress bar).
    ///
    /// Errors: as [`Relighter::set_emission`]; nothing is solved then.
    pub fn relight(&mut self, per_triangle: &[[f64; 3]]) -> Result<Relit> {
        self.set_emission(per_triangle)?;
        Ok(self.solve(&Progress::hidden()))
    }
}
