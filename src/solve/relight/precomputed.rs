//! Precomputed lights of a [`Relighter`]: the responses to emission patterns, solved once
//! each, and their linear combination ([`Relighter::mix`]).

use std::time::Instant;

use glam::DVec3;

use super::{check_radiance, emitter_bands, Lighting, PrecomputedLight, Relighter, Relit};
use crate::error::{Error, Result};
use crate::progress::Progress;

impl Relighter {
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
}
