//! Cost of the implicit MPM step: wall time per step split into set-up (shape functions, P2G, pattern),
//! assembly (residuals and Jacobians in Rust) and PETSc (linear solves, line search), per Newton iteration,
//! for two linear solvers and three sizes.
//!
//! ```text
//! cargo run --release --example bench_step [-- <output json, default target/bench_step.json> [steps, default 3]]
//! ```
//!
//! Problem (units mm, s, N, MPa, t): square block of concrete-like neo-Hookean material (K = 18750 MPa,
//! G = 15254 MPa, rho = 2.4e-9 t/mm^3), side 50, 100 or 197 mm, h = 1 mm, 2 x 2 points per cell (10,000,
//! 40,000 and 155,236 points), CPDI1, Newmark trapezoidal rule with dt = 1e-6 s; base on rollers, the top
//! edge pushed down with 4300 mm/s from t = 0 (a compression wave runs into the block). Solvers: MUMPS LU
//! (`-ksp_type preonly -pc_type lu -pc_factor_mat_solver_type mumps`) and GMRES with hypre BoomerAMG
//! (`-ksp_type gmres -pc_type hypre -ksp_rtol 1e-8`); Newton to `-snes_rtol 1e-8`.

use mpm_concrete::boundary::{Motion, NodeBox};
use mpm_concrete::geometry::{Geometry, Region, Seeding};
use mpm_concrete::grid::Grid;
use mpm_concrete::material::MaterialConfig;
use mpm_concrete::model::{Parameters, Setup, TimeIntegration};
use mpm_concrete::particles::Particles;
use mpm_concrete::petsc::{self, Session};
use mpm_concrete::shape::ShapeKind;
use mpm_concrete::solver::{Simulation, StepReport};
use nalgebra::Vector2;
use serde::Serialize;

/// Averages over the timed steps of one (size, solver) case.
#[derive(Debug, Serialize)]
struct Case {
    solver: &'static str,
    points: usize,
    unknowns: usize,
    nonzeros: usize,
    steps: usize,
    newton_per_step: f64,
    linear_per_newton: f64,
    setup_s_per_step: f64,
    assembly_s_per_newton: f64,
    linear_solve_s_per_newton: f64,
    total_s_per_step: f64,
    evaluations_per_step: [f64; 2],
}

const SOLVERS: [(&str, &str); 2] = [
    (
        "mumps",
        "-ksp_type preonly -pc_type lu -pc_factor_mat_solver_type mumps",
    ),
    (
        "gmres_hypre",
        "-ksp_type gmres -pc_type hypre -pc_hypre_type boomeramg -ksp_rtol 1e-8",
    ),
];

fn run(
    s: &petsc::SessionGuard,
    side: f64,
    solver: &'static str,
    steps: usize,
) -> Result<Case, Box<dyn std::error::Error>> {
    let h = 1.0;
    let rho = 2.4e-9;
    let geometry = Geometry {
        include: vec![Region::Rect {
            min: [0.0, 0.0],
            max: [side, side],
        }],
        exclude: vec![],
    };
    let particles = Particles::seed(
        &geometry,
        &Seeding {
            h,
            points_per_cell: 2,
            density: rho,
            body: 0,
        },
    )?;
    let points = particles.len();
    let grid = Grid::covering(Vector2::new(0.0, 0.0), Vector2::new(side, side), h, 2)?;
    let material: MaterialConfig =
        toml::from_str("model = \"neo_hookean\"\nbulk_modulus = 18750.0\nshear_modulus = 15254.0")?;
    let far = 1e6;
    let dt = 1e-6;
    let setup = Setup::of(
        Parameters {
            boxes: vec![
                NodeBox {
                    name: "base".into(),
                    min: Vector2::new(-far, -far),
                    max: Vector2::new(far, 0.0),
                    motion: [Motion::Free, Motion::Velocity(0.0)],
                    rise_time: 0.0,
                },
                NodeBox {
                    name: "top".into(),
                    min: Vector2::new(-far, side),
                    max: Vector2::new(far, far),
                    motion: [Motion::Free, Motion::Velocity(-4300.0)],
                    rise_time: 0.0,
                },
            ],
            options_prefix: Some(format!("{solver}_")),
            ..Parameters::new(
                grid,
                vec![material.build()?],
                ShapeKind::Cpdi1,
                TimeIntegration {
                    dt,
                    dt_min: dt,
                    ..TimeIntegration::default()
                },
            )
        },
        particles,
    );
    let mut sim = Simulation::new(setup)?;
    let reports: Vec<StepReport> = (0..steps)
        .map(|_| sim.advance(s))
        .collect::<Result<_, _>>()?;
    let n = steps as f64;
    let newton: f64 = reports.iter().map(|r| r.solve.iterations as f64).sum();
    let linear: f64 = reports
        .iter()
        .map(|r| r.solve.linear_iterations as f64)
        .sum();
    let sum = |f: &dyn Fn(&StepReport) -> f64| reports.iter().map(f).sum::<f64>();
    Ok(Case {
        solver,
        points,
        unknowns: reports[0].unknowns,
        nonzeros: reports[0].nonzeros,
        steps,
        newton_per_step: newton / n,
        linear_per_newton: linear / newton,
        setup_s_per_step: sum(&|r| r.wall_setup) / n,
        assembly_s_per_newton: sum(&|r| r.wall_assembly) / newton,
        linear_solve_s_per_newton: sum(&|r| r.wall_solve - r.wall_assembly) / newton,
        total_s_per_step: sum(&|r| r.wall_total) / n,
        evaluations_per_step: [
            sum(&|r| r.evaluations[0] as f64) / n,
            sum(&|r| r.evaluations[1] as f64) / n,
        ],
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "target/bench_step.json".into());
    let steps: usize = std::env::args()
        .nth(2)
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(3);
    let s = Session::get()?;
    for (name, opts) in SOLVERS {
        let prefixed: String = opts
            .split_whitespace()
            .map(|t| match t.strip_prefix('-') {
                Some(option) => format!("-{name}_{option}"),
                None => t.into(),
            })
            .collect::<Vec<_>>()
            .join(" ");
        petsc::apply_default_options(
            &s,
            &format!("{prefixed} -{name}_snes_rtol 1e-8 -{name}_snes_atol 1e-10"),
        )?;
    }
    let mut cases = Vec::new();
    println!(
        "solver       points  unknowns  newton/step  lin/newton  setup/step [s]  assembly/newton [s]  solve/newton [s]  total/step [s]"
    );
    for side in [50.0, 100.0, 197.0] {
        for (name, _) in SOLVERS {
            let c = run(&s, side, name, steps)?;
            println!(
                "{:<12} {:>7} {:>9} {:>12.2} {:>11.1} {:>15.4} {:>20.4} {:>17.4} {:>15.4}",
                c.solver,
                c.points,
                c.unknowns,
                c.newton_per_step,
                c.linear_per_newton,
                c.setup_s_per_step,
                c.assembly_s_per_newton,
                c.linear_solve_s_per_newton,
                c.total_s_per_step
            );
            cases.push(c);
        }
    }
    if let Some(dir) = std::path::Path::new(&out)
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
    {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(&out, serde_json::to_string_pretty(&cases)?)?;
    println!("wrote {out}");
    Ok(())
}
