//! Throughput of the constitutive update with the full consistent tangent.
//!
//! `cargo bench --bench material`; evaluations per second = 1 / (time per iteration).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use mpm_concrete::material::{
    Constitutive, MaterialConfig, MicroplaneConfig, PointUpdate, Preset, Quadrature, Response,
};
use nalgebra::Matrix3;

fn bench_microplane(c: &mut Criterion) {
    let f = Matrix3::new(
        1.0021, 0.0007, -0.0004, -0.0003, 0.9992, 0.0005, 0.0002, 0.0006, 1.0011,
    );
    for q in [Quadrature::Bo21, Quadrature::Bo61] {
        let m = MaterialConfig::Microplane(MicroplaneConfig {
            quadrature: Some(q),
            ..MicroplaneConfig::preset(Preset::PaperGamma0Low)
        })
        .build()
        .expect("preset is valid");
        let mut h_n = vec![0.0; m.history_len()];
        m.init_history(&mut h_n);
        let mut h_trial = h_n.clone();
        let mut out = Response::zeros();
        m.update(PointUpdate::new(&f, 0.0, &h_n, &mut h_trial), &mut out)
            .expect("update");
        let eta = out.eta;
        // elastic state (eta_bar below gamma_0) and a loading state (local eta_bar = eta, planes damaging)
        for (label, eta_bar) in [("elastic", 0.0), ("loading", eta)] {
            c.bench_function(&format!("microplane_{q:?}_{label}").to_lowercase(), |b| {
                b.iter(|| {
                    m.update(
                        PointUpdate::new(black_box(&f), black_box(eta_bar), &h_n, &mut h_trial),
                        &mut out,
                    )
                    .expect("update");
                    black_box(&out);
                })
            });
        }
    }
}

fn bench_elastic(c: &mut Criterion) {
    let f = Matrix3::new(1.02, 0.01, 0.0, -0.01, 0.99, 0.0, 0.0, 0.0, 1.0);
    let cfg = "model = \"neo_hookean\"\nyoungs_modulus = 36000.0\npoisson_ratio = 0.18\n";
    let m = toml::from_str::<MaterialConfig>(cfg)
        .expect("toml")
        .build()
        .expect("valid");
    let mut out = Response::zeros();
    c.bench_function("neo_hookean", |b| {
        b.iter(|| {
            m.update(PointUpdate::new(black_box(&f), 0.0, &[], &mut []), &mut out)
                .expect("update");
            black_box(&out);
        })
    });
}

criterion_group!(benches, bench_microplane, bench_elastic);
criterion_main!(benches);
