//! The analytic lights of a [`Relighter`]: set, described, and their direct light traced
//! again for the lights that moved.

use std::time::Instant;

use super::{Lighting, Relighter};
use crate::error::{Error, Result};
use crate::geometry::raytrace::RayScene;
use crate::mesh;
use crate::scene::lights::Light;

impl Relighter {
    /// Replaces analytic light `index` (its place in
    /// [`Scene::lights`](crate::scene::Scene::lights)) by `light`: moved, turned, recoloured, or
    /// of another kind. Takes effect at the next solve: a light that only changed colour has its
    /// direct light rescaled; any other change traces its shadow rays again (only this light's),
    /// within that solve's time.
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

    /// Computes the direct light of every analytic light that moved since its last one (shadow
    /// rays); returns the seconds spent.
    pub(super) fn update_light_sources(&mut self) -> f64 {
        if self.analytic.iter().all(|a| a.unit_source.is_some()) {
            return 0.0;
        }
        let start = Instant::now();
        let rays = RayScene::of(&self.patches);
        // Per face of the solver, as the cold solve's exact direct light gives them
        // (`mesh::lights::faces_source`).
        let faces: Vec<_> = self
            .prepared
            .faces()
            .map(|f| (f.corners, f.normal, f.patch))
            .collect();
        for (k, a) in self.analytic.iter_mut().enumerate() {
            if a.unit_source.is_none() {
                let unit = a
                    .light
                    .with_colour([1.0; 3])
                    .to_unit(&self.patches.frame, 1.0);
                a.unit_source = Some(mesh::lights::light_faces_source(
                    &self.patches,
                    &rays,
                    &unit,
                    k,
                    &faces,
                ));
            }
        }
        start.elapsed().as_secs_f64()
    }

    /// The analytic lights' reflected direct radiance per face of the solver
    /// ([`crate::solve::hierarchical::Prepared::faces`]), scene units (empty when `lighting`
    /// leaves them out or the scene has none). Lights whose direct light is not computed yet
    /// ([`Relighter::update_light_sources`]) are left out.
    pub(super) fn light_source(&self, lighting: Lighting) -> Vec<[f64; 3]> {
        if lighting == Lighting::EmissionOnly || self.analytic.is_empty() {
            return Vec::new();
        }
        let mut total = vec![[0.0f64; 3]; self.prepared.face_count()];
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
    pub(super) fn analytic_lit(&self) -> bool {
        self.analytic.iter().any(|a| a.light.strength() > 0.0)
    }
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
