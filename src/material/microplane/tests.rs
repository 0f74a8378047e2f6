//! Tests of the microplane model: tangents against finite differences, isotropy, the damage law and the
//! Table 1 response.

use super::*;
use crate::material::fdcheck::{eval, generic_f, rel_err, rotation, tangent_errors};
use crate::material::{green_lagrange, sym_to_matrix};
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
        // The tangent of the undamaged planes, formed once for the kernel's undamaged points: Hooke's
        // C_IJKL = (K - 2G/3) d_IJ d_KL + G (d_IK d_JL + d_IL d_JK).
        let kd = |i: usize, j: usize| f64::from(u8::from(i == j));
        for (a, &(i, j)) in crate::material::PAIRS.iter().enumerate() {
            for (b, &(k, l)) in crate::material::PAIRS.iter().enumerate() {
                let c = (kk - 2.0 * gg / 3.0) * kd(i, j) * kd(k, l)
                    + gg * (kd(i, k) * kd(j, l) + kd(i, l) * kd(j, k));
                let got = m.undamaged.1[a][b];
                assert!(
                    (got - c).abs() <= 1e-10 * kk,
                    "{q:?}: C[{a}][{b}] = {got} vs {c}"
                );
            }
        }
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

/// Asking for the in-plane tangent only (the 2D assembly's request) must give the whole tangent's
/// in-plane entries to the bit for a plane-strain `F`, in every state of the law, and the same stress,
/// history and nonlocal terms.
#[test]
fn in_plane_tangent_is_the_whole_tangent_restricted() {
    let m = paper();
    for (label, f, eb, h) in states(&m, 2.5e-3) {
        let mut f2 = Matrix3::identity();
        f2.fixed_view_mut::<2, 2>(0, 0)
            .copy_from(&f.fixed_view::<2, 2>(0, 0));
        let (mut full, mut part) = (Response::zeros(), Response::zeros());
        let (mut h1, mut h2) = (h.clone(), h.clone());
        m.update(PointUpdate::new(&f2, eb, &h, &mut h1), &mut full)
            .unwrap();
        m.update(
            PointUpdate::new(&f2, eb, &h, &mut h2).in_plane(true),
            &mut part,
        )
        .unwrap();
        assert_eq!(h1, h2, "{label}");
        assert_eq!(
            (full.p, full.dp_deta_bar),
            (part.p, part.dp_deta_bar),
            "{label}"
        );
        assert_eq!(
            (full.eta, full.deta_df, full.damage),
            (part.eta, part.deta_df, part.damage)
        );
        let mut nonzero_out_of_plane = 0;
        for r in 0..9 {
            for c in 0..9 {
                let in_plane = r % 3 < 2 && r / 3 < 2 && c % 3 < 2 && c / 3 < 2;
                if in_plane {
                    assert_eq!(full.a[(r, c)], part.a[(r, c)], "{label}: A[{r}, {c}]");
                } else {
                    assert_eq!(part.a[(r, c)], 0.0, "{label}: A[{r}, {c}] formed");
                    nonzero_out_of_plane += usize::from(full.a[(r, c)] != 0.0);
                }
            }
        }
        // The whole tangent has out-of-plane entries (S_33 and the Poisson coupling), so the request
        // did change what was formed.
        assert!(nonzero_out_of_plane > 0, "{label}");
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
    let cfg: MicroplaneConfig = toml::from_str("preset = \"paper_gamma0_1.25e-4_scaled\"").unwrap();
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

/// The trapezoidal rule in `psi_0` (`Response::dissipation_trapezoidal`, with the step's starting `F_n`)
/// along the same uniaxial stretch: within 2 % of `W - Psi` with 10 increments of the softening tail
/// where the end-point rule is 5-20 % off, and within 0.1 % with 1000; without `F_n` it is the end-point
/// sum.
#[test]
fn trapezoidal_dissipation_closes_the_uniaxial_books() {
    let m = paper();
    let run = |n: usize| {
        let mut h = fresh(&m);
        let (mut work, mut trapezoidal, mut end_point, mut stored) = (0.0, 0.0, 0.0, 0.0);
        let (mut p_last, mut e_last) = (0.0, 0.0);
        let path = (1..=100)
            .map(|k| 2e-3 * k as f64 / 100.0)
            .chain((1..=n).map(|k| 2e-3 + 6e-3 * k as f64 / n as f64));
        for e in path {
            let stretch =
                |e: f64| Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0 + e, 1.0, 1.0));
            let (f, f_n) = (stretch(e), stretch(e_last));
            let (local, _) = eval(&m, &f, 0.0, &h);
            let (mut r, mut h_new) = (Response::zeros(), vec![0.0; m.history_len()]);
            m.update(
                PointUpdate::new(&f, local.eta, &h, &mut h_new).with_start(&f_n),
                &mut r,
            )
            .expect("update");
            work += 0.5 * (p_last + r.p[(0, 0)]) * (e - e_last);
            trapezoidal += r.dissipation_trapezoidal;
            end_point += r.dissipation[0] + r.dissipation[1];
            let (plain, _) = eval(&m, &f, local.eta, &h);
            assert_eq!(
                plain.dissipation_trapezoidal,
                plain.dissipation[0] + plain.dissipation[1]
            );
            (p_last, e_last, stored, h) = (r.p[(0, 0)], e, r.energy, h_new);
        }
        (trapezoidal, end_point, work - stored)
    };
    let (coarse, coarse_end, balance_coarse) = run(10);
    let (fine, _, balance_fine) = run(1000);
    let bias = |x: f64, balance: f64| x / balance - 1.0;
    assert!(
        bias(coarse_end, balance_coarse) > 0.05,
        "{}",
        bias(coarse_end, balance_coarse)
    );
    assert!(
        bias(coarse, balance_coarse).abs() < 0.02,
        "{}",
        bias(coarse, balance_coarse)
    );
    assert!(
        bias(fine, balance_fine).abs() < 1e-3,
        "{}",
        bias(fine, balance_fine)
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
