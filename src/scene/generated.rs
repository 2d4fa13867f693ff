//! Built-in test scenes and an OBJ+MTL writer.
//!
//! Every generator returns a [`Scene`] built with [`Scene::from_triangles`]: quads become two
//! triangles `(q0, q1, q2), (q0, q2, q3)` (the same fan an OBJ loader applies to `f q0 q1 q2 q3`),
//! and every triangle is oriented so that its front side (counter-clockwise, see the design note)
//! faces where light is received or emitted. [`write_obj`] writes a scene so that
//! [`crate::scene::load_obj`] reads back the same triangles, in the same order, with the same
//! albedo and emission, bit for bit.
//!
//! The generators only use exact literals, sums, products and quotients (no transcendental
//! functions), so their output, and the files [`write_obj`] makes of it, are identical on every
//! platform. The committed files in `scenes/` are checked against them by `tests/scenes.rs`.

use std::collections::{HashMap, HashSet};
use std::path::PathBuf;

use glam::DVec3;

use crate::error::{Error, Result};
pub use crate::scene::write_obj::write_obj;
use crate::scene::{Scene, SceneCamera};

/// Cornell box white reflectance (floor, ceiling, back wall, blocks), RGB.
pub const CORNELL_WHITE: [f64; 3] = [0.725, 0.71, 0.68];
/// Cornell box red reflectance (the left wall seen from the camera, at x ~ 556 mm), RGB.
pub const CORNELL_RED: [f64; 3] = [0.63, 0.065, 0.05];
/// Cornell box green reflectance (the right wall seen from the camera, at x = 0), RGB.
pub const CORNELL_GREEN: [f64; 3] = [0.14, 0.45, 0.091];
/// Cornell box light reflectance, RGB (the light is a diffuse surface too).
pub const CORNELL_LIGHT_ALBEDO: [f64; 3] = [0.78, 0.78, 0.78];
/// Cornell box light emitted radiance, RGB (warm white, the usual RGB stand-in for the measured
/// spectrum).
pub const CORNELL_LIGHT_EMISSION: [f64; 3] = [17.0, 12.0, 4.0];

/// The parts of [`cornell_box`] in triangle order, with their triangle counts.
///
/// Triangles `0..2` are the floor, the next 16 the ceiling, and so on; the counts sum to
/// [`CORNELL_BOX_TRIANGLES`]. [`subdivide`] keeps the order and multiplies every count by k * k.
pub const CORNELL_BOX_PARTS: [(&str, usize); 8] = [
    ("floor", 2),
    ("ceiling", 16),
    ("light", 2),
    ("back wall", 2),
    ("red wall", 2),
    ("green wall", 2),
    ("short block", 10),
    ("tall block", 10),
];

/// Number of triangles of [`cornell_box`].
pub const CORNELL_BOX_TRIANGLES: usize = 46;

/// Collects triangles with their materials, then builds a [`Scene`].
#[derive(Default)]
pub(crate) struct Builder {
    corners: Vec<[DVec3; 3]>,
    albedo: Vec<[f64; 3]>,
    emission: Vec<[f64; 3]>,
    /// Material name of each triangle (`None` for the unnamed generators).
    names: Vec<Option<&'static str>>,
    /// Name given to the triangles added from now on.
    current: Option<&'static str>,
}

/// The point of the plane `axis = level` (0, 1, 2 for x, y, z) at coordinates `u`, `v` along the
/// two other axes, in cyclic order after `axis`.
fn plane_point(axis: usize, level: f64, u: f64, v: f64) -> DVec3 {
    let mut p = [0.0; 3];
    p[axis] = level;
    p[(axis + 1) % 3] = u;
    p[(axis + 2) % 3] = v;
    DVec3::from_array(p)
}

impl Builder {
    fn triangle(&mut self, tri: [DVec3; 3], albedo: [f64; 3], emission: [f64; 3]) {
        self.corners.push(tri);
        self.albedo.push(albedo);
        self.emission.push(emission);
        self.names.push(self.current);
    }

    /// Names the material of the triangles added from now on.
    fn name(&mut self, name: &'static str) {
        self.current = Some(name);
    }

