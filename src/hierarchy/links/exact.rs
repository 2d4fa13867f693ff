//! The exact element-to-element couplings of link refinement: per receiving element, every
//! exact sender integrated over the receiver's one set of points, per pair of faces that see
//! each other.

use rayon::prelude::*;

use super::{EXACT_RECEIVER_BACK, EXACT_SENDER_BACK};
use crate::geometry::bins::Bins;
use crate::hierarchy::cost::Meter;
use crate::hierarchy::ClusterTree;
use crate::transport::{couple, Coupling, CouplingParams, Entry, PatchGeom, Receiver};

/// The exact links into one receiver: senders, entry counts, entries.
#[derive(Default)]
pub(super) struct Row {
    pub(super) senders: Vec<u32>,
    pub(super) sides: Vec<u8>,
    pub(super) counts: Vec<u32>,
    pub(super) entries: Vec<Entry>,
    pub(super) empty: Vec<u32>,
    pub(super) q: usize,
    pub(super) points: u64,
}
impl Row {
    /// Appends the link from sender `s` (faces `side`) with entries `entries`, unless empty.
    fn push(&mut self, s: u32, side: u8, entries: &[Entry]) {
        if entries.is_empty() {
            return;
        }
        self.senders.push(s);
        self.sides.push(side);
        self.counts.push(entries.len() as u32);
        self.entries.extend_from_slice(entries);
    }
}
/// The links of the faces other than front to front, for a pair where the receiver or the
/// sender is two-sided: the sender's back (its B seen by the receiver points behind it:
/// `f_b`, `o_b` of the flipped sender), the receiver's back (what its back face gathers:
/// `f_b`, `f_a` of the flipped receiver), and both backs. The antiradiance weights the front
/// link already holds are left out of the others.
fn faces_coupled(
    (receiver, receiver_back): (&Receiver, Option<&Receiver>),
    (s, sender, sender_two_sided): (u32, &PatchGeom, bool),
    bins: &Bins,
    coupling: &CouplingParams,
    scratch: &mut Coupling,
    row: &mut Row,
) {
    // The sender's back is seen only from receiver points behind its plane, and the
    // receiver's back only sees what lies behind the receiver's plane.
    let behind = |of: &PatchGeom, corners: &[glam::DVec3; 3]| {
        let tol = crate::geometry::plane_tol(of.size.max(receiver.geom.size));
        corners
            .iter()
            .any(|&c| of.normal.dot(c - of.corners[0]) < -tol)
    };
    let flipped =
        (sender_two_sided && behind(sender, &receiver.geom.corners)).then(|| sender.flipped());
    let receiver_back = receiver_back.filter(|_| behind(&receiver.geom, &sender.corners));
    let keep = |scratch: &mut Coupling, radiance_only: bool, antiradiance_out: bool| {
        for e in scratch.iter_mut() {
            if radiance_only {
                e.f_a = 0.0;
                e.o_a = 0.0;
            }
            if !antiradiance_out {
                e.o_b = 0.0;
                e.o_a = 0.0;
            }
        }
        scratch.retain(|e| e.f_b != 0.0 || e.f_a != 0.0 || e.o_b != 0.0 || e.o_a != 0.0);
    };
    if let Some(back) = &flipped {
        couple(receiver, back, bins, coupling, scratch);
        keep(scratch, true, true);
        row.push(s, EXACT_SENDER_BACK, scratch);
    }
    if let Some(r_back) = receiver_back {
        couple(r_back, sender, bins, coupling, scratch);
        keep(scratch, false, false);
        row.push(s, EXACT_RECEIVER_BACK, scratch);
        if let Some(back) = &flipped {
            couple(r_back, back, bins, coupling, scratch);
            keep(scratch, true, false);
            row.push(s, EXACT_SENDER_BACK | EXACT_RECEIVER_BACK, scratch);
        }
    }
}

/// Most receiver points per side of a faint pair's coupling ([`super::traverse::faint`]: the
/// light it carries is within the flux rule's share whatever its geometry, so a finer
/// quadrature refines next to nothing). Faint pairs do not set the points of their receiver's
/// other pairs either: a receiver has one set for its faint senders and one for the rest, each
/// by the rule of its nearest ([`Receiver::for_senders`], up to 6 x 6). Against one set for
/// all pairs by the nearest of any kind: b90_office (96% of its exact pairs faint) 165.6M ->
/// 46.1M quadrature points, couplings 17.2 -> 11.3 s, 4.09% from its path-traced reference
/// either way (bias +0.87% -> +0.82%); the generated classroom 2.358% -> 2.361%; the seed room
/// 2.279% either way. At 1 x 1: b90_office 4.16%, the classroom 2.37%, and the sliver strip
/// of `tests/stability.rs` 0.6% off. A receiver's row then sums over two point sets (see
/// [`Receiver`] on why one set keeps an enclosure's rows at 1); the faint pairs' share is too
/// small to show: a closed box at albedo 0.99 lit by its ceiling, with two tiny cubes on its
/// floor (226 faint pairs), is within 0.001% of the one-set result.
const FAINT_POINTS: usize = 2;

