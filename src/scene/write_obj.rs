//! The OBJ + MTL writer of generated scenes (atomic, materials kept by name, lights as `Ke`).

use crate::error::{Error, Result};
use crate::files::write_atomic;
use crate::scene::Scene;
use glam::DVec3;
use std::collections::{HashMap, HashSet};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Writes `scene` as an OBJ file at `obj_path` plus an MTL file next to it (same name, extension
/// `mtl`), so that [`crate::scene::load_obj`] with default options gives back the same triangles
/// in the same order with the same albedo and emission.
///
/// Vertices are shared between triangles where their coordinates are bit-identical; numbers are
/// written in Rust's shortest round-trip form, so they read back exactly. There is one material
/// per distinct (material name, albedo, emission), each with a `Kd` and a `Ke` line, and
/// `usemtl` switches wherever the material changes. A material is named after the scene's own
/// material name ([`Scene::material_name`]; whitespace and `#` become `_`) and `m0`, `m1`, ...
/// (its position in order of first use) when the triangle has none; a name already taken by an
/// earlier material gets a suffix `_2`, `_3`, ... `title` becomes comment lines at the top of
/// both files. The output depends only on the scene and the title.
///
/// Each file is written atomically (a temporary file in the same directory, renamed once
/// complete), the MTL file first: a failure leaves no partial file, and when the OBJ file
/// cannot be written an MTL file this call created is removed again.
///
/// Errors: [`Error::Parameter`] for an empty scene, a non-finite vertex, albedo outside [0, 1),
/// negative or non-finite emission, or an `obj_path` without a file name or ending in `.mtl`;
/// [`Error::Io`] (one line naming the file) when a file cannot be written.
pub fn write_obj(scene: &Scene, obj_path: &Path, title: &str) -> Result<()> {
    check_writable(scene)?;
    let (mtl_path, mtl_name) = mtl_file(obj_path)?;
    let mut header = String::new();
    for line in title.lines() {
        let _ = writeln!(header, "# {line}");
    }
    let materials = Materials::of(scene);
    let (vertices, faces) = shared_vertices(scene);
    let mtl = mtl_text(scene, &header, &materials);
    let obj = obj_text(scene, header, &mtl_name, &materials, &vertices, &faces);

    let mtl_existed = mtl_path.exists();
    write_atomic(&mtl_path, |w| w.write_all(mtl.as_bytes()))?;
    if let Err(e) = write_atomic(obj_path, |w| w.write_all(obj.as_bytes())) {
        if !mtl_existed {
            let _ = std::fs::remove_file(&mtl_path);
        }
        return Err(e);
    }
    Ok(())
}

/// The checks of [`write_obj`] on the scene: not empty, one albedo and emission per triangle,
/// vertex indices in range, finite vertices, albedo in [0, 1), emission finite and >= 0.
fn check_writable(scene: &Scene) -> Result<()> {
    if scene.is_empty() {
        return Err(Error::Parameter(
            "write_obj: the scene has no triangles".into(),
        ));
    }
    if scene.albedo.len() != scene.len() || scene.emission.len() != scene.len() {
        return Err(Error::Parameter(
            "write_obj: albedo or emission count differs from the triangle count".into(),
        ));
    }
    for t in 0..scene.len() {
        if scene.triangles[t]
            .iter()
            .any(|&i| i as usize >= scene.positions.len())
        {
            return Err(Error::Parameter(format!(
                "write_obj: triangle {t} has a vertex index out of range"
            )));
        }
        if !scene.corners(t).iter().all(|p| p.is_finite()) {
            return Err(Error::Parameter(format!(
                "write_obj: triangle {t} has a non-finite vertex"
            )));
        }
        if !scene.albedo[t].iter().all(|&x| (0.0..1.0).contains(&x)) {
            return Err(Error::Parameter(format!(
                "write_obj: triangle {t} has albedo {:?} outside [0, 1)",
                scene.albedo[t]
            )));
        }
        if !scene.emission[t].iter().all(|&x| x.is_finite() && x >= 0.0) {
            return Err(Error::Parameter(format!(
                "write_obj: triangle {t} has emission {:?} (must be finite and >= 0)",
                scene.emission[t]
            )));
        }
    }
    Ok(())
}

/// The MTL file next to `obj_path` (same name, extension `mtl`) and its name as the OBJ file's
/// `mtllib` line gives it.
fn mtl_file(obj_path: &Path) -> Result<(PathBuf, String)> {
    let file_name = obj_path
        .file_name()
        .ok_or_else(|| {
            Error::Parameter(format!(
                "write_obj: {} has no file name",
                obj_path.display()
            ))
        })?
        .to_string_lossy()
        .into_owned();
    let mtl_path = obj_path.with_extension("mtl");
    if mtl_path == obj_path {
        return Err(Error::Parameter(format!(
            "write_obj: {} would be overwritten by its own MTL file",
            obj_path.display()
        )));
    }
    let mtl_name = mtl_path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| format!("{file_name}.mtl"));
    Ok((mtl_path, mtl_name))
}

