//! The coloured PLY mesh of a solution.

use std::io::Write;
use std::path::Path;

use crate::error::Result;
use crate::files::{format_f64, write_atomic};
use crate::mesh::Patches;
use crate::output::render;
use crate::solve::solution::{sanitize, Solution};

/// Writes the patches as a coloured triangle mesh in ASCII PLY (opens in MeshLab and Blender).
///
/// Vertices are in WORLD coordinates (`patches.frame.world_from_unit`), as doubles, with
/// per-vertex `red green blue` (uchar): [`render::tone_map`] at `exposure` of the area-weighted
/// mean B of the faces sharing the vertex. Corners are welded where positions are identical,
/// the faces have normals within 30 degrees of each other and the same emitter status (so
/// colours stay sharp across creases and around lights); degenerate patches keep their own
/// three vertices. Each patch becomes one face, in patch order (degenerate ones included), with
/// float properties `radiance_r radiance_g radiance_b` = the raw B (W / (m^2 sr); non-finite
/// written as 0, beyond the f32 range clamped to it).
///
/// `exposure` multiplies B before tone mapping (see [`render::auto_exposure`]); a non-finite
/// or non-positive value is an [`crate::Error::Parameter`].
/// Precondition: `solution.patch_radiance.len() == patches.len()` (an error otherwise).
pub fn write_ply(path: &Path, patches: &Patches, solution: &Solution, exposure: f64) -> Result<()> {
    super::check_per_patch(path, patches, solution, exposure)?;
    let welded = render::weld(patches, solution);
    write_atomic(path, |w| {
        writeln!(w, "ply")?;
        writeln!(w, "format ascii 1.0")?;
        writeln!(
            w,
            "comment antiradiance: world coordinates; vertex colour = tone-mapped B (exposure {}); face radiance_* = raw B in W/(m^2 sr)",
            format_f64(exposure)
        )?;
        writeln!(w, "element vertex {}", welded.positions.len())?;
        for axis in ["x", "y", "z"] {
            writeln!(w, "property double {axis}")?;
        }
        for channel in ["red", "green", "blue"] {
            writeln!(w, "property uchar {channel}")?;
        }
        writeln!(w, "element face {}", patches.len())?;
        writeln!(w, "property list uchar int vertex_indices")?;
        for channel in ["r", "g", "b"] {
            writeln!(w, "property float radiance_{channel}")?;
        }
        writeln!(w, "end_header")?;
        for (v, p) in welded.positions.iter().enumerate() {
            let world = patches.frame.world_from_unit(*p);
            let [r, g, b] = render::tone_map(welded.radiance[v], exposure);
            writeln!(
                w,
                "{} {} {} {r} {g} {b}",
                format_f64(world.x),
                format_f64(world.y),
                format_f64(world.z)
            )?;
        }
        for (p, corners) in welded.faces.iter().enumerate() {
            let b = solution.patch_radiance[p].map(to_f32);
            writeln!(
                w,
                "3 {} {} {} {} {} {}",
                corners[0], corners[1], corners[2], b[0], b[1], b[2]
            )?;
        }
        Ok(())
    })
}

/// An f64 as a finite f32 (non-finite becomes 0, out of range clamps to the f32 range).
fn to_f32(x: f64) -> f32 {
    sanitize(x).clamp(f32::MIN as f64, f32::MAX as f64) as f32
}
