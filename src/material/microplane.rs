//! Finite-strain, implicit-gradient-enhanced microplane damage model (source paper eqs. 9-16;
//! Platen, Zreid & Kaliske 2023; Zreid & Kaliske 2014). Notation of the paper and of spec Sec. 3.
//!
//! **Kinematics.** Green-Lagrange strain `E = (F^T F - I)/2`. On a microplane with unit normal `n`:
//! `E_V = tr(E)/3`, `E_D = E n - E_V n`, and `Dev^T . E_D = (n (x) E_D + E_D (x) n)/2 - (n . E_D)/3 I`.
//!
//! **Energy (eqs. 9, 10).** `Psi = (3/(4 pi)) int_Omega psi_mic dOmega = 6 sum_I w_I psi_mic,I` with
//! `psi_mic = (1 - d_mic) (K_mic E_V^2/2 + G_mic E_D . E_D)`, and `S = dPsi/dE = 6 sum_I w_I (1 - d_I) s_I`,
//! `s_I = K_mic E_V I/3 + 2 G_mic Dev^T . E_D`. With this normalisation the undamaged response is
//! isotropic with bulk modulus `K_mic/3` and shear modulus `G_mic`; the config holds the macroscopic
//! `K`, `G` (Table 1) and the model uses `K_mic = 3K`, `G_mic = G`.
//!
//! **Damage (eqs. 11, 12).** `d(gamma) = 1 - (gamma_0/gamma)(1 - alpha + alpha exp(beta (gamma_0 - gamma)))`,
//! one history variable per direction, `gamma_I = max(gamma_0, gamma_I^n, eta_bar_mic,I)`.
//! `d -> 1` as `gamma -> inf` while the microplane "stress" `(1 - d) gamma -> (1 - alpha) gamma_0`.
//!
//! **Equivalent strains (eqs. 13-16).** `eta_mic = 3 k1 E_V + sqrt((3 k1 E_V)^2 + 3/2 k2 E_D . E_D)`,
//! `k1 = (k_r - 1)/(2 k_r (1 - 2 nu))`, `k2 = 3/(k_r (1 + nu)^2)`. The macroscopic local equivalent
//! strain `eta` (source of the Helmholtz equation) is `max_I eta_mic,I` ([`EtaMode::Max`], the paper's
//! "maximum local equivalent strain") or the sphere average `2 sum_I w_I eta_mic,I` ([`EtaMode::Mean`]).
//! Nonlocal microplane strain (eq. 13): `eta_bar_mic,I = (eta_bar/eta) eta_mic,I`; for `eta <= 1e-14`
//! (undeformed or purely hydrostatically compressed point) `eta_bar_mic,I = eta_bar` on every plane.
//!
//! **Tangent.** `dS/dE = 6 sum_I w_I [(1 - d_I) C_I - chi_I d'(gamma_I) s_I (x) d eta_bar_mic,I/dE]`
//! with the constant per-plane `C_I = K_mic V (x) V + 2 G_mic Dev_I^T . Dev_I` (summed through the
//! precomputed `n_I (x) n_I`, see `Microplane::add_elastic_tangent`) and the
//! loading indicator `chi_I = 1` iff `eta_bar_mic,I > gamma_I^n` and `> gamma_0`;
//! `dS/d eta_bar = -6 sum_I w_I chi_I d'(gamma_I) (eta_mic,I/eta) s_I`; `A` follows from
//! [`super::first_piola_from_pk2`], `dP/d eta_bar = F dS/d eta_bar`, `d eta/dF = F d eta/dE`.
//! At `r_I = sqrt((k1 tr E)^2 + 3/2 k2 E_D . E_D) = 0` the gradient of `eta_mic` is taken as its
//! one-sided limit (`2 k1 I` if `k1 tr E > 0`, else 0).
//!
//! **Implementation.** The directions are stored as structure of arrays, padded with zero-weight
//! planes to a multiple of four, and every per-plane quantity is a row over the planes; the sums over
//! the planes run in four lanes with a fixed order, and the loading part of the tangent,
//! `sum_I c_I s_I (x) g_I`, is expanded into `I (x) I`, `I (x) Dev^T . E_D` and
//! `Dev^T . E_D (x) Dev^T . E_D` sums (the last symmetric for the Green-Lagrange measure), so there is no
//! per-plane 6 x 6 update. The same code is compiled a second time with AVX2 and chosen at run time
//! where the processor has it; both give the same bits.
//!
//! **Output damage.** [`Response::damage`] is the energy-weighted damage `1 - Psi/Psi_0`, `Psi_0` the
//! undamaged energy at the same `E` (i.e. the `psi_0`-weighted mean of `d_I`); at `Psi_0 = 0`
//! (`E = 0`) the plain sphere average `2 sum_I w_I d_I` is reported instead.

use serde::{Deserialize, Serialize};

use super::activity::GradientActivity;
use super::elastic::positive;
use super::quadrature::Quadrature;
use super::{
    Constitutive, MaterialError, PAIRS, PointUpdate, Response, Sym6, check_softening,
    first_piola_from_pk2, green_lagrange, invalid,
};

/// Below this macroscopic `eta` the ratio `eta_bar/eta` of eq. 13 is replaced by `eta_bar_mic = eta_bar`.
const ETA_TINY: f64 = 1e-14;
/// Below this `r_I` the gradient of `eta_mic` takes its one-sided limit.
const R_TINY: f64 = 1e-200;

/// How the macroscopic local equivalent strain `eta` is formed from the microplane values.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EtaMode {
    /// `eta = max_I eta_mic,I` (the paper's "maximum local equivalent strain"; default).
    #[default]
    Max,
    /// `eta = 2 sum_I w_I eta_mic,I` (sphere average).
    Mean,
}