    /// Adds a quad as `(q0, q1, q2), (q0, q2, q3)`, with the vertex order reversed first when
    /// needed so that the front side faces `facing`.
    pub(crate) fn quad(
        &mut self,
        q: [DVec3; 4],
        facing: DVec3,
        albedo: [f64; 3],
        emission: [f64; 3],
    ) {
        let n = (q[1] - q[0]).cross(q[2] - q[0]) + (q[2] - q[0]).cross(q[3] - q[0]);
        let q = if n.dot(facing) >= 0.0 {
            q
        } else {
            [q[0], q[3], q[2], q[1]]
        };
        self.triangle([q[0], q[1], q[2]], albedo, emission);
        self.triangle([q[0], q[2], q[3]], albedo, emission);
    }

    /// Adds a quad whose front faces away from `inside` (a point inside a closed block).
    fn quad_away_from(&mut self, q: [DVec3; 4], inside: DVec3, albedo: [f64; 3]) {
        let centre = (q[0] + q[1] + q[2] + q[3]) * 0.25;
        self.quad(q, centre - inside, albedo, [0.0; 3]);
    }

    /// Adds an axis-aligned rectangular grid of `n x m` quads in the plane `axis = level`,
    /// spanning `[u0, u1] x [v0, v1]` in the two other axes (cyclic order after `axis`), facing
    /// `facing`. Cells run row by row, `u` fastest.
    #[allow(clippy::too_many_arguments)]
    fn grid(
        &mut self,
        axis: usize,
        level: f64,
        (u0, u1, n): (f64, f64, usize),
        (v0, v1, m): (f64, f64, usize),
        facing: DVec3,
        albedo: [f64; 3],
        emission: [f64; 3],
    ) {
        let point = |u: f64, v: f64| plane_point(axis, level, u, v);
        let us: Vec<f64> = (0..=n).map(|i| lerp_steps(u0, u1, i, n)).collect();
        let vs: Vec<f64> = (0..=m).map(|j| lerp_steps(v0, v1, j, m)).collect();
        for j in 0..m {
            for i in 0..n {
                let q = [
                    point(us[i], vs[j]),
                    point(us[i + 1], vs[j]),
                    point(us[i + 1], vs[j + 1]),
                    point(us[i], vs[j + 1]),
                ];
                self.quad(q, facing, albedo, emission);
            }
        }
    }

    /// The scene of the triangles added.
    pub(crate) fn build(self) -> Scene {
        Scene::from_triangles(&self.corners, &self.albedo, &self.emission)
    }
}

/// `a + (b - a) * i / n` computed so that both ends are exact.
fn lerp_steps(a: f64, b: f64, i: usize, n: usize) -> f64 {
    if i == 0 {
        a
    } else if i == n {
        b
    } else {
        (a * (n - i) as f64 + b * i as f64) / n as f64
    }
}

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

