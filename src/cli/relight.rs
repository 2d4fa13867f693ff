//! `antiradiance relight`: animate the lights of a scene with a [`Relighter`], one picture per frame.

use crate::cli::driver::{self, Report, SceneArgs, SolverArgs, Timings};
use antiradiance::error::{Error, Result};
use antiradiance::memory;
use antiradiance::output::render::{self, CameraOptions, Shading};
use antiradiance::progress::Progress;
use antiradiance::scene::lights::Light;
use antiradiance::scene::Scene;
use antiradiance::solve::hierarchical::Prepared;
use antiradiance::solve::relight::{
    animated_light, check_light_changes, emitter_centroids, frame_path, light_phase, sweep_weights,
    LightChange, Relighter, Relit,
};
use antiradiance::solve::solution::{error_against, sanitize};
use antiradiance::solve::SolverOptions;
use clap::Args;
use glam::DVec3;
use serde::Serialize;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

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
    /// Number of frames (1..=10000): a bright spot sweeps across the emitting triangles, and
    /// the analytic lights move and change as --move-light and --scale-light say.
    #[arg(long, value_name = "N", help_heading = "Animation options")]
    pub frames: usize,
    /// Analytic light I (0-based, in the order of the scene's lights, then --light, then
    /// --sky) moves in a straight line from where it is to X,Y,Z over the frames (a point or
    /// spot light: its position; a sun: the direction its light travels). Repeatable.
    #[arg(long = "move-light", value_name = "I:X,Y,Z", value_parser = parse_move_light, allow_hyphen_values = true, help_heading = "Animation options")]
    pub move_light: Vec<LightChange>,
    /// Analytic light I's colour goes from its own to F times it over the frames (F = 0.25
    /// dims it to a quarter). Repeatable.
    #[arg(long = "scale-light", value_name = "I:F", value_parser = parse_scale_light, allow_hyphen_values = true, help_heading = "Animation options")]
    pub scale_light: Vec<LightChange>,
    /// The last H frames keep the lighting the animation reached (0..frames): with
    /// --frame-budget they show the progressive solve converging.
    #[arg(
        long,
        value_name = "H",
        default_value_t = 0,
        help_heading = "Animation options"
    )]
    pub hold: usize,
    /// Progressive relighting: each frame does as many sweeps as fit MS milliseconds (at least
    /// one) and the next frame goes on from there, so the answer converges over frames; the
    /// first frame's lighting is solved to the tolerance once before the frames. Without it,
    /// every frame is solved to the tolerance. 0..=60000.
    #[arg(
        long,
        value_name = "MS",
        allow_negative_numbers = true,
        conflicts_with = "bands",
        help_heading = "Animation options"
    )]
    pub frame_budget: Option<f64>,
    /// Also solve every frame's lighting from scratch to a tenth of the tolerance and report
    /// the relight's error against it (the design note's measure; not counted in the frame's
    /// time).
    #[arg(long, help_heading = "Animation options")]
    pub errors: bool,
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

/// Largest `--frame-budget`, milliseconds.
pub const MAX_FRAME_BUDGET_MS: f64 = 60_000.0;

/// Parses `--move-light I:X,Y,Z`.
fn parse_move_light(text: &str) -> std::result::Result<LightChange, String> {
    let (index, to) = text
        .split_once(':')
        .ok_or_else(|| format!("'{text}' is not I:X,Y,Z"))?;
    Ok(LightChange::MoveTo {
        light: parse_index(index, text)?,
        to: driver::parse_point(to)?,
    })
}

/// Parses `--scale-light I:F`.
fn parse_scale_light(text: &str) -> std::result::Result<LightChange, String> {
    let (index, factor) = text
        .split_once(':')
        .ok_or_else(|| format!("'{text}' is not I:F"))?;
    let factor: f64 = factor
        .trim()
        .parse()
        .ok()
        .filter(|f: &f64| f.is_finite() && *f >= 0.0)
        .ok_or_else(|| format!("'{factor}' in '{text}' is not a finite factor >= 0"))?;
    Ok(LightChange::Scale {
        light: parse_index(index, text)?,
        factor,
    })
}

