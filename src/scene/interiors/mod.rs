//! Generated CAD-like interiors: a classroom and an office, meshed the way CAD exporters mesh.
//!
//! Both are built from planar polygons, each fan-triangulated from its first vertex as many
//! exporters do: a floor, a wall or a ceiling is one big polygon with extra vertices along its
//! far edges (where other parts meet it), so its fan is a spray of long slivers; furniture is
//! boxes and cylinders (legs as thin cylinders, caps as fans). A deterministic share
//! [`REVERSED_SHARE`] of the non-emitting polygons is written with reversed winding (back side
//! forward), as CAD exports of two-sided models are; emitters keep their orientation, so the
//! scenes are lit. Lights are materials with `Ke`, so the written scenes solve with default
//! options.
//!
//! - [`classroom`]: a 9 x 3 x 7 m room, a window wall with four openings closed by emissive
//!   sky panes, 24 desks with chairs in six rows, a teacher's desk, a blackboard, a door,
//!   twelve tube lights (thin emissive cylinders under housings); [`CLASSROOM_TRIANGLES`].
//! - [`office`]: a 4 x 2.8 x 5 m room, a window with a deep reveal and an emissive sky pane
//!   behind Venetian blinds (66 slats 0.8 mm thick, 21 mm apart, tilted 40 degrees), a desk with
//!   a monitor, keyboard and mug, a desk lamp with an emissive bulb in its shade, a chair, a
//!   bookshelf full of books; [`OFFICE_TRIANGLES`].
//!
//! Units are metres, y is up, the floor is y = 0. The seed decides which polygons are reversed
//! and a few placements (chairs pulled out, book widths); the same seed gives the same scene,
//! bit for bit, on every platform (only sums, products and quotients: angles come from
//! [`cos_sin_turn`], a fixed polynomial).

use std::ops::RangeInclusive;

use glam::DVec3;

use crate::scene::Scene;

mod cad;

use cad::{Cad, Material};

/// Share of the non-emitting polygons written with reversed winding (each polygon reversed
/// with this probability, drawn from the seed).
pub const REVERSED_SHARE: f64 = 0.3;

/// Triangle counts [`classroom`] stays within for every seed.
pub const CLASSROOM_TRIANGLES: RangeInclusive<usize> = 8_000..=12_000;

/// Triangle counts [`office`] stays within for every seed.
pub const OFFICE_TRIANGLES: RangeInclusive<usize> = 1_500..=6_000;

/// A generated interior: the scene and how its polygons were written.
#[derive(Clone, Debug)]
pub struct Interior {
    /// The scene: triangles in polygon order, materials named, lights as emission.
    pub scene: Scene,
    /// Number of polygons the triangles come from.
    pub polygons: usize,
    /// Number of those written with reversed winding.
    pub reversed_polygons: usize,
    /// Per triangle: true when its polygon was written reversed (its front faces away from
    /// where the polygon's surface faces: into a wall, a box or the floor).
    pub reversed: Vec<bool>,
}

/// `(cos, sin)` of the angle `2 pi i / n` (`n > 0`), from a fixed polynomial on the eighth of
/// the circle nearest to it, so the result is the same on every platform (to within 2 ulp of
/// the true values; checked against the standard library in the tests).
pub fn cos_sin_turn(i: usize, n: usize) -> (f64, f64) {
    let quarter = std::f64::consts::FRAC_PI_2;
    let theta = std::f64::consts::TAU * (i % n) as f64 / n as f64;
    let q = (theta / quarter).round();
    let r = theta - q * quarter;
    let x2 = r * r;
    let s = r
        * (1.0
            - x2 / 6.0
                * (1.0
                    - x2 / 20.0
                        * (1.0
                            - x2 / 42.0
                                * (1.0
                                    - x2 / 72.0
                                        * (1.0
                                            - x2 / 110.0
                                                * (1.0 - x2 / 156.0 * (1.0 - x2 / 210.0)))))));
    let c = 1.0
        - x2 / 2.0
            * (1.0
                - x2 / 12.0
                    * (1.0
                        - x2 / 30.0
                            * (1.0
                                - x2 / 56.0
                                    * (1.0
                                        - x2 / 90.0
                                            * (1.0
                                                - x2 / 132.0
                                                    * (1.0 - x2 / 182.0 * (1.0 - x2 / 240.0)))))));
    match (q as i64).rem_euclid(4) {
        0 => (c, s),
        1 => (-s, c),
        2 => (-c, -s),
        _ => (s, -c),
    }
}

