//! Interactive relighting: build the hierarchy and links of a scene once, then re-solve it for
//! new lighting as often as needed, each solve warm-started from the previous one.
//!
//! Links, form factors and antiradiance couplings depend only on geometry, albedo and solver
//! options, never on the lights (the equations are linear in the source). A [`Relighter`]
//! therefore pays for the tree and the links once ([`Relighter::new`]) and each relight is only
//! the Jacobi sweeps of [`Prepared::resume_with_source`], started from the previous answer with
//! each element moved by the change of its own source, and with the previous solve's Anderson
//! history: its differences of sweeps do not depend on the source, so the slow modes it found
//! (the overall light level of a closed room) are removed from the first sweep on. On the seed
//! room a random change of every emitter's brightness is within 0.3–0.6% of the converged answer
//! after one sweep, and a relight to the tolerance takes 2–3 sweeps where a cold solve takes 7–9
//! (docs/performance.md).
//!
//! What can change:
//!
//! - emission, per input triangle ([`Relighter::set_emission`],
//!   [`Relighter::set_triangle_emission`]) or per material name
//!   ([`Relighter::set_material_emission`], for scenes loaded from OBJ+MTL), in the scene's own
//!   units (W / (m² sr), RGB);
//! - the scene's analytic lights ([`Scene::lights`]: point, spot, sun, sky), moved, turned or
//!   recoloured ([`Relighter::set_analytic_light`]). Their direct light is computed with shadow
//!   rays, as in a from-scratch solve ([`crate::mesh::lights`]), once per light and position:
//!   a change of intensity only rescales it (it is linear in the colour), a move recomputes
//!   that light's alone; the indirect bounces are re-solved warm-started.
//!
//! Every solution comes back in the scene's units, as from a from-scratch solve of the same
//! lighting (up to the solver's tolerance).
//!
//! **Progressive relighting.** With [`Relighter::frame_budget`] set, each
//! [`Relighter::solve`] does as many sweeps as fit the budget and returns the current iterate;
//! the iteration goes on at the next call (its sweep count, convergence estimate, health checks
//! and Anderson history are kept), so an interactive caller calls it once per frame and the
//! answer converges over frames, like Enlighten spreads its updates. A frame whose lighting did
//! not change since a converged solve costs nothing (the converged solution is returned).
//!
//! # Example
//!
//! ```
//! use antiradiance::scene::generated;
//! use antiradiance::scene::lights::Light;
//! use antiradiance::solve::relight::Relighter;
//! use antiradiance::solve::SolverOptions;
//! use glam::DVec3;
//!
//! # fn main() -> antiradiance::Result<()> {
//! let mut scene = generated::cornell_box();
//! scene.lights.push(Light::Point {
//!     position: DVec3::new(278.0, 400.0, 279.0),
//!     intensity: [2e4; 3],
//! });
//! // Tree and links are built here, once.
//! let mut relighter = Relighter::new(&scene, None, &SolverOptions::fast())?;
//!
//! // The lights as modelled, then the area light at half power: a warm-started re-solve.
//! let full = relighter.solve(&antiradiance::progress::Progress::hidden());
//! let mut dimmed = scene.emission.clone();
//! for e in dimmed.iter_mut() {
//!     *e = e.map(|x| 0.5 * x);
//! }
//! let half = relighter.relight(&dimmed)?;
//! assert!(half.warm_started);
//!
//! // The point light moved and dimmed: its shadow rays are traced again, the rest re-solved.
//! relighter.set_analytic_light(
//!     0,
//!     Light::Point {
//!         position: DVec3::new(150.0, 450.0, 200.0),
//!         intensity: [1e4; 3],
//!     },
//! )?;
//! let moved = relighter.solve(&antiradiance::progress::Progress::hidden());
//! assert!(moved.solution.stats.converged);
//!
//! // Progressive: a time budget per call, converging over calls.
//! relighter.frame_budget = Some(std::time::Duration::from_millis(5));
//! relighter.set_triangle_emission(0, [1.0, 1.0, 1.0])?;
//! let mut frames = 0;
//! while !relighter.solve(&antiradiance::progress::Progress::hidden()).solution.stats.converged {
//!     frames += 1;
//! }
//! assert!(frames < 100);
//!
//! // Bad input is an error, not a panic, and changes nothing.
//! assert!(relighter.set_triangle_emission(0, [f64::NAN, 0.0, 0.0]).is_err());
//! assert!(relighter.set_emission(&dimmed[..3]).is_err());
//! assert!(relighter.set_analytic_light(7, scene.lights[0]).is_err());
//! # let _ = (full, half);
//! # Ok(())
//! # }
//! ```
//!
//! The command `antiradiance relight` animates the lights this way and writes one picture per
//! frame with the time each relight took.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use glam::DVec3;

