//! The SIMD kernel of the microplane update: the directions as structure of arrays in groups of
//! [`LANES`], the lane sums and the per-point update (see the module above for the equations).

use super::{EtaMode, Microplane, StrainMeasure};
use crate::material::quadrature::Quadrature;
use crate::material::{PAIRS, PointUpdate, Response, Sym6, first_piola_from_pk2, green_lagrange};

/// Below this macroscopic `eta` the ratio `eta_bar/eta` of eq. 13 is replaced by `eta_bar_mic = eta_bar`.
const ETA_TINY: f64 = 1e-14;
/// Below this `r_I` the gradient of `eta_mic` takes its one-sided limit.
const R_TINY: f64 = 1e-200;

/// Planes per SIMD group: the per-plane loops run over structure-of-arrays data in groups of
/// `LANES` with one accumulator per lane, which the compiler maps onto vector registers (two SSE2
/// registers, or one AVX2 register where the processor has it). The order of every sum is fixed by
/// the source, so both instruction sets give the same bits.
const LANES: usize = 4;

/// The integration directions as structure of arrays, padded to `N` (a multiple of [`LANES`]) with
/// zero-weight planes of zero normal, which contribute nothing to any sum.
#[derive(Clone, Debug)]
pub(super) struct Planes<const N: usize> {
    /// Number of real directions (the history length).
    count: usize,
    /// Components of the unit normals `n_I`.
    n: [[f64; N]; 3],
    /// `n_I (x) n_I` in [`Sym6`] order, one row per component.
    nn: [[f64; N]; 6],
    /// `6 w_I` (sphere integral weight).
    w6: [f64; N],
    /// `2 w_I` (weight of a sphere average).
    w2: [f64; N],
}

impl<const N: usize> Planes<N> {
    fn new(q: Quadrature) -> Self {
        let mut p = Self {
            count: 0,
            n: [[0.0; N]; 3],
            nn: [[0.0; N]; 6],
            w6: [0.0; N],
            w2: [0.0; N],
        };
        for (i, (n, w)) in q.directions().enumerate() {
            for (row, nk) in p.n.iter_mut().zip(n) {
                row[i] = nk;
            }
            for (a, &(k, l)) in PAIRS.iter().enumerate() {
                p.nn[a][i] = n[k] * n[l];
            }
            p.w6[i] = 6.0 * w;
            p.w2[i] = p.w6[i] / 3.0;
            p.count = i + 1;
        }
        p
    }
}

/// The directions of each rule, padded to the next multiple of [`LANES`].
#[derive(Clone, Debug)]
pub(super) enum PlaneSet {
    P24(Box<Planes<24>>),
    P28(Box<Planes<28>>),
    P36(Box<Planes<36>>),
    P64(Box<Planes<64>>),
}

impl PlaneSet {
    pub(super) fn new(q: Quadrature) -> Self {
        match q {
            Quadrature::Bo21 => Self::P24(Box::new(Planes::new(q))),
            Quadrature::Bo28 => Self::P28(Box::new(Planes::new(q))),
            Quadrature::Bo33 => Self::P36(Box::new(Planes::new(q))),
            Quadrature::Bo61 => Self::P64(Box::new(Planes::new(q))),
        }
    }

    pub(super) fn count(&self) -> usize {
        match self {
            Self::P24(p) => p.count,
            Self::P28(p) => p.count,
            Self::P36(p) => p.count,
            Self::P64(p) => p.count,
        }
    }
}

/// The sum of the lane accumulators, as a pairwise tree.
#[inline(always)]
fn fold_lanes(acc: &[f64; LANES]) -> f64 {
    let mut a = *acc;
    let mut width = LANES;
    while width > 1 {
        width /= 2;
        for k in 0..width {
            a[k] += a[k + width];
        }
    }
    a[0]
}

/// `sum_I x_I`, in lanes.
#[inline(always)]
fn lane_sum<const N: usize>(x: &[f64; N]) -> f64 {
    let mut acc = [0.0; LANES];
    for c in x.chunks_exact(LANES) {
        for k in 0..LANES {
            acc[k] += c[k];
        }
    }
    fold_lanes(&acc)
}