/// The Cornell box, from the geometry published by the Cornell University Program of Computer
/// Graphics (<https://www.graphics.cornell.edu/online/box/data.html>), in millimetres.
///
/// Coordinates are the published vertex lists: floor (y = 0), ceiling (y = 548.8), back wall
/// (z = 559.2), red wall (x ~ 550..556, slightly non-planar as published: its quad is split into
/// two planar triangles), green wall (x = 0), the short block (165 mm tall) and the tall block
/// (330 mm tall), each as its five published faces (no bottom), and the light, the published
/// 130 x 105 mm rectangle `343.0 548.8 227.0 .. 213.0 548.8 332.0`. The front (z = 0, where the
/// published camera at (278, 273, -800) looks in along +z) is open, as published.
///
/// Choices not fixed by the published data:
/// - The ceiling has a hole exactly where the light is: it is the 3 x 3 grid of rectangles cut by
///   the light's edges, minus the centre one, and the light fills the hole in the ceiling plane
///   (y = 548.8), facing down. Ceiling and light do not overlap, and no two parallel surfaces are
///   a fraction of a millimetre apart.
/// - RGB reflectances instead of the measured spectra: white [`CORNELL_WHITE`] =
///   (0.725, 0.71, 0.68), red [`CORNELL_RED`] = (0.63, 0.065, 0.05), green [`CORNELL_GREEN`] =
///   (0.14, 0.45, 0.091), the light [`CORNELL_LIGHT_ALBEDO`] = 0.78 grey; emitted radiance
///   [`CORNELL_LIGHT_EMISSION`] = (17, 12, 4) (the values common RGB renditions of the box use).
///
/// Orientation: walls, floor, ceiling and light face the inside of the box; the blocks' faces face
/// outward. Triangle order is given by [`CORNELL_BOX_PARTS`] (46 triangles).
pub fn cornell_box() -> Scene {
    let mut b = Builder::default();
    let white = CORNELL_WHITE;
    let black = [0.0; 3];
    // Direction tests use the centre of the box: walls face it.
    let centre = v(278.0, 274.4, 279.6);
    let wall = |b: &mut Builder, q: [DVec3; 4], albedo: [f64; 3]| {
        let c = (q[0] + q[1] + q[2] + q[3]) * 0.25;
        b.quad(q, centre - c, albedo, black);
    };

    // Floor.
    wall(
        &mut b,
        [
            v(552.8, 0.0, 0.0),
            v(0.0, 0.0, 0.0),
            v(0.0, 0.0, 559.2),
            v(549.6, 0.0, 559.2),
        ],
        white,
    );

    // Ceiling with a hole for the light: a 3 x 3 grid minus its centre cell.
    let xs = [556.0, 343.0, 213.0, 0.0];
    let zs = [0.0, 227.0, 332.0, 559.2];
    for j in 0..3 {
        for i in 0..3 {
            if (i, j) == (1, 1) {
                continue;
            }
            wall(
                &mut b,
                [
                    v(xs[i], 548.8, zs[j]),
                    v(xs[i], 548.8, zs[j + 1]),
                    v(xs[i + 1], 548.8, zs[j + 1]),
                    v(xs[i + 1], 548.8, zs[j]),
                ],
                white,
            );
        }
    }

    // Light, in the ceiling's hole, facing down.
    b.quad(
        [
            v(343.0, 548.8, 227.0),
            v(343.0, 548.8, 332.0),
            v(213.0, 548.8, 332.0),
            v(213.0, 548.8, 227.0),
        ],
        v(0.0, -1.0, 0.0),
        CORNELL_LIGHT_ALBEDO,
        CORNELL_LIGHT_EMISSION,
    );

    // Back wall.
    wall(
        &mut b,
        [
            v(549.6, 0.0, 559.2),
            v(0.0, 0.0, 559.2),
            v(0.0, 548.8, 559.2),
            v(556.0, 548.8, 559.2),
        ],
        white,
    );

    // Red wall (left in the published camera's view).
    wall(
        &mut b,
        [
            v(552.8, 0.0, 0.0),
            v(549.6, 0.0, 559.2),
            v(556.0, 548.8, 559.2),
            v(556.0, 548.8, 0.0),
        ],
        CORNELL_RED,
    );

    // Green wall (right in the published camera's view).
    wall(
        &mut b,
        [
            v(0.0, 0.0, 559.2),
            v(0.0, 0.0, 0.0),
            v(0.0, 548.8, 0.0),
            v(0.0, 548.8, 559.2),
        ],
        CORNELL_GREEN,
    );

    // Short block: top then four sides, as published; faces point away from the block's centre.
    let short_top = [
        v(130.0, 165.0, 65.0),
        v(82.0, 165.0, 225.0),
        v(240.0, 165.0, 272.0),
        v(290.0, 165.0, 114.0),
    ];
    block(&mut b, short_top, [(3, 2), (0, 3), (1, 0), (2, 1)], white);

    // Tall block.
    let tall_top = [
        v(423.0, 330.0, 247.0),
        v(265.0, 330.0, 296.0),
        v(314.0, 330.0, 456.0),
        v(472.0, 330.0, 406.0),
    ];
    block(&mut b, tall_top, [(0, 3), (3, 2), (2, 1), (1, 0)], white);

    let mut scene = b.build();
    scene.camera = Some(CORNELL_BOX_CAMERA);
    scene
}

