//! Isotropic (scalar) gradient-enhanced damage: a verification material for the implicit gradient
//! enhancement (`docs/gradient-enhancement.md`, section 1; benchmark V4, `tests/peerlings_bar.rs`).
//!
//! **Stress.** `P = (1 - d(gamma)) P_0(F)` (MPa) with, selected by `kinematics`,
//! - `"finite"` (default): the St. Venant-Kirchhoff stress `P_0 = F S_0`, `S_0 = lambda tr(E) I + 2 mu E`,
//!   with the Green-Lagrange strain `E = (F^T F - I)/2`;
//! - `"small"`: the Hooke stress `P_0 = lambda tr(eps) I + 2 mu eps` with `eps = sym(F) - I` (geometrically
//!   linear; the setting of the closed form of V4).
//!
//! In what follows `E` stands for the strain of the chosen kinematics.
//!
//! **Damage (eq. 11 of the source paper, the same law as the microplane model).**
//! `d(gamma) = 1 - (gamma_0/gamma)(1 - alpha + alpha exp(beta (gamma_0 - gamma)))`;
//! "perfect damage" `alpha = 1, beta = 0` gives `d = 1 - gamma_0/gamma`.
//!
//! **History (eq. 12).** One slot, `gamma = max(gamma_0, gamma_n, eta_bar)`, written to the trial history
//! and committed by the caller after a converged step.
//!
//! **Local equivalent strain `eta`** (the source of the Helmholtz equation `eta_bar - c lap eta_bar = eta`,
//! eq. 3), selected by `equivalent_strain`:
//! - `"axial"`: `eta = E_11` (the one-dimensional "eta = strain" of Peerlings et al. 1996),
//!   `d eta/dE = e_1 (x) e_1`;
//! - `"max_principal"`: the largest principal Green-Lagrange strain `eta = E_1`,
//!   `d eta/dE = v_1 (x) v_1` (`v_1` its unit eigenvector; exact for a simple largest eigenvalue).
//!
//! **Linearisation** (loading indicator `chi = 1` if `eta_bar > gamma_n` and `eta_bar > gamma_0`, else 0):
//! `dS/dE = (1 - d) C`, `dS/d eta_bar = -chi d'(gamma) S_0`, `A = dP/dF` from `S` and `dS/dE`
//! (material + geometric part), `dP/d eta_bar = F dS/d eta_bar`, `d eta/dF = F d eta/dE`.
//! Energy `Psi = (1 - d) Psi_0`, `Psi_0 = lambda/2 tr(E)^2 + mu E:E` (MPa).
//!
//! The module also holds the closed-form solution of the one-dimensional bar of V4 ([`peerlings`]).

use nalgebra::{Matrix3, SymmetricEigen};
use serde::{Deserialize, Serialize};

use super::activity::GradientActivity;
use super::elastic::modulus;
use super::{
    Constitutive, ElasticModuli, MaterialError, PAIR_INDEX, PAIRS, PointUpdate, Response, Sym6,
    check_softening, check_threshold, first_piola_from_pk2, green_lagrange, invalid, sym_to_matrix,
};

/// Definition of the local equivalent strain `eta`.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
pub enum EquivalentStrain {
    /// `eta = E_11` (one-dimensional verification).
    #[serde(rename = "axial")]
    Axial,
    /// Largest principal Green-Lagrange strain.
    #[default]
    #[serde(rename = "max_principal")]
    MaxPrincipal,
}

/// Strain measure and stress of the undamaged material.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
pub enum Kinematics {
    /// St. Venant-Kirchhoff in the Green-Lagrange strain.
    #[default]
    #[serde(rename = "finite")]
    Finite,
    /// Geometrically linear Hooke law in `eps = sym(F) - I`.
    #[serde(rename = "small")]
    Small,
}

