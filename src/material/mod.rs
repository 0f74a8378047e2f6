//! Constitutive models in the first-Piola form used by the implicit MPM assembly.
//!
//! Every material is evaluated in 3D from the deformation gradient `F` (a 2D plane-strain run passes
//! `F13 = F23 = F31 = F32 = 0`, `F33 = 1`). Units: stress and energy density in MPa (= mJ/mm^3 per
//! reference volume), strains dimensionless, the gradient parameter `c` in mm^2.
//!
//! Models (see `docs/material.md`):
//! - [`LinearElastic`]: geometrically linear Hooke law, verification only.
//! - [`StVenantKirchhoff`]: `S = lambda tr(E) I + 2 mu E`.
//! - [`NeoHookean`]: compressible, `P = mu (F - F^-T) + lambda ln J F^-T`.
//! - [`Microplane`]: the finite-strain, gradient-enhanced microplane damage model of the source paper
//!   (Oropeza-Navarro et al., eqs. 9-16), see [`microplane`].
//!
//! The interface is incremental and pure: [`Constitutive::update`] reads the committed history `h_n`
//! and writes the trial history `h_trial`, which the caller commits only after the step converged.

pub mod activity;
pub mod driver;
pub mod elastic;
pub mod isotropic;
pub mod microplane;
pub mod quadrature;

use nalgebra::{Matrix3, SMatrix};
use serde::{Deserialize, Serialize};

pub use activity::{Activity, GradientActivity};
pub use elastic::{ElasticConfig, ElasticModuli, LinearElastic, NeoHookean, StVenantKirchhoff};
pub use isotropic::{EquivalentStrain, IsotropicDamage, IsotropicDamageConfig, Kinematics};
pub use microplane::{
    EtaMode, Microplane, MicroplaneConfig, MicroplaneParams, Preset, StrainMeasure,
};
pub use quadrature::Quadrature;

/// 9x9 matrix of a fourth-order two-point tangent, `A_iJkL` stored at `(3*i+J, 3*k+L)`.
pub type Matrix9 = SMatrix<f64, 9, 9>;

/// Output of one constitutive evaluation (units: MPa; energy in MPa = mJ/mm^3 per reference volume).
#[derive(Clone, Copy, Debug)]
pub struct Response {
    /// First Piola-Kirchhoff stress `P = F S` (MPa).
    pub p: Matrix3<f64>,
    /// Consistent tangent `A_iJkL = dP_iJ/dF_kL` stored at `(3*i+J, 3*k+L)` (MPa), at fixed `eta_bar`.
    pub a: Matrix9,
    /// `dP/d eta_bar` at fixed `F` (MPa; zero for local/elastic materials).
    pub dp_deta_bar: Matrix3<f64>,
    /// Macroscopic local equivalent strain `eta`, the source of the Helmholtz equation (eq. 3; 0 for elastic).
    pub eta: f64,
    /// `d eta / dF` (`= F d eta/dE` for an `eta(E)`).
    pub deta_df: Matrix3<f64>,
    /// Scalar damage for output. Microplane: energy-weighted `1 - Psi/Psi_0` (see
    /// [`Microplane`]); 0 for elastic materials.
    pub damage: f64,
    /// Stored (free) energy density `Psi` per reference volume (MPa).
    pub energy: f64,
    /// Energy density dissipated over the step (MPa = mJ/mm^3 per reference volume), split into the
    /// microplanes under tensile `[0]` and compressive `[1]` normal strain `n . E . n` (microplane model;
    /// zero for the other laws): `sum_I 6 w_I psi_0,I (d_I - d_I^n)`.
    pub dissipation: [f64; 2],
    /// The same released energy by the trapezoidal rule in the undamaged plane energy,
    /// `sum_I 6 w_I (psi_0,I^n + psi_0,I)/2 (d_I - d_I^n)` (MPa), with `psi_0,I^n` at the step's start
    /// `F_n` ([`PointUpdate::with_start`]); without `F_n`, the sum of [`Response::dissipation`]. It
    /// converges to the path integral of `psi_0 dd` at second order in the strain increment, where the
    /// end-point rule converges at first order and overestimates it.
    pub dissipation_trapezoidal: f64,
    /// Gradient activity `c` of the Helmholtz equation at this state (mm^2) and its derivatives
    /// `dc/d eta`, `dc/d eta_bar` (see [`activity`]); 0 for local and elastic materials.
    pub activity: Activity,
}

