//! The assembled Jacobian of an MPM step against central differences of the assembled residual, for
//! every interpolator and every material (the microplane model gradient-enhanced in a damaging state,
//! and local), on a small pre-deformed block with inertia and constrained nodes, in 2D and in 3D.

mod common;

use common::material;

use mpm_concrete::assembly::Assembler;
use mpm_concrete::boundary::{Motion, NodeBox};
use mpm_concrete::geometry::{BoxBody, Seeding};
use mpm_concrete::grid::Grid;
use mpm_concrete::material::Material;
use mpm_concrete::model::{Model, Parameters, Setup, TimeIntegration};
use mpm_concrete::particles::Particles;
use mpm_concrete::petsc::{BlockLayout, Session};
use mpm_concrete::shape::ShapeKind;
use mpm_concrete::solver::StepData;
use nalgebra::{SMatrix, SVector};

/// Deterministic pseudo-random numbers in [-1, 1].
fn noise(i: usize) -> f64 {
    let x = ((i as f64 + 1.0) * 12.9898).sin() * 43758.5453;
    2.0 * (x - x.floor()) - 1.0
}

/// Max |J - J_fd| / max |J| for one interpolator and material on the 3 x 2 mm plane block.
fn fd_error(kind: ShapeKind, mat: Material, strain: f64, eta_bar: f64, fields: usize) -> f64 {
    fd_check::<2>(kind, mat, strain, eta_bar, fields, |_| 0.0).0
}