use crate::error::{Error, Result};
use crate::geometry::raytrace::RayScene;
use crate::mesh::{self, Patches};
use crate::progress::Progress;
use crate::scene::lights::Light;
use crate::scene::Scene;
use crate::solve::hierarchical::{ElementState, Prepared};
use crate::solve::solution::Solution;
use crate::solve::SolverOptions;

/// Largest factor by which the brightest emission may drift from the normalization scale of the
/// warm state before the state is dropped and the scale reset (keeps the solver's f32
/// antiradiance far from overflow and underflow).
pub const RESCALE_FACTOR: f64 = 1e6;

/// The tolerance of [`Relighter::converged`] against the solver's own: the reference a relight is
/// measured against is solved ten times tighter than the relights themselves.
pub const REFERENCE_TOLERANCE_FACTOR: f64 = 0.1;

/// One relight: the solution and how it was obtained.
#[derive(Clone, Debug)]
pub struct Relit {
    /// Outgoing radiance per patch and per input triangle, in the scene's units
    /// (W / (m² sr), RGB), with the solver's statistics: `iterations` are the sweeps of this
    /// relight (0 when nothing changed since a converged one), `converged` says whether the
    /// tolerance was reached (in progressive mode, not before the last frame).
    pub solution: Solution,
    /// True when the solve started from the previous solution rather than from the emission.
    pub warm_started: bool,
    /// Wall-clock seconds of the relight: shadow rays of the analytic lights that changed,
    /// sweeps, and the solution (tree and links were built before).
    pub seconds: f64,
    /// Of `seconds`, those spent on the direct light of analytic lights that moved.
    pub direct_seconds: f64,
}

/// A scene prepared once (patches, cluster tree, links) and re-solved for new lighting.
///
/// Holds the current emission per input triangle (scene units), the analytic lights, and the
/// solver state of the last solve, from which the next one starts. See the
/// [module documentation](self).
pub struct Relighter {
    /// The solver's patches; `emission` and `source` hold the current emission and analytic
    /// lights' direct light divided by `emission_scale` (the normalization of the warm state),
    /// `lights` the analytic lights in the unit frame.
    patches: Patches,
    /// Tree and links, built once.
    prepared: Prepared,
    /// Current emission per input triangle, scene units.
    emission: Vec<[f64; 3]>,
    /// Per input triangle, its material's name index (`None`: no material).
    material: Vec<Option<u32>>,
    /// Material names of the scene.
    material_names: Vec<String>,
    /// The analytic lights, as currently set.
    analytic: Vec<AnalyticLight>,
    /// State of the last solve (normalized by `patches.emission_scale`).
    warm: Option<ElementState>,
    /// The last solution when it converged (returned again while nothing changes).
    last: Option<Solution>,
    /// Seconds the last solve spent after its sweeps (the solution's assembly), kept out of
    /// the next frame's sweep budget.
    tail_seconds: f64,
    /// Seconds spent building patches, tree and links.
    build_seconds: f64,
    /// Precomputed lights ([`Relighter::add_light`]).
    lights: Vec<PrecomputedLight>,
    /// Progressive relighting: the wall-clock time each [`Relighter::solve`] may take. It does
    /// as many sweeps as are expected to fit (at least one) and stops, unconverged unless the
    /// tolerance was reached; the next call goes on from there. `None` (the default): every
    /// solve runs to the tolerance.
    pub frame_budget: Option<Duration>,
}

/// An analytic light of a [`Relighter`] and its direct light.
#[derive(Clone, Debug)]
struct AnalyticLight {
    /// The light as set, scene frame, radiometric.
    light: Light,
    /// Reflected direct radiance per patch at colour (1, 1, 1), scene units; `None` until
    /// computed for the light's present position.
    unit_source: Option<Vec<[f64; 3]>>,
}

/// A light of a [`Relighter`]: an emission pattern and the scene's response to it.
#[derive(Clone, Debug)]
struct PrecomputedLight {
    /// Its name, as given.
    name: String,
    /// Emission per input triangle at unit intensity, scene units.
    emission: Vec<[f64; 3]>,
    /// Outgoing radiance per patch it causes, scene units, negative values kept.
    response: Vec<[f64; 3]>,
}

/// What a solve of the relighter solves for.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Lighting {
    /// The emission and the analytic lights.
    All,
    /// The emission alone (a precomputed light's response).
    EmissionOnly,
}

