//! Evolving gradient activity `c` of the Helmholtz equation `eta_bar - div(c grad eta_bar) = eta` (eq. 3).
//!
//! The source paper keeps `c` constant (Table 1: `c_0 = 1 mm^2`). With a constant `c` the damage band of
//! the implicit gradient model widens without bound as the crack opens (the nonlocal field keeps feeding
//! the band's flanks; see `docs/theory.md`, "Evolving gradient activity"). The paper's conclusion names the
//! remedy: let the activity evolve. Two established forms are implemented, per material point `p`:
//!
//! - **Localizing** (Poh & Sun 2017, "localizing gradient damage model with decreasing interactions";
//!   Zhao, Yin, Tarachandani & Kaliske 2023): the interaction decreases with the damage `omega` driven by
//!   the nonlocal history `kappa_bar = max(gamma_0, kappa_bar_n, eta_bar_p)`,
//!   `omega = d(kappa_bar)` with the material's own damage law (eq. 11; for the microplane model with the
//!   paper's `eta = max_I eta_mic,I` this is the damage of the most strained plane),
//!   `g(omega) = ((1 - R) exp(-n omega) + R - exp(-n)) / (1 - exp(-n))` (`n = decay > 0`; `n = 0` is the
//!   linear limit `g = 1 - (1 - R) omega`), `c = c_0 g`, so `c_0 R <= c <= c_0`. One extra history slot
//!   holds `kappa_bar` (monotone: the interaction never grows back on unloading).
//! - **Transient** (Geers, de Borst, Brekelmans & Peerlings 1998, strain-based transient gradient): the
//!   activity follows the *local* equivalent strain of the point, `c = c_0 min(1, max(R, (eta/eta_u)^m))`
//!   (`eta_u = ultimate_strain`, `m = exponent`), so points that unload or stay elastic stop feeding the
//!   band. No history.
//!
//! The derivatives `dc/d eta_bar` (localizing, while `kappa_bar` grows) and `dc/d eta` (transient) enter
//! the Jacobian of the Helmholtz rows (see `assembly`); `c` is evaluated at the current Newton iterate.

use serde::{Deserialize, Serialize};

use super::{MaterialError, invalid};
use crate::input::serde_defaults;

serde_defaults! {
    default_residual: f64 = 0.01;
    default_decay: f64 = 5.0;
    default_exponent: f64 = 1.0;
}

/// How the gradient activity `c` evolves; `c_0` is the material's `c` (mm^2).
///
/// ```toml
/// gradient_activity = { kind = "localizing", residual = 0.01, decay = 5.0 }
/// gradient_activity = { kind = "transient", ultimate_strain = 5e-3, exponent = 1.0, residual = 0.01 }
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", deny_unknown_fields)]
pub enum GradientActivity {
    /// `c = c_0` (the source paper).
    #[default]
    #[serde(rename = "constant")]
    Constant,
    /// `c = c_0 g(d(kappa_bar))`, decreasing with the nonlocal damage (Poh & Sun 2017).
    #[serde(rename = "localizing")]
    Localizing {
        /// Residual fraction `R` of `c_0` at full damage, `0 < R <= 1` (default 0.01).
        #[serde(default = "default_residual")]
        residual: f64,
        /// Decay rate `n >= 0` of the interaction with damage (default 5; 0 = linear in damage).
        #[serde(default = "default_decay")]
        decay: f64,
    },
    /// `c = c_0 min(1, max(R, (eta/eta_u)^m))`, following the local equivalent strain (Geers et al. 1998).
    #[serde(rename = "transient")]
    Transient {
        /// Local equivalent strain `eta_u` (-) at which the full activity `c_0` is reached, > 0.
        ultimate_strain: f64,
        /// Exponent `m > 0` (default 1).
        #[serde(default = "default_exponent")]
        exponent: f64,
        /// Lower bound `R` of `c/c_0`, `0 < R <= 1` (default 0.01).
        #[serde(default = "default_residual")]
        residual: f64,
    },
}

/// The activity of one point at the current iterate and its derivatives.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Activity {
    /// `c` (mm^2).
    pub c: f64,
    /// `dc/d eta` at fixed `eta_bar` (mm^2).
    pub dc_deta: f64,
    /// `dc/d eta_bar` at fixed `eta` (mm^2).
    pub dc_deta_bar: f64,
}

