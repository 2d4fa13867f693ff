//! `antiradiance scene`: writes generated scenes (OBJ + MTL) so that every scene a figure in the
//! documentation was measured on can be made again by a user.
//!
//! The geometry is built by [`antiradiance::scene::generated`] ([`generated::cornell_box`],
//! [`generated::subdivided_cornell_box`], [`generated::in_room`], [`generated::under_light`]) and
//! [`antiradiance::scene::interiors`] ([`interiors::classroom`], [`interiors::office`]) and written by
//! [`generated::write_obj`] (atomic, MTL file next to the OBJ file). Every light is a material with
//! `Ke`, so the written scenes solve with default options (no `--emit-above`).
//!
//! `scene variant` writes a mesh's geometry triangulated badly ([`variants::make_variant`],
//! [`variants::write_variant`]), with the mesh's own materials and a map back to its
//! triangles; the scene options that applied to the mesh apply to the variant.
//!
//! As in the other commands, every parameter and the output path are checked before the mesh is
//! loaded, a bad mesh gives the loader's one-line `file:line: message` error, and nothing is
//! written unless everything succeeded.

use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};

use crate::cli::driver::check_outputs;
use antiradiance::error::{Error, Result};
use antiradiance::mesh::MAX_PATCHES;
use antiradiance::scene::generated;
use antiradiance::scene::interiors;
use antiradiance::scene::variants::{self, VariantKind, VariantOptions};
use antiradiance::scene::{self, Scene, SceneOptions};

/// Arguments of `antiradiance scene`.
#[derive(Args, Clone, Debug)]
pub struct StageArgs {
    /// Which scene to write.
    #[command(subcommand)]
    pub kind: StageKind,
}

/// The scenes `antiradiance scene` can write.
#[derive(Subcommand, Clone, Debug)]
pub enum StageKind {
    /// The Cornell box (written as cornell_box.obj: byte for byte scenes/cornell_box.obj), or with --triangles N split
    /// uniformly into at least N triangles (46 k^2).
    CornellBox(CornellBoxArgs),
    /// A mesh standing on the floor of a closed box room (floor albedo 0.6, walls and ceiling
    /// 0.7) lit by a square area light in the ceiling; the mesh's triangles come first.
    InRoom(MeshArgs),
    /// A mesh as it is, with a rectangular area light above it facing down (half the mesh's
    /// footprint, 1.5 times its height above its top); the mesh's triangles come first.
    UnderLight(MeshArgs),
    /// The mesh's geometry triangulated badly (slivers, random, jittered, translated, back to
    /// back twins, T-junctions, huge beside tiny), with a map back to its triangles
    /// (OUT.map.csv); materials kept by name, the MTL file copied.
    Variant(VariantArgs),
    /// A CAD-like classroom (about 10k triangles): fan-triangulated walls with window openings,
    /// rows of desks and chairs, tube lights, 30% of the polygons reversed.
    Classroom(InteriorArgs),
    /// A CAD-like office: a window with an emissive sky pane behind Venetian blinds, a desk, a
    /// lamp, a bookshelf, large wall polygons beside small objects, 30% of the polygons reversed.
    Office(InteriorArgs),
}

/// The output file of every scene kind.
#[derive(Args, Clone, Debug)]
pub struct OutArgs {
    /// Scene file to write; the MTL file goes next to it (same name, extension .mtl). Both are
    /// written atomically. A name ending in .glb writes binary glTF instead.
    #[arg(long, value_name = "OUT.obj")]
    pub out: PathBuf,
    /// Print nothing but warnings and errors.
    #[arg(long)]
    pub quiet: bool,
}

/// Arguments of `antiradiance scene cornell-box`.
#[derive(Args, Clone, Debug)]
pub struct CornellBoxArgs {
    /// Split the box uniformly into the smallest 46 k^2 triangles >= N (growth measurements).
    #[arg(long, value_name = "N")]
    pub triangles: Option<u64>,
    /// The output file.
    #[command(flatten)]
    pub out: OutArgs,
}