impl Response {
    /// All fields zero.
    pub fn zeros() -> Self {
        Self {
            p: Matrix3::zeros(),
            a: Matrix9::zeros(),
            dp_deta_bar: Matrix3::zeros(),
            eta: 0.0,
            deta_df: Matrix3::zeros(),
            damage: 0.0,
            energy: 0.0,
            dissipation: [0.0; 2],
            dissipation_trapezoidal: 0.0,
            activity: Activity::default(),
        }
    }

    /// Tangent of `P` along a local path `eta_bar = eta(F)`:
    /// `A + dP/d eta_bar (x) d eta/dF` (the Jacobian a local material-point driver needs).
    pub fn local_tangent(&self) -> Matrix9 {
        let mut a = self.a;
        for ij in 0..9 {
            let dp = self.dp_deta_bar[(ij / 3, ij % 3)];
            if dp != 0.0 {
                for kl in 0..9 {
                    a[(ij, kl)] += dp * self.deta_df[(kl / 3, kl % 3)];
                }
            }
        }
        a
    }
}

impl Default for Response {
    fn default() -> Self {
        Self::zeros()
    }
}

/// Errors of the material layer: invalid configuration, inadmissible states, driver failures.
#[derive(Clone, Debug, thiserror::Error)]
pub enum MaterialError {
    /// A parameter is outside its admissible range.
    #[error("material parameter `{field}` = {} is invalid: allowed is {allowed}", crate::input::shown(*.value))]
    InvalidParameter {
        /// The parameter's config key.
        field: &'static str,
        /// The value given.
        value: f64,
        /// The admissible range.
        allowed: &'static str,
    },
    /// A parameter is neither given nor provided by a preset.
    #[error("material parameter `{field}` is missing: {hint}")]
    MissingParameter {
        /// The parameter's config key.
        field: &'static str,
        /// How to provide it.
        hint: &'static str,
    },
    /// Parameters that exclude each other were given together.
    #[error("conflicting material parameters: {0}")]
    Conflict(&'static str),
    /// `det F <= 0`: the configuration is inverted (report as a domain error to the solver).
    #[error("non-positive Jacobian det F = {det}")]
    NonPositiveJacobian {
        /// `J = det F`.
        det: f64,
    },
    /// `F` or `eta_bar` contains NaN or infinity.
    #[error("non-finite input to the material update ({what})")]
    NonFiniteInput {
        /// Which input.
        what: &'static str,
    },
    /// The history slices do not have [`Constitutive::history_len`] entries.
    #[error("history slice has length {got}, the material needs {expected}")]
    HistoryLength {
        /// Entries the material needs.
        expected: usize,
        /// Entries given.
        got: usize,
    },
    /// The material-point driver's Newton iteration on the free components did not converge.
    #[error("material-point driver: no convergence at step {step} (residual {residual:e} MPa)")]
    DriverNotConverged {
        /// The load step.
        step: usize,
        /// Largest free stress component at the last iterate (MPa).
        residual: f64,
    },
    /// Invalid arguments of a material-point path.
    #[error("material-point driver: {0}")]
    DriverArgument(String),
    /// A material section given as text does not parse (unknown model or key, wrong type).
    #[error("material section: {0}")]
    Section(String),
}

/// The error of a parameter `field` (config key) whose `value` lies outside the range `allowed`.
pub(crate) fn invalid<T>(
    field: &'static str,
    value: f64,
    allowed: &'static str,
) -> Result<T, MaterialError> {
    Err(MaterialError::InvalidParameter {
        field,
        value,
        allowed,
    })
}

/// The largest softening parameter `beta` (-): 1e7, four decades above Table 1's 650; beyond it
/// `exp(beta (gamma_0 - gamma))` drops from 1 to 0 within a strain increment of 1e-6 or less, below what
/// a step resolves.
pub const BETA_MAX: f64 = 1e7;

/// The largest gradient parameter `c` (mm^2): 1e6, an interaction length `sqrt(c)` of one metre, larger
/// than any specimen this code is meant for.
pub const C_MAX: f64 = 1e6;

/// The largest damage threshold `gamma_0` (a strain): 0.1, eighty times Table 1's 1.25e-3; a threshold
/// beyond it is not that of a quasi-brittle material.
pub const GAMMA_0_MAX: f64 = 0.1;

/// Checks the damage threshold `0 < gamma_0 <=` [`GAMMA_0_MAX`] of the damage models.
pub(crate) fn check_threshold(gamma_0: f64) -> Result<(), MaterialError> {
    if gamma_0 > 0.0 && gamma_0 <= GAMMA_0_MAX {
        Ok(())
    } else {
        invalid("gamma_0", gamma_0, "0 < gamma_0 <= 0.1 (a strain)")
    }
}

/// Checks the parameters of the damage law (eq. 11) and of the Helmholtz equation shared by the damage
/// models: maximum degradation `0 <= alpha <= 1`, softening `0 <= beta <=` [`BETA_MAX`] (-) and the
/// gradient parameter `0 <= c <=` [`C_MAX`] (mm^2; 0 = local).
pub(crate) fn check_softening(alpha: f64, beta: f64, c: f64) -> Result<(), MaterialError> {
    if !(0.0..=1.0).contains(&alpha) {
        return invalid("alpha", alpha, "0 <= alpha <= 1");
    }
    if !(0.0..=BETA_MAX).contains(&beta) {
        return invalid("beta", beta, "0 <= beta <= 1e7");
    }
    if !(0.0..=C_MAX).contains(&c) {
        return invalid("c", c, "0 <= c <= 1e6 (mm^2; 0 = local)");
    }
    Ok(())
}

/// A constitutive law in first-Piola form (see [`Response`]).
pub trait Constitutive: Send + Sync {
    /// Number of f64 history slots per material point (microplane: one `gamma` per direction); none
    /// unless the law keeps a history.
    fn history_len(&self) -> usize {
        0
    }
    /// Initial (virgin) history; nothing unless the law keeps a history.
    fn init_history(&self, _h: &mut [f64]) {}
    /// Pure in the committed history `p.h_n`; writes the trial history to `p.h_trial` (committed by
    /// the caller only after the step converges).
    fn update(&self, p: PointUpdate<'_>, out: &mut Response) -> Result<(), MaterialError>;
}

/// The arguments of one constitutive evaluation at a material point.
pub struct PointUpdate<'a> {
    /// Deformation gradient `F` (3x3; plane strain: `F33 = 1`, no out-of-plane shear).
    pub f: &'a Matrix3<f64>,
    /// Nonlocal equivalent strain `eta_bar` (-) at the point (0 for a local evaluation).
    pub eta_bar: f64,
    /// Committed history `h_n` (read only).
    pub h_n: &'a [f64],
    /// Trial history `h_trial` (written; committed by the caller only after the step converged).
    pub h_trial: &'a mut [f64],
    /// Deformation gradient `F_n` at the start of the step, for the trapezoidal dissipation
    /// ([`Response::dissipation_trapezoidal`]); `None` takes the end-point rule.
    pub f_n: Option<&'a Matrix3<f64>>,
    /// The caller reads only the in-plane entries of the tangent [`Response::a`] (every index `< 2`:
    /// plane strain, whose `F` has `F33 = 1` and no out-of-plane shear). A law may then leave the other
    /// entries untouched; the microplane law does, its push-forward to `A` being then a fifth of the
    /// work, with the in-plane entries the same to the bit. False: the whole `A`.
    pub in_plane: bool,
}

impl<'a> PointUpdate<'a> {
    /// The arguments `F`, `eta_bar`, `h_n`, `h_trial` bundled.
    pub fn new(f: &'a Matrix3<f64>, eta_bar: f64, h_n: &'a [f64], h_trial: &'a mut [f64]) -> Self {
        Self {
            f,
            eta_bar,
            h_n,
            h_trial,
            f_n: None,
            in_plane: false,
        }
    }

