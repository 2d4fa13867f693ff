//! Every tolerance of the crate, each with its unit and the reason for its value. Health
//! thresholds (how much divergence or negative mass fails a solve) are in
//! [`crate::solve::health`] and memory margins in [`crate::memory`]; they are limits, not
//! rounding allowances.
//!
//! Unit frame: the solver's coordinates, centred on the scene's bounds and scaled to diameter 1
//! ([`crate::mesh::UnitFrame`]), so an absolute tolerance there is a fraction of the scene.
//!
//! Not here: guards against a division by zero (`x.max(f64::MIN_POSITIVE)`), which change no
//! decision, ranges of user parameters (a field of view of 1e-3 to 179 degrees) and the
//! allowances of tests.

/// Relative tolerance for "this point lies in that plane": distances below
/// `PLANE_EPS * size` count as zero, where `size` is the larger triangle's longest edge.
/// Rounding of the unit-frame arithmetic is far below it. See also [`SCENE_EPS`] and
/// [`plane_tol`], which every plane decision uses.
pub const PLANE_EPS: f64 = 1e-9;

/// Absolute tolerance of every plane decision ("coplanar", "behind", "in front"), unit frame
/// (scene diameter 1): a point within `SCENE_EPS` of a plane lies in it.
///
/// Exported files carry float noise: 6 to 7 significant digits, or a vertex jitter of 1e-6 in
/// world units, move a vertex off its neighbours' plane by up to a few 1e-6 of the scene
/// diameter, and with exact decisions every such pair of coplanar neighbours became a costly
/// exact coupling (the seed room jittered by 1e-6: +45% links). The thinnest geometry that
/// matters in an interior (a 1 mm blind slat in a 10 m room, 1e-4) is far above it. What is
/// lost: a surface closer than 1e-5 of the scene diameter to another's plane exchanges nothing
/// with it (a sheet of paper on a desk), which is below what any binning resolves.
pub const SCENE_EPS: f64 = 1e-5;

/// The tolerance of a plane decision between objects of size `size` (unit frame):
/// `PLANE_EPS * size + SCENE_EPS`.
pub fn plane_tol(size: f64) -> f64 {
    PLANE_EPS * size + SCENE_EPS
}

/// Self-intersection offset for visibility rays, relative to the scene's diameter (the solver and
/// the path tracer work in a frame where the diameter is 1).
pub const RAY_EPS: f64 = 1e-6;

/// Largest `|sin|` of a triangle's corner angle below which it counts as degenerate (zero area).
///
/// Relative to the triangle's own edges, so it does not depend on the scene's scale: a sliver with
/// aspect ratio 1e6 (sin ~ 1e-6) is a real triangle, three collinear points (sin ~ 1e-16) are not.
pub const DEGENERATE_SIN: f64 = 1e-10;

/// Padding of the f32 boxes the ray-tracing BVH is built over, unit frame, so that rounding
/// the f64 corners and rays to f32 never culls a box that holds an f64 hit: an absolute part
/// ([`BOX_PAD`], above f32 rounding at unit magnitude, 6e-8) and a part relative to the
/// coordinate ([`BOX_PAD_RELATIVE`], above f32's relative rounding, 6e-8).
pub const BOX_PAD: f32 = 1e-5;

/// See [`BOX_PAD`].
pub const BOX_PAD_RELATIVE: f32 = 1e-6;

/// Slack of the f32 distance bound that culls BVH boxes beyond an f64 hit (relative and
/// absolute, unit frame): the bound must never fall below the f64 distance after rounding.
pub const RAY_T_SLACK: f64 = 1e-5;

/// A cluster-tree split is taken only when its surface-area cost is below the best so far by
/// this relative margin, so that ties between bins, which float noise of the input would break
/// differently, keep the first bin.
pub const SAH_IMPROVEMENT: f64 = 1e-6;

/// Rounding margin added to the cosine bound of a normal cone (dimensionless), so a cone never
/// excludes a direction it contains.
pub const CONE_COS_SLACK: f64 = 1e-9;