/// The Cornell box's published camera (Cornell University Program of Computer Graphics): the
/// eye 800 mm in front of the opening, looking straight in, 39.3 degrees of vertical field.
pub const CORNELL_BOX_CAMERA: SceneCamera = SceneCamera {
    eye: DVec3::new(278.0, 273.0, -800.0),
    target: DVec3::new(278.0, 273.0, 0.0),
    fov_deg: 39.3,
};

/// Adds a block standing on y = 0 with the given top face: the top, then the four sides, the side
/// under top edge `(a, c)` being `floor(a), a, c, floor(c)` as the published data lists them, all
/// facing away from the block's centre.
fn block(b: &mut Builder, top: [DVec3; 4], sides: [(usize, usize); 4], albedo: [f64; 3]) {
    let h = top[0].y;
    let centre = (top[0] + top[1] + top[2] + top[3]) * 0.25 - v(0.0, h * 0.5, 0.0);
    b.quad_away_from(top, centre, albedo);
    let floor = |p: DVec3| v(p.x, 0.0, p.z);
    for (a, c) in sides {
        let (pa, pc) = (top[a], top[c]);
        b.quad_away_from([floor(pa), pa, pc, floor(pc)], centre, albedo);
    }
}

/// Appends an axis-aligned cube to `scene`: corner `at`, edge `size`, 8 shared vertices and 12
/// triangles facing out, two per face in the order -z, +z, -y, +y, -x, +x, of grey albedo
/// `albedo`, no emission and no material. Returns the index of its first triangle.
pub fn push_cube(scene: &mut Scene, at: DVec3, size: f64, albedo: f64) -> usize {
    let (first, base) = (scene.len(), scene.positions.len() as u32);
    for i in 0..8 {
        let c = v((i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64);
        scene.positions.push(at + c * size);
    }
    // Quads counter-clockwise seen from outside.
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    for q in quads {
        for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
            scene.triangles.push(t.map(|k| base + k));
            scene.albedo.push([albedo; 3]);
            scene.emission.push([0.0; 3]);
            scene.material.push(None);
        }
    }
    first
}

/// Floor cells per side in [`occluder_scene`].
pub const OCCLUDER_FLOOR_CELLS: usize = 12;

/// A light, an occluding plate and a floor that receives the plate's shadow; open (no walls), in
/// metres.
///
/// - Light: the 1 x 1 square `[-0.5, 0.5] x [-0.5, 0.5]` (x, z) at y = 1.5, facing down, emitted
///   radiance 1 (grey), albedo 0. Triangles 0..2.
/// - Plate: a one-sided 0.6 x 0.6 square `[-0.3, 0.3]^2` at y = 0.5, facing up (towards the
///   light), albedo 0.5 grey. Triangles 2..4. Its back absorbs; by itself it casts the shadow.
/// - Floor: `[-1.5, 1.5]^2` at y = 0, facing up, albedo 0.5 grey, split into
///   [`OCCLUDER_FLOOR_CELLS`]^2 squares of 0.25 (two triangles each; cells ordered by x, then z), so
///   the shadow shows in per-triangle results: umbra within |x|, |z| <= 0.2 of the centre,
///   penumbra out to 0.7, fully lit beyond.
pub fn occluder_scene() -> Scene {
    let mut b = Builder::default();
    let up = v(0.0, 1.0, 0.0);
    // Grids in the plane y = level: axis 1, u = z, v = x.
    b.grid(
        1,
        1.5,
        (-0.5, 0.5, 1),
        (-0.5, 0.5, 1),
        -up,
        [0.0; 3],
        [1.0; 3],
    );
    b.grid(
        1,
        0.5,
        (-0.3, 0.3, 1),
        (-0.3, 0.3, 1),
        up,
        [0.5; 3],
        [0.0; 3],
    );
    let n = OCCLUDER_FLOOR_CELLS;
    b.grid(
        1,
        0.0,
        (-1.5, 1.5, n),
        (-1.5, 1.5, n),
        up,
        [0.5; 3],
        [0.0; 3],
    );
    b.build()
}