/// `(cos, sin)` of `degrees` (a whole number of degrees), as [`cos_sin_turn`].
fn cos_sin_degrees(degrees: usize) -> (f64, f64) {
    cos_sin_turn(degrees, 360)
}

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

const FLOOR: Material = ("floor", [0.35, 0.33, 0.3], [0.0; 3]);
const WALL: Material = ("wall", [0.7, 0.68, 0.62], [0.0; 3]);
const CEILING: Material = ("ceiling", [0.8, 0.8, 0.78], [0.0; 3]);
const WOOD: Material = ("desk_top", [0.55, 0.4, 0.25], [0.0; 3]);
const METAL: Material = ("metal", [0.5, 0.5, 0.52], [0.0; 3]);
const CHAIR: Material = ("chair", [0.2, 0.3, 0.6], [0.0; 3]);
const BLACKBOARD: Material = ("blackboard", [0.05, 0.15, 0.08], [0.0; 3]);
const DOOR: Material = ("door", [0.45, 0.3, 0.2], [0.0; 3]);
const HOUSING: Material = ("housing", [0.8, 0.8, 0.8], [0.0; 3]);
const TUBE: Material = ("tube", [0.5, 0.5, 0.5], [25.0, 25.0, 23.0]);
const SKY: Material = ("sky", [0.0; 3], [2.0, 2.2, 2.6]);

/// A rectangular wall in the plane z = `z` from x = 0 to `width`, y = 0 to `height`, with a row
/// of openings `openings` (x ranges) from y = `sill` to `head`, facing `facing`: one polygon
/// below the openings and one above (their edges along the openings carry every opening's
/// corners, so they fan into slivers), a pier between every two openings, and each opening
/// closed by a pane of material `pane`.
#[allow(clippy::too_many_arguments)]
fn wall_with_openings(
    cad: &mut Cad,
    z: f64,
    (width, height): (f64, f64),
    (sill, head): (f64, f64),
    openings: &[(f64, f64)],
    facing: DVec3,
    wall: Material,
    pane: Option<Material>,
) {
    // Below: apex (0, 0), then along the bottom, up the far end, back along the sill line.
    let mut below = vec![v(0.0, 0.0, z), v(width, 0.0, z), v(width, sill, z)];
    for &(a, b) in openings.iter().rev() {
        below.push(v(b, sill, z));
        below.push(v(a, sill, z));
    }
    below.push(v(0.0, sill, z));
    cad.polygon(&below, facing, wall);
    // Above: apex (0, height), down to the head line, along it, up the far end.
    let mut above = vec![v(0.0, height, z), v(0.0, head, z)];
    for &(a, b) in openings {
        above.push(v(a, head, z));
        above.push(v(b, head, z));
    }
    above.push(v(width, head, z));
    above.push(v(width, height, z));
    cad.polygon(&above, facing, wall);
    let mut x = 0.0;
    for &(a, b) in openings {
        cad.polygon(
            &[v(x, sill, z), v(a, sill, z), v(a, head, z), v(x, head, z)],
            facing,
            wall,
        );
        if let Some(pane) = pane {
            cad.polygon(
                &[v(a, sill, z), v(b, sill, z), v(b, head, z), v(a, head, z)],
                facing,
                pane,
            );
        }
        x = b;
    }
    cad.polygon(
        &[
            v(x, sill, z),
            v(width, sill, z),
            v(width, head, z),
            v(x, head, z),
        ],
        facing,
        wall,
    );
}

/// A window wall's openings: (sill, head) heights, the openings' x ranges, and the panes'
/// material when they are closed.
type Window<'a> = ((f64, f64), &'a [(f64, f64)], Option<Material>);

/// The shell of a `w x h x d` room from the origin (floor y = 0, window wall z = 0): what
/// [`Cad::big_rectangle`] makes of the floor, the ceiling (one polygon per x range of
/// `ceiling`), the window wall ([`wall_with_openings`]), the back wall and the two side walls,
/// in that order, with `extra` edge vertices on each (floor, ceiling, walls).
struct Shell<'a> {
    size: (f64, f64, f64),
    extra: (usize, usize, usize),
    ceiling: &'a [(f64, f64)],
    /// The window wall's openings (x ranges) from y = sill to head, closed by panes of
    /// `pane` when given.
    window: Window<'a>,
}