/// The strain tensor whose projections give the microplane equivalent strains `eta_mic` (eq. 14). The
/// stress stays the derivative of the energy in the Green-Lagrange strain either way.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StrainMeasure {
    /// Green-Lagrange `E = (C - I)/2` (the paper).
    #[default]
    GreenLagrange,
    /// Logarithmic (Hencky) `E_h = ln(C)/2`: grows like the engineering strain under large stretch
    /// (`E_h = ln(lambda)` against `E = (lambda^2 - 1)/2` for a uniaxial stretch `lambda`).
    Hencky,
}

/// Named parameter sets (Table 1 of the paper and its low-threshold variant).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Preset {
    /// Table 1: K = 18750 MPa, G = 15254 MPa, nu = 0.18, gamma_0 = 1.25e-3, k_r = 14, alpha = 0.98,
    /// beta = 650, c = 1 mm^2.
    #[serde(rename = "paper")]
    Paper,
    /// Table 1 with gamma_0 = 1.25e-4 (a tensile strength near that of concrete).
    #[serde(rename = "paper_gamma0_1.25e-4")]
    PaperGamma0Low,
    /// Table 1 with gamma_0 = 1.25e-4 and beta = 6500: beta scaled with 1/gamma_0 so that the onset
    /// half-wavelength `pi sqrt(c/(alpha beta gamma_0))` (3.5 mm) and so the width over which damage first
    /// localises stay those of Table 1 (see [`MicroplaneParams::onset_half_wavelength`]).
    #[serde(rename = "paper_gamma0_1.25e-4_scaled")]
    PaperGamma0LowScaled,
}

impl Preset {
    /// Every preset.
    pub const ALL: [Preset; 3] = [
        Preset::Paper,
        Preset::PaperGamma0Low,
        Preset::PaperGamma0LowScaled,
    ];

    /// The name used in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Paper => "paper",
            Preset::PaperGamma0Low => "paper_gamma0_1.25e-4",
            Preset::PaperGamma0LowScaled => "paper_gamma0_1.25e-4_scaled",
        }
    }

    /// The complete parameter set.
    pub fn params(self) -> MicroplaneParams {
        let paper = MicroplaneParams {
            bulk_modulus: 18750.0,
            shear_modulus: 15254.0,
            poisson_ratio: 0.18,
            gamma_0: 1.25e-3,
            k_r: 14.0,
            alpha: 0.98,
            beta: 650.0,
            c: 1.0,
            quadrature: Quadrature::Bo21,
            eta_mode: EtaMode::Max,
            gradient_activity: GradientActivity::Constant,
            strain_measure: StrainMeasure::GreenLagrange,
            erosion_damage: None,
        };
        match self {
            Preset::Paper => paper,
            Preset::PaperGamma0Low => MicroplaneParams {
                gamma_0: 1.25e-4,
                ..paper
            },
            Preset::PaperGamma0LowScaled => MicroplaneParams {
                gamma_0: 1.25e-4,
                beta: 6500.0,
                ..paper
            },
        }
    }
}

/// The `model = "microplane"` config section. Every field is optional when a `preset` is given;
/// an explicit field overrides the preset.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MicroplaneConfig {
    /// `"paper"` or `"paper_gamma0_1.25e-4"`.
    pub preset: Option<Preset>,
    /// Macroscopic bulk modulus K (MPa), > 0; `K_mic = 3K`.
    pub bulk_modulus: Option<f64>,
    /// Macroscopic shear modulus G (MPa), > 0; `G_mic = G`.
    pub shear_modulus: Option<f64>,
    /// Poisson's ratio nu used in k1, k2 (eqs. 15, 16) only, 0 <= nu < 0.5.
    pub poisson_ratio: Option<f64>,
    /// Damage threshold gamma_0 (-), > 0.
    pub gamma_0: Option<f64>,
    /// Ratio of compressive to tensile strength k_r (-), > 1.
    pub k_r: Option<f64>,
    /// Maximum degradation alpha (-), 0 <= alpha <= 1.
    pub alpha: Option<f64>,
    /// Softening parameter beta (-), >= 0.
    pub beta: Option<f64>,
    /// Gradient activity parameter c (mm^2), >= 0; 0 means local.
    pub c: Option<f64>,
    /// Sphere integration rule (default `bo21`).
    pub quadrature: Option<Quadrature>,
    /// `"max"` (default) or `"mean"`.
    pub eta_mode: Option<EtaMode>,
    /// Evolution of `c` (default `{ kind = "constant" }`, the paper), see [`super::activity`].
    pub gradient_activity: Option<GradientActivity>,
    /// Strain projected for `eta_mic`: `"green_lagrange"` (default, the paper) or `"hencky"`.
    pub strain_measure: Option<StrainMeasure>,
    /// Damage `d_e` (0 < d_e < 1) at which a point erodes into a void (see `docs/theory.md`, "Eroded
    /// points"); default: never.
    pub erosion_damage: Option<f64>,
}

/// Complete, validated microplane parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MicroplaneParams {
    /// Macroscopic bulk modulus K (MPa).
    pub bulk_modulus: f64,
    /// Macroscopic shear modulus G (MPa).
    pub shear_modulus: f64,
    /// Poisson's ratio in k1, k2.
    pub poisson_ratio: f64,
    /// Damage threshold gamma_0.
    pub gamma_0: f64,
    /// Compressive/tensile strength ratio k_r.
    pub k_r: f64,
    /// Maximum degradation alpha.
    pub alpha: f64,
    /// Softening parameter beta.
    pub beta: f64,
    /// Gradient activity parameter c (mm^2).
    pub c: f64,
    /// Sphere integration rule.
    pub quadrature: Quadrature,
    /// Definition of the macroscopic eta.
    pub eta_mode: EtaMode,
    /// Evolution of the gradient activity `c` (constant in the paper).
    pub gradient_activity: GradientActivity,
    /// Strain tensor of the equivalent strains.
    pub strain_measure: StrainMeasure,
    /// Damage at which a point erodes (None: never).
    pub erosion_damage: Option<f64>,
}