impl GradientActivity {
    /// The name used in configs.
    pub fn name(&self) -> &'static str {
        match self {
            GradientActivity::Constant => "constant",
            GradientActivity::Localizing { .. } => "localizing",
            GradientActivity::Transient { .. } => "transient",
        }
    }

    /// Checks the parameter ranges (field names as in the config).
    pub fn validate(&self) -> Result<(), MaterialError> {
        let residual_ok = |r: f64| r.is_finite() && r > 0.0 && r <= 1.0;
        match *self {
            GradientActivity::Constant => Ok(()),
            GradientActivity::Localizing { residual, decay } => {
                if !residual_ok(residual) {
                    return invalid(
                        "gradient_activity.residual",
                        residual,
                        "0 < residual <= 1 (fraction of c left at full damage)",
                    );
                }
                if !(decay.is_finite() && (0.0..=50.0).contains(&decay)) {
                    return invalid("gradient_activity.decay", decay, "0 <= decay <= 50");
                }
                Ok(())
            }
            GradientActivity::Transient {
                ultimate_strain,
                exponent,
                residual,
            } => {
                if !(ultimate_strain.is_finite() && ultimate_strain > 0.0) {
                    return invalid(
                        "gradient_activity.ultimate_strain",
                        ultimate_strain,
                        "a finite strain > 0",
                    );
                }
                if !(exponent.is_finite() && exponent > 0.0 && exponent <= 10.0) {
                    return invalid("gradient_activity.exponent", exponent, "0 < exponent <= 10");
                }
                if !residual_ok(residual) {
                    return invalid(
                        "gradient_activity.residual",
                        residual,
                        "0 < residual <= 1 (lower bound of c/c_0)",
                    );
                }
                Ok(())
            }
        }
    }

    /// History slots this form adds to the material's (localizing: `kappa_bar`).
    pub fn history_len(&self) -> usize {
        match self {
            GradientActivity::Localizing { .. } => 1,
            _ => 0,
        }
    }

    /// Virgin history: `kappa_bar = gamma_0`.
    pub fn init_history(&self, gamma_0: f64, h: &mut [f64]) {
        h.fill(gamma_0);
    }

    /// `c` and its derivatives for a point with local `eta`, nonlocal `eta_bar`, committed history `h_n`
    /// (length [`GradientActivity::history_len`]); writes the trial history. `damage(kappa)` is the
    /// material's damage law `(d, d')`, `c0` its `c` (mm^2).
    #[allow(clippy::too_many_arguments)]
    pub fn evaluate(
        &self,
        c0: f64,
        gamma_0: f64,
        damage: impl Fn(f64) -> (f64, f64),
        eta: f64,
        eta_bar: f64,
        h_n: &[f64],
        h_trial: &mut [f64],
    ) -> Activity {
        match *self {
            GradientActivity::Constant => Activity {
                c: c0,
                ..Activity::default()
            },
            GradientActivity::Localizing { residual, decay } => {
                let kappa_n = h_n[0].max(gamma_0);
                let loading = eta_bar > kappa_n;
                let kappa = if loading { eta_bar } else { kappa_n };
                h_trial[0] = kappa;
                let (omega, domega) = damage(kappa);
                let (g, dg) = interaction(omega, residual, decay);
                Activity {
                    c: c0 * g,
                    dc_deta: 0.0,
                    dc_deta_bar: if loading { c0 * dg * domega } else { 0.0 },
                }
            }
            GradientActivity::Transient {
                ultimate_strain,
                exponent,
                residual,
            } => {
                let ratio = eta.max(0.0) / ultimate_strain;
                if ratio >= 1.0 {
                    return Activity {
                        c: c0,
                        ..Activity::default()
                    };
                }
                let g = ratio.powf(exponent);
                if g <= residual {
                    return Activity {
                        c: c0 * residual,
                        ..Activity::default()
                    };
                }
                Activity {
                    c: c0 * g,
                    dc_deta: c0 * exponent * g / eta,
                    dc_deta_bar: 0.0,
                }
            }
        }
    }
}