/// The exact couplings of the element pairs below the node pairs `exact_pairs` (a leaf
/// recorded in a pair may have been split afterwards: the pair then stands for all pairs of
/// elements below its two nodes), one [`Row`] per receiving element; `faint[i]` tells whether
/// `exact_pairs[i]` is faint, whose element pairs take at most [`FAINT_POINTS`] per side.
/// Counts the pairs and entries on `meter` and stops early once it is over.
pub(super) fn couple_exact(
    tree: &ClusterTree,
    exact_pairs: Vec<(u32, u32)>,
    faint: &[bool],
    bins: &Bins,
    coupling: &CouplingParams,
    meter: &Meter,
) -> Vec<Row> {
    let mut exact_pairs: Vec<(u32, u32, bool)> = exact_pairs
        .into_iter()
        .zip(faint)
        .flat_map(|((s, r), &f)| {
            let (s0, s1) = tree.nodes[s as usize].elements;
            let (r0, r1) = tree.nodes[r as usize].elements;
            (r0..r1).flat_map(move |re| (s0..s1).map(move |se| (re, se, f)))
        })
        .collect();
    exact_pairs.sort_unstable();
    let n_elements = tree.elements.len();
    let geoms: Vec<PatchGeom> = tree
        .elements
        .par_iter()
        .map(|&node| {
            let n = &tree.nodes[node as usize];
            PatchGeom::new(n.corners, n.plane.map(|p| p.0).unwrap_or(glam::DVec3::Z))
                .blocking_back(n.blocks_back)
        })
        .collect();
    // Receivers' ranges in `exact_pairs`.
    let mut pair_start = vec![0u32; n_elements + 1];
    for &(r, _, _) in &exact_pairs {
        pair_start[r as usize + 1] += 1;
    }
    for e in 0..n_elements {
        pair_start[e + 1] += pair_start[e];
    }
    let two_sided: Vec<bool> = tree
        .elements
        .iter()
        .map(|&node| tree.nodes[node as usize].two_sided)
        .collect();
    // Faint pairs carry too little light for their nearest pieces to be cut finer over bins
    // (b90_office: couplings 9.3 -> 15.0 s when they were, for 2.88% from its reference
    // against 2.90%).
    let faint_coupling = CouplingParams {
        piece_depth: 0,
        ..*coupling
    };
    let rows: Vec<Row> = (0..n_elements)
        .into_par_iter()
        .map_init(Coupling::new, |scratch, r| {
            let pairs = &exact_pairs[pair_start[r] as usize..pair_start[r + 1] as usize];
            let mut row = Row::default();
            if pairs.is_empty() || meter.is_over() {
                return row;
            }
            // One set of points for the pairs that are not faint (the rule of the nearest of
            // them), and one, at most FAINT_POINTS x FAINT_POINTS, for the faint ones.
            let senders = |faint: bool| {
                (pairs.iter())
                    .filter(move |&&(_, _, f)| f == faint)
                    .map(|&(_, s, _)| &geoms[s as usize])
            };
            let faces = |q: usize| {
                (
                    Receiver::new(geoms[r], q),
                    // A two-sided receiver's back face is integrated over the same points. (It
                    // gathers radiance only: the front's coupling holds the receiver's
                    // antiradiance.)
                    two_sided[r].then(|| Receiver::new(geoms[r].flipped().blocking_back(false), q)),
                )
            };
            let q = Receiver::for_senders(geoms[r], senders(false), coupling).quadrature();
            let q_faint = Receiver::for_senders(geoms[r], senders(true), coupling)
                .quadrature()
                .min(FAINT_POINTS);
            row.q = q;
            let near = faces(q);
            let faint = (q_faint != q).then(|| faces(q_faint));
            for &(_, s, f) in pairs {
                let (receiver, receiver_back) = match (&faint, f) {
                    (Some(faint), true) => faint,
                    _ => &near,
                };
                row.points += receiver.points_for(&geoms[s as usize]) as u64;
                let params = if f { &faint_coupling } else { coupling };
                couple(receiver, &geoms[s as usize], bins, params, scratch);
                if scratch.is_empty() && !two_sided[s as usize] && receiver_back.is_none() {
                    row.empty.push(s);
                    continue;
                }
                let before = row.senders.len();
                row.push(s, 0, scratch);
                if two_sided[r] || two_sided[s as usize] {
                    faces_coupled(
                        (receiver, receiver_back.as_ref()),
                        (s, &geoms[s as usize], two_sided[s as usize]),
                        bins,
                        params,
                        scratch,
                        &mut row,
                    );
                }
                if row.senders.len() == before {
                    row.empty.push(s);
                }
            }
            meter.add(0, 0, pairs.len() as u64, row.entries.len() as u64);
            row
        })
        .collect();
    rows
}
