//! `antiradiance relight`: animate the lights of a scene with a [`Relighter`], one picture per frame.

use crate::cli::driver::{self, Report, SceneArgs, SolverArgs, Timings};
use antiradiance::error::{Error, Result};
use antiradiance::memory;
use antiradiance::output::render::{self, CameraOptions, Shading};
use antiradiance::progress::Progress;
use antiradiance::solve::relight::{emitter_centroids, frame_path, sweep_weights, Relighter};
use antiradiance::solve::solution::sanitize;
use clap::Args;
use glam::DVec3;
use serde::Serialize;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The camera of the frames.
#[derive(Args, Clone, Debug)]
#[command(next_help_heading = "Picture options")]
pub struct FrameCameraArgs {
    /// Camera position in scene units (automatic framing by default, fixed for every frame).
    #[arg(long, value_name = "X,Y,Z", value_parser = driver::parse_point, allow_hyphen_values = true)]
    pub eye: Option<DVec3>,
    /// Point the camera looks at, in scene units.
    #[arg(long, value_name = "X,Y,Z", value_parser = driver::parse_point, allow_hyphen_values = true)]
    pub target: Option<DVec3>,
    /// Vertical field of view, degrees.
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 50.0,
        allow_negative_numbers = true
    )]
    pub fov: f64,
    /// Frame width in pixels.
    #[arg(long, value_name = "W", default_value_t = 400)]
    pub width: u32,
    /// Frame height in pixels.
    #[arg(long, value_name = "H", default_value_t = 300)]
    pub height: u32,
    /// Multiplier applied to B before the sRGB curve, the same for every frame; by default the
    /// automatic exposure of the first frame (95th percentile of lit, non-emissive radiance to
    /// 0.8) is kept for all frames, so brightness changes show.
    #[arg(long, value_name = "X", allow_negative_numbers = true)]
    pub exposure: Option<f64>,
    /// Smooth (Gouraud) shading instead of one constant B per patch.
    #[arg(long)]
    pub smooth: bool,
}

impl FrameCameraArgs {
    /// The camera options (eye and target possibly still automatic).
    pub fn camera(&self) -> CameraOptions {
        CameraOptions {
            eye: self.eye,
            target: self.target,
            fov_deg: self.fov,
            width: self.width,
            height: self.height,
            exposure: self.exposure,
        }
    }
}

/// `antiradiance relight`: animate the lights of a scene, one relight per frame.
#[derive(Args, Clone, Debug)]
pub struct RelightArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub solver_args: SolverArgs,
    /// Number of frames (1..=10000): a bright spot sweeps across the emitting triangles.
    #[arg(long, value_name = "N", help_heading = "Animation options")]
    pub frames: usize,
    /// Fraction of its own emission an emitter keeps far from the spot, in [0, 1].
    #[arg(
        long,
        value_name = "F",
        default_value_t = 0.1,
        allow_negative_numbers = true,
        help_heading = "Animation options"
    )]
    pub dim: f64,
    /// Precompute K lights, the emitters cut into K bands across the sweep, and mix them per
    /// frame (no sweep per frame: the spot then moves band by band, each band at the spot
    /// brightness of its centre). 0 (the default) re-solves every frame, warm-started.
    #[arg(
        long,
        value_name = "K",
        default_value_t = 0,
        help_heading = "Animation options"
    )]
    pub bands: usize,
    /// Directory for the frames `frame_0000.png`, `frame_0001.png`, ... (created when missing;
    /// its parent must exist; existing frames of the same names are replaced).
    #[arg(long, value_name = "DIR", help_heading = "Output options")]
    pub out: PathBuf,
    /// JSON report: one-time build seconds, per-frame solve seconds and iterations.
    #[arg(long, value_name = "OUT.json", help_heading = "Output options")]
    pub report: Option<PathBuf>,
    #[command(flatten)]
    pub camera: FrameCameraArgs,
    /// No progress bar (the summary line on stdout is still printed).
    #[arg(long, short)]
    pub quiet: bool,
}

/// Largest `--bands`.
pub const MAX_BANDS: usize = 256;

/// Largest `--frames` (frame names have four digits).
pub const MAX_FRAMES: usize = 10_000;

/// One frame of `relight`, as it appears in the report.
#[derive(Clone, Debug, Serialize)]
pub struct FrameRecord {
    /// Frame number (0-based), also in the file name.
    pub frame: usize,
    /// Wall-clock seconds of the relight (solve only).
    pub seconds: f64,
    /// Seconds to render and write the picture.
    pub render_seconds: f64,
    /// Jacobi sweeps of the relight.
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
        }
    }
}