impl Shell<'_> {
    fn add(&self, cad: &mut Cad) {
        let (w, h, d) = self.size;
        let (floor_extra, ceiling_extra, wall_extra) = self.extra;
        let up = v(0.0, 1.0, 0.0);
        cad.big_rectangle(
            [
                v(0.0, 0.0, 0.0),
                v(w, 0.0, 0.0),
                v(w, 0.0, d),
                v(0.0, 0.0, d),
            ],
            floor_extra,
            up,
            FLOOR,
        );
        for &(x0, x1) in self.ceiling {
            cad.big_rectangle(
                [v(x0, h, 0.0), v(x1, h, 0.0), v(x1, h, d), v(x0, h, d)],
                ceiling_extra,
                -up,
                CEILING,
            );
        }
        let (sill_head, openings, pane) = self.window;
        wall_with_openings(
            cad,
            0.0,
            (w, h),
            sill_head,
            openings,
            v(0.0, 0.0, 1.0),
            WALL,
            pane,
        );
        cad.big_rectangle(
            [v(0.0, 0.0, d), v(w, 0.0, d), v(w, h, d), v(0.0, h, d)],
            wall_extra,
            v(0.0, 0.0, -1.0),
            WALL,
        );
        cad.big_rectangle(
            [
                v(0.0, 0.0, 0.0),
                v(0.0, 0.0, d),
                v(0.0, h, d),
                v(0.0, h, 0.0),
            ],
            wall_extra,
            v(1.0, 0.0, 0.0),
            WALL,
        );
        cad.big_rectangle(
            [v(w, 0.0, d), v(w, 0.0, 0.0), v(w, h, 0.0), v(w, h, d)],
            wall_extra,
            v(-1.0, 0.0, 0.0),
            WALL,
        );
    }
}

/// Four thin vertical cylinders from y = 0 to `height` at the corners of the rectangle
/// `[x0, x1] x [z0, z1]` (legs).
#[allow(clippy::too_many_arguments)]
fn legs(
    cad: &mut Cad,
    (x0, x1): (f64, f64),
    (z0, z1): (f64, f64),
    height: f64,
    radius: f64,
    sides: usize,
    m: Material,
) {
    for (x, z) in [(x0, z0), (x1, z0), (x1, z1), (x0, z1)] {
        cad.cylinder(1, v(x, 0.0, z), height, radius, sides, true, m);
    }
}

/// The classroom (see the module documentation), with polygon reversals and chair placements
/// drawn from `seed`. Its triangle count is within [`CLASSROOM_TRIANGLES`].
pub fn classroom(seed: u64) -> Interior {
    let mut cad = Cad::new(seed);
    let (w, h, d) = (9.0, 3.0, 7.0);

    // Room shell: the floor, the ceiling in two halves, four walls; the window wall (z = 0)
    // with four openings 1.6 m wide between 0.9 m and 2.5 m.
    let pier = (w - 4.0 * 1.6) / 5.0;
    let openings: Vec<(f64, f64)> = (0..4)
        .map(|i| {
            let a = pier + i as f64 * (1.6 + pier);
            (a, a + 1.6)
        })
        .collect();
    Shell {
        size: (w, h, d),
        extra: (14, 9, 8),
        ceiling: &[(0.0, 4.5), (4.5, w)],
        window: ((0.9, 2.5), &openings, Some(SKY)),
    }
    .add(&mut cad);

    // Blackboard on the back wall, a door against the far side wall.
    cad.block(v(2.0, 0.9, d - 0.03), v(6.0, 2.1, d), BLACKBOARD);
    cad.block(v(w - 0.04, 0.0, 5.6), v(w, 2.1, 6.6), DOOR);

    // Teacher's desk: a top on two side panels, a modesty panel.
    cad.block(v(6.5, 0.72, 6.0), v(8.1, 0.76, 6.75), WOOD);
    cad.block(v(6.52, 0.0, 6.05), v(6.56, 0.72, 6.7), WOOD);
    cad.block(v(8.04, 0.0, 6.05), v(8.08, 0.72, 6.7), WOOD);
    cad.block(v(6.56, 0.25, 6.66), v(8.04, 0.7, 6.69), WOOD);

    // Desks with chairs behind them, facing the board.
    for row in 0..6 {
        let z = 1.0 + 0.9 * row as f64;
        for x in [1.4, 3.45, 5.55, 7.6] {
            desk_and_chair(&mut cad, x, z);
        }
    }

    // Tube lights: 1.2 m tubes of radius 16 mm under housings hanging from the ceiling.
    for z in [1.5, 3.5, 5.5] {
        for x in [1.4, 3.45, 5.55, 7.6] {
            cad.block(
                v(x - 0.64, 2.83, z - 0.06),
                v(x + 0.64, 2.9, z + 0.06),
                HOUSING,
            );
            cad.cylinder(0, v(x - 0.6, 2.8, z), 1.2, 0.016, 16, true, TUBE);
        }
    }
    cad.build()
}

