//! The command-line driver: what each subcommand does, stage by stage.
//!
//! Every command reads top-down in the same order:
//!
//! 1. **check** every parameter and output path (nothing is loaded or solved with a bad one);
//! 2. **load** the scene ([`scene::load_obj`]) and print its warnings;
//! 3. **build** the patches ([`mesh::build_patches`], `--max-edge` splits triangles);
//! 4. **solve** ([`dense::solve_dense`], [`hierarchical::solve_hierarchical`] or
//!    [`reference::solve_reference`]);
//! 5. **output**: picture, PLY, per-triangle CSV, then the JSON report (every writer is atomic,
//!    and nothing is written before every computation is done, so a failure never leaves a
//!    half-written file).
//!
//! Each stage is timed ([`Timings`]); [`Report`] assembles the JSON report. The argument structs
//! derive [`clap::Args`] so that every subcommand (and later ones) shares the same flags; they
//! are plain structs with public fields and can be filled in by hand as well.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::{Args, ValueEnum};
use glam::DVec3;
use serde::Serialize;
use serde_json::{json, Map, Value};

use crate::error::{Error, Result};
use crate::mesh::{self, Patches};
use crate::progress::Progress;
use crate::reference::{self, ReferenceOptions};
use crate::render::{self, CameraOptions, Shading};
use crate::scene::{self, Scene, SceneOptions};
use crate::solution::{self, Solution, SolveStats};
use crate::solve::SolverOptions;
use crate::{budget, dense, direct, geometry, hierarchical, memory, output};

/// Largest number of patches `--max-edge` may split a scene into (a guard against a typo such
/// as a length in the wrong unit, which would otherwise exhaust memory before any message; a
/// scene that has more triangles than this to begin with is not refused).
pub const MAX_PATCHES: u64 = 1 << 22;

// ---------------------------------------------------------------------------------------------
// Arguments

/// The scene and the options that complete or override its materials.
#[derive(Args, Clone, Debug)]
#[command(next_help_heading = "Scene options")]
pub struct SceneArgs {
    /// Scene file: Wavefront OBJ; materials from the MTL files it names (Kd = albedo, Ke =
    /// emitted radiance, map_Kd / map_Ke textures). Polygons are fan-triangulated in file order.
    /// A name ending in .gltf or .glb is read as glTF 2.0.
    #[arg(value_name = "SCENE.obj", help_heading = "Arguments")]
    pub scene: PathBuf,
    /// Grey albedo in [0, 1) for triangles whose material has no Kd.
    #[arg(
        long,
        value_name = "A",
        default_value_t = 0.75,
        allow_negative_numbers = true
    )]
    pub albedo: f64,
    /// Make every triangle whose three vertices have y > Y emit radiance --emission.
    #[arg(long, value_name = "Y", allow_negative_numbers = true)]
    pub emit_above: Option<f64>,
    /// Emitted radiance (grey, W/(m^2 sr)) of the triangles selected by --emit-above.
    #[arg(
        long,
        value_name = "L",
        default_value_t = 1.0,
        allow_negative_numbers = true
    )]
    pub emission: f64,
    /// Split input triangles into pieces whose edges are at most L (scene units) before
    /// solving; per-triangle results stay per input triangle (area-weighted mean of pieces).
    #[arg(long, value_name = "L", allow_negative_numbers = true)]
    pub max_edge: Option<f64>,
    /// An analytic light (repeatable): point:X,Y,Z:R,G,B (W/sr),
    /// spot:X,Y,Z:DX,DY,DZ:INNER,OUTER:R,G,B (W/sr on the axis, cone half-angles in degrees,
    /// the direction it points) or sun:DX,DY,DZ:R,G,B (W/m^2, the direction light travels).
    #[arg(long = "light", value_name = "LIGHT", value_parser = crate::lights::parse_light, allow_hyphen_values = true)]
    pub lights: Vec<crate::lights::Light>,
    /// A uniform sky of radiance R,G,B (W/(m^2 sr)) in every direction nothing blocks.
    #[arg(long, value_name = "R,G,B", value_parser = crate::lights::parse_sky)]
    pub sky: Option<crate::lights::Light>,
}

impl SceneArgs {
    /// The loader's options.
    pub fn options(&self) -> SceneOptions {
        SceneOptions {
            default_albedo: self.albedo,
            emit_above: self.emit_above,
            emission: self.emission,
        }
    }

    /// Checks every scene option (before anything is loaded).
    pub fn validate(&self) -> Result<()> {
        self.options().validate()?;
        if let Some(l) = self.max_edge {
            if !(l.is_finite() && l > 0.0) {
                return Err(Error::Parameter(format!(
                    "--max-edge {l} must be finite and > 0"
                )));
            }
        }
        Ok(())
    }

    /// The scene options as they appear in reports.
    pub fn to_json(&self) -> Value {
        json!({
            "albedo": self.albedo,
            "emit_above": self.emit_above,
            "emission": self.emission,
            "max_edge": self.max_edge,
            "lights": self.lights.len(),
            "sky": self.sky.is_some(),
        })
    }
}

/// Which antiradiance solver to run.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SolverKind {
    /// Clustered links, O(n log n) (the default).
    Hierarchical,
    /// Every pair of patches (the oracle).
    Dense,
}

impl SolverKind {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            SolverKind::Hierarchical => "hierarchical",
            SolverKind::Dense => "dense",
        }
    }
}

/// A named set of solver parameters (`SolverOptions::preset`).
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// 6 x 6 bins, coarse links, looser tolerance.
    Fast,
    /// 8 x 8 bins, balanced.
    Default,
    /// 12 x 12 bins, fine links, tight tolerance.
    Accurate,
}

impl Preset {
    /// The name `SolverOptions::preset` knows.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Fast => "fast",
            Preset::Default => "default",
            Preset::Accurate => "accurate",
        }
    }
}