/// Checks `--out`: an existing directory, or a missing one whose parent exists; not a file.
fn check_out_dir(dir: &Path) -> Result<()> {
    let fail = |message: &str| Error::Io {
        path: dir.to_path_buf(),
        message: message.to_string(),
    };
    if dir.exists() {
        if !dir.is_dir() {
            return Err(fail("--out must be a directory, and this is a file"));
        }
        return Ok(());
    }
    let parent = match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !parent.is_dir() {
        return Err(fail(&format!(
            "--out: parent directory {} does not exist",
            parent.display()
        )));
    }
    Ok(())
}

/// `antiradiance relight`: builds tree and links once, then for each frame sets the emission of
/// the sweep ([`sweep_weights`]), relights (warm start), and writes `DIR/frame_NNNN.png` with a
/// camera and an exposure fixed across frames. Prints one summary line on stdout (build time,
/// time per relight) and writes the report when asked.
///
/// Errors (one line each, nothing solved): bad scene, solver or picture parameter, `--frames`
/// outside 1..=[`MAX_FRAMES`], `--dim` outside [0, 1], `--out` not a directory or its parent
/// missing, a bad `--report` path, a scene without emitters; a failed write names its file.
pub fn relight(args: &RelightArgs) -> Result<()> {
    let start = Instant::now();
    let mut timings = Timings::default();
    args.scene.validate()?;
    let options = args.solver_args.options()?;
    if !(1..=MAX_FRAMES).contains(&args.frames) {
        return Err(Error::Parameter(format!(
            "--frames {} outside 1..={MAX_FRAMES}",
            args.frames
        )));
    }
    if args.bands > MAX_BANDS {
        return Err(Error::Parameter(format!(
            "--bands {} outside 0..={MAX_BANDS}",
            args.bands
        )));
    }
    if !(0.0..=1.0).contains(&args.dim) {
        return Err(Error::Parameter(format!(
            "--dim {} outside [0, 1]",
            args.dim
        )));
    }
    let camera = args.camera.camera();
    driver::check_camera(&camera)?;
    check_out_dir(&args.out)?;
    let report_files: Vec<(&str, &Path)> = args
        .report
        .iter()
        .map(|p| ("--report", p.as_path()))
        .collect();
    driver::check_outputs(&report_files, &args.scene.scene)?;

    let loaded = driver::load(&args.scene, &mut timings)?;
    let (emitters, centroids) = emitter_centroids(&loaded.scene);
    if emitters.is_empty() {
        return Err(Error::Scene {
            path: args.scene.scene.clone(),
            message: "no emitting triangle to animate (give a material Ke, or use --emit-above)"
                .into(),
        });
    }
    let mut relighter = driver::timed(&mut timings.build, || {
        Relighter::from_patches(&loaded.scene, loaded.patches.clone(), &options)
    })?;
    let build_seconds = relighter.build_seconds();
    let memory_warning =
        antiradiance::solve::warnings::memory_warning(Some(relighter.prepared().memory()));
    if let Some(w) = &memory_warning {
        crate::cli::driver::print_warning(&w);
    }

    // The camera is resolved once, so every frame has the same view.
    let (eye, target) = render::resolve_view(relighter.patches(), &camera);
    let mut camera = CameraOptions {
        eye: Some(eye),
        target: Some(target),
        ..camera
    };
    let shading = if args.camera.smooth {
        Shading::Smooth
    } else {
        Shading::Flat
    };
    if !args.out.exists() {
        std::fs::create_dir(&args.out).map_err(|e| Error::io(&args.out, e))?;
    }

    let base = loaded.scene.emission.clone();
    let power = |emission: &[[f64; 3]]| -> f64 {
        emitters
            .iter()
            .map(|&t| loaded.scene.area(t) * emission[t].iter().sum::<f64>() / 3.0)
            .sum()
    };
    let base_power = power(&base);
    // With --bands: one precomputed light per band of emitters, mixed per frame.
    let lights_start = Instant::now();
    let bands = if args.bands > 0 {
        Some(relighter.add_band_lights(&emitters, &centroids, args.bands)?)
    } else {
        None
    };
    let lights_seconds = lights_start.elapsed().as_secs_f64();
    let progress = Progress::new("relight", args.frames as u64, !args.quiet);
    let mut records = Vec::with_capacity(args.frames);
    for frame in 0..args.frames {
        let (relit, emission) = match &bands {
            None => {
                let weights = sweep_weights(&centroids, frame, args.frames, args.dim);
                let mut emission = base.clone();
                for (&t, w) in emitters.iter().zip(&weights) {
                    emission[t] = base[t].map(|x| x * w);
                }
                (relighter.relight(&emission)?, emission)
            }
            Some(centres) => {
                // The spot's brightness at each band's centre, over the same span as the
                // emitters (the centres are inside it).
                let mut points = centres.clone();
                points.extend(&centroids);
                let weights = sweep_weights(&points, frame, args.frames, args.dim);
                let intensities: Vec<[f64; 3]> =
                    weights[..centres.len()].iter().map(|&w| [w; 3]).collect();
                let relit = relighter.mix(&intensities)?;
                (relit, relighter.emission().to_vec())
            }
        };
        timings.solve += relit.seconds;
        // A failed relight is an error: its frame and the later ones are not written.
        relit
            .solution
            .stats
            .check("hierarchical")
            .map_err(|e| Error::Solve(format!("frame {frame}: {e}")))?;
        if camera.exposure.is_none() {
            camera.exposure = Some(render::auto_exposure(relighter.patches(), &relit.solution));
        }
        let render_start = Instant::now();
        render::render_png_shaded(
            &frame_path(&args.out, frame),
            relighter.patches(),
            &relit.solution,
            &camera,
            shading,
        )?;
        let render_seconds = render_start.elapsed().as_secs_f64();
        timings.output += render_seconds;
        let stats = &relit.solution.stats;
        records.push(FrameRecord {
            frame,
            seconds: relit.seconds,
            render_seconds,
            iterations: stats.iterations,
            residual: sanitize(stats.residual),
            converged: stats.converged,
            warm_started: relit.warm_started,
            relative_power: if base_power > 0.0 {
                sanitize(power(&emission) / base_power)
            } else {
                0.0
            },
        });
        progress.inc(1);
        progress.message(format!("{:.0} ms per relight", 1e3 * relit.seconds));
    }
    progress.finish();
    timings.total = start.elapsed().as_secs_f64();
    let peak = memory::peak_rss_bytes();
    let summary = FrameSummary::of(&records);

    if let Some(path) = &args.report {
        let mut report = Report::new("relight", &args.scene.scene, &loaded);
        report
            .add_warnings(memory_warning)
            .insert(
                "parameters",
                json!({
                    "solver": "hierarchical",
                    "preset": args.solver_args.preset_name(),
                    "solver_options": options,
                    "scene_options": args.scene.to_json(),
                    "frames": args.frames,
                    "dim": args.dim,
                    "exposure": camera.exposure,
                    "eye": [eye.x, eye.y, eye.z],
                    "target": [target.x, target.y, target.z],
                    "width": camera.width,
                    "height": camera.height,
                    "out": args.out.display().to_string(),
                }),
            )
            .insert("build_seconds", build_seconds)
            .insert("bands", bands.as_ref().map_or(0, Vec::len))
            .insert("lights_seconds", lights_seconds)
            .insert(
                "hierarchy",
                json!({
                    "links": relighter.prepared().links.len(),
                    "elements": relighter.prepared().element_count(),
                    "solver_bytes": relighter.prepared().bytes(),
                    "memory": relighter.prepared().memory(),
                }),
            )
            .insert("summary", summary)
            .insert("frames", &records)
            .finish(&timings, peak);
        report.write(path)?;
    }
    println!(
        "{}",
        relight_summary(
            &loaded,
            args,
            build_seconds,
            bands.as_ref().map(|c| (c.len(), lights_seconds)),
            &summary
        )
    );
    Ok(())
}

/// The line `relight` prints on stdout when done.
fn relight_summary(
    loaded: &driver::Loaded,
    args: &RelightArgs,
    build_seconds: f64,
    lights: Option<(usize, f64)>,
    summary: &FrameSummary,
) -> String {
    let build = match lights {
        Some((k, s)) => {
            format!("build {build_seconds:.2} s and {k} band lights in {s:.2} s once, then mixed")
        }
        None => format!("build {build_seconds:.2} s once, then"),
    };
    let warm = match summary.mean_warm_seconds {
        Some(s) => format!(", {:.1} ms per warm-started relight", 1e3 * s),
        None => String::new(),
    };
    format!(
        "Relit {} ({} triangles, {} patches) over {} frames: {build} {:.1} ms per relight on average{warm} (min {:.1} ms, max {:.1} ms, {:.1} iterations); frames in {}.",
        args.scene.scene.display(),
        loaded.scene.len(),
        loaded.patches.len(),
        args.frames,
        1e3 * summary.mean_seconds,
        1e3 * summary.min_seconds,
        1e3 * summary.max_seconds,
        summary.mean_iterations,
        args.out.display()
    )
}
