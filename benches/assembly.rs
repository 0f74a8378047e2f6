//! Cost per material point of the step's assembly in 2D and in 3D: the constitutive updates at an
//! iterate (`evaluate`), the residual and the Jacobian's values, for blocks of 20,000 points (2D: 100 x 50
//! mm, 2 x 2 points per 1 mm cell, 3 unknowns per node; 3D: 25 x 20 x 5 mm, 2 x 2 x 2 points per cell, 4
//! unknowns per node), CPDI1, the gradient-enhanced microplane model (21 microplanes) in its elastic
//! range, and neo-Hookean (the assembly's own cost).
//!
//! Run: `cargo bench --bench assembly`.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use nalgebra::{SMatrix, SVector};
use std::hint::black_box;

use mpm_concrete::assembly::Assembler;
use mpm_concrete::geometry::{BoxBody, Seeding};
use mpm_concrete::grid::Grid;
use mpm_concrete::model::{Model, Setup, TimeIntegration};
use mpm_concrete::particles::Particles;
use mpm_concrete::petsc::{BlockLayout, Session};
use mpm_concrete::shape::ShapeKind;
use mpm_concrete::solver::StepData;

#[path = "../tests/common/mod.rs"]
mod common;
use common::material;

/// Times evaluate, residual and Jacobian for the block `size` in `D` dimensions.
fn bench_block<const D: usize>(c: &mut Criterion, size: SVector<f64, D>) {
    let h = 1.0;
    let seeding = Seeding {
        h,
        points_per_cell: 2,
        density: 2.4e-9,
        body: 0,
    };
    let particles = Particles::<D>::seed(&BoxBody::from_origin(size), &seeding).expect("seed");
    let grid = Grid::covering(SVector::zeros(), size, h, 2).expect("grid");
    let f = SMatrix::<f64, D, D>::from_fn(|i, j| if i == j { 1.0 + 1e-5 } else { 2e-6 });
    let n = particles.len();
    let mut group = c.benchmark_group(format!("assembly_{D}d_{n}"));
    for (name, text) in [
        (
            "microplane",
            "model = \"microplane\"\npreset = \"paper_gamma0_1.25e-4\"",
        ),
        (
            "neo_hookean",
            "model = \"neo_hookean\"\nyoungs_modulus = 36000.0\npoisson_ratio = 0.18",
        ),
    ] {
        // Newmark steps of 1 us.
        let time = TimeIntegration::default();
        let setup = Setup::new(
            grid.clone(),
            particles.clone(),
            vec![material(text)],
            ShapeKind::Cpdi1,
            time,
        );
        let (model, mut state) = Model::new(setup).expect("model");
        for p in 0..n {
            state.particles.set_deformation(p, f);
        }
        let session = Session::get().expect("PETSc");
        let data = StepData::new(&session, &model, &state, time.dt).expect("step");
        drop(session);
        let (input, dofs) = (data.input(&model), data.dofs());
        let mut asm = Assembler::new();
        asm.begin_step(&input);
        let x: Vec<f64> = (0..dofs.len())
            .map(|i| 1e-6 * ((i as f64 * 0.37).sin()))
            .collect();
        let mut iterate = 0;
        group.bench_function(BenchmarkId::new("evaluate", name), |b| {
            b.iter(|| {
                // A new iterate every time: the cache must not answer.
                iterate += 1;
                let mut xi = x.clone();
                xi[0] += iterate as f64 * 1e-12;
                asm.evaluate(&input, black_box(&xi)).expect("evaluate");
            })
        });
        asm.evaluate(&input, &x).expect("evaluate");
        let mut r = vec![0.0; dofs.len()];
        group.bench_function(BenchmarkId::new("residual", name), |b| {
            b.iter(|| {
                asm.residual(&input, &x, black_box(&mut r), false)
                    .expect("residual")
            })
        });
        let mut values = vec![0.0; asm.nonzeros()];
        let rows = 0..dofs.num_active();
        group.bench_function(BenchmarkId::new("jacobian", name), |b| {
            b.iter(|| {
                asm.jacobian_into(
                    &input,
                    rows.clone(),
                    black_box(&mut values),
                    BlockLayout::Rows,
                )
            })
        });
    }
    group.finish();
}

fn bench_assembly(c: &mut Criterion) {
    bench_block::<2>(c, SVector::from([100.0, 50.0]));
    bench_block::<3>(c, SVector::from([25.0, 20.0, 5.0]));
}

criterion_group!(benches, bench_assembly);
criterion_main!(benches);