/// Parameters of the antiradiance solvers: a preset, then explicit overrides.
#[derive(Args, Clone, Debug, Default)]
#[command(next_help_heading = "Solver options")]
pub struct SolverArgs {
    /// Parameter preset; explicit --bins, --epsilon, --tol, --max-iterations override it.
    #[arg(long, value_enum, value_name = "PRESET")]
    pub preset: Option<Preset>,
    /// Direction bins per side of the octahedral map (R x R bins over the sphere).
    #[arg(long, value_name = "R")]
    pub bins: Option<usize>,
    /// Link refinement threshold of the hierarchical solver (smaller is finer).
    #[arg(long, value_name = "E", allow_negative_numbers = true)]
    pub epsilon: Option<f64>,
    /// Largest share of the scene's transport a geometrically coarse link may carry and still
    /// be kept (0 refines by geometry alone); default 1e-5.
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub flux_share: Option<f64>,
    /// Stop when the estimated remaining relative error of B is under T.
    #[arg(long, value_name = "T", allow_negative_numbers = true)]
    pub tol: Option<f64>,
    /// Iteration cap (the summary and the report say when it was reached).
    #[arg(long, value_name = "N")]
    pub max_iterations: Option<usize>,
    /// Most times the hierarchical solver may split an input triangle in four where a smaller,
    /// nearby object needs a finer receiver (0 keeps the input mesh; default 4).
    #[arg(long, value_name = "D")]
    pub split_depth: Option<u8>,
    /// Create antiradiance from light arriving at both sides of every surface; by default the
    /// front of every surface creates it, and the back of those whose back is exposed to light.
    #[arg(long, conflicts_with = "front_only_antiradiance")]
    pub two_sided_antiradiance: bool,
    /// Create antiradiance only from light arriving at a surface's front, everywhere (exact for
    /// closed, consistently oriented objects; back-lit surfaces then leak).
    #[arg(long)]
    pub front_only_antiradiance: bool,
    /// Switch antiradiance off (unoccluded radiosity: light goes through walls).
    #[arg(long)]
    pub no_antiradiance: bool,
    /// Keep negative radiance in the results instead of clamping it to 0 (it is reported
    /// either way).
    #[arg(long)]
    pub keep_negative: bool,
    /// Exact direct light: the first bounce from the emitters with shadow rays, antiradiance
    /// for the indirect bounces only (on by default in the default and accurate presets).
    #[arg(long, conflicts_with = "no_direct_light")]
    pub direct_light: bool,
    /// No exact direct light: antiradiance for every bounce (the fast preset's choice).
    #[arg(long)]
    pub no_direct_light: bool,
    /// Most memory the process may hold while solving: bytes, or with a suffix K, M, G, T
    /// (powers of 1024: 512M, 4G, 1.5G). A model that would not fit is coarsened (with a
    /// warning); one that cannot fit even so is an error before anything large is allocated.
    /// Default: half the machine's physical memory.
    #[arg(
        long,
        value_name = "SIZE",
        value_parser = parse_memory_limit,
        allow_hyphen_values = true
    )]
    pub memory_limit: Option<u64>,
}

/// Parses `--memory-limit SIZE` ([`budget::parse_size`]).
pub fn parse_memory_limit(text: &str) -> std::result::Result<u64, String> {
    budget::parse_size(text)
}

impl SolverArgs {
    /// The preset with the explicit overrides applied, validated.
    pub fn options(&self) -> Result<SolverOptions> {
        let mut options = SolverOptions::preset(self.preset.unwrap_or(Preset::Default).name())?;
        if let Some(bins) = self.bins {
            options.bins = bins;
        }
        if let Some(epsilon) = self.epsilon {
            options.epsilon = epsilon;
        }
        if let Some(share) = self.flux_share {
            options.flux_share = share;
        }
        if let Some(tol) = self.tol {
            options.tol = tol;
        }
        if let Some(depth) = self.split_depth {
            options.split_depth = depth;
        }
        if let Some(n) = self.max_iterations {
            options.max_iterations = n;
        }
        options.two_sided = self.two_sided_antiradiance;
        options.block_exposed_backs = !self.front_only_antiradiance;
        options.antiradiance = !self.no_antiradiance;
        options.clamp_negative = !self.keep_negative;
        if self.direct_light {
            options.direct_light = true;
        }
        if self.no_direct_light {
            options.direct_light = false;
        }
        if let Some(limit) = self.memory_limit {
            options.memory_limit_bytes = limit;
        }
        options.validate()?;
        Ok(options)
    }

    /// The preset's name as it appears in reports.
    pub fn preset_name(&self) -> &'static str {
        self.preset.unwrap_or(Preset::Default).name()
    }
}

/// Output files and the camera of the picture.
#[derive(Args, Clone, Debug, Default)]
#[command(next_help_heading = "Output options")]
pub struct OutputArgs {
    /// Per-triangle results: CSV `index,area,emissive,r,g,b`, one row per input triangle in
    /// input order, r,g,b = outgoing radiance B.
    #[arg(long, value_name = "OUT.csv")]
    pub triangles: Option<PathBuf>,
    /// The mesh (patches) with tone-mapped vertex colours and per-face float radiance.
    #[arg(long, value_name = "OUT.ply")]
    pub ply: Option<PathBuf>,
    /// The mesh as binary glTF: linear per-vertex COLOR_0 (exposure-scaled), one primitive per
    /// material, per-triangle radiance in an accessor named in each primitive's extras.
    #[arg(long, value_name = "OUT.glb")]
    pub gltf: Option<PathBuf>,
    /// A picture of the solution (auto-framed unless --eye / --target are given).
    #[arg(long, value_name = "OUT.png")]
    pub png: Option<PathBuf>,
    /// JSON report: counts, parameters, time per stage, solver statistics, peak memory.
    #[arg(long, value_name = "OUT.json")]
    pub report: Option<PathBuf>,
    /// Camera position in scene units.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true)]
    pub eye: Option<DVec3>,
    /// Point the camera looks at, in scene units.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true)]
    pub target: Option<DVec3>,
    /// Vertical field of view of the picture, degrees.
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 50.0,
        allow_negative_numbers = true
    )]
    pub fov: f64,
    /// Picture width in pixels.
    #[arg(long, value_name = "W", default_value_t = 800)]
    pub width: u32,
    /// Picture height in pixels.
    #[arg(long, value_name = "H", default_value_t = 600)]
    pub height: u32,
    /// Multiplier applied to B before the sRGB curve (picture and PLY colours); automatic by
    /// default (95th percentile of lit, non-emissive radiance to 0.8).
    #[arg(long, value_name = "X", allow_negative_numbers = true)]
    pub exposure: Option<f64>,
    /// Smooth (Gouraud) shading in the picture: B interpolated from per-vertex averages of
    /// adjacent patches; by default each patch is drawn in its own constant B.
    #[arg(long)]
    pub smooth: bool,
}

impl OutputArgs {
    /// The camera of the picture.
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

