//! Interactive relighting: build the hierarchy and links of a scene once, then re-solve it for
//! new lighting as often as needed, each solve warm-started from the previous ones (the
//! combination of the last [`crate::solve::hierarchical::WARM_BASES`] solutions whose sources
//! come closest to the new source).
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

mod analytic;
mod animation;
mod precomputed;
mod solving;

pub use analytic::light_kind;
pub use animation::{
    animated_light, check_light_changes, emitter_bands, emitter_centroids, frame_path, light_phase,
    sweep_weights, LightChange, SPOT_WIDTH,
};

use std::time::{Duration, Instant};

use crate::error::{Error, Result};
use crate::mesh::{self, Patches};
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
    /// analytic lights are the scene's own until changed. Closed objects are solved as given,
    /// not turned outward as [`crate::solve::run`] does ([`crate::mesh::closed`]): any
    /// triangle may be made to emit, also one facing an object's inside.
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
        // Overlapping coplanar patches send by the share of them that shows, as in a solve.
        let mut patches = patches;
        patches.visible_shares = mesh::overlap::visible_shares(&patches);
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
