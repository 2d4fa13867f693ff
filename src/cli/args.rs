//! The arguments the commands share: scene, solver and output options, and those of
//! `solve`, `reference` and `compare`.

use antiradiance::error::{Error, Result};
use antiradiance::output::render::CameraOptions;
use antiradiance::scene::lights::Light;

use crate::cli::lights;
use antiradiance::scene::{Scene, SceneOptions};
use antiradiance::solve::budget;
use antiradiance::solve::{Preset, SolverKind, SolverOptions};
use clap::Args;
use glam::DVec3;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

use crate::cli::driver::*;

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
    #[arg(long = "light", value_name = "LIGHT", value_parser = lights::parse_light, allow_hyphen_values = true)]
    pub lights: Vec<Light>,
    /// A uniform sky of radiance R,G,B (W/(m^2 sr)) in every direction nothing blocks.
    #[arg(long, value_name = "R,G,B", value_parser = lights::parse_sky)]
    pub sky: Option<Light>,
    /// Every surface is two-sided: both faces of each triangle emit and reflect, each with its
    /// own radiance (the CSV adds back_r,back_g,back_b), and block light arriving at either.
    #[arg(long)]
    pub two_sided: bool,
    /// The triangles of material NAME are two-sided (repeatable; see --two-sided).
    #[arg(long = "two-sided-material", value_name = "NAME")]
    pub two_sided_materials: Vec<String>,
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
            "two_sided": self.two_sided,
            "two_sided_materials": self.two_sided_materials,
        })
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
    /// be kept (0 refines by geometry alone); default 2e-5.
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub flux_share: Option<f64>,
    /// Faint pairs whose bounding spheres overlap become one link each instead of exact
    /// couplings between their elements: about twice as fast on interiors full of small
    /// tessellated objects, less accurate (b90_office 1.52% -> 2.34% from its reference; on in
    /// the fast preset).
    #[arg(long, conflicts_with = "exact_faint_pairs")]
    pub faint_links: bool,
    /// Faint pairs are coupled element by element (the default and accurate presets' choice).
    #[arg(long)]
    pub exact_faint_pairs: bool,
    /// Largest receiver extent over its distance from the sender for which a cluster link is
    /// gathered once at the receiver node, as its field to second order (0 gathers every link
    /// at every element); default 0.3.
    #[arg(long, value_name = "R", allow_negative_numbers = true)]
    pub field_ratio: Option<f64>,
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
        let mut options = self.preset.unwrap_or(Preset::Default).options();
        if let Some(bins) = self.bins {
            options.bins = bins;
        }
        if let Some(epsilon) = self.epsilon {
            options.epsilon = epsilon;
        }
        if let Some(share) = self.flux_share {
            options.flux_share = share;
        }
        if self.faint_links {
            options.faint_links = true;
        }
        if self.exact_faint_pairs {
            options.faint_links = false;
        }
        if let Some(ratio) = self.field_ratio {
            options.field_ratio = ratio;
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
            options.memory_limit_bytes = Some(limit);
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
    /// Per-element results: CSV `element,triangle,x0,y0,z0,x1,y1,z1,x2,y2,z2,area,r,g,b`, one
    /// row per solved element (the pieces the hierarchical solver split input triangles into,
    /// its own resolution), corners in scene units, r,g,b = B of its front face.
    #[arg(long, value_name = "OUT.csv")]
    pub elements: Option<PathBuf>,
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
    /// Vertical field of view of the picture, degrees [default: the scene's camera's, else 50].
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    pub fov: Option<f64>,
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
    /// The camera of the picture as given on the command line.
    pub fn camera(&self) -> CameraOptions {
        CameraOptions {
            eye: self.eye,
            target: self.target,
            fov_deg: self.fov.unwrap_or(CameraOptions::default().fov_deg),
            width: self.width,
            height: self.height,
            exposure: self.exposure,
        }
    }

    /// The camera of the picture of `scene`: the scene's own camera ([`Scene::camera`]) where
    /// neither `--eye` nor `--target` is given (its field of view unless `--fov` is), else
    /// [`OutputArgs::camera`].
    pub fn camera_for(&self, scene: &Scene) -> CameraOptions {
        let mut camera = self.camera();
        if let (None, None, Some(c)) = (self.eye, self.target, scene.camera) {
            camera.eye = Some(c.eye);
            camera.target = Some(c.target);
            camera.fov_deg = self.fov.unwrap_or(c.fov_deg);
        }
        camera
    }

    /// The output files, with the flag that names each (report last).
    pub fn files(&self) -> Vec<(&'static str, &Path)> {
        [
            ("--png", &self.png),
            ("--ply", &self.ply),
            ("--gltf", &self.gltf),
            ("--triangles", &self.triangles),
            ("--elements", &self.elements),
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