    /// The same arguments, asking for the in-plane entries of `A` only where `in_plane`
    /// ([`PointUpdate::in_plane`]).
    pub fn in_plane(self, in_plane: bool) -> Self {
        Self { in_plane, ..self }
    }

    /// The same arguments with the step's starting deformation gradient `F_n` (3x3), from which the
    /// trapezoidal dissipation takes `psi_0,I^n`.
    pub fn with_start(self, f_n: &'a Matrix3<f64>) -> Self {
        Self {
            f_n: Some(f_n),
            ..self
        }
    }

    /// Checks `F` and `eta_bar` for NaN/inf.
    pub(crate) fn check_finite(&self) -> Result<(), MaterialError> {
        if !self.f.iter().all(|x| x.is_finite()) {
            return Err(MaterialError::NonFiniteInput {
                what: "deformation gradient F",
            });
        }
        if !self.eta_bar.is_finite() {
            return Err(MaterialError::NonFiniteInput { what: "eta_bar" });
        }
        Ok(())
    }

    /// [`PointUpdate::check_finite`], then `det F > 0` ([`MaterialError::NonPositiveJacobian`]
    /// otherwise): the checks of the laws that need an invertible `F`. Returns `J = det F`.
    pub(crate) fn check_jacobian(&self) -> Result<f64, MaterialError> {
        self.check_finite()?;
        positive_jacobian(self.f)
    }