/// A closed unit cube `[0, 1]^3` facing inward (12 triangles), whose every triangle emits
/// `emission` and reflects `albedo` (grey): the furnace test, B = E / (1 - rho) everywhere.
///
/// The mesh is closed and consistently oriented: every edge is shared by exactly two triangles
/// that traverse it in opposite directions. Values are stored as given (no range check; the
/// loader and [`write_obj`] reject albedo outside [0, 1) and negative emission).
pub fn furnace_box(emission: f64, albedo: f64) -> Scene {
    let mut b = Builder::default();
    let centre = DVec3::splat(0.5);
    for axis in 0..3 {
        for level in [0.0, 1.0] {
            let mut facing = [0.0; 3];
            facing[axis] = 0.5 - level;
            b.grid(
                axis,
                level,
                (0.0, 1.0, 1),
                (0.0, 1.0, 1),
                DVec3::from_array(facing),
                [albedo; 3],
                [emission; 3],
            );
        }
    }
    debug_assert!(b.corners.iter().all(|t| {
        let n = (t[1] - t[0]).cross(t[2] - t[0]);
        n.dot(centre - t[0]) > 0.0
    }));
    b.build()
}

/// Splits every triangle of `scene` uniformly into `k * k` triangles (the k-th subdivision of
/// each edge), keeping order, orientation and materials: the pieces of input triangle t are
/// triangles `t * k * k .. (t + 1) * k * k` of the result.
///
/// Points on an edge are computed from that edge's two end points only, in an order-independent
/// way, so two triangles that share an edge get bit-identical points on it and a closed mesh
/// stays closed. The result has no path and no warnings.
///
/// # Panics
///
/// When `k` is 0.
pub fn subdivide(scene: &Scene, k: usize) -> Scene {
    assert!(k >= 1, "subdivide: k must be at least 1");
    let pieces = scene.len() * k * k;
    let mut corners = Vec::with_capacity(pieces);
    let mut albedo = Vec::with_capacity(pieces);
    let mut emission = Vec::with_capacity(pieces);
    let kf = k as f64;
    for t in 0..scene.len() {
        let [a, b, c] = scene.corners(t);
        // Lattice point with integer barycentric weights (k - i - j, i, j).
        let point = |i: usize, j: usize| -> DVec3 {
            let w = k - i - j;
            if w == k {
                a
            } else if i == k {
                b
            } else if j == k {
                c
            } else {
                (a * w as f64 + b * i as f64 + c * j as f64) / kf
            }
        };
        for j in 0..k {
            for i in 0..k - j {
                corners.push([point(i, j), point(i + 1, j), point(i, j + 1)]);
                if i + j + 2 <= k {
                    corners.push([point(i + 1, j), point(i + 1, j + 1), point(i, j + 1)]);
                }
            }
        }
        let added = corners.len() - albedo.len();
        albedo.extend(std::iter::repeat_n(scene.albedo[t], added));
        emission.extend(std::iter::repeat_n(scene.emission[t], added));
    }
    Scene::from_triangles(&corners, &albedo, &emission)
}

/// The [`cornell_box`] split uniformly (see [`subdivide`]) with the smallest k such that it has at
/// least `target_triangles` triangles: `46 * k * k` triangles (k = 5 gives 1150, k = 75 gives
/// 258 750, k = 148 gives 1 007 584). The same scene at growing sizes, for growth measurements.
pub fn subdivided_cornell_box(target_triangles: usize) -> Scene {
    let mut k = 1usize;
    while CORNELL_BOX_TRIANGLES * k * k < target_triangles {
        k += 1;
    }
    subdivide(&cornell_box(), k)
}

