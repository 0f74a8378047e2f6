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
//! `first_piola_from_pk2`, `dP/d eta_bar = F dS/d eta_bar`, `d eta/dF = F d eta/dE`.
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
use super::elastic::modulus;
use super::quadrature::Quadrature;
use super::{
    Constitutive, MaterialError, PAIRS, PointUpdate, Response, Sym6, check_softening,
    check_threshold, invalid,
};

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
        modulus("bulk_modulus", self.bulk_modulus)?;
        modulus("shear_modulus", self.shear_modulus)?;
        check_threshold(self.gamma_0)?;
        let nu = self.poisson_ratio;
        if !(nu.is_finite() && (0.0..0.5).contains(&nu)) {
            return invalid("poisson_ratio", nu, "0 <= nu < 0.5");
        }
        if !(self.k_r > 1.0 && self.k_r <= K_R_MAX) {
            return invalid("k_r", self.k_r, "1 < k_r <= 1000");
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

mod kernel;
#[cfg(test)]
mod tests;

use kernel::PlaneSet;

/// The largest compressive-to-tensile strength ratio `k_r`: 1000 (concrete: 10-20).
pub const K_R_MAX: f64 = 1e3;

/// The microplane damage material (spec Sec. 3). History: one `gamma_I` per direction.
#[derive(Clone, Debug)]
pub struct Microplane {
    params: MicroplaneParams,
    k1: f64,
    k2: f64,
    k_mic: f64,
    g_mic: f64,
    planes: PlaneSet,
    /// `sum_I 6 w_I` and the elastic tangent `dS/dE` of the undamaged planes (pair form): what the
    /// kernel sums for a point none of whose planes is damaged or loading, formed once.
    undamaged: (f64, [[f64; 6]; 6]),
}

impl Microplane {
    /// Validates the parameters, then builds the model, laying out the directions, `n_I (x) n_I` and `6 w_I` as structure of arrays.
    pub fn new(params: MicroplaneParams) -> Result<Self, MaterialError> {
        params.validate()?;
        let nu = params.poisson_ratio;
        let k_r = params.k_r;
        let k_mic = 3.0 * params.bulk_modulus;
        let g_mic = params.shear_modulus;
        let mut m = Self {
            params,
            k1: (k_r - 1.0) / (2.0 * k_r * (1.0 - 2.0 * nu)),
            k2: 3.0 / (k_r * (1.0 + nu) * (1.0 + nu)),
            k_mic,
            g_mic,
            planes: PlaneSet::new(params.quadrature),
            undamaged: (0.0, [[0.0; 6]; 6]),
        };
        m.undamaged = m.undamaged_tangent();
        Ok(m)
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
        self.update_checked(p, out);
        Ok(())
    }
}