impl MicroplaneConfig {
    /// A config holding only a preset.
    pub fn preset(p: Preset) -> Self {
        Self {
            preset: Some(p),
            ..Default::default()
        }
    }

    /// Merges the preset with the explicit fields and validates the result.
    pub fn resolve(&self) -> Result<MicroplaneParams, MaterialError> {
        let base = self.preset.map(Preset::params);
        let get = |v: Option<f64>, from: fn(&MicroplaneParams) -> f64, field: &'static str| {
            v.or(base.as_ref().map(from)).ok_or(MaterialError::MissingParameter {
                field,
                hint: "give it in the [material] section or choose a preset (\"paper\", \"paper_gamma0_1.25e-4\")",
            })
        };
        let p = MicroplaneParams {
            bulk_modulus: get(self.bulk_modulus, |p| p.bulk_modulus, "bulk_modulus")?,
            shear_modulus: get(self.shear_modulus, |p| p.shear_modulus, "shear_modulus")?,
            poisson_ratio: get(self.poisson_ratio, |p| p.poisson_ratio, "poisson_ratio")?,
            gamma_0: get(self.gamma_0, |p| p.gamma_0, "gamma_0")?,
            k_r: get(self.k_r, |p| p.k_r, "k_r")?,
            alpha: get(self.alpha, |p| p.alpha, "alpha")?,
            beta: get(self.beta, |p| p.beta, "beta")?,
            c: get(self.c, |p| p.c, "c")?,
            quadrature: self.quadrature.unwrap_or_default(),
            eta_mode: self.eta_mode.unwrap_or_default(),
            gradient_activity: self.gradient_activity.unwrap_or_default(),
            strain_measure: self.strain_measure.unwrap_or_default(),
            erosion_damage: self.erosion_damage.or(base.and_then(|b| b.erosion_damage)),
        };
        p.validate()?;
        Ok(p)
    }
}

impl MicroplaneParams {
    /// Onset half-wavelength `pi sqrt(c/(alpha beta gamma_0))` (mm): the width over which softening first
    /// localises in the 1D gradient problem linearised at `gamma_0` (softening slope `alpha beta gamma_0`
    /// relative to the elastic one). It depends on `beta gamma_0` only, so a threshold changed by a factor
    /// keeps it when `beta` changes by the inverse factor. Infinite for `c > 0` without softening.
    pub fn onset_half_wavelength(&self) -> f64 {
        std::f64::consts::PI * (self.c / (self.alpha * self.beta * self.gamma_0)).sqrt()
    }

    /// Checks every parameter range.
    pub fn validate(&self) -> Result<(), MaterialError> {
        positive("bulk_modulus", self.bulk_modulus)?;
        positive("shear_modulus", self.shear_modulus)?;
        positive("gamma_0", self.gamma_0)?;
        let nu = self.poisson_ratio;
        if !(nu.is_finite() && (0.0..0.5).contains(&nu)) {
            return invalid("poisson_ratio", nu, "0 <= nu < 0.5");
        }
        if !(self.k_r.is_finite() && self.k_r > 1.0) {
            return invalid("k_r", self.k_r, "a finite value > 1");
        }
        check_softening(self.alpha, self.beta, self.c)?;
        if let Some(de) = self.erosion_damage
            && !(de > 0.0 && de < 1.0)
        {
            return invalid("erosion_damage", de, "0 < erosion_damage < 1");
        }
        self.gradient_activity.validate()
    }
}
/// Planes per SIMD group: the per-plane loops run over structure-of-arrays data in groups of
/// `LANES` with one accumulator per lane, which the compiler maps onto vector registers (two SSE2
/// registers, or one AVX2 register where the processor has it). The order of every sum is fixed by
/// the source, so both instruction sets give the same bits.
const LANES: usize = 4;

/// The integration directions as structure of arrays, padded to `N` (a multiple of [`LANES`]) with
/// zero-weight planes of zero normal, which contribute nothing to any sum.
#[derive(Clone, Debug)]
struct Planes<const N: usize> {
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
enum PlaneSet {
    P24(Box<Planes<24>>),
    P28(Box<Planes<28>>),
    P36(Box<Planes<36>>),
    P64(Box<Planes<64>>),
}

impl PlaneSet {
    fn new(q: Quadrature) -> Self {
        match q {
            Quadrature::Bo21 => Self::P24(Box::new(Planes::new(q))),
            Quadrature::Bo28 => Self::P28(Box::new(Planes::new(q))),
            Quadrature::Bo33 => Self::P36(Box::new(Planes::new(q))),
            Quadrature::Bo61 => Self::P64(Box::new(Planes::new(q))),
        }
    }