impl Relighter {
    /// Builds patches (`max_edge` splits input triangles as in [`mesh::build_patches`];
    /// `None` keeps them), cluster tree and links of `scene` for `options`. The emission and
    /// analytic lights are the scene's own until changed.
    ///
    /// Errors: [`Error::Parameter`] for invalid `options`, a `max_edge` that is not a finite
    /// positive length or would make more than [`mesh::MAX_PATCHES`] patches, invalid
    /// emission or an invalid analytic light in the scene; [`Error::Scene`] for a scene without
    /// triangles, with a non-finite vertex or a vertex index out of range.
    pub fn new(scene: &Scene, max_edge: Option<f64>, options: &SolverOptions) -> Result<Relighter> {
        let start = Instant::now();
        check_lights(scene)?;
        let patches = mesh::checked_patches(scene, max_edge)?;
        options.validate()?;
        let mut relighter = Relighter::from_patches(scene, patches, options)?;
        relighter.build_seconds = start.elapsed().as_secs_f64();
        Ok(relighter)
    }

    /// Like [`Relighter::new`] for patches already built from `scene` with
    /// [`mesh::build_patches`] (the command-line driver has them from loading).
    ///
    /// Errors: as [`Relighter::new`], and [`Error::Parameter`] when `patches` were not built
    /// from a scene with as many triangles as `scene`.
    pub fn from_patches(
        scene: &Scene,
        patches: Patches,
        options: &SolverOptions,
    ) -> Result<Relighter> {
        let start = Instant::now();
        mesh::check_scene(scene)?;
        check_lights(scene)?;
        options.validate()?;
        if patches.has_two_sided() && !scene.lights.is_empty() {
            return Err(Error::Parameter(
                "relighting a scene with two-sided surfaces and analytic lights is not supported (the lights' direct light on back faces is not recomputed); solve it instead".into(),
            ));
        }
        if patches.first.len() != scene.len() + 1
            || patches.parent.len() != patches.len()
            || patches.parent.iter().any(|&t| t as usize >= scene.len())
        {
            return Err(Error::Parameter(format!(
                "the patches were built from a scene of {} triangles, not this one of {}",
                patches.first.len().saturating_sub(1),
                scene.len()
            )));
        }
        for (t, &e) in scene.emission.iter().enumerate() {
            check_radiance(e, || format!("emission of scene triangle {t}"))?;
        }
        let prepared = Prepared::new(&patches, options, false)?;
        let material = (0..scene.len())
            .map(|t| scene.material.get(t).copied().flatten())
            .collect();
        Ok(Relighter {
            patches,
            prepared,
            emission: scene.emission.clone(),
            material,
            material_names: scene.material_names.clone(),
            analytic: scene
                .lights
                .iter()
                .map(|&light| AnalyticLight {
                    light,
                    unit_source: None,
                })
                .collect(),
            warm: None,
            last: None,
            tail_seconds: 0.0,
            build_seconds: start.elapsed().as_secs_f64(),
            lights: Vec::new(),
            frame_budget: None,
        })
    }

    /// Number of input triangles (the length of [`Relighter::emission`] and of every
    /// `triangle_radiance`).
    pub fn triangle_count(&self) -> usize {
        self.emission.len()
    }

    /// The solver's patches. Their `emission`, `source` and `lights` are those of the last
    /// solve (or of the scene before the first one), normalized by their `emission_scale`, so
    /// they render and export consistently with the last solution.
    pub fn patches(&self) -> &Patches {
        &self.patches
    }

    /// The prepared tree and links (link counts, element counts, memory).
    pub fn prepared(&self) -> &Prepared {
        &self.prepared
    }

    /// Wall-clock seconds spent building patches, tree and links (paid once).
    pub fn build_seconds(&self) -> f64 {
        self.build_seconds
    }

    /// The current emission per input triangle, scene units (W / (m² sr), RGB).
    pub fn emission(&self) -> &[[f64; 3]] {
        &self.emission
    }

    /// The scene's material names (those [`Relighter::set_material_emission`] accepts).
    pub fn material_names(&self) -> &[String] {
        &self.material_names
    }

    /// The analytic lights as currently set (scene frame, radiometric), in the order of
    /// [`Scene::lights`].
    pub fn analytic_lights(&self) -> Vec<Light> {
        self.analytic.iter().map(|a| a.light).collect()
    }

    /// Replaces analytic light `index` (its place in [`Scene::lights`]) by `light`: moved,
    /// turned, recoloured, or of another kind. Takes effect at the next solve: a light that only
    /// changed colour has its direct light rescaled; any other change traces its shadow rays
    /// again (only this light's), within that solve's time.
    ///
    /// Errors: [`Error::Parameter`] when the scene has no light `index` (the message lists
    /// them) or `light` is invalid ([`Light::validate`]); nothing changes then.
    pub fn set_analytic_light(&mut self, index: usize, light: Light) -> Result<()> {
        let Some(current) = self.analytic.get(index) else {
            return Err(Error::Parameter(format!(
                "no analytic light {index}: {}",
                self.describe_lights()
            )));
        };
        light.validate(&format!("analytic light {index}"))?;
        let same_place = light.with_colour([1.0; 3]) == current.light.with_colour([1.0; 3]);
        let entry = &mut self.analytic[index];
        entry.light = light;
        if !same_place {
            entry.unit_source = None;
        }
        Ok(())
    }