/// A classroom desk centred at (`x`, `z`) (a 1.2 x 0.6 m top on four thin legs) and its chair
/// behind it, pulled out by 0-10 cm.
fn desk_and_chair(cad: &mut Cad, x: f64, z: f64) {
    cad.block(v(x - 0.6, 0.72, z - 0.3), v(x + 0.6, 0.75, z + 0.3), WOOD);
    legs(
        cad,
        (x - 0.55, x + 0.55),
        (z - 0.25, z + 0.25),
        0.72,
        0.02,
        10,
        METAL,
    );
    let pull = 0.1 * cad.rng.next_f64();
    let (cx, cz) = (x, z - 0.5 - pull);
    cad.block(
        v(cx - 0.21, 0.43, cz - 0.21),
        v(cx + 0.21, 0.46, cz + 0.21),
        CHAIR,
    );
    cad.block(
        v(cx - 0.21, 0.52, cz - 0.22),
        v(cx + 0.21, 0.85, cz - 0.2),
        CHAIR,
    );
    legs(
        cad,
        (cx - 0.18, cx + 0.18),
        (cz - 0.18, cz + 0.18),
        0.43,
        0.012,
        8,
        METAL,
    );
    for px in [cx - 0.18, cx + 0.18] {
        cad.cylinder(1, v(px, 0.46, cz - 0.18), 0.39, 0.012, 8, true, METAL);
    }
}

const SLAT: Material = ("slat", [0.75, 0.75, 0.72], [0.0; 3]);
const CORD: Material = ("cord", [0.6, 0.6, 0.58], [0.0; 3]);
const SHADE: Material = ("shade", [0.6, 0.55, 0.45], [0.0; 3]);
const BULB: Material = ("bulb", [0.5, 0.5, 0.5], [60.0, 52.0, 40.0]);
const OFFICE_SKY: Material = ("sky", [0.0; 3], [3.0, 3.3, 3.8]);
const SCREEN: Material = ("screen", [0.04, 0.04, 0.05], [0.0; 3]);
const PLASTIC: Material = ("plastic", [0.15, 0.15, 0.16], [0.0; 3]);
const MUG: Material = ("mug", [0.7, 0.2, 0.15], [0.0; 3]);
const SHELF: Material = ("shelf", [0.6, 0.5, 0.35], [0.0; 3]);
const BOOKS: [Material; 3] = [
    ("book_red", [0.5, 0.1, 0.1], [0.0; 3]),
    ("book_blue", [0.1, 0.15, 0.45], [0.0; 3]),
    ("book_cream", [0.7, 0.65, 0.5], [0.0; 3]),
];

/// The office's window: from x = 0.9 to 3.1 m, y = 0.85 to 2.35 m, in the wall z = 0.
const OFFICE_WINDOW: (f64, f64, f64, f64) = (0.9, 3.1, 0.85, 2.35);

/// The office (see the module documentation), with polygon reversals and book widths drawn
/// from `seed`. Its triangle count is within [`OFFICE_TRIANGLES`].
pub fn office(seed: u64) -> Interior {
    let mut cad = Cad::new(seed);
    let (w, h, d) = (4.0, 2.8, 5.0);
    let (wx0, wx1, sill, head) = OFFICE_WINDOW;

    // Room shell: large polygons.
    Shell {
        size: (w, h, d),
        extra: (10, 10, 6),
        ceiling: &[(0.0, w)],
        window: ((sill, head), &[(wx0, wx1)], None),
    }
    .add(&mut cad);
    window_reveal(&mut cad);
    blinds(&mut cad);
    let top = 0.76;
    office_desk(&mut cad, top);
    desk_lamp(&mut cad, top);
    office_chair(&mut cad);
    bookshelf(&mut cad, w);
    cad.build()
}