/// Arguments of `antiradiance scene in-room` and `under-light`.
#[derive(Args, Clone, Debug)]
pub struct MeshArgs {
    /// The mesh: Wavefront OBJ, materials from the MTL files it names (kept as they are).
    #[arg(value_name = "MESH.obj")]
    pub mesh: PathBuf,
    /// Grey albedo in [0, 1) for the mesh's triangles whose material has no Kd.
    #[arg(
        long,
        value_name = "A",
        default_value_t = 0.75,
        allow_negative_numbers = true
    )]
    pub albedo: f64,
    /// Emitted radiance of the added light (grey, W/(m^2 sr), > 0).
    #[arg(
        long,
        value_name = "L",
        default_value_t = generated::DEFAULT_LIGHT_RADIANCE,
        allow_negative_numbers = true
    )]
    pub light_radiance: f64,
    /// The output file.
    #[command(flatten)]
    pub out: OutArgs,
}

/// Arguments of `antiradiance scene variant`.
#[derive(Args, Clone, Debug)]
pub struct VariantArgs {
    /// The kind of bad triangulation.
    #[arg(value_enum, value_name = "KIND")]
    pub kind: VariantKind,
    /// The mesh: Wavefront OBJ, materials from the MTL files it names (copied to the output).
    #[arg(value_name = "MESH.obj")]
    pub mesh: PathBuf,
    /// Seed of the random choices (random, jitter, tjunction).
    #[arg(long, value_name = "S", default_value_t = 1)]
    pub seed: u64,
    /// The kind's amount: fan slivers per triangle k (8), random interior points per
    /// triangle (3), jitter distance (1e-6), translation per axis (1e3), tjunction share of
    /// shared edges (0.3), huge-tiny tiny triangles (4000); twins takes none.
    #[arg(long, value_name = "X", allow_negative_numbers = true)]
    pub amount: Option<f64>,
    /// Grey albedo in [0, 1) for triangles whose material has no Kd (as for solve; it decides
    /// which triangles are the same material for huge-tiny; the output keeps the mesh's
    /// materials).
    #[arg(
        long,
        value_name = "A",
        default_value_t = 0.75,
        allow_negative_numbers = true
    )]
    pub albedo: f64,
    /// As for solve: triangles with all three vertices above Y emit. The output writes them
    /// as materials with their emission (`Ke`), so solve it without --emit-above (the rule
    /// applied to the variant's own triangles would select others: slivers of a wall).
    #[arg(long, value_name = "Y", allow_negative_numbers = true)]
    pub emit_above: Option<f64>,
    /// As for solve: the radiance of the --emit-above emitters.
    #[arg(
        long,
        value_name = "L",
        default_value_t = 1.0,
        allow_negative_numbers = true
    )]
    pub emission: f64,
    /// The output file; the map goes next to it (same name, extension .map.csv).
    #[command(flatten)]
    pub out: OutArgs,
}

/// Arguments of `antiradiance scene classroom` and `office`.
#[derive(Args, Clone, Debug)]
pub struct InteriorArgs {
    /// Seed of the reversed polygons and a few placements; the same seed gives the same file.
    #[arg(long, value_name = "S", default_value_t = 1)]
    pub seed: u64,
    /// The output file.
    #[command(flatten)]
    pub out: OutArgs,
}

/// The title of the shipped Cornell box file (`scenes/cornell_box.obj`), so that
/// `scene cornell-box` writes that file byte for byte.
pub const CORNELL_BOX_TITLE: &str = "Cornell box (Cornell University Program of Computer \
     Graphics geometry, mm), generated by antiradiance::scene::generated::cornell_box";

