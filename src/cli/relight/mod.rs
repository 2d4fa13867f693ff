//! `antiradiance relight`: animate the lights of a scene with a [`Relighter`], one picture per frame.

mod frames;
mod records;

use frames::*;
use records::*;

use crate::cli::driver::{self, Report, SceneArgs, SolverArgs, Timings};
use antiradiance::error::{Error, Result};
use antiradiance::memory;
use antiradiance::output::render::{self, CameraOptions, Shading};
use antiradiance::solve::relight::{
    check_light_changes, emitter_centroids, LightChange, Relighter,
};
use antiradiance::solve::SolverOptions;
use clap::Args;
use glam::DVec3;
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
///
/// [`sweep_weights`]: antiradiance::solve::relight::sweep_weights
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
        crate::cli::driver::print_warning(w);
    }
    // The relighter solves emitters as given, so emitters just in front of a surface are left
    // to antiradiance (the solve command works their gaps out on their own).
    let covered_warning = options
        .antiradiance
        .then(|| {
            antiradiance::solve::warnings::covered_emitter_warning(
                relighter.patches(),
                &antiradiance::solve::solution::SolveStats::default(),
            )
        })
        .flatten();
    if let Some(w) = &covered_warning {
        crate::cli::driver::print_warning(w);
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
        raster: None,
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
            .add_warnings(memory_warning.into_iter().chain(covered_warning))
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
