//! Closed objects turned outward: files as found orient their polygons at random, and a
//! closed object (a box, a chair leg) whose inside no light reaches is solved as if its faces
//! all faced out.
//!
//! A triangle of a closed object whose front faces the object's inside sees only the inside:
//! its front receives nothing, so its outgoing radiance is its emission, and its back, lit
//! from outside, absorbs and casts a shadow (a one-sided surface lit from behind). A triangle
//! facing out is a one-sided surface as usual. Solving the reversed triangle as it is given
//! costs a back-blocking surface and couplings among every pair of the object's faces, which
//! must cancel the light that the antiradiance method lets through the object; solving it
//! turned around, as a black one-sided surface facing out, gives the same answer with front-only
//! antiradiance, whose plane tests cull every pair within a convex object.
//!
//! An object is *closed* when every edge of its triangles (vertices matched exactly, as an
//! exporter shares them) joins exactly two of them, and their orientations can be made
//! consistent; its outside is the side its signed volume says. Its inside is *dark* when no
//! other object's emitting triangle and no point or spot light lies within its bounds
//! (conservatively: the bounds, not the volume). Objects with both one-sided and two-sided
//! triangles are left alone. A two-sided object's faces inside are dark too, so it is solved
//! one-sided, facing out, and its faces are put back after the solve.
//!
//! An object's own emitting triangles (a closed tube light) light its inside, but nothing
//! outside sees that light: a two-sided emitting tube is solved as a one-sided one facing out,
//! its faces inside reported with their emission. Such an object is left alone when its inside
//! is meant to be seen: a one-sided emitting triangle faces inside, the object encloses the
//! whole scene (a furnace), or another object's triangle lies within its bounds (a room whose
//! ceiling lights are part of its mesh). Solved as given, a two-sided tube's faces inside
//! filled it with light that antiradiance had to cancel everywhere outside it, and where the
//! exposure test gave them faces the generated classroom's two-sided solve came out 9% off.

use std::collections::HashMap;

use glam::DVec3;

use super::Patches;
use crate::scene::lights::Light;
use crate::union_find::UnionFind;

/// Smallest `|volume| / area^1.5` of a closed object that is turned outward: below it the
/// object is flat (two triangles back to back, a folded sheet) and has no inside to speak of.
/// A chair leg (radius 12 mm, 0.7 m) has 0.026, a slat 0.8 mm thick 0.002.
pub const MIN_VOLUME_RATIO: f64 = 1e-4;

/// Most (object, emitter) bound tests; above it no object is turned (the test is quadratic).
/// Objects with emitters of their own are tested against every patch, and left alone when
/// those tests number more.
const MAX_BOUND_TESTS: u64 = 100_000_000;

/// What [`Patches::closed_objects_outward`] changed.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Outward {
    /// Closed objects with a dark inside.
    pub objects: u64,
    /// Their patches that faced inward and are solved turned around.
    pub turned: u64,
    /// The turned patches that were two-sided: their solved front is their back face (see
    /// `Solution::restore_outward` in the solver).
    pub turned_two_sided: Vec<u32>,
    /// The two-sided emitting patches of those objects: their face inside is reported with
    /// its emission (what it sends into the object, where nothing outside sees it).
    pub emitting_inside: Vec<u32>,
}

impl Patches {
    /// These patches with every closed, dark object solved facing out, and what changed;
    /// `None` when nothing changes. See the [module](self) for what counts as closed and dark.
    ///
    /// - A one-sided object's inward-facing patches are turned around (corners reversed) and
    ///   made black (albedo and analytic source 0): their front radiance is their emission.
    /// - A two-sided object's patches become one-sided (their faces inside are dark), its
    ///   inward-facing ones turned around with their back face's analytic source; after the
    ///   solve `Solution::restore_outward` in the solver gives each its two faces back.
    pub fn closed_objects_outward(&self) -> Option<(Patches, Outward)> {
        let closed = closed_dark_objects(self);
        if closed.objects == 0 {
            return None;
        }
        let mut out = self.clone();
        let mut turned_two_sided = Vec::new();
        let mut emitting_inside = Vec::new();
        let mut turned = 0;
        for p in (0..self.len()).filter(|&p| closed.member[p]) {
            let two_sided = self.is_two_sided(p);
            if two_sided {
                out.two_sided[p] = false;
                if self.is_emitter(p) {
                    emitting_inside.push(p as u32);
                }
            }
            if !closed.turn[p] {
                continue;
            }
            turned += 1;
            out.turn_around(p);
            if two_sided {
                turned_two_sided.push(p as u32);
            } else {
                out.blacken(p);
            }
        }
        out.forget_two_sided_if_none();
        Some((
            out,
            Outward {
                objects: closed.objects,
                turned,
                turned_two_sided,
                emitting_inside,
            },
        ))
    }
}

