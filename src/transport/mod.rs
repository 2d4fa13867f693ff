//! Stage 3: the coupling of one sender patch to one receiver patch, shared by every solver.
//!
//! A coupling is a short list of [`Entry`] values, one per direction bin the sender covers as seen
//! from the receiver. With `N_s(w) = B_s [n_s . w > 0] - A_s[bin(w)]` the net radiance leaving the
//! sender towards the receiver, the receiver's updates are
//!
//! ```text
//! B_r        = E_r + rho_r * sum_entries (f_b * B_s - f_a * A_s[bin])
//! A_r[bin]  +=                 (o_b * B_s - o_a * A_s[bin])
//! ```
//!
//! `f` is the (unoccluded) form factor from r to the part of s that lies in that bin, integrated
//! over r with analytic point-to-triangle form factors; `o` is the solid angle of that part seen
//! from r divided by the bin's solid angle (capped at [`BIN_SHARE_CAP`] per receiver point).
//! The `_b` weights only count receiver points in front of the sender (which sees its B); the `_a`
//! weights count every receiver point (antiradiance leaves both sides of the sender).

use glam::DVec3;
use smallvec::SmallVec;

use crate::geometry::bins::Bins;
use crate::geometry::{self, plane_tol, Poly, Tri};

/// One bin's share of a sender -> receiver coupling.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Entry {
    /// Direction bin of travel (from sender to receiver).
    pub bin: u16,
    /// Form factor weight of the sender's B (receiver points that see the sender's front).
    pub f_b: f32,
    /// Form factor weight of the sender's antiradiance in `bin`.
    pub f_a: f32,
    /// Antiradiance weight of the sender's B: solid angle over bin solid angle.
    pub o_b: f32,
    /// Antiradiance weight of the sender's antiradiance in `bin`.
    pub o_a: f32,
}

/// The entries of one coupling; most far pairs need one, near pairs a handful.
pub type Coupling = SmallVec<[Entry; 4]>;

/// Parameters of the coupling computation.
#[derive(Clone, Copy, Debug)]
pub struct CouplingParams {
    /// Create antiradiance from light arriving at either side (full sphere) instead of the front
    /// only. Needed for open scenes where a one-sided surface is lit from behind.
    pub two_sided: bool,
    /// Receiver quadrature (points per side) for the nearest pairs; 1..=16, default 6 (the
    /// `default` preset uses 4).
    pub near_quadrature: usize,
    /// Largest share of a bin's solid angle one sender piece may have before it is split further;
    /// smaller spreads near senders more finely over bins. Default 0.5.
    pub piece_fraction: f64,
    /// Most times a sender piece that still covers more than `piece_fraction` of a bin, once
    /// the part is cut into the most pieces at once, is cut in four again (see
    /// `refine_piece`); 0 keeps the pieces as cut. Default 16; faint pairs take 0
    /// (`hierarchy::links::exact`).
    pub piece_depth: u32,
}

impl CouplingParams {
    /// The defaults, which are also the `default` solver preset's
    /// ([`crate::solve::SolverOptions::default_preset`] takes `two_sided` and
    /// `near_quadrature` from here).
    pub const DEFAULT: CouplingParams = CouplingParams {
        two_sided: false,
        near_quadrature: 4,
        piece_fraction: 0.5,
        piece_depth: 16,
    };
}

impl Default for CouplingParams {
    fn default() -> Self {
        CouplingParams::DEFAULT
    }
}

/// Geometry of one patch as the coupling needs it.
#[derive(Clone, Copy, Debug)]
pub struct PatchGeom {
    /// Corners, counter-clockwise = front.
    pub corners: Tri,
    /// Unit normal.
    pub normal: DVec3,
    /// Centroid.
    pub centroid: DVec3,
    /// Longest edge.
    pub size: f64,
    /// Radius of the bounding sphere about the centroid.
    pub radius: f64,
    /// Area.
    pub area: f64,
    /// The patch blocks light arriving at its back too: light reaching its back creates
    /// antiradiance, and its antiradiance leaves through both sides (two-sided coupling).
    pub blocks_back: bool,
}