/// Poh & Sun's interaction function `g(omega)` and `g'(omega)`: `g(0) = 1`, `g(1) = R`, decreasing.
fn interaction(omega: f64, residual: f64, decay: f64) -> (f64, f64) {
    if decay < 1e-8 {
        return (1.0 - (1.0 - residual) * omega, -(1.0 - residual));
    }
    let en = (-decay).exp();
    let e = (-decay * omega).exp();
    let den = 1.0 - en;
    (
        ((1.0 - residual) * e + residual - en) / den,
        -(1.0 - residual) * decay * e / den,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn law(kappa: f64) -> (f64, f64) {
        // eq. 11 with gamma_0 = 1e-4, alpha = 0.98, beta = 650 (enough for the derivative checks).
        let (g0, a, b) = (1e-4, 0.98, 650.0);
        if kappa <= g0 {
            return (0.0, 0.0);
        }
        let ex = (b * (g0 - kappa)).exp();
        let r = g0 / kappa;
        let g = 1.0 - a + a * ex;
        (1.0 - r * g, r / kappa * g + r * a * b * ex)
    }

    #[test]
    fn interaction_runs_from_one_to_the_residual() {
        for decay in [0.0, 1.0, 5.0, 20.0] {
            let (g0, _) = interaction(0.0, 0.02, decay);
            let (g1, _) = interaction(1.0, 0.02, decay);
            assert!(
                (g0 - 1.0).abs() < 1e-14 && (g1 - 0.02).abs() < 1e-12,
                "{decay}"
            );
            for k in 0..100 {
                let w = k as f64 / 100.0;
                let (g, dg) = interaction(w, 0.02, decay);
                let h = 1e-7;
                let fd = (interaction(w + h, 0.02, decay).0 - interaction(w - h, 0.02, decay).0)
                    / (2.0 * h);
                assert!((dg - fd).abs() < 1e-6 * dg.abs().max(1.0), "{decay} {w}");
                assert!(dg < 0.0 && g > 0.0);
            }
        }
    }

    #[test]
    fn derivatives_match_finite_differences_and_history_is_monotone() {
        let loc = GradientActivity::Localizing {
            residual: 0.01,
            decay: 5.0,
        };
        let tr = GradientActivity::Transient {
            ultimate_strain: 2e-3,
            exponent: 1.5,
            residual: 0.01,
        };
        let eval = |a: &GradientActivity, eta: f64, eb: f64, hn: f64| {
            let mut ht = [0.0];
            let r = a.evaluate(1.3, 1e-4, law, eta, eb, &[hn], &mut ht);
            (r, ht[0])
        };
        // Loading (eta_bar above the history): dc/d eta_bar < 0 and the history follows eta_bar.
        let (r, k) = eval(&loc, 5e-4, 8e-4, 3e-4);
        assert_eq!(k, 8e-4);
        let h = 1e-10;
        let fd = (eval(&loc, 5e-4, 8e-4 + h, 3e-4).0.c - eval(&loc, 5e-4, 8e-4 - h, 3e-4).0.c)
            / (2.0 * h);
        assert!(r.dc_deta_bar < 0.0 && (r.dc_deta_bar - fd).abs() < 1e-6 * fd.abs());
        assert!(r.c < 1.3 && r.c > 0.013);
        // Unloading: c frozen at the history value, no derivative.
        let (r2, k2) = eval(&loc, 5e-4, 6e-4, 8e-4);
        assert_eq!((k2, r2.dc_deta_bar), (8e-4, 0.0));
        assert!((r2.c - r.c).abs() < 1e-14);
        // Transient: derivative in eta, bounds.
        let (r, _) = eval(&tr, 1e-3, 0.0, 0.0);
        let fd =
            (eval(&tr, 1e-3 + h, 0.0, 0.0).0.c - eval(&tr, 1e-3 - h, 0.0, 0.0).0.c) / (2.0 * h);
        assert!(
            (r.dc_deta - fd).abs() < 1e-6 * fd.abs(),
            "{} {fd}",
            r.dc_deta
        );
        assert_eq!(eval(&tr, 5e-3, 0.0, 0.0).0.c, 1.3);
        assert!((eval(&tr, 1e-7, 0.0, 0.0).0.c - 0.013).abs() < 1e-15);
        assert_eq!(eval(&GradientActivity::Constant, 1.0, 1.0, 0.0).0.c, 1.3);
    }

    #[test]
    fn config_forms_parse_and_bad_values_name_the_field() {
        #[derive(Deserialize)]
        struct W {
            gradient_activity: GradientActivity,
        }
        let w: W = toml::from_str("gradient_activity = { kind = \"localizing\" }").unwrap();
        assert_eq!(
            w.gradient_activity,
            GradientActivity::Localizing {
                residual: 0.01,
                decay: 5.0
            }
        );
        assert!(toml::from_str::<W>("gradient_activity = { kind = \"transient\" }").is_err());
        assert!(
            toml::from_str::<W>("gradient_activity = { kind = \"localizing\", rate = 2 }").is_err()
        );
        let w: W = toml::from_str("gradient_activity = { kind = \"localizing\", residual = 0.0 }")
            .unwrap();
        let e = w.gradient_activity.validate().unwrap_err().to_string();
        assert!(e.contains("gradient_activity.residual"), "{e}");
    }
}