    /// The output files, with the flag that names each (report last).
    pub fn files(&self) -> Vec<(&'static str, &Path)> {
        [
            ("--png", &self.png),
            ("--ply", &self.ply),
            ("--gltf", &self.gltf),
            ("--triangles", &self.triangles),
            ("--report", &self.report),
        ]
        .into_iter()
        .filter_map(|(flag, p)| p.as_deref().map(|p| (flag, p)))
        .collect()
    }

    /// Checks the camera and every output path before any work is done (see [`check_outputs`]).
    pub fn validate(&self, scene: &Path) -> Result<()> {
        check_camera(&self.camera())?;
        check_outputs(&self.files(), scene)
    }
}

/// Parses `x,y,z` into a point (for `--eye` and `--target`).
pub fn parse_point(text: &str) -> std::result::Result<DVec3, String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("expected x,y,z (three numbers), got '{text}'"));
    }
    let mut v = [0.0; 3];
    for (slot, part) in v.iter_mut().zip(&parts) {
        *slot = part
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("'{part}' is not a finite number"))?;
    }
    Ok(DVec3::from_array(v))
}

/// `antiradiance solve`: the antiradiance solution of a scene.
#[derive(Args, Clone, Debug)]
pub struct SolveArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Solver: hierarchical (clustered links) or dense (every pair of patches; the oracle).
    #[arg(long, value_enum, default_value_t = SolverKind::Hierarchical, help_heading = "Solver options")]
    pub solver: SolverKind,
    #[command(flatten)]
    pub solver_args: SolverArgs,
    #[command(flatten)]
    pub output: OutputArgs,
    /// No progress bars and no summary (warnings and errors are still printed).
    #[arg(long, short)]
    pub quiet: bool,
}

/// `antiradiance reference`: the path-traced ground truth of a scene.
#[derive(Args, Clone, Debug)]
pub struct ReferenceArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Samples per patch (noise falls as 1 / sqrt(N)).
    #[arg(long, value_name = "N", help_heading = "Path tracer options")]
    pub spp: usize,
    /// Seed of the random streams (results are reproducible for a given seed).
    #[arg(
        long,
        value_name = "S",
        default_value_t = 1,
        help_heading = "Path tracer options"
    )]
    pub seed: u64,
    #[command(flatten)]
    pub output: OutputArgs,
    /// No progress bars and no summary (warnings and errors are still printed).
    #[arg(long, short)]
    pub quiet: bool,
}

/// `antiradiance compare`: dense and hierarchical side by side (and against the path tracer).
#[derive(Args, Clone, Debug)]
pub struct CompareArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub solver_args: SolverArgs,
    /// Also run the path tracer with N samples per patch and give each solver's error against it.
    #[arg(long, value_name = "N", help_heading = "Path tracer options")]
    pub reference_spp: Option<usize>,
    /// Seed of the path tracer.
    #[arg(
        long,
        value_name = "S",
        default_value_t = 1,
        help_heading = "Path tracer options"
    )]
    pub seed: u64,
    /// JSON report of the comparison.
    #[arg(long, value_name = "OUT.json", help_heading = "Output options")]
    pub report: Option<PathBuf>,
    /// No progress bars (the table is still printed).
    #[arg(long, short)]
    pub quiet: bool,
}

// ---------------------------------------------------------------------------------------------
// Checks done before any work

/// Checks a camera the way the renderer will (size, field of view, exposure, eye and target), so
/// a bad picture option fails before the solve rather than after it.
pub fn check_camera(camera: &CameraOptions) -> Result<()> {
    if camera.width == 0 || camera.height == 0 || camera.width > 16384 || camera.height > 16384 {
        return Err(Error::Parameter(format!(
            "--width {} --height {}: the picture must be between 1x1 and 16384x16384 pixels",
            camera.width, camera.height
        )));
    }
    if !(camera.fov_deg.is_finite() && camera.fov_deg > 0.0 && camera.fov_deg < 180.0) {
        return Err(Error::Parameter(format!(
            "--fov {} must be in (0, 180) degrees",
            camera.fov_deg
        )));
    }
    if let Some(e) = camera.exposure {
        if !(e.is_finite() && e > 0.0) {
            return Err(Error::Parameter(format!(
                "--exposure {e} must be finite and > 0"
            )));
        }
    }
    if let (Some(eye), Some(target)) = (camera.eye, camera.target) {
        if eye == target {
            return Err(Error::Parameter(format!(
                "--eye and --target are the same point {},{},{}",
                eye.x, eye.y, eye.z
            )));
        }
    }
    Ok(())
}

/// Checks output paths before any work: each must name a file in an existing directory, must
/// not be a directory, must not be the scene file, and no two may be the same file.
pub fn check_outputs(files: &[(&str, &Path)], scene: &Path) -> Result<()> {
    let scene_resolved = resolved(scene);
    let mut seen: Vec<(&str, PathBuf)> = Vec::new();
    for &(flag, path) in files {
        let fail = |message: String| Error::Io {
            path: path.to_path_buf(),
            message,
        };
        if path.file_name().is_none() {
            return Err(fail(format!("{flag} needs a file name")));
        }
        if path.is_dir() {
            return Err(fail(format!("{flag}: is a directory")));
        }
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        if !dir.is_dir() {
            return Err(fail(format!(
                "{flag}: directory {} does not exist",
                dir.display()
            )));
        }
        let r = resolved(path);
        if r == scene_resolved {
            return Err(fail(format!("{flag} would overwrite the scene file")));
        }
        if let Some((other, _)) = seen.iter().find(|(_, p)| *p == r) {
            return Err(fail(format!("{flag} names the same file as {other}")));
        }
        seen.push((flag, r));
    }
    Ok(())
}

/// The path with its directory made canonical (when it exists), for comparing file names.
fn resolved(path: &Path) -> PathBuf {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match (dir.canonicalize(), path.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => path.to_path_buf(),
    }
}

/// Number of patches [`mesh::build_patches`] makes from `scene` with `max_edge` (each
/// non-degenerate triangle becomes k*k pieces, k = ceil(longest edge / max_edge) in 1..=1024).
pub fn patch_count(scene: &Scene, max_edge: Option<f64>) -> u64 {
    (0..scene.len())
        .map(|t| match max_edge {
            Some(l) if l > 0.0 && l.is_finite() && !scene.is_degenerate(t) => {
                let k = (geometry::longest_edge(&scene.corners(t)) / l)
                    .ceil()
                    .clamp(1.0, 1024.0) as u64;
                k * k
            }
            _ => 1,
        })
        .sum()
}

// ---------------------------------------------------------------------------------------------
// Stages