impl PatchGeom {
    /// The same geometry, blocking light at its back when `blocks_back`.
    pub fn blocking_back(mut self, blocks_back: bool) -> PatchGeom {
        self.blocks_back = blocks_back;
        self
    }

    /// The same patch seen from its back: corners in the reverse order, the normal negated
    /// (what a two-sided patch's back face is to a coupling).
    pub fn flipped(&self) -> PatchGeom {
        let [a, b, c] = self.corners;
        PatchGeom {
            corners: [a, c, b],
            normal: -self.normal,
            ..*self
        }
    }

    /// Gathers the geometry of a triangle with a known unit normal.
    pub fn new(corners: Tri, normal: DVec3) -> PatchGeom {
        let centroid = geometry::centroid(&corners);
        PatchGeom {
            corners,
            normal,
            centroid,
            size: geometry::longest_edge(&corners),
            radius: corners
                .iter()
                .map(|c| (*c - centroid).length())
                .fold(0.0, f64::max),
            area: geometry::area(&corners),
            blocks_back: false,
        }
    }
}

/// Distance over receiver size above which one receiver point suffices.
pub const FAR_RATIO: f64 = 6.0;

/// Separation of a pair as the receiver's quadrature sees it: the distance from the receiver's
/// centroid to the sender's bounding sphere, over the receiver's size (longest edge).
pub fn separation(r: &PatchGeom, s: &PatchGeom) -> f64 {
    let gap = (r.centroid - s.centroid).length() - s.radius;
    gap.max(0.0) / r.size.max(f64::MIN_POSITIVE)
}

/// True when the coupling of `s` to `r` needs more than one receiver point or more than one
/// sender piece (and so costs much more than a far pair): what the dense solver caches.
pub fn is_near(r: &PatchGeom, s: &PatchGeom, bins: &Bins, params: &CouplingParams) -> bool {
    let gap = ((r.centroid - s.centroid).length() - s.radius).max(0.0);
    if gap <= FAR_RATIO * r.size {
        return true;
    }
    let omega_estimate = s.area / (gap * gap);
    omega_estimate > params.piece_fraction * bins.min_solid_angle
}

/// Receiver points per side for a pair of the given [`separation`].
fn receiver_quadrature(ratio: f64, near: usize) -> usize {
    if ratio > FAR_RATIO {
        1
    } else if ratio > 3.0 {
        2.min(near)
    } else if ratio > 1.5 {
        3.min(near)
    } else if ratio > 0.6 {
        4.min(near)
    } else {
        near
    }
}

/// Per-bin accumulator of one receiver point: (bin, form factor, solid angle).
type PointBins = SmallVec<[(u16, f64, f64); 8]>;

fn add_point_bin(acc: &mut PointBins, bin: u16, f: f64, omega: f64) {
    if let Some(e) = acc.iter_mut().find(|e| e.0 == bin) {
        e.1 += f;
        e.2 += omega;
    } else {
        acc.push((bin, f, omega));
    }
}