    /// Refuses history slices `h_n`, `h_trial` that do not both have `expected` entries
    /// ([`MaterialError::HistoryLength`], naming the first that differs).
    pub(crate) fn check_history_len(&self, expected: usize) -> Result<(), MaterialError> {
        for got in [self.h_n.len(), self.h_trial.len()] {
            if got != expected {
                return Err(MaterialError::HistoryLength { expected, got });
            }
        }
        Ok(())
    }
}

/// The materials of the project (enum dispatch).
#[derive(Clone, Debug)]
pub enum Material {
    /// Geometrically linear Hooke law.
    LinearElastic(LinearElastic),
    /// St. Venant-Kirchhoff hyperelasticity.
    StVenantKirchhoff(StVenantKirchhoff),
    /// Compressible neo-Hooke hyperelasticity.
    NeoHookean(NeoHookean),
    /// The gradient-enhanced microplane damage model of the paper (boxed: its plane tables are large).
    Microplane(Box<Microplane>),
    /// Isotropic gradient-enhanced damage (verification of the Helmholtz field, see [`isotropic`]).
    IsotropicDamage(IsotropicDamage),
}

impl Material {
    /// True for a damage model with a gradient parameter `c > 0` (then the Helmholtz field is solved).
    pub fn is_nonlocal(&self) -> bool {
        self.gradient_parameter() > 0.0
    }

    /// How the gradient activity evolves (constant for every material without a Helmholtz field).
    pub fn gradient_activity(&self) -> GradientActivity {
        match self {
            Material::Microplane(m) => m.params().gradient_activity,
            Material::IsotropicDamage(m) => m.config().gradient_activity,
            _ => GradientActivity::Constant,
        }
    }

    /// Damage threshold `gamma_0` and damage law `d(gamma), d'(gamma)` (eq. 11) of a damage model.
    fn damage_law(&self, gamma: f64) -> (f64, f64) {
        match self {
            Material::Microplane(m) => m.damage_law(gamma.max(m.params().gamma_0)),
            Material::IsotropicDamage(m) => m.damage_law(gamma),
            _ => (0.0, 0.0),
        }
    }

    /// Damage threshold `gamma_0` of a damage model (0 for elastic laws).
    pub fn gamma_0(&self) -> f64 {
        match self {
            Material::Microplane(m) => m.params().gamma_0,
            Material::IsotropicDamage(m) => m.config().gamma_0,
            _ => 0.0,
        }
    }

    /// Whether a point with committed damage `damage` has eroded into a void: no stress, no stiffness, its
    /// deformation gradient frozen and no nonlocal diffusion through it (`erosion_damage` of the config).
    pub fn is_eroded(&self, damage: f64) -> bool {
        match self {
            Material::Microplane(m) => m.params().erosion_damage.is_some_and(|de| damage >= de),
            _ => false,
        }
    }

    /// History slots of the constitutive law itself (before the activity's).
    fn law_history_len(&self) -> usize {
        match self {
            Material::LinearElastic(m) => m.history_len(),
            Material::StVenantKirchhoff(m) => m.history_len(),
            Material::NeoHookean(m) => m.history_len(),
            Material::Microplane(m) => m.history_len(),
            Material::IsotropicDamage(m) => m.history_len(),
        }
    }

    /// Reference gradient activity parameter `c_0` of eq. 3 (mm^2; the constant `c` of the paper);
    /// 0 for local and elastic materials.
    pub fn gradient_parameter(&self) -> f64 {
        match self {
            Material::Microplane(m) => m.params().c,
            Material::IsotropicDamage(m) => m.config().c,
            _ => 0.0,
        }
    }

    /// Small-strain elastic moduli `(K, G)` in MPa (for wave speeds, time-step estimates, scaling).
    pub fn elastic_moduli(&self) -> ElasticModuli {
        match self {
            Material::LinearElastic(m) => m.moduli,
            Material::StVenantKirchhoff(m) => m.moduli,
            Material::NeoHookean(m) => m.moduli,
            Material::Microplane(m) => ElasticModuli {
                bulk: m.params().bulk_modulus,
                shear: m.params().shear_modulus,
            },
            Material::IsotropicDamage(m) => m.moduli(),
        }
    }
}

/// History layout of a [`Material`]: the law's slots, then the gradient activity's (`kappa_bar` of the
/// localizing form).
impl Constitutive for Material {
    fn history_len(&self) -> usize {
        self.law_history_len() + self.gradient_activity().history_len()
    }