/// The `model = "isotropic_damage"` config section (all fields required except `equivalent_strain`,
/// default `"max_principal"`, and `kinematics`, default `"finite"`).
///
/// ```toml
/// [material]
/// model = "isotropic_damage"
/// youngs_modulus = 20000.0   # MPa
/// poisson_ratio = 0.0
/// gamma_0 = 1.0e-4
/// alpha = 1.0
/// beta = 0.0
/// c = 1.0                    # mm^2; 0 = local
/// equivalent_strain = "axial"
/// kinematics = "small"
/// ```
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct IsotropicDamageConfig {
    /// Young's modulus E (MPa), > 0.
    pub youngs_modulus: f64,
    /// Poisson's ratio nu (-), -1 < nu < 0.5.
    pub poisson_ratio: f64,
    /// Damage threshold gamma_0 (-), > 0.
    pub gamma_0: f64,
    /// Maximum degradation alpha (-), 0 <= alpha <= 1.
    pub alpha: f64,
    /// Softening parameter beta (-), >= 0.
    pub beta: f64,
    /// Gradient activity parameter c (mm^2), >= 0; 0 means local.
    pub c: f64,
    /// Local equivalent strain `eta`.
    #[serde(default)]
    pub equivalent_strain: EquivalentStrain,
    /// Strain measure and undamaged stress.
    #[serde(default)]
    pub kinematics: Kinematics,
    /// Evolution of `c` (default `{ kind = "constant" }`), see [`super::activity`].
    #[serde(default)]
    pub gradient_activity: GradientActivity,
}

/// The isotropic damage material (history: one `gamma`).
#[derive(Clone, Debug)]
pub struct IsotropicDamage {
    config: IsotropicDamageConfig,
    moduli: ElasticModuli,
}

impl IsotropicDamageConfig {
    /// Validates the parameters and builds the material.
    pub fn build(&self) -> Result<IsotropicDamage, MaterialError> {
        let e = modulus("youngs_modulus", self.youngs_modulus)?;
        let nu = self.poisson_ratio;
        if !(nu.is_finite() && nu > -1.0 && nu < 0.5) {
            return invalid("poisson_ratio", nu, "-1 < nu < 0.5");
        }
        check_threshold(self.gamma_0)?;
        check_softening(self.alpha, self.beta, self.c)?;
        self.gradient_activity.validate()?;
        Ok(IsotropicDamage {
            config: self.clone(),
            moduli: ElasticModuli {
                bulk: e / (3.0 * (1.0 - 2.0 * nu)),
                shear: e / (2.0 * (1.0 + nu)),
            },
        })
    }
}

impl IsotropicDamage {
    /// The validated parameters.
    pub fn config(&self) -> &IsotropicDamageConfig {
        &self.config
    }

    /// Small-strain moduli `(K, G)` (MPa).
    pub fn moduli(&self) -> ElasticModuli {
        self.moduli
    }

    /// Damage `d(gamma)` of eq. 11 and `d'(gamma)` for `gamma >= gamma_0` (`d = 0, d' = 0` below).
    pub fn damage_law(&self, gamma: f64) -> (f64, f64) {
        let IsotropicDamageConfig {
            gamma_0,
            alpha,
            beta,
            ..
        } = self.config;
        if gamma <= gamma_0 {
            return (0.0, 0.0);
        }
        let ex = (beta * (gamma_0 - gamma)).exp();
        let g = 1.0 - alpha + alpha * ex;
        let r = gamma_0 / gamma;
        (1.0 - r * g, r / gamma * g + r * alpha * beta * ex)
    }

