//! Stage 2: turn input triangles into the solver's patches, in a normalized frame.
//!
//! The solver never sees the scene's own units: positions are moved to a frame centred on the
//! scene's bounds and scaled to unit diameter (`unit_from_world`), and emission is divided by its
//! largest value. Both are exact symmetries of the model (radiance is scale invariant and the
//! equations are linear in E), so the answer does not depend on where, how large or how bright
//! the scene is, and f32 storage neither overflows nor underflows.

pub mod closed;
pub mod lights;
pub mod overlap;

use glam::DVec3;

use crate::error::{Error, Result};
use crate::geometry::{self, Tri};
use crate::scene::Scene;

/// Spacing of the grid unit-frame coordinates are rounded to (2^-36, about 1.5e-11 of the
/// scene's diameter, far below [`crate::geometry::SCENE_EPS`]).
pub const UNIT_FRAME_GRID: f64 = 1.0 / (1u64 << 36) as f64;

/// The similarity that maps world coordinates to the solver's unit frame.
#[derive(Clone, Copy, Debug, Default)]
pub struct UnitFrame {
    /// World-space centre of the scene's bounds.
    pub center: DVec3,
    /// Multiply world lengths by this to get unit-frame lengths (1 / diameter).
    pub scale: f64,
}

impl UnitFrame {
    /// Unit-frame position of a world-space point, on a grid of [`UNIT_FRAME_GRID`]: the same
    /// scene scaled or translated then lands on the same coordinates (the rounding of the map
    /// itself, about 1e-16, stays within one grid step, so the model's threshold decisions do
    /// not flip between copies of a scene).
    pub fn unit_from_world(&self, p: DVec3) -> DVec3 {
        let unit = (p - self.center) * self.scale;
        (unit / UNIT_FRAME_GRID).round() * UNIT_FRAME_GRID
    }

    /// World-space position of a unit-frame point.
    pub fn world_from_unit(&self, p: DVec3) -> DVec3 {
        p / self.scale + self.center
    }
}

/// The solver's elements: input triangles, optionally split so no edge exceeds `max_edge`.
#[derive(Clone, Debug, Default)]
pub struct Patches {
    /// Corners in the unit frame, counter-clockwise = front.
    pub corners: Vec<Tri>,
    /// Unit normal (zero for degenerate patches).
    pub normal: Vec<DVec3>,
    /// Area in the unit frame.
    pub area: Vec<f64>,
    /// Centroid in the unit frame.
    pub centroid: Vec<DVec3>,
    /// Input triangle each patch comes from.
    pub parent: Vec<u32>,
    /// Albedo, RGB in [0, 1).
    pub albedo: Vec<[f64; 3]>,
    /// Emitted radiance divided by `emission_scale`, RGB.
    pub emission: Vec<[f64; 3]>,
    /// False for zero-area patches: they take no part in transport and keep B = E.
    pub active: Vec<bool>,
    /// World <-> unit frame map.
    pub frame: UnitFrame,
    /// The largest emitted radiance of the scene (1 when nothing emits); multiply B by it.
    pub emission_scale: f64,
    /// First patch of each input triangle; patches of triangle t are `first[t]..first[t + 1]`.
    pub first: Vec<u32>,
    /// Per input triangle, the earlier triangle it duplicates ([`Scene::duplicates`]): its
    /// patches are inactive and it takes that triangle's radiance.
    pub twin: Vec<Option<u32>>,
    /// Per input triangle, the earlier triangle whose back face it is
    /// ([`Scene::back_to_back_twins`]): its patches are inactive, the earlier triangle is
    /// two-sided, and it is reported with that triangle's back face (and its back with the
    /// triangle's front).
    pub back_twin: Vec<Option<u32>>,
    /// Per patch, the reflected direct radiance of the scene's analytic lights
    /// ([`lights::direct_source`], normalized like `emission`): a source the solvers add
    /// to the emission. Empty when the scene has no analytic light.
    pub source: Vec<[f64; 3]>,
    /// The scene's analytic lights in the unit frame, normalized like `emission` (what the
    /// reference path tracer samples). Empty when there are none.
    pub lights: Vec<crate::scene::lights::Light>,
    /// Per patch: two-sided ([`Scene::two_sided`]): it emits and reflects on both faces, each
    /// with its own radiance, and blocks light arriving at either. May be shorter than the
    /// patch list (missing entries mean one-sided); see [`Patches::is_two_sided`].
    pub two_sided: Vec<bool>,
    /// Per patch, the reflected direct radiance of the analytic lights on its back face (as
    /// `source`; 0 for one-sided patches). Empty when there is no analytic light or no
    /// two-sided patch.
    pub source_back: Vec<[f64; 3]>,
    /// Per patch, the share of its area that shows where coplanar patches facing the same way
    /// overlap it ([`overlap::visible_shares`]): what it sends (radiance, antiradiance,
    /// emission) is weighed by it. Empty when no patch overlaps another (every share 1); see
    /// [`Patches::visible_share`].
    pub visible_shares: Vec<f64>,
    /// The ray BVH of these patches, once a ray scene was made of them
    /// ([`crate::geometry::raytrace::RayScene::of`]); clones share it.
    pub ray_cache: crate::geometry::raytrace::RayCache,
}