    fn init_history(&self, h: &mut [f64]) {
        let n = self.law_history_len();
        self.gradient_activity()
            .init_history(self.gamma_0(), &mut h[n..]);
        let h = &mut h[..n];
        match self {
            Material::LinearElastic(m) => m.init_history(h),
            Material::StVenantKirchhoff(m) => m.init_history(h),
            Material::NeoHookean(m) => m.init_history(h),
            Material::Microplane(m) => m.init_history(h),
            Material::IsotropicDamage(m) => m.init_history(h),
        }
    }

    fn update(&self, p: PointUpdate<'_>, out: &mut Response) -> Result<(), MaterialError> {
        p.check_history_len(self.history_len())?;
        let n = self.law_history_len();
        let (law_n, act_n) = p.h_n.split_at(n);
        let (law_trial, act_trial) = p.h_trial.split_at_mut(n);
        let (f, eta_bar) = (p.f, p.eta_bar);
        let law = PointUpdate {
            f_n: p.f_n,
            in_plane: p.in_plane,
            ..PointUpdate::new(f, eta_bar, law_n, law_trial)
        };
        match self {
            Material::LinearElastic(m) => m.update(law, out)?,
            Material::StVenantKirchhoff(m) => m.update(law, out)?,
            Material::NeoHookean(m) => m.update(law, out)?,
            Material::Microplane(m) => m.update(law, out)?,
            Material::IsotropicDamage(m) => m.update(law, out)?,
        }
        out.activity = self.gradient_activity().evaluate(
            self.gradient_parameter(),
            self.gamma_0(),
            |g| self.damage_law(g),
            out.eta,
            eta_bar,
            act_n,
            act_trial,
        );
        Ok(())
    }
}

/// Material section of a TOML config, tagged by `model`. Density is not part of it.
///
/// ```toml
/// [material]
/// model = "microplane"
/// preset = "paper"        # Table 1; any field given explicitly overrides the preset
/// gamma_0 = 1.25e-4
/// ```
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(tag = "model")]
pub enum MaterialConfig {
    /// Small-strain Hooke law (verification).
    #[serde(rename = "linear_elastic")]
    LinearElastic(ElasticConfig),
    /// St. Venant-Kirchhoff.
    #[serde(rename = "svk")]
    StVenantKirchhoff(ElasticConfig),
    /// Compressible neo-Hooke.
    #[serde(rename = "neo_hookean")]
    NeoHookean(ElasticConfig),
    /// Gradient-enhanced finite-strain microplane damage (spec Sec. 3).
    #[serde(rename = "microplane")]
    Microplane(MicroplaneConfig),
    /// Isotropic gradient-enhanced damage (verification, see [`isotropic`]).
    #[serde(rename = "isotropic_damage")]
    IsotropicDamage(IsotropicDamageConfig),
}

impl MaterialConfig {
    /// Validates all parameters and builds the material (precomputing the microplane tensors).
    pub fn build(&self) -> Result<Material, MaterialError> {
        Ok(match self {
            MaterialConfig::LinearElastic(c) => {
                Material::LinearElastic(LinearElastic::new(c.moduli()?))
            }
            MaterialConfig::StVenantKirchhoff(c) => {
                Material::StVenantKirchhoff(StVenantKirchhoff::new(c.moduli()?))
            }
            MaterialConfig::NeoHookean(c) => Material::NeoHookean(NeoHookean::new(c.moduli()?)),
            MaterialConfig::Microplane(c) => {
                Material::Microplane(Box::new(Microplane::new(c.resolve()?)?))
            }
            MaterialConfig::IsotropicDamage(c) => Material::IsotropicDamage(c.build()?),
        })
    }

    /// The material of a section given as TOML text (`model = "svk"\nyoungs_modulus = 100.0 ...`),
    /// built ([`MaterialConfig::build`]): for tests, examples and studies that write a law inline.
    pub fn build_toml(text: &str) -> Result<Material, MaterialError> {
        let cfg: MaterialConfig = toml::from_str(text)
            .map_err(|e| MaterialError::Section(e.message().trim().replace('\n', " ")))?;
        cfg.build()
    }
}

/// Symmetric second-order tensor in tensor components `[T11, T22, T33, T12, T23, T13]`.
pub(crate) type Sym6 = [f64; 6];

/// Index pairs `(I, J)` of the [`Sym6`] components.
pub(crate) const PAIRS: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2)];

/// Component index in [`Sym6`] of the pair `(I, J)`.
pub(crate) const PAIR_INDEX: [[usize; 3]; 3] = [[0, 3, 5], [3, 1, 4], [5, 4, 2]];

