//! One Jacobi sweep of the hierarchical solver (pull along the cluster links, gather per
//! element) and the packing of its state for Anderson acceleration and extrapolation.

use super::*;

/// Sums over a sweep's elements: relative change numerator and denominator, largest row sum
/// (exact links), largest |B|, and whether every value written was finite.
#[derive(Clone, Copy, Debug)]
pub(super) struct SweepSums {
    pub(super) num: f64,
    pub(super) den: f64,
    pub(super) max_row: f64,
    pub(super) largest: f64,
    pub(super) finite: bool,
}

impl Default for SweepSums {
    fn default() -> Self {
        SweepSums {
            num: 0.0,
            den: 0.0,
            max_row: 0.0,
            largest: 0.0,
            finite: true,
        }
    }
}

impl SweepSums {
    pub(super) fn add(self, o: SweepSums) -> SweepSums {
        SweepSums {
            num: self.num + o.num,
            den: self.den + o.den,
            max_row: self.max_row.max(o.max_row),
            largest: self.largest.max(o.largest),
            finite: self.finite && o.finite,
        }
    }
}

/// Everything a sweep reads that does not change between sweeps.
pub(super) struct SweepContext<'a> {
    pub(super) tree: &'a ClusterTree,
    /// Per node, its centroid and spread ([`Links::point`]).
    pub(super) points: &'a [NodePoint],
    pub(super) bins: &'a Bins,
    pub(super) live: &'a LiveBins,
    pub(super) elem_area: &'a [f64],
    /// Per element, the area it sends by (its area times its patch's visible share).
    pub(super) send_area: &'a [f64],
    pub(super) elem_normal: &'a [DVec3],
    pub(super) elem_center: &'a [DVec3],
    pub(super) elem_back: &'a [bool],
    /// Per element: two-sided (its back face gathers too); empty when none is.
    pub(super) elem_two: &'a [bool],
    /// Which links are gathered through their receiver's field (the rest per element).
    pub(super) fields: &'a Fields,
    pub(super) use_anti: bool,
    pub(super) two_sided: bool,
}

