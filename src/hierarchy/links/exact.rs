//! The exact element-to-element couplings of link refinement: per receiving element, every
//! exact sender integrated over the receiver's one set of points. A pair with a two-sided
//! element has one link for the faces that see each other, or, when it straddles a plane, one
//! per pair of faces.

use rayon::prelude::*;

use super::{EXACT_RECEIVER_BACK, EXACT_SENDER_BACK};
use crate::geometry::bins::Bins;
use crate::hierarchy::cost::Meter;
use crate::hierarchy::ClusterTree;
use crate::transport::{couple, entry_of, Coupling, CouplingParams, Entry, PatchGeom, Receiver};

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

    /// Merges the links of one element pair pushed since link `first` (one per pair of faces,
    /// [`faces_coupled`]) into one link when they can share its faces: every link whose
    /// entries carry the sender's radiance (`f_b`, `o_b`) reads the same sender face, and every
    /// link whose entries light the receiver (`f_b`, `f_a`) lights the same receiver face. The
    /// antiradiance the pair passes on (`o_a`) and creates (`o_b`) goes to the receiver's bins
    /// whatever its faces. A pair that does not straddle either element's plane sees one face
    /// of each, so its links always merge; a straddling pair keeps its links. The merged
    /// entries hold the sums of the links' entries bin by bin, so the gather adds the same
    /// terms.
    fn merge_faces(&mut self, first: usize) {
        let links = self.senders.len() - first;
        if links < 2 {
            return;
        }
        let n_entries: usize = self.counts[first..].iter().map(|&c| c as usize).sum();
        let start = self.entries.len() - n_entries;
        let (mut sender_face, mut receiver_face) = (None, None);
        let mut at = start;
        for k in first..self.senders.len() {
            let side = self.sides[k];
            let entries = &self.entries[at..at + self.counts[k] as usize];
            at += self.counts[k] as usize;
            let reads_b = entries.iter().any(|e| e.f_b != 0.0 || e.o_b != 0.0);
            let lights = entries.iter().any(|e| e.f_b != 0.0 || e.f_a != 0.0);
            for (used, face, bit) in [
                (reads_b, &mut sender_face, EXACT_SENDER_BACK),
                (lights, &mut receiver_face, EXACT_RECEIVER_BACK),
            ] {
                if used {
                    match *face {
                        Some(f) if f != side & bit => return,
                        _ => *face = Some(side & bit),
                    }
                }
            }
        }
        let mut merged: Coupling = Coupling::new();
        for e in &self.entries[start..] {
            let m = entry_of(&mut merged, e.bin);
            m.f_b += e.f_b;
            m.f_a += e.f_a;
            m.o_b += e.o_b;
            m.o_a += e.o_a;
        }
        let s = self.senders[first];
        let side = sender_face.unwrap_or(0) | receiver_face.unwrap_or(0);
        self.senders.truncate(first);
        self.sides.truncate(first);
        self.counts.truncate(first);
        self.entries.truncate(start);
        self.push(s, side, &merged);
    }
}

/// True when coupling `c` of a two-sided `sender` has no receiver point in front of it (no
/// weight of its front's radiance, `f_b` and `o_b`): its points then see the sender's back, and
/// the back's radiance reaches them with the weights the sender's antiradiance has (`f_a`,
/// `o_a`: it leaves through both faces, `sender.blocks_back`).
fn seen_from_behind(sender: &PatchGeom, coupling: &CouplingParams, c: &Coupling) -> bool {
    (sender.blocks_back || coupling.two_sided) && c.iter().all(|e| e.f_b == 0.0 && e.o_b == 0.0)
}

/// True when all of `sender` lies behind the plane of `receiver`, beyond the tolerance of
/// [`couple`] (which then sees no part of it in front).
fn wholly_behind(receiver: &PatchGeom, sender: &PatchGeom) -> bool {
    let tol = crate::geometry::plane_tol(receiver.size.max(sender.size));
    let (front, _) =
        crate::geometry::clip_by_plane(&sender.corners, receiver.corners[0], receiver.normal, tol);
    front.len == 0
}