/// Floor albedo (grey) of the room [`in_room`] builds.
pub const ROOM_FLOOR_ALBEDO: f64 = 0.6;
/// Wall and ceiling albedo (grey) of the room [`in_room`] builds.
pub const ROOM_WALL_ALBEDO: f64 = 0.7;
/// Default emitted radiance (grey, W/(m^2 sr)) of the lights [`in_room`] and [`under_light`]
/// add (the `scene` command's `--light-radiance`).
pub const DEFAULT_LIGHT_RADIANCE: f64 = 10.0;
/// Number of triangles [`in_room`] adds after the object's: floor, ceiling (with the light as
/// its centre cell) and four walls, each a 3 x 3 grid of quads.
pub const ROOM_TRIANGLES: usize = 108;
/// Number of triangles [`under_light`] adds after the mesh's: one rectangle.
pub const LIGHT_TRIANGLES: usize = 2;
/// Material name given to an object's triangles that have no material of their own, in
/// [`in_room`] and [`under_light`] (made unique if the object already uses it).
pub const OBJECT_MATERIAL: &str = "object";

/// The room [`in_room`] builds around an object, in the object's units and frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Room {
    /// Lowest corner of the room's box: `min.y` is the floor, the object's lowest y.
    pub min: DVec3,
    /// Highest corner: `max.y` is the ceiling.
    pub max: DVec3,
    /// The light's rectangle in the ceiling (y = `max.y`), lowest (x, z) corner.
    pub light_min: DVec3,
    /// The light's rectangle, highest (x, z) corner.
    pub light_max: DVec3,
}

/// Width and depth of the object's axis-aligned bounds (x and z extents), its height (y extent)
/// and the largest of the three; an error when all three are 0 or not finite.
fn extents(object: &Scene, what: &str) -> Result<(DVec3, DVec3, f64)> {
    if object.is_empty() {
        return Err(Error::Parameter(format!(
            "{what}: the object has no triangles"
        )));
    }
    let (lo, hi) = object.bounds();
    let size = hi - lo;
    let largest = size.max_element();
    if !(lo.is_finite() && hi.is_finite() && largest > 0.0) {
        return Err(Error::Parameter(format!(
            "{what}: the object's bounds {lo} .. {hi} have no extent or are not finite"
        )));
    }
    Ok((lo, hi, largest))
}

/// The room [`in_room`] puts around `object`: a box standing on the object's lowest point,
/// centred on its bounds in x and z.
///
/// With the object's bounds of width `sx`, height `sy` and depth `sz` (scene units), the room
/// is `w = max(3 max(sx, sz), 1.5 sy)` wide and deep and `h = max(2 sy, w / 2)` high; the floor is
/// at the object's lowest y, so the object stands on it. The light is the square of side `w / 4`
/// at the centre of the ceiling.
///
/// Errors: [`Error::Parameter`] for an object without triangles or whose bounds have no extent
/// (every vertex at one point) or are not finite.
pub fn room_around(object: &Scene) -> Result<Room> {
    let (lo, hi, _) = extents(object, "in_room")?;
    let size = hi - lo;
    let w = (3.0 * size.x.max(size.z)).max(1.5 * size.y);
    let h = (2.0 * size.y).max(0.5 * w);
    let c = (lo + hi) * 0.5;
    let (half, light_half) = (0.5 * w, 0.125 * w);
    Ok(Room {
        min: DVec3::new(c.x - half, lo.y, c.z - half),
        max: DVec3::new(c.x + half, lo.y + h, c.z + half),
        light_min: DVec3::new(c.x - light_half, lo.y + h, c.z - light_half),
        light_max: DVec3::new(c.x + light_half, lo.y + h, c.z + light_half),
    })
}