/// The closed objects with a dark inside ([`closed_dark_objects`]).
#[derive(Clone, Debug, Default)]
pub struct Closed {
    /// Per patch: it belongs to such an object and its front faces inside.
    pub turn: Vec<bool>,
    /// Per patch: it belongs to such an object.
    pub member: Vec<bool>,
    /// The number of such objects.
    pub objects: u64,
}

/// The closed objects of `patches` whose inside is dark (see the [module](self)); objects
/// whose patches are all one-sided or all two-sided, never a mix.
pub fn closed_dark_objects(patches: &Patches) -> Closed {
    let (verts, edges) = edges_of(patches);
    let (root, mut open, joins) = join(patches, &verts, &edges);
    let (flip, members) = orient(patches.len(), &verts, &root, &mut open, &joins);
    let closed: Vec<&Vec<u32>> = members
        .iter()
        .filter(|(r, _)| !open[**r as usize])
        .map(|(_, m)| m)
        .collect();
    outward_if_dark(patches, &flip, &closed)
}

/// An edge of a patch: (key of its two vertex ids, patch, runs from the smaller id).
type Edge = (u64, u32, bool);

/// Two patches sharing an edge: (patch, patch, their orientations agree).
type Join = (u32, u32, bool);

/// 1. Vertices matched exactly: per patch its three vertex ids (`u32::MAX` for an inactive or
///    degenerate one), and every edge as (vertex pair key, patch, runs from the smaller id),
///    sorted.
fn edges_of(patches: &Patches) -> (Vec<[u32; 3]>, Vec<Edge>) {
    let n = patches.len();
    let mut ids: HashMap<[u64; 3], u32> = HashMap::new();
    let mut vid = |p: DVec3| {
        let key = crate::geometry::point_key(p);
        let next = ids.len() as u32;
        *ids.entry(key).or_insert(next)
    };
    let mut verts = vec![[u32::MAX; 3]; n];
    let mut edges: Vec<Edge> = Vec::with_capacity(3 * n);
    for p in (0..n).filter(|&p| patches.active[p]) {
        let v = patches.corners[p].map(&mut vid);
        if v[0] == v[1] || v[1] == v[2] || v[0] == v[2] {
            continue;
        }
        verts[p] = v;
        for k in 0..3 {
            let (a, b) = (v[k], v[(k + 1) % 3]);
            let key = u64::from(a.min(b)) << 32 | u64::from(a.max(b));
            edges.push((key, p as u32, a < b));
        }
    }
    edges.sort_unstable();
    (verts, edges)
}

/// 2. Objects: patches joined across edges that join exactly two. Returns per patch its
///    object (a root patch), per root whether the object is left alone (an edge with one or
///    more than two patches, a degenerate patch, one- and two-sided patches mixed),
///    and each join as (patch, patch, orientations agree: they run along the edge in opposite
///    directions).
fn join(patches: &Patches, verts: &[[u32; 3]], edges: &[Edge]) -> (Vec<u32>, Vec<bool>, Vec<Join>) {
    let n = patches.len();
    let mut sets = UnionFind::new(n);
    let mut open_edge = vec![false; n];
    let mut joins: Vec<Join> = Vec::new();
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j].0 == edges[i].0 {
            j += 1;
        }
        if j - i == 2 {
            let ((_, p, dp), (_, q, dq)) = (edges[i], edges[i + 1]);
            joins.push((p, q, dp != dq));
            sets.union(p as usize, q as usize);
        } else {
            for e in &edges[i..j] {
                open_edge[e.1 as usize] = true;
            }
        }
        i = j;
    }
    let root: Vec<u32> = (0..n).map(|p| sets.find(p) as u32).collect();
    let mut open = vec![false; n];
    // Per object: 1 when some patch is one-sided, 2 when some is two-sided.
    let mut sides = vec![0u8; n];
    for p in 0..n {
        let r = root[p] as usize;
        sides[r] |= if patches.is_two_sided(p) { 2 } else { 1 };
        if verts[p][0] == u32::MAX || open_edge[p] {
            open[r] = true;
        }
    }
    for r in 0..n {
        open[r] |= sides[r] == 3;
    }
    (root, open, joins)
}