/// Spreads one sender part (a triangle clipped to one side of the receiver's plane) of solid
/// angle `omega` seen from `x` over the bins it covers, splitting it into pieces of at most
/// `piece_fraction` of the smallest bin's solid angle (at most 8 x 8 pieces). `with_ff`: also
/// accumulate each bin's share of the form factor.
fn spread_part(
    x: DVec3,
    n_x: DVec3,
    (part, omega): (&Tri, f64),
    with_ff: bool,
    bins: &Bins,
    params: &CouplingParams,
    acc: &mut PointBins,
) {
    if !(omega > 0.0) {
        return;
    }
    let pieces_needed = omega / (params.piece_fraction * bins.min_solid_angle);
    let m = if pieces_needed <= 1.0 {
        1
    } else {
        (pieces_needed.sqrt().ceil() as usize).min(MAX_PIECES_PER_SIDE)
    };
    if m > 1 {
        // Within one octant a bin is a convex spherical polygon, and the directions from x to
        // the part form the spherical triangle of its corners' directions: when the three
        // corners lie in one bin and one octant, so does the whole part, and every piece would
        // land in that bin.
        let cell = |v: DVec3| {
            let w = x - v;
            let octant =
                u8::from(w.x >= 0.0) | u8::from(w.y >= 0.0) << 1 | u8::from(w.z >= 0.0) << 2;
            (bins.bin_of(w), octant)
        };
        let c0 = cell(part[0]);
        if cell(part[1]) == c0 && cell(part[2]) == c0 {
            // A whole part in one bin (rare: 531 of 3M parts on the bear): its exact form
            // factor costs one contour and is better than the cosine estimate below for a
            // part this large.
            let f = if with_ff {
                geometry::point_form_factor(x, n_x, part)
            } else {
                0.0
            };
            add_point_bin(acc, c0.0 as u16, f, omega);
            return;
        }
    }
    // Pieces still too large once the part is cut into the most at once are cut further.
    let limit = params.piece_fraction * bins.min_solid_angle;
    let depth = if m == MAX_PIECES_PER_SIDE {
        params.piece_depth
    } else {
        0
    };
    let mut add_piece = |piece: &Tri, w: f64| {
        refine_piece(x, n_x, (piece, w), with_ff, bins, limit, depth, acc);
    };
    if m == 1 {
        add_piece(part, omega);
        return;
    }
    // The pieces a lane group at a time, in subdivision order (collected whole, the up to 64
    // pieces were an array of 4.6 kB moved on every call).
    let mut pieces = geometry::subdivide(part, m);
    let mut group = [[DVec3::ZERO; 3]; geometry::LANES];
    loop {
        let mut k = 0;
        for (slot, piece) in group.iter_mut().zip(pieces.by_ref()) {
            *slot = piece;
            k += 1;
        }
        if k == 0 {
            break;
        }
        let w = geometry::solid_angles_at(x, &group[..k]).to_array();
        for (piece, &w) in group[..k].iter().zip(&w) {
            add_piece(piece, w);
        }
        if k < geometry::LANES {
            break;
        }
    }
}

/// Most pieces per side a sender part is cut into at once ([`spread_part`]).
const MAX_PIECES_PER_SIDE: usize = 8;

/// Adds one piece of a sender part (solid angle `w` at `x`) to `acc` by the direction of the
/// centre of the spherical triangle it spans at `x`, first cutting it in four, `depth` times at
/// most (0: as it is), while it covers more than `limit` (steradians): a part cut into the most
/// pieces per side at once can still hold, right beside `x`, one piece with most of the part's
/// solid angle, whose centroid points elsewhere (a rug 0.76 mm above a 4.6 m floor put the
/// whole hemisphere the floor sees of it in grazing bins).
#[allow(clippy::too_many_arguments)]
fn refine_piece(
    x: DVec3,
    n_x: DVec3,
    (piece, w): (&Tri, f64),
    with_ff: bool,
    bins: &Bins,
    limit: f64,
    depth: u32,
    acc: &mut PointBins,
) {
    if !(w > 0.0) {
        return;
    }
    if w <= limit || depth == 0 {
        // The piece's direction is the centre of the spherical triangle it spans at x (the sum
        // of the unit vectors to its corners), not its planar centroid's: seen close and
        // obliquely, most of a piece's solid angle lies on the side nearest x while its
        // centroid lies further out, so a near sender's pieces landed in bins too grazing, and
        // the per-bin cap ([`bin_share`]) cut what overflowed them. A blocker 14 mm under a
        // bright plate stopped 68% of the light it should (the floor beneath 11.7% too
        // bright); docs/ARCHITECTURE.md, "Sender spread".
        let to_piece = (piece[0] - x).normalize_or_zero()
            + (piece[1] - x).normalize_or_zero()
            + (piece[2] - x).normalize_or_zero();
        // Only each bin's share of the part's form factor is used ([`Spread`]): a piece's
        // projected solid angle is taken as its solid angle times the cosine towards that
        // centre. Exact for a small piece, rougher for the near, grazing pieces of a part
        // right beside x.
        let f = if with_ff {
            w * n_x.dot(to_piece.normalize_or_zero()).max(0.0)
        } else {
            0.0
        };
        add_point_bin(acc, bins.bin_of(-to_piece) as u16, f, w);
        return;
    }
    let mut quarters = [[DVec3::ZERO; 3]; 4];
    for (slot, q) in quarters.iter_mut().zip(geometry::subdivide(piece, 2)) {
        *slot = q;
    }
    let ws = geometry::solid_angles_at(x, &quarters).to_array();
    for (q, &wq) in quarters.iter().zip(&ws) {
        refine_piece(x, n_x, (q, wq), with_ff, bins, limit, depth - 1, acc);
    }
}

