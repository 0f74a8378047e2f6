//! Elastic verification materials: small-strain Hooke, St. Venant-Kirchhoff, compressible neo-Hooke.
//!
//! All are history-free (`history_len() == 0`), local (`eta = 0`, `dP/d eta_bar = 0`) and report
//! `damage = 0`. Parameters: either Young's modulus `E` and Poisson's ratio `nu`, or bulk modulus `K`
//! and shear modulus `G` (MPa); Lame `lambda = K - 2G/3`, `mu = G`.

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

use super::{
    Constitutive, MaterialError, PointUpdate, Response, Sym6, first_piola_from_pk2, green_lagrange,
    invalid, positive_jacobian,
};

/// Elastic parameters of the `linear_elastic`, `svk` and `neo_hookean` config sections: give either
/// `youngs_modulus` + `poisson_ratio` or `bulk_modulus` + `shear_modulus`.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ElasticConfig {
    /// Young's modulus E (MPa), > 0.
    pub youngs_modulus: Option<f64>,
    /// Poisson's ratio nu (-), -1 < nu < 0.5.
    pub poisson_ratio: Option<f64>,
    /// Bulk modulus K (MPa), > 0.
    pub bulk_modulus: Option<f64>,
    /// Shear modulus G (MPa), > 0.
    pub shear_modulus: Option<f64>,
}

/// Small-strain isotropic moduli (MPa).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ElasticModuli {
    /// Bulk modulus K.
    pub bulk: f64,
    /// Shear modulus G = mu.
    pub shear: f64,
}

impl ElasticModuli {
    /// Lame's first parameter `lambda = K - 2G/3`.
    pub fn lambda(&self) -> f64 {
        self.bulk - 2.0 * self.shear / 3.0
    }
    /// Young's modulus `E = 9KG/(3K + G)`.
    pub fn youngs_modulus(&self) -> f64 {
        9.0 * self.bulk * self.shear / (3.0 * self.bulk + self.shear)
    }
    /// Poisson's ratio `nu = (3K - 2G)/(2(3K + G))`.
    pub fn poisson_ratio(&self) -> f64 {
        (3.0 * self.bulk - 2.0 * self.shear) / (2.0 * (3.0 * self.bulk + self.shear))
    }
}

/// The range of an elastic modulus (Young's, bulk or shear; MPa) a real solid can have: from soft foams
/// (1e-6 MPa) to ten times diamond's Young's modulus (1.2e6 MPa); outside it the stiffness or the wave
/// speed of a run overflows or vanishes and the first step gives NaN.
pub const MODULUS_RANGE: (f64, f64) = (1e-6, 1e7);

/// An elastic modulus `v` (MPa) within [`MODULUS_RANGE`].
pub(crate) fn modulus(field: &'static str, v: f64) -> Result<f64, MaterialError> {
    if v.is_finite() && (MODULUS_RANGE.0..=MODULUS_RANGE.1).contains(&v) {
        Ok(v)
    } else {
        invalid(
            field,
            v,
            "a modulus in [1e-6, 1e7] MPa (concrete about 3e4, steel 2.1e5, diamond 1.2e6)",
        )
    }
}

impl ElasticConfig {
    /// Validated moduli.
    pub fn moduli(&self) -> Result<ElasticModuli, MaterialError> {
        match (
            self.youngs_modulus,
            self.poisson_ratio,
            self.bulk_modulus,
            self.shear_modulus,
        ) {
            (Some(e), Some(nu), None, None) => {
                let e = modulus("youngs_modulus", e)?;
                if !(nu.is_finite() && nu > -1.0 && nu < 0.5) {
                    return invalid("poisson_ratio", nu, "-1 < nu < 0.5");
                }
                Ok(ElasticModuli {
                    bulk: e / (3.0 * (1.0 - 2.0 * nu)),
                    shear: e / (2.0 * (1.0 + nu)),
                })
            }
            (None, None, Some(k), Some(g)) => Ok(ElasticModuli {
                bulk: modulus("bulk_modulus", k)?,
                shear: modulus("shear_modulus", g)?,
            }),
            (None, None, None, None) => Err(MaterialError::MissingParameter {
                field: "youngs_modulus",
                hint: "give youngs_modulus + poisson_ratio or bulk_modulus + shear_modulus",
            }),
            (e, nu, k, g) if (e.is_some() || nu.is_some()) && (k.is_some() || g.is_some()) => {
                Err(MaterialError::Conflict(
                    "give either youngs_modulus + poisson_ratio or bulk_modulus + shear_modulus, not both",
                ))
            }
            (e, _, k, _) => Err(MaterialError::MissingParameter {
                field: if e.is_some() {
                    "poisson_ratio"
                } else if k.is_some() {
                    "shear_modulus"
                } else if self.poisson_ratio.is_some() {
                    "youngs_modulus"
                } else {
                    "bulk_modulus"
                },
                hint: "elastic moduli come in pairs: youngs_modulus + poisson_ratio or bulk_modulus + shear_modulus",
            }),
        }
    }
}