/// The written materials: one per distinct (material name, albedo, emission), in order of
/// first use.
struct Materials {
    /// The first triangle using each material.
    first: Vec<usize>,
    /// Each material's name in the files, unique.
    names: Vec<String>,
    /// Each triangle's material.
    of_triangle: Vec<usize>,
}

impl Materials {
    fn of(scene: &Scene) -> Materials {
        type Key<'a> = (Option<&'a str>, [u64; 6]);
        let key = |t: usize| -> Key {
            let (a, e) = (scene.albedo[t], scene.emission[t]);
            (
                scene.material_name(t),
                [a[0], a[1], a[2], e[0], e[1], e[2]].map(f64::to_bits),
            )
        };
        let mut material_of: HashMap<Key, usize> = HashMap::new();
        let mut first: Vec<usize> = Vec::new();
        let mut of_triangle = Vec::with_capacity(scene.len());
        for t in 0..scene.len() {
            let m = *material_of.entry(key(t)).or_insert_with(|| {
                first.push(t);
                first.len() - 1
            });
            of_triangle.push(m);
        }
        let mut taken = HashSet::new();
        let names: Vec<String> = first
            .iter()
            .enumerate()
            .map(|(m, &t)| {
                let base = scene
                    .material_name(t)
                    .map(|n| n.replace(|c: char| c.is_whitespace() || c == '#', "_"))
                    .filter(|n| !n.is_empty())
                    .unwrap_or_else(|| format!("m{m}"));
                let mut name = base.clone();
                let mut k = 2;
                while !taken.insert(name.clone()) {
                    name = format!("{base}_{k}");
                    k += 1;
                }
                name
            })
            .collect();
        Materials {
            first,
            names,
            of_triangle,
        }
    }
}

/// The vertices in order of first use, shared when bit-identical, and every triangle's face
/// (1-based vertex numbers).
fn shared_vertices(scene: &Scene) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let mut vertex_of: HashMap<[u64; 3], u32> = HashMap::new();
    let mut vertices: Vec<DVec3> = Vec::new();
    let mut faces: Vec<[u32; 3]> = Vec::with_capacity(scene.len());
    for t in 0..scene.len() {
        let face = scene.corners(t).map(|p| {
            *vertex_of
                .entry(p.to_array().map(f64::to_bits))
                .or_insert_with(|| {
                    vertices.push(p);
                    vertices.len() as u32
                })
        });
        faces.push(face);
    }
    (vertices, faces)
}

/// The MTL file: `header`, then every material with its `Kd` and `Ke`.
fn mtl_text(scene: &Scene, header: &str, materials: &Materials) -> String {
    let mut mtl = header.to_string();
    let _ = writeln!(
        mtl,
        "# materials: {} (Kd = albedo, Ke = emitted radiance, RGB)",
        materials.first.len()
    );
    for (m, &t) in materials.first.iter().enumerate() {
        let (a, e) = (scene.albedo[t], scene.emission[t]);
        let _ = writeln!(mtl, "\nnewmtl {}", materials.names[m]);
        let _ = writeln!(mtl, "Kd {} {} {}", a[0], a[1], a[2]);
        let _ = writeln!(mtl, "Ke {} {} {}", e[0], e[1], e[2]);
    }
    mtl
}

/// The OBJ file: `header`, counts, the camera, `mtllib`, vertices, then the faces with a
/// `usemtl` wherever the material changes.
fn obj_text(
    scene: &Scene,
    header: String,
    mtl_name: &str,
    materials: &Materials,
    vertices: &[DVec3],
    faces: &[[u32; 3]],
) -> String {
    let mut obj = header;
    let _ = writeln!(
        obj,
        "# vertices: {}, triangles: {}, materials: {}",
        vertices.len(),
        faces.len(),
        materials.first.len()
    );
    if let Some(camera) = &scene.camera {
        let _ = writeln!(obj, "{}", camera.to_line());
    }
    let _ = writeln!(obj, "mtllib {mtl_name}");
    for p in vertices {
        let _ = writeln!(obj, "v {} {} {}", p.x, p.y, p.z);
    }
    let mut current = usize::MAX;
    for (t, f) in faces.iter().enumerate() {
        if materials.of_triangle[t] != current {
            current = materials.of_triangle[t];
            let _ = writeln!(obj, "usemtl {}", materials.names[current]);
        }
        let _ = writeln!(obj, "f {} {} {}", f[0], f[1], f[2]);
    }
    obj
}