/// 3. Orientation: per patch of an object not left alone, whether it is flipped against the
///    object's first patch (a walk over the joins), and each object's patches by root. An
///    object whose orientations cannot be made consistent is left alone (`open`).
#[allow(clippy::type_complexity)]
fn orient(
    n: usize,
    verts: &[[u32; 3]],
    root: &[u32],
    open: &mut [bool],
    joins: &[Join],
) -> (Vec<Option<bool>>, HashMap<u32, Vec<u32>>) {
    let mut adjacency: Vec<Vec<(u32, bool)>> = vec![Vec::new(); n];
    for &(p, q, agree) in joins {
        if !open[root[p as usize] as usize] {
            adjacency[p as usize].push((q, agree));
            adjacency[q as usize].push((p, agree));
        }
    }
    let mut flip: Vec<Option<bool>> = vec![None; n];
    let mut members: HashMap<u32, Vec<u32>> = HashMap::new();
    for p in 0..n {
        let r = root[p];
        if verts[p][0] == u32::MAX || open[r as usize] || flip[p].is_some() {
            continue;
        }
        let list = members.entry(r).or_default();
        flip[p] = Some(false);
        let mut stack = vec![p as u32];
        while let Some(a) = stack.pop() {
            list.push(a);
            let fa = flip[a as usize].unwrap_or(false);
            for &(b, agree) in &adjacency[a as usize] {
                let want = fa ^ !agree;
                match flip[b as usize] {
                    None => {
                        flip[b as usize] = Some(want);
                        stack.push(b);
                    }
                    Some(f) if f != want => open[r as usize] = true,
                    Some(_) => {}
                }
            }
        }
    }
    (flip, members)
}

/// 4. Each closed object's outside from its signed volume (none below [`MIN_VOLUME_RATIO`]);
///    its inside dark when no other object's emitter and no point or spot light lies within
///    its bounds, and its own emitters' light is not meant to be seen inside (see the
///    [module](self)). The dark objects' patches are members, those whose orientation
///    disagrees with the outward one turned.
fn outward_if_dark(patches: &Patches, flip: &[Option<bool>], closed: &[&Vec<u32>]) -> Closed {
    let n = patches.len();
    let mut out = Closed {
        turn: vec![false; n],
        member: vec![false; n],
        objects: 0,
    };
    let emitters: Vec<(usize, (DVec3, DVec3))> = (0..n)
        .filter(|&p| patches.active[p] && patches.is_emitter(p))
        .map(|p| (p, bounds_of(&patches.corners[p])))
        .collect();
    let (scene_lo, scene_hi) = (0..n).filter(|&p| patches.active[p]).fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| {
            let (a, b) = bounds_of(&patches.corners[p]);
            (lo.min(a), hi.max(b))
        },
    );
    // Per patch, the closed object it belongs to (an index into `closed`).
    let mut object = vec![usize::MAX; n];
    for (k, list) in closed.iter().enumerate() {
        for &p in list.iter() {
            object[p as usize] = k;
        }
    }
    let lamps: Vec<DVec3> = patches
        .lights
        .iter()
        .filter_map(|l| match l {
            Light::Point { position, .. } | Light::Spot { position, .. } => Some(*position),
            _ => None,
        })
        .collect();
    if closed.len() as u64 * (emitters.len() + lamps.len()) as u64 > MAX_BOUND_TESTS {
        return out;
    }
    // Objects with emitters of their own are tested against every patch (left alone when
    // that takes more than MAX_BOUND_TESTS).
    let own_emitting = closed
        .iter()
        .filter(|list| list.iter().any(|&p| patches.is_emitter(p as usize)))
        .count();
    let own_tests_fit = own_emitting as u64 * n as u64 <= MAX_BOUND_TESTS;
    for (k, list) in closed.iter().enumerate() {
        let (lo, hi) = list.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), &p| {
                let (a, b) = bounds_of(&patches.corners[p as usize]);
                (lo.min(a), hi.max(b))
            },
        );
        let centre = (lo + hi) * 0.5;
        let (mut volume, mut area) = (0.0f64, 0.0f64);
        for &p in list.iter() {
            let [a, b, c] = patches.corners[p as usize].map(|x| x - centre);
            let signed = a.dot(b.cross(c)) / 6.0;
            volume += if flip[p as usize] == Some(true) {
                -signed
            } else {
                signed
            };
            area += patches.area[p as usize];
        }
        if volume.abs() < MIN_VOLUME_RATIO * area.powf(1.5) {
            continue;
        }
        let pad = DVec3::splat(crate::geometry::SCENE_EPS);
        let (lo, hi) = (lo - pad, hi + pad);
        let inside = |x: DVec3| x.cmpge(lo).all() && x.cmple(hi).all();
        let lit_inside = emitters
            .iter()
            .any(|&(p, (a, b))| object[p] != k && a.cmple(hi).all() && b.cmpge(lo).all())
            || lamps.iter().any(|&x| inside(x));
        if lit_inside {
            continue;
        }
        // Patches whose orientation disagrees with the outward one face inside.
        let outward_flip = volume < 0.0;
        let faces_inside = |p: u32| flip[p as usize] != Some(outward_flip);
        // An object with emitting patches of its own (a closed tube light) sends its inside
        // nothing that gets out, unless it is meant to be seen from inside: a one-sided
        // emitting patch faces inside, the object encloses the whole scene (a furnace), or
        // another object's patch lies within its bounds (a room whose ceiling lights emit).
        let own_emitters = || list.iter().filter(|&&p| patches.is_emitter(p as usize));
        if own_emitters().next().is_some()
            && (!own_tests_fit
                || own_emitters().any(|&p| faces_inside(p) && !patches.is_two_sided(p as usize))
                || (lo.cmple(scene_lo).all() && hi.cmpge(scene_hi).all())
                || (0..n)
                    .any(|p| patches.active[p] && object[p] != k && inside(patches.centroid[p])))
        {
            continue;
        }
        out.objects += 1;
        for &p in list.iter() {
            out.turn[p as usize] = faces_inside(p);
            out.member[p as usize] = true;
        }
    }
    out
}

