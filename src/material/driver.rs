//! Material-point driver: runs one material point along strain- or mixed-controlled paths.
//!
//! Paths ([`PathKind`]); the control variable `eps` is a nominal strain:
//! - uniaxial tension/compression: `F11 = 1 + eps` prescribed, `P22 = P33 = 0` (uniaxial stress),
//!   the lateral stretches `F22`, `F33` solved by Newton with the consistent tangent;
//! - cyclic tension/compression: the same with load-unload-reload to zero strain at
//!   `eps = 0.3, 0.6, 1.0 x max_strain`;
//! - biaxial tension: `F11 = F22 = 1 + eps`, `P33 = 0`;
//! - pure shear: `F = I + eps/2 (e1 (x) e2 + e2 (x) e1)`, fully strain controlled.
//!
//! Nonlocal variable: local (`eta_bar = eta(F)`, Newton uses `A + dP/d eta_bar (x) d eta/dF`) or a
//! prescribed ramp `eta_bar = eta_bar_max |eps| / max_strain`. The history is committed after each
//! converged step, exactly as the MPM solver does.
//!
//! [`uniaxial_strengths`] measures the implied uniaxial tensile and compressive strengths of a microplane
//! material (peak `|P11|` on monotonic uniaxial-stress paths). The `material-driver` command (files,
//! plot, command line) is `crate::app::material_driver`.

use nalgebra::{DMatrix, DVector, Matrix3};

use super::{Constitutive, Material, MaterialError, PointUpdate, Response};

/// Load path of the material-point driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathKind {
    /// Uniaxial stress, tension.
    UniaxialTension,
    /// Uniaxial stress, compression.
    UniaxialCompression,
    /// Uniaxial stress, load-unload-reload in tension.
    CyclicTension,
    /// Uniaxial stress, load-unload-reload in compression.
    CyclicCompression,
    /// Equibiaxial tension, `P33 = 0`.
    BiaxialTension,
    /// Pure shear strain `F12 = F21 = eps/2`.
    PureShear,
}

impl PathKind {
    /// Every path.
    pub const ALL: [PathKind; 6] = [
        PathKind::UniaxialTension,
        PathKind::UniaxialCompression,
        PathKind::CyclicTension,
        PathKind::CyclicCompression,
        PathKind::BiaxialTension,
        PathKind::PureShear,
    ];

    /// Kebab-case name (as on the command line).
    pub fn name(self) -> &'static str {
        match self {
            PathKind::UniaxialTension => "uniaxial-tension",
            PathKind::UniaxialCompression => "uniaxial-compression",
            PathKind::CyclicTension => "cyclic-tension",
            PathKind::CyclicCompression => "cyclic-compression",
            PathKind::BiaxialTension => "biaxial-tension",
            PathKind::PureShear => "pure-shear",
        }
    }

    /// Sign of the control strain.
    pub fn sign(self) -> f64 {
        match self {
            PathKind::UniaxialCompression | PathKind::CyclicCompression => -1.0,
            _ => 1.0,
        }
    }

    /// Stress component plotted against the control strain.
    pub fn stress_component(self) -> (usize, usize) {
        if self == PathKind::PureShear {
            (0, 1)
        } else {
            (0, 0)
        }
    }

    /// Free components of `F` (their conjugate `P` components vanish).
    fn free_components(self) -> &'static [(usize, usize)] {
        match self {
            PathKind::PureShear => &[],
            PathKind::BiaxialTension => &[(2, 2)],
            _ => &[(1, 1), (2, 2)],
        }
    }

    /// Prescribed part of `F` at control strain `eps` (free components are overwritten by the solver).
    fn prescribed_f(self, eps: f64) -> Matrix3<f64> {
        let mut f = Matrix3::identity();
        match self {
            PathKind::PureShear => {
                f[(0, 1)] = 0.5 * eps;
                f[(1, 0)] = 0.5 * eps;
            }
            PathKind::BiaxialTension => {
                f[(0, 0)] = 1.0 + eps;
                f[(1, 1)] = 1.0 + eps;
            }
            _ => f[(0, 0)] = 1.0 + eps,
        }
        f
    }

    /// Control strains of the `steps + 1` states (starting at 0); `max_strain` is a magnitude.
    pub fn control_path(self, max_strain: f64, steps: usize) -> Vec<f64> {
        let s = self.sign() * max_strain;
        let turning: &[f64] = match self {
            PathKind::CyclicTension | PathKind::CyclicCompression => {
                &[0.0, 0.3, 0.0, 0.6, 0.0, 1.0]
            }
            _ => &[0.0, 1.0],
        };
        let total: f64 = turning.windows(2).map(|w| (w[1] - w[0]).abs()).sum();
        let mut path = vec![0.0];
        for w in turning.windows(2) {
            let n = ((steps as f64 * (w[1] - w[0]).abs() / total).round() as usize).max(1);
            path.extend((1..=n).map(|k| s * (w[0] + (w[1] - w[0]) * k as f64 / n as f64)));
        }
        path
    }
}

