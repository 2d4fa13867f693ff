//! The per-sweep sums of the fields (their expansions at each node) and their evaluation at
//! each element.

use super::*;

/// Irradiance field terms per channel: `G` at the centre (3), its Jacobian's symmetric part
/// (6: `xx, xy, xz, yy, yz, zz`) and antisymmetric part (3: `xy, xz, yz`), and its second
/// derivatives `N_pqr = d_q d_r G_p` (18: per `p`, the six `q <= r` in the same order) of
/// [`SweepContext::sum_fields`].
pub(super) const IRR_TERMS: usize = 30;

/// The pairs `(q, r)`, `q <= r`, in the order of a symmetric 3 x 3 matrix's upper triangle.
const UPPER: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// Antiradiance field terms per channel: the value at the centre, its gradient (3) and its
/// symmetric Hessian (6).
pub(super) const ANTI_TERMS: usize = 10;

/// One sweep's field sums: per irradiance group, the [`IRR_TERMS`] of its `G` per channel; per
/// slot, the antiradiance, its gradient and its Hessian's upper triangle.
pub(crate) struct FieldSums<const C: usize> {
    pub(super) irr: Vec<[[f32; C]; IRR_TERMS]>,
    pub(super) anti: Vec<[[f32; C]; ANTI_TERMS]>,
}

impl<const C: usize> FieldSums<C> {
    /// Zeroed sums for `fields`.
    pub(crate) fn new(fields: &Fields) -> Self {
        FieldSums {
            irr: vec![[[0.0; C]; IRR_TERMS]; fields.group_mask.len()],
            anti: vec![[[0.0; C]; ANTI_TERMS]; fields.live_slots],
        }
    }
}