fn bounds_of(t: &[DVec3; 3]) -> (DVec3, DVec3) {
    (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    /// A cube standing in a large emitting quad's light, far from it.
    fn scene_with_cube() -> Scene {
        let mut scene = Scene::default();
        crate::scene::generated::push_cube(&mut scene, DVec3::ZERO, 1.0, 0.5);
        let base = scene.positions.len() as u32;
        for p in [
            [-5.0, 4.0, -5.0],
            [5.0, 4.0, -5.0],
            [5.0, 4.0, 5.0],
            [-5.0, 4.0, 5.0],
        ] {
            scene.positions.push(DVec3::from_array(p));
        }
        for t in [[0, 1, 2], [0, 2, 3]] {
            scene.triangles.push(t.map(|k| base + k));
            scene.albedo.push([0.0; 3]);
            scene.emission.push([1.0; 3]);
            scene.material.push(None);
        }
        scene
    }

    fn turned(scene: &Scene) -> (Vec<usize>, u64) {
        let patches = crate::mesh::build_patches(scene, None);
        let closed = closed_dark_objects(&patches);
        let turn = closed.turn;
        (
            (0..turn.len()).filter(|&p| turn[p]).collect(),
            closed.objects,
        )
    }

    /// Adds a triangle facing down at height `y` within the unit cube of [`scene_with_cube`],
    /// grey `albedo` and `emission`, two-sided when the scene's triangles are.
    fn push_triangle_inside(scene: &mut Scene, y: f64, albedo: f64, emission: f64) {
        let base = scene.positions.len() as u32;
        for p in [[0.2, y, 0.2], [0.8, y, 0.2], [0.5, y, 0.8]] {
            scene.positions.push(DVec3::from_array(p));
        }
        scene.triangles.push([base, base + 2, base + 1]);
        scene.albedo.push([albedo; 3]);
        scene.emission.push([emission; 3]);
        scene.material.push(None);
        if !scene.two_sided.is_empty() {
            scene.two_sided.push(true);
        }
    }

    /// Every triangle with its own copies of its corners, and the copies at x = 0 of every other
    /// triangle written as -0.0 (as an exporter that transforms each copy on its own may):
    /// the corners still meet, and the cube is one closed object.
    #[test]
    fn a_cube_whose_corner_copies_differ_by_the_sign_of_zero_is_closed() {
        let mut scene = scene_with_cube();
        let mut positions = Vec::new();
        for t in 0..scene.triangles.len() {
            let base = positions.len() as u32;
            for k in scene.triangles[t] {
                let mut p = scene.positions[k as usize];
                if t % 2 == 0 && p.x == 0.0 {
                    p.x = -0.0;
                }
                positions.push(p);
            }
            scene.triangles[t] = [base, base + 1, base + 2];
        }
        assert!(positions
            .iter()
            .any(|p| p.x == 0.0 && p.x.is_sign_negative()));
        scene.positions = positions;
        assert_eq!(turned(&scene), (vec![], 1));
    }

    #[test]
    fn a_consistently_outward_cube_turns_nothing() {
        assert_eq!(turned(&scene_with_cube()), (vec![], 1));
    }

    #[test]
    fn a_cube_with_reversed_faces_turns_exactly_those() {
        let mut scene = scene_with_cube();
        for t in [1, 4, 7] {
            scene.triangles[t].swap(1, 2);
        }
        assert_eq!(turned(&scene), (vec![1, 4, 7], 1));
        let patches = crate::mesh::build_patches(&scene, None);
        let (out, what) = patches.closed_objects_outward().unwrap();
        assert_eq!((what.objects, what.turned), (1, 3));
        assert!(what.turned_two_sided.is_empty());
        for t in [1, 4, 7] {
            assert!(out.normal[t].dot(patches.normal[t]) < -0.99);
            assert_eq!(out.albedo[t], [0.0; 3]);
        }
        assert_eq!(out.albedo[0], patches.albedo[0]);
    }

    #[test]
    fn a_cube_facing_inward_turns_every_face() {
        let mut scene = scene_with_cube();
        for t in 0..12 {
            scene.triangles[t].swap(1, 2);
        }
        assert_eq!(turned(&scene), ((0..12).collect(), 1));
    }

    /// [`scene_with_cube`] with the cube emitting, its triangles `reversed` turned around,
    /// every triangle two-sided or none; `lamp` false drops the emitting quad.
    fn emitting_cube(reversed: &[usize], two_sided: bool, lamp: bool) -> Scene {
        let mut scene = scene_with_cube();
        if !lamp {
            for list in [&mut scene.albedo, &mut scene.emission] {
                list.truncate(12);
            }
            scene.triangles.truncate(12);
            scene.material.truncate(12);
        }
        for t in 0..12 {
            scene.emission[t] = [2.0; 3];
        }
        for &t in reversed {
            scene.triangles[t].swap(1, 2);
        }
        if two_sided {
            scene.two_sided = vec![true; scene.triangles.len()];
        }
        scene
    }

    #[test]
    fn a_two_sided_emitting_cube_is_solved_facing_out() {
        let scene = emitting_cube(&[1, 4, 7], true, true);
        assert_eq!(turned(&scene), (vec![1, 4, 7], 1));
        let patches = crate::mesh::build_patches(&scene, None);
        let (out, what) = patches.closed_objects_outward().unwrap();
        assert_eq!(what.turned_two_sided, vec![1, 4, 7]);
        assert_eq!(what.emitting_inside, (0..12).collect::<Vec<u32>>());
        for t in 0..12 {
            assert!(!out.is_two_sided(t));
            assert_eq!(out.emission[t], patches.emission[t], "both faces emit");
        }
    }

    #[test]
    fn a_one_sided_cube_emitting_inward_or_enclosing_the_scene_is_left_alone() {
        // Outward: nothing to turn, its light all goes out.
        assert_eq!(turned(&emitting_cube(&[], false, true)), (vec![], 1));
        // A one-sided face emitting inside: that light is meant to be seen there.
        assert_eq!(turned(&emitting_cube(&[4], false, true)), (vec![], 0));
        // A two-sided emitting cube that is the whole scene is a furnace, seen from inside.
        assert_eq!(turned(&emitting_cube(&[4], true, false)), (vec![], 0));
        // One with something inside it is a room whose lights are part of its mesh.
        let mut room = emitting_cube(&[4], true, true);
        push_triangle_inside(&mut room, 0.1, 0.5, 0.0);
        assert_eq!(turned(&room), (vec![], 0));
    }

    #[test]
    fn an_open_or_lit_inside_cube_is_left_alone() {
        let mut open = scene_with_cube();
        open.triangles[1].swap(1, 2);
        open.triangles.remove(0);
        assert_eq!(turned(&open), (vec![], 0));
        // An emitter inside the cube's bounds: the inside may be lit.
        let mut lit = scene_with_cube();
        lit.triangles[1].swap(1, 2);
        push_triangle_inside(&mut lit, 0.5, 0.0, 1.0);
        assert_eq!(turned(&lit), (vec![], 0));
    }
}