/// The light index of a light change.
fn parse_index(index: &str, text: &str) -> std::result::Result<usize, String> {
    index
        .trim()
        .parse()
        .map_err(|_| format!("'{index}' in '{text}' is not a light index (0, 1, ...)"))
}

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
/// outside 1..=[`MAX_FRAMES`], `--dim` outside [0, 1], `--hold` not below `--frames`,
/// `--frame-budget` outside [0, [`MAX_FRAME_BUDGET_MS`]], `--out` not a directory or its parent
/// missing, a bad `--report` path, a light change naming no light of the scene (or moving a
/// sky), `--bands` with lit analytic lights or light changes, a scene with nothing to animate;
/// a failed write names its file.
pub fn relight(args: &RelightArgs) -> Result<()> {
    let start = Instant::now();
    let mut timings = Timings::default();
    let Checked {
        options,
        frame_budget,
        changes,
        camera,
    } = check_args(args)?;

    let loaded = driver::load(&args.scene, &mut timings)?;
    let (emitters, centroids) = emitter_centroids(&loaded.scene);
    check_scene(args, &loaded, &emitters, &changes)?;
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
    let mut view = FrameView {
        camera: CameraOptions {
            eye: Some(eye),
            target: Some(target),
            ..camera
        },
        shading: if args.camera.smooth {
            Shading::Smooth
        } else {
            Shading::Flat
        },
    };
    if !args.out.exists() {
        std::fs::create_dir(&args.out).map_err(|e| Error::io(&args.out, e))?;
    }

    let animation = Animation::new(args, &loaded.scene, emitters, centroids, changes);
    let base_power = animation.power(&animation.base);
    // With --bands: one precomputed light per band of emitters, mixed per frame.
    let lights_start = Instant::now();
    let bands = if args.bands > 0 {
        Some(relighter.add_band_lights(&animation.emitters, &animation.centroids, args.bands)?)
    } else {
        None
    };
    let lights_seconds = lights_start.elapsed().as_secs_f64();
    let initial_seconds = initial_solve(&animation, &mut relighter, frame_budget)?;
    let records = run_frames(
        &animation,
        &mut relighter,
        bands.as_deref(),
        &mut view,
        base_power,
        &mut timings,
    )?;
    timings.total = start.elapsed().as_secs_f64();
    let peak = memory::peak_rss_bytes();
    let summary = FrameSummary::of(&records);

    if let Some(path) = &args.report {
        let mut report = Report::new("relight", &args.scene.scene, &loaded);
        report
            .add_warnings(memory_warning)
            .insert(
                "parameters",
                parameters_json(args, &options, &view.camera, eye, target),
            )
            .insert("build_seconds", build_seconds)
            .insert("initial_seconds", initial_seconds)
            .insert("bands", bands.as_ref().map_or(0, Vec::len))
            .insert("lights_seconds", lights_seconds)
            .insert("hierarchy", hierarchy_json(relighter.prepared()))
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
            initial_seconds,
            &summary
        )
    );
    Ok(())
}

/// The arguments of `relight` after [`check_args`].
struct Checked {
    /// The solver options.
    options: SolverOptions,
    /// `--frame-budget` as a duration.
    frame_budget: Option<Duration>,
    /// `--move-light` then `--scale-light`.
    changes: Vec<LightChange>,
    /// The camera (eye and target possibly still automatic).
    camera: CameraOptions,
}