    fn count(&self) -> usize {
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

/// The microplane damage material (spec Sec. 3). History: one `gamma_I` per direction.
#[derive(Clone, Debug)]
pub struct Microplane {
    params: MicroplaneParams,
    k1: f64,
    k2: f64,
    k_mic: f64,
    g_mic: f64,
    planes: PlaneSet,
}

impl Microplane {
    /// Validates the parameters, then builds the model, laying out the directions, `n_I (x) n_I` and `6 w_I` as structure of arrays.
    pub fn new(params: MicroplaneParams) -> Result<Self, MaterialError> {
        params.validate()?;
        let nu = params.poisson_ratio;
        let k_r = params.k_r;
        let k_mic = 3.0 * params.bulk_modulus;
        let g_mic = params.shear_modulus;
        Ok(Self {
            params,
            k1: (k_r - 1.0) / (2.0 * k_r * (1.0 - 2.0 * nu)),
            k2: 3.0 / (k_r * (1.0 + nu) * (1.0 + nu)),
            k_mic,
            g_mic,
            planes: PlaneSet::new(params.quadrature),
        })
    }

    /// The validated parameters.
    pub fn params(&self) -> &MicroplaneParams {
        &self.params
    }

    /// `(k1, k2)` of eqs. 15, 16.
    pub fn k1_k2(&self) -> (f64, f64) {
        (self.k1, self.k2)
    }

    /// Micro moduli `(K_mic, G_mic) = (3K, G)` in MPa.
    pub fn micro_moduli(&self) -> (f64, f64) {
        (self.k_mic, self.g_mic)
    }

    /// Damage of eq. 11 and its derivative `d'(gamma)`.
    pub fn damage_law(&self, gamma: f64) -> (f64, f64) {
        let (omd, dd) = self.integrity(gamma);
        (1.0 - omd, dd)
    }

    /// Integrity `1 - d(gamma) = (gamma_0/gamma)(1 - alpha + alpha exp(beta (gamma_0 - gamma)))` (eq. 11),
    /// evaluated without the cancellation of `1 - d` near full damage, and `d'(gamma)`.
    #[inline(always)]
    fn integrity(&self, gamma: f64) -> (f64, f64) {
        let MicroplaneParams {
            gamma_0,
            alpha,
            beta,
            ..
        } = self.params;
        let ex = (beta * (gamma_0 - gamma)).exp();
        let g = 1.0 - alpha + alpha * ex;
        let r = gamma_0 / gamma;
        (r * g, r / gamma * g + r * alpha * beta * ex)
    }

    /// Adds `sum_I m_I C_I` to `d` (pair form), given `m0 = sum_I m_I` and `mm = sum_I m_I n_I (x) n_I`.
    ///
    /// `C_I = K_mic V (x) V + 2 G_mic Dev_I^T . Dev_I` depends on `n_I` only through `n_I (x) n_I`:
    /// `(Dev^T . Dev)_ijkl = (N_il d_jk + N_ik d_jl + N_jl d_ik + N_jk d_il)/4 - d_kl N_ij/3 - N_kl d_ij/3
    /// + d_ij d_kl/9` with `N = n (x) n`, so the weighted sum over the planes needs only 7 numbers.
    #[inline(always)]
    fn add_elastic_tangent(&self, m0: f64, mm: &Sym6, d: &mut [[f64; 6]; 6]) {
        let m = super::sym_to_matrix(mm);
        let kd = |i: usize, j: usize| if i == j { 1.0 } else { 0.0 };
        let vol = self.k_mic / 9.0 * m0 + 2.0 * self.g_mic * m0 / 9.0;
        for (a, &(i, j)) in PAIRS.iter().enumerate() {
            for (b, &(k, l)) in PAIRS.iter().enumerate() {
                let dev = 0.25
                    * (m[(i, l)] * kd(j, k)
                        + m[(i, k)] * kd(j, l)
                        + m[(j, l)] * kd(i, k)
                        + m[(j, k)] * kd(i, l))
                    - (kd(k, l) * m[(i, j)] + m[(k, l)] * kd(i, j)) / 3.0;
                d[a][b] += vol * kd(i, j) * kd(k, l) + 2.0 * self.g_mic * dev;
            }
        }
    }

    /// Largest microplane damage `max_I d(gamma_I)` of a history (an alternative output scalar).
    pub fn max_plane_damage(&self, h: &[f64]) -> f64 {
        h.iter()
            .map(|&g| self.damage_law(g.max(self.params.gamma_0)).0)
            .fold(0.0, f64::max)
    }
}
impl Constitutive for Microplane {
    fn history_len(&self) -> usize {
        self.planes.count()
    }

    fn init_history(&self, h: &mut [f64]) {
        h.fill(self.params.gamma_0);
    }

    fn update(&self, p: PointUpdate<'_>, out: &mut Response) -> Result<(), MaterialError> {
        p.check_history_len(self.planes.count())?;
        p.check_jacobian()?;
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor supports AVX2 (checked on the line above).
            unsafe { self.update_avx2(p, out) };
            return Ok(());
        }
        self.update_any(p, out);
        Ok(())
    }
}

impl Microplane {
    /// [`Microplane::update_planes`] compiled with AVX2 (four planes per instruction); the same bits
    /// as [`Microplane::update_any`].
    ///
    /// # Safety
    /// The processor must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn update_avx2(&self, p: PointUpdate<'_>, out: &mut Response) {
        self.update_any(p, out);
    }

    /// The update for the padded plane set of the rule; inputs already checked.
    #[inline(always)]
    fn update_any(&self, p: PointUpdate<'_>, out: &mut Response) {
        match &self.planes {
            PlaneSet::P24(planes) => self.update_planes(planes, p, out),
            PlaneSet::P28(planes) => self.update_planes(planes, p, out),
            PlaneSet::P36(planes) => self.update_planes(planes, p, out),
            PlaneSet::P64(planes) => self.update_planes(planes, p, out),
        }
    }

