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

use mpm_concrete::assembly::{Assembler, Newmark, StepInput};
use mpm_concrete::dofs::{DofMap, FieldLayout};
use mpm_concrete::geometry::{BoxBody, Seeding};
use mpm_concrete::grid::Grid;
use mpm_concrete::material::{Constitutive, Material, MaterialConfig};
use mpm_concrete::particles::Particles;
use mpm_concrete::petsc::BlockLayout;
use mpm_concrete::shape::{ShapeKind, ShapeTable};
use mpm_concrete::transfer::{GridState, particles_to_grid};

fn material(text: &str) -> Material {
    toml::from_str::<MaterialConfig>(text)
        .expect("material config")
        .build()
        .expect("valid material")
}

/// Times evaluate, residual and Jacobian for the block `size` in `D` dimensions.
fn bench_block<const D: usize>(c: &mut Criterion, size: SVector<f64, D>) {
    let h = 1.0;
    let seeding = Seeding {
        h,
        points_per_cell: 2,
        density: 2.4e-9,
        body: 0,
    };
    let mut particles = Particles::<D>::seed(&BoxBody::from_origin(size), &seeding).expect("seed");
    let grid = Grid::covering(SVector::zeros(), size, h, 2).expect("grid");
    let f = SMatrix::<f64, D, D>::from_fn(|i, j| if i == j { 1.0 + 1e-5 } else { 2e-6 });
    for p in 0..particles.len() {
        particles.set_deformation(p, f);
    }
    let mut table = ShapeTable::new();
    table
        .compute(ShapeKind::Cpdi1, &grid, &particles)
        .expect("shape functions");
    let mut gs = GridState::new();
    particles_to_grid(&table, &particles, &grid, 1e-10, &mut gs).expect("p2g");
    let n = particles.len();
    let mut group = c.benchmark_group(format!("assembly_{D}d_{n}"));
    for (name, text, eta_bar) in [
        (
            "microplane",
            "model = \"microplane\"\npreset = \"paper_gamma0_1.25e-4\"",
            true,
        ),
        (
            "neo_hookean",
            "model = \"neo_hookean\"\nyoungs_modulus = 36000.0\npoisson_ratio = 0.18",
            false,
        ),
    ] {
        let mat = material(text);
        particles.resize_history(mat.history_len(), 0.0);
        for p in 0..n {
            mat.init_history(&mut particles.history_mut(p)[..mat.history_len()]);
        }
        let mut dofs = DofMap::default();
        dofs.rebuild(&gs.active, FieldLayout::new(D, eta_bar));
        let materials = [mat];
        let input = StepInput {
            table: &table,
            particles: &particles,
            materials: &materials,
            dofs: &dofs,
            mass: &gs.mass,
            velocity: &gs.velocity,
            acceleration: &gs.acceleration,
            newmark: Some(Newmark {
                beta: 0.25,
                gamma: 0.5,
                dt: 1e-6,
            }),
            body_force: SVector::zeros(),
            nodal_force: &[],
            row_scale: 3e4,
            partners: &[],
        };
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