/// `[sum_I w_I rows[r]_I]` for every row, in lanes.
#[inline(always)]
fn lane_dots<const R: usize, const N: usize>(w: &[f64; N], rows: [&[f64; N]; R]) -> [f64; R] {
    let mut acc = [[0.0; LANES]; R];
    for c in (0..N).step_by(LANES) {
        for (r, row) in rows.iter().enumerate() {
            for k in 0..LANES {
                acc[r][k] += w[c + k] * row[c + k];
            }
        }
    }
    acc.map(|a| fold_lanes(&a))
}

/// Per-plane projections of a strain `e` for every plane: `E_D` (3 rows) and `n . E_D`.
#[inline(always)]
fn project_all<const N: usize>(p: &Planes<N>, e: &Sym6, ev: f64) -> ([[f64; N]; 3], [f64; N]) {
    let mut ed = [[0.0; N]; 3];
    let mut ned = [0.0; N];
    for i in 0..N {
        let (n0, n1, n2) = (p.n[0][i], p.n[1][i], p.n[2][i]);
        let d0 = e[0] * n0 + e[3] * n1 + e[5] * n2 - ev * n0;
        let d1 = e[3] * n0 + e[1] * n1 + e[4] * n2 - ev * n1;
        let d2 = e[5] * n0 + e[4] * n1 + e[2] * n2 - ev * n2;
        ed[0][i] = d0;
        ed[1][i] = d1;
        ed[2][i] = d2;
        ned[i] = n0 * d0 + n1 * d1 + n2 * d2;
    }
    (ed, ned)
}

/// `Dev^T . E_D = sym(n (x) E_D) - (n . E_D)/3 I` for every plane, one row per [`Sym6`] component.
#[inline(always)]
fn dev_t_all<const N: usize>(p: &Planes<N>, ed: &[[f64; N]; 3], ned: &[f64; N]) -> [[f64; N]; 6] {
    let mut t = [[0.0; N]; 6];
    for i in 0..N {
        for (a, &(k, l)) in PAIRS.iter().enumerate() {
            let sym = 0.5 * (p.n[k][i] * ed[l][i] + p.n[l][i] * ed[k][i]);
            t[a][i] = if k == l {
                sym - ned[i] * (1.0 / 3.0)
            } else {
                sym
            };
        }
    }
    t
}

/// `sum_I w_I x_I (x) y_I` as a 6 x 6 array, in lanes; `y = None` means `y = x`, for which only the
/// symmetric half is summed.
#[inline(always)]
#[expect(
    clippy::needless_range_loop,
    reason = "the symmetric half is filled by (row, column) index"
)]
fn lane_outer<const N: usize>(
    w: &[f64; N],
    x: &[[f64; N]; 6],
    y: Option<&[[f64; N]; 6]>,
) -> [[f64; 6]; 6] {
    let mut out = [[0.0; 6]; 6];
    match y {
        Some(y) => {
            for (a, row) in out.iter_mut().enumerate() {
                let mut wx = [0.0; N];
                for i in 0..N {
                    wx[i] = w[i] * x[a][i];
                }
                *row = lane_dots(&wx, y.each_ref());
            }
        }
        None => {
            let mut acc = [[0.0; LANES]; 21];
            for c in (0..N).step_by(LANES) {
                let mut k = 0;
                for a in 0..6 {
                    for b in a..6 {
                        for l in 0..LANES {
                            acc[k][l] += w[c + l] * x[a][c + l] * x[b][c + l];
                        }
                        k += 1;
                    }
                }
            }
            let mut k = 0;
            for a in 0..6 {
                for b in a..6 {
                    let v = fold_lanes(&acc[k]);
                    out[a][b] = v;
                    out[b][a] = v;
                    k += 1;
                }
            }
        }
    }
    out
}