impl Patches {
    /// Number of patches.
    pub fn len(&self) -> usize {
        self.corners.len()
    }

    /// True when there are no patches.
    pub fn is_empty(&self) -> bool {
        self.corners.is_empty()
    }

    /// True when patch `p` is two-sided and active (an inactive patch has no faces to solve).
    pub fn is_two_sided(&self, p: usize) -> bool {
        self.active[p] && self.two_sided.get(p).copied().unwrap_or(false)
    }

    /// The share of patch `p`'s area that shows (its entry of [`Patches::visible_shares`], 1
    /// when that list is empty): in (0, 1].
    pub fn visible_share(&self, p: usize) -> f64 {
        self.visible_shares.get(p).copied().unwrap_or(1.0)
    }

    /// True when patch `p` emits in some channel (its normalized emission is above 0).
    pub fn is_emitter(&self, p: usize) -> bool {
        self.emission[p].iter().any(|&e| e > 0.0)
    }

    /// True when some active patch is two-sided.
    pub fn has_two_sided(&self) -> bool {
        (0..self.len()).any(|p| self.is_two_sided(p))
    }

    /// True when no patch emits and the scene has no analytic light: the radiance is 0
    /// everywhere.
    pub fn is_dark(&self) -> bool {
        self.lights.is_empty() && self.emission.iter().all(|e| *e == [0.0; 3])
    }

    /// Turns patch `p` around: corners reversed, normal negated, and its back face's analytic
    /// source (`source_back`, 0 when none) made its front's. Its albedo and emission stay.
    pub fn turn_around(&mut self, p: usize) {
        let [a, b, c] = self.corners[p];
        self.corners[p] = [a, c, b];
        self.normal[p] = -self.normal[p];
        let back = self.source_back.get(p).copied().unwrap_or([0.0; 3]);
        if let Some(s) = self.source.get_mut(p) {
            *s = back;
        }
    }

    /// Makes patch `p` black and dark: albedo, emission and analytic source 0.
    pub fn blacken(&mut self, p: usize) {
        self.albedo[p] = [0.0; 3];
        self.emission[p] = [0.0; 3];
        if let Some(s) = self.source.get_mut(p) {
            *s = [0.0; 3];
        }
    }

    /// Empties `two_sided` and `source_back` when no patch is two-sided any more (after some
    /// were made one-sided).
    pub fn forget_two_sided_if_none(&mut self) {
        if self.two_sided.iter().all(|&t| !t) {
            self.two_sided = Vec::new();
            self.source_back = Vec::new();
        }
    }

    /// These patches with every two-sided patch's back face appended as a one-sided patch of
    /// its own (corners reversed, after the last patch; the pair covers each other's backs),
    /// and per patch the index of its back face's patch. Input triangles keep their patches
    /// (`first`), so the appended ones are outside every triangle's range.
    pub fn with_back_faces(&self) -> (Patches, Vec<Option<usize>>) {
        let mut out = self.clone();
        out.two_sided = Vec::new();
        out.source_back = Vec::new();
        let has_source = !self.source.is_empty();
        let mut back_of = vec![None; self.len()];
        for p in (0..self.len()).filter(|&p| self.is_two_sided(p)) {
            let [a, b, c] = self.corners[p];
            back_of[p] = Some(out.len());
            out.push(
                [a, c, b],
                self.parent[p],
                self.albedo[p],
                self.emission[p],
                true,
            );
            if has_source {
                out.source
                    .push(self.source_back.get(p).copied().unwrap_or([0.0; 3]));
            }
        }
        (out, back_of)
    }