/// Max |J - J_fd| / max |J| and the dense Jacobian (row-major, with its size), for points with the
/// committed damage `damage(p)`, on a pre-deformed block of 3 x 2 mm (2D) or 2 x 2 x 1 mm (3D) with
/// 2^D points per 1 mm cell; `fields` unknowns per node (`D`, or `D + 1` with eta_bar).
fn fd_check<const D: usize>(
    kind: ShapeKind,
    mat: Material,
    strain: f64,
    eta_bar: f64,
    fields: usize,
    damage: impl Fn(usize) -> f64,
) -> (f64, Vec<f64>, usize) {
    let h = 1.0;
    let extent = if D == 2 {
        [3.0, 2.0, 0.0]
    } else {
        [2.0, 2.0, 1.0]
    };
    let size = SVector::<f64, D>::from_fn(|d, _| extent[d]);
    let seeding = Seeding {
        h,
        points_per_cell: 2,
        density: 2.4e-9,
        body: 0,
    };
    let particles = Particles::<D>::seed(&BoxBody::from_origin(size), &seeding).expect("seed");
    let grid = Grid::covering(SVector::zeros(), size, h, 2).expect("grid");
    let dt = 1e-6;
    // Newmark with beta = 1/4, gamma = 1/2.
    let time = TimeIntegration {
        dt,
        ..TimeIntegration::default()
    };
    let far = 1e6;
    // The x component of the active nodes on the left edge of the body moves by 1e-4 mm in the step.
    let left_edge = NodeBox {
        name: "left edge".into(),
        min: SVector::from_fn(|d, _| if d == 0 { 0.0 } else { -far }),
        max: SVector::from_fn(|d, _| if d == 0 { 0.0 } else { far }),
        motion: std::array::from_fn(|d| match d {
            0 => Motion::Velocity(1e-4 / dt),
            _ => Motion::Free,
        }),
        rise_time: 0.0,
    };
    let setup = Setup::of(
        Parameters {
            body_force: SVector::from_fn(|d, _| if d == 1 { -9810.0 } else { 0.0 }),
            boxes: vec![left_edge],
            ..Parameters::new(grid, vec![mat], kind, time)
        },
        particles,
    );
    let (model, mut state) = Model::new(setup).expect("model");
    // Pre-deformed start-of-step state: F_n != I (sheared and stretched domains).
    let table3 = [
        [1.02, 0.03, 0.01],
        [-0.01, 0.985, 0.02],
        [0.015, -0.02, 1.01],
    ];
    let fn_ = SMatrix::<f64, D, D>::from_fn(|i, j| table3[i][j]);
    let particles = &mut state.particles;
    for p in 0..particles.len() {
        particles.set_deformation(p, fn_);
        particles.v[p] =
            SVector::from_fn(|d, _| [100.0, 50.0, -70.0][d] * noise(p + [0, 7, 13][d]));
        particles.a[p] = SVector::from_fn(|d, _| [1e6, -1e6, 5e5][d] * noise(p + [3, 5, 17][d]));
        particles.damage[p] = damage(p);
        particles.eta_bar[p] = 2e-3 * (1.0 + 0.2 * noise(p + 11));
    }
    let data = StepData::new(&Session::get().expect("PETSc"), &model, &state, dt).expect("step");
    let (input, dofs) = (data.input(&model), data.dofs());
    assert_eq!(dofs.unknowns_per_node(), fields, "unknowns per node");
    assert!(dofs.num_constrained() > 0);
    let mut asm = Assembler::new();
    asm.begin_step(&input);
    let n = dofs.len();
    let x0: Vec<f64> = (0..n)
        .map(|i| match (i % fields, dofs.prescribed(i)) {
            (_, Some(v)) => v,
            (c, None) if c == D => eta_bar * (1.0 + 0.3 * noise(i)),
            _ => strain * h * noise(i),
        })
        .collect();
    // Dense Jacobian from the block pattern.
    asm.evaluate(&input, &x0).expect("evaluate");
    let (rows, cols) = asm.pattern();
    let mut vals = vec![0.0; asm.nonzeros()];
    let na = dofs.active_nodes().len();
    asm.jacobian_into(&input, 0..na, &mut vals, BlockLayout::Rows);
    // A process's block rows (the middle third) are the matching slice of the whole.
    let part = na / 3..(2 * na / 3).max(na / 3 + 1);
    let (mut part_rows, mut part_cols) = (Vec::new(), Vec::new());
    asm.block_rows_pattern(part.clone(), &mut part_rows, &mut part_cols);
    let mut sub = vec![0.0; part_cols.len() * fields * fields];
    asm.jacobian_into(&input, part.clone(), &mut sub, BlockLayout::Rows);
    let lo = asm.block_pattern().row_ptr[part.start] * fields * fields;
    assert_eq!(
        sub,
        vals[lo..lo + sub.len()],
        "rows {part:?} of the Jacobian"
    );
    // A process evaluating only the points of its rows (the others left at another iterate) assembles
    // the same rows of the Jacobian and the residual.
    let mut full_r = vec![0.0; n];
    asm.residual(&input, &x0, &mut full_r, false)
        .expect("residual");
    // The residual sums each node's point terms in point order whether it is formed point by point in
    // one chunk of points per worker or node by node where chunks meet: the same bits on any number of
    // workers.
    for workers in [1, 3, 5] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(workers)
            .build()
            .expect("thread pool");
        let r = pool.install(|| {
            let mut other = Assembler::new();
            other.begin_step(&input);
            other.evaluate(&input, &x0).expect("evaluate");
            let mut r = vec![0.0; n];
            other
                .residual(&input, &x0, &mut r, false)
                .expect("residual");
            r
        });
        assert!(
            r.iter()
                .zip(&full_r)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "the residual on {workers} workers"
        );
    }
    let x1: Vec<f64> = x0.iter().map(|v| 1.7 * v + 1e-4).collect();
    asm.evaluate(&input, &x1).expect("evaluate x1");
    asm.restrict_to_rows(&input, part.clone());
    asm.evaluate_owned(&input, &x0).expect("evaluate owned");
    let mut own = vec![0.0; part_cols.len() * fields * fields];
    asm.jacobian_into(&input, part.clone(), &mut own, BlockLayout::Rows);
    assert_eq!(own, sub, "rows {part:?} from the points of these rows");
    let mut part_r = vec![0.0; n];
    asm.residual_rows(&input, &x0, &mut part_r, false, part.clone())
        .expect("residual rows");
    let scalars = part.start * fields..part.end * fields;
    assert_eq!(
        part_r[scalars.clone()],
        full_r[scalars],
        "residual rows {part:?}"
    );
    // The whole again for the finite-difference check below.
    asm.evaluate(&input, &x0).expect("evaluate x0");
    let mut jac = vec![0.0; n * n];
    for ((r, c), v) in rows.iter().zip(&cols).zip(&vals) {
        jac[r * n + c] += v;
    }
    let (mut rp, mut rm) = (vec![0.0; n], vec![0.0; n]);
    let (mut max_diff, mut max_j) = (0.0f64, 0.0f64);
    let mut worst = (0, 0, 0.0, 0.0);
    for j in 0..n {
        let step = if j % fields == D {
            1e-7 * eta_bar.max(1e-4)
        } else {
            1e-8 * h
        };
        let mut x = x0.clone();
        x[j] += step;
        asm.evaluate(&input, &x).expect("evaluate +");
        asm.residual(&input, &x, &mut rp, false)
            .expect("residual +");
        x[j] -= 2.0 * step;
        asm.evaluate(&input, &x).expect("evaluate -");
        asm.residual(&input, &x, &mut rm, false)
            .expect("residual -");
        for i in 0..n {
            let fd = (rp[i] - rm[i]) / (2.0 * step);
            if (jac[i * n + j] - fd).abs() > max_diff {
                worst = (i, j, jac[i * n + j], fd);
            }
            max_diff = max_diff.max((jac[i * n + j] - fd).abs());
            max_j = max_j.max(jac[i * n + j].abs());
        }
    }
    if max_diff > 1e-6 * max_j {
        eprintln!("worst entry (row, col, J, FD) = {worst:?} of {n} unknowns");
    }
    (max_diff / max_j, jac, n)
}