/// How one spreading point sees the sender: per bin, the fractions of the total form factor and
/// solid angle of the front part, and of the solid angle of the back part.
#[derive(Default)]
struct Spread {
    front: PointBins,
    back: PointBins,
}

impl Spread {
    /// Sets this to the spread at `x` of the `front` parts (their solid angles at `x` in
    /// `front_omega`) and, two-sided, of the `back` parts.
    fn fill(
        &mut self,
        (x, n_x): (DVec3, DVec3),
        (front, front_omega): (&[Tri], [f64; 2]),
        back: &Poly,
        receiver_back: bool,
        bins: &Bins,
        params: &CouplingParams,
    ) {
        self.front.clear();
        self.back.clear();
        for (part, &omega) in front.iter().zip(&front_omega) {
            spread_part(x, n_x, (part, omega), true, bins, params, &mut self.front);
        }
        if receiver_back {
            for part in back.triangles() {
                let omega = geometry::solid_angle(x, &part);
                spread_part(x, n_x, (&part, omega), false, bins, params, &mut self.back);
            }
        }
        for list in [&mut self.front, &mut self.back] {
            let f_total: f64 = list.iter().map(|e| e.1).sum();
            let w_total: f64 = list.iter().map(|e| e.2).sum();
            for e in list.iter_mut() {
                // Where the form factor vanishes at this point (grazing), share it like the
                // solid angle.
                e.1 = if f_total > 0.0 {
                    e.1 / f_total
                } else {
                    e.2 / w_total.max(f64::MIN_POSITIVE)
                };
                e.2 = if w_total > 0.0 { e.2 / w_total } else { 0.0 };
            }
        }
    }
}

/// What [`Seen`] holds per coupling, kept by each thread and refilled on every call: the
/// spreads and the points' form factors were arrays of 1.6 kB and 0.6 kB built and moved on
/// every coupling (the memory copies were 3.5% of the generated classroom's solve).
#[derive(Default)]
struct SeenScratch {
    spreads: Vec<Spread>,
    front_seen: Vec<(f64, f64)>,
}

thread_local! {
    static SEEN_SCRATCH: std::cell::RefCell<SeenScratch> =
        std::cell::RefCell::new(SeenScratch::default());
}

/// Exact form factor (when `with_ff`) and solid angle of `poly` seen from `x` (normal `n_x`).
fn poly_ff_omega(x: DVec3, n_x: DVec3, poly: &Poly, with_ff: bool) -> (f64, f64) {
    if with_ff {
        geometry::poly_form_factor_solid_angle(x, n_x, poly)
    } else {
        (
            0.0,
            poly.triangles().map(|t| geometry::solid_angle(x, &t)).sum(),
        )
    }
}

/// True when anything can travel from `s` to `r`: part of `s` lies strictly in front of `r`'s
/// plane (or behind it, in two-sided mode). Exactly the pairs whose coupling [`couple`] does not
/// skip at once; the receiver's quadrature rule is chosen among them ([`Receiver::for_senders`]).
pub fn exchanges(r: &PatchGeom, s: &PatchGeom, params: &CouplingParams) -> bool {
    let tol = plane_tol(r.size.max(s.size));
    let (front, back) = geometry::clip_by_plane(&s.corners, r.corners[0], r.normal, tol);
    front.len > 0 || (back.len > 0 && (params.two_sided || r.blocks_back))
}

