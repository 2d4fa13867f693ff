//! The emitters of a scene and their groups: emitters edge to edge with the same emission and
//! normal are one light for the shadow rays.

use super::*;

/// The emitting patches.
pub(super) struct Emitters {
    /// Patch index of each emitter.
    pub(super) patch: Vec<u32>,
    /// Geometry of each emitter (unit frame).
    pub(super) geom: Vec<PatchGeom>,
    /// Emitted radiance (normalized units).
    pub(super) emission: Vec<[f64; 3]>,
}

impl Emitters {
    /// True when patch `p` is an emitter: active and emitting in some channel (positive area x
    /// largest channel).
    pub(super) fn emits(patches: &Patches, p: usize) -> bool {
        let e = patches.emission[p];
        let w = patches.area[p] * e[0].max(e[1]).max(e[2]);
        patches.active[p] && w > 0.0 && w.is_finite()
    }

    /// The number of emitters [`Emitters::new`] finds.
    pub(super) fn count(patches: &Patches) -> usize {
        (0..patches.len())
            .filter(|&p| Emitters::emits(patches, p))
            .map(|p| 1 + usize::from(patches.is_two_sided(p)))
            .sum()
    }

    /// The active patches that emit in some channel; a two-sided one whose `back_face(p)`
    /// emits from its back face too (a second emitter, its corners reversed).
    pub(super) fn new(patches: &Patches, back_face: &dyn Fn(usize) -> bool) -> Emitters {
        let mut emitters = Emitters {
            patch: Vec::new(),
            geom: Vec::new(),
            emission: Vec::new(),
        };
        for p in 0..patches.len() {
            let e = patches.emission[p];
            if Emitters::emits(patches, p) {
                let front = PatchGeom::new(patches.corners[p], patches.normal[p]);
                // A two-sided emitter emits from its back face too: a second emitter.
                let faces = if patches.is_two_sided(p) && back_face(p) {
                    vec![front, front.flipped()]
                } else {
                    vec![front]
                };
                // Its visible share: 1 for the scene's own emitters (`mesh::overlap`), less
                // for an overlapped surface a relight made emit.
                let e = e.map(|x| x * patches.visible_share(p));
                for geom in faces {
                    emitters.patch.push(p as u32);
                    emitters.geom.push(geom);
                    emitters.emission.push(e);
                }
            }
        }
        emitters
    }

    pub(super) fn len(&self) -> usize {
        self.patch.len()
    }
}

/// One emitter group's unoccluded light at one receiver: what the receiver's shadow rays are
/// distributed by.
#[derive(Clone, Copy, Debug)]
pub(super) struct GroupLight {
    /// Index into the groups.
    pub(super) group: u32,
    /// The group's mean unoccluded form factor seen from the receiver (> 0).
    pub(super) form_factor: f64,
}

/// A set of emitters joined edge to edge, with the same emission and (nearly) the same normal,
/// such as a ceiling light made of hundreds of triangles.
///
/// Seen from a point in front of every member and with every member in front of the point's
/// plane, the members' form factors sum to Lambert's contour sum over the group's boundary
/// only: each shared edge appears in its two triangles with opposite directions, and its two
/// terms cancel exactly (whatever the triangles' planes). So the group costs its boundary edges
/// instead of three edges per member.
pub(super) struct EmitterGroup {
    /// Indices into [`Emitters`].
    pub(super) members: Vec<u32>,
    /// Directed boundary edges (start, end), in the members' counter-clockwise order, collinear
    /// runs merged ([`merge_collinear`]).
    pub(super) boundary: Vec<(DVec3, DVec3)>,
    /// Area-weighted mean unit normal and centroid.
    pub(super) normal: DVec3,
    pub(super) centroid: DVec3,
    /// Largest |n_member - normal|.
    pub(super) normal_spread: f64,
    /// Largest distance of a vertex from the mean plane.
    pub(super) thickness: f64,
    /// Bounding sphere of the vertices: centre and radius.
    pub(super) center: DVec3,
    pub(super) radius: f64,
    /// Every directed edge belongs to one member at most, so any subset of the members is
    /// bounded by the edges it does not share with itself (what a group cut by a receiver's
    /// plane needs).
    pub(super) manifold: bool,
    /// The members lie in one plane (normals and vertices within rounding of the mean plane's):
    /// the plane of a receiver cuts the group along one line.
    pub(super) planar: bool,
    /// The members' bounding-sphere tree, each node with its rim (see [`MemberTree`]).
    pub(super) tree: MemberTree,
    /// The members' common emission (normalized units).
    pub(super) emission: [f64; 3],
    /// Total area of the members.
    pub(super) area: f64,
    /// Cumulative area fraction of the members, in member order (last entry exactly 1): a
    /// shadow ray's member is chosen by area, so its point is uniform over the group.
    pub(super) member_cdf: Vec<f64>,
    /// Per bucket `b` of `[b / G, (b + 1) / G)` (`G` its length, the member count), the first
    /// member whose cumulative fraction exceeds `b / G`: [`EmitterGroup::pick`] scans on from
    /// there instead of bisecting the whole list (the same answer, found in a step or two).
    pub(super) member_guide: Vec<u32>,
}

