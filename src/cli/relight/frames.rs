//! The frames of `relight`: the animation's lighting per frame, the relights and the pictures.

use super::records::FrameRecord;
use super::RelightArgs;
use crate::cli::driver::Timings;
use antiradiance::error::{Error, Result};
use antiradiance::output::render::{self, CameraOptions, Shading};
use antiradiance::progress::Progress;
use antiradiance::scene::lights::Light;
use antiradiance::scene::Scene;
use antiradiance::solve::relight::{
    animated_light, frame_path, light_phase, sweep_weights, LightChange, Relighter, Relit,
};
use antiradiance::solve::solution::{error_against, sanitize};
use glam::DVec3;
use std::time::{Duration, Instant};

/// What changes over the frames of `relight`: the emitters' sweep and the analytic lights'
/// changes, from the scene's own lighting.
pub(super) struct Animation<'a> {
    /// The arguments (`--dim`, `--frames`, `--hold`, ...).
    args: &'a RelightArgs,
    /// The scene.
    scene: &'a Scene,
    /// The emitting triangles ([`emitter_centroids`]).
    ///
    /// [`emitter_centroids`]: antiradiance::solve::relight::emitter_centroids
    pub(super) emitters: Vec<usize>,
    /// Their centroids.
    pub(super) centroids: Vec<DVec3>,
    /// The light changes ([`check_light_changes`]).
    ///
    /// [`check_light_changes`]: antiradiance::solve::relight::check_light_changes
    changes: Vec<LightChange>,
    /// The scene's emission per input triangle.
    pub(super) base: Vec<[f64; 3]>,
    /// The scene's analytic lights.
    base_lights: Vec<Light>,
    /// Frames that move the lights (all but the `--hold` ones).
    animated: usize,
}

impl<'a> Animation<'a> {
    /// The animation of `scene` as `args` ask, from its own emission and lights.
    pub(super) fn new(
        args: &'a RelightArgs,
        scene: &'a Scene,
        emitters: Vec<usize>,
        centroids: Vec<DVec3>,
        changes: Vec<LightChange>,
    ) -> Animation<'a> {
        Animation {
            args,
            scene,
            emitters,
            centroids,
            changes,
            base: scene.emission.clone(),
            base_lights: scene.lights.clone(),
            animated: args.frames - args.hold,
        }
    }

    /// The emitted power of `emission` (sum of a_t E_t over the emitters, mean over RGB).
    pub(super) fn power(&self, emission: &[[f64; 3]]) -> f64 {
        self.emitters
            .iter()
            .map(|&t| self.scene.area(t) * emission[t].iter().sum::<f64>() / 3.0)
            .sum()
    }

    /// Sets the lighting of animation step `step` on `relighter`: the emitters' sweep and the
    /// lights' changes; returns the emission.
    fn lighting(&self, relighter: &mut Relighter, step: usize) -> Result<Vec<[f64; 3]>> {
        let mut emission = self.base.clone();
        if !self.emitters.is_empty() {
            let weights = sweep_weights(&self.centroids, step, self.animated, self.args.dim);
            for (&t, w) in self.emitters.iter().zip(&weights) {
                emission[t] = self.base[t].map(|x| x * w);
            }
        }
        let t = light_phase(step, self.animated);
        for change in &self.changes {
            let k = change.light();
            relighter
                .set_analytic_light(k, animated_light(&self.base_lights[k], k, &self.changes, t))?;
        }
        relighter.set_emission(&emission)?;
        Ok(emission)
    }

    /// The relight of animation step `step`: warm-started sweeps, or with `bands` (the band
    /// lights' centres) the mix of the band lights; returns it with its emission.
    fn relight_step(
        &self,
        relighter: &mut Relighter,
        bands: Option<&[DVec3]>,
        step: usize,
    ) -> Result<(Relit, Vec<[f64; 3]>)> {
        Ok(match bands {
            None => {
                let emission = self.lighting(relighter, step)?;
                (relighter.solve(&Progress::hidden()), emission)
            }
            Some(centres) => {
                // The spot's brightness at each band's centre, over the same span as the
                // emitters (the centres are inside it).
                let mut points = centres.to_vec();
                points.extend(&self.centroids);
                let weights = sweep_weights(&points, step, self.animated, self.args.dim);
                let intensities: Vec<[f64; 3]> =
                    weights[..centres.len()].iter().map(|&w| [w; 3]).collect();
                let relit = relighter.mix(&intensities)?;
                (relit, relighter.emission().to_vec())
            }
        })
    }
}