/// The receiver side of every coupling into one patch: one fixed set of quadrature points.
///
/// A receiver integrates the form factors of all its near senders (separation up to
/// [`FAR_RATIO`]) over the same q x q points, q chosen by its nearest sender ([`Self::for_senders`]).
/// In a closed enclosure the point form factors at any one point sum to exactly 1, so a row
/// integrated over one set of points sums to 1 too; choosing the points per pair instead (4 x 4
/// for one sender, 6 x 6 for the next) made rows sum to up to 1.00064, which 1 / (1 - rho)
/// amplifies at high albedo (+53% at 0.999). Far senders use the centroid alone: their form
/// factor varies smoothly over the receiver.
#[derive(Clone, Debug)]
pub struct Receiver {
    /// The receiving patch.
    pub geom: PatchGeom,
    /// Points per side of the quadrature of near senders.
    q: usize,
    /// The q x q quadrature points (centroids of the congruent sub-triangles, equal weights).
    points: Vec<DVec3>,
    /// Points where the split of a sender over bins is measured: min(q, 2)^2 of them.
    spread_points: SmallVec<[DVec3; 4]>,
    /// For each quadrature point, the index of its nearest spreading point.
    nearest: Vec<u8>,
    /// The quadrature points by groups of [`geometry::LANES`] (x, y, z arrays; the last group
    /// padded with copies of the last point), for the vectorized kernel.
    lanes: Vec<[geometry::Lanes; 3]>,
    /// The spreading points likewise (padded with copies of the last).
    spread_lanes: [geometry::Lanes; 3],
}

impl Receiver {
    /// A receiver integrated with `q` x `q` points for its near senders (`q >= 1`).
    pub fn new(geom: PatchGeom, q: usize) -> Receiver {
        let q = q.max(1);
        let centroids = |m: usize| -> Vec<DVec3> {
            if m == 1 {
                vec![geom.centroid]
            } else {
                geometry::subdivide(&geom.corners, m)
                    .map(|t| geometry::centroid(&t))
                    .collect()
            }
        };
        let points = centroids(q);
        let spread_points: SmallVec<[DVec3; 4]> = centroids(q.min(2)).into_iter().collect();
        let nearest = points
            .iter()
            .map(|x| {
                let mut best = 0;
                for (k, p) in spread_points.iter().enumerate() {
                    if (*p - *x).length_squared() < (spread_points[best] - *x).length_squared() {
                        best = k;
                    }
                }
                best as u8
            })
            .collect();
        let lanes = points
            .chunks(geometry::LANES)
            .map(geometry::lanes_of)
            .collect();
        let spread_lanes = geometry::lanes_of(&spread_points);
        Receiver {
            geom,
            q,
            points,
            spread_points,
            nearest,
            lanes,
            spread_lanes,
        }
    }

    /// The receiver with the rule its nearest exchanging sender needs: q from the smallest
    /// [`separation`] to any of `senders` that [`exchanges`] with it (1 when none is nearer
    /// than [`FAR_RATIO`]). Every coupling into this receiver then uses the same points.
    pub fn for_senders<'a>(
        geom: PatchGeom,
        senders: impl IntoIterator<Item = &'a PatchGeom>,
        params: &CouplingParams,
    ) -> Receiver {
        let mut nearest = f64::INFINITY;
        for s in senders {
            let ratio = separation(&geom, s);
            if ratio < nearest && ratio <= FAR_RATIO && exchanges(&geom, s, params) {
                nearest = ratio;
            }
        }
        Receiver::new(geom, receiver_quadrature(nearest, params.near_quadrature))
    }

    /// Points per side of the quadrature of near senders.
    pub fn quadrature(&self) -> usize {
        self.q
    }

    /// Receiver points [`couple`] integrates the sender `s` over.
    pub fn points_for(&self, s: &PatchGeom) -> usize {
        if self.q == 1 || separation(&self.geom, s) > FAR_RATIO {
            1
        } else {
            self.points.len()
        }
    }
}