impl SweepContext<'_> {
    /// Sums every field's links (intensities `intensity`) into `sums`. Per link with sender
    /// point `c_s`, spread `s`, and `v = c_r - c_s` from it to the field's centre (`r = |v|`,
    /// `D = r^2 + s`, `h = 1 / (r D)`, `q = h' / r`, `k = -1 / pi`):
    ///
    /// - the irradiance field `G = k h v`, its Jacobian `k (h I + q v v^T)` and its second
    ///   derivatives `N_pqr = k (q (d_qr v_p + d_pq v_r + d_pr v_q) + (q' / r) v_p v_q v_r)`:
    ///   an element at `c_r + x` with normal `n` gets `n . G + n . J x + N(n, x, x) / 2`;
    /// - the antiradiance `1 / (D Omega)`, its gradient `-2 v / (D^2 Omega)` and Hessian
    ///   `(-2 I / D^2 + 8 v v^T / D^3) / Omega`;
    /// - both times the sender's cosine toward the point over the link's
    ///   ([`crate::hierarchy::links::NodePoint::cosine_ratio`]) for a flat sender, to second
    ///   order: `t = (n_s . v) / (r n_s . w)`, with gradient `(n_s - t' v / r) / (r n_s . w)`
    ///   (`t' = n_s . v / r`) and Hessian `(3 a v v^T / r^2 - a I - n_s v^T - v n_s^T) /
    ///   (r^3 n_s . w)` (`a = n_s . v`). The product `t G` adds `G grad(t)^T` to the Jacobian
    ///   (no longer symmetric: its antisymmetric part is kept apart) and `J_pq t_r + J_pr t_q +
    ///   G_p t_qr` to `N_pqr`; `t phi` adds `phi grad(t)` to the
    ///   antiradiance's gradient and `grad(t) grad(phi)^T + grad(phi) grad(t)^T + phi H(t)` to
    ///   its Hessian. Such links are fields only while the linear term stays within
    ///   [`super::FIELD_TURN`] (`field_key`).
    ///
    /// A first-order expansion was tried: the kernels are convex, so it is low everywhere but
    /// at the centre (the room 0.17% darker), and its remainder limited the fields to
    /// receivers of 0.15-0.2 of the distance.
    pub(crate) fn sum_fields<const C: usize>(
        &self,
        fields: &Fields,
        links: &Links,
        intensity: &[[f32; C]],
        sums: &mut FieldSums<C>,
    ) {
        let anti_parts = split_by_start(&mut sums.anti, &fields.sum_start);
        let irr_parts = split_by_start(&mut sums.irr, &fields.group_start);
        anti_parts
            .into_par_iter()
            .zip(irr_parts.into_par_iter())
            .enumerate()
            .for_each(|(f, (anti, irr))| {
                let g0 = fields.group_start[f] as usize;
                for (g, irr) in irr.iter_mut().enumerate() {
                    let mut acc = [[0.0f64; C]; IRR_TERMS];
                    let slots = fields.group_slots[g0 + g] as usize
                        ..fields.group_slots[g0 + g + 1] as usize;
                    for s in slots {
                        let sum = fields.slot_sum[s];
                        let a =
                            self.sum_slot(fields, links, intensity, (f, s), &mut acc, sum != NONE);
                        if sum != NONE {
                            anti[(sum - fields.sum_start[f]) as usize] = a;
                        }
                    }
                    *irr = acc.map(|x| x.map(|y| y as f32));
                }
            });
    }

    /// The links of slot `s` of field `f`: adds their irradiance terms to `irr` and returns
    /// their antiradiance terms (0 unless `with_anti`), each link's terms from the cache when
    /// there is one ([`Fields::cache_terms`]).
    fn sum_slot<const C: usize>(
        &self,
        fields: &Fields,
        links: &Links,
        intensity: &[[f32; C]],
        (f, s): (usize, usize),
        irr: &mut [[f64; C]; IRR_TERMS],
        with_anti: bool,
    ) -> [[f32; C]; ANTI_TERMS] {
        let mut a = [[0.0f64; C]; ANTI_TERMS];
        let cached = f + 1 < fields.term_start.len();
        let first = fields.near_end[fields.node[f] as usize] as usize;
        for j in fields.slot_links(f, s) {
            let i = intensity[j].map(f64::from);
            if cached {
                // Widened term by term: a widened copy of the 40 terms cost more than the sums.
                let t = &fields.terms[fields.term_start[f] as usize + (j - first)];
                add_terms(irr, &t[..IRR_TERMS], &i);
                if with_anti {
                    add_terms(&mut a, &t[IRR_TERMS..], &i);
                }
            } else {
                let (t, a_t) = self.link_terms(fields, links, (f, s, j), with_anti);
                add_terms(irr, &t, &i);
                if with_anti {
                    add_terms(&mut a, &a_t, &i);
                }
            }
        }
        a.map(|x| x.map(|y| y as f32))
    }

    /// The field terms of link `j` in slot `s` of field `f` per unit of its intensity:
    /// irradiance ([`IRR_TERMS`]) and antiradiance ([`ANTI_TERMS`], 0 unless `with_anti`).
    pub(super) fn link_terms(
        &self,
        fields: &Fields,
        links: &Links,
        (f, s, j): (usize, usize, usize),
        with_anti: bool,
    ) -> ([f64; IRR_TERMS], [f64; ANTI_TERMS]) {
        let center = fields.center[f];
        // The receiving elements' extent, when they share the field node's plane.
        let receiver = self.tree.nodes[fields.node[f] as usize]
            .plane
            .map(|(normal, _)| (fields.element_spread[f] as f64, normal));
        let (bin, _) = fields.slot_bin(s);
        let omega = self.bins.solid_angle[bin];
        let k = -std::f64::consts::FRAC_1_PI;
        let mut a_t = [0.0f64; ANTI_TERMS];
        let link = &links.cluster[j];
        let sender = &self.points[link.sender as usize];
        let v = center - sender.centroid();
        let r2 = v.length_squared();
        if !(r2 > 0.0) {
            return ([0.0; IRR_TERMS], a_t);
        }
        let r = r2.sqrt();
        let inv_r = 1.0 / r;
        let kernel = sender.kernel_toward(v, r2, inv_r);
        let vv = [v.x, v.y, v.z];
        // The sender's cosine toward x over the link's, t(x), at the centre, with its
        // gradient and Hessian.
        let flat_sender = self.flat_sender(link);
        let (turn, turn_grad, turn_hess) = match flat_sender {
            Some((n_s, c_link)) => {
                let a = n_s.dot(v);
                let turn = crate::hierarchy::links::cosine_ratio(c_link, a * inv_r);
                if turn > 0.0 {
                    let grad = (n_s - v * (a * inv_r * inv_r)) * (inv_r / c_link);
                    let scale = inv_r * inv_r * inv_r / c_link;
                    let nn = n_s.to_array();
                    let hess: [[f64; 3]; 3] = std::array::from_fn(|p| {
                        std::array::from_fn(|q| {
                            let diagonal = if p == q { a } else { 0.0 };
                            scale
                                * (3.0 * a * vv[p] * vv[q] * inv_r * inv_r
                                    - diagonal
                                    - nn[p] * vv[q]
                                    - vv[p] * nn[q])
                        })
                    });
                    (turn, grad, hess)
                } else {
                    (turn, DVec3::ZERO, [[0.0; 3]; 3])
                }
            }
            None => (1.0, DVec3::ZERO, [[0.0; 3]; 3]),
        };
        let tg = turn_grad.to_array();
        let spread = kernel.irradiance
            + receiver.map_or(0.0, |(s_e, n_e)| {
                crate::hierarchy::links::receiver_spread(s_e, n_e.dot(v) * inv_r, r2)
            });
        let big_d = r2 + spread;
        let big_d_ar = r2 + kernel.anti;
        if self.use_anti && with_anti {
            let phi = 1.0 / (big_d_ar * omega);
            let phi_grad = v * (-2.0 * phi / big_d_ar);
            let grad = phi_grad * turn + turn_grad * phi;
            let phi_grad = phi_grad.to_array();
            let hess = |p: usize, q: usize| {
                turn * phi * ((if p == q { -2.0 } else { 0.0 }) + 8.0 * vv[p] * vv[q] / big_d_ar)
                    / big_d_ar
                    + tg[p] * phi_grad[q]
                    + phi_grad[p] * tg[q]
                    + phi * turn_hess[p][q]
            };
            a_t = [
                turn * phi,
                grad.x,
                grad.y,
                grad.z,
                hess(0, 0),
                hess(0, 1),
                hess(0, 2),
                hess(1, 1),
                hess(1, 2),
                hess(2, 2),
            ];
        }
        let r3 = r2 * r;
        let h = 1.0 / (r * big_d);
        let q = -(3.0 * r2 + spread) / (r3 * big_d * big_d);
        let dq_over_r = -(6.0 / (r3 * big_d * big_d)
            - 3.0 * (3.0 * r2 + spread) / (r3 * r2 * big_d * big_d)
            - 4.0 * (3.0 * r2 + spread) / (r3 * big_d * big_d * big_d));
        // G, with the sender's tilt term at the centre (`n . G` gains `-n . tilt / (pi
        // D^2)`; its variation over the field is left out).
        let g = v * (k * h) + kernel.tilt * (k / (big_d * big_d));
        let gg = g.to_array();
        // G's Jacobian, and that of t G: t J + G grad(t)^T.
        let flat = turn_grad != DVec3::ZERO;
        let radial: [[f64; 3]; 3] = std::array::from_fn(|p| {
            std::array::from_fn(|s| k * ((if p == s { h } else { 0.0 }) + q * vv[p] * vv[s]))
        });
        let jac: [[f64; 3]; 3] =
            std::array::from_fn(|p| std::array::from_fn(|s| turn * radial[p][s] + gg[p] * tg[s]));
        let sym = |p: usize, s: usize| 0.5 * (jac[p][s] + jac[s][p]);
        let anti = |p: usize, s: usize| 0.5 * (jac[p][s] - jac[s][p]);
        let mut t = [0.0f64; IRR_TERMS];
        // The receiving elements' cross term at the centre (a flat sender's to a flat
        // receiver's; see `SweepContext::pair_factor`), per unit of the link's intensity;
        // its variation over the field is left out.
        let cross = match (flat_sender, receiver) {
            (Some((n_s, c_link)), Some((s_e, n_plane))) if turn > 0.0 => {
                let cos_r = -n_plane.dot(v) * inv_r;
                let n_r = if cos_r > 0.0 { n_plane } else { -n_plane };
                let weight = crate::hierarchy::links::expansion_weight(r2, s_e);
                n_r * (-k * -(weight * s_e * n_s.dot(n_r) * cos_r * cos_r)
                    / (big_d * big_d * c_link))
            }
            _ => DVec3::ZERO,
        };
        t[..3].copy_from_slice(&(g * turn + cross).to_array());
        t[3..9].copy_from_slice(&[
            sym(0, 0),
            sym(0, 1),
            sym(0, 2),
            sym(1, 1),
            sym(1, 2),
            sym(2, 2),
        ]);
        t[9..12].copy_from_slice(&[anti(0, 1), anti(0, 2), anti(1, 2)]);
        // N: t times G's own second derivatives, plus the cosine's terms.
        let delta = |a: usize, b: usize| if a == b { 1.0 } else { 0.0 };
        let (tkq, tkr) = (turn * k * q, turn * k * dq_over_r);
        for p in 0..3 {
            for (u, &(a, b)) in UPPER.iter().enumerate() {
                let mut n = tkq * (delta(a, b) * vv[p] + delta(p, a) * vv[b] + delta(p, b) * vv[a])
                    + tkr * vv[p] * vv[a] * vv[b];
                if flat {
                    n += radial[p][a] * tg[b] + radial[p][b] * tg[a] + gg[p] * turn_hess[a][b];
                }
                t[12 + 6 * p + u] = n;
            }
        }
        (t, a_t)
    }

    /// Adds the fields on element `e`'s path to its front irradiance `h`, its back face's
    /// `h_back` (two-sided elements) and its antiradiance bins `a_acc`.
    #[allow(clippy::needless_range_loop)]
    pub(crate) fn gather_fields<const C: usize>(
        &self,
        e: usize,
        (fields, sums): (&Fields, &FieldSums<C>),
        a_acc: &mut [[f64; C]],
        (h, h_back): (&mut [f64; C], &mut [f64; C]),
    ) {
        let n = self.elem_normal[e];
        let x = self.elem_center[e];
        let back = self.two_sided || self.elem_back[e];
        let two = self.elem_two.get(e).copied().unwrap_or(false);
        for (f, k) in fields.path_slabs(e) {
            let bit = 1u16 << k;
            let dx = x - fields.center[f];
            let w = irradiance_weights(n, dx);
            for g in fields.group_start[f] as usize..fields.group_start[f + 1] as usize {
                let front = fields.group_mask[g] & bit != 0;
                if !front && !two {
                    continue;
                }
                let t = &sums.irr[g];
                let mut value = [0.0f64; C];
                for k in 0..IRR_TERMS {
                    for c in 0..C {
                        value[c] += w[k] * t[k][c] as f64;
                    }
                }
                // Behind: n . G is the (negative) irradiance of the back face.
                let (out, sign) = if front {
                    (&mut *h, 1.0)
                } else {
                    (&mut *h_back, -1.0)
                };
                for c in 0..C {
                    out[c] += sign * value[c];
                }
            }
            if self.use_anti {
                let wa = [
                    1.0,
                    dx.x,
                    dx.y,
                    dx.z,
                    0.5 * dx.x * dx.x,
                    dx.x * dx.y,
                    dx.x * dx.z,
                    0.5 * dx.y * dx.y,
                    dx.y * dx.z,
                    0.5 * dx.z * dx.z,
                ];
                for s in fields.slot_start[f] as usize..fields.slot_start[f + 1] as usize {
                    let (bin, mask) = fields.slot_bin(s);
                    if !back && mask & bit == 0 {
                        continue;
                    }
                    let sum = fields.slot_sum[s];
                    if sum == NONE {
                        continue;
                    }
                    let t = &sums.anti[sum as usize];
                    for k in 0..ANTI_TERMS {
                        for c in 0..C {
                            a_acc[bin][c] += wa[k] * t[k][c] as f64;
                        }
                    }
                }
            }
        }
    }
}