    /// Stress, tangents, equivalent strain and history for `N` (padded) planes.
    ///
    /// Every per-plane quantity is a row of `N` numbers; the sums over the planes are lane sums
    /// ([`lane_dots`]). The loading part of the tangent, `sum_I c_I s_I (x) g_I` with
    /// `s_I = K_mic E_V/3 I + 2 G_mic t_I` and `g_I = a_I I + b_I u_I` (`t_I`, `u_I` the `Dev^T . E_D` of
    /// the stress and of the equivalent-strain measure, equal for Green-Lagrange), is expanded into
    /// `I (x) I`, `I (x) u`, `t (x) I` and `t (x) u` sums, so no per-plane 6 x 6 update is needed.
    #[inline(always)]
    fn update_planes<const N: usize>(
        &self,
        p: &Planes<N>,
        point: PointUpdate<'_>,
        out: &mut Response,
    ) {
        let PointUpdate {
            f,
            eta_bar,
            h_n,
            h_trial,
        } = point;
        let nd = p.count;
        let (k1, k2, k_mic, g_mic) = (self.k1, self.k2, self.k_mic, self.g_mic);
        let gamma_0 = self.params.gamma_0;

        let e = green_lagrange(f);
        let ev = (e[0] + e[1] + e[2]) / 3.0;
        // The strain of the equivalent strains: E itself, or E_h with its pull-back to E.
        let hencky = match self.params.strain_measure {
            StrainMeasure::GreenLagrange => None,
            StrainMeasure::Hencky => Some(super::Hencky::new(f)),
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

        // Pass 2 (one exp per damaged plane): history, integrity, loading coefficients, dissipation.
        let mut omd = [0.0; N]; // 1 - d_I (0 on the padding planes, whose weight is 0)
        let mut c = [0.0; N]; // 6 w_I d'(gamma_I) on loading planes, else 0
        let mut rel = [0.0; N]; // eta_mic,I/eta (1 outside the ratio mode) on loading planes
        let mut any_loading = false;
        let (mut dis_tension, mut dis_compression) = (0.0, 0.0);
        for i in 0..nd {
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
                let released = p.w6[i] * p0[i] * ((1.0 - o) - d_n);
                if ev + ned[i] < 0.0 {
                    dis_compression += released;
                } else {
                    dis_tension += released;
                }
                c[i] = p.w6[i] * dd;
                rel[i] = if ratio_mode { eta_mic[i] / eta } else { 1.0 };
            }
        }

        // Pass 3: the sums over the planes.
        let mut wd = [0.0; N]; // 6 w_I (1 - d_I)
        let mut dw = [0.0; N]; // 2 w_I d_I
        for i in 0..N {
            wd[i] = p.w6[i] * omd[i];
            dw[i] = p.w2[i] * (1.0 - omd[i]);
        }
        let [psi, t0, t1, t2, t3, t4, t5] =
            lane_dots(&wd, [&p0, &t[0], &t[1], &t[2], &t[3], &t[4], &t[5]]);
        let mm = lane_dots(&wd, p.nn.each_ref());
        let [psi0] = lane_dots(&p.w6, [&p0]);
        let (m0, d_mean) = (lane_sum(&wd), lane_sum(&dw));
        let vol = k_mic * ev / 3.0;
        let s_tot: Sym6 = [
            vol * m0 + 2.0 * g_mic * t0,
            vol * m0 + 2.0 * g_mic * t1,
            vol * m0 + 2.0 * g_mic * t2,
            2.0 * g_mic * t3,
            2.0 * g_mic * t4,
            2.0 * g_mic * t5,
        ];
        let mut d_tot = [[0.0; 6]; 6];
        self.add_elastic_tangent(m0, &mm, &mut d_tot);
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

        first_piola_from_pk2(f, &s_tot, &d_tot, &mut out.p, &mut out.a);
        out.dp_deta_bar = f * super::sym_to_matrix(&ds_deb);
        out.eta = eta;
        out.deta_df = f * super::sym_to_matrix(&g_eta);
        out.energy = psi;
        out.dissipation = [dis_tension, dis_compression];
        out.damage = if psi0 > 0.0 { 1.0 - psi / psi0 } else { d_mean };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::fdcheck::{eval, generic_f, rel_err, rotation, tangent_errors};
    use crate::material::sym_to_matrix;
    use nalgebra::Matrix3;

    fn paper() -> Microplane {
        Microplane::new(Preset::Paper.params()).unwrap()
    }

    fn fresh(m: &Microplane) -> Vec<f64> {
        let mut h = vec![0.0; m.history_len()];
        m.init_history(&mut h);
        h
    }

    #[test]
    fn undamaged_stress_is_isotropic_hooke_in_green_strain() {
        for q in [
            Quadrature::Bo21,
            Quadrature::Bo28,
            Quadrature::Bo33,
            Quadrature::Bo61,
        ] {
            let m = Microplane::new(MicroplaneParams {
                quadrature: q,
                ..Preset::Paper.params()
            })
            .unwrap();
            let (kk, gg) = (18750.0, 15254.0);
            for scale in [1e-4, 0.2] {
                let f = generic_f(scale);
                // eta_bar = 0 keeps every plane undamaged whatever the strain.
                let (r, h) = eval(&m, &f, 0.0, &fresh(&m));
                let e = sym_to_matrix(&green_lagrange(&f));
                let s_exact = Matrix3::identity() * (kk * e.trace())
                    + (e - Matrix3::identity() * (e.trace() / 3.0)) * (2.0 * gg);
                let s = f.try_inverse().unwrap() * r.p;
                assert!(
                    (s - s_exact).norm() <= 1e-10 * s_exact.norm(),
                    "{q:?}: S = {s} vs {s_exact}"
                );
                let psi = 0.5 * kk * e.trace().powi(2)
                    + gg * (e - Matrix3::identity() * (e.trace() / 3.0)).norm_squared();
                assert!((r.energy - psi).abs() <= 1e-10 * psi, "{q:?}");
                assert_eq!(r.damage, 0.0);
                assert!(h.iter().all(|&g| g == m.params().gamma_0));
            }
        }
    }

    #[test]
    fn micro_parameters_follow_the_paper() {
        let m = paper();
        let (k1, k2) = m.k1_k2();
        assert!((k1 - 13.0 / (28.0 * 0.64)).abs() < 1e-14);
        assert!((k2 - 3.0 / (14.0 * 1.18 * 1.18)).abs() < 1e-14);
        assert_eq!(m.micro_moduli(), (56250.0, 15254.0));
        // Uniaxial stress, small strain: the plane normal to the load sees eta_mic = 1.063 eps.
        let (eps, nu) = (1e-6, 0.18);
        let f = Matrix3::from_diagonal(&nalgebra::Vector3::new(
            1.0 + eps,
            1.0 - nu * eps,
            1.0 - nu * eps,
        ));
        let (r, _) = eval(&m, &f, 0.0, &fresh(&m));
        assert!(
            (r.eta / eps - 1.063).abs() < 5e-4,
            "eta/eps = {}",
            r.eta / eps
        );
    }

    /// The AVX2 variant must give the bits of the portable one (fixed lane order, no contraction).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn instruction_sets_give_the_same_bits() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        for (mode, measure, q) in [
            (EtaMode::Max, StrainMeasure::GreenLagrange, Quadrature::Bo21),
            (EtaMode::Mean, StrainMeasure::Hencky, Quadrature::Bo61),
        ] {
            let m = Microplane::new(MicroplaneParams {
                eta_mode: mode,
                strain_measure: measure,
                quadrature: q,
                ..Preset::Paper.params()
            })
            .unwrap();
            for (label, f, eb, h) in states(&m, 2.5e-3) {
                let (mut r1, mut r2) = (Response::zeros(), Response::zeros());
                let (mut h1, mut h2) = (h.clone(), h.clone());
                m.update_any(PointUpdate::new(&f, eb, &h, &mut h1), &mut r1);
                // SAFETY: AVX2 is available (checked above).
                unsafe { m.update_avx2(PointUpdate::new(&f, eb, &h, &mut h2), &mut r2) };
                assert_eq!(h1, h2, "{label}");
                assert_eq!(
                    (r1.p, r1.a, r1.dp_deta_bar),
                    (r2.p, r2.a, r2.dp_deta_bar),
                    "{label}"
                );
                assert_eq!((r1.eta, r1.deta_df), (r2.eta, r2.deta_df), "{label}");
                assert_eq!(
                    (r1.energy, r1.dissipation, r1.damage),
                    (r2.energy, r2.dissipation, r2.damage)
                );
            }
        }
    }