/// Geometrically linear Hooke law: `P = lambda tr(eps) I + 2 mu eps`, `eps = sym(F) - I`.
/// The tangent `A_iJkL = lambda delta_iJ delta_kL + mu (delta_ik delta_JL + delta_iL delta_Jk)` is constant.
/// Energy `Psi = lambda/2 tr(eps)^2 + mu eps:eps`.
#[derive(Clone, Debug)]
pub struct LinearElastic {
    /// Bulk and shear modulus (MPa).
    pub moduli: ElasticModuli,
}

/// St. Venant-Kirchhoff: `S = lambda tr(E) I + 2 mu E`, `P = F S`, `Psi = lambda/2 tr(E)^2 + mu E:E`.
#[derive(Clone, Debug)]
pub struct StVenantKirchhoff {
    /// Bulk and shear modulus (MPa).
    pub moduli: ElasticModuli,
}

/// Compressible neo-Hooke: `P = mu (F - F^-T) + lambda ln J F^-T`,
/// `Psi = mu/2 (tr C - 3) - mu ln J + lambda/2 (ln J)^2`; `det F <= 0` is an error.
#[derive(Clone, Debug)]
pub struct NeoHookean {
    /// Bulk and shear modulus (MPa).
    pub moduli: ElasticModuli,
}

impl LinearElastic {
    /// The law with the moduli `moduli` (MPa).
    pub fn new(moduli: ElasticModuli) -> Self {
        Self { moduli }
    }
}
impl StVenantKirchhoff {
    /// The law with the moduli `moduli` (MPa).
    pub fn new(moduli: ElasticModuli) -> Self {
        Self { moduli }
    }
}
impl NeoHookean {
    /// The law with the moduli `moduli` (MPa).
    pub fn new(moduli: ElasticModuli) -> Self {
        Self { moduli }
    }
}

fn kd(i: usize, j: usize) -> f64 {
    if i == j { 1.0 } else { 0.0 }
}

fn clear_nonlocal(out: &mut Response) {
    out.dp_deta_bar = Matrix3::zeros();
    out.eta = 0.0;
    out.deta_df = Matrix3::zeros();
    out.damage = 0.0;
}

/// A history-free local elastic law (the three laws of this file): only the stress, the tangent and the
/// energy differ; [`Constitutive::update`] checks `F` and clears the nonlocal outputs around
/// [`ElasticLaw::stress`].
trait ElasticLaw {
    /// `out.p`, `out.a` and `out.energy` at a finite `f`.
    fn stress(&self, f: &Matrix3<f64>, out: &mut Response) -> Result<(), MaterialError>;
}

impl<T: ElasticLaw + Send + Sync> Constitutive for T {
    fn update(&self, p: PointUpdate<'_>, out: &mut Response) -> Result<(), MaterialError> {
        p.check_finite()?;
        self.stress(p.f, out)?;
        clear_nonlocal(out);
        Ok(())
    }
}

impl ElasticLaw for LinearElastic {
    fn stress(&self, f: &Matrix3<f64>, out: &mut Response) -> Result<(), MaterialError> {
        let (lam, mu) = (self.moduli.lambda(), self.moduli.shear);
        let eps = (f + f.transpose()) * 0.5 - Matrix3::identity();
        let tr = eps.trace();
        out.p = Matrix3::identity() * (lam * tr) + eps * (2.0 * mu);
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    for l in 0..3 {
                        out.a[(3 * i + j, 3 * k + l)] = lam * kd(i, j) * kd(k, l)
                            + mu * (kd(i, k) * kd(j, l) + kd(i, l) * kd(j, k));
                    }
                }
            }
        }
        out.energy = 0.5 * lam * tr * tr + mu * eps.norm_squared();
        Ok(())
    }
}

impl ElasticLaw for StVenantKirchhoff {
    fn stress(&self, f: &Matrix3<f64>, out: &mut Response) -> Result<(), MaterialError> {
        let (lam, mu) = (self.moduli.lambda(), self.moduli.shear);
        let e = green_lagrange(f);
        let tr = e[0] + e[1] + e[2];
        let mut s: Sym6 = [0.0; 6];
        let mut d = [[0.0; 6]; 6];
        for (a, row) in d.iter_mut().enumerate() {
            s[a] = 2.0 * mu * e[a] + if a < 3 { lam * tr } else { 0.0 };
            if a < 3 {
                row[..3].fill(lam);
            }
            row[a] += if a < 3 { 2.0 * mu } else { mu };
        }
        first_piola_from_pk2::<3>(f, &s, &d, &mut out.p, &mut out.a);
        let ee = e[0] * e[0]
            + e[1] * e[1]
            + e[2] * e[2]
            + 2.0 * (e[3] * e[3] + e[4] * e[4] + e[5] * e[5]);
        out.energy = 0.5 * lam * tr * tr + mu * ee;
        Ok(())
    }
}

