//! Shape-function evaluation, P2G and G2P for the CT plate of `spec/03-ct-test.md`: 200 x 200 mm minus a
//! 110 x 10 mm notch, h = 1 mm, 2 x 2 points per cell (155,600 points; the paper reports 155,530).
//!
//! Two configurations: as seeded (CPDI corners and GIMP supports on grid lines, so 4 support nodes) and after a
//! homogeneous deformation `F = [[1.002, 0.001], [0.0005, 0.998]]` about the plate centre (corners off the
//! grid lines: 9 support nodes, the typical state during a run).
//!
//! The same for a 3D plate of about as many points (`shape_3d_*`, `transfer_3d_*`).
//!
//! Run: `cargo bench --bench shape`.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, Vector2, Vector3};
use std::hint::black_box;

use mpm_concrete::geometry::{Geometry, Region, Seeding};
use mpm_concrete::grid::Grid;
use mpm_concrete::particles::Particles;
use mpm_concrete::shape::{ShapeKind, ShapeTable};
use mpm_concrete::solids::{Solid, Solids};
use mpm_concrete::transfer::{
    DEFAULT_RELATIVE_MASS_TOLERANCE, GridState, StepSolution, grid_to_particles, particles_to_grid,
};

/// The CT plate as seeded, and the grid covering it with 3 cells of margin.
fn ct_plate() -> (Grid, Particles) {
    let geometry = Geometry {
        include: vec![Region::Rect {
            min: [0.0, 0.0],
            max: [200.0, 200.0],
        }],
        exclude: vec![Region::Rect {
            min: [0.0, 95.0],
            max: [110.0, 105.0],
        }],
    };
    let seeding = Seeding {
        h: 1.0,
        points_per_cell: 2,
        density: 2.4e-9,
        body: 0,
    };
    let particles = Particles::seed(&geometry, &seeding).expect("CT geometry seeds");
    let grid = Grid::covering(Vector2::zeros(), Vector2::new(200.0, 200.0), 1.0, 3).expect("grid");
    (grid, particles)
}

/// Shape functions of every interpolator for the `seeded` and `deformed` points, then P2G and G2P with
/// the linear and CPDI1 tables, as the groups `shape_{tag}{n}` and `transfer_{tag}{n}`.
fn bench_points<const D: usize>(
    c: &mut Criterion,
    tag: &str,
    grid: &Grid<D>,
    seeded: &Particles<D>,
    deformed: &Particles<D>,
) {
    let n = seeded.len();
    let mut group = c.benchmark_group(format!("shape_{tag}{n}"));
    let mut table = ShapeTable::new();
    for kind in ShapeKind::ALL {
        for (state, particles) in [("seeded", seeded), ("deformed", deformed)] {
            group.bench_function(BenchmarkId::new(kind.name(), state), |b| {
                b.iter(|| {
                    table
                        .compute(black_box(kind), grid, black_box(particles))
                        .expect("in grid")
                })
            });
        }
    }
    group.finish();

    let mut group = c.benchmark_group(format!("transfer_{tag}{n}"));
    let mut state = GridState::new();
    for kind in [ShapeKind::Linear, ShapeKind::Cpdi1] {
        table.compute(kind, grid, deformed).expect("in grid");
        group.bench_function(BenchmarkId::new("p2g", kind.name()), |b| {
            b.iter(|| {
                particles_to_grid(
                    &table,
                    black_box(deformed),
                    grid,
                    DEFAULT_RELATIVE_MASS_TOLERANCE,
                    &mut state,
                )
                .expect("sizes match")
            })
        });
        let zero = vec![SVector::<f64, D>::zeros(); grid.num_nodes()];
        let solution = StepSolution {
            du: &zero,
            acceleration: &zero,
            gamma: 0.5,
            dt: 1e-6,
        };
        let mut particles = deformed.clone();
        group.bench_function(BenchmarkId::new("g2p", kind.name()), |b| {
            b.iter(|| {
                grid_to_particles(&table, grid, black_box(&solution), &mut particles)
                    .expect("sizes match")
            })
        });
    }
    group.finish();
}

/// `particles` deformed homogeneously by `f` about `centre`.
fn deformed<const D: usize>(
    particles: &Particles<D>,
    f: SMatrix<f64, D, D>,
    centre: SVector<f64, D>,
) -> Particles<D> {
    let mut out = particles.clone();
    for p in 0..out.len() {
        out.x[p] = centre + f * (out.x[p] - centre);
        out.set_deformation(p, f);
    }
    out
}

fn bench_shape(c: &mut Criterion) {
    let (grid, seeded) = ct_plate();
    let f = Matrix2::new(1.002, 0.001, 0.0005, 0.998);
    let moved = deformed(&seeded, f, Vector2::new(100.0, 100.0));
    bench_points(c, "", &grid, &seeded, &moved);
}

/// The 3D plate 40 x 40 x 12 mm, h = 1 mm, 2 x 2 x 2 points per cell (153,600 points, about the CT's
/// 2D count), as seeded and after a homogeneous deformation about its centre.
fn bench_shape_3d(c: &mut Criterion) {
    let plate = Solids {
        include: vec![Solid::Box {
            min: [0.0, 0.0, 0.0],
            max: [40.0, 40.0, 12.0],
        }],
        exclude: vec![],
    };
    let seeding = Seeding {
        h: 1.0,
        points_per_cell: 2,
        density: 2.4e-9,
        body: 0,
    };
    let seeded = Particles::<3>::seed(&plate, &seeding).expect("plate seeds");
    let grid =
        Grid::covering(Vector3::zeros(), Vector3::new(40.0, 40.0, 12.0), 1.0, 3).expect("grid");
    let f = Matrix3::new(
        1.002, 0.001, 0.0004, 0.0005, 0.998, -0.0003, 0.0002, 0.0006, 1.001,
    );
    let moved = deformed(&seeded, f, Vector3::new(20.0, 20.0, 6.0));
    bench_points(c, "3d_", &grid, &seeded, &moved);
}

criterion_group!(benches, bench_shape, bench_shape_3d);
criterion_main!(benches);
