//! antiradiance: diffuse global illumination on triangle meshes with the antiradiance method.
//!
//! One module per stage of the pipeline, each using only the ones before it in this list:
//!
//! - [`geometry`]: exact kernels (solid angles, form factors, clipping), direction bins,
//!   sampling, ray tracing over a BVH and every tolerance;
//! - [`scene`]: what the user gives (OBJ+MTL and glTF loading, textures, analytic lights,
//!   generated scenes, OBJ writing);
//! - [`mesh`]: the solver's patches in a unit frame (splitting, twins);
//! - [`hierarchy`]: the cluster tree and the links between its nodes;
//! - [`transport`]: the couplings of one sender to one receiver, shared by every solver;
//! - [`mod@solve`]: options and presets, the dense oracle, the hierarchical solver, exact direct
//!   light, relighting, and the [`solve::solution::Solution`] every solver returns;
//! - [`mod@reference`]: the path tracer used as ground truth;
//! - [`output`]: CSV, PLY, binary glTF, PNG pictures, atomic writes.
//!
//! The command line (`src/cli/`, the `cli` feature) is a client of this library like any other.
//!
//! # The front door
//!
//! Four calls cover the common job: [`load()`] a scene, [`solve()`] it, [`write()`] the results,
//! or build a [`relight()`]er that re-solves it for new emission.
//!
//! The supported surface is this front door (the four calls and the types they take and
//! return, re-exported here: [`Scene`], [`SceneOptions`], [`SolverOptions`], [`Solved`],
//! [`Relighter`], [`Error`], [`Result`], [`Warning`]) plus [`details`]: the internals the
//! benches and the integration tests use beyond it (generated scenes, patches, the tree and
//! links, each solver on its own, the path tracer, solution measures, the writers). The stage
//! modules stay public for the tests; the rest of what they hold may change.
//!
//! ```
//! # fn main() -> antiradiance::Result<()> {
//! use antiradiance::details::generated;
//! use antiradiance::{SceneOptions, SolverOptions};
//!
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("cornell_box.obj");
//! // A generated scene written to disk, as any OBJ+MTL file would be.
//! generated::write_obj(&generated::cornell_box(), &path, "Cornell box")?;
//!
//! let scene = antiradiance::load(&path, &SceneOptions::default())?;
//! let solved = antiradiance::solve(&scene, None, &SolverOptions::fast())?;
//! assert_eq!(solved.solution.triangle_radiance.len(), scene.len());
//! antiradiance::write(&dir.path().join("cornell.csv"), &scene, &solved)?;
//! antiradiance::write(&dir.path().join("cornell.png"), &scene, &solved)?;
//!
//! // Half the light: links are kept, only the sweeps run again.
//! let mut relighter = antiradiance::relight(&scene, None, &SolverOptions::fast())?;
//! let half: Vec<[f64; 3]> = scene.emission.iter().map(|e| e.map(|x| 0.5 * x)).collect();
//! let relit = relighter.relight(&half)?;
//! let (full, dim) = (solved.solution.triangle_radiance[0][0], relit.solution.triangle_radiance[0][0]);
//! assert!((dim - 0.5 * full).abs() < 0.02 * full);
//! # Ok(())
//! # }
//! ```

// `!(x > 0.0)` is used on purpose: it is also true for NaN, which must be rejected too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod error;
pub mod files;
pub mod geometry;
pub mod hierarchy;
pub mod memory;
pub mod mesh;
pub mod output;
pub mod progress;
pub mod reference;
pub mod scene;
pub mod solve;
pub mod transport;
pub mod union_find;

pub use error::{Error, Result, Warning, WarningKind};
pub use scene::{Scene, SceneOptions};
pub use solve::relight::{Relighter, Relit};
pub use solve::{Preset, SolverOptions};

use std::path::Path;

use mesh::Patches;
use solve::solution::Solution;
use solve::SolverKind;

/// What the benches and the integration tests use beyond the front door, by stage: loaders,
/// generated scenes and lights; patches and geometry; the cluster tree and links; each solver,
/// its parts and the path tracer; solution measures; the output writers and the renderer.
pub mod details {
    pub use crate::scene::lights::{spot_falloff, Light, LUMENS_PER_WATT};
    pub use crate::scene::{generated, interiors, load_obj, load_scene, variants};

    pub use crate::geometry::bins::Bins;
    pub use crate::geometry::raytrace::RayScene;
    pub use crate::geometry::sampling::Rng;
    pub use crate::geometry::Tri;
    pub use crate::mesh::{build_patches, Patches};

    pub use crate::hierarchy::{links, ClusterTree};