    /// The analytic lights by index and kind, for messages.
    fn describe_lights(&self) -> String {
        if self.analytic.is_empty() {
            return "the scene has no analytic lights".to_string();
        }
        let kinds: Vec<String> = self
            .analytic
            .iter()
            .enumerate()
            .map(|(k, a)| format!("{k} {}", light_kind(&a.light)))
            .collect();
        format!(
            "the scene has {} (numbered from 0: {})",
            self.analytic.len(),
            kinds.join(", ")
        )
    }

    /// Replaces the emission of every input triangle (scene units, RGB, input order). Takes
    /// effect at the next solve.
    ///
    /// Errors: [`Error::Parameter`] when the length is not the triangle count or a value is
    /// negative, NaN or infinite; the emission is then left unchanged.
    pub fn set_emission(&mut self, per_triangle: &[[f64; 3]]) -> Result<()> {
        if per_triangle.len() != self.emission.len() {
            return Err(Error::Parameter(format!(
                "emission has {} values but the scene has {} triangles",
                per_triangle.len(),
                self.emission.len()
            )));
        }
        for (t, &e) in per_triangle.iter().enumerate() {
            check_radiance(e, || format!("emission of triangle {t}"))?;
        }
        self.emission.copy_from_slice(per_triangle);
        Ok(())
    }

    /// Sets the emission of input triangle `t` (scene units, RGB). Takes effect at the next
    /// solve.
    ///
    /// Errors: [`Error::Parameter`] when `t` is out of range or a value is negative, NaN or
    /// infinite (nothing changes).
    pub fn set_triangle_emission(&mut self, t: usize, rgb: [f64; 3]) -> Result<()> {
        if t >= self.emission.len() {
            return Err(Error::Parameter(format!(
                "triangle {t} out of range (the scene has {} triangles)",
                self.emission.len()
            )));
        }
        check_radiance(rgb, || format!("emission of triangle {t}"))?;
        self.emission[t] = rgb;
        Ok(())
    }

    /// Sets the emission of every triangle whose material is called `name` (scene units, RGB);
    /// returns how many triangles that is. Takes effect at the next solve.
    ///
    /// Errors: [`Error::Parameter`] when no material has that name (the message lists the
    /// names) or a value is negative, NaN or infinite (nothing changes).
    pub fn set_material_emission(&mut self, name: &str, rgb: [f64; 3]) -> Result<usize> {
        check_radiance(rgb, || format!("emission of material '{name}'"))?;
        let ids: Vec<u32> = (0..self.material_names.len() as u32)
            .filter(|&m| self.material_names[m as usize] == name)
            .collect();
        if ids.is_empty() {
            let known = if self.material_names.is_empty() {
                "the scene has no materials".to_string()
            } else {
                format!("materials: {}", self.material_names.join(", "))
            };
            return Err(Error::Parameter(format!(
                "no material named '{name}' ({known})"
            )));
        }
        let mut changed = 0;
        for (t, m) in self.material.iter().enumerate() {
            if m.is_some_and(|m| ids.contains(&m)) {
                self.emission[t] = rgb;
                changed += 1;
            }
        }
        Ok(changed)
    }

    /// Computes the direct light of every analytic light that moved since its last one (shadow
    /// rays); returns the seconds spent.
    fn update_light_sources(&mut self) -> f64 {
        if self.analytic.iter().all(|a| a.unit_source.is_some()) {
            return 0.0;
        }
        let start = Instant::now();
        let rays = RayScene::new(&self.patches.corners, &self.patches.active);
        for (k, a) in self.analytic.iter_mut().enumerate() {
            if a.unit_source.is_none() {
                let unit = a
                    .light
                    .with_colour([1.0; 3])
                    .to_unit(&self.patches.frame, 1.0);
                a.unit_source = Some(mesh::lights::light_source(&self.patches, &rays, &unit, k));
            }
        }
        start.elapsed().as_secs_f64()
    }