/// Relative rounding allowed by the cluster tree's invariant checks (a child's sphere inside its
/// parent's, areas summing to the parent's): far above the rounding of the sums they compare
/// (about 1e-15 per operation), far below any real violation.
pub const TREE_CHECK_RELATIVE: f64 = 1e-9;

/// Absolute part of the same checks, unit frame.
pub const TREE_CHECK_ABSOLUTE: f64 = 1e-12;

/// Two normals of one sender group are the same when 1 - cos of their angle is at most this
/// (dimensionless; about 4.5e-5 radians): equal up to rounding, so groups are exact.
pub const SAME_NORMAL: f64 = 1e-9;

/// Receiver fields ([`crate::solve::SolverOptions::field_ratio`]) merge two normals of a
/// receiver's elements into one plane slab when 1 - cos of their angle is at most this
/// (dimensionless; about 1e-3 radians), and widen the side test by the angle times the
/// distance: merging keeps the slabs few on meshes whose coplanar faces carry rounding or a
/// 1e-6 jitter, the margin keeps the test conservative.
pub const FIELD_NORMAL_MERGE: f64 = 5e-7;

/// A normal is taken as unit when its squared length is within this of 1 (dimensionless);
/// normals that are not (degenerate corners) send the groups to the coarse direction grid.
pub const UNIT_NORMAL_SLACK: f64 = 1e-9;

/// Tolerance of the convexity test, unit frame: a vertex this far behind a plane still counts
/// as on it. Coarser than [`SCENE_EPS`] is not needed (the test compares whole planes), and
/// finer than exported-file noise would call a closed box with a jittered corner non-convex.
pub const CONVEX_TOLERANCE: f64 = 1e-7;

/// Largest contraction ratio (dimensionless) the convergence estimate and the radiance bounds
/// take: a ratio of successive residuals, or the largest albedo, is capped here so that
/// `1 / (1 - q)` stays finite (at most 1e4). Albedos are at most [`crate::scene::ALBEDO_MAX`]
/// (0.99), so the cap never binds on a bound; it binds only on a residual ratio at or above 1
/// (a sweep that did not contract).
pub const MAX_CONTRACTION: f64 = 0.9999;

/// A colour is grey when its channels agree to this relative amount (dimensionless): exact up
/// to the rounding of reading the same number three times.
pub const GREY_RELATIVE: f64 = 1e-12;

/// Largest deviation between the normals of two emitters merged into one direct-light group
/// (|n_a - n_b|, about the angle in radians): coplanar up to the noise of exported files.
pub const GROUP_NORMAL_TOLERANCE: f64 = 1e-3;

/// Largest uniform random number a sampler uses where a sample of exactly 1, reachable by
/// adding a stratum's offset and rounding, would fall outside its range: a cosine-weighted
/// direction drawn at 1 lies in the surface's plane, an inverse-CDF lookup at 1 picks past its
/// last interval. Dimensionless; two f64 steps below 1, so the mapping stays strictly inside.
pub const SAMPLE_BELOW_ONE: f64 = 1.0 - f64::EPSILON;

/// A bound used slightly tightened, as `bound * TIGHTER`, so that rounding cannot carry a
/// value across it: the emitter groups' rim test of the direct light takes a member as wholly
/// in front of a receiver only where the member's own test ([`crate::solve::direct`]) would;
/// the `jitter` mesh variant moves a vertex by less than its distance. Dimensionless; 1e-9 is
/// far above the rounding of the products compared, far below any change they could make.
pub const TIGHTER: f64 = 1.0 - 1e-9;

/// Shortest direction vector of an analytic light (a spot's axis, a sun's direction), in the
/// scene's units: at or below it the direction cannot be normalized reliably and the light is
/// refused. Any real direction is many orders of magnitude longer.
pub const MIN_LIGHT_DIRECTION: f64 = 1e-12;