impl EmitterGroup {
    /// True when `x` lies clearly in front of every member's plane (beyond the members' spread
    /// about the group's plane): the condition of the group's contour sum at `x`.
    pub(super) fn clearly_in_front(&self, x: DVec3) -> bool {
        let margin = self.normal_spread * ((x - self.center).length() + self.radius)
            + self.thickness
            + PLANE_EPS * self.radius;
        self.normal.dot(x - self.centroid) > margin
    }

    /// The member (index into [`Emitters`]) whose cumulative area interval holds `u` in [0, 1).
    pub(super) fn pick(&self, u: f64) -> usize {
        self.members[guided_interval(&self.member_cdf, &self.member_guide, u)] as usize
    }
}

/// The guide of `cdf` (non-decreasing): per bucket `b` of `cdf.len()` equal buckets of [0, 1),
/// the first entry above `b / cdf.len()`.
fn guide_of(cdf: &[f64]) -> Vec<u32> {
    let g = cdf.len();
    (0..g)
        .map(|b| cdf.partition_point(|&c| c <= b as f64 / g as f64) as u32)
        .collect()
}

/// [`interval_of`] `(cdf, u)` through `guide` ([`guide_of`] of `cdf`): from the first entry
/// above the start of `u`'s bucket, on to the first entry above `u`. Exactly `interval_of`'s
/// answer; should rounding put the bucket's start above `u`, it bisects instead.
fn guided_interval(cdf: &[f64], guide: &[u32], u: f64) -> usize {
    let g = guide.len();
    let b = ((u * g as f64) as usize).min(g.saturating_sub(1));
    let Some(&start) = guide.get(b) else {
        return interval_of(cdf, u);
    };
    let mut i = start as usize;
    if i > 0 && cdf.get(i - 1).is_some_and(|&c| c > u) {
        return interval_of(cdf, u);
    }
    while i < cdf.len() && cdf[i] <= u {
        i += 1;
    }
    i.min(cdf.len().saturating_sub(1))
}

/// Largest normal spread, and thickness relative to the radius, of a planar group (see
/// [`EmitterGroup::planar`]): rounding only.
const PLANAR: f64 = 1e-9;

/// No member across this edge (see [`edge_neighbours`]).
pub(super) const NO_NEIGHBOUR: u32 = u32::MAX;