/// Places `object` standing on the floor of a closed box room lit by a rectangular area light
/// in the ceiling.
///
/// The object is kept as it is (same triangles, order, corners bit for bit, albedo, emission
/// and material names; triangles without a material are named [`OBJECT_MATERIAL`]): its
/// triangles are `0..object.len()` of the result. The room ([`room_around`]) follows:
/// [`ROOM_TRIANGLES`] triangles, each of its six faces a 3 x 3 grid of quads (two triangles
/// each) facing the inside, the floor first (material `room_floor`, albedo
/// [`ROOM_FLOOR_ALBEDO`]), then the ceiling's eight outer cells (`room_ceiling`,
/// [`ROOM_WALL_ALBEDO`]), the light (`room_light`: the ceiling's centre cell, facing down,
/// albedo 0, emitted radiance `light_radiance` grey, in W/(m^2 sr)), then the walls at the
/// lowest x, highest x, lowest z and highest z (`room_wall`, [`ROOM_WALL_ALBEDO`]). Neighbouring
/// cells share their corners exactly, so the room is a closed, consistently oriented mesh
/// (every edge shared by two of its triangles, traversed in opposite directions). The result has
/// no path and no warnings.
///
/// The object's emitters, if any, keep emitting; the room adds the one light.
///
/// Errors: [`Error::Parameter`] when `light_radiance` is not finite and > 0, and those of
/// [`room_around`].
pub fn in_room(object: &Scene, light_radiance: f64) -> Result<Scene> {
    check_radiance(light_radiance)?;
    let room = room_around(object)?;
    let (lo, hi) = (room.min, room.max);
    let xs = [lo.x, room.light_min.x, room.light_max.x, hi.x];
    let zs = [lo.z, room.light_min.z, room.light_max.z, hi.z];
    let ys = [
        lo.y,
        lerp_steps(lo.y, hi.y, 1, 3),
        lerp_steps(lo.y, hi.y, 2, 3),
        hi.y,
    ];
    let centre = (lo + hi) * 0.5;
    let floor = [ROOM_FLOOR_ALBEDO; 3];
    let wall = [ROOM_WALL_ALBEDO; 3];
    let black = [0.0; 3];
    let light = [light_radiance; 3];
    let mut b = Builder::default();
    // A cell of the grid over `us` x `vs` in the plane `axis = level`, facing the room's centre.
    let cell = |b: &mut Builder,
                axis: usize,
                level: f64,
                (us, i): (&[f64; 4], usize),
                (vs, j): (&[f64; 4], usize),
                albedo: [f64; 3],
                emission: [f64; 3]| {
        let point = |u: f64, v: f64| plane_point(axis, level, u, v);
        let q = [
            point(us[i], vs[j]),
            point(us[i + 1], vs[j]),
            point(us[i + 1], vs[j + 1]),
            point(us[i], vs[j + 1]),
        ];
        let mid = (q[0] + q[1] + q[2] + q[3]) * 0.25;
        let mut facing = DVec3::ZERO;
        facing[axis] = centre[axis] - mid[axis];
        b.quad(q, facing, albedo, emission);
    };
    // Planes y = level: axis 1, u = z, v = x. Planes x = level: axis 0, u = y, v = z. Planes
    // z = level: axis 2, u = x, v = y.
    b.name("room_floor");
    for j in 0..3 {
        for i in 0..3 {
            cell(&mut b, 1, lo.y, (&zs, i), (&xs, j), floor, black);
        }
    }
    b.name("room_ceiling");
    for j in 0..3 {
        for i in 0..3 {
            if (i, j) != (1, 1) {
                cell(&mut b, 1, hi.y, (&zs, i), (&xs, j), wall, black);
            }
        }
    }
    b.name("room_light");
    cell(&mut b, 1, hi.y, (&zs, 1), (&xs, 1), black, light);
    b.name("room_wall");
    for level in [lo.x, hi.x] {
        for j in 0..3 {
            for i in 0..3 {
                cell(&mut b, 0, level, (&ys, i), (&zs, j), wall, black);
            }
        }
    }
    for level in [lo.z, hi.z] {
        for j in 0..3 {
            for i in 0..3 {
                cell(&mut b, 2, level, (&xs, i), (&ys, j), wall, black);
            }
        }
    }
    debug_assert_eq!(b.corners.len(), ROOM_TRIANGLES);
    Ok(append(object, b))
}

/// The light [`under_light`] puts above `object`, as its (lowest, highest) corners: a horizontal
/// rectangle centred over the object's bounds.
///
/// With the bounds of width `sx`, height `sy`, depth `sz` and largest extent `m` (scene units),
/// the rectangle is `max(sx / 2, m / 10)` by `max(sz / 2, m / 10)` (half the footprint, never a
/// sliver) at `1.5 max(sy, m / 10)` above the object's top.
///
/// Errors: [`Error::Parameter`] for an object without triangles or whose bounds have no extent
/// or are not finite.
pub fn light_above(object: &Scene) -> Result<(DVec3, DVec3)> {
    let (lo, hi, m) = extents(object, "under_light")?;
    let size = hi - lo;
    let c = (lo + hi) * 0.5;
    let half_x = 0.5 * (0.5 * size.x).max(0.1 * m);
    let half_z = 0.5 * (0.5 * size.z).max(0.1 * m);
    let y = hi.y + 1.5 * size.y.max(0.1 * m);
    Ok((
        DVec3::new(c.x - half_x, y, c.z - half_z),
        DVec3::new(c.x + half_x, y, c.z + half_z),
    ))
}

