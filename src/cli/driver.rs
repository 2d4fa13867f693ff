//! The command-line driver: what each subcommand does, stage by stage.
//!
//! Every command reads top-down in the same order:
//!
//! 1. **check** every parameter and output path (nothing is loaded or solved with a bad one);
//! 2. **load** the scene ([`scene::load_scene`]: OBJ or glTF) and print its warnings;
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

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use antiradiance::error::{Error, Result};
use antiradiance::mesh::{self, Patches};
use antiradiance::mesh::{patch_count, MAX_PATCHES};
use antiradiance::output;
use antiradiance::output::render::{self, CameraOptions, Shading};
use antiradiance::progress::Progress;
use antiradiance::reference::{self, ReferenceOptions};
use antiradiance::scene::{self, Scene};
use antiradiance::solve::solution::Solution;
use antiradiance::solve::{SolverKind, SolverOptions};

// ---------------------------------------------------------------------------------------------
// Checks done before any work

/// Checks a camera the way the renderer will (size, field of view, exposure, eye and target), so
/// a bad picture option fails before the solve rather than after it.
pub fn check_camera(camera: &CameraOptions) -> Result<()> {
    camera.validate()
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
pub(crate) fn resolved(path: &Path) -> PathBuf {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match (dir.canonicalize(), path.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => path.to_path_buf(),
    }
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
    let mut scene = timed(&mut timings.load, || {
        scene::load_scene(&args.scene, &args.options())
    })?;
    scene
        .lights
        .extend(args.lights.iter().chain(&args.sky).copied());
    if !scene.lights.is_empty() {
        // Lit by `--light` or `--sky`: the file's lack of emitters is no longer a finding.
        scene
            .warnings
            .retain(|w| w.kind != antiradiance::error::WarningKind::NoEmitter);
    }
    if args.two_sided {
        scene.set_two_sided();
    }
    for name in &args.two_sided_materials {
        scene.set_two_sided_material(name)?;
    }
    for w in &scene.warnings {
        print_warning(w);
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

/// Stage 4 for the antiradiance solvers ([`antiradiance::solve::run`]), with a progress bar
/// unless `quiet`. Precondition: `options.validate()` passed.
pub fn run_solver(
    kind: SolverKind,
    patches: &Patches,
    options: &SolverOptions,
    quiet: bool,
) -> Result<Solution> {
    let progress = Progress::new(kind.name(), options.max_iterations as u64, !quiet);
    let solution = antiradiance::solve::run(kind, patches, options, &progress);
    progress.finish();
    solution
}

/// Stage 4 for the path tracer, with a progress bar unless `quiet`.
pub fn run_reference(patches: &Patches, options: &ReferenceOptions, quiet: bool) -> Solution {
    let progress = Progress::new("reference", patches.len() as u64, !quiet);
    let solution = reference::solve_reference(patches, options, &progress);
    progress.finish();
    solution
}

/// Stage 5 without the report: picture, PLY, CSV, binary glTF (each atomic). Preconditions:
/// `output.validate()` passed and `solution` belongs to `loaded`.
pub fn write_outputs(output: &OutputArgs, loaded: &Loaded, solution: &Solution) -> Result<()> {
    let camera = output.camera_for(&loaded.scene);
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
    if let Some(path) = &output.elements {
        output::write_elements_csv(path, &loaded.patches, solution)?;
    }
    if let Some(path) = &output.gltf {
        let exposure = output
            .exposure
            .unwrap_or_else(|| render::auto_exposure(&loaded.patches, solution));
        output::write_baked_glb(path, &loaded.scene, &loaded.patches, solution, exposure)?;
    }
    Ok(())
}

pub use crate::cli::args::*;
pub use crate::cli::commands::*;
pub use crate::cli::report::*;
pub use crate::cli::text::*;

#[cfg(test)]
mod tests {
    use super::*;
    use antiradiance::solve::Preset;
    use glam::DVec3;

    #[test]
    fn patch_count_matches_build_patches() {
        let scene = antiradiance::scene::generated::occluder_scene();
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