impl SweepContext<'_> {
    /// Calls `f` with the index of every cluster link into element `e` or one of its ancestors
    /// that is gathered per element (element first, then up the tree; the near links of a node
    /// in stored order, [`Fields::near_end`]) and the pair's factors.
    #[inline]
    pub(super) fn for_each_pair(
        &self,
        e: usize,
        links: &Links,
        mut f: impl FnMut(usize, &ClusterLink, PairFactor),
    ) {
        let (n_e, x_e) = (self.elem_normal[e], self.elem_center[e]);
        let back = self.two_sided || self.elem_back[e];
        let two = self.elem_two.get(e).copied().unwrap_or(false);
        let s_e = crate::hierarchy::links::element_spread(self.tree, e);
        let mut node = self.tree.elements[e];
        while node != NONE {
            let range = self.fields.near_links(links, node);
            for (i, l) in range.clone().zip(&links.cluster[range]) {
                f(i, l, self.pair_factor(l, n_e, x_e, back, two, s_e));
            }
            node = self.tree.nodes[node as usize].parent;
        }
    }

    /// The vector of cluster link `l`, from its sender's centroid to its receiver's.
    #[inline]
    fn link_vector(&self, l: &ClusterLink) -> DVec3 {
        self.points[l.receiver as usize].centroid() - self.points[l.sender as usize].centroid()
    }

    /// The direction of cluster link `l` (unit, [`Self::link_vector`]), along which
    /// [`Self::pull`] measures its intensity.
    #[inline]
    pub(super) fn link_direction(&self, l: &ClusterLink) -> DVec3 {
        self.link_vector(l).normalize_or_zero()
    }

    /// A flat sender's unit normal and its cosine along cluster link `l`
    /// ([`Self::link_direction`]); `None` for a curved sender. With the sender's cosine toward
    /// a point, [`crate::hierarchy::links::cosine_ratio`] turns the link's intensity to it.
    #[inline]
    pub(super) fn flat_sender(&self, l: &ClusterLink) -> Option<(DVec3, f64)> {
        let n_s = self.points[l.sender as usize].flat_normal()?;
        Some((n_s, n_s.dot(self.link_direction(l))))
    }

    /// What a cluster link gives an element with normal `n_e` at `x_e` and spread `s_e`
    /// ([`crate::hierarchy::links::element_spread`]): irradiance `(cos g - n_r . tilt g^2) / pi`
    /// per unit of the link's intensity, `g = 1 / (d^2 + s)` with the sender's and the
    /// element's spreads in `s` ([`crate::hierarchy::links::NodePoint::kernel_toward`],
    /// [`crate::hierarchy::links::receiver_spread`]), with the
    /// element's own direction and distance from the sender, and antiradiance `1 / ((d^2 +
    /// s_anti) Omega_bin)` in the link's bin where the light arrives at a side that creates it
    /// (the front, and the back too when `back`). For a two-sided element (`two`), light
    /// arriving at its back gives a negative irradiance factor, the irradiance of its back
    /// face (normal `n_r = -n_e`). Both are turned from the link's direction to the
    /// element's ([`crate::hierarchy::links::NodePoint::cosine_ratio`]).
    #[inline]
    pub(super) fn pair_factor(
        &self,
        l: &ClusterLink,
        n_e: DVec3,
        x_e: DVec3,
        back: bool,
        two: bool,
        s_e: f64,
    ) -> PairFactor {
        let sender = &self.points[l.sender as usize];
        let v = x_e - sender.centroid();
        let d2 = v.length_squared();
        if !(d2 > 0.0) {
            return PairFactor::default();
        }
        let inv_d = 1.0 / d2.sqrt();
        let cos = -n_e.dot(v) * inv_d;
        let kernel = sender.kernel_toward(v, d2, inv_d);
        let flat = self.flat_sender(l);
        let turn = flat.map_or(1.0, |(n_s, c_link)| {
            crate::hierarchy::links::cosine_ratio(c_link, n_s.dot(v) * inv_d)
        });
        // The receiving element's own extent, by the same expansion as the sender's
        // (`NodePoint::kernel_toward`) with the roles swapped.
        let receiver = crate::hierarchy::links::receiver_spread(s_e, cos, d2);
        let g = 1.0 / (d2 + kernel.irradiance + receiver);
        let irradiance = if cos > 0.0 || two {
            // The face that receives: the front (normal n_e) or a two-sided element's back
            // (normal -n_e, its irradiance negative).
            let n_r = if cos > 0.0 { n_e } else { -n_e };
            let mut h = turn * (cos.abs() * g - n_r.dot(kernel.tilt) * g * g);
            // The receiver's extent's cross term, the sender's tilt with the roles swapped:
            // `-s_e (n_s . n_r) cos_r^2 g^2` per unit of the sender's area times radiance, so
            // over `n_s . w` per unit of the link's intensity (which is known only for a flat
            // sender). It raised the closed-box furnace at albedo 0.8 from 9.96 to 9.99 (10
            // exactly) on patches of 0.25 of the box.
            if let Some((n_s, c_link)) = flat.filter(|_| turn > 0.0) {
                let t = crate::hierarchy::links::expansion_weight(d2, s_e);
                h -= t * s_e * n_s.dot(n_r) * cos * cos * g * g / c_link;
            }
            h.max(0.0).copysign(cos) * std::f64::consts::FRAC_1_PI
        } else {
            0.0
        };
        let anti = if self.use_anti && (cos > 0.0 || back) {
            1.0 / ((d2 + kernel.anti) * self.bins.solid_angle[l.bin as usize])
        } else {
            0.0
        };
        PairFactor {
            irradiance: irradiance as f32,
            anti: (turn * anti) as f32,
        }
    }

    /// The radiant intensity a cluster link's sender sends along the link: B through the front of
    /// every element (and the back face's B through the back of two-sided ones), minus
    /// antiradiance through the back (both sides when two-sided). `group_b_back` and
    /// `radiance_back` are empty when no element is two-sided.
    #[allow(clippy::needless_range_loop, clippy::too_many_arguments)]
    pub(super) fn pull<const C: usize>(
        &self,
        l: &ClusterLink,
        groups: &SenderGroups,
        (group_b, group_b_back): (&[[f64; C]], &[[f64; C]]),
        group_a: &[[f64; C]],
        (radiance, radiance_back): (&[[f64; C]], &[[f64; C]]),
        anti: &[[f32; C]],
    ) -> [f32; C] {
        // The terms are summed along the unnormalized direction and scaled once at the end: the
        // square root and division then overlap the sums instead of delaying every term.
        let w = self.link_vector(l);
        let length = w.length();
        if !(length > 0.0) || !length.is_finite() {
            return [0.0; C];
        }
        let bin = l.bin as usize;
        let mut acc = [0.0f64; C];
        // The state is read only where a term uses it (see [`pull_term`]).
        let anti_at = |cos: f64, both: bool| self.use_anti && (self.two_sided || both || cos < 0.0);
        if groups.is_grouped(l.sender) {
            let (g0, g1) = groups.range[l.sender as usize];
            for g in g0 as usize..g1 as usize {
                let cos = groups.normal[g].dot(w);
                pull_term(
                    &mut acc,
                    cos,
                    || group_b[g],
                    || group_b_back.get(g).copied(),
                    anti_at(cos, groups.both[g]).then(|| group_a[bin * groups.normal.len() + g]),
                );
            }
        } else {
            let (e0, e1) = groups.elements[l.sender as usize];
            for e in e0 as usize..e1 as usize {
                let (a, cos) = (self.send_area[e], self.elem_normal[e].dot(w));
                pull_term(
                    &mut acc,
                    cos,
                    || radiance[e].map(|x| a * x),
                    || radiance_back.get(e).map(|b| b.map(|x| a * x)),
                    anti_at(cos, self.elem_back[e]).then(|| {
                        self.live
                            .slot(e, bin)
                            .map_or([0.0; C], |k| anti[k].map(|x| a * x as f64))
                    }),
                );
            }
        }
        let inv = 1.0 / length;
        acc.map(|x| (x * inv) as f32)
    }
}