/// Wall-clock seconds per stage. `total` runs from the start of the command to the end of the
/// output stage (the report itself is written after it).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Timings {
    /// Reading and checking the scene files.
    pub load: f64,
    /// Building the patches (meshing, unit frame).
    pub build: f64,
    /// The solver(s).
    pub solve: f64,
    /// Writing the picture, PLY and CSV.
    pub output: f64,
    /// From the start of the command to the end of the output stage.
    pub total: f64,
}

/// Runs `f` and adds its wall-clock seconds to `*seconds`.
pub fn timed<T>(seconds: &mut f64, f: impl FnOnce() -> T) -> T {
    let start = Instant::now();
    let value = f();
    *seconds += start.elapsed().as_secs_f64();
    value
}

/// A loaded scene and its patches.
pub struct Loaded {
    /// The input triangles (file order) with materials and warnings.
    pub scene: Scene,
    /// The solver's elements.
    pub patches: Patches,
}

/// Stages 2 and 3: loads the scene, prints its warnings (`warning: ...` on stderr, even when
/// quiet), builds the patches. Precondition: `args.validate()` passed.
pub fn load(args: &SceneArgs, timings: &mut Timings) -> Result<Loaded> {
    let scene = timed(&mut timings.load, || {
        scene::load_scene(&args.scene, &args.options())
    })?;
    let mut scene = scene;
    scene
        .lights
        .extend(args.lights.iter().chain(&args.sky).copied());
    for w in &scene.warnings {
        eprintln!("warning: {}", one_line(w));
    }
    let count = patch_count(&scene, args.max_edge);
    if count > MAX_PATCHES && count > scene.len() as u64 {
        return Err(Error::Parameter(format!(
            "--max-edge {} would split {} into {count} patches (at most {MAX_PATCHES}); choose a larger --max-edge",
            args.max_edge.unwrap_or(0.0),
            args.scene.display()
        )));
    }
    let patches = timed(&mut timings.build, || {
        mesh::build_patches(&scene, args.max_edge)
    });
    Ok(Loaded { scene, patches })
}

/// Stage 4 for the antiradiance solvers, with a progress bar unless `quiet`.
/// Precondition: `options.validate()` passed.
///
/// Errors: [`Error::Memory`] when the solve does not fit `options.memory_limit_bytes` (see
/// [`crate::budget`]).
pub fn run_solver(
    kind: SolverKind,
    patches: &Patches,
    options: &SolverOptions,
    quiet: bool,
) -> Result<Solution> {
    let progress = Progress::new(kind.name(), options.max_iterations as u64, !quiet);
    let solution = match (kind, options.direct_light) {
        (SolverKind::Dense, false) => dense::solve_dense(patches, options, &progress),
        (SolverKind::Hierarchical, false) => {
            hierarchical::solve_hierarchical(patches, options, &progress)
        }
        (SolverKind::Dense, true) => direct::solve_dense_direct(patches, options, &progress),
        (SolverKind::Hierarchical, true) => {
            direct::solve_hierarchical_direct(patches, options, &progress)
        }
    };
    progress.finish();
    let mut solution = solution?;
    // Degenerate and duplicate triangles' patches get the values the model fixes for them,
    // whatever the solver left there.
    solution.settle_inactive(patches);
    Ok(solution)
}

/// The warnings of one antiradiance solve: memory limit ([`memory_warning`]), iteration cap
/// ([`cap_warning`]), skipped direct light ([`direct_light_warning`]), capped form-factor rows
/// ([`capped_rows_warning`]), much negative radiance ([`negative_warning`]) and radiance above
/// the bound ([`bound_warning`]). A failed solve is not warned about here: it is an error
/// ([`SolveStats::check`]).
pub fn solve_warnings(
    kind: SolverKind,
    stats: &SolveStats,
    options: &SolverOptions,
    patches: &Patches,
) -> Vec<String> {
    memory_warning(stats.memory.as_ref())
        .into_iter()
        .chain(cap_warning(kind.name(), stats, options, patches))
        .chain(direct_light_warning(stats, options))
        .chain(capped_rows_warning(kind.name(), stats))
        .chain(negative_warning(kind.name(), stats, options))
        .chain(bound_warning(kind.name(), stats))
        .collect()
}

/// The warning for a solve whose largest B is above 1 + [`crate::health::BOUND_WARNING`] times
/// the bound `E_max / (1 - rho_max)` (but not above 1 + [`crate::health::BOUND_SLACK`], which
/// fails the solve); `None` otherwise.
pub fn bound_warning(solver: &str, stats: &SolveStats) -> Option<String> {
    let ratio = stats.largest_b_over_bound;
    (stats.failure.is_none() && ratio > 1.0 + crate::health::BOUND_WARNING).then(|| {
        format!(
            "the {solver} solver's largest radiance is {ratio:.3} times the bound E_max/(1 - rho_max) = {:.6} the emission and albedos allow: some patches are brighter than the light can make them (cluster links or antiradiance bins too coarse; a smaller --epsilon or more --bins usually lowers it)",
            stats.radiance_bound
        )
    })
}

/// The warning for a solve that scaled form-factor rows down to 1 (a convex enclosure whose
/// rows summed above 1 + [`crate::health::ROW_SUM_TOLERANCE`]; `None` when none was).
pub fn capped_rows_warning(solver: &str, stats: &SolveStats) -> Option<String> {
    (stats.capped_rows > 0).then(|| {
        format!(
            "the {solver} solver scaled {} down to 1: in this convex enclosure their form factors summed to up to {:.6} (more than 1 + {:.0e}, discretization error that 1/(1 - rho) would amplify)",
            plural(stats.capped_rows, "form-factor row", "form-factor rows"),
            stats.max_row_sum,
            crate::health::ROW_SUM_TOLERANCE
        )
    })
}

/// The warning for a solve whose negative radiance mass is above
/// [`crate::health::NEGATIVE_WARNING`] of the positive (but not above
/// [`crate::health::NEGATIVE_LIMIT`], which fails the solve); `None` otherwise.
pub fn negative_warning(
    solver: &str,
    stats: &SolveStats,
    options: &SolverOptions,
) -> Option<String> {
    (stats.failure.is_none() && stats.negative_fraction > crate::health::NEGATIVE_WARNING).then(|| {
        format!(
            "the {solver} solver's negative radiance is {:.1}% of the positive mass (more than {:.0}%): antiradiance cancelled more light than it should{}; more --bins usually lowers it",
            100.0 * stats.negative_fraction,
            100.0 * crate::health::NEGATIVE_WARNING,
            if options.two_sided {
                ", which two-sided antiradiance does where surfaces are doubled back to back"
            } else {
                ""
            }
        )
    })
}