    /// Appends one patch; `corners` in the unit frame.
    pub fn push(
        &mut self,
        corners: Tri,
        parent: u32,
        albedo: [f64; 3],
        emission: [f64; 3],
        active: bool,
    ) {
        let n = geometry::normal(&corners);
        let active = active && n.is_some();
        self.corners.push(corners);
        self.normal.push(n.unwrap_or(DVec3::ZERO));
        self.area.push(if active {
            geometry::area(&corners)
        } else {
            0.0
        });
        self.centroid.push(geometry::centroid(&corners));
        self.parent.push(parent);
        self.albedo.push(albedo);
        self.emission.push(emission);
        self.active.push(active);
    }

    /// Per-input-triangle values from per-patch values: the area-weighted mean of each triangle's
    /// patches (a triangle whose patches all have zero area takes its first patch's value; a
    /// duplicate takes the value of the triangle it repeats, see [`Patches::twin`]).
    pub fn to_input(&self, per_patch: &[[f64; 3]]) -> Vec<[f64; 3]> {
        (0..self.first.len() - 1)
            .map(|t| {
                let t = self
                    .twin
                    .get(t)
                    .copied()
                    .flatten()
                    .map_or(t, |u| u as usize);
                let range = self.first[t] as usize..self.first[t + 1] as usize;
                let total: f64 = range.clone().map(|p| self.area[p]).sum();
                if total > 0.0 {
                    let mut acc = [0.0; 3];
                    for p in range {
                        for c in 0..3 {
                            acc[c] += self.area[p] * per_patch[p][c];
                        }
                    }
                    acc.map(|x| x / total)
                } else {
                    per_patch[range.start]
                }
            })
            .collect()
    }

    /// The solvers' source per patch: the emission plus the analytic lights' reflected direct
    /// radiance ([`Patches::source`]), normalized units.
    pub fn emission_and_source(&self) -> Vec<[f64; 3]> {
        let mut e = self.emission.clone();
        for (e, s) in e.iter_mut().zip(&self.source) {
            for c in 0..3 {
                e[c] += s[c];
            }
        }
        e
    }

    /// The emission of the back faces: a two-sided patch emits from both faces; one-sided
    /// patches get 0.
    pub fn emission_back(&self) -> Vec<[f64; 3]> {
        (0..self.len())
            .map(|p| {
                if self.is_two_sided(p) {
                    self.emission[p]
                } else {
                    [0.0; 3]
                }
            })
            .collect()
    }

    /// Number of active (non-degenerate) patches.
    pub fn active_count(&self) -> usize {
        self.active.iter().filter(|&&a| a).count()
    }
}

pub use crate::scene::MAX_PATCHES;

/// The area-weighted mean per patch of values given per element (a piece of a patch the
/// solver works on: `(patch, area, value)`), summed in the order given; `None` for a patch
/// without elements of positive total area. The one element-to-patch average of the solvers.
pub fn patch_means(
    patch_count: usize,
    elements: impl IntoIterator<Item = (usize, f64, [f64; 3])>,
) -> Vec<Option<[f64; 3]>> {
    let mut sum = vec![[0.0f64; 3]; patch_count];
    let mut area = vec![0.0f64; patch_count];
    for (p, a, b) in elements {
        area[p] += a;
        for c in 0..3 {
            sum[p][c] += a * b[c];
        }
    }
    (0..patch_count)
        .map(|p| (area[p] > 0.0).then(|| sum[p].map(|x| x / area[p])))
        .collect()
}

/// The split of one input triangle (world corners): [`build_patches`] cuts it into k*k pieces,
/// k = ceil(longest edge / max_edge) in 1..=1024; 1 for a degenerate triangle and for a
/// `max_edge` that is `None`, not positive or not finite.
pub fn split_factor(world: &Tri, degenerate: bool, max_edge: Option<f64>) -> u64 {
    match max_edge {
        Some(l) if l > 0.0 && l.is_finite() && !degenerate => (geometry::longest_edge(world) / l)
            .ceil()
            .clamp(1.0, 1024.0)
            as u64,
        _ => 1,
    }
}