/// How `eta_bar` is set along the path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EtaBarPath {
    /// Local model: `eta_bar = eta(F)`.
    Local,
    /// `eta_bar = max |eps| / max_strain`, independent of `F`.
    Prescribed {
        /// `eta_bar` at the largest strain of the path.
        max: f64,
    },
}

/// One converged state of the path.
#[derive(Clone, Copy, Debug)]
pub struct PathPoint {
    /// Control strain (nominal).
    pub control: f64,
    /// Deformation gradient.
    pub f: Matrix3<f64>,
    /// First Piola-Kirchhoff stress (MPa).
    pub p: Matrix3<f64>,
    /// Cauchy stress (MPa).
    pub sigma: Matrix3<f64>,
    /// Local equivalent strain eta.
    pub eta: f64,
    /// Nonlocal equivalent strain used.
    pub eta_bar: f64,
    /// Output damage scalar (see [`Response::damage`]).
    pub damage: f64,
    /// Free energy density (MPa).
    pub energy: f64,
    /// Newton iterations of the step.
    pub iterations: usize,
}

/// Implied uniaxial strengths (peak nominal stress magnitudes, MPa) and the strains at the peaks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Strengths {
    /// Peak `P11` in uniaxial tension (MPa).
    pub tensile: f64,
    /// `F11 - 1` at the tensile peak.
    pub tensile_strain: f64,
    /// Peak `|P11|` in uniaxial compression (MPa).
    pub compressive: f64,
    /// `|F11 - 1|` at the compressive peak.
    pub compressive_strain: f64,
}