/// The warning for a solve that was changed to fit its memory limit (`None` when nothing was):
/// the limit, what was coarsened, and the estimate of the model solved.
pub fn memory_warning(memory: Option<&budget::MemoryStats>) -> Option<String> {
    let m = memory?;
    if m.coarsened.is_empty() {
        return None;
    }
    Some(format!(
        "the model was coarsened to fit the memory limit of {} (--memory-limit): {}; its estimate is {} beside the {} in use before the solve; the result is less accurate than asked",
        format_bytes(m.limit_bytes),
        m.coarsened.join(", "),
        format_bytes(m.estimate_bytes),
        format_bytes(m.base_bytes)
    ))
}

/// The warning for a solve that was asked for exact direct light but skipped it because the
/// scene's emitters were over [`direct::DIRECT_LIGHT_BUDGET`] (`None` otherwise; a direct light
/// skipped to fit the memory limit is in [`memory_warning`]).
pub fn direct_light_warning(stats: &SolveStats, options: &SolverOptions) -> Option<String> {
    let for_memory = stats
        .memory
        .as_ref()
        .is_some_and(|m| m.coarsened.iter().any(|c| c == direct::DIRECT_LIGHT_OFF));
    (options.direct_light && stats.direct_light_skipped && !for_memory).then(|| {
        format!(
            "exact direct light skipped: receivers x emitter groups is over {:.0e} or the shadow rays over {:.0e}; antiradiance carried every bounce (--no-direct-light silences this)",
            direct::DIRECT_LIGHT_BUDGET as f64,
            direct::MAX_SHADOW_RAYS as f64
        )
    })
}

/// The warning for a solve that stopped at the iteration cap (`None` when it converged or
/// diverged): the
/// solver, the iterations, the last residual against the tolerance and, since the residual
/// underestimates the remaining error when the iteration contracts slowly, an estimate of that
/// error and of the iterations still needed, taking the contraction per sweep to be the highest
/// albedo of the scene (exact for a closed box of one albedo, an upper bound otherwise).
pub fn cap_warning(
    solver: &str,
    stats: &SolveStats,
    options: &SolverOptions,
    patches: &Patches,
) -> Option<String> {
    if stats.converged || stats.failure.is_some() {
        return None;
    }
    let rho = (0..patches.len())
        .filter(|&p| patches.active[p])
        .flat_map(|p| patches.albedo[p])
        .fold(0.0f64, f64::max)
        .min(0.9999);
    let r = solution::sanitize(stats.residual);
    let mut text = format!(
        "the {solver} solver stopped at the iteration cap ({} iterations) without converging: last residual {r:.2e}, tolerance {:.1e}; the result is not the converged solution",
        stats.iterations, options.tol
    );
    if rho > 0.0 && r > 0.0 {
        let remaining = r * rho / (1.0 - rho);
        let more = ((options.tol * (1.0 - rho) / (r * rho)).ln() / rho.ln()).ceil();
        text += &format!(
            " (its remaining error may be as large as {:.2}% of B: residual x rho/(1 - rho) with the highest albedo rho = {rho})",
            100.0 * remaining
        );
        if more.is_finite() && more > 0.0 {
            text += &format!(
                "; raise --max-iterations (to about {} at this rate)",
                stats.iterations as f64 + more
            );
        } else {
            text += "; raise --max-iterations or --tol";
        }
    } else {
        text += "; raise --max-iterations or --tol";
    }
    Some(text)
}

/// Stage 4 for the path tracer, with a progress bar unless `quiet`.
pub fn run_reference(patches: &Patches, options: &ReferenceOptions, quiet: bool) -> Solution {
    let progress = Progress::new("reference", patches.len() as u64, !quiet);
    let solution = reference::solve_reference(patches, options, &progress);
    progress.finish();
    solution
}

/// Stage 5 without the report: picture, PLY, CSV (each atomic). Preconditions:
/// `output.validate()` passed and `solution` belongs to `loaded`.
pub fn write_outputs(output: &OutputArgs, loaded: &Loaded, solution: &Solution) -> Result<()> {
    let camera = output.camera();
    if let Some(path) = &output.png {
        let shading = if output.smooth {
            Shading::Smooth
        } else {
            Shading::Flat
        };
        render::render_png_shaded(path, &loaded.patches, solution, &camera, shading)?;
    }
    if let Some(path) = &output.ply {
        let exposure = output
            .exposure
            .unwrap_or_else(|| render::auto_exposure(&loaded.patches, solution));
        output::write_ply(path, &loaded.patches, solution, exposure)?;
    }
    if let Some(path) = &output.triangles {
        output::write_triangles_csv(path, &loaded.scene, solution)?;
    }
    if let Some(path) = &output.gltf {
        let exposure = output
            .exposure
            .unwrap_or_else(|| render::auto_exposure(&loaded.patches, solution));
        crate::gltf_out::write_baked_glb(path, &loaded.scene, &loaded.patches, solution, exposure)?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Reports

/// Scene counts as they appear in reports.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Counts {
    /// Input triangles (after fan triangulation), the length of every per-triangle output.
    pub input_triangles: usize,
    /// Patches the solver worked on (more than the triangles with `--max-edge`).
    pub patches: usize,
    /// Zero-area input triangles (kept in the outputs with B = E).
    pub degenerate_triangles: usize,
    /// Input triangles that emit.
    pub emitters: usize,
}

impl Counts {
    /// The counts of a loaded scene.
    pub fn of(loaded: &Loaded) -> Counts {
        Counts {
            input_triangles: loaded.scene.len(),
            patches: loaded.patches.len(),
            degenerate_triangles: loaded.scene.degenerate_count(),
            emitters: loaded.scene.emitter_count(),
        }
    }
}

/// A JSON report under construction: a header common to every command (`tool`, `version`,
/// `command`, `scene`, `counts`, `warnings`) plus whatever the command inserts.
#[derive(Clone, Debug, Default)]
pub struct Report {
    fields: Map<String, Value>,
}

impl Report {
    /// The common header of a report for `command` on a loaded scene.
    pub fn new(command: &str, scene_path: &Path, loaded: &Loaded) -> Report {
        let mut report = Report::default();
        report
            .insert("tool", env!("CARGO_PKG_NAME"))
            .insert("version", env!("CARGO_PKG_VERSION"))
            .insert("command", command)
            .insert("scene", scene_path.display().to_string())
            .insert("counts", Counts::of(loaded))
            .insert("warnings", &loaded.scene.warnings);
        report
    }

    /// Appends warnings of the run (iteration cap, ...) to the scene's in `warnings`.
    pub fn add_warnings(&mut self, warnings: impl IntoIterator<Item = String>) -> &mut Report {
        let list = self
            .fields
            .entry("warnings")
            .or_insert_with(|| Value::Array(Vec::new()));
        if let Value::Array(list) = list {
            list.extend(warnings.into_iter().map(Value::String));
        }
        self
    }

    /// Sets `key` (replacing any previous value); a value that cannot be serialized becomes null.
    pub fn insert(&mut self, key: &str, value: impl Serialize) -> &mut Report {
        let value = serde_json::to_value(value).unwrap_or(Value::Null);
        self.fields.insert(key.to_string(), value);
        self
    }

    /// Adds `time_seconds` and `peak_memory_bytes` (read now), the closing fields of a report.
    pub fn finish(&mut self, timings: &Timings, peak_memory_bytes: Option<u64>) -> &mut Report {
        self.insert("time_seconds", timings)
            .insert("peak_memory_bytes", peak_memory_bytes)
    }

    /// The report as a JSON value.
    pub fn to_value(&self) -> Value {
        Value::Object(self.fields.clone())
    }

    /// Writes the report (pretty-printed, atomically).
    pub fn write(&self, path: &Path) -> Result<()> {
        output::write_json(path, &self.to_value())
    }
}

/// What a mesh cost a solve (the report's `stats.mesh`): the shapes of the input triangles,
/// the elements solved and the links per input triangle.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct MeshStats {
    /// Aspect ratios (longest edge squared over area) and area range of the non-degenerate
    /// input triangles ([`Scene::shapes`]).
    #[serde(flatten)]
    pub shapes: scene::TriangleShapes,
    /// Elements solved: the hierarchical solver's leaf triangles after its splits, the dense
    /// solver's patches; 0 for the path tracer.
    pub elements: usize,
    /// Links per non-degenerate input triangle (0 for the path tracer).
    pub links_per_triangle: f64,
}

