//! What `relight` reports: one record per frame, their summary, the report's parameters and
//! the summary line on stdout.

use super::RelightArgs;
use crate::cli::driver;
use antiradiance::output::render::CameraOptions;
use antiradiance::solve::hierarchical::Prepared;
use antiradiance::solve::relight::LightChange;
use antiradiance::solve::SolverOptions;
use glam::DVec3;
use serde::Serialize;
use serde_json::{json, Value};

/// A light change as the command line gives it.
fn change_text(change: &LightChange) -> String {
    match *change {
        LightChange::MoveTo { light, to } => format!("{light}:{},{},{}", to.x, to.y, to.z),
        LightChange::Scale { light, factor } => format!("{light}:{factor}"),
    }
}

/// One frame of `relight`, as it appears in the report.
#[derive(Clone, Debug, Serialize)]
pub struct FrameRecord {
    /// Frame number (0-based), also in the file name.
    pub frame: usize,
    /// Wall-clock seconds of the relight (solve only).
    pub seconds: f64,
    /// Seconds to render and write the picture.
    pub render_seconds: f64,
    /// Of `seconds`, those spent on the shadow rays of analytic lights that moved.
    pub direct_seconds: f64,
    /// Jacobi sweeps of the relight (0 when the lighting did not change since a converged
    /// one).
    pub iterations: usize,
    /// Final residual.
    pub residual: f64,
    /// True when the tolerance was reached before the iteration cap.
    pub converged: bool,
    /// True when the relight started from the previous frame's solution.
    pub warm_started: bool,
    /// Total emitted power of the frame relative to the scene's own emission (sum of a_t E_t,
    /// mean over RGB), in [dim, 1].
    pub relative_power: f64,
    /// With `--errors`: the design note's error of the relight against the frame's lighting
    /// solved from scratch to a tenth of the tolerance.
    pub error_vs_converged: Option<f64>,
}

/// Timing figures over the frames of a `relight` run, seconds.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct FrameSummary {
    /// Mean relight time over all frames.
    pub mean_seconds: f64,
    /// Mean over the warm-started frames (all but the first); `None` with one frame.
    pub mean_warm_seconds: Option<f64>,
    /// Fastest relight.
    pub min_seconds: f64,
    /// Slowest relight.
    pub max_seconds: f64,
    /// Mean iterations per relight.
    pub mean_iterations: f64,
    /// Frames whose relight reached the tolerance.
    pub converged_frames: usize,
    /// With `--errors`: mean and largest error against the converged answer.
    pub mean_error: Option<f64>,
    pub max_error: Option<f64>,
}

impl FrameSummary {
    /// The summary of `frames` (all zero when empty).
    pub fn of(frames: &[FrameRecord]) -> FrameSummary {
        if frames.is_empty() {
            return FrameSummary::default();
        }
        let n = frames.len() as f64;
        let warm: Vec<f64> = frames
            .iter()
            .filter(|f| f.warm_started)
            .map(|f| f.seconds)
            .collect();
        let errors: Option<Vec<f64>> = frames.iter().map(|f| f.error_vs_converged).collect();
        FrameSummary {
            mean_seconds: frames.iter().map(|f| f.seconds).sum::<f64>() / n,
            mean_warm_seconds: (!warm.is_empty())
                .then(|| warm.iter().sum::<f64>() / warm.len() as f64),
            min_seconds: frames
                .iter()
                .map(|f| f.seconds)
                .fold(f64::INFINITY, f64::min),
            max_seconds: frames.iter().map(|f| f.seconds).fold(0.0, f64::max),
            mean_iterations: frames.iter().map(|f| f.iterations as f64).sum::<f64>() / n,
            converged_frames: frames.iter().filter(|f| f.converged).count(),
            mean_error: errors
                .as_ref()
                .map(|e| e.iter().sum::<f64>() / e.len() as f64),
            max_error: errors
                .as_ref()
                .map(|e| e.iter().copied().fold(0.0, f64::max)),
        }
    }
}
/// The `parameters` of the `relight` report.
pub(super) fn parameters_json(
    args: &RelightArgs,
    options: &SolverOptions,
    camera: &CameraOptions,
    eye: DVec3,
    target: DVec3,
) -> Value {
    json!({
        "solver": "hierarchical",
        "preset": args.solver_args.preset_name(),
        "solver_options": options,
        "scene_options": args.scene.to_json(),
        "frames": args.frames,
        "dim": args.dim,
        "hold": args.hold,
        "frame_budget_ms": args.frame_budget,
        "move_light": args.move_light.iter().map(change_text).collect::<Vec<_>>(),
        "scale_light": args.scale_light.iter().map(change_text).collect::<Vec<_>>(),
        "errors": args.errors,
        "exposure": camera.exposure,
        "eye": [eye.x, eye.y, eye.z],
        "target": [target.x, target.y, target.z],
        "width": camera.width,
        "height": camera.height,
        "out": args.out.display().to_string(),
    })
}

/// The `hierarchy` of the `relight` report: links, elements and memory of the tree and links.
pub(super) fn hierarchy_json(prepared: &Prepared) -> Value {
    json!({
        "links": prepared.links.len(),
        "elements": prepared.element_count(),
        "solver_bytes": prepared.bytes(),
        "memory": prepared.memory(),
    })
}

/// The line `relight` prints on stdout when done.
pub(super) fn relight_summary(
    loaded: &driver::Loaded,
    args: &RelightArgs,
    build_seconds: f64,
    lights: Option<(usize, f64)>,
    initial_seconds: Option<f64>,
    summary: &FrameSummary,
) -> String {
    let build = match (lights, initial_seconds, args.frame_budget) {
        (Some((k, s)), _, _) => {
            format!("build {build_seconds:.2} s and {k} band lights in {s:.2} s once, then mixed")
        }
        (None, Some(initial), Some(ms)) => format!(
            "build {build_seconds:.2} s and the initial solve {initial:.2} s once, then progressive within {ms} ms per frame:"
        ),
        _ => format!("build {build_seconds:.2} s once, then"),
    };
    let errors = match (summary.mean_error, summary.max_error) {
        (Some(mean), Some(max)) => format!(
            "; error against the converged answer {:.3}% on average, {:.3}% at most",
            100.0 * mean,
            100.0 * max
        ),
        _ => String::new(),
    };
    let warm = match summary.mean_warm_seconds {
        Some(s) => format!(", {:.1} ms per warm-started relight", 1e3 * s),
        None => String::new(),
    };
    format!(
        "Relit {} ({} triangles, {} patches) over {} frames: {build} {:.1} ms per relight on average{warm} (min {:.1} ms, max {:.1} ms, {:.1} iterations, {} frames converged){errors}; frames in {}.",
        args.scene.scene.display(),
        loaded.scene.len(),
        loaded.patches.len(),
        args.frames,
        1e3 * summary.mean_seconds,
        1e3 * summary.min_seconds,
        1e3 * summary.max_seconds,
        summary.mean_iterations,
        summary.converged_frames,
        args.out.display()
    )
}