    /// `eta(E)` and `d eta/dE` (tensor components as [`Sym6`]).
    fn equivalent_strain(&self, e: &Sym6) -> (f64, Sym6) {
        match self.config.equivalent_strain {
            EquivalentStrain::Axial => (e[0], [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
            EquivalentStrain::MaxPrincipal => {
                let eig = SymmetricEigen::new(sym_to_matrix(e));
                let k = eig.eigenvalues.imax();
                let v = eig.eigenvectors.column(k);
                (
                    eig.eigenvalues[k],
                    [
                        v[0] * v[0],
                        v[1] * v[1],
                        v[2] * v[2],
                        v[0] * v[1],
                        v[1] * v[2],
                        v[0] * v[2],
                    ],
                )
            }
        }
    }
}

impl Constitutive for IsotropicDamage {
    fn history_len(&self) -> usize {
        1
    }

    fn init_history(&self, h: &mut [f64]) {
        h.fill(self.config.gamma_0);
    }

    fn update(&self, p: PointUpdate<'_>, out: &mut Response) -> Result<(), MaterialError> {
        p.check_history_len(1)?;
        p.check_jacobian()?;
        let (f, eta_bar, g_n) = (p.f, p.eta_bar, p.h_n[0]);
        let (lam, mu) = (self.moduli.lambda(), self.moduli.shear);
        let gamma_0 = self.config.gamma_0;
        let small = self.config.kinematics == Kinematics::Small;
        let e = if small {
            let eps = (f + f.transpose()) * 0.5 - Matrix3::identity();
            [
                eps[(0, 0)],
                eps[(1, 1)],
                eps[(2, 2)],
                eps[(0, 1)],
                eps[(1, 2)],
                eps[(0, 2)],
            ]
        } else {
            green_lagrange(f)
        };
        let tr = e[0] + e[1] + e[2];
        let (eta, g_eta) = self.equivalent_strain(&e);

        let loading = eta_bar > g_n && eta_bar > gamma_0;
        let gamma = gamma_0.max(g_n).max(eta_bar);
        p.h_trial[0] = gamma;
        let (d, dd) = self.damage_law(gamma);
        let omd = 1.0 - d;

        let mut s0: Sym6 = [0.0; 6];
        let mut dmat = [[0.0; 6]; 6];
        for (a, row) in dmat.iter_mut().enumerate() {
            s0[a] = 2.0 * mu * e[a] + if a < 3 { lam * tr } else { 0.0 };
            if a < 3 {
                row[..3].fill(omd * lam);
            }
            row[a] += omd * if a < 3 { 2.0 * mu } else { mu };
        }
        let s = s0.map(|v| omd * v);
        let chi = if loading { 1.0 } else { 0.0 };
        // d eps/dF is the symmetrisation, d E/dF = F^T (.) sym: P = S or F S, d(.)/dF likewise.
        let fk = if small { Matrix3::identity() } else { *f };
        if small {
            out.p = sym_to_matrix(&s);
            for (ij, ab) in PAIRS.iter().enumerate() {
                for k in 0..3 {
                    for l in 0..3 {
                        let v = dmat[ij][PAIR_INDEX[k][l]];
                        out.a[(3 * ab.0 + ab.1, 3 * k + l)] = v;
                        out.a[(3 * ab.1 + ab.0, 3 * k + l)] = v;
                    }
                }
            }
        } else {
            first_piola_from_pk2::<3>(f, &s, &dmat, &mut out.p, &mut out.a);
        }
        out.dp_deta_bar = fk * sym_to_matrix(&s0) * (-chi * dd);
        out.eta = eta;
        out.deta_df = fk * sym_to_matrix(&g_eta);
        let ee = e[0] * e[0]
            + e[1] * e[1]
            + e[2] * e[2]
            + 2.0 * (e[3] * e[3] + e[4] * e[4] + e[5] * e[5]);
        out.energy = omd * (0.5 * lam * tr * tr + mu * ee);
        out.damage = d;
        Ok(())
    }
}

/// Closed-form solution of the one-dimensional gradient damage bar of Peerlings et al. (1996), spec
/// 02-benchmarks V4: bar of length `L` (mm), centre zone of width `W` with the cross-section reduced by
/// the fraction `weakening`, "perfect damage" `d = 1 - gamma_0/eta_bar`, `eta = strain`, Helmholtz
/// parameter `c = l^2` (mm^2), elongation `dL` (mm).
///
/// On the half bar `0 <= x <= L/2` (`x` from the centre), with `sigma` the stress in the full section
/// and `sigma/(E gamma_0) = 1 - b^2 = (1 - weakening)(1 + g^2)`:
///
/// ```text
/// 0 <= x <= W/2:   eta_bar = C cos(g x/l),                      eps = (1 + g^2) eta_bar
/// W/2 < x <= w/2:  eta_bar = B1 exp(b x/l) + B2 exp(-b x/l),    eps = (1 - b^2) eta_bar
/// w/2 < x <= L/2:  eta_bar = (1 - b^2) gamma_0 + b^2 gamma_0 cosh((L/2 - x)/l)/cosh((L/2 - w/2)/l),
///                  eps = (1 - b^2) gamma_0
/// ```
///
/// `eta_bar` continuous, `eta_bar(w/2) = gamma_0`, `eta_bar'` continuous at `w/2`, and at `W/2` the flux
/// condition `kappa eta_bar'(W/2-) = eta_bar'(W/2+)`, and `int_0^{L/2} eps dx = dL/2`.
/// `kappa = 1` is the spec's closed form (the Helmholtz equation does not see the cross-section);
/// `kappa = 1 - weakening` is the solution of the area-weighted weak form
/// `int A [(eta_bar - eta) v + c eta_bar' v'] dx = 0` that an MPM model gets when the reduced section is
/// represented by scaling the particle volumes (then `A eta_bar'` is continuous at `W/2`).
pub mod peerlings {
    /// The bar (lengths in mm, `c` in mm^2).
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub struct Bar {
        /// Length L (mm).
        pub length: f64,
        /// Width W of the weakened centre zone (mm).
        pub weak_width: f64,
        /// Relative reduction of the cross-section in the centre zone (0.1 = 10 %).
        pub weakening: f64,
        /// Damage threshold gamma_0.
        pub gamma_0: f64,
        /// Gradient parameter c (mm^2).
        pub c: f64,
        /// Flux ratio kappa at `x = W/2` (1: spec; `1 - weakening`: area-weighted weak form).
        pub kappa: f64,
    }

    /// The solution at one elongation.
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub struct Solution {
        /// The bar.
        pub bar: Bar,
        /// Parameter b of the damaged outer zone.
        pub b: f64,
        /// Parameter g of the centre zone.
        pub g: f64,
        /// Width w of the damaged zone (mm).
        pub w: f64,
        /// Amplitude C of the centre solution.
        pub amplitude: f64,
        /// Elongation dL (mm).
        pub elongation: f64,
    }

    impl Solution {
        /// `sigma/(E gamma_0) = 1 - b^2` (stress in the full section).
        pub fn stress_ratio(&self) -> f64 {
            1.0 - self.b * self.b
        }

        /// `eta_bar(x)`, `x` measured from the centre of the bar (mm).
        pub fn eta_bar(&self, x: f64) -> f64 {
            let bar = &self.bar;
            let l = bar.c.sqrt();
            let (xi, a, s, lam) = (
                x.abs() / l,
                0.5 * bar.weak_width / l,
                0.5 * self.w / l,
                0.5 * bar.length / l,
            );
            let (b, g0) = (self.b, bar.gamma_0);
            if xi <= a {
                self.amplitude * (self.g * xi).cos()
            } else if xi <= s {
                let (p, q) = bar.outer_coefficients(b, s);
                p * (-b * (s - xi)).exp() + q * (b * (s - xi)).exp()
            } else {
                (1.0 - b * b) * g0 + b * b * g0 * (lam - xi).cosh() / (lam - s).cosh()
            }
        }
    }

    impl Bar {
        /// The V4 bar of the spec: L = 100 mm, W = 10 mm, 10 % weaker, gamma_0 = 1e-4, c = 1 mm^2.
        pub fn spec(kappa: f64) -> Self {
            Self {
                length: 100.0,
                weak_width: 10.0,
                weakening: 0.1,
                gamma_0: 1e-4,
                c: 1.0,
                kappa,
            }
        }

        /// `g` from `(1 - weakening)(1 + g^2) = 1 - b^2` (NaN when `b^2 > weakening`).
        fn g_of(&self, b: f64) -> f64 {
            ((1.0 - b * b) / (1.0 - self.weakening) - 1.0).sqrt()
        }

        /// `(P, Q)` with `eta_bar = P exp(-b (s - xi)) + Q exp(b (s - xi))` in the damaged outer zone:
        /// `eta_bar(s) = gamma_0` and `eta_bar'(s)` (per `xi = x/l`) equal to the elastic zone's
        /// `D = -b^2 gamma_0 tanh(L/(2l) - s)`.
        fn outer_coefficients(&self, b: f64, s: f64) -> (f64, f64) {
            let lam = 0.5 * self.length / self.c.sqrt();
            let d = -b * b * self.gamma_0 * (lam - s).tanh();
            (0.5 * (self.gamma_0 + d / b), 0.5 * (self.gamma_0 - d / b))
        }

        /// Flux mismatch at `W/2` for given `b` and `s = w/(2l)`, and the centre amplitude `C`.
        fn mismatch(&self, b: f64, s: f64) -> (f64, f64) {
            let a = 0.5 * self.weak_width / self.c.sqrt();
            let g = self.g_of(b);
            let (p, q) = self.outer_coefficients(b, s);
            let (ep, em) = ((-b * (s - a)).exp(), (b * (s - a)).exp());
            let eb_a = p * ep + q * em;
            let slope_out = b * (p * ep - q * em);
            let amplitude = eb_a / (g * a).cos();
            (self.kappa * g * (g * a).tan() * eb_a + slope_out, amplitude)
        }

        /// Half-width parameter `s = w/(2l)` at which the flux condition holds for this `b`.
        fn half_width(&self, b: f64) -> Option<(f64, f64)> {
            let l = self.c.sqrt();
            let (a, lam) = (0.5 * self.weak_width / l, 0.5 * self.length / l);
            let n = 4000;
            let at = |k: usize| a + (lam - a) * k as f64 / n as f64;
            let r = |s: f64| self.mismatch(b, s).0;
            let k = (0..n).find(|&k| r(at(k)).signum() != r(at(k + 1)).signum())?;
            let (mut lo, mut hi) = (at(k), at(k + 1));
            let r_lo = r(lo);
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if r(mid).signum() == r_lo.signum() {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let s = 0.5 * (lo + hi);
            Some((s, self.mismatch(b, s).1))
        }

        /// The solution for a given `b` (None if no damaged zone wider than `W` exists for it).
        fn at(&self, b: f64) -> Option<Solution> {
            let g = self.g_of(b);
            if g.is_nan() || g <= 0.0 {
                return None;
            }
            let (s, amplitude) = self.half_width(b)?;
            let l = self.c.sqrt();
            let (a, lam) = (0.5 * self.weak_width / l, 0.5 * self.length / l);
            let (p, q) = self.outer_coefficients(b, s);
            // int_0^{L/2} eps dx, zone by zone (per xi, times l).
            let centre = amplitude * (g * a).sin() / g;
            let outer = p / b * (1.0 - (-b * (s - a)).exp()) + q / b * ((b * (s - a)).exp() - 1.0);
            let elastic = (1.0 - b * b) * self.gamma_0 * (lam - s);
            let half = l * ((1.0 + g * g) * centre + (1.0 - b * b) * outer + elastic);
            Some(Solution {
                bar: *self,
                b,
                g,
                w: 2.0 * s * l,
                amplitude,
                elongation: 2.0 * half,
            })
        }

        /// The solution at the elongation `dl` (mm), by bisection on `b` in `(0, sqrt(weakening))`.
        ///
        /// The elongation falls with `b`: it grows without bound as `b` decreases to the root `b*` of
        /// `kappa g tan(g W/(2l)) = b` (below it no finite damaged zone satisfies the flux condition), and
        /// near `b = sqrt(weakening)` the damaged zone shrinks to the weak zone (no solution with `w > W`).
        pub fn solve(&self, dl: f64) -> Option<Solution> {
            let a = 0.5 * self.weak_width / self.c.sqrt();
            let too_long = |b: f64| match self.at(b) {
                Some(sol) => sol.elongation > dl,
                None => {
                    let ga = self.g_of(b) * a;
                    ga >= std::f64::consts::FRAC_PI_2 || self.kappa * self.g_of(b) * ga.tan() >= b
                }
            };
            let (mut lo, mut hi) = (0.0, self.weakening.sqrt());
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if too_long(mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let sol = self.at(hi)?;
            ((sol.elongation - dl).abs() <= 1e-9 * dl).then_some(sol)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::peerlings::Bar;
    use super::*;
    use crate::material::fdcheck::{eval, generic_f, tangent_errors};

    fn material(eq: EquivalentStrain, alpha: f64, beta: f64) -> IsotropicDamage {
        material_k(eq, alpha, beta, Kinematics::Finite)
    }

    fn material_k(eq: EquivalentStrain, alpha: f64, beta: f64, k: Kinematics) -> IsotropicDamage {
        IsotropicDamageConfig {
            youngs_modulus: 20000.0,
            poisson_ratio: 0.2,
            gamma_0: 1e-4,
            alpha,
            beta,
            c: 1.0,
            equivalent_strain: eq,
            kinematics: k,
            gradient_activity: GradientActivity::Constant,
        }
        .build()
        .unwrap()
    }

    /// Tangents against central differences in the undamaged, loading and unloading states, for both
    /// equivalent strains, both kinematics and both damage laws (perfect damage and exponential
    /// softening).
    #[test]
    fn tangents_match_finite_differences() {
        let kin = [Kinematics::Finite, Kinematics::Small];
        for (eq, k) in [EquivalentStrain::Axial, EquivalentStrain::MaxPrincipal]
            .into_iter()
            .flat_map(|eq| kin.map(|k| (eq, k)))
        {
            for (alpha, beta) in [(1.0, 0.0), (0.98, 650.0)] {
                let m = material_k(eq, alpha, beta, k);
                let f = generic_f(2e-3);
                let (r, _) = eval(&m, &f, 0.0, &[1e-4]);
                assert!(r.eta > 1e-4, "{eq:?}: eta = {}", r.eta);
                for (state, eta_bar, gamma_n) in [
                    ("undamaged", 0.5e-4, 1e-4),
                    ("loading", 3e-3, 1e-3),
                    ("unloading", 1e-3, 3e-3),
                ] {
                    let (ea, ep, ee) = tangent_errors(&m, &f, eta_bar, &[gamma_n]);
                    assert!(
                        ea < 1e-6 && ep < 1e-6 && ee < 1e-6,
                        "{eq:?} {k:?} alpha {alpha} {state}: A {ea:.2e}, dP/deta_bar {ep:.2e}, deta/dF {ee:.2e}"
                    );
                    let (r, h) = eval(&m, &f, eta_bar, &[gamma_n]);
                    let loading = state == "loading";
                    assert_eq!(r.dp_deta_bar.norm() > 0.0, loading, "{state}");
                    assert_eq!(h[0], gamma_n.max(eta_bar).max(1e-4));
                }
            }
        }
    }

    /// `eta` is `E_11` or the largest principal Green strain; damage and energy follow eq. 11.
    #[test]
    fn equivalent_strain_damage_and_energy() {
        let f = generic_f(2e-3);
        let e = green_lagrange(&f);
        let ax = material(EquivalentStrain::Axial, 1.0, 0.0);
        let (r, _) = eval(&ax, &f, 4e-4, &[1e-4]);
        assert_eq!(r.eta, e[0]);
        assert!((r.damage - 0.75).abs() < 1e-14, "d = 1 - gamma_0/gamma");
        let (r0, _) = eval(&ax, &f, 0.0, &[1e-4]);
        assert!((r.energy - 0.25 * r0.energy).abs() < 1e-12 * r0.energy);
        assert!((r.p - 0.25 * r0.p).norm() < 1e-12 * r0.p.norm());
        let mp = material(EquivalentStrain::MaxPrincipal, 1.0, 0.0);
        let (r, _) = eval(&mp, &f, 0.0, &[1e-4]);
        let eig = SymmetricEigen::new(sym_to_matrix(&e)).eigenvalues;
        assert_eq!(r.eta, eig.max());
        assert!(r.eta > e[0]);
        // Small strain: P = (1 - d)(lambda tr(eps) I + 2 mu eps), eps = sym(F) - I.
        let sm = material_k(EquivalentStrain::Axial, 1.0, 0.0, Kinematics::Small);
        let (r, _) = eval(&sm, &f, 4e-4, &[1e-4]);
        let eps = (f + f.transpose()) * 0.5 - Matrix3::identity();
        let (lam, mu) = (sm.moduli().lambda(), sm.moduli().shear);
        let hooke = Matrix3::identity() * (lam * eps.trace()) + eps * (2.0 * mu);
        assert!((r.p - 0.25 * hooke).norm() < 1e-12 * hooke.norm());
        assert_eq!(r.eta, eps[(0, 0)]);
        // Exponential law: d(gamma_0) = 0, d -> alpha for large gamma (beta > 0).
        let soft = material(EquivalentStrain::Axial, 0.98, 650.0);
        assert_eq!(soft.damage_law(1e-4).0, 0.0);
        assert!((soft.damage_law(1.0).0 - (1.0 - 1e-4 * 0.02)).abs() < 1e-12);
        // Rejected parameters.
        let bad = IsotropicDamageConfig {
            alpha: 1.5,
            ..ax.config().clone()
        };
        assert!(matches!(
            bad.build(),
            Err(MaterialError::InvalidParameter { field: "alpha", .. })
        ));
    }

    /// The closed form reproduces the spec's numbers at dL = 0.05 mm, and its `eta_bar` satisfies
    /// `int eta_bar = int eps` when the flux is continuous (kappa = 1).
    #[test]
    fn peerlings_closed_form_matches_the_spec() {
        let sol = Bar::spec(1.0).solve(0.05).expect("solution");
        let checks = [
            ("sigma/(E gamma_0)", sol.stress_ratio(), 0.93205),
            ("b", sol.b, 0.260666),
            ("g", sol.g, 0.188718),
            ("w", sol.w, 36.469),
            ("eta_bar(0)", sol.eta_bar(0.0), 3.3846e-3),
        ];
        for (name, got, want) in checks {
            assert!(
                ((got - want) / want).abs() < 2e-5,
                "{name}: {got} vs spec {want}"
            );
        }
        // Continuity and int_0^{L/2} eta_bar dx = dL/2 (midpoint rule on 10^5 intervals).
        let n = 100_000;
        let dx = 50.0 / n as f64;
        let int: f64 = (0..n)
            .map(|k| sol.eta_bar((k as f64 + 0.5) * dx) * dx)
            .sum();
        assert!((int - 0.025).abs() < 1e-6 * 0.025, "int eta_bar = {int}");
        for x in [5.0, 0.5 * sol.w] {
            let jump = sol.eta_bar(x + 1e-9) - sol.eta_bar(x - 1e-9);
            assert!(jump.abs() < 1e-9 * sol.eta_bar(x), "jump at {x}");
        }
        assert!((sol.eta_bar(0.5 * sol.w) - 1e-4).abs() < 1e-12);
        // The area-weighted variant: steeper outside, same elongation.
        let weighted = Bar::spec(0.9).solve(0.05).expect("solution");
        assert!((weighted.elongation - 0.05).abs() < 1e-12);
        assert!(weighted.stress_ratio() != sol.stress_ratio());
    }
}