/// The office window's reveal, 25 cm deep, and the sky pane closing it.
fn window_reveal(cad: &mut Cad) {
    let (wx0, wx1, sill, head) = OFFICE_WINDOW;
    let up = v(0.0, 1.0, 0.0);
    let back = -0.25;
    cad.polygon(
        &[
            v(wx0, sill, 0.0),
            v(wx1, sill, 0.0),
            v(wx1, sill, back),
            v(wx0, sill, back),
        ],
        up,
        WALL,
    );
    cad.polygon(
        &[
            v(wx0, head, 0.0),
            v(wx1, head, 0.0),
            v(wx1, head, back),
            v(wx0, head, back),
        ],
        -up,
        WALL,
    );
    cad.polygon(
        &[
            v(wx0, sill, 0.0),
            v(wx0, head, 0.0),
            v(wx0, head, back),
            v(wx0, sill, back),
        ],
        v(1.0, 0.0, 0.0),
        WALL,
    );
    cad.polygon(
        &[
            v(wx1, sill, 0.0),
            v(wx1, head, 0.0),
            v(wx1, head, back),
            v(wx1, sill, back),
        ],
        v(-1.0, 0.0, 0.0),
        WALL,
    );
    cad.polygon(
        &[
            v(wx0, sill, back),
            v(wx1, sill, back),
            v(wx1, head, back),
            v(wx0, head, back),
        ],
        v(0.0, 0.0, 1.0),
        OFFICE_SKY,
    );
}

/// Venetian blinds in front of the office window: 66 slats 2.3 m x 25 mm x 0.8 mm, 21 mm
/// apart, tilted 40 degrees about their long axis, a head rail, a bottom rail, four ladder
/// cords.
fn blinds(cad: &mut Cad) {
    let (wx0, wx1, _, head) = OFFICE_WINDOW;
    let (bx0, bx1, bz) = (wx0 - 0.05, wx1 + 0.05, 0.06);
    let (c, s) = cos_sin_degrees(40);
    let across = v(0.0, s, c) * 0.0125;
    let thick = v(0.0, c, -s) * 0.0004;
    let slats = 66;
    for i in 0..slats {
        let y = head - 0.03 - 0.021 * i as f64;
        cad.slab(
            v(0.5 * (bx0 + bx1), y, bz),
            [v(0.5 * (bx1 - bx0), 0.0, 0.0), across, thick],
            SLAT,
        );
    }
    let bottom = head - 0.03 - 0.021 * (slats - 1) as f64 - 0.02;
    cad.block(
        v(bx0, head - 0.01, bz - 0.03),
        v(bx1, head + 0.04, bz + 0.03),
        SLAT,
    );
    cad.block(
        v(bx0, bottom - 0.012, bz - 0.012),
        v(bx1, bottom, bz + 0.012),
        SLAT,
    );
    for x in [bx0 + 0.35, bx1 - 0.35] {
        for z in [bz - 0.012, bz + 0.012] {
            cad.cylinder(
                1,
                v(x, bottom, z),
                head - 0.01 - bottom,
                0.001,
                6,
                true,
                CORD,
            );
        }
    }
}

/// The office desk facing the window, its top at height `top` (a top on two side panels, a
/// modesty panel), with a monitor (stand, screen), a keyboard and a mug on it.
fn office_desk(cad: &mut Cad, top: f64) {
    let (dx0, dx1, dz0, dz1) = (1.2, 2.8, 1.2, 2.0);
    cad.block(v(dx0, top - 0.04, dz0), v(dx1, top, dz1), WOOD);
    cad.block(
        v(dx0 + 0.02, 0.0, dz0 + 0.05),
        v(dx0 + 0.05, top - 0.04, dz1 - 0.05),
        WOOD,
    );
    cad.block(
        v(dx1 - 0.05, 0.0, dz0 + 0.05),
        v(dx1 - 0.02, top - 0.04, dz1 - 0.05),
        WOOD,
    );
    cad.block(
        v(dx0 + 0.05, 0.3, dz0 + 0.05),
        v(dx1 - 0.05, top - 0.06, dz0 + 0.07),
        WOOD,
    );
    cad.block(v(1.9, top, 1.3), v(2.1, top + 0.01, 1.45), PLASTIC);
    cad.block(
        v(1.98, top + 0.01, 1.36),
        v(2.02, top + 0.12, 1.39),
        PLASTIC,
    );
    cad.block(v(1.72, top + 0.12, 1.33), v(2.28, top + 0.45, 1.36), SCREEN);
    cad.block(v(1.78, top, 1.55), v(2.22, top + 0.02, 1.7), PLASTIC);
    cad.cylinder(1, v(2.45, top, 1.75), 0.1, 0.04, 20, true, MUG);
}