/// Progressive relighting (`frame_budget` set): the first frame's lighting converged once,
/// before the frames, which then run within the budget; returns the seconds of that solve.
pub(super) fn initial_solve(
    animation: &Animation,
    relighter: &mut Relighter,
    frame_budget: Option<Duration>,
) -> Result<Option<f64>> {
    Ok(match frame_budget {
        Some(_) => {
            animation.lighting(relighter, 0)?;
            let initial = relighter.solve(&Progress::hidden());
            initial
                .solution
                .stats
                .check("hierarchical")
                .map_err(|e| Error::Solve(format!("the initial solve: {e}")))?;
            relighter.frame_budget = frame_budget;
            Some(initial.seconds)
        }
        None => None,
    })
}

/// How the frames are drawn: the fixed camera (its exposure set by the first frame when not
/// given) and the shading.
pub(super) struct FrameView {
    /// The camera, eye and target resolved.
    pub(super) camera: CameraOptions,
    /// Flat or smooth.
    pub(super) shading: Shading,
    /// With flat shading, the view's pixels, rasterized for the first frame and shaded for
    /// every frame (the geometry does not change, only the light).
    pub(super) raster: Option<render::Raster>,
}

/// Relights and writes every frame; returns their records. `base_power`: the emitted power of
/// the scene's own emission ([`Animation::power`]).
pub(super) fn run_frames(
    animation: &Animation,
    relighter: &mut Relighter,
    bands: Option<&[DVec3]>,
    view: &mut FrameView,
    base_power: f64,
    timings: &mut Timings,
) -> Result<Vec<FrameRecord>> {
    let args = animation.args;
    let progress = Progress::new("relight", args.frames as u64, !args.quiet);
    let mut records = Vec::with_capacity(args.frames);
    for frame in 0..args.frames {
        // The last `hold` frames keep the animation's last lighting.
        let step = frame.min(animation.animated - 1);
        let (relit, emission) = animation.relight_step(relighter, bands, step)?;
        timings.solve += relit.seconds;
        // A failed relight is an error: its frame and the later ones are not written.
        relit
            .solution
            .stats
            .check("hierarchical")
            .map_err(|e| Error::Solve(format!("frame {frame}: {e}")))?;
        let error_vs_converged = if args.errors {
            Some(error_vs_converged(
                animation.scene,
                relighter,
                &relit,
                frame,
            )?)
        } else {
            None
        };
        let render_seconds = render_frame(args, relighter, &relit, view, frame)?;
        timings.output += render_seconds;
        let stats = &relit.solution.stats;
        records.push(FrameRecord {
            frame,
            seconds: relit.seconds,
            direct_seconds: relit.direct_seconds,
            render_seconds,
            iterations: stats.iterations,
            residual: sanitize(stats.residual),
            converged: stats.converged,
            warm_started: relit.warm_started,
            relative_power: if base_power > 0.0 {
                sanitize(animation.power(&emission) / base_power)
            } else {
                0.0
            },
            error_vs_converged,
        });
        progress.inc(1);
        progress.message(format!("{:.0} ms per relight", 1e3 * relit.seconds));
    }
    progress.finish();
    Ok(records)
}

/// `--errors`: the error of frame `frame`'s relight against its lighting solved from scratch
/// ([`Relighter::converged`]).
fn error_vs_converged(
    scene: &Scene,
    relighter: &mut Relighter,
    relit: &Relit,
    frame: usize,
) -> Result<f64> {
    let reference = relighter.converged(&Progress::hidden());
    reference
        .solution
        .stats
        .check("hierarchical")
        .map_err(|e| Error::Solve(format!("frame {frame}, the converged solve: {e}")))?;
    Ok(sanitize(error_against(
        scene,
        &relit.solution,
        &reference.solution,
    )))
}

/// Writes the picture of frame `frame` (the first frame fixes the exposure when none was
/// given); returns the seconds it took.
fn render_frame(
    args: &RelightArgs,
    relighter: &Relighter,
    relit: &Relit,
    view: &mut FrameView,
    frame: usize,
) -> Result<f64> {
    let camera = &mut view.camera;
    if camera.exposure.is_none() {
        camera.exposure = Some(render::auto_exposure(relighter.patches(), &relit.solution));
    }
    let render_start = Instant::now();
    let path = frame_path(&args.out, frame);
    let patches = relighter.patches();
    if view.shading == Shading::Flat {
        let raster = view
            .raster
            .get_or_insert_with(|| render::Raster::new(patches, camera));
        raster.write_png(&path, patches, &relit.solution, camera.exposure)?;
    } else {
        render::render_png_shaded(&path, patches, &relit.solution, camera, view.shading)?;
    }
    Ok(render_start.elapsed().as_secs_f64())
}