    pub use crate::progress::Progress;
    pub use crate::reference::{solve_reference, ReferenceOptions};
    pub use crate::solve::budget::LinkBudget;
    pub use crate::solve::dense::solve_dense;
    pub use crate::solve::direct::{solve_dense_direct, solve_hierarchical_direct};
    pub use crate::solve::health::{self, FailureKind};
    pub use crate::solve::hierarchical::{link_params, solve_hierarchical, Prepared};
    pub use crate::solve::model::{exposed_backs, ModelStats};
    pub use crate::solve::relight::{
        animated_light, check_light_changes, emitter_centroids, frame_path, light_phase,
        sweep_weights, LightChange,
    };
    pub use crate::solve::warnings::cap_warning;
    pub use crate::solve::{change_ratio, run, SolverKind};

    pub use crate::solve::solution::{error_against, relative_error, Solution, SolveStats};

    pub use crate::output::render;
    pub use crate::output::{
        read_triangles_csv, write_atomic, write_baked_glb, write_json, write_ply, write_scene_glb,
        write_triangles_csv, TRIANGLES_CSV_HEADER,
    };
}

/// Reads a scene file ([`scene::load_scene`]): glTF 2.0 when the name ends in `.gltf` or
/// `.glb`, otherwise an OBJ file and the MTL files it names.
pub fn load(path: &Path, options: &SceneOptions) -> Result<Scene> {
    scene::load_scene(path, options)
}

/// A solved scene: the patches it was solved on, the solution, and what to warn about.
#[derive(Clone, Debug)]
pub struct Solved {
    /// The solver's patches (the scene's triangles, split by `max_edge`).
    pub patches: Patches,
    /// Radiance per patch and per input triangle, with the solve's statistics.
    pub solution: Solution,
    /// What did not fail but is less accurate than asked ([`solve::warnings::solve_warnings`]).
    pub warnings: Vec<Warning>,
}

/// Solves `scene` with the hierarchical solver: input triangles split so no edge is longer
/// than `max_edge` (scene units; `None` keeps them), then [`solve::run`].
///
/// Errors: invalid `options` or `max_edge`, more than [`mesh::MAX_PATCHES`] patches, a solve
/// that does not fit its memory limit, or one that failed its health checks
/// ([`solve::solution::SolveStats::check`]).
pub fn solve(scene: &Scene, max_edge: Option<f64>, options: &SolverOptions) -> Result<Solved> {
    options.validate()?;
    let patches = mesh::checked_patches(scene, max_edge)?;
    let kind = SolverKind::Hierarchical;
    let solution = solve::run(kind, &patches, options, &progress::Progress::hidden())?;
    solution.stats.check(kind.name())?;
    let warnings = solve::warnings::solve_warnings(kind, &solution.stats, options, &patches);
    Ok(Solved {
        patches,
        solution,
        warnings,
    })
}

/// A [`Relighter`] for `scene`: tree and links built once, re-solved for new emission and moved
/// or recoloured analytic lights, to the tolerance or progressively within a time per frame.
pub fn relight(scene: &Scene, max_edge: Option<f64>, options: &SolverOptions) -> Result<Relighter> {
    Relighter::new(scene, max_edge, options)
}

/// Writes a result, chosen by the file's extension: `.csv` the per-triangle CSV
/// ([`output::write_triangles_csv`]), `.ply` the coloured mesh at auto exposure
/// ([`output::write_ply`]), `.glb` binary glTF with the baked radiance at auto exposure
/// ([`output::write_baked_glb`]), `.png` a smoothly shaded picture from the scene's camera or
/// auto-framed ([`output::render::render_png_shaded`]). Atomic: a failure leaves no file.
pub fn write(path: &Path, scene: &Scene, solved: &Solved) -> Result<()> {
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match extension.as_deref() {
        Some("csv") => output::write_triangles_csv(path, scene, &solved.solution),
        Some("ply") => {
            let exposure = output::render::auto_exposure(&solved.patches, &solved.solution);
            output::write_ply(path, &solved.patches, &solved.solution, exposure)
        }
        Some("png") => {
            let mut camera = output::render::CameraOptions::default();
            if let Some(c) = scene.camera {
                camera.eye = Some(c.eye);
                camera.target = Some(c.target);
                camera.fov_deg = c.fov_deg;
            }
            output::render::render_png_shaded(
                path,
                &solved.patches,
                &solved.solution,
                &camera,
                output::render::Shading::Smooth,
            )
        }
        Some("glb") => {
            let exposure = output::render::auto_exposure(&solved.patches, &solved.solution);
            output::write_baked_glb(path, scene, &solved.patches, &solved.solution, exposure)
        }
        _ => Err(Error::Parameter(format!(
            "{}: write needs a .csv, .ply, .glb or .png file name",
            path.display()
        ))),
    }
}