/// `Dev^T . E_D` of plane `i`.
#[inline(always)]
fn dev_t_of<const N: usize>(t: &[[f64; N]; 6], i: usize) -> Sym6 {
    [t[0][i], t[1][i], t[2][i], t[3][i], t[4][i], t[5][i]]
}

impl Microplane {
    /// The update of a point whose inputs are checked: [`Microplane::update_avx2`] where the processor
    /// supports AVX2, else [`Microplane::update_any`] (the same bits).
    pub(super) fn update_checked(&self, p: PointUpdate<'_>, out: &mut Response) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor supports AVX2 (checked on the line above).
            unsafe { self.update_avx2(p, out) };
            return;
        }
        self.update_any(p, out);
    }

    /// [`Microplane::update_planes`] compiled with AVX2 (four planes per instruction); the same bits
    /// as [`Microplane::update_any`].
    ///
    /// # Safety
    /// The processor must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn update_avx2(&self, p: PointUpdate<'_>, out: &mut Response) {
        self.update_any(p, out);
    }

    /// `(m0, dS/dE)` of a point none of whose planes is damaged: `m0 = sum_I 6 w_I` and the elastic
    /// tangent summed over the planes, by the same sums as [`Microplane::update_planes`] forms for
    /// such a point (there `6 w_I (1 - d_I)` is `6 w_I` to the bit), so the same bits.
    pub(super) fn undamaged_tangent(&self) -> (f64, [[f64; 6]; 6]) {
        fn of<const N: usize>(m: &Microplane, p: &Planes<N>) -> (f64, [[f64; 6]; 6]) {
            let mm = lane_dots(&p.w6, p.nn.each_ref());
            let m0 = lane_sum(&p.w6);
            let mut d = [[0.0; 6]; 6];
            m.add_elastic_tangent(m0, &mm, &mut d);
            (m0, d)
        }
        match &self.planes {
            PlaneSet::P24(p) => of(self, p),
            PlaneSet::P28(p) => of(self, p),
            PlaneSet::P36(p) => of(self, p),
            PlaneSet::P64(p) => of(self, p),
        }
    }

    /// The update for the padded plane set of the rule; inputs already checked.
    #[inline(always)]
    pub(super) fn update_any(&self, p: PointUpdate<'_>, out: &mut Response) {
        let (f, in_plane) = (p.f, p.in_plane);
        let (s, d) = match &self.planes {
            PlaneSet::P24(planes) => self.update_planes(planes, p, out),
            PlaneSet::P28(planes) => self.update_planes(planes, p, out),
            PlaneSet::P36(planes) => self.update_planes(planes, p, out),
            PlaneSet::P64(planes) => self.update_planes(planes, p, out),
        };
        // The push-forward to `P` and `A`, once here rather than in each plane count's kernel.
        if in_plane {
            first_piola_from_pk2::<2>(f, &s, &d, &mut out.p, &mut out.a);
        } else {
            first_piola_from_pk2::<3>(f, &s, &d, &mut out.p, &mut out.a);
        }
    }

    /// The trapezoidal dissipation `(end_point + sum_I released_I psi_0,I(E_n))/2` of a point whose
    /// planes released `released_I = 6 w_I (d_I - d_I^n)` and dissipated `end_point` by the end-point
    /// rule, with `E_n` the Green-Lagrange strain of the step's starting `f_n`; `end_point` itself without
    /// `f_n` (or when no plane is loading).
    #[inline(always)]
    fn trapezoidal<const N: usize>(
        &self,
        p: &Planes<N>,
        f_n: Option<&nalgebra::Matrix3<f64>>,
        released: &[f64; N],
        end_point: f64,
    ) -> f64 {
        let Some(f_n) = f_n else {
            return end_point;
        };
        let e = green_lagrange(f_n);
        let ev = (e[0] + e[1] + e[2]) / 3.0;
        let (ed, _) = project_all(p, &e, ev);
        let vol_energy = 0.5 * self.k_mic * ev * ev;
        let mut p0 = [0.0; N];
        for i in 0..N {
            p0[i] = vol_energy
                + self.g_mic * (ed[0][i] * ed[0][i] + ed[1][i] * ed[1][i] + ed[2][i] * ed[2][i]);
        }
        let [start] = lane_dots(released, [&p0]);
        0.5 * end_point + 0.5 * start
    }

    /// Stress, tangents, equivalent strain and history for `N` (padded) planes.
    ///
    /// Every per-plane quantity is a row of `N` numbers; the sums over the planes are lane sums
    /// ([`lane_dots`]). The loading part of the tangent, `sum_I c_I s_I (x) g_I` with
    /// `s_I = K_mic E_V/3 I + 2 G_mic t_I` and `g_I = a_I I + b_I u_I` (`t_I`, `u_I` the `Dev^T . E_D` of
    /// the stress and of the equivalent-strain measure, equal for Green-Lagrange), is expanded into
    /// `I (x) I`, `I (x) u`, `t (x) I` and `t (x) u` sums, so no per-plane 6 x 6 update is needed.
    /// Returns `S` and `dS/dE`, which the caller pushes forward to `P` and `A`.
    #[inline(always)]
    fn update_planes<const N: usize>(
        &self,
        p: &Planes<N>,
        point: PointUpdate<'_>,
        out: &mut Response,
    ) -> (Sym6, [[f64; 6]; 6]) {
        let PointUpdate {
            f,
            eta_bar,
            h_n,
            h_trial,
            f_n,
            in_plane: _,
        } = point;
        let nd = p.count;
        let (k1, k2, k_mic, g_mic) = (self.k1, self.k2, self.k_mic, self.g_mic);
        let gamma_0 = self.params.gamma_0;

        let e = green_lagrange(f);
        let ev = (e[0] + e[1] + e[2]) / 3.0;
        // The strain of the equivalent strains: E itself, or E_h with its pull-back to E.
        let hencky = match self.params.strain_measure {
            StrainMeasure::GreenLagrange => None,
            StrainMeasure::Hencky => Some(crate::material::Hencky::new(f)),
        };
        let e_eta = hencky.as_ref().map_or(e, |h| h.0);
        let tr = e_eta[0] + e_eta[1] + e_eta[2];
        let a_vol = k1 * tr; // = 3 k1 E_V

        // Pass 1: projections and local equivalent strains (eq. 14), and the coefficients of
        // d eta_mic,I/dE = a_I I + b_I u_I (the one-sided limit at r_I = 0).
        let (ed_eta, ned_eta) = project_all(p, &e_eta, tr / 3.0);
        let u = dev_t_all(p, &ed_eta, &ned_eta);
        let mut eta_mic = [0.0; N];
        let mut ga = [0.0; N];
        let mut gb = [0.0; N];
        for i in 0..N {
            let ed2 = ed_eta[0][i] * ed_eta[0][i]
                + ed_eta[1][i] * ed_eta[1][i]
                + ed_eta[2][i] * ed_eta[2][i];
            let r = (a_vol * a_vol + 1.5 * k2 * ed2).sqrt();
            eta_mic[i] = a_vol + r;
            (ga[i], gb[i]) = if r > R_TINY {
                (k1 * (1.0 + a_vol / r), 1.5 * k2 / r)
            } else if a_vol > 0.0 {
                (2.0 * k1, 0.0)
            } else {
                (0.0, 0.0)
            };
        }
        let pull = |g: Sym6| match &hencky {
            Some((_, h)) => h.pull(&g),
            None => g,
        };
        let (eta, g_eta) = match self.params.eta_mode {
            EtaMode::Max => {
                let (mut eta, mut i_max) = (f64::NEG_INFINITY, 0);
                for (i, &em) in eta_mic[..nd].iter().enumerate() {
                    if em > eta {
                        eta = em;
                        i_max = i;
                    }
                }
                let ui = dev_t_of(&u, i_max);
                let (a, b) = (ga[i_max], gb[i_max]);
                let g = [
                    a + b * ui[0],
                    a + b * ui[1],
                    a + b * ui[2],
                    b * ui[3],
                    b * ui[4],
                    b * ui[5],
                ];
                (eta, pull(g))
            }
            EtaMode::Mean => {
                let mut w3b = [0.0; N];
                for i in 0..N {
                    w3b[i] = p.w2[i] * gb[i];
                }
                let [eta, a] = lane_dots(&p.w2, [&eta_mic, &ga]);
                let b = lane_dots(&w3b, u.each_ref());
                (eta, pull([a + b[0], a + b[1], a + b[2], b[3], b[4], b[5]]))
            }
        };
        let ratio_mode = eta > ETA_TINY;
        let q = if ratio_mode { eta_bar / eta } else { 0.0 };

        // Projections of E for the stress (those of pass 1 unless eta uses another strain).
        let stress_proj;
        let (ed, ned, t) = if hencky.is_some() {
            let (ed, ned) = project_all(p, &e, ev);
            let t = dev_t_all(p, &ed, &ned);
            stress_proj = (ed, ned, t);
            (&stress_proj.0, &stress_proj.1, &stress_proj.2)
        } else {
            (&ed_eta, &ned_eta, &u)
        };
        let vol_energy = 0.5 * k_mic * ev * ev;
        let mut p0 = [0.0; N]; // undamaged plane energy psi_0,I
        for i in 0..N {
            p0[i] = vol_energy
                + g_mic * (ed[0][i] * ed[0][i] + ed[1][i] * ed[1][i] + ed[2][i] * ed[2][i]);
        }

        // A point that stays undamaged: every plane's history and `eta_bar_mic` at `gamma_0` or below, so
        // no plane is damaged or loading. It skips pass 2 and takes the precomputed elastic tangent; its
        // sums below are those of the general path, whose `6 w_I (1 - d_I)` is then `6 w_I` to the bit.
        let undamaged = h_n[..nd].iter().all(|&g| g <= gamma_0)
            && eta_mic[..nd]
                .iter()
                .all(|&em| (if ratio_mode { q * em } else { eta_bar }) <= gamma_0);

        // Pass 2 (one exp per damaged plane): history, integrity, loading coefficients, dissipation.
        let mut omd = [0.0; N]; // 1 - d_I (0 on the padding planes, whose weight is 0)
        let mut c = [0.0; N]; // 6 w_I d'(gamma_I) on loading planes, else 0
        let mut rel = [0.0; N]; // eta_mic,I/eta (1 outside the ratio mode) on loading planes
        let mut any_loading = false;
        let (mut dis_tension, mut dis_compression) = (0.0, 0.0);
        let mut released = [0.0; N]; // 6 w_I (d_I - d_I^n) on loading planes, else 0
        if undamaged {
            h_trial[..nd].fill(gamma_0);
        }
        let pass_2 = if undamaged { 0..0 } else { 0..nd };
        for i in pass_2 {
            let eb_mic = if ratio_mode { q * eta_mic[i] } else { eta_bar };
            let g_n = h_n[i];
            let loading = eb_mic > g_n && eb_mic > gamma_0;
            let gamma = gamma_0.max(g_n).max(eb_mic);
            h_trial[i] = gamma;
            let (o, dd) = if gamma > gamma_0 {
                self.integrity(gamma)
            } else {
                (1.0, 0.0)
            };
            omd[i] = o;
            if loading {
                any_loading = true;
                // Dissipation psi_0 (d - d_n) of this plane, by the sign of its normal strain.
                let d_n = if g_n > gamma_0 {
                    1.0 - self.integrity(g_n).0
                } else {
                    0.0
                };
                released[i] = p.w6[i] * ((1.0 - o) - d_n);
                let energy = p.w6[i] * p0[i] * ((1.0 - o) - d_n);
                if ev + ned[i] < 0.0 {
                    dis_compression += energy;
                } else {
                    dis_tension += energy;
                }
                c[i] = p.w6[i] * dd;
                rel[i] = if ratio_mode { eta_mic[i] / eta } else { 1.0 };
            }
        }

        // Pass 3: the sums over the planes.
        let (mut wd, mut dw) = (p.w6, [0.0; N]); // 6 w_I (1 - d_I), 2 w_I d_I
        if !undamaged {
            for i in 0..N {
                wd[i] = p.w6[i] * omd[i];
                dw[i] = p.w2[i] * (1.0 - omd[i]);
            }
        }
        let [psi, t0, t1, t2, t3, t4, t5] =
            lane_dots(&wd, [&p0, &t[0], &t[1], &t[2], &t[3], &t[4], &t[5]]);
        let (m0, d_mean, psi0, mut d_tot) = if undamaged {
            (self.undamaged.0, 0.0, psi, self.undamaged.1)
        } else {
            let mm = lane_dots(&wd, p.nn.each_ref());
            let [psi0] = lane_dots(&p.w6, [&p0]);
            let mut d_tot = [[0.0; 6]; 6];
            let m0 = lane_sum(&wd);
            self.add_elastic_tangent(m0, &mm, &mut d_tot);
            (m0, lane_sum(&dw), psi0, d_tot)
        };
        let vol = k_mic * ev / 3.0;
        let s_tot: Sym6 = [
            vol * m0 + 2.0 * g_mic * t0,
            vol * m0 + 2.0 * g_mic * t1,
            vol * m0 + 2.0 * g_mic * t2,
            2.0 * g_mic * t3,
            2.0 * g_mic * t4,
            2.0 * g_mic * t5,
        ];
        let mut ds_deb: Sym6 = [0.0; 6];
        if any_loading {
            // sum_I c_I rel_I s_I: dS/d eta_bar = -it, and the ratio term of dS/dE is q it (x) d eta/dE.
            let mut crel = [0.0; N];
            for i in 0..N {
                crel[i] = c[i] * rel[i];
            }
            let r0 = lane_sum(&crel);
            let rt = lane_dots(&crel, t.each_ref());
            for a in 0..6 {
                let sr = if a < 3 { vol * r0 } else { 0.0 } + 2.0 * g_mic * rt[a];
                ds_deb[a] = -sr;
                if ratio_mode {
                    for b in 0..6 {
                        d_tot[a][b] += q * sr * g_eta[b];
                    }
                }
            }
            if ratio_mode {
                // -q sum_I c_I s_I (x) g_I, the planes' d eta_bar_mic,I/dE through d eta_mic,I/dE.
                let mut ca = [0.0; N];
                let mut cb = [0.0; N];
                for i in 0..N {
                    ca[i] = q * c[i] * ga[i];
                    cb[i] = q * c[i] * gb[i];
                }
                let a_t = lane_dots(&ca, t.each_ref());
                let b_u = lane_dots(&cb, u.each_ref());
                let a0 = lane_sum(&ca);
                let x = lane_outer(&cb, t, hencky.as_ref().map(|_| &u));
                for a in 0..6 {
                    let x = x[a];
                    let mut row = [0.0; 6];
                    for b in 0..6 {
                        let mut m = 2.0 * g_mic * x[b];
                        if a < 3 {
                            m += vol * b_u[b];
                        }
                        if b < 3 {
                            m += 2.0 * g_mic * a_t[a];
                        }
                        if a < 3 && b < 3 {
                            m += vol * a0;
                        }
                        row[b] = m;
                    }
                    let row = pull(row);
                    for b in 0..6 {
                        d_tot[a][b] -= row[b];
                    }
                }
            }
        }

        out.dp_deta_bar = f * crate::material::sym_to_matrix(&ds_deb);
        out.eta = eta;
        out.deta_df = f * crate::material::sym_to_matrix(&g_eta);
        out.energy = psi;
        out.dissipation = [dis_tension, dis_compression];
        let end_point = dis_tension + dis_compression;
        out.dissipation_trapezoidal =
            self.trapezoidal(p, f_n.filter(|_| any_loading), &released, end_point);
        out.damage = if psi0 > 0.0 { 1.0 - psi / psi0 } else { d_mean };
        (s_tot, d_tot)
    }
}