/// The one link of a two-sided receiver with a sender wholly behind its plane: what its back
/// face sees of the sender (radiance and antiradiance) and the antiradiance the sender's light
/// makes at its back, which its front would otherwise have taken in a coupling of its own;
/// the sender's back face when the back sees that. The same weights as the two to four links
/// of [`faces_coupled`], from one coupling instead.
fn coupled_behind(
    receiver_back: &Receiver,
    (s, sender, sender_two_sided): (u32, &PatchGeom, bool),
    bins: &Bins,
    coupling: &CouplingParams,
    scratch: &mut Coupling,
    row: &mut Row,
) {
    couple(receiver_back, sender, bins, coupling, scratch);
    let mut side = EXACT_RECEIVER_BACK;
    if sender_two_sided && !scratch.is_empty() && seen_from_behind(sender, coupling, scratch) {
        for e in scratch.iter_mut() {
            (e.f_b, e.o_b) = (e.f_a, e.o_a);
        }
        side |= EXACT_SENDER_BACK;
    }
    if scratch.is_empty() {
        row.empty.push(s);
    } else {
        row.push(s, side, scratch);
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
        // `scratch` holds the front-to-front coupling. When none of its points lie in front of
        // the sender, they see its back, with the weights its antiradiance has there (the
        // sender sends antiradiance through both faces): the same integral as the flipped
        // sender's coupling, which is then not computed again.
        if seen_from_behind(sender, coupling, scratch) {
            for e in scratch.iter_mut() {
                (e.f_b, e.o_b, e.f_a, e.o_a) = (e.f_a, e.o_a, 0.0, 0.0);
            }
            scratch.retain(|e| e.f_b != 0.0 || e.o_b != 0.0);
        } else {
            couple(receiver, back, bins, coupling, scratch);
            keep(scratch, true, true);
        }
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
                if let Some(r_back) = receiver_back
                    .as_ref()
                    .filter(|_| wholly_behind(&geoms[r], &geoms[s as usize]))
                {
                    let sender = (s, &geoms[s as usize], two_sided[s as usize]);
                    coupled_behind(r_back, sender, bins, params, scratch, &mut row);
                    continue;
                }
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
                row.merge_faces(before);
            }
            meter.add(0, 0, pairs.len() as u64, row.entries.len() as u64);
            row
        })
        .collect();
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn entry(bin: u16, [f_b, f_a, o_b, o_a]: [f32; 4]) -> Entry {
        Entry {
            bin,
            f_b,
            f_a,
            o_b,
            o_a,
        }
    }

    /// The entries of each link of `row`, with its faces.
    fn links_of(row: &Row) -> Vec<(u8, Vec<Entry>)> {
        let mut at = 0;
        (row.sides.iter().zip(&row.counts))
            .map(|(&side, &count)| {
                let entries = row.entries[at..at + count as usize].to_vec();
                at += count as usize;
                (side, entries)
            })
            .collect()
    }

    #[test]
    fn back_to_back_pair_merges_into_one_link_of_both_backs() {
        // Each face pair carries one kind of weight: the sender's antiradiance passed on
        // (front to front), its back's radiance making antiradiance (sender back), what the
        // receiver's back sees of its antiradiance (receiver back) and of its back's radiance.
        let mut row = Row::default();
        row.push(7, 0, &[entry(3, [0.0, 0.0, 0.0, 0.1])]);
        row.push(7, EXACT_SENDER_BACK, &[entry(3, [0.0, 0.0, 0.2, 0.0])]);
        let back = [
            entry(3, [0.0, 0.3, 0.0, 0.0]),
            entry(5, [0.0, 0.05, 0.0, 0.0]),
        ];
        row.push(7, EXACT_RECEIVER_BACK, &back);
        let both = [entry(3, [0.4, 0.0, 0.0, 0.0])];
        row.push(7, EXACT_SENDER_BACK | EXACT_RECEIVER_BACK, &both);
        row.merge_faces(0);
        assert_eq!(row.senders, [7]);
        assert_eq!(
            links_of(&row),
            [(
                EXACT_SENDER_BACK | EXACT_RECEIVER_BACK,
                vec![
                    entry(3, [0.4, 0.3, 0.2, 0.1]),
                    entry(5, [0.0, 0.05, 0.0, 0.0])
                ]
            )]
        );
    }

    #[test]
    fn straddling_pair_keeps_a_link_per_face() {
        // Receiver points on both sides of the sender: its front's radiance and its back's
        // reach the receiver's front, so one link cannot say which face to read.
        let mut row = Row::default();
        row.push(2, 0, &[entry(1, [0.5, 0.1, 0.2, 0.1])]);
        row.push(2, EXACT_SENDER_BACK, &[entry(1, [0.3, 0.0, 0.1, 0.0])]);
        let before = links_of(&row);
        row.merge_faces(0);
        assert_eq!(links_of(&row), before);
        assert_eq!(row.senders, [2, 2]);
    }

    #[test]
    fn sender_back_taken_from_the_front_coupling_matches_the_flipped_sender() {
        // A two-sided sender facing away from a receiver in front of it, tilted and offset so
        // that its weights spread over several bins.
        let bins = Bins::new(8);
        let params = CouplingParams::DEFAULT;
        let sender_corners = [
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::new(0.8, 0.1, 1.3),
            DVec3::new(0.1, 0.9, 1.1),
        ];
        let normal = (sender_corners[1] - sender_corners[0])
            .cross(sender_corners[2] - sender_corners[0])
            .normalize();
        // Wound so that its normal points up, away from the receiver below.
        assert!(normal.z > 0.0);
        let sender = PatchGeom::new(sender_corners, normal).blocking_back(true);
        let receiver_geom = PatchGeom::new(
            [
                DVec3::new(-0.5, -0.5, 0.0),
                DVec3::new(1.5, -0.2, 0.0),
                DVec3::new(0.2, 1.5, 0.0),
            ],
            DVec3::Z,
        );
        for q in [1, 4] {
            let receiver = Receiver::new(receiver_geom, q);
            let mut scratch = Coupling::new();
            couple(&receiver, &sender, &bins, &params, &mut scratch);
            assert!(scratch.iter().all(|e| e.f_b == 0.0 && e.o_b == 0.0));
            assert!(scratch.iter().any(|e| e.f_a > 0.0));
            let mut row = Row::default();
            faces_coupled(
                (&receiver, None),
                (0, &sender, true),
                &bins,
                &params,
                &mut scratch,
                &mut row,
            );
            let mut flipped = Coupling::new();
            couple(&receiver, &sender.flipped(), &bins, &params, &mut flipped);
            let links = links_of(&row);
            assert_eq!(links.len(), 1);
            assert_eq!(links[0].0, EXACT_SENDER_BACK);
            let derived = &links[0].1;
            assert_eq!(derived.len(), flipped.len());
            for d in derived {
                let f = flipped.iter().find(|f| f.bin == d.bin).unwrap();
                assert!((d.f_b - f.f_b).abs() <= 1e-6 * f.f_b, "q {q}: {d:?} {f:?}");
                assert!((d.o_b - f.o_b).abs() <= 1e-6 * f.o_b, "q {q}: {d:?} {f:?}");
                assert_eq!((d.f_a, d.o_a), (0.0, 0.0));
            }
        }
    }
}