/// Checks every argument of `relight` that can be checked before the scene is loaded, and the
/// output paths.
fn check_args(args: &RelightArgs) -> Result<Checked> {
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
    if args.hold >= args.frames {
        return Err(Error::Parameter(format!(
            "--hold {} must be below --frames {} (at least one frame moves the lights)",
            args.hold, args.frames
        )));
    }
    let frame_budget = match args.frame_budget {
        Some(ms) if (0.0..=MAX_FRAME_BUDGET_MS).contains(&ms) => {
            Some(Duration::from_secs_f64(ms / 1e3))
        }
        Some(ms) => {
            return Err(Error::Parameter(format!(
                "--frame-budget {ms} outside [0, {MAX_FRAME_BUDGET_MS}] milliseconds"
            )))
        }
        None => None,
    };
    let changes: Vec<LightChange> = args
        .move_light
        .iter()
        .chain(&args.scale_light)
        .copied()
        .collect();
    if args.bands > 0 && !changes.is_empty() {
        return Err(Error::Parameter(
            "--bands mixes precomputed emission lights; it does not animate analytic lights (--move-light, --scale-light)".into(),
        ));
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
    Ok(Checked {
        options,
        frame_budget,
        changes,
        camera,
    })
}

/// Checks the loaded scene against the arguments: the light changes name its lights, there is
/// something to animate, and `--bands` has emitters and no lit analytic light.
fn check_scene(
    args: &RelightArgs,
    loaded: &driver::Loaded,
    emitters: &[usize],
    changes: &[LightChange],
) -> Result<()> {
    check_light_changes(&loaded.scene.lights, changes).map_err(|e| {
        let flag = if args.move_light.is_empty() {
            "--scale-light"
        } else if args.scale_light.is_empty() {
            "--move-light"
        } else {
            "--move-light/--scale-light"
        };
        let message = match e {
            Error::Parameter(m) => m,
            other => other.to_string(),
        };
        Error::Parameter(format!("{flag}: {message}"))
    })?;
    if emitters.is_empty() && changes.is_empty() {
        return Err(Error::Scene {
            path: args.scene.scene.clone(),
            message: "no emitting triangle to animate (give a material Ke, or use --emit-above) and no analytic light to move or scale (--move-light, --scale-light)"
                .into(),
        });
    }
    if emitters.is_empty() && args.bands > 0 {
        return Err(Error::Scene {
            path: args.scene.scene.clone(),
            message: "--bands: no emitting triangle to cut into bands".into(),
        });
    }
    if args.bands > 0 && loaded.scene.lights.iter().any(|l| l.strength() > 0.0) {
        return Err(Error::Parameter(
            "--bands mixes precomputed emission lights, and the scene has lit analytic lights (point, spot, sun, sky); relight without --bands".into(),
        ));
    }
    Ok(())
}

/// What changes over the frames of `relight`: the emitters' sweep and the analytic lights'
/// changes, from the scene's own lighting.
struct Animation<'a> {
    /// The arguments (`--dim`, `--frames`, `--hold`, ...).
    args: &'a RelightArgs,
    /// The scene.
    scene: &'a Scene,
    /// The emitting triangles ([`emitter_centroids`]).
    emitters: Vec<usize>,
    /// Their centroids.
    centroids: Vec<DVec3>,
    /// The light changes ([`check_light_changes`]).
    changes: Vec<LightChange>,
    /// The scene's emission per input triangle.
    base: Vec<[f64; 3]>,
    /// The scene's analytic lights.
    base_lights: Vec<Light>,
    /// Frames that move the lights (all but the `--hold` ones).
    animated: usize,
}

impl<'a> Animation<'a> {
    /// The animation of `scene` as `args` ask, from its own emission and lights.
    fn new(
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
    fn power(&self, emission: &[[f64; 3]]) -> f64 {
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
fn initial_solve(
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
struct FrameView {
    /// The camera, eye and target resolved.
    camera: CameraOptions,
    /// Flat or smooth.
    shading: Shading,
}

/// Relights and writes every frame; returns their records. `base_power`: the emitted power of
/// the scene's own emission ([`Animation::power`]).
fn run_frames(
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
    render::render_png_shaded(
        &frame_path(&args.out, frame),
        relighter.patches(),
        &relit.solution,
        camera,
        view.shading,
    )?;
    Ok(render_start.elapsed().as_secs_f64())
}

/// The `parameters` of the `relight` report.
fn parameters_json(
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
fn hierarchy_json(prepared: &Prepared) -> Value {
    json!({
        "links": prepared.links.len(),
        "elements": prepared.element_count(),
        "solver_bytes": prepared.bytes(),
        "memory": prepared.memory(),
    })
}

/// The line `relight` prints on stdout when done.
fn relight_summary(
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