/// Green-Lagrange strain `E = (F^T F - I)/2` as [`Sym6`].
pub(crate) fn green_lagrange(f: &Matrix3<f64>) -> Sym6 {
    let mut e = [0.0; 6];
    for (a, &(i, j)) in PAIRS.iter().enumerate() {
        let mut cij = 0.0;
        for k in 0..3 {
            cij += f[(k, i)] * f[(k, j)];
        }
        e[a] = 0.5 * (cij - if i == j { 1.0 } else { 0.0 });
    }
    e
}

/// The logarithmic (Hencky) strain `E_h = ln(C)/2`, `C = F^T F`, with what is needed to pull a gradient
/// back to the Green-Lagrange strain: `dE_h/dE = d ln C/dC =: L` (as `C = 2E + I`), in the spectral form
/// `L : G = sum_ab theta_ab (N_a . G . N_b) N_a (x) N_b` over the eigenpairs `(lambda_a, N_a)` of `C`,
/// `theta_aa = 1/lambda_a`, `theta_ab = (ln lambda_a - ln lambda_b)/(lambda_a - lambda_b)`. `L` is
/// major-symmetric, so a gradient `G_h = d phi/dE_h` gives `d phi/dE = L : G_h`.
pub(crate) struct Hencky {
    q: Matrix3<f64>,
    theta: [[f64; 3]; 3],
}

impl Hencky {
    /// `E_h` as [`Sym6`] and its pull-back operator, for `F` with `det F > 0`.
    pub(crate) fn new(f: &Matrix3<f64>) -> (Sym6, Self) {
        let eig = nalgebra::SymmetricEigen::new(f.transpose() * f);
        let lam = eig.eigenvalues;
        let q = eig.eigenvectors;
        let ln = lam.map(f64::ln);
        let mut theta = [[0.0; 3]; 3];
        for a in 0..3 {
            for b in 0..3 {
                let (la, lb) = (lam[a], lam[b]);
                theta[a][b] = if (la - lb).abs() <= 1e-9 * la.max(lb) {
                    // Limit of the divided difference, to second order in (la - lb).
                    let m = 0.5 * (la + lb);
                    1.0 / m
                } else {
                    (ln[a] - ln[b]) / (la - lb)
                };
            }
        }
        let eh = q * Matrix3::from_diagonal(&(0.5 * ln)) * q.transpose();
        (PAIRS.map(|(i, j)| eh[(i, j)]), Self { q, theta })
    }

    /// `L : G` for a symmetric `G` given as [`Sym6`] tensor components.
    pub(crate) fn pull(&self, g: &Sym6) -> Sym6 {
        let mut gq = self.q.transpose() * sym_to_matrix(g) * self.q;
        for a in 0..3 {
            for b in 0..3 {
                gq[(a, b)] *= self.theta[a][b];
            }
        }
        let out = self.q * gq * self.q.transpose();
        PAIRS.map(|(i, j)| out[(i, j)])
    }
}

/// Full matrix of a [`Sym6`].
pub(crate) fn sym_to_matrix(s: &Sym6) -> Matrix3<f64> {
    Matrix3::new(s[0], s[3], s[5], s[3], s[1], s[4], s[5], s[4], s[2])
}

/// First Piola stress and two-point tangent from `S` and a material tangent `dS/dE`.
///
/// `d[a][b] = C_IJKL` with `(I, J) = PAIRS[a]`, `(K, L) = PAIRS[b]`, minor-symmetric in both pairs
/// (need not be major-symmetric). Then `P = F S` and
/// `A_iJkL = delta_ik S_JL + F_iI C_IJML F_kM`, for every index below `N`: `N = 3` forms the whole
/// `A`; `N = 2` only its in-plane entries (the others are left as they were), which for a plane-strain
/// `F` (`F_i2 = 0` for `i < 2`) equal those of `N = 3` to the bit: the terms it leaves out are exact
/// zeros added last.
#[inline(always)]
pub(crate) fn first_piola_from_pk2<const N: usize>(
    f: &Matrix3<f64>,
    s: &Sym6,
    d: &[[f64; 6]; 6],
    p: &mut Matrix3<f64>,
    a: &mut Matrix9,
) {
    let sm = sym_to_matrix(s);
    *p = f * sm;
    // b[a][k][l] = sum_M C_{pair a, M l} F_kM
    let mut b = [[[0.0; 3]; 3]; 6];
    for (ab, row) in d.iter().enumerate() {
        for k in 0..N {
            for l in 0..N {
                let mut acc = 0.0;
                for m in 0..N {
                    acc += row[PAIR_INDEX[m][l]] * f[(k, m)];
                }
                b[ab][k][l] = acc;
            }
        }
    }
    for i in 0..N {
        for jj in 0..N {
            for k in 0..N {
                for l in 0..N {
                    let mut acc = if i == k { sm[(jj, l)] } else { 0.0 };
                    for ii in 0..N {
                        acc += f[(i, ii)] * b[PAIR_INDEX[ii][jj]][k][l];
                    }
                    a[(3 * i + jj, 3 * k + l)] = acc;
                }
            }
        }
    }
}