impl MeshStats {
    /// The figures of a solve of a loaded scene.
    pub fn of(loaded: &Loaded, stats: &SolveStats) -> MeshStats {
        let shapes = loaded.scene.shapes();
        MeshStats {
            shapes,
            elements: stats.elements,
            links_per_triangle: if shapes.triangles > 0 {
                stats.links as f64 / shapes.triangles as f64
            } else {
                0.0
            },
        }
    }
}

/// Solver statistics as they appear in reports, with what the mesh cost (`mesh`, see
/// [`MeshStats`]). Non-finite numbers become 0 rather than null, except the residual of a
/// failed solve (null when it was NaN or infinite: that is what failed); `failure` is null for
/// a healthy solve, else the failure's figures with its one-line `message`.
pub fn stats_json(stats: &SolveStats, loaded: &Loaded) -> Value {
    let mut s = stats.clone();
    if s.failure.is_none() {
        s.residual = solution::sanitize(s.residual);
    }
    s.negative_fraction = solution::sanitize(s.negative_fraction);
    s.max_row_sum = solution::sanitize(s.max_row_sum);
    s.largest_b_over_bound = solution::sanitize(s.largest_b_over_bound);
    s.radiance_bound = solution::sanitize(s.radiance_bound);
    let mut value = serde_json::to_value(s).unwrap_or(Value::Null);
    if let (Some(f), Some(Value::Object(failure))) = (&stats.failure, value.get_mut("failure")) {
        failure.insert("message".into(), Value::String(f.to_string()));
    }
    if let Value::Object(map) = &mut value {
        let mesh = serde_json::to_value(MeshStats::of(loaded, stats)).unwrap_or(Value::Null);
        map.insert("mesh".into(), mesh);
    }
    value
}

/// The design-note error of `estimate` against `truth`, per input triangle of `scene`.
pub fn error_against(scene: &Scene, estimate: &Solution, truth: &Solution) -> f64 {
    let areas: Vec<f64> = (0..scene.len()).map(|t| scene.area(t)).collect();
    let emissive: Vec<bool> = (0..scene.len()).map(|t| scene.is_emitter(t)).collect();
    solution::relative_error(
        &areas,
        &emissive,
        &estimate.triangle_radiance,
        &truth.triangle_radiance,
    )
}

// ---------------------------------------------------------------------------------------------
// Commands

/// `antiradiance solve`.
pub fn solve(args: &SolveArgs) -> Result<()> {
    let start = Instant::now();
    let mut timings = Timings::default();
    args.scene.validate()?;
    let options = args.solver_args.options()?;
    args.output.validate(&args.scene.scene)?;

    let loaded = load(&args.scene, &mut timings)?;
    let solution = timed(&mut timings.solve, || {
        run_solver(args.solver, &loaded.patches, &options, args.quiet)
    })?;
    let cap = solve_warnings(args.solver, &solution.stats, &options, &loaded.patches);
    for w in &cap {
        eprintln!("warning: {w}");
    }
    // A failed solve writes no result (picture, PLY, CSV); its report says why.
    let failed = solution.stats.check(args.solver.name());
    if failed.is_ok() {
        timed(&mut timings.output, || {
            write_outputs(&args.output, &loaded, &solution)
        })?;
    }
    timings.total = start.elapsed().as_secs_f64();
    let peak = memory::peak_rss_bytes();

    if let Some(path) = &args.output.report {
        let mut report = Report::new("solve", &args.scene.scene, &loaded);
        report
            .add_warnings(cap)
            .insert(
                "parameters",
                json!({
                    "solver": args.solver,
                    "preset": args.solver_args.preset_name(),
                    "solver_options": options,
                    "scene_options": args.scene.to_json(),
                }),
            )
            .insert("stats", stats_json(&solution.stats, &loaded))
            .finish(&timings, peak);
        report.write(path)?;
    }
    failed?;
    if !args.quiet {
        eprintln!(
            "{}",
            solve_summary(
                args.solver.name(),
                &loaded,
                &solution.stats,
                &options,
                &timings,
                peak
            )
        );
    }
    Ok(())
}