const ELASTIC: [(&str, &str); 3] = [
    (
        "linear",
        "model = \"linear_elastic\"\nyoungs_modulus = 30000.0\npoisson_ratio = 0.2",
    ),
    (
        "svk",
        "model = \"svk\"\nyoungs_modulus = 30000.0\npoisson_ratio = 0.2",
    ),
    (
        "neo-Hookean",
        "model = \"neo_hookean\"\nyoungs_modulus = 30000.0\npoisson_ratio = 0.2",
    ),
];

#[test]
fn elastic_jacobians_match_finite_differences_for_every_interpolator() {
    for kind in ShapeKind::ALL {
        for (name, text) in ELASTIC {
            let err = fd_error(kind, material(text), 0.05, 0.0, 2);
            assert!(
                err < 1e-6,
                "{name} with {}: relative Jacobian error {err:e}",
                kind.name()
            );
        }
    }
}

#[test]
fn gradient_enhanced_microplane_jacobian_matches_finite_differences_while_damaging() {
    let text = "model = \"microplane\"\npreset = \"paper_gamma0_1.25e-4\"";
    for kind in ShapeKind::ALL {
        // strains ~ 1e-3 (eight times gamma_0) and eta_bar above the threshold: damage grows.
        let err = fd_error(kind, material(text), 1e-3, 1e-3, 3);
        assert!(
            err < 1e-6,
            "microplane (u, eta_bar) with {}: relative Jacobian error {err:e}",
            kind.name()
        );
    }
}

#[test]
fn local_microplane_jacobian_matches_finite_differences_while_damaging() {
    let text = "model = \"microplane\"\npreset = \"paper_gamma0_1.25e-4\"\nc = 0.0";
    for kind in [ShapeKind::Linear, ShapeKind::Cpdi1] {
        let err = fd_error(kind, material(text), 1e-3, 0.0, 2);
        assert!(
            err < 1e-6,
            "local microplane with {}: relative Jacobian error {err:e}",
            kind.name()
        );
    }
}