    /// The analytic lights' reflected direct radiance per patch, scene units (empty when
    /// `lighting` leaves them out or the scene has none). Lights whose direct light is not
    /// computed yet ([`Relighter::update_light_sources`]) are left out.
    fn light_source(&self, lighting: Lighting) -> Vec<[f64; 3]> {
        if lighting == Lighting::EmissionOnly || self.analytic.is_empty() {
            return Vec::new();
        }
        let mut total = vec![[0.0f64; 3]; self.patches.len()];
        for a in &self.analytic {
            let colour = a.light.colour();
            let Some(unit) = a.unit_source.as_ref() else {
                continue;
            };
            for (sum, d) in total.iter_mut().zip(unit) {
                for c in 0..3 {
                    sum[c] += colour[c] * d[c];
                }
            }
        }
        total
    }

    /// True when some analytic light gives any light.
    fn analytic_lit(&self) -> bool {
        self.analytic.iter().any(|a| a.light.strength() > 0.0)
    }

    /// The largest emission channel of any triangle, or direct radiance of any patch from
    /// `source` (the analytic lights'), scene units.
    fn brightest(&self, source: &[[f64; 3]]) -> f64 {
        self.emission
            .iter()
            .chain(source)
            .flat_map(|e| e.iter().copied())
            .fold(0.0f64, f64::max)
    }