/// Adds one element's or normal group's term to a link's intensity `acc`: `cos` (its normal
/// against the link's direction) times its radiance `b` through the front when it faces the
/// receiver, else its back face's `b_back` (two-sided elements), minus `|cos|` times its
/// antiradiance `a` when the side the link leaves by blocks (`None`: it does not). The
/// radiance is read only when the term uses it, and the caller reads the antiradiance only
/// when it counts: the pull is bound by these reads (a front-only sender facing the receiver
/// never reads its antiradiance).
#[inline(always)]
fn pull_term<const C: usize>(
    acc: &mut [f64; C],
    cos: f64,
    b: impl FnOnce() -> [f64; C],
    b_back: impl FnOnce() -> Option<[f64; C]>,
    a: Option<[f64; C]>,
) {
    if cos > 0.0 {
        let b = b();
        for c in 0..C {
            acc[c] += cos * b[c];
        }
    } else if let Some(b_back) = b_back() {
        for c in 0..C {
            acc[c] -= cos * b_back[c];
        }
    }
    if let Some(a) = a {
        let k = cos.abs();
        for c in 0..C {
            acc[c] -= k * a[c];
        }
    }
}

/// What a sweep's sources are, per element: emission (the source of the front faces), the back
/// faces' source (empty when no element is two-sided) and albedo, in `C` channels.
pub(super) struct Sources<'a, const C: usize> {
    pub(super) emission: &'a [[f64; C]],
    pub(super) emission_back: &'a [[f64; C]],
    pub(super) albedo: &'a [[f64; C]],
    /// The box this sweep's radiance and antiradiance are written into.
    pub(super) projection: crate::solve::health::Projection,
}

/// What one sweep's gather reads: the links (and their pair cache), every cluster link's
/// intensity from the pull, and the state the sweep started from.
pub(super) struct SweepState<'a, const C: usize> {
    pub(super) links: &'a Links,
    pub(super) pairs: Option<&'a PairCache>,
    pub(super) intensity: &'a [[f32; C]],
    pub(super) radiance: &'a [[f64; C]],
    pub(super) radiance_back: &'a [[f64; C]],
    pub(super) anti: &'a [[f32; C]],
    /// This sweep's field sums (from `intensity`).
    pub(super) field_sums: &'a FieldSums<C>,
}