#[test]
fn evolving_gradient_activity_jacobians_match_finite_differences_while_damaging() {
    // Localizing (c decreasing with the nonlocal damage, dc/d eta_bar != 0 while loading) and transient
    // (c following the local eta, dc/d eta != 0 below eta_u; the block is pre-stretched by 2 %, so
    // eta_u is well above that): the extra Helmholtz-row terms.
    for activity in [
        "{ kind = \"localizing\", residual = 0.02, decay = 5.0 }",
        "{ kind = \"localizing\", residual = 0.05, decay = 0.0 }",
        "{ kind = \"transient\", ultimate_strain = 0.08, exponent = 1.5 }",
    ] {
        let text = format!(
            "model = \"microplane\"\npreset = \"paper_gamma0_1.25e-4\"\ngradient_activity = {activity}"
        );
        for kind in [ShapeKind::Cpdi1, ShapeKind::Bspline2] {
            let err = fd_error(kind, material(&text), 1e-3, 1e-3, 3);
            assert!(
                err < 1e-6,
                "microplane with activity {activity}, {}: relative Jacobian error {err:e}",
                kind.name()
            );
        }
    }
}

const ERODING: &str =
    "model = \"microplane\"\npreset = \"paper_gamma0_1.25e-4\"\nerosion_damage = 0.95";

#[test]
fn jacobian_with_eroded_points_matches_finite_differences() {
    // Every third point eroded (a void: no stiffness, the lumped eta_bar anchor), the rest damaging.
    for kind in [ShapeKind::Cpdi1, ShapeKind::Bspline2] {
        let eroded = |p: usize| if p % 3 == 0 { 0.99 } else { 0.0 };
        let (err, _, _) = fd_check::<2>(kind, material(ERODING), 1e-3, 1e-3, 3, eroded);
        assert!(
            err < 1e-6,
            "{}: relative Jacobian error {err:e}",
            kind.name()
        );
    }
}

#[test]
fn helmholtz_rows_stay_regular_where_only_eroded_points_support_the_grid() {
    // All points eroded. The consistent anchor sum_p S_Ip S_Jp (the code before the lumped one) has
    // rank at most the number of points and is ill-conditioned wherever few points carry a patch of
    // nodes: on this block its smallest singular value was 7e-8 of the largest, and on the paper-size
    // CT it was singular. The lumped anchor is diagonal with the nodes' weight sums (ratio 4e-4 here).
    let (_, jac, n) = fd_check::<2>(ShapeKind::Cpdi1, material(ERODING), 1e-3, 1e-3, 3, |_| 0.99);
    let eta: Vec<usize> = (2..n).step_by(3).collect();
    let block = nalgebra::DMatrix::from_fn(eta.len(), eta.len(), |i, j| jac[eta[i] * n + eta[j]]);
    let sv = block.singular_values();
    let (lo, hi) = (sv.min(), sv.max());
    assert!(
        lo > 1e-6 * hi,
        "eta_bar block: singular values {lo:e} .. {hi:e}"
    );
}

#[test]
fn three_dimensional_jacobians_match_finite_differences() {
    // Elastic (neo-Hookean, 3 unknowns per node) with every interpolator; the gradient-enhanced
    // microplane model while damaging (u_x, u_y, u_z, eta_bar) with CPDI1 and the B-spline.
    for kind in ShapeKind::ALL {
        let (err, _, n) = fd_check::<3>(kind, material(ELASTIC[2].1), 0.05, 0.0, 3, |_| 0.0);
        assert!(
            err < 1e-6,
            "3D neo-Hookean with {}: relative Jacobian error {err:e} ({n} unknowns)",
            kind.name()
        );
    }
    let text = "model = \"microplane\"\npreset = \"paper_gamma0_1.25e-4\"";
    for kind in [ShapeKind::Cpdi1, ShapeKind::Bspline2] {
        let (err, _, n) = fd_check::<3>(kind, material(text), 1e-3, 1e-3, 4, |_| 0.0);
        assert!(
            err < 1e-6,
            "3D microplane (u, eta_bar) with {}: relative Jacobian error {err:e} ({n} unknowns)",
            kind.name()
        );
    }
}