/// Computes the coupling of sender `s` to receiver `r` into `out` (cleared first).
///
/// The receiver is integrated over its own fixed points (see [`Receiver`]; its centroid alone
/// when the pair's [`separation`] exceeds [`FAR_RATIO`]), each with the exact form factor and
/// solid angle of the sender; how those split over bins is measured at up to 2 x 2 spreading
/// points, each splitting the sender into pieces small against a bin. Per receiver point, no
/// bin receives more solid angle than it spans. Exactly coplanar pairs exchange nothing.
/// Preconditions: both patches have positive area.
pub fn couple(
    receiver: &Receiver,
    s: &PatchGeom,
    bins: &Bins,
    params: &CouplingParams,
    out: &mut Coupling,
) {
    out.clear();
    let r = &receiver.geom;
    let tol = plane_tol(r.size.max(s.size));
    let (front, back) = geometry::clip_by_plane(&s.corners, r.corners[0], r.normal, tol);
    // The receiver takes antiradiance from light arriving at its back; the sender's
    // antiradiance leaves through its front as well as its back.
    let receiver_back = params.two_sided || r.blocks_back;
    let sender_both = params.two_sided || s.blocks_back;
    if front.len == 0 && (back.len == 0 || !receiver_back) {
        return;
    }
    SEEN_SCRATCH.with_borrow_mut(|scratch| {
        let seen = Seen::new(
            receiver,
            s,
            (&front, &back),
            receiver_back,
            (bins, params),
            scratch,
        );
        if receiver_back || sender_both {
            seen.bin_per_point(s, &back, (receiver_back, sender_both), bins, out);
        } else {
            seen.bin_front_only(s, bins, out);
        }
    });
}

/// What the points of one coupling's receiver see of the sender: the points (the centroid alone
/// when far), how each spreading point splits the sender over bins, and the front part's form
/// factor and solid angle at every point.
struct Seen<'a> {
    receiver: &'a Receiver,
    far: bool,
    points: &'a [DVec3],
    spreads: &'a [Spread],
    front_seen: &'a [(f64, f64)],
    weight: f64,
}