impl ElasticLaw for NeoHookean {
    fn stress(&self, f: &Matrix3<f64>, out: &mut Response) -> Result<(), MaterialError> {
        let (lam, mu) = (self.moduli.lambda(), self.moduli.shear);
        let det = positive_jacobian(f)?;
        let fi = f
            .try_inverse()
            .ok_or(MaterialError::NonPositiveJacobian { det })?;
        let ln_j = det.ln();
        let fit = fi.transpose();
        out.p = (f - fit) * mu + fit * (lam * ln_j);
        // A_iJkL = mu d_ik d_JL + (mu - lambda ln J) Fi_Jk Fi_Li + lambda Fi_Ji Fi_Lk
        let c1 = mu - lam * ln_j;
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    for l in 0..3 {
                        out.a[(3 * i + j, 3 * k + l)] = mu * kd(i, k) * kd(j, l)
                            + c1 * fi[(j, k)] * fi[(l, i)]
                            + lam * fi[(j, i)] * fi[(l, k)];
                    }
                }
            }
        }
        out.energy = 0.5 * mu * (f.norm_squared() - 3.0) - mu * ln_j + 0.5 * lam * ln_j * ln_j;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::fdcheck::{eval, generic_f, rel_err, rotation, tangent_errors};

    fn moduli() -> ElasticModuli {
        ElasticConfig {
            youngs_modulus: Some(36000.0),
            poisson_ratio: Some(0.18),
            ..Default::default()
        }
        .moduli()
        .unwrap()
    }

    fn all() -> Vec<(&'static str, Box<dyn Constitutive>)> {
        vec![
            ("linear", Box::new(LinearElastic::new(moduli()))),
            ("svk", Box::new(StVenantKirchhoff::new(moduli()))),
            ("neo", Box::new(NeoHookean::new(moduli()))),
        ]
    }

    #[test]
    fn moduli_conversions_round_trip() {
        let m = moduli();
        assert!((m.youngs_modulus() - 36000.0).abs() < 1e-9);
        assert!((m.poisson_ratio() - 0.18).abs() < 1e-14);
        let table1 = ElasticModuli {
            bulk: 18750.0,
            shear: 15254.0,
        };
        assert!(
            (table1.poisson_ratio() - 0.18).abs() < 1e-4,
            "Table 1: nu = {}",
            table1.poisson_ratio()
        );
    }

    #[test]
    fn tangents_match_finite_differences() {
        for (name, m) in all() {
            for scale in [1e-3, 0.1] {
                let f = generic_f(scale);
                let (ea, ep, ee) = tangent_errors(m.as_ref(), &f, 0.0, &[]);
                assert!(ea < 1e-6, "{name} scale {scale}: A rel err {ea}");
                assert!(
                    ep == 0.0 && ee == 0.0,
                    "{name}: local material has eta-derivatives"
                );
            }
        }
    }

    #[test]
    fn stress_is_energy_derivative() {
        for (name, m) in all() {
            let f = generic_f(0.05);
            let (r, _) = eval(m.as_ref(), &f, 0.0, &[]);
            let h = 1e-7;
            let mut p_fd = Matrix3::zeros();
            for k in 0..3 {
                for l in 0..3 {
                    let mut fp = f;
                    fp[(k, l)] += h;
                    let mut fm = f;
                    fm[(k, l)] -= h;
                    p_fd[(k, l)] = (eval(m.as_ref(), &fp, 0.0, &[]).0.energy
                        - eval(m.as_ref(), &fm, 0.0, &[]).0.energy)
                        / (2.0 * h);
                }
            }
            assert!(rel_err(&r.p, &p_fd) < 1e-6, "{name}: P != dPsi/dF");
        }
    }

    #[test]
    fn finite_strain_models_are_frame_invariant() {
        let f = generic_f(0.1);
        let q = rotation([0.3, -0.7, 0.4]);
        for (name, m) in all().into_iter().skip(1) {
            let (r, _) = eval(m.as_ref(), &f, 0.0, &[]);
            let (rq, _) = eval(m.as_ref(), &(q * f), 0.0, &[]);
            assert!(
                rel_err(&rq.p, &(q * r.p)) < 1e-13,
                "{name}: P(QF) != Q P(F)"
            );
            assert!(
                (rq.energy - r.energy).abs() <= 1e-13 * r.energy,
                "{name}: energy not invariant"
            );
        }
    }

    #[test]
    fn small_strain_limit_agrees_between_models() {
        let f = generic_f(1e-6);
        let (lin, _) = eval(&LinearElastic::new(moduli()), &f, 0.0, &[]);
        for (name, m) in all() {
            let (r, _) = eval(m.as_ref(), &f, 0.0, &[]);
            assert!(rel_err(&r.p, &lin.p) < 1e-5, "{name}");
            assert!(rel_err(&r.a, &lin.a) < 1e-5, "{name}");
        }
    }

    #[test]
    fn neo_hookean_rejects_inverted_f() {
        let m = NeoHookean::new(moduli());
        let f = Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, -0.5, 1.0));
        let mut out = Response::zeros();
        let err = m
            .update(PointUpdate::new(&f, 0.0, &[], &mut []), &mut out)
            .unwrap_err();
        assert!(matches!(err, MaterialError::NonPositiveJacobian { det } if det == -0.5));
    }
}