/// `J = det F` of a finite `F`, or [`MaterialError::NonPositiveJacobian`] where `J <= 0`.
pub(crate) fn positive_jacobian(f: &Matrix3<f64>) -> Result<f64, MaterialError> {
    let det = f.determinant();
    if det <= 0.0 {
        return Err(MaterialError::NonPositiveJacobian { det });
    }
    Ok(det)
}

/// Finite-difference helpers shared by the material tests.
#[cfg(test)]
pub(crate) mod fdcheck {
    use super::*;

    /// Relative error `|a - b| / max(|a|, |b|)` in the Frobenius norm (0 when both vanish).
    pub fn rel_err<const R: usize, const C: usize>(
        a: &SMatrix<f64, R, C>,
        b: &SMatrix<f64, R, C>,
    ) -> f64 {
        let den = a.norm().max(b.norm());
        if den == 0.0 {
            0.0
        } else {
            (a - b).norm() / den
        }
    }

    /// Evaluates the material, panicking on error (test helper).
    pub fn eval(
        m: &dyn Constitutive,
        f: &Matrix3<f64>,
        eta_bar: f64,
        h_n: &[f64],
    ) -> (Response, Vec<f64>) {
        let mut out = Response::zeros();
        let mut h = vec![0.0; m.history_len()];
        m.update(PointUpdate::new(f, eta_bar, h_n, &mut h), &mut out)
            .expect("material update");
        (out, h)
    }

    /// Central finite differences of `P` w.r.t. `F`, of `P` w.r.t. `eta_bar` and of `eta` w.r.t. `F`.
    /// Returns the relative errors `(A, dP/d eta_bar, d eta/dF)`.
    pub fn tangent_errors(
        m: &dyn Constitutive,
        f: &Matrix3<f64>,
        eta_bar: f64,
        h_n: &[f64],
    ) -> (f64, f64, f64) {
        let (r, _) = eval(m, f, eta_bar, h_n);
        let h = 1e-8;
        let mut a_fd = Matrix9::zeros();
        let mut deta_fd = Matrix3::zeros();
        for k in 0..3 {
            for l in 0..3 {
                let mut fp = *f;
                fp[(k, l)] += h;
                let mut fm = *f;
                fm[(k, l)] -= h;
                let (rp, _) = eval(m, &fp, eta_bar, h_n);
                let (rm, _) = eval(m, &fm, eta_bar, h_n);
                for i in 0..3 {
                    for j in 0..3 {
                        a_fd[(3 * i + j, 3 * k + l)] = (rp.p[(i, j)] - rm.p[(i, j)]) / (2.0 * h);
                    }
                }
                deta_fd[(k, l)] = (rp.eta - rm.eta) / (2.0 * h);
            }
        }
        let he = 1e-7 * eta_bar.abs().max(1e-4);
        let (rp, _) = eval(m, f, eta_bar + he, h_n);
        let (rm, _) = eval(m, f, eta_bar - he, h_n);
        let dp_fd = (rp.p - rm.p) / (2.0 * he);
        (
            rel_err(&r.a, &a_fd),
            rel_err(&r.dp_deta_bar, &dp_fd),
            rel_err(&r.deta_df, &deta_fd),
        )
    }

    /// A rotation matrix from a rotation vector (Rodrigues).
    pub fn rotation(axis: [f64; 3]) -> Matrix3<f64> {
        nalgebra::Rotation3::new(nalgebra::Vector3::from(axis)).into_inner()
    }