    #[test]
    fn damage_law_limits() {
        let m = paper();
        let g0 = m.params().gamma_0;
        assert_eq!(m.damage_law(g0).0, 0.0);
        let mut prev = 0.0;
        for k in 1..200 {
            let gamma = g0 * (1.0 + 0.1 * k as f64);
            let (d, dd) = m.damage_law(gamma);
            assert!(d > prev && d < 1.0 && dd > 0.0);
            // residual microplane stress (1 - d) gamma >= (1 - alpha) gamma_0
            assert!((1.0 - d) * gamma >= (1.0 - m.params().alpha) * g0 * (1.0 - 1e-12));
            let h = 1e-7 * gamma;
            let fd = (m.damage_law(gamma + h).0 - m.damage_law(gamma - h).0) / (2.0 * h);
            assert!((fd - dd).abs() < 1e-6 * dd, "d' at {gamma}: {dd} vs {fd}");
            prev = d;
        }
    }

    /// The states of the tangent test: (label, F, eta_bar, committed history).
    fn states(m: &Microplane, scale: f64) -> Vec<(String, Matrix3<f64>, f64, Vec<f64>)> {
        let h0 = fresh(m);
        let f_load = generic_f(scale);
        let (r_load, h_load) = eval(m, &f_load, 0.0, &h0);
        let mut v = Vec::new();
        // eta_bar below gamma_0: undamaged, elastic.
        v.push((
            "undamaged".into(),
            f_load,
            0.5 * m.params().gamma_0,
            h0.clone(),
        ));
        // loading: local (eta_bar = eta) and nonlocal (eta_bar != eta) from a virgin state.
        v.push(("loading local".into(), f_load, r_load.eta, h0.clone()));
        v.push((
            "loading nonlocal".into(),
            f_load,
            1.3 * r_load.eta,
            h0.clone(),
        ));
        // committed history from the loaded state
        let (_, h_peak) = eval(m, &f_load, r_load.eta, &h0);
        assert!(h_load.iter().all(|&g| g == m.params().gamma_0));
        let f_unload = generic_f(0.6 * scale);
        let (r_un, _) = eval(m, &f_unload, 0.0, &h_peak);
        v.push(("unloading".into(), f_unload, r_un.eta, h_peak.clone()));
        let f_reload = generic_f(1.4 * scale);
        let (r_re, _) = eval(m, &f_reload, 0.0, &h_peak);
        v.push(("reloading".into(), f_reload, r_re.eta, h_peak.clone()));
        v.push((
            "reloading nonlocal".into(),
            f_reload,
            0.8 * r_re.eta,
            h_peak,
        ));
        v
    }

    #[test]
    fn tangents_match_finite_differences_in_all_states() {
        for (mode, measure) in [
            (EtaMode::Max, StrainMeasure::GreenLagrange),
            (EtaMode::Mean, StrainMeasure::GreenLagrange),
            (EtaMode::Max, StrainMeasure::Hencky),
            (EtaMode::Mean, StrainMeasure::Hencky),
        ] {
            let m = Microplane::new(MicroplaneParams {
                eta_mode: mode,
                strain_measure: measure,
                ..Preset::Paper.params()
            })
            .unwrap();
            for scale in [2.5e-3, 0.1] {
                let mut n_loading_states = 0;
                for (label, f, eb, h) in states(&m, scale) {
                    let (r, ht) = eval(&m, &f, eb, &h);
                    let n_loading = ht.iter().zip(&h).filter(|(a, b)| a > b).count();
                    if label.starts_with("loading") || label.starts_with("reloading") {
                        assert!(
                            n_loading > 0,
                            "{mode:?} {measure:?} {scale} {label}: no plane loads"
                        );
                        n_loading_states += 1;
                    }
                    if label == "unloading" || label == "undamaged" {
                        assert_eq!(n_loading, 0, "{mode:?} {measure:?} {scale} {label}");
                        assert_eq!(r.dp_deta_bar, Matrix3::zeros());
                    }
                    let (ea, ep, ee) = tangent_errors(&m, &f, eb, &h);
                    let tag = format!("{mode:?} {measure:?} scale {scale} {label}");
                    assert!(ea < 1e-6, "{tag}: A rel err {ea}");
                    assert!(ep < 1e-6, "{tag}: dP/d eta_bar rel err {ep}");
                    assert!(ee < 1e-6, "{tag}: d eta/dF rel err {ee}");
                }
                assert_eq!(n_loading_states, 4);
            }
        }
    }

