//! Interactive relighting: build the hierarchy and links of a scene once, then re-solve it for
//! new emission as often as needed, each solve warm-started from the previous one.
//!
//! Links, form factors and antiradiance couplings depend only on geometry, albedo and solver
//! options, never on emission (the equations are linear in E). A [`Relighter`] therefore pays
//! for the tree and the links once ([`Relighter::new`]) and each relight is only the Jacobi
//! sweeps of [`Prepared::solve_with_emission`], started from the previous answer: after a small
//! change of the lights most of the old radiance and antiradiance is still right, so fewer
//! sweeps are needed than from the emission alone.
//!
//! Emission is given in the scene's own units (W / (m² sr), RGB), per input triangle
//! ([`Relighter::set_emission`], [`Relighter::set_triangle_emission`]) or per material name
//! ([`Relighter::set_material_emission`], for scenes loaded from OBJ+MTL); every solution comes
//! back in the scene's units too, exactly as from a from-scratch solve of the same emission (up
//! to the solver's tolerance).
//!
//! # Example
//!
//! ```
//! use antiradiance::scene::generated;
//! use antiradiance::solve::relight::Relighter;
//! use antiradiance::solve::SolverOptions;
//!
//! # fn main() -> antiradiance::Result<()> {
//! let scene = generated::cornell_box();
//! // Tree and links are built here, once.
//! let mut relighter = Relighter::new(&scene, None, &SolverOptions::fast())?;
//!
//! // The light as modelled, then at half power: a warm-started re-solve.
//! let full = relighter.solve(&antiradiance::progress::Progress::hidden());
//! let mut dimmed = scene.emission.clone();
//! for e in dimmed.iter_mut() {
//!     *e = e.map(|x| 0.5 * x);
//! }
//! let half = relighter.relight(&dimmed)?;
//! assert!(half.warm_started);
//!
//! // Radiance is linear in emission: the floor (triangle 0) gets half the light.
//! let (b_full, b_half) = (
//!     full.solution.triangle_radiance[0][0],
//!     half.solution.triangle_radiance[0][0],
//! );
//! assert!((b_half - 0.5 * b_full).abs() < 0.01 * b_full);
//!
//! // Bad emission is an error, not a panic, and changes nothing.
//! assert!(relighter.set_triangle_emission(0, [f64::NAN, 0.0, 0.0]).is_err());
//! assert!(relighter.set_emission(&dimmed[..3]).is_err());
//! # Ok(())
//! # }
//! ```
//!
//! The command `antiradiance relight` animates a light this way and writes one
//! picture per frame with the time each relight took.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::DVec3;

use crate::error::{Error, Result};
use crate::mesh::{self, Patches};
use crate::progress::Progress;
use crate::scene::Scene;
use crate::solve::hierarchical::{ElementState, Prepared};
use crate::solve::solution::Solution;
use crate::solve::SolverOptions;

/// Largest factor by which the brightest emission may drift from the normalization scale of the
/// warm state before the state is dropped and the scale reset (keeps the solver's f32
/// antiradiance far from overflow and underflow).
pub const RESCALE_FACTOR: f64 = 1e6;

/// One relight: the solution and how it was obtained.
#[derive(Clone, Debug)]
pub struct Relit {
    /// Outgoing radiance per patch and per input triangle, in the scene's units
    /// (W / (m² sr), RGB), with the solver's statistics (iterations, residual, ...).
    pub solution: Solution,
    /// True when the solve started from the previous solution rather than from the emission.
    pub warm_started: bool,
    /// Wall-clock seconds of the solve (the sweeps only: tree and links were built before).
    pub seconds: f64,
}

/// A scene prepared once (patches, cluster tree, links) and re-solved for new emission.
///
/// Holds the current emission per input triangle (scene units) and the solver state of the
/// last solve, from which the next one starts. See the [module documentation](self).
pub struct Relighter {
    /// The solver's patches; `emission` holds the current emission divided by
    /// `emission_scale` (the normalization of the warm state).
    patches: Patches,
    /// Tree and links, built once.
    prepared: Prepared,
    /// Current emission per input triangle, scene units.
    emission: Vec<[f64; 3]>,
    /// Per input triangle, its material's name index (`None`: no material).
    material: Vec<Option<u32>>,
    /// Material names of the scene.
    material_names: Vec<String>,
    /// State of the last solve (normalized by `patches.emission_scale`).
    warm: Option<ElementState>,
    /// Seconds spent building patches, tree and links.
    build_seconds: f64,
    /// Precomputed lights ([`Relighter::add_light`]).
    lights: Vec<Light>,
}

/// A light of a [`Relighter`]: an emission pattern and the scene's response to it.
#[derive(Clone, Debug)]
struct Light {
    /// Its name, as given.
    name: String,
    /// Emission per input triangle at unit intensity, scene units.
    emission: Vec<[f64; 3]>,
    /// Outgoing radiance per patch it causes, scene units, negative values kept.
    response: Vec<[f64; 3]>,
}