/// Slack of a spot light's outer cone angle above 90 degrees (radians), so that 90 degrees
/// given in degrees and converted to radians is accepted.
pub const CONE_ANGLE_SLACK: f64 = 1e-9;

/// Smallest span of cosines between a spot's inner and outer cone (dimensionless) over which
/// its falloff ramps: a narrower ramp is widened to it rather than divided by a near-zero span
/// (about 2.6 degrees at a 30-degree cone).
pub const SPOT_MIN_COS_SPAN: f64 = 1e-3;

/// A triangle's UV footprint smaller than this (texels squared) is degenerate and takes the
/// texel at its centre: no texel cell's clipped area can then be told from rounding.
pub const MIN_UV_AREA: f64 = 1e-12;

/// Two unit directions are opposite when their sum is shorter than this (dimensionless, about
/// the angle in radians): a sun turned to its exact opposite has no path between (refused by
/// the relighting animation).
pub const OPPOSITE_DIRECTIONS: f64 = 1e-6;

/// Rounding allowed in a slab's normal deviation for the receiver fields (the length of the
/// difference of two unit normals): f64 rounding of unit vectors is about 1e-16, so the margin
/// keeps a slab conservative without widening it measurably.
pub const NORMAL_ROUNDING: f64 = 1e-12;

/// Regularization of Anderson acceleration's small least-squares system, relative to its
/// trace (dimensionless): keeps the normal equations solvable when two stored differences are
/// nearly parallel, and moves the solution by far less than the solver's tolerance.
pub const ANDERSON_REGULARIZATION: f64 = 1e-12;

/// The rasterizer's near plane, relative to the scene's diameter (or to 1 when the diameter is
/// not usable): close enough that nothing in front of the camera is clipped, far enough that
/// the inverse depth stays finite.
pub const NEAR_PLANE_RELATIVE: f64 = 1e-6;

/// A projected triangle with less signed area than this (pixels squared) is not drawn: it
/// covers no pixel centre the edge functions can tell from rounding.
pub const MIN_SCREEN_AREA: f64 = 1e-12;

/// Two inverse depths within this relative amount are at the same depth for the rasterizer's
/// depth test (so a front side wins over a back side there): coincident surfaces differ by
/// rounding only.
pub const DEPTH_TIE_RELATIVE: f64 = 1e-9;

/// An eye closer than this fraction of the scene's radius to the scene's centre is at the
/// centre: auto-framing then looks along -z instead of at the centre.
pub const SAME_POINT_RELATIVE: f64 = 1e-9;

/// Mesh variants ([`crate::scene::variants`]): a polygon corner whose two edges have a cross
/// product below this relative to their lengths (about the sine of the angle) is collinear
/// and dropped from a merged region's outline.
pub const VARIANT_COLLINEAR: f64 = 1e-12;

/// Mesh variants: a merged region's triangulation is kept only when its area equals the
/// region's to this relative amount (float rounding of the sums, far below a missing piece).
pub const VARIANT_AREA_MATCH: f64 = 1e-9;

/// Ear clipping ([`crate::geometry::polygon::ear_clip`], for concave polygons of scene files and
/// the mesh variants' merged regions): a corner turns, and a point lies off an ear's edge,
/// when twice the signed area of their triangle is beyond this, relative to the polygon's
/// extent squared.
pub const EAR_TOLERANCE: f64 = 1e-14;

/// Mesh variants: two triangles are coplanar for region merging when the far corner of one is
/// within this fraction of the scene's diameter of the other's plane (the noise of exported
/// files, as [`SCENE_EPS`] is for the solver).
pub const VARIANT_PLANE: f64 = 1e-6;

/// Mesh variants: two triangles face the same way for region merging when the dot product of
/// their unit normals is at least 1 minus this (about 1.4e-4 radians).
pub const VARIANT_SAME_NORMAL: f64 = 1e-8;

/// Mesh variants: an overlap of a merged triangle with an input triangle counts when its area
/// is above this share of the merged triangle's (rounding of the clipped areas).
pub const VARIANT_OVERLAP: f64 = 1e-12;