/// `antiradiance reference`.
pub fn reference(args: &ReferenceArgs) -> Result<()> {
    let start = Instant::now();
    let mut timings = Timings::default();
    args.scene.validate()?;
    if args.spp == 0 {
        return Err(Error::Parameter("--spp must be at least 1".into()));
    }
    args.output.validate(&args.scene.scene)?;
    let options = ReferenceOptions {
        spp: args.spp,
        seed: args.seed,
        ..ReferenceOptions::default()
    };

    let loaded = load(&args.scene, &mut timings)?;
    let solution = timed(&mut timings.solve, || {
        run_reference(&loaded.patches, &options, args.quiet)
    });
    timed(&mut timings.output, || {
        write_outputs(&args.output, &loaded, &solution)
    })?;
    timings.total = start.elapsed().as_secs_f64();
    let peak = memory::peak_rss_bytes();

    if let Some(path) = &args.output.report {
        let mut report = Report::new("reference", &args.scene.scene, &loaded);
        report
            .insert(
                "parameters",
                json!({
                    "solver": "reference",
                    "reference_options": {
                        "spp": options.spp,
                        "seed": options.seed,
                        "max_depth": options.max_depth,
                    },
                    "scene_options": args.scene.to_json(),
                }),
            )
            .insert("stats", stats_json(&solution.stats, &loaded))
            .finish(&timings, peak);
        report.write(path)?;
    }
    if !args.quiet {
        eprintln!(
            "{}",
            reference_summary(&loaded, &options, &solution.stats, &timings, peak)
        );
    }
    Ok(())
}

/// One solver's run in `compare`.
#[derive(Clone, Debug, Serialize)]
pub struct CompareRun {
    /// Wall-clock seconds of the solve.
    pub seconds: f64,
    /// Peak resident memory during the solve above the resident memory before it, in bytes
    /// (`None` when the peak cannot be measured per stage, e.g. off Linux).
    pub peak_memory_delta_bytes: Option<u64>,
    /// The solver's statistics.
    pub stats: Value,
    /// Design-note error against the path tracer (when it was run).
    pub error_vs_reference: Option<f64>,
}

/// Runs `f` and measures its time and peak memory above the resident memory before it.
/// `overall_peak` keeps the process's peak across the resets this needs.
pub fn measured<T>(overall_peak: &mut Option<u64>, f: impl FnOnce() -> T) -> (T, f64, Option<u64>) {
    *overall_peak = (*overall_peak).max(memory::peak_rss_bytes());
    let reset = memory::reset_peak_rss();
    let base = memory::current_rss_bytes();
    let start = Instant::now();
    let value = f();
    let seconds = start.elapsed().as_secs_f64();
    let peak = memory::peak_rss_bytes();
    *overall_peak = (*overall_peak).max(peak);
    let delta = match (reset, base, peak) {
        (true, Some(b), Some(p)) => Some(p.saturating_sub(b)),
        _ => None,
    };
    (value, seconds, delta)
}