    /// Sets the patches' emission, source and lights to the current ones over the current
    /// normalization scale (`source`: the analytic lights' direct light, scene units, or empty).
    fn sync_patches(&mut self, source: &[[f64; 3]], lighting: Lighting) {
        let scale = self.patches.emission_scale;
        for (p, &t) in self.patches.parent.iter().enumerate() {
            self.patches.emission[p] = self.emission[t as usize].map(|x| x / scale);
        }
        self.patches.source = source.iter().map(|s| s.map(|x| x / scale)).collect();
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
    fn resync(&mut self) {
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
    fn solve_lighting(
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
        let elem_source = self.prepared.element_source_sides(
            &self.patches.emission_and_source(),
            &self.patches.emission_and_source_back(),
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

    /// Precomputes the scene's response to an emission pattern (scene units per input
    /// triangle, at unit intensity) as a light that [`Relighter::mix`] can then scale and
    /// combine with the others in time linear in the patch count, with no sweep: radiance is
    /// linear in emission, so a mix is exactly the solve of the mixed emission (up to the
    /// tolerance each light was solved to). One from-scratch solve per light, of the pattern
    /// alone (without the analytic lights); returns the light's index. The relighter's current
    /// lighting and warm state are left unchanged.
    ///
    /// Errors: as [`Relighter::set_emission`], and [`Error::Solve`] when the light's solve
    /// failed its health checks ([`crate::solve::health`]); nothing is added either way.
    pub fn add_light(&mut self, name: &str, per_triangle: &[[f64; 3]]) -> Result<usize> {
        let current = self.emission.clone();
        let scale = self.patches.emission_scale;
        let tail = self.tail_seconds;
        self.set_emission(per_triangle)?;
        // Keep negative radiance: the sum of clamped responses would not be the clamped sum.
        let clamp = std::mem::replace(&mut self.prepared.options.clamp_negative, false);
        let (relit, _) = self.solve_lighting(
            None,
            None,
            None,
            Lighting::EmissionOnly,
            Instant::now(),
            &Progress::hidden(),
        );
        self.prepared.options.clamp_negative = clamp;
        self.emission = current;
        self.patches.emission_scale = scale;
        self.tail_seconds = tail;
        self.resync();
        relit
            .solution
            .stats
            .check("hierarchical")
            .map_err(|e| Error::Solve(format!("light '{name}': {e}")))?;
        self.lights.push(PrecomputedLight {
            name: name.to_string(),
            emission: per_triangle.to_vec(),
            response: relit.solution.patch_radiance,
        });
        Ok(self.lights.len() - 1)
    }
    /// Adds one light ([`Relighter::add_light`]) per material that emits in the current
    /// emission, named after the material, with that material's triangles at their current
    /// emission; returns their indices.
    ///
    /// Errors: [`Error::Solve`] when a light's solve failed its health checks (the lights
    /// added before it stay).
    pub fn add_material_lights(&mut self) -> Result<Vec<usize>> {
        let mut added = Vec::new();
        for m in 0..self.material_names.len() as u32 {
            let emission: Vec<[f64; 3]> = (0..self.emission.len())
                .map(|t| {
                    if self.material[t] == Some(m) {
                        self.emission[t]
                    } else {
                        [0.0; 3]
                    }
                })
                .collect();
            if emission.iter().any(|e| e.iter().any(|&x| x > 0.0)) {
                let name = self.material_names[m as usize].clone();
                added.push(self.add_light(&name, &emission)?);
            }
        }
        Ok(added)
    }

    /// Adds one light ([`Relighter::add_light`]) per band of `emitters` (input triangles, with
    /// their `centroids`) cut by [`emitter_bands`] into at most `bands` bands, each band's
    /// triangles at their current emission; returns the centres of the bands added, in light
    /// order (after any lights added before).
    ///
    /// Errors: [`Error::Parameter`] when `bands` is 0, the two slices differ in length or an
    /// emitter index is out of range (nothing is added).
    pub fn add_band_lights(
        &mut self,
        emitters: &[usize],
        centroids: &[DVec3],
        bands: usize,
    ) -> Result<Vec<DVec3>> {
        if bands == 0 || emitters.len() != centroids.len() {
            return Err(Error::Parameter(format!(
                "{bands} bands of {} emitters with {} centroids",
                emitters.len(),
                centroids.len()
            )));
        }
        if let Some(&t) = emitters.iter().find(|&&t| t >= self.emission.len()) {
            return Err(Error::Parameter(format!(
                "emitter {t} out of range (the scene has {} triangles)",
                self.emission.len()
            )));
        }
        let (band, centres) = emitter_bands(centroids, bands);
        for k in 0..centres.len() {
            let mut emission = vec![[0.0; 3]; self.emission.len()];
            for (&t, &b) in emitters.iter().zip(&band) {
                if b == k {
                    emission[t] = self.emission[t];
                }
            }
            self.add_light(&format!("band {k}"), &emission)?;
        }
        Ok(centres)
    }

    /// Names of the precomputed lights, in index order.
    pub fn light_names(&self) -> Vec<&str> {
        self.lights.iter().map(|l| l.name.as_str()).collect()
    }

    /// The solution for the precomputed lights at the given RGB intensities (one per light,
    /// index order; 1 = as added), by linear combination: no sweep, time linear in the patch
    /// count. The emission becomes the mix's, and the next [`Relighter::solve`] starts cold.
    ///
    /// Errors: [`Error::Parameter`] when the count is not the number of lights, an intensity
    /// is negative, NaN or infinite, or an analytic light is lit (the precomputed lights are
    /// emission patterns; the analytic lights' share needs [`Relighter::solve`]): nothing
    /// changes then.
    pub fn mix(&mut self, intensities: &[[f64; 3]]) -> Result<Relit> {
        let start = Instant::now();
        if self.analytic_lit() {
            return Err(Error::Parameter(
                "mix() combines precomputed emission lights, and the scene's analytic lights are lit; set their colour to 0 or solve() instead".into(),
            ));
        }
        if self.patches.has_two_sided() {
            return Err(Error::Parameter(
                "mix() keeps the front faces of its precomputed lights only, and the scene has two-sided surfaces; solve() instead".into(),
            ));
        }
        if intensities.len() != self.lights.len() {
            return Err(Error::Parameter(format!(
                "{} intensities for {} lights",
                intensities.len(),
                self.lights.len()
            )));
        }
        for (k, &w) in intensities.iter().enumerate() {
            check_radiance(w, || format!("intensity of light {k}"))?;
        }
        let mut emission = vec![[0.0f64; 3]; self.emission.len()];
        let mut radiance = vec![[0.0f64; 3]; self.patches.len()];
        for (light, w) in self.lights.iter().zip(intensities) {
            for (dst, src) in emission.iter_mut().zip(&light.emission) {
                for c in 0..3 {
                    dst[c] += w[c] * src[c];
                }
            }
            for (dst, src) in radiance.iter_mut().zip(&light.response) {
                for c in 0..3 {
                    dst[c] += w[c] * src[c];
                }
            }
        }
        self.emission = emission;
        self.forget_warm_start();
        let brightest = self.brightest(&[]);
        if brightest > 0.0 {
            self.patches.emission_scale = brightest;
        }
        self.sync_patches(&[], Lighting::All);
        let scale = self.patches.emission_scale;
        let normalized: Vec<[f64; 3]> = radiance.iter().map(|b| b.map(|x| x / scale)).collect();
        let stats = crate::solve::solution::SolveStats {
            converged: true,
            links: self.prepared.links.len() as u64,
            ..Default::default()
        };
        let solution = crate::solve::finish(
            &self.patches,
            normalized,
            stats,
            self.prepared.options.clamp_negative,
            crate::solve::emission_bound(&self.patches, self.prepared.options.antiradiance),
        );
        Ok(Relit {
            solution,
            warm_started: false,
            seconds: start.elapsed().as_secs_f64(),
            direct_seconds: 0.0,
        })
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

/// Rejects an emitted radiance with a negative, NaN or infinite channel.
fn check_radiance(rgb: [f64; 3], what: impl FnOnce() -> String) -> Result<()> {
    if rgb.iter().all(|&x| x.is_finite() && x >= 0.0) {
        Ok(())
    } else {
        Err(Error::Parameter(format!(
            "{} is ({}, {}, {}); each channel must be finite and >= 0",
            what(),
            rgb[0],
            rgb[1],
            rgb[2]
        )))
    }
}

/// Checks the scene's analytic lights ([`Light::validate`]).
fn check_lights(scene: &Scene) -> Result<()> {
    for (k, light) in scene.lights.iter().enumerate() {
        light.validate(&format!("analytic light {k}"))?;
    }
    Ok(())
}

/// The kind of a light, as the command line names it.
pub fn light_kind(light: &Light) -> &'static str {
    match light {
        Light::Point { .. } => "point",
        Light::Spot { .. } => "spot",
        Light::Sun { .. } => "sun",
        Light::Sky { .. } => "sky",
    }
}

// ---------------------------------------------------------------------------------------------
// The animation of the command line

/// Width (standard deviation) of the sweeping spot, as a fraction of the emitters' extent
/// along the sweep axis.
pub const SPOT_WIDTH: f64 = 0.15;

/// The axis (0, 1, 2) along which `centroids` spread most, with the lowest corner of their
/// bounds and their extent along it (0 or NaN when they do not spread).
fn sweep_axis(centroids: &[DVec3]) -> (DVec3, usize, f64) {
    let (lo, hi) = centroids.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &c| (lo.min(c), hi.max(c)),
    );
    let extent = hi - lo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    (lo, axis, extent[axis])
}

/// The emitting triangles of `scene` (input order) and their centroids (scene units).
pub fn emitter_centroids(scene: &Scene) -> (Vec<usize>, Vec<DVec3>) {
    let emitters: Vec<usize> = (0..scene.len()).filter(|&t| scene.is_emitter(t)).collect();
    let centroids = emitters
        .iter()
        .map(|&t| {
            let [a, b, c] = scene.corners(t);
            (a + b + c) / 3.0
        })
        .collect();
    (emitters, centroids)
}

/// Brightness factor (in `[dim, 1]`) of each emitter in frame `frame` of `frames` of a sweep.
///
/// A bright spot moves along the axis in which the emitters' `centroids` (world units) spread
/// most, from the lowest to the highest coordinate over the frames (the middle when
/// `frames == 1`). An emitter at normalized distance `d` from the spot gets
/// `dim + (1 - dim) exp(-(d / SPOT_WIDTH)² / 2)`. When the emitters do not spread (a single
/// emitter, or all at one point) they all pulse together instead: `dim` at the ends, 1 in the
/// middle frame. Preconditions: `frame < frames`, `dim` in [0, 1].
pub fn sweep_weights(centroids: &[DVec3], frame: usize, frames: usize, dim: f64) -> Vec<f64> {
    let phase = if frames > 1 {
        frame as f64 / (frames - 1) as f64
    } else {
        0.5
    };
    let (lo, axis, span) = sweep_axis(centroids);
    if !(span > 0.0 && span.is_finite()) {
        let pulse = dim + (1.0 - dim) * (std::f64::consts::PI * phase).sin();
        return vec![pulse.clamp(dim, 1.0); centroids.len()];
    }
    centroids
        .iter()
        .map(|c| {
            let d = (c[axis] - lo[axis]) / span - phase;
            dim + (1.0 - dim) * (-0.5 * (d / SPOT_WIDTH).powi(2)).exp()
        })
        .collect()
}

/// Cuts emitters into `bands` bands of equal width along the axis their `centroids` spread most;
/// returns each emitter's band and each band's centroid (mean of its emitters; bands without
/// emitters are dropped, so there may be fewer than asked). Precondition: `bands >= 1`.
pub fn emitter_bands(centroids: &[DVec3], bands: usize) -> (Vec<usize>, Vec<DVec3>) {
    let (lo, axis, span) = sweep_axis(centroids);
    let raw: Vec<usize> = centroids
        .iter()
        .map(|c| {
            if span > 0.0 && span.is_finite() {
                (((c[axis] - lo[axis]) / span * bands as f64) as usize).min(bands - 1)
            } else {
                0
            }
        })
        .collect();
    // Renumber the non-empty bands in order.
    let mut used: Vec<usize> = raw.clone();
    used.sort_unstable();
    used.dedup();
    let band: Vec<usize> = raw
        .iter()
        .map(|b| used.binary_search(b).expect("present"))
        .collect();
    let mut sum = vec![(DVec3::ZERO, 0usize); used.len()];
    for (&b, &c) in band.iter().zip(centroids) {
        sum[b].0 += c;
        sum[b].1 += 1;
    }
    let centres = sum.iter().map(|(s, n)| *s / *n as f64).collect();
    (band, centres)
}

/// The file of frame `frame` in `dir`: `frame_0000.png`, ...
pub fn frame_path(dir: &Path, frame: usize) -> PathBuf {
    dir.join(format!("frame_{frame:04}.png"))
}

/// A change of an analytic light over the frames of an animation (`--move-light` and
/// `--scale-light` of `antiradiance relight`), applied by [`animated_light`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightChange {
    /// Light `light` (its index in [`Scene::lights`]) moves in a straight line from where it
    /// is to `to` (a point or spot light: its position; a sun: the direction its light
    /// travels, along the straight line between the two unit directions, normalized).
    MoveTo {
        /// Index of the light.
        light: usize,
        /// End position, or end direction for a sun.
        to: DVec3,
    },
    /// Light `light`'s colour goes from its own to `factor` times it, linearly.
    Scale {
        /// Index of the light.
        light: usize,
        /// Colour factor at the end, finite, >= 0.
        factor: f64,
    },
}

impl LightChange {
    /// The index of the light it changes.
    pub fn light(&self) -> usize {
        match *self {
            LightChange::MoveTo { light, .. } | LightChange::Scale { light, .. } => light,
        }
    }
}

/// Checks `changes` against the scene's analytic `lights`: every index names a light, a sky is
/// not moved (it has no position or direction), a sun is not turned to the opposite of its
/// direction (no straight path between them), factors are finite and >= 0, end positions and
/// directions finite (a direction non-zero).
///
/// Errors: [`Error::Parameter`] naming the change.
pub fn check_light_changes(lights: &[Light], changes: &[LightChange]) -> Result<()> {
    for change in changes {
        let k = change.light();
        let Some(light) = lights.get(k) else {
            let kinds: Vec<String> = lights
                .iter()
                .enumerate()
                .map(|(i, l)| format!("{i} {}", light_kind(l)))
                .collect();
            let known = if lights.is_empty() {
                "the scene has no analytic lights".to_string()
            } else {
                format!(
                    "the scene has {} (numbered from 0: {})",
                    lights.len(),
                    kinds.join(", ")
                )
            };
            return Err(Error::Parameter(format!("no analytic light {k}: {known}")));
        };
        match *change {
            LightChange::Scale { factor, .. } => {
                if !(factor.is_finite() && factor >= 0.0) {
                    return Err(Error::Parameter(format!(
                        "light {k}: the colour factor {factor} must be finite and >= 0"
                    )));
                }
            }
            LightChange::MoveTo { to, .. } => {
                if !to.is_finite() {
                    return Err(Error::Parameter(format!(
                        "light {k}: the end position is not finite"
                    )));
                }
                match light {
                    Light::Sky { .. } => {
                        return Err(Error::Parameter(format!(
                            "light {k} is a sky, which has no position or direction to move"
                        )))
                    }
                    Light::Sun { direction, .. } => {
                        let (a, b) = (direction.normalize_or_zero(), to.normalize_or_zero());
                        if b == DVec3::ZERO || (a + b).length() < 1e-6 {
                            return Err(Error::Parameter(format!(
                                "light {k} is a sun: its end direction must be non-zero and not opposite to its direction"
                            )));
                        }
                    }
                    _ => {}
                }
            }
        }
    }
    Ok(())
}

/// The phase in [0, 1] of frame `frame` of an animation of `frames` frames: 0 at the first,
/// 1 at the last (1 when there is one frame).
pub fn light_phase(frame: usize, frames: usize) -> f64 {
    if frames > 1 {
        (frame as f64 / (frames - 1) as f64).min(1.0)
    } else {
        1.0
    }
}

/// Light `index` as it stands at phase `t` in [0, 1] ([`light_phase`]) of the `changes` that
/// name it (moves first, then colour factors), starting from `light` (its place at phase 0).
/// Preconditions: the changes passed [`check_light_changes`].
pub fn animated_light(light: &Light, index: usize, changes: &[LightChange], t: f64) -> Light {
    let mut out = *light;
    for change in changes.iter().filter(|c| c.light() == index) {
        match (*change, &mut out) {
            (
                LightChange::MoveTo { to, .. },
                Light::Point { position, .. } | Light::Spot { position, .. },
            ) => *position += t * (to - *position),
            (LightChange::MoveTo { to, .. }, Light::Sun { direction, .. }) => {
                let from = direction.normalize();
                *direction = (from + t * (to.normalize() - from)).normalize();
            }
            _ => {}
        }
    }
    for change in changes.iter().filter(|c| c.light() == index) {
        if let LightChange::Scale { factor, .. } = *change {
            let k = 1.0 + (factor - 1.0) * t;
            out = out.with_colour(out.colour().map(|x| x * k));
        }
    }
    out
}