/// `antiradiance scene`: builds the requested scene and writes it to `--out` (OBJ) and the MTL
/// file next to it, then prints a one-line summary on stderr unless `--quiet`.
///
/// Preconditions: none (every argument is checked here). Errors: [`Error::Parameter`] for a bad
/// value (`--triangles` 0 or above [`MAX_PATCHES`], `--albedo` outside [0, 1),
/// `--light-radiance` not finite and > 0, `--out` ending in `.mtl`), [`Error::Io`] for an output
/// path that cannot be written (missing directory, a directory, the mesh itself), and every
/// error of [`scene::load_obj`] for the mesh (one line naming the file and line). Nothing is
/// written on error. The mesh's loader warnings are printed as `warning: ...` lines.
pub fn stage(args: &StageArgs) -> Result<()> {
    match &args.kind {
        StageKind::CornellBox(a) => {
            check_out(&a.out.out, None)?;
            let (scene, title) = match a.triangles {
                None => (generated::cornell_box(), CORNELL_BOX_TITLE.to_string()),
                Some(n) => {
                    if n == 0 || n > MAX_PATCHES {
                        return Err(Error::Parameter(format!(
                            "--triangles {n} must be between 1 and {MAX_PATCHES}"
                        )));
                    }
                    let scene = generated::subdivided_cornell_box(n as usize);
                    let title = format!(
                        "Cornell box split uniformly into {} triangles (at least {n}), mm; \
                         generated by `antiradiance scene cornell-box --triangles {n}` \
                         (antiradiance::scene::generated::subdivided_cornell_box)",
                        scene.len()
                    );
                    (scene, title)
                }
            };
            write(&scene, &a.out, &title, "")
        }
        StageKind::InRoom(a) => {
            let object = load_mesh(a)?;
            let room = generated::room_around(&object)?;
            let scene = generated::in_room(&object, a.light_radiance)?;
            let title = format!(
                "{} standing in a closed room, generated by `antiradiance scene in-room` \
                 (antiradiance {}; --albedo {} --light-radiance {})\n\
                 triangles 0..{} are the mesh's, then {} of the room: floor (albedo {}), \
                 ceiling, light (Ke {}), walls (albedo {})\n\
                 room {} .. {}, light {} .. {}",
                display_name(&a.mesh),
                env!("CARGO_PKG_VERSION"),
                a.albedo,
                a.light_radiance,
                object.len(),
                generated::ROOM_TRIANGLES,
                generated::ROOM_FLOOR_ALBEDO,
                a.light_radiance,
                generated::ROOM_WALL_ALBEDO,
                room.min,
                room.max,
                room.light_min,
                room.light_max,
            );
            let note = format!(
                " ({} of the mesh, {} of the room {} .. {})",
                object.len(),
                generated::ROOM_TRIANGLES,
                room.min,
                room.max
            );
            write(&scene, &a.out, &title, &note)
        }
        StageKind::UnderLight(a) => {
            let object = load_mesh(a)?;
            let (lo, hi) = generated::light_above(&object)?;
            let scene = generated::under_light(&object, a.light_radiance)?;
            let title = format!(
                "{} under a rectangular area light, generated by `antiradiance scene \
                 under-light` (antiradiance {}; --albedo {} --light-radiance {})\n\
                 triangles 0..{} are the mesh's, then {} of the light (facing down, Ke {}) \
                 {} .. {}",
                display_name(&a.mesh),
                env!("CARGO_PKG_VERSION"),
                a.albedo,
                a.light_radiance,
                object.len(),
                generated::LIGHT_TRIANGLES,
                a.light_radiance,
                lo,
                hi,
            );
            let note = format!(
                " ({} of the mesh, {} of the light {} .. {})",
                object.len(),
                generated::LIGHT_TRIANGLES,
                lo,
                hi
            );
            write(&scene, &a.out, &title, &note)
        }
        StageKind::Variant(a) => variant(a),
        StageKind::Classroom(a) | StageKind::Office(a) => {
            check_out(&a.out.out, None)?;
            let (interior, what) = if matches!(args.kind, StageKind::Classroom(_)) {
                (interiors::classroom(a.seed), "classroom")
            } else {
                (interiors::office(a.seed), "office")
            };
            let title = format!(
                "CAD-like {what} (m, y up), generated by `antiradiance scene {what} --seed {}` \
                 (antiradiance::interiors::{what})\n\
                 {} polygons fan-triangulated from their first vertex, {} of them reversed",
                a.seed, interior.polygons, interior.reversed_polygons
            );
            let note = format!(
                " ({} polygons, {} reversed)",
                interior.polygons, interior.reversed_polygons
            );
            write(&interior.scene, &a.out, &title, &note)
        }
    }
}