/// `antiradiance compare`: prints a table on stdout.
pub fn compare(args: &CompareArgs) -> Result<()> {
    let start = Instant::now();
    let mut timings = Timings::default();
    args.scene.validate()?;
    let options = args.solver_args.options()?;
    if args.reference_spp == Some(0) {
        return Err(Error::Parameter(
            "--reference-spp must be at least 1".into(),
        ));
    }
    let report_files: Vec<(&str, &Path)> = args
        .report
        .iter()
        .map(|p| ("--report", p.as_path()))
        .collect();
    check_outputs(&report_files, &args.scene.scene)?;

    let loaded = load(&args.scene, &mut timings)?;
    let mut overall_peak = None;
    let mut runs = Vec::new();
    let mut cap_warnings = Vec::new();
    for kind in [SolverKind::Dense, SolverKind::Hierarchical] {
        let (solution, seconds, delta) = measured(&mut overall_peak, || {
            run_solver(kind, &loaded.patches, &options, args.quiet)
        });
        let solution = solution?;
        timings.solve += seconds;
        for w in solve_warnings(kind, &solution.stats, &options, &loaded.patches) {
            eprintln!("warning: {w}");
            cap_warnings.push(w);
        }
        // A failed solve makes the comparison meaningless: no table, no report.
        solution.stats.check(kind.name())?;
        runs.push((kind, solution, seconds, delta));
    }
    let reference_options = args.reference_spp.map(|spp| ReferenceOptions {
        spp,
        seed: args.seed,
        ..ReferenceOptions::default()
    });
    let reference = reference_options.as_ref().map(|ro| {
        let (solution, seconds, delta) = measured(&mut overall_peak, || {
            run_reference(&loaded.patches, ro, args.quiet)
        });
        timings.solve += seconds;
        (solution, seconds, delta)
    });
    let between = error_against(&loaded.scene, &runs[1].1, &runs[0].1);
    timings.total = start.elapsed().as_secs_f64();
    overall_peak = overall_peak.max(memory::peak_rss_bytes());

    let mut results: Vec<(SolverKind, CompareRun)> = Vec::new();
    for (kind, solution, seconds, delta) in &runs {
        results.push((
            *kind,
            CompareRun {
                seconds: *seconds,
                peak_memory_delta_bytes: *delta,
                stats: stats_json(&solution.stats, &loaded),
                error_vs_reference: reference
                    .as_ref()
                    .map(|r| error_against(&loaded.scene, solution, &r.0)),
            },
        ));
    }

    let table = compare_table(
        &loaded,
        &args.scene.scene,
        &runs,
        &results,
        between,
        &reference,
    );
    let mut stdout = std::io::stdout().lock();
    // A closed pipe (`| head`) is not an error worth a message.
    let _ = stdout.write_all(table.as_bytes());
    let _ = stdout.flush();

    if let Some(path) = &args.report {
        let mut solvers = Map::new();
        for (kind, run) in &results {
            solvers.insert(
                kind.name().to_string(),
                serde_json::to_value(run).unwrap_or(Value::Null),
            );
        }
        let reference_json = match (&reference, &reference_options) {
            (Some((solution, seconds, delta)), Some(ro)) => json!({
                "spp": ro.spp,
                "seed": ro.seed,
                "seconds": seconds,
                "peak_memory_delta_bytes": delta,
                "stats": stats_json(&solution.stats, &loaded),
            }),
            _ => Value::Null,
        };
        let mut report = Report::new("compare", &args.scene.scene, &loaded);
        report
            .add_warnings(cap_warnings)
            .insert(
                "parameters",
                json!({
                    "preset": args.solver_args.preset_name(),
                    "solver_options": options,
                    "scene_options": args.scene.to_json(),
                }),
            )
            .insert("solvers", solvers)
            .insert("reference", reference_json)
            .insert("hierarchical_vs_dense_error", between)
            .finish(&timings, overall_peak);
        report.write(path)?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Human-readable text

/// A message on one line (line breaks become spaces).
pub fn one_line(text: &str) -> String {
    text.split(['\n', '\r'])
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
}

/// Bytes as a short human figure (MB or GB).
pub fn format_bytes(bytes: u64) -> String {
    let mb = bytes as f64 / (1024.0 * 1024.0);
    if mb >= 1024.0 {
        format!("{:.2} GB", mb / 1024.0)
    } else {
        format!("{mb:.1} MB")
    }
}

/// `n` and the noun in singular or plural (`plural(2, "patch", "patches")`).
fn plural(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

fn scene_phrase(loaded: &Loaded) -> String {
    let c = Counts::of(loaded);
    let mut s = plural(c.input_triangles, "triangle", "triangles");
    if c.patches != c.input_triangles {
        s += &format!(" ({} patches)", c.patches);
    }
    s
}

fn time_phrase(t: &Timings, peak: Option<u64>) -> String {
    let mut s = format!(
        "in {:.2} s (load {:.2} s, build {:.2} s, solve {:.2} s, output {:.2} s)",
        t.total, t.load, t.build, t.solve, t.output
    );
    if let Some(p) = peak {
        s += &format!(", peak memory {}", format_bytes(p));
    }
    s
}

/// The paragraph `solve` prints on stderr when done.
pub fn solve_summary(
    solver: &str,
    loaded: &Loaded,
    stats: &SolveStats,
    options: &SolverOptions,
    timings: &Timings,
    peak: Option<u64>,
) -> String {
    let convergence = if stats.converged {
        format!(
            "converged after {} (residual {:.2e})",
            plural(stats.iterations, "iteration", "iterations"),
            stats.residual
        )
    } else {
        format!(
            "stopped at the iteration cap ({}) with residual {:.2e} (tolerance {:.1e})",
            stats.iterations, stats.residual, options.tol
        )
    };
    let negative = if stats.negative_patches == 0 {
        "no negative radiance".to_string()
    } else {
        format!(
            "negative radiance {:.3}% of the positive mass on {} ({})",
            100.0 * stats.negative_fraction,
            plural(stats.negative_patches, "patch", "patches"),
            if options.clamp_negative {
                "clamped to 0"
            } else {
                "kept"
            }
        )
    };
    format!(
        "Solved {} with the {solver} solver {}; {convergence}; {negative}; {} links.",
        scene_phrase(loaded),
        time_phrase(timings, peak),
        stats.links
    )
}

/// The paragraph `reference` prints on stderr when done.
pub fn reference_summary(
    loaded: &Loaded,
    options: &ReferenceOptions,
    stats: &SolveStats,
    timings: &Timings,
    peak: Option<u64>,
) -> String {
    format!(
        "Path-traced {} with {} samples per patch (seed {}) {}; {} iterations.",
        scene_phrase(loaded),
        options.spp,
        options.seed,
        time_phrase(timings, peak),
        stats.iterations
    )
}

fn percent(x: f64) -> String {
    format!("{:.3}%", 100.0 * x)
}

fn compare_table(
    loaded: &Loaded,
    scene_path: &Path,
    runs: &[(SolverKind, Solution, f64, Option<u64>)],
    results: &[(SolverKind, CompareRun)],
    between: f64,
    reference: &Option<(Solution, f64, Option<u64>)>,
) -> String {
    let c = Counts::of(loaded);
    let mut out = format!(
        "{}: {}, {} patches, {}\n",
        scene_path.display(),
        plural(c.input_triangles, "triangle", "triangles"),
        c.patches,
        plural(c.emitters, "emitter", "emitters")
    );
    let mut header = format!(
        "{:<13} {:>10} {:>12} {:>12} {:>10} {:>10}",
        "solver", "time (s)", "peak mem", "links", "iterations", "residual"
    );
    if reference.is_some() {
        header += &format!(" {:>12}", "vs reference");
    }
    out += &header;
    out.push('\n');
    let mem = |d: Option<u64>| d.map(format_bytes).unwrap_or_else(|| "n/a".into());
    for ((kind, solution, seconds, delta), (_, run)) in runs.iter().zip(results) {
        let s = &solution.stats;
        let mut line = format!(
            "{:<13} {:>10.3} {:>12} {:>12} {:>10} {:>10.2e}",
            kind.name(),
            seconds,
            mem(*delta),
            s.links,
            if s.converged {
                s.iterations.to_string()
            } else if s.failure.is_some() {
                format!("{} (failed)", s.iterations)
            } else {
                format!("{} (cap)", s.iterations)
            },
            s.residual
        );
        if let Some(e) = run.error_vs_reference {
            line += &format!(" {:>12}", percent(e));
        }
        out += &line;
        out.push('\n');
    }
    if let Some((solution, seconds, delta)) = reference {
        out += &format!(
            "{:<13} {:>10.3} {:>12} {:>12} {:>10} {:>10}\n",
            "reference",
            seconds,
            mem(*delta),
            "-",
            format!("{} spp", solution.stats.iterations),
            "-"
        );
    }
    out += &format!(
        "hierarchical vs dense (area-weighted relative L1, non-emissive): {}\n",
        percent(between)
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patch_count_matches_build_patches() {
        let scene = crate::scenes::occluder_scene();
        for max_edge in [None, Some(10.0), Some(0.3), Some(0.07)] {
            assert_eq!(
                patch_count(&scene, max_edge),
                mesh::build_patches(&scene, max_edge).len() as u64,
                "{max_edge:?}"
            );
        }
    }

    #[test]
    fn points_parse() {
        assert_eq!(parse_point("1,-2, 3.5"), Ok(DVec3::new(1.0, -2.0, 3.5)));
        assert!(parse_point("1,2").is_err());
        assert!(parse_point("1,2,nan").is_err());
        assert!(parse_point("1,2,3,4").is_err());
    }

    #[test]
    fn explicit_solver_flags_override_the_preset() {
        let args = SolverArgs {
            preset: Some(Preset::Fast),
            bins: Some(10),
            ..SolverArgs::default()
        };
        let o = args.options().unwrap();
        assert_eq!(o.bins, 10);
        assert_eq!(o.epsilon, SolverOptions::fast().epsilon);
        assert!(SolverArgs {
            tol: Some(0.0),
            ..SolverArgs::default()
        }
        .options()
        .is_err());
    }

    #[test]
    fn one_line_joins_lines() {
        assert_eq!(one_line("a\nb\r\n  c  \n"), "a b c");
    }
}