/// Number of patches [`build_patches`] makes from `scene` with `max_edge`, without making them.
pub fn patch_count(scene: &Scene, max_edge: Option<f64>) -> u64 {
    (0..scene.len())
        .map(|t| split_factor(&scene.corners(t), scene.is_degenerate(t), max_edge).pow(2))
        .sum()
}

/// Checks what [`build_patches`] assumes of a scene: triangles, every per-triangle array
/// as long as the triangle list, vertex indices in range, finite vertices.
pub fn check_scene(scene: &Scene) -> Result<()> {
    let fail = |message: String| Error::Scene {
        path: scene.path.clone(),
        message,
    };
    if scene.is_empty() {
        return Err(fail("no triangles".into()));
    }
    if scene.albedo.len() != scene.len() || scene.emission.len() != scene.len() {
        return Err(fail(format!(
            "{} triangles but {} albedo and {} emission values",
            scene.len(),
            scene.albedo.len(),
            scene.emission.len()
        )));
    }
    for (t, tri) in scene.triangles.iter().enumerate() {
        if tri.iter().any(|&v| v as usize >= scene.positions.len()) {
            return Err(fail(format!(
                "triangle {t} has a vertex index out of range"
            )));
        }
        if !scene.corners(t).iter().all(|p| p.is_finite()) {
            return Err(fail(format!("triangle {t} has a non-finite vertex")));
        }
    }
    Ok(())
}

/// [`build_patches`] after checking what it assumes: the scene ([`check_scene`]), a `max_edge`
/// that is `None` or a positive finite length, and at most [`MAX_PATCHES`] patches (unless the
/// scene has more triangles than that to begin with).
pub fn checked_patches(scene: &Scene, max_edge: Option<f64>) -> Result<Patches> {
    check_scene(scene)?;
    if let Some(l) = max_edge {
        if !(l.is_finite() && l > 0.0) {
            return Err(Error::Parameter(format!(
                "max edge {l} must be finite and > 0"
            )));
        }
    }
    let count = patch_count(scene, max_edge);
    if count > MAX_PATCHES && count > scene.len() as u64 {
        return Err(Error::Parameter(format!(
            "max edge {} would split the scene into {count} patches (at most {MAX_PATCHES})",
            max_edge.unwrap_or(0.0),
        )));
    }
    Ok(build_patches(scene, max_edge))
}

/// Builds the patches of a scene. Each input triangle whose longest edge exceeds `max_edge`
/// (world units) is split into k*k congruent pieces, k = ceil(longest / max_edge).
///
/// A triangle that repeats an earlier one ([`Scene::duplicates`]) gets inactive patches (it
/// takes no part in transport, so the surface counts once) and is reported with the radiance of
/// the triangle it repeats.
///
/// Preconditions: the scene has at least one triangle and finite coordinates (as `load_obj`
/// guarantees); a non-positive or non-finite `max_edge` means no splitting.
pub fn build_patches(scene: &Scene, max_edge: Option<f64>) -> Patches {
    let (lo, hi) = scene.bounds();
    let diameter = (hi - lo).length();
    let scale = if diameter > 0.0 && diameter.is_finite() {
        1.0 / diameter
    } else {
        1.0
    };
    let frame = UnitFrame {
        center: (lo + hi) * 0.5,
        scale,
    };
    let emission_max = scene
        .emission
        .iter()
        .flat_map(|e| e.iter().copied())
        .fold(0.0f64, f64::max);
    let emission_scale = if emission_max > 0.0 {
        emission_max
    } else {
        1.0
    };

    let twin = scene.duplicates();
    let mut patches = Patches {
        frame,
        emission_scale,
        back_twin: scene.back_to_back_twins_given(&twin),
        twin,
        ..Patches::default()
    };
    let mut has_back_twin = vec![false; scene.len()];
    for &u in patches.back_twin.iter().flatten() {
        has_back_twin[u as usize] = true;
    }
    if max_edge.is_none() {
        // One patch per triangle: each array in parallel, as `push` would fill it.
        patches.whole_triangles(scene, &has_back_twin);
    } else {
        patches.split_triangles(scene, max_edge, &has_back_twin);
    }
    if !scene.lights.is_empty() {
        lights::attach(&mut patches, &scene.lights);
    }
    patches
}