    /// A generic (non-symmetric) deformation gradient `I + scale * G` with a fixed pattern `G`.
    pub fn generic_f(scale: f64) -> Matrix3<f64> {
        let g = Matrix3::new(0.83, 0.31, -0.22, -0.17, -0.41, 0.27, 0.12, 0.35, 0.56);
        Matrix3::identity() + g * scale
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_parses_tagged_sections_and_rejects_unknown_fields() {
        let c: MaterialConfig =
            toml::from_str("model = \"microplane\"\npreset = \"paper\"\ngamma_0 = 2e-4\n").unwrap();
        let m = c.build().unwrap();
        assert!(m.is_nonlocal());
        assert_eq!(m.gradient_parameter(), 1.0);
        let Material::Microplane(mp) = &m else {
            panic!("not a microplane")
        };
        assert_eq!(mp.params().gamma_0, 2e-4);
        assert_eq!(mp.params().k_r, 14.0);

        let c: MaterialConfig =
            toml::from_str("model = \"svk\"\nyoungs_modulus = 100.0\npoisson_ratio = 0.0\n")
                .unwrap();
        assert!(!c.build().unwrap().is_nonlocal());
        assert!(
            toml::from_str::<MaterialConfig>("model = \"svk\"\nyoungs_modulus = 1.0\nfoo = 1\n")
                .is_err()
        );
        assert!(
            toml::from_str::<MaterialConfig>(
                "model = \"microplane\"\npreset = \"paper\"\nkr = 3\n"
            )
            .is_err()
        );
        assert!(toml::from_str::<MaterialConfig>("model = \"plastic\"\n").is_err());
    }

    #[test]
    fn invalid_parameters_name_field_and_value() {
        let c: MaterialConfig =
            toml::from_str("model = \"microplane\"\npreset = \"paper\"\nk_r = 0.5\n").unwrap();
        let err = c.build().unwrap_err();
        assert!(
            matches!(err, MaterialError::InvalidParameter { field: "k_r", value, .. } if value == 0.5)
        );
        let msg = err.to_string();
        assert!(
            msg.contains("k_r") && msg.contains("0.5") && msg.contains("1 < k_r <= 1000"),
            "{msg}"
        );

        for (toml_src, field) in [
            ("alpha = 1.5", "alpha"),
            ("beta = -1.0", "beta"),
            ("beta = 2e7", "beta"),
            ("gamma_0 = 0.0", "gamma_0"),
            ("gamma_0 = 0.2", "gamma_0"),
            ("c = -1.0", "c"),
            ("c = 2e6", "c"),
            ("k_r = 1001.0", "k_r"),
            ("poisson_ratio = 0.5", "poisson_ratio"),
            ("bulk_modulus = -3.0", "bulk_modulus"),
            ("shear_modulus = 0.0", "shear_modulus"),
        ] {
            let c: MaterialConfig = toml::from_str(&format!(
                "model = \"microplane\"\npreset = \"paper\"\n{toml_src}\n"
            ))
            .unwrap();
            let err = c.build().unwrap_err();
            assert!(
                matches!(err, MaterialError::InvalidParameter { field: f, .. } if f == field),
                "{toml_src}: {err}"
            );
        }
        let c: MaterialConfig = toml::from_str("model = \"microplane\"\nk_r = 10.0\n").unwrap();
        assert!(matches!(
            c.build().unwrap_err(),
            MaterialError::MissingParameter { .. }
        ));
        let c: MaterialConfig =
            toml::from_str("model = \"neo_hookean\"\nyoungs_modulus = -1.0\npoisson_ratio = 0.3\n")
                .unwrap();
        assert!(matches!(
            c.build().unwrap_err(),
            MaterialError::InvalidParameter {
                field: "youngs_modulus",
                ..
            }
        ));
        let c: MaterialConfig = toml::from_str(
            "model = \"linear_elastic\"\nyoungs_modulus = 1.0\npoisson_ratio = 0.3\nbulk_modulus = 1.0\nshear_modulus = 1.0\n",
        )
        .unwrap();
        assert!(matches!(c.build().unwrap_err(), MaterialError::Conflict(_)));
    }

    #[test]
    fn wrong_history_length_and_nan_are_errors() {
        let m = MaterialConfig::Microplane(MicroplaneConfig::preset(Preset::Paper))
            .build()
            .unwrap();
        let mut h = vec![0.0; m.history_len()];
        m.init_history(&mut h);
        let mut ht = vec![0.0; 3];
        let mut out = Response::zeros();
        let f = Matrix3::identity();
        assert!(matches!(
            m.update(PointUpdate::new(&f, 0.0, &h, &mut ht), &mut out),
            Err(MaterialError::HistoryLength { .. })
        ));
        let mut ht = h.clone();
        let mut fnan = f;
        fnan[(0, 1)] = f64::NAN;
        assert!(matches!(
            m.update(PointUpdate::new(&fnan, 0.0, &h, &mut ht), &mut out),
            Err(MaterialError::NonFiniteInput { .. })
        ));
        let finv = Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, -1.0));
        assert!(matches!(
            m.update(PointUpdate::new(&finv, 0.0, &h, &mut ht), &mut out),
            Err(MaterialError::NonPositiveJacobian { .. })
        ));
    }
}