impl<'a> Seen<'a> {
    /// What `receiver`'s points see of sender `s`, clipped by the receiver's plane into `front`
    /// and `back` parts (the back part's bins only when `receiver_back`), in `scratch`.
    fn new(
        receiver: &'a Receiver,
        s: &PatchGeom,
        (front, back): (&Poly, &Poly),
        receiver_back: bool,
        (bins, params): (&Bins, &CouplingParams),
        scratch: &'a mut SeenScratch,
    ) -> Seen<'a> {
        let r = &receiver.geom;
        let far = receiver.q == 1 || separation(r, s) > FAR_RATIO;
        let (points, spread_points): (&[DVec3], &[DVec3]) = if far {
            (
                std::slice::from_ref(&r.centroid),
                std::slice::from_ref(&r.centroid),
            )
        } else {
            (&receiver.points, &receiver.spread_points)
        };
        // The front parts' solid angles at the spreading points (four at a time when near).
        let front_parts: SmallVec<[Tri; 2]> = front.triangles().collect();
        let mut front_omega = [[0.0; geometry::LANES]; 2];
        for (part, omega) in front_parts.iter().zip(&mut front_omega) {
            if far {
                omega[0] = geometry::solid_angle(r.centroid, part);
            } else {
                *omega = geometry::solid_angle_lanes(&receiver.spread_lanes, part).to_array();
            }
        }
        let SeenScratch {
            spreads,
            front_seen,
        } = scratch;
        if spreads.len() < spread_points.len() {
            spreads.resize_with(spread_points.len(), Spread::default);
        }
        for (k, (&x, spread)) in spread_points.iter().zip(spreads.iter_mut()).enumerate() {
            let omega = [front_omega[0][k], front_omega[1][k]];
            spread.fill(
                (x, r.normal),
                (&front_parts, omega),
                back,
                receiver_back,
                bins,
                params,
            );
        }
        let spreads = &spreads[..spread_points.len()];
        let weight = 1.0 / points.len() as f64;
        // The front part's form factor and solid angle at every point, a group of points at a time.
        front_seen.clear();
        if far {
            front_seen.push(poly_ff_omega(r.centroid, r.normal, front, true));
        } else {
            for group in &receiver.lanes {
                let (f, w) = geometry::poly_form_factor_solid_angle_lanes(group, r.normal, front);
                front_seen.extend(f.to_array().into_iter().zip(w.to_array()));
            }
        }
        Seen {
            receiver,
            far,
            points,
            spreads,
            front_seen,
            weight,
        }
    }

    /// The spreading point of receiver point `k`.
    fn spread_of(&self, k: usize) -> usize {
        if self.far {
            0
        } else {
            self.receiver.nearest[k] as usize
        }
    }

    /// The entries, point by point: each point's front and (`receiver_back`) back parts'
    /// shares of each bin, its antiradiance weights counted where the sender's antiradiance
    /// reaches it (behind the sender, or anywhere when `sender_both`).
    fn bin_per_point(
        &self,
        s: &PatchGeom,
        back: &Poly,
        (receiver_back, sender_both): (bool, bool),
        bins: &Bins,
        out: &mut Coupling,
    ) {
        let (r, points, spreads, front_seen, weight) = (
            &self.receiver.geom,
            self.points,
            &self.spreads,
            &self.front_seen,
            self.weight,
        );
        let spread_of = |k: usize| self.spread_of(k);
        let facing = |x: DVec3| s.normal.dot(x - s.corners[0]) > 0.0;
        // Per point: the front and back parts' shares of each bin.
        let mut acc = PointBins::new();
        for (k, &x) in points.iter().enumerate() {
            let spread = &spreads[spread_of(k)];
            acc.clear();
            let (f_front, w_front) = front_seen[k];
            for &(bin, f_frac, w_frac) in &spread.front {
                add_point_bin(&mut acc, bin, f_front * f_frac, w_front * w_frac);
            }
            if receiver_back {
                let (_, w_back) = poly_ff_omega(x, r.normal, back, false);
                for &(bin, _, w_frac) in &spread.back {
                    add_point_bin(&mut acc, bin, 0.0, w_back * w_frac);
                }
            }
            let in_front = facing(x);
            for &(bin, f, omega) in &acc {
                let o = bin_share(omega, bins.solid_angle[bin as usize]);
                let entry = entry_of(out, bin);
                if sender_both || !in_front {
                    entry.f_a += (f * weight) as f32;
                    entry.o_a += (o * weight) as f32;
                }
                if in_front {
                    entry.f_b += (f * weight) as f32;
                    entry.o_b += (o * weight) as f32;
                }
            }
        }
    }

    /// The entries when neither side takes antiradiance from behind: the points sharing a
    /// spreading point and a side of the sender differ only by their form factor and solid
    /// angle, so those are summed first; a bin's share of a point's solid angle is capped at
    /// the bin's, which the largest point shows whether it binds.
    fn bin_front_only(&self, s: &PatchGeom, bins: &Bins, out: &mut Coupling) {
        let (points, spreads, front_seen, weight) =
            (self.points, &self.spreads, &self.front_seen, self.weight);
        let spread_of = |k: usize| self.spread_of(k);
        let facing = |x: DVec3| s.normal.dot(x - s.corners[0]) > 0.0;
        #[derive(Clone, Copy, Default)]
        struct Side {
            f: f64,
            w: f64,
            w_max: f64,
            points: u32,
        }
        let mut sides = [[Side::default(); 2]; 4];
        // Each point's (spreading point, side), for the points where the cap binds.
        let mut side_of: SmallVec<[(usize, usize); 36]> = SmallVec::new();
        for (k, &x) in points.iter().enumerate() {
            let key = (spread_of(k), usize::from(facing(x)));
            side_of.push(key);
            let side = &mut sides[key.0][key.1];
            let (f, w) = front_seen[k];
            side.f += f;
            side.w += w;
            side.w_max = side.w_max.max(w);
            side.points += 1;
        }
        for (g, spread) in spreads.iter().enumerate() {
            for (in_front, side) in sides[g].iter().enumerate() {
                if side.points == 0 {
                    continue;
                }
                for &(bin, f_frac, w_frac) in &spread.front {
                    let omega_bin = bins.solid_angle[bin as usize];
                    let o = if side.w_max * w_frac <= omega_bin {
                        side.w * w_frac / omega_bin
                    } else {
                        (0..points.len())
                            .filter(|&k| side_of[k] == (g, in_front))
                            .map(|k| bin_share(front_seen[k].1 * w_frac, omega_bin))
                            .sum()
                    };
                    let (f, o) = ((side.f * f_frac * weight) as f32, (o * weight) as f32);
                    let entry = entry_of(out, bin);
                    if in_front == 1 {
                        entry.f_b += f;
                        entry.o_b += o;
                    } else {
                        entry.f_a += f;
                        entry.o_a += o;
                    }
                }
            }
        }
    }
}