impl Patches {
    /// [`build_patches`]'s patches when no triangle is split: patch `t` is triangle `t`.
    fn whole_triangles(&mut self, scene: &Scene, has_back_twin: &[bool]) {
        use rayon::prelude::*;
        let (frame, scale) = (self.frame, self.emission_scale);
        let n = scene.len();
        self.corners = (0..n)
            .into_par_iter()
            .map(|t| scene.corners(t).map(|p| frame.unit_from_world(p)))
            .collect();
        let normal: Vec<Option<DVec3>> = self.corners.par_iter().map(geometry::normal).collect();
        self.active = (0..n)
            .into_par_iter()
            .map(|t| {
                !scene.is_degenerate(t)
                    && self.twin[t].is_none()
                    && self.back_twin[t].is_none()
                    && normal[t].is_some()
            })
            .collect();
        self.normal = normal
            .par_iter()
            .map(|n| n.unwrap_or(DVec3::ZERO))
            .collect();
        self.area = (self.corners.par_iter().zip(&self.active))
            .map(|(c, &active)| if active { geometry::area(c) } else { 0.0 })
            .collect();
        self.centroid = self.corners.par_iter().map(geometry::centroid).collect();
        self.parent = (0..n as u32).collect();
        self.albedo = scene.albedo.clone();
        self.emission = scene
            .emission
            .par_iter()
            .map(|e| e.map(|e| e / scale))
            .collect();
        self.two_sided = (0..n)
            .into_par_iter()
            .map(|t| scene.is_two_sided(t) || has_back_twin[t])
            .collect();
        self.first = (0..=n as u32).collect();
    }

    /// [`build_patches`]'s patches, each triangle split by [`split_factor`] for `max_edge`.
    fn split_triangles(&mut self, scene: &Scene, max_edge: Option<f64>, has_back_twin: &[bool]) {
        let (frame, emission_scale) = (self.frame, self.emission_scale);
        let patches = self;
        for (t, &back_twinned) in has_back_twin.iter().enumerate() {
            patches.first.push(patches.len() as u32);
            let world = scene.corners(t);
            let unit: Tri = world.map(|p| frame.unit_from_world(p));
            let emission = scene.emission[t].map(|e| e / emission_scale);
            let degenerate = scene.is_degenerate(t);
            let active = !degenerate && patches.twin[t].is_none() && patches.back_twin[t].is_none();
            let k = split_factor(&world, degenerate, max_edge) as usize;
            let two_sided = scene.is_two_sided(t) || back_twinned;
            for piece in geometry::subdivide(&unit, k) {
                patches.push(piece, t as u32, scene.albedo[t], emission, active);
                patches.two_sided.push(two_sided);
            }
        }
        patches.first.push(patches.len() as u32);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Without `max_edge` every array is filled in parallel; with a `max_edge` no triangle
    /// reaches, one triangle at a time by `push`. Both must make the same patches, with a
    /// duplicate, a back-to-back twin, a degenerate and a two-sided triangle among them.
    #[test]
    fn whole_triangles_match_the_triangle_by_triangle_build() {
        let mut scene = crate::scene::generated::cornell_box();
        let [a, b, c] = scene.triangles[3];
        for tri in [[a, b, c], [a, c, b], [a, a, b]] {
            scene.triangles.push(tri);
            scene.albedo.push(scene.albedo[3]);
            scene.emission.push(scene.emission[3]);
        }
        scene.two_sided = vec![false, true];
        let whole = build_patches(&scene, None);
        let split = build_patches(&scene, Some(1e9));
        assert_eq!(whole.len(), scene.len());
        assert!(whole.twin.iter().any(Option::is_some));
        assert!(whole.back_twin.iter().any(Option::is_some));
        assert!(whole.active.iter().any(|a| !a));
        assert_eq!(whole.corners, split.corners);
        assert_eq!(whole.normal, split.normal);
        assert_eq!(whole.area, split.area);
        assert_eq!(whole.centroid, split.centroid);
        assert_eq!(whole.parent, split.parent);
        assert_eq!(whole.albedo, split.albedo);
        assert_eq!(whole.emission, split.emission);
        assert_eq!(whole.active, split.active);
        assert_eq!(whole.first, split.first);
        assert_eq!(whole.two_sided, split.two_sided);
    }
}