/// Runs `material` along `kind` and returns the converged states (the first one is `F = I`).
pub fn run_path(
    material: &Material,
    kind: PathKind,
    max_strain: f64,
    steps: usize,
    eta_bar_path: EtaBarPath,
) -> Result<Vec<PathPoint>, MaterialError> {
    if !(max_strain.is_finite() && max_strain > 0.0 && max_strain < 1.0) {
        return Err(MaterialError::DriverArgument(format!(
            "max strain {max_strain} must lie in (0, 1)"
        )));
    }
    if steps == 0 {
        return Err(MaterialError::DriverArgument("steps must be >= 1".into()));
    }
    let free = kind.free_components();
    let nfree = free.len();
    let mut h_n = vec![0.0; material.history_len()];
    material.init_history(&mut h_n);
    let mut h_trial = h_n.clone();
    let mut out = Response::zeros();
    let mut x = vec![1.0; nfree]; // free components of F (diagonal stretches)
    let mut points = Vec::new();
    for (step, &eps) in kind.control_path(max_strain, steps).iter().enumerate() {
        let mut f = kind.prescribed_f(eps);
        let mut iterations = 0;
        let mut eta_bar;
        loop {
            for (j, &(a, b)) in free.iter().enumerate() {
                f[(a, b)] = x[j];
            }
            eta_bar = match eta_bar_path {
                EtaBarPath::Local => {
                    material.update(PointUpdate::new(&f, 0.0, &h_n, &mut h_trial), &mut out)?;
                    out.eta
                }
                EtaBarPath::Prescribed { max } => max * eps.abs() / max_strain,
            };
            material.update(PointUpdate::new(&f, eta_bar, &h_n, &mut h_trial), &mut out)?;
            let r = DVector::from_iterator(nfree, free.iter().map(|&(a, b)| out.p[(a, b)]));
            let tol = 1e-9 + 1e-12 * out.p.norm();
            let res = r.amax();
            if res <= tol {
                break;
            }
            if iterations == 50 {
                return Err(MaterialError::DriverNotConverged {
                    step,
                    residual: res,
                });
            }
            let tangent = match eta_bar_path {
                EtaBarPath::Local => out.local_tangent(),
                EtaBarPath::Prescribed { .. } => out.a,
            };
            let jac = DMatrix::from_fn(nfree, nfree, |j, k| {
                let (a, b) = free[j];
                let (c, d) = free[k];
                tangent[(3 * a + b, 3 * c + d)]
            });
            let dx = jac
                .lu()
                .solve(&r)
                .ok_or(MaterialError::DriverNotConverged {
                    step,
                    residual: res,
                })?;
            for j in 0..nfree {
                x[j] -= dx[j];
            }
            iterations += 1;
        }
        h_n.copy_from_slice(&h_trial);
        let det = f.determinant();
        points.push(PathPoint {
            control: eps,
            f,
            p: out.p,
            sigma: out.p * f.transpose() / det,
            eta: out.eta,
            eta_bar,
            damage: out.damage,
            energy: out.energy,
            iterations,
        });
    }
    Ok(points)
}

/// Peak magnitude of the plotted stress component and the control strain there.
pub fn peak(points: &[PathPoint], kind: PathKind) -> (f64, f64) {
    let (i, j) = kind.stress_component();
    points.iter().fold((0.0, 0.0), |acc, pt| {
        let s = pt.p[(i, j)].abs();
        if s > acc.0 {
            (s, pt.control.abs())
        } else {
            acc
        }
    })
}