impl Relighter {
    /// Builds patches (`max_edge` splits input triangles as in [`mesh::build_patches`];
    /// `None` keeps them), cluster tree and links of `scene` for `options`. The emission is the
    /// scene's own until changed.
    ///
    /// Errors: [`Error::Parameter`] for invalid `options`, a `max_edge` that is not a finite
    /// positive length or would make more than [`mesh::MAX_PATCHES`] patches, or invalid
    /// emission in the scene; [`Error::Scene`] for a scene without triangles, with a non-finite vertex or a
    /// vertex index out of range, or with analytic lights ([`Scene::lights`]: the relighter
    /// animates emitting triangles only).
    pub fn new(scene: &Scene, max_edge: Option<f64>, options: &SolverOptions) -> Result<Relighter> {
        let start = Instant::now();
        check_no_lights(scene)?;
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
        check_no_lights(scene)?;
        options.validate()?;
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
            warm: None,
            build_seconds: start.elapsed().as_secs_f64(),
            lights: Vec::new(),
        })
    }

    /// Number of input triangles (the length of [`Relighter::emission`] and of every
    /// `triangle_radiance`).
    pub fn triangle_count(&self) -> usize {
        self.emission.len()
    }

    /// The solver's patches. Their `emission` is the emission of the last solve (or of the
    /// scene before the first one) divided by their `emission_scale`, so they render and export
    /// consistently with the last solution.
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

    /// The largest emission channel of any triangle, scene units.
    fn brightest(&self) -> f64 {
        self.emission
            .iter()
            .flat_map(|e| e.iter().copied())
            .fold(0.0f64, f64::max)
    }

    /// Sets the patches' emission to the current emission over the current normalization scale.
    fn sync_patch_emission(&mut self) {
        let scale = self.patches.emission_scale;
        for (p, &t) in self.patches.parent.iter().enumerate() {
            self.patches.emission[p] = self.emission[t as usize].map(|x| x / scale);
        }
    }

    /// Forgets the last solution: the next solve starts from the emission, as a from-scratch
    /// solve would (same links, so the same answer up to the tolerance).
    pub fn forget_warm_start(&mut self) {
        self.warm = None;
    }

    /// Solves for the current emission, warm-started from the previous solve when there is one.
    /// Returns a solution in every case (the emission was checked when it was set; no NaN
    /// reaches the solution), but one whose solve failed its health checks carries
    /// `solution.stats.failure` with `converged == false` ([`crate::solve::health`]; check it with
    /// [`crate::solve::solution::SolveStats::check`]): its radiance is not a solution, and the next
    /// solve starts cold rather than from it.
    pub fn solve(&mut self, progress: &Progress) -> Relit {
        let start = Instant::now();
        let brightest = self.brightest();
        let scale = self.patches.emission_scale;
        // Without a warm state the normalization is free: use the brightest emission, exactly
        // as a from-scratch solve does. With one, keep its scale unless the lights drifted by
        // more than RESCALE_FACTOR (then the old state is not worth keeping anyway).
        if brightest > 0.0
            && (self.warm.is_none()
                || brightest > scale * RESCALE_FACTOR
                || brightest < scale / RESCALE_FACTOR)
        {
            self.patches.emission_scale = brightest;
            self.warm = None;
        }
        self.sync_patch_emission();
        let warm = self.warm.take();
        let warm_started = warm.is_some();
        let (solution, state) = self.prepared.solve_with_emission(
            &self.patches,
            &self.patches.emission,
            warm.as_ref(),
            progress,
        );
        // A failed solve's state is not worth starting from.
        self.warm = solution.stats.failure.is_none().then_some(state);
        Relit {
            solution,
            warm_started,
            seconds: start.elapsed().as_secs_f64(),
        }
    }

    /// Precomputes the scene's response to an emission pattern (scene units per input
    /// triangle, at unit intensity) as a light that [`Relighter::mix`] can then scale and
    /// combine with the others in time linear in the patch count, with no sweep: radiance is
    /// linear in emission, so a mix is exactly the solve of the mixed emission (up to the
    /// tolerance each light was solved to). One from-scratch solve per light; returns the
    /// light's index. The relighter's current emission and warm state are left unchanged.
    ///
    /// Errors: as [`Relighter::set_emission`], and [`Error::Solve`] when the light's solve
    /// failed its health checks ([`crate::solve::health`]); nothing is added either way.
    pub fn add_light(&mut self, name: &str, per_triangle: &[[f64; 3]]) -> Result<usize> {
        let current = self.emission.clone();
        let warm = self.warm.take();
        let scale = self.patches.emission_scale;
        self.set_emission(per_triangle)?;
        // Keep negative radiance: the sum of clamped responses would not be the clamped sum.
        let clamp = std::mem::replace(&mut self.prepared.options.clamp_negative, false);
        let relit = self.solve(&Progress::hidden());
        self.prepared.options.clamp_negative = clamp;
        self.emission = current;
        self.warm = warm;
        self.patches.emission_scale = scale;
        relit
            .solution
            .stats
            .check("hierarchical")
            .map_err(|e| Error::Solve(format!("light '{name}': {e}")))?;
        self.lights.push(Light {
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
    /// Errors: [`Error::Parameter`] when the count is not the number of lights or an
    /// intensity is negative, NaN or infinite (nothing changes).
    pub fn mix(&mut self, intensities: &[[f64; 3]]) -> Result<Relit> {
        let start = Instant::now();
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
        self.warm = None;
        let brightest = self.brightest();
        if brightest > 0.0 {
            self.patches.emission_scale = brightest;
        }
        self.sync_patch_emission();
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

/// The relighter animates emitting triangles only: a scene with analytic lights is refused.
fn check_no_lights(scene: &Scene) -> Result<()> {
    if scene.lights.is_empty() {
        return Ok(());
    }
    Err(Error::Scene {
        path: scene.path.clone(),
        message: format!(
            "{} analytic lights (point, spot, sun, sky): the relighter animates emitting triangles only",
            scene.lights.len()
        ),
    })
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