impl SweepContext<'_> {
    /// The exact links into element `e`: adds what they bring to the irradiance of its front
    /// (`h`) and back face (`h_back`) and to its antiradiance bins (`a_acc`). Returns the
    /// largest of its two faces' form-factor row sums.
    fn gather_exact<const C: usize>(
        &self,
        e: usize,
        state: &SweepState<C>,
        a_acc: &mut [[f64; C]],
        (h, h_back): (&mut [f64; C], &mut [f64; C]),
    ) -> f64 {
        let nb = self.bins.len();
        let (links, live) = (state.links, self.live);
        let (radiance, radiance_back, anti) = (state.radiance, state.radiance_back, state.anti);
        let (use_anti, two_sided, elem_back) = (self.use_anti, self.two_sided, self.elem_back);
        let (mut row, mut row_back) = (0.0, 0.0);
        for l in links.exact_start[e]..links.exact_start[e + 1] {
            let s = links.exact_sender[l as usize] as usize;
            let (sender_back, receiver_back) = links.exact_faces_of(l as usize);
            let b_s = if sender_back {
                radiance_back[s]
            } else {
                radiance[s]
            };
            let (h, row) = if receiver_back {
                (&mut *h_back, &mut row_back)
            } else {
                (&mut *h, &mut row)
            };
            *row += gather_entries(
                links.exact_entries_of(l as usize),
                b_s,
                |bin| {
                    live.slot(s, bin)
                        .map_or([0.0; C], |k| anti[k].map(f64::from))
                },
                use_anti,
                two_sided || elem_back[s],
                h,
                &mut a_acc[..nb],
            );
        }
        f64::max(row, row_back)
    }

    /// Gathers element `e` (step 3 of a sweep): its exact links, then the cluster links into
    /// it and its ancestors, each with the element's own direction and distance from the
    /// link's sender (the antiradiance goes to the link's bin, the one its sender reads when it
    /// passes it on). Writes its new radiance (`b_out`, and `back_out` for a two-sided
    /// element's back face) and its stored antiradiance bins (`a_out`); `a_acc` is scratch of
    /// twice the bins. Returns the element's share of the sweep's sums.
    #[allow(clippy::needless_range_loop)]
    pub(super) fn gather_element<const C: usize>(
        &self,
        e: usize,
        (sources, state): (&Sources<C>, &SweepState<C>),
        a_acc: &mut [[f64; C]],
        (b_out, a_out, back_out): (&mut [f64; C], &mut [[f32; C]], Option<&mut [f64; C]>),
    ) -> SweepSums {
        let ctx = self;
        let nb = self.bins.len();
        let (links, live, pairs, intensity) =
            (state.links, self.live, state.pairs, state.intensity);
        let (radiance, radiance_back) = (state.radiance, state.radiance_back);
        let (emission, emission_back, albedo) =
            (sources.emission, sources.emission_back, sources.albedo);
        let (elem_two, elem_area) = (self.elem_two, self.elem_area);
        a_acc[..nb].fill([0.0; C]);
        let mut h = [0.0f64; C];
        let mut h_back = [0.0f64; C];
        let row = self.gather_exact(e, state, a_acc, (&mut h, &mut h_back));
        let two = elem_two.get(e).copied().unwrap_or(false);
        let mut add = |l: &ClusterLink, i: &[f32; C], k: PairFactor| {
            // Negative: light arriving at a two-sided element's back face.
            let h = if k.irradiance < 0.0 {
                &mut h_back
            } else {
                &mut h
            };
            let f = (k.irradiance as f64).abs();
            for c in 0..C {
                h[c] += f * i[c] as f64;
            }
            if k.anti != 0.0 {
                let bin = l.bin as usize;
                for c in 0..C {
                    a_acc[bin][c] += k.anti as f64 * i[c] as f64;
                }
            }
        };
        match pairs {
            // A two-sided element's factors route by their sign.
            Some(cache) if two => cache.for_each_node(e, |range, factors| {
                for ((j, l), &[f, g]) in range.clone().zip(&links.cluster[range]).zip(factors) {
                    add(
                        l,
                        &intensity[j],
                        PairFactor {
                            irradiance: f,
                            anti: g,
                        },
                    );
                }
            }),
            Some(cache) => stream_cached(cache, e, intensity, nb, a_acc, &mut h),
            None => ctx.for_each_pair(e, links, |i, l, k| add(l, &intensity[i], k)),
        }
        self.gather_fields(
            e,
            (self.fields, state.field_sums),
            a_acc,
            (&mut h, &mut h_back),
        );
        let mut largest = 0.0f64;
        let mut finite = true;
        let a = elem_area[e];
        let (mut num, mut den) = (0.0, 0.0);
        // The largest |B| and finiteness are of the values before the projection (the guard
        // must see what the sweep computed).
        let box_ = sources.projection;
        for c in 0..C {
            let b = emission[e][c] + albedo[e][c] * h[c];
            largest = largest.max(b.abs());
            finite &= b.is_finite();
            b_out[c] = box_.apply(b);
        }
        if let Some(back) = back_out {
            for c in 0..C {
                let b = emission_back[e][c] + albedo[e][c] * h_back[c];
                largest = largest.max(b.abs());
                finite &= b.is_finite();
                back[c] = box_.apply(b);
                num += a * (back[c] - radiance_back[e][c]).abs();
                den += a * back[c].abs();
            }
        }
        for (dst, bin) in a_out.iter_mut().zip(live.bins_of(e)) {
            *dst = a_acc[bin].map(|x| box_.apply_anti(x, row) as f32);
            finite &= a_acc[bin].iter().all(|x| x.is_finite()) && dst.iter().all(|x| x.is_finite());
        }
        num += (0..C)
            .map(|c| a * (b_out[c] - radiance[e][c]).abs())
            .sum::<f64>();
        den += (0..C).map(|c| a * b_out[c].abs()).sum::<f64>();
        SweepSums {
            num,
            den,
            max_row: row,
            largest,
            finite,
        }
    }
}