/// Implied uniaxial strengths of a microplane material: local model, monotonic uniaxial stress,
/// tension to `10 gamma_0` and compression to `40 gamma_0` with `steps` steps each (the peaks lie well
/// inside). `None` for elastic materials (no strength).
pub fn uniaxial_strengths(
    material: &Material,
    steps: usize,
) -> Result<Option<Strengths>, MaterialError> {
    let Material::Microplane(m) = material else {
        return Ok(None);
    };
    let g0 = m.params().gamma_0;
    let t = run_path(
        material,
        PathKind::UniaxialTension,
        10.0 * g0,
        steps,
        EtaBarPath::Local,
    )?;
    let c = run_path(
        material,
        PathKind::UniaxialCompression,
        40.0 * g0,
        steps,
        EtaBarPath::Local,
    )?;
    let (tensile, tensile_strain) = peak(&t, PathKind::UniaxialTension);
    let (compressive, compressive_strain) = peak(&c, PathKind::UniaxialCompression);
    Ok(Some(Strengths {
        tensile,
        tensile_strain,
        compressive,
        compressive_strain,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{ElasticConfig, MaterialConfig, MicroplaneConfig, Preset};

    /// The path of `kind` driven with the local `eta_bar = eta` (panics on error).
    fn local_path(m: &Material, kind: PathKind, max: f64, steps: usize) -> Vec<PathPoint> {
        run_path(m, kind, max, steps, EtaBarPath::Local).unwrap()
    }

    fn paper(preset: Preset) -> Material {
        MaterialConfig::Microplane(MicroplaneConfig::preset(preset))
            .build()
            .unwrap()
    }

    #[test]
    fn uniaxial_stress_path_has_zero_lateral_stress_and_elastic_start() {
        let m = paper(Preset::Paper);
        let pts = local_path(&m, PathKind::UniaxialTension, 5e-4, 10);
        let e_mod = 9.0 * 18750.0 * 15254.0 / (3.0 * 18750.0 + 15254.0);
        for p in &pts[1..] {
            assert!(p.p[(1, 1)].abs() < 1e-8 && p.p[(2, 2)].abs() < 1e-8);
            assert!(p.damage == 0.0);
            // nominal stress of SVK-like small strain response: E eps (1 + O(eps))
            assert!(
                (p.p[(0, 0)] / (e_mod * p.control) - 1.0).abs() < 3.0 * p.control,
                "{}",
                p.p[(0, 0)]
            );
            // lateral contraction: Poisson ratio 0.18
            assert!(((1.0 - p.f[(1, 1)]) / p.control - 0.18).abs() < 1e-3);
        }
    }

    #[test]
    fn tensile_peak_matches_the_onset_estimate_and_softens() {
        // Elastic limit: the plane normal to the load reaches gamma_0 at eps = gamma_0 / 1.0630.
        let m = paper(Preset::PaperGamma0Low);
        let (max, steps) = (3e-3, 600);
        let pts = local_path(&m, PathKind::UniaxialTension, max, steps);
        let (peak_s, peak_e) = peak(&pts, PathKind::UniaxialTension);
        let onset = pts.iter().find(|p| p.damage > 0.0).unwrap().control;
        let expected = 1.25e-4 / 1.0630;
        assert!(
            onset >= expected * (1.0 - 1e-3) && onset <= expected + max / steps as f64 * 1.001,
            "onset at {onset}"
        );
        assert!(peak_e > onset && peak_s > 0.0);
        let last = pts.last().unwrap();
        assert!(
            last.p[(0, 0)] < 0.5 * peak_s,
            "no softening: {}",
            last.p[(0, 0)]
        );
        assert!(last.damage > 0.5);
    }

    /// Strength-ratio bound. For the de Vree equivalent strain that eqs. 14-16 distribute over the
    /// microplanes, an elastic uniaxial stress state (Poisson nu) gives eta = eps in tension and
    /// eta = |eps|/k_r in compression, so a scalar damage model driven by it has strength ratio exactly k_r.
    /// The microplane version damages plane by plane: in compression the planes inclined to the load
    /// carry the largest eta_mic (onset ratio eta_t/eta_c computed below from eq. 14), and planes that
    /// are still elastic keep carrying load after the first ones soften. Hence the measured ratio must
    /// lie between the onset ratio (first-damage stresses) and k_r (the scalar de Vree value).
    #[test]
    fn strength_ratio_lies_between_onset_ratio_and_k_r() {
        for preset in [Preset::Paper, Preset::PaperGamma0Low] {
            let m = paper(preset);
            let Material::Microplane(mp) = &m else {
                unreachable!()
            };
            let k_r = mp.params().k_r;
            // onset ratio from the elastic uniaxial-stress strain state, maximised over the planes
            let onset = |sign: f64| {
                let eps = sign * 1e-7;
                let f = Matrix3::from_diagonal(&nalgebra::Vector3::new(
                    1.0 + eps,
                    1.0 - 0.18 * eps,
                    1.0 - 0.18 * eps,
                ));
                let mut h = vec![0.0; m.history_len()];
                m.init_history(&mut h);
                let mut ht = h.clone();
                let mut out = Response::zeros();
                m.update(PointUpdate::new(&f, 0.0, &h, &mut ht), &mut out)
                    .unwrap();
                out.eta / 1e-7
            };
            let onset_ratio = onset(1.0) / onset(-1.0);
            let s = uniaxial_strengths(&m, 300).unwrap().unwrap();
            let ratio = s.compressive / s.tensile;
            assert!(onset_ratio > 1.0 && onset_ratio < k_r);
            assert!(
                ratio > onset_ratio && ratio < k_r,
                "{preset:?}: ratio {ratio}, onset {onset_ratio}, k_r {k_r}"
            );
            // the peaks are interior to the driven ranges
            let g0 = mp.params().gamma_0;
            assert!(
                s.tensile_strain < 9.0 * g0 && s.compressive_strain < 39.0 * g0,
                "{s:?}"
            );
        }
    }

    #[test]
    fn cyclic_path_unloads_secantly_to_zero_stress() {
        let m = paper(Preset::PaperGamma0Low);
        let pts = local_path(&m, PathKind::CyclicTension, 1e-3, 300);
        // unloading branches end at zero strain with zero stress
        for p in pts.iter().skip(1).filter(|p| p.control == 0.0) {
            assert!(p.p.norm() < 1e-8, "stress at zero strain {}", p.p.norm());
        }
        // on the first unloading branch P11/eps is constant (secant stiffness), smaller than E
        let peak1 = pts
            .iter()
            .position(|p| (p.control - 3e-4).abs() < 1e-15)
            .unwrap();
        let k_sec = pts[peak1].p[(0, 0)] / pts[peak1].control;
        let e_mod = 9.0 * 18750.0 * 15254.0 / (3.0 * 18750.0 + 15254.0);
        assert!(k_sec < 0.9 * e_mod);
        for p in pts[peak1..].iter().take_while(|p| p.control > 0.0) {
            assert!(
                (p.p[(0, 0)] / p.control - k_sec).abs() < 1e-3 * k_sec + 1e-6,
                "not secant at {}",
                p.control
            );
        }
    }

    #[test]
    fn monotone_history_along_cyclic_compression() {
        let m = MaterialConfig::Microplane(MicroplaneConfig {
            preset: Some(Preset::PaperGamma0Low),
            eta_mode: Some(crate::material::EtaMode::Mean),
            ..Default::default()
        })
        .build()
        .unwrap();
        let pts = local_path(&m, PathKind::CyclicCompression, 3e-3, 200);
        let d_max = pts.iter().map(|p| p.damage).fold(0.0, f64::max);
        assert!(d_max > 0.1 && d_max < 1.0);
        assert!(pts.iter().all(|p| p.iterations < 20));
    }

    #[test]
    fn prescribed_eta_bar_and_other_paths_run() {
        let m = paper(Preset::Paper);
        let pts = run_path(
            &m,
            PathKind::BiaxialTension,
            2e-3,
            50,
            EtaBarPath::Prescribed { max: 5e-3 },
        )
        .unwrap();
        assert!((pts.last().unwrap().eta_bar - 5e-3).abs() < 1e-15);
        assert!(pts.iter().all(|p| p.p[(2, 2)].abs() < 1e-8));
        let pts = local_path(&m, PathKind::PureShear, 2e-3, 20);
        let g = 15254.0;
        assert!((pts[1].p[(0, 1)] / (g * pts[1].control) - 1.0).abs() < 1e-3);
        let elastic = MaterialConfig::NeoHookean(ElasticConfig {
            youngs_modulus: Some(100.0),
            poisson_ratio: Some(0.3),
            ..Default::default()
        })
        .build()
        .unwrap();
        let pts = local_path(&elastic, PathKind::UniaxialCompression, 0.2, 20);
        assert!(pts.last().unwrap().p[(1, 1)].abs() < 1e-8);
        assert!(uniaxial_strengths(&elastic, 10).unwrap().is_none());
        assert!(
            run_path(
                &elastic,
                PathKind::UniaxialTension,
                2.0,
                20,
                EtaBarPath::Local
            )
            .is_err()
        );
    }
}