    #[test]
    fn scaled_preset_keeps_the_onset_half_wavelength() {
        let w = |p: Preset| p.params().onset_half_wavelength();
        assert!(
            (w(Preset::Paper) - 3.5).abs() < 0.05,
            "{}",
            w(Preset::Paper)
        );
        assert!((w(Preset::PaperGamma0LowScaled) - w(Preset::Paper)).abs() < 1e-12);
        assert!((w(Preset::PaperGamma0Low) / w(Preset::Paper) - 10f64.sqrt()).abs() < 1e-12);
        let cfg: MicroplaneConfig =
            toml::from_str("preset = \"paper_gamma0_1.25e-4_scaled\"").unwrap();
        assert_eq!(cfg.resolve().unwrap().beta, 6500.0);
    }

    /// Along a uniaxial stretch into softening (local: eta_bar = eta), the dissipation summed step by
    /// step, `psi_0(E_n+1) (d - d_n)`, converges to the work minus the stored energy, `W - Psi`, as the
    /// increments shrink; with coarse increments it overestimates (psi_0 at the end of the step, a
    /// one-sided rule in time): with the stretch from 2e-3 (past the peak, damage starts near 0.8e-3) to
    /// 8e-3 in 10 increments +11 %, in 1000 +1 %.
    #[test]
    fn summed_dissipation_converges_to_work_minus_stored_energy() {
        let m = paper();
        let run = |n: usize| {
            let mut h = fresh(&m);
            let (mut work, mut summed, mut stored) = (0.0, 0.0, 0.0);
            let (mut p_last, mut e_last) = (0.0, 0.0);
            // To 2e-3 (onset and peak included) in 100 increments, then the softening tail to 8e-3 in n.
            let path = (1..=100)
                .map(|k| 2e-3 * k as f64 / 100.0)
                .chain((1..=n).map(|k| 2e-3 + 6e-3 * k as f64 / n as f64));
            for e in path {
                let f = Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0 + e, 1.0, 1.0));
                let (local, _) = eval(&m, &f, 0.0, &h);
                let (r, h_new) = eval(&m, &f, local.eta, &h);
                work += 0.5 * (p_last + r.p[(0, 0)]) * (e - e_last);
                summed += r.dissipation[0] + r.dissipation[1];
                (p_last, e_last, stored, h) = (r.p[(0, 0)], e, r.energy, h_new);
            }
            (summed, work - stored)
        };
        let (coarse, balance_coarse) = run(10);
        let (fine, balance_fine) = run(1000);
        assert!(balance_fine > 0.0 && (balance_coarse / balance_fine - 1.0).abs() < 0.01);
        let bias = |summed: f64| summed / balance_fine - 1.0;
        assert!(bias(fine).abs() < 0.015, "{}", bias(fine));
        assert!(
            bias(coarse) > 0.05 && bias(coarse) < 0.2,
            "{}",
            bias(coarse)
        );
    }

    #[test]
    fn dissipation_is_the_released_energy_split_by_the_sign_of_the_normal_strain() {
        let m = paper();
        // At fixed F, raising eta_bar releases exactly the dissipated energy: sum w6 psi_0 (d - d_n).
        for f in [
            Matrix3::from_diagonal(&nalgebra::Vector3::new(1.004, 1.0, 1.0)),
            Matrix3::from_diagonal(&nalgebra::Vector3::new(0.99, 1.0, 1.0)),
            generic_f(3e-3),
        ] {
            let (r1, h1) = eval(&m, &f, 3e-3, &fresh(&m));
            let (r2, _) = eval(&m, &f, 6e-3, &h1);
            let released = r1.energy - r2.energy;
            let total = r2.dissipation[0] + r2.dissipation[1];
            assert!(released > 0.0);
            assert!(
                (total - released).abs() < 1e-12 * released.max(1e-12),
                "{total} {released}"
            );
        }
        // Uniaxial stretch: every damaging plane with a negative normal strain is in the second bucket.
        let f = Matrix3::from_diagonal(&nalgebra::Vector3::new(1.004, 1.0, 1.0));
        let (r, _) = eval(&m, &f, 6e-3, &fresh(&m));
        assert!(
            r.dissipation[0] > 0.0 && r.dissipation[1] == 0.0,
            "{:?}",
            r.dissipation
        );
        // Uniaxial compression: the lateral planes see no normal strain, the axial ones a negative one.
        let f = Matrix3::from_diagonal(&nalgebra::Vector3::new(0.99, 1.0, 1.0));
        let (r, _) = eval(&m, &f, 6e-3, &fresh(&m));
        assert!(r.dissipation[1] > 0.0, "{:?}", r.dissipation);
    }

    #[test]
    fn hencky_measure_uses_the_logarithmic_strain() {
        // Uniaxial stretch lambda along x: every plane sees E_h = ln(lambda) e_x (x) e_x instead of
        // E = (lambda^2 - 1)/2 e_x (x) e_x, so eta scales by the ratio of the two (eta is homogeneous of
        // degree one in the strain); the stress is the same.
        let gl = paper();
        let hk = Microplane::new(MicroplaneParams {
            strain_measure: StrainMeasure::Hencky,
            ..Preset::Paper.params()
        })
        .unwrap();
        let lam: f64 = 1.3;
        let f = Matrix3::from_diagonal(&nalgebra::Vector3::new(lam, 1.0, 1.0));
        let (rg, _) = eval(&gl, &f, 0.0, &fresh(&gl));
        let (rh, _) = eval(&hk, &f, 0.0, &fresh(&hk));
        let ratio = lam.ln() / (0.5 * (lam * lam - 1.0));
        assert!(
            (rh.eta / rg.eta - ratio).abs() < 1e-12,
            "{} {}",
            rh.eta / rg.eta,
            ratio
        );
        assert!(rel_err(&rh.p, &rg.p) < 1e-14);
        // Small strain: both measures agree to first order.
        let f = generic_f(1e-6);
        let (rg, _) = eval(&gl, &f, 0.0, &fresh(&gl));
        let (rh, _) = eval(&hk, &f, 0.0, &fresh(&hk));
        assert!((rh.eta - rg.eta).abs() < 1e-5 * rg.eta);
    }

    #[test]
    fn tangent_at_tiny_eta_and_pure_dilatation() {
        let m = paper();
        let h0 = fresh(&m);
        // Pure dilatation: E_D = 0 on every plane, r_I = k1 tr E > 0 (limit branch of d eta_mic/dE).
        let f = Matrix3::identity() * 1.002;
        let (ea, ep, ee) = tangent_errors(&m, &f, 0.0, &h0);
        assert!(ea < 1e-6 && ep < 1e-6 && ee < 1e-6, "{ea} {ep} {ee}");
        // Undeformed point with eta_bar > gamma_0 from its neighbours: every plane damages uniformly.
        let (r, h) = eval(&m, &Matrix3::identity(), 2e-3, &h0);
        assert!(r.eta == 0.0 && h.iter().all(|&g| g == 2e-3));
        assert!(r.p.norm() < 1e-9);
        assert!(r.dp_deta_bar.norm() < 1e-9);
        let (d, _) = m.damage_law(2e-3);
        assert!((r.damage - d).abs() < 1e-14);
    }

    #[test]
    fn frame_invariance() {
        let m = paper();
        let h0 = fresh(&m);
        let q = rotation([0.4, 1.1, -0.6]);
        for scale in [2.5e-3, 0.1] {
            let f = generic_f(scale);
            let (r, h) = eval(&m, &f, 0.0, &h0);
            let (r_l, h_l) = eval(&m, &f, r.eta, &h0);
            let (rq, hq) = eval(&m, &(q * f), r.eta, &h0);
            assert!(rel_err(&rq.p, &(q * r_l.p)) < 1e-12, "P(QF) != Q P(F)");
            assert!((rq.eta - r.eta).abs() <= 1e-12 * r.eta);
            assert!(rel_err(&rq.deta_df, &(q * r_l.deta_df)) < 1e-12);
            assert!(rel_err(&rq.dp_deta_bar, &(q * r_l.dp_deta_bar)) < 1e-12);
            assert!(hq.iter().zip(&h_l).all(|(a, b)| (a - b).abs() <= 1e-12 * b));
            assert!((rq.energy - r_l.energy).abs() <= 1e-12 * r_l.energy);
            assert!(h.iter().all(|&g| g == m.params().gamma_0));
        }
    }

    /// Symmetric stretch `U = sqrt(I + 2 E)` with a given Green strain.
    fn stretch_with_green_strain(e: &Matrix3<f64>) -> Matrix3<f64> {
        let c = Matrix3::identity() + e * 2.0;
        let eig = c.symmetric_eigen();
        eig.eigenvectors
            * Matrix3::from_diagonal(&eig.eigenvalues.map(f64::sqrt))
            * eig.eigenvectors.transpose()
    }

    #[test]
    fn damage_is_monotone_and_unloading_is_secant() {
        let m = paper();
        let mut h = fresh(&m);
        let f_peak = generic_f(5e-3);
        let e_peak = sym_to_matrix(&green_lagrange(&f_peak));
        // load - unload to zero strain - reload beyond: E = lambda E_peak, local eta_bar = eta
        let path: Vec<f64> = (0..=20)
            .map(|k| k as f64 / 20.0)
            .chain((0..=20).map(|k| 1.0 - k as f64 / 20.0))
            .chain((0..=30).map(|k| k as f64 / 20.0))
            .collect();
        let mut prev_damage_planes = h.clone();
        let mut s_at_peak = None;
        for (step, &lam) in path.iter().enumerate() {
            let f = stretch_with_green_strain(&(e_peak * lam));
            let (r0, _) = eval(&m, &f, 0.0, &h);
            let (r, ht) = eval(&m, &f, r0.eta, &h);
            assert!(
                ht.iter().zip(&prev_damage_planes).all(|(a, b)| a >= b),
                "history decreased at {step}"
            );
            assert!(r.damage < 1.0 && r.damage >= 0.0);
            let s = f.try_inverse().unwrap() * r.p;
            if (21..=41).contains(&step) {
                // unloading: history frozen, S linear in E along the ray (secant stiffness)
                assert_eq!(ht, h, "history changed while unloading at step {step}");
                let s_peak: Matrix3<f64> = s_at_peak.unwrap();
                assert!(
                    (s - s_peak * lam).norm() <= 1e-9 * s_peak.norm(),
                    "not secant at {lam}"
                );
            }
            if step == 20 {
                s_at_peak = Some(s);
                assert!(r.damage > 0.5, "path must damage: {}", r.damage);
            }
            if step == 41 {
                assert!(
                    s.norm() < 1e-9 * s_at_peak.unwrap().norm(),
                    "stress at zero strain: {s}"
                );
            }
            prev_damage_planes = ht.clone();
            h = ht;
        }
    }
}