/// The cached (element, cluster link) pairs of element `e` (step 3 of a sweep, with a pair
/// cache): adds each link's intensity times its factors to the irradiance `h` and to the
/// link's bin of `a_acc` (twice the bins of scratch; the second half is left zeroed).
#[allow(clippy::needless_range_loop)]
fn stream_cached<const C: usize>(
    cache: &PairCache,
    e: usize,
    intensity: &[[f32; C]],
    nb: usize,
    a_acc: &mut [[f64; C]],
    h: &mut [f64; C],
) {
    // A stream of multiply-adds: factors, intensities and bins
    // side by side (a factor of 0 adds nothing), alternate pairs
    // into two sets of sums so that consecutive adds into one bin
    // do not wait on each other.
    let (a_even, a_odd) = a_acc.split_at_mut(nb);
    let mut h_odd = [0.0f64; C];
    cache.for_each_node(e, |range, factors| {
        let intensity = &intensity[range.clone()];
        let bins = &cache.link_bin[range];
        let pairs = factors.len() / 2;
        for k in 0..pairs {
            let (j0, j1) = (2 * k, 2 * k + 1);
            let [f0, g0] = factors[j0].map(f64::from);
            let [f1, g1] = factors[j1].map(f64::from);
            let (i0, i1) = (intensity[j0].map(f64::from), intensity[j1].map(f64::from));
            let (b0, b1) = (bins[j0] as usize, bins[j1] as usize);
            for c in 0..C {
                h[c] += f0 * i0[c];
                h_odd[c] += f1 * i1[c];
                a_even[b0][c] += g0 * i0[c];
                a_odd[b1][c] += g1 * i1[c];
            }
        }
        if factors.len() % 2 == 1 {
            let j = factors.len() - 1;
            let [f0, g0] = factors[j].map(f64::from);
            let (i0, b0) = (intensity[j].map(f64::from), bins[j] as usize);
            for c in 0..C {
                h[c] += f0 * i0[c];
                a_even[b0][c] += g0 * i0[c];
            }
        }
    });
    for c in 0..C {
        h[c] += h_odd[c];
    }
    for (even, odd) in a_even.iter_mut().zip(a_odd.iter_mut()) {
        for c in 0..C {
            even[c] += odd[c];
        }
        *odd = [0.0; C];
    }
}

/// Radiance and antiradiance state as one flat vector (radiance first, then the back faces'
/// radiance, then the antiradiance slots in order).
pub(super) fn pack<const C: usize>(
    (radiance, radiance_back): (&[[f64; C]], &[[f64; C]]),
    anti: &[[f32; C]],
    out: &mut Vec<f64>,
) {
    out.clear();
    out.extend(radiance.iter().flatten());
    out.extend(radiance_back.iter().flatten());
    out.extend(anti.iter().flatten().map(|&x| x as f64));
}

/// The inverse of [`pack`].
pub(super) fn unpack<const C: usize>(
    flat: &[f64],
    (radiance, radiance_back): (&mut [[f64; C]], &mut [[f64; C]]),
    anti: &mut [[f32; C]],
) {
    let (b, a) = flat.split_at((radiance.len() + radiance_back.len()) * C);
    for (dst, src) in radiance
        .iter_mut()
        .chain(radiance_back.iter_mut())
        .zip(b.chunks_exact(C))
    {
        dst.copy_from_slice(src);
    }
    for (dst, src) in anti.iter_mut().zip(a.chunks_exact(C)) {
        for c in 0..C {
            dst[c] = src[c] as f32;
        }
    }
}

/// `x += k (x - x_previous)`, element-wise.
pub(super) fn extrapolate<const C: usize, T>(x: &mut [[T; C]], x_previous: &[[T; C]], k: f64)
where
    T: Copy + Into<f64> + health::FromF64 + Send + Sync,
{
    x.par_iter_mut()
        .zip(x_previous.par_iter())
        .for_each(|(a, b)| {
            for c in 0..C {
                let (v, p): (f64, f64) = (a[c].into(), b[c].into());
                a[c] = T::from_f64(v + k * (v - p));
            }
        });
}