/// A desk lamp standing on the desk top at height `top`: a base, an arm, a shade (outside and
/// inside) with an emissive bulb in it.
fn desk_lamp(cad: &mut Cad, top: f64) {
    let up = v(0.0, 1.0, 0.0);
    let (lx, lz) = (1.45, 1.45);
    cad.cylinder(1, v(lx, top, lz), 0.02, 0.07, 24, true, METAL);
    cad.cylinder(1, v(lx, top + 0.02, lz), 0.32, 0.008, 8, true, METAL);
    let shade = top + 0.3;
    cad.cylinder(1, v(lx, shade, lz), 0.12, 0.09, 24, false, SHADE);
    cad.cylinder_inside(v(lx, shade, lz), 0.12, 0.089, 24, SHADE);
    let ring: Vec<DVec3> = (0..24)
        .map(|i| {
            let (c, s) = cos_sin_turn(i, 24);
            v(lx + 0.09 * c, shade + 0.12, lz + 0.09 * s)
        })
        .collect();
    cad.polygon(&ring, up, SHADE);
    let inner: Vec<DVec3> = ring.iter().map(|p| v(p.x, p.y - 0.001, p.z)).collect();
    cad.polygon(&inner, -up, SHADE);
    cad.cylinder(1, v(lx, shade + 0.04, lz), 0.05, 0.02, 12, true, BULB);
}

/// The office chair, pulled out by 0-10 cm: a base disc, a column, a seat, a back.
fn office_chair(cad: &mut Cad) {
    let (chx, chz) = (2.0, 2.45 + 0.1 * cad.rng.next_f64());
    cad.cylinder(1, v(chx, 0.02, chz), 0.03, 0.3, 24, true, PLASTIC);
    cad.cylinder(1, v(chx, 0.05, chz), 0.38, 0.025, 12, true, METAL);
    cad.block(
        v(chx - 0.24, 0.43, chz - 0.24),
        v(chx + 0.24, 0.5, chz + 0.24),
        CHAIR,
    );
    cad.block(
        v(chx - 0.22, 0.55, chz + 0.24),
        v(chx + 0.22, 1.0, chz + 0.28),
        CHAIR,
    );
}

/// A bookshelf against the side wall x = `w`: two sides, a back, six boards, books of drawn
/// widths and heights on the lower five.
fn bookshelf(cad: &mut Cad, w: f64) {
    let (sx0, sx1, sz0, sz1, sh) = (w - 0.36, w - 0.01, 2.5, 4.0, 2.0);
    cad.block(v(sx0, 0.0, sz0), v(sx1, sh, sz0 + 0.02), SHELF);
    cad.block(v(sx0, 0.0, sz1 - 0.02), v(sx1, sh, sz1), SHELF);
    cad.block(
        v(sx1 - 0.01, 0.0, sz0 + 0.02),
        v(sx1, sh, sz1 - 0.02),
        SHELF,
    );
    for k in 0..6 {
        let y = 0.05 + 0.38 * k as f64;
        cad.block(
            v(sx0, y, sz0 + 0.02),
            v(sx1 - 0.01, y + 0.02, sz1 - 0.02),
            SHELF,
        );
        if k == 5 {
            break;
        }
        let mut z = sz0 + 0.03;
        let mut b = 0;
        while z < sz1 - 0.15 {
            let width = 0.025 + 0.03 * cad.rng.next_f64();
            let tall = 0.22 + 0.1 * cad.rng.next_f64();
            cad.block(
                v(sx0 + 0.03, y + 0.02, z),
                v(sx1 - 0.03, y + 0.02 + tall, z + width),
                BOOKS[b % 3],
            );
            z += width + 0.004;
            b += 1;
        }
    }
}