/// `antiradiance scene variant`: checks the arguments, loads the mesh, builds the variant and
/// writes it with its map and the mesh's materials.
fn variant(a: &VariantArgs) -> Result<()> {
    let options = SceneOptions {
        default_albedo: a.albedo,
        emit_above: a.emit_above,
        emission: a.emission,
    };
    options.validate()?;
    let out = &a.out.out;
    let map = variants::map_path(out);
    check_out(out, Some(&a.mesh))?;
    check_outputs(&[("--out's map file", &map)], &a.mesh)?;
    let variant_options = VariantOptions {
        seed: a.seed,
        amount: a.amount,
    };
    variants::resolve_amount(a.kind, a.amount)?;
    let scene = scene::load_obj(&a.mesh, &options)?;
    // The mesh may well be lit by --emit-above only when it is solved.
    for w in scene
        .warnings
        .iter()
        .filter(|w| !w.contains("no emitting triangle"))
    {
        crate::cli::driver::print_warning(w);
    }
    // The output's MTL file must not replace one the mesh reads.
    let out_mtl = out.with_extension("mtl");
    let same = |p: &Path| match (p.canonicalize(), out_mtl.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if let Some(p) = variants::material_files(&a.mesh)?.iter().find(|p| same(p)) {
        return Err(Error::Io {
            path: out_mtl.clone(),
            message: format!(
                "--out's MTL file would overwrite {}, a material file of the mesh",
                p.display()
            ),
        });
    }
    let mtl = variants::material_text(&a.mesh)?;
    let variant = variants::make_variant(&scene, a.kind, &variant_options)?;
    let title = format!(
        "{} as the {} variant, generated by `antiradiance scene variant {} --seed {}{}` \
         (antiradiance {})\n{}\n\
         every triangle's input triangles: {}",
        display_name(&a.mesh),
        a.kind.name(),
        a.kind.name(),
        a.seed,
        variant
            .amount
            .map(|x| format!(" --amount {x}"))
            .unwrap_or_default(),
        env!("CARGO_PKG_VERSION"),
        variant.note,
        map.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
    );
    variants::write_variant(&variant, out, &mtl, &title, a.emit_above.is_some())?;
    if !a.out.quiet {
        eprintln!(
            "wrote {}, {} and {}: {} triangles from {} ({})",
            out.display(),
            out.with_extension("mtl").display(),
            map.display(),
            variant.scene.len(),
            scene.len(),
            variant.note
        );
    }
    Ok(())
}

/// The mesh's file name, for titles (the same whatever directory the command ran from).
fn display_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

/// Checks `--out` (and the MTL path next to it) against each other and the input mesh.
fn check_out(out: &Path, mesh: Option<&Path>) -> Result<()> {
    let mtl = out.with_extension("mtl");
    if mtl == out {
        return Err(Error::Io {
            path: out.to_path_buf(),
            message: "--out must not end in .mtl (the MTL file is written next to it)".into(),
        });
    }
    check_outputs(
        &[("--out", out), ("--out's MTL file", &mtl)],
        mesh.unwrap_or(Path::new("")),
    )
}

/// Checks every argument, then loads the mesh and prints its warnings.
fn load_mesh(args: &MeshArgs) -> Result<Scene> {
    let options = SceneOptions {
        default_albedo: args.albedo,
        ..SceneOptions::default()
    };
    options.validate()?;
    if !(args.light_radiance.is_finite() && args.light_radiance > 0.0) {
        return Err(Error::Parameter(format!(
            "--light-radiance {} must be finite and > 0",
            args.light_radiance
        )));
    }
    check_out(&args.out.out, Some(&args.mesh))?;
    let object = scene::load_obj(&args.mesh, &options)?;
    // The mesh alone may well have no emitter: the light added here is the scene's.
    for w in object
        .warnings
        .iter()
        .filter(|w| !w.contains("no emitting triangle"))
    {
        crate::cli::driver::print_warning(w);
    }
    Ok(object)
}

/// Writes the scene and prints the summary.
fn write(scene: &Scene, out: &OutArgs, title: &str, note: &str) -> Result<()> {
    if antiradiance::scene::gltf::is_gltf(&out.out) {
        antiradiance::output::gltf::write_scene_glb(&out.out, scene)?;
        if !out.quiet {
            eprintln!(
                "wrote {}: {} triangles{note}, {} emitting",
                out.out.display(),
                scene.len(),
                scene.emitter_count()
            );
        }
        return Ok(());
    }
    generated::write_obj(scene, &out.out, title)?;
    if !out.quiet {
        eprintln!(
            "wrote {} and {}: {} triangles{note}, {} emitting",
            out.out.display(),
            out.out.with_extension("mtl").display(),
            scene.len(),
            scene.emitter_count(),
        );
    }
    Ok(())
}