/// Most of a bin's own solid angle that one sender may put in it at one receiver point.
///
/// A sender's pieces are filed whole under one bin each, so a bin next to a piece that
/// straddles its edge is overfilled by as much as its neighbour is short; the sum over the
/// bins is exact. Capped at 1, the overflow was lost, and the antiradiance of a blocker right
/// under a bright surface with it: in `docs/tube_under_housing.py`'s scenes, at 1 / 1.5 / 2,
/// the blocker scene 8.13% / 4.96% / 3.69% from its path tracer and the tube scene 2.09% /
/// 1.46% / 1.34%; the classroom 2.15% / 2.08% / 2.07%, the Cornell box 1.28% / 1.26% / 1.26%,
/// the seed room 2.279% at each. The cap still bounds what one sender can make a bin hold.
pub const BIN_SHARE_CAP: f64 = 2.0;

/// The antiradiance weight of solid angle `omega` (sr) seen by one receiver point in a bin of
/// solid angle `omega_bin`: their ratio, capped at [`BIN_SHARE_CAP`].
fn bin_share(omega: f64, omega_bin: f64) -> f64 {
    (omega / omega_bin).min(BIN_SHARE_CAP)
}

/// The entry of `bin` in `out`, appended (zero) when missing.
pub(crate) fn entry_of(out: &mut Coupling, bin: u16) -> &mut Entry {
    let k = match out.iter().position(|e| e.bin == bin) {
        Some(k) => k,
        None => {
            out.push(Entry {
                bin,
                ..Entry::default()
            });
            out.len() - 1
        }
    };
    &mut out[k]
}

/// Applies one coupling to a receiver's accumulators: adds `f_b B_s - f_a A_s[bin]` to the
/// irradiance sum `h` and `o_b B_s - o_a A_s[bin]` to the receiver's antiradiance bin, reading the
/// sender's radiance `b_s` and its antiradiance in a bin through `anti_s` (not called when
/// `use_anti` is false). `C` is the number of colour channels (3, or 1 for grey scenes).
/// Returns the coupling's share of the receiver's form-factor row sum. Shared by the dense and
/// hierarchical solvers, so their element-to-element transport is the same code.
///
/// # Panics
/// When an entry's bin is out of range of `a_acc`.
pub fn gather_entries<const C: usize>(
    entries: &[Entry],
    b_s: [f64; C],
    anti_s: impl Fn(usize) -> [f64; C],
    use_anti: bool,
    two_sided: bool,
    h: &mut [f64; C],
    a_acc: &mut [[f64; C]],
) -> f64 {
    let mut row = 0.0;
    for e in entries {
        row += if two_sided { e.f_a } else { e.f_a + e.f_b } as f64;
        let bin = e.bin as usize;
        let a_s = if use_anti && (e.f_a != 0.0 || e.o_a != 0.0) {
            anti_s(bin)
        } else {
            [0.0; C]
        };
        for c in 0..C {
            h[c] += e.f_b as f64 * b_s[c] - e.f_a as f64 * a_s[c];
            a_acc[bin][c] += e.o_b as f64 * b_s[c] - e.o_a as f64 * a_s[c];
        }
    }
    row
}

#[cfg(test)]
mod tests;