/// Root of `i` in a union-find forest (with path halving).
pub(super) fn find_root(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

/// Groups the emitters: two emitters join when they share an edge traversed in opposite
/// directions (bit-identical end points), emit exactly the same radiance and have normals within
/// [`GROUP_NORMAL_TOLERANCE`]. Every emitter is in exactly one group (often alone).
pub(super) fn group_emitters(emitters: &Emitters) -> Vec<EmitterGroup> {
    // 1. Union over shared edges.
    let mut parent = union_shared_edges(emitters);
    // 2. Members per group, in emitter order.
    let groups = members_by_root(&mut parent);
    // 3. Boundary, plane and bounds of each group.
    groups
        .into_iter()
        .map(|members| build_group(emitters, members))
        .collect()
}

/// The union-find forest of the emitters joined over shared edges (see [`group_emitters`]).
fn union_shared_edges(emitters: &Emitters) -> Vec<u32> {
    use std::collections::HashMap;
    let n = emitters.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    let mut edge_owner: HashMap<([u64; 3], [u64; 3]), u32> = HashMap::new();
    for (k, g) in emitters.geom.iter().enumerate() {
        for i in 0..3 {
            let (a, b) = (point_key(g.corners[i]), point_key(g.corners[(i + 1) % 3]));
            edge_owner.insert((a, b), k as u32);
        }
    }
    for (k, g) in emitters.geom.iter().enumerate() {
        for i in 0..3 {
            let (a, b) = (point_key(g.corners[i]), point_key(g.corners[(i + 1) % 3]));
            let Some(&other) = edge_owner.get(&(b, a)) else {
                continue;
            };
            let o = other as usize;
            if o == k
                || emitters.emission[o] != emitters.emission[k]
                || (emitters.geom[o].normal - g.normal).length() > GROUP_NORMAL_TOLERANCE
            {
                continue;
            }
            let (ra, rb) = (
                find_root(&mut parent, k as u32),
                find_root(&mut parent, other),
            );
            if ra != rb {
                parent[ra.max(rb) as usize] = ra.min(rb);
            }
        }
    }
    parent
}

/// The members of each tree of the forest `parent`, in element order, the trees in the order
/// of their roots.
fn members_by_root(parent: &mut [u32]) -> Vec<Vec<u32>> {
    use std::collections::HashMap;
    let mut members_of: HashMap<u32, Vec<u32>> = HashMap::new();
    for k in 0..parent.len() as u32 {
        let root = find_root(parent, k);
        members_of.entry(root).or_default().push(k);
    }
    let mut roots: Vec<u32> = members_of.keys().copied().collect();
    roots.sort_unstable();
    roots
        .into_iter()
        .map(|root| members_of.remove(&root).unwrap_or_default())
        .collect()
}

/// The group of `members` (indices into `emitters`, in emitter order): its boundary, plane,
/// bounds and member tree.
fn build_group(emitters: &Emitters, members: Vec<u32>) -> EmitterGroup {
    let Outline {
        boundary,
        vertices,
        normal_sum,
        centroid_sum,
        area,
    } = Outline::of(emitters, &members);
    let normal = normal_sum.normalize_or_zero();
    let centroid = centroid_sum / area;
    let center = vertices.iter().copied().sum::<DVec3>() / vertices.len() as f64;
    let radius = vertices
        .iter()
        .map(|v| (*v - center).length())
        .fold(0.0, f64::max);
    let thickness = vertices
        .iter()
        .map(|v| normal.dot(*v - centroid).abs())
        .fold(0.0, f64::max);
    let normal_spread = members
        .iter()
        .map(|&m| (emitters.geom[m as usize].normal - normal).length())
        .fold(0.0, f64::max);
    let member_cdf = cumulative(members.iter().map(|&m| emitters.geom[m as usize].area));
    let member_guide = guide_of(&member_cdf);
    let (neighbours, manifold) = edge_neighbours(emitters, &members);
    let tree = MemberTree::new(emitters, &members, &neighbours);
    let boundary = merge_collinear(boundary);
    let planar = normal_spread <= PLANAR && thickness <= PLANAR * radius;
    EmitterGroup {
        planar,
        tree,
        emission: emitters.emission[members[0] as usize],
        manifold,
        area,
        member_cdf,
        member_guide,
        members,
        boundary,
        normal,
        centroid,
        normal_spread,
        thickness,
        center,
        radius,
    }
}

/// A group's outline and area-weighted sums, from its members.
struct Outline {
    /// Directed boundary edges, in the order of their end points' keys.
    boundary: Vec<(DVec3, DVec3)>,
    /// The members' corners without repeats, in the order of their keys.
    vertices: Vec<DVec3>,
    /// Sum of area times unit normal.
    normal_sum: DVec3,
    /// Sum of area times centroid.
    centroid_sum: DVec3,
    /// Total area.
    area: f64,
}

impl Outline {
    /// The outline of `members` (indices into `emitters`).
    fn of(emitters: &Emitters, members: &[u32]) -> Outline {
        use std::collections::HashMap;
        // Directed edge (start key, end key) -> (start, end, copies).
        type DirectedEdges = HashMap<([u64; 3], [u64; 3]), (DVec3, DVec3, u32)>;
        let mut directed: DirectedEdges = HashMap::new();
        let mut vertices: HashMap<[u64; 3], DVec3> = HashMap::new();
        let mut normal_sum = DVec3::ZERO;
        let mut centroid_sum = DVec3::ZERO;
        let mut area = 0.0;
        for &m in members {
            let g = &emitters.geom[m as usize];
            normal_sum += g.normal * g.area;
            centroid_sum += g.centroid * g.area;
            area += g.area;
            for i in 0..3 {
                let (a, b) = (g.corners[i], g.corners[(i + 1) % 3]);
                vertices.insert(point_key(a), a);
                directed
                    .entry((point_key(a), point_key(b)))
                    .or_insert((a, b, 0))
                    .2 += 1;
            }
        }
        // An edge is interior when its reverse belongs to the group too: the pair cancels
        // (copies beyond a pair stay, so the sum always equals the members' sum).
        let mut boundary = Vec::new();
        let mut keys: Vec<_> = directed.keys().copied().collect();
        keys.sort_unstable();
        for key in keys {
            let (a, b, count) = directed[&key];
            let reverse = directed.get(&(key.1, key.0)).map_or(0, |e| e.2);
            for _ in 0..count.saturating_sub(reverse) {
                boundary.push((a, b));
            }
        }
        let mut vertex_list: Vec<([u64; 3], DVec3)> = vertices.into_iter().collect();
        vertex_list.sort_unstable_by_key(|v| v.0);
        let vertices: Vec<DVec3> = vertex_list.into_iter().map(|v| v.1).collect();
        Outline {
            boundary,
            vertices,
            normal_sum,
            centroid_sum,
            area,
        }
    }
}

/// Who is across each edge of each of `members`: for each member (in `members` order) and each
/// of its edges (corner i to i + 1), the member owning its reverse (its position in `members`),
/// or [`NO_NEIGHBOUR`]; and whether every directed edge has one owner at most
/// ([`EmitterGroup::manifold`]).
fn edge_neighbours(emitters: &Emitters, members: &[u32]) -> (Vec<[u32; 3]>, bool) {
    use std::collections::HashMap;
    let edge_of = |m: u32, i: usize| {
        let c = emitters.geom[m as usize].corners;
        (point_key(c[i]), point_key(c[(i + 1) % 3]))
    };
    let mut owner: HashMap<([u64; 3], [u64; 3]), u32> = HashMap::new();
    let mut manifold = true;
    for (local, &m) in members.iter().enumerate() {
        for i in 0..3 {
            manifold &= owner.insert(edge_of(m, i), local as u32).is_none();
        }
    }
    let neighbours: Vec<[u32; 3]> = members
        .iter()
        .map(|&m| {
            [0, 1, 2].map(|i| {
                let (a, b) = edge_of(m, i);
                owner.get(&(b, a)).copied().unwrap_or(NO_NEIGHBOUR)
            })
        })
        .collect();
    (neighbours, manifold)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The guided search gives bisection's answer for every `u`, at bucket starts, just below
    /// and above them, and at random, on area lists with zero areas, equal areas and one huge
    /// member.
    #[test]
    fn guided_interval_is_the_bisection() {
        let lists: [Vec<f64>; 4] = [
            vec![1.0],
            vec![1.0, 0.0, 0.0, 2.0, 1.0],
            vec![1.0; 7],
            (0..40)
                .map(|i| if i == 17 { 1e6 } else { 1.0 + i as f64 * 0.1 })
                .collect(),
        ];
        let mut rng = crate::geometry::sampling::Rng::new(7, 0);
        for areas in &lists {
            let cdf = cumulative(areas.iter().copied());
            let guide = guide_of(&cdf);
            let g = cdf.len() as f64;
            let mut us: Vec<f64> = (0..cdf.len())
                .flat_map(|b| {
                    let t = b as f64 / g;
                    [t, t.next_down().max(0.0), t.next_up()]
                })
                .collect();
            us.extend(cdf.iter().flat_map(|&c| [c, c.next_down(), c.next_up()]));
            us.extend((0..1000).map(|_| rng.next_f64()));
            for u in us.into_iter().filter(|u| (0.0..1.0).contains(u)) {
                assert_eq!(
                    guided_interval(&cdf, &guide, u),
                    interval_of(&cdf, u),
                    "u = {u}, cdf = {cdf:?}"
                );
            }
        }
    }
}