/// Puts a rectangular area light above `object`, facing down, and keeps everything else.
///
/// The object is kept as it is (triangles `0..object.len()`: same order, corners bit for bit,
/// albedo, emission and material names; triangles without a material are named
/// [`OBJECT_MATERIAL`]); the light ([`light_above`]) follows as [`LIGHT_TRIANGLES`] triangles of
/// material `light`: albedo 0, emitted radiance `light_radiance` grey (W/(m^2 sr)). Nothing
/// closes the scene: light that misses the object leaves it. The result has no path and no
/// warnings.
///
/// Errors: [`Error::Parameter`] when `light_radiance` is not finite and > 0, and those of
/// [`light_above`].
pub fn under_light(object: &Scene, light_radiance: f64) -> Result<Scene> {
    check_radiance(light_radiance)?;
    let (a, c) = light_above(object)?;
    let mut b = Builder::default();
    b.name("light");
    b.quad(
        [a, DVec3::new(c.x, a.y, a.z), c, DVec3::new(a.x, a.y, c.z)],
        DVec3::new(0.0, -1.0, 0.0),
        [0.0; 3],
        [light_radiance; 3],
    );
    Ok(append(object, b))
}

fn check_radiance(light_radiance: f64) -> Result<()> {
    if light_radiance.is_finite() && light_radiance > 0.0 {
        Ok(())
    } else {
        Err(Error::Parameter(format!(
            "light radiance {light_radiance} must be finite and > 0"
        )))
    }
}

/// `object` followed by the builder's triangles, with material names: the object's own, or
/// [`OBJECT_MATERIAL`]; the builder's names, made distinct from the object's.
fn append(object: &Scene, extra: Builder) -> Scene {
    let mut names: Vec<String> = object.material_names.clone();
    let object_names: HashSet<&str> = object.material_names.iter().map(String::as_str).collect();
    let mut fresh: HashMap<&str, u32> = HashMap::new();
    let mut fresh_index = |names: &mut Vec<String>, name: &'static str| -> u32 {
        *fresh.entry(name).or_insert_with(|| {
            let mut unique = name.to_string();
            let mut k = 2;
            while object_names.contains(unique.as_str()) {
                unique = format!("{name}_{k}");
                k += 1;
            }
            names.push(unique);
            (names.len() - 1) as u32
        })
    };
    let mut material = Vec::with_capacity(object.len() + extra.corners.len());
    for t in 0..object.len() {
        let own = object
            .material
            .get(t)
            .copied()
            .flatten()
            .filter(|&m| (m as usize) < object.material_names.len());
        material.push(Some(match own {
            Some(m) => m,
            None => fresh_index(&mut names, OBJECT_MATERIAL),
        }));
    }
    for name in &extra.names {
        material.push(name.map(|n| fresh_index(&mut names, n)));
    }
    let mut positions = object.positions.clone();
    let mut triangles = object.triangles.clone();
    for tri in &extra.corners {
        let base = positions.len() as u32;
        positions.extend_from_slice(tri);
        triangles.push([base, base + 1, base + 2]);
    }
    let mut albedo = object.albedo.clone();
    albedo.extend_from_slice(&extra.albedo);
    let mut emission = object.emission.clone();
    emission.extend_from_slice(&extra.emission);
    Scene {
        path: PathBuf::new(),
        positions,
        triangles,
        albedo,
        emission,
        material,
        material_names: names,
        warnings: Vec::new(),
        camera: None,
        lights: object.lights.clone(),
        two_sided: Vec::new(),
    }
}