/// The weights of an irradiance group's terms ([`SweepContext::sum_fields`]) for an element
/// with normal `n` at `dx` from the field's centre: `n . G + n . J dx + N(n, dx, dx) / 2`, with
/// `J` its symmetric part plus its antisymmetric part `K` (`n . K dx = sum over p < q of K_pq
/// (n_p dx_q - n_q dx_p)`) and `N` symmetric in its last two indices.
fn irradiance_weights(n: DVec3, dx: DVec3) -> [f64; IRR_TERMS] {
    let (nn, xx) = ([n.x, n.y, n.z], [dx.x, dx.y, dx.z]);
    let mut w = [0.0f64; IRR_TERMS];
    w[..3].copy_from_slice(&nn);
    // J's upper triangle: n_p x_s + n_s x_p off the diagonal.
    for (u, &(p, s)) in UPPER.iter().enumerate() {
        w[3 + u] = if p == s {
            nn[p] * xx[p]
        } else {
            nn[p] * xx[s] + nn[s] * xx[p]
        };
    }
    for (u, (p, s)) in [(0, 1), (0, 2), (1, 2)].into_iter().enumerate() {
        w[9 + u] = nn[p] * xx[s] - nn[s] * xx[p];
    }
    for p in 0..3 {
        for (u, &(a, b)) in UPPER.iter().enumerate() {
            let half = if a == b { 0.5 } else { 1.0 };
            w[12 + 6 * p + u] = half * nn[p] * xx[a] * xx[b];
        }
    }
    w
}

/// Adds each term (per unit of a link's intensity; f32 as cached, f64 as computed) times the
/// link's intensity `i` to its sum in `acc`, widening the term to f64 first.
#[inline(always)]
#[allow(clippy::needless_range_loop)]
fn add_terms<T: Copy + Into<f64>, const C: usize>(acc: &mut [[f64; C]], terms: &[T], i: &[f64; C]) {
    for (acc, &t) in acc.iter_mut().zip(terms) {
        let t: f64 = t.into();
        for c in 0..C {
            acc[c] += t * i[c];
        }
    }
}
