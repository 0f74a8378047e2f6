//! The default PETSc solver of a run, chosen from the kind of step the model makes (docs/solvers.md).
//!
//! What makes a linear solver fast here is the balance in the Jacobian between the inertia term
//! `M / (beta dt^2)` and the stiffness. Their ratio on the diagonal, for a cell of size `h`,
//!
//! ```text
//! r = rho h^2 / (beta dt^2 M),   M = K + 4 G / 3 (P-wave modulus, MPa)
//! ```
//!
//! is `(h / (c dt))^2 / beta` with `c` the P-wave speed: the inverse square of the step's Courant number.
//! With `r` of order 0.1-1 (the CT test at 1 us steps: r = 0.25) the Jacobian is dominated by its diagonal
//! blocks and GMRES with ILU(0) converges in a handful of iterations; with `r` far below that (long steps,
//! soft or stiff-and-light bodies, quasi-static steps) ILU(0) needs hundreds of iterations and the solve
//! needs a multigrid or a direct method. Every choice below can be overridden by `run.petsc_options` and,
//! with the final word, by the command line.

use crate::material::Material;
use crate::model::Setup;
use crate::petsc::{self, SessionGuard};
use crate::space::Frame;

/// Below this ratio `r` a dynamic step counts as stiffness-dominated.
pub const STIFFNESS_DOMINATED_BELOW: f64 = 0.01;

/// The kind of implicit step, for the choice of the linear solver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StepClass {
    /// Dynamic, inertia significant (`r >= 0.01`): GMRES with ILU(0).
    InertiaDominated {
        /// The ratio `r`.
        ratio: f64,
    },
    /// Dynamic, `r < 0.01`: GMRES with the geometric multigrid of the background grid (displacements
    /// only) or a field split of (u, eta_bar) with algebraic multigrid on u (gradient-enhanced models).
    StiffnessDominated {
        /// The ratio `r`.
        ratio: f64,
    },
    /// No inertia: Newton with an LU factorisation.
    QuasiStatic,
}

/// Newton settings shared by every class: the absolute residual tolerance, at most 25 iterations.
const NEWTON: &str = "-snes_atol 1e-8 -snes_max_it 25";

/// Newton's relative tolerance where the linear solves are GMRES + ILU(0) to `ksp_rtol 1e-6`: the same
/// 1e-6. A Newton iteration cannot bring the residual much below what its own linear solve reaches, and
/// the former 1e-8 bought a last iteration in most steps that only polished the answer: on the first 150
/// steps of the half-resolution CT at 4.3 m/s 463 instead of 536 Newton iterations (2656 instead of 3019
/// Krylov), the histories within a relative L2 distance of 4e-8 of those at 1e-8 (damage dissipation;
/// reactions 8e-10). At 1e-5 the contact active sets settle differently (support reaction 3e-2 apart);
/// `docs/benchmarks.md`, "Newton to the linear solves' tolerance".
///
/// And no convergence on a small Newton step (`stol 0`): PETSc's default `stol = 1e-8` ends a solve whose
/// step fell below 1e-8 of the solution as converged whatever its residual, and in the paper-size CT at
/// 4.3 m/s (a229891, step 647) a stalled solve that crawled through 16 iterations of one Krylov iteration
/// each was so taken for converged with its residual not reduced. A stall is the convergence test's to
/// catch (`petsc::snes`: the step then goes to the fallback); in the whole paper-size run of 6a033f5 no
/// step converged on its step size, so no converged step changes there.
///
/// And the first Newton iteration's linear solve only to 1e-3 (`-mpm_first_ksp_rtol`,
/// `Snes::set_first_linear_rtol`; the later ones to `ksp_rtol`): that iteration carries the devices'
/// motion into the interior and leaves the residual at a few thousandths of where it started whatever its
/// linear solve reaches (the paper-size CT at 4.3 m/s after 300 steps: 3460 -> 10 -> 0.04 -> 3e-7), so
/// its last Krylov iterations bought nothing. Cracked paper-size steps 301-320: the same 73 Newton and 472
/// instead of 589 Krylov iterations, 0.927x the time; the half-resolution CT's first 150 steps 465 / 2250
/// against 463 / 2656, 0.958x, histories within relative L2 1.5e-7 (`docs/benchmarks.md`, "The first
/// Newton iteration's linear solve to 1e-3"). Eisenstat-Walker's forcing with the same first term and
/// quadratic decrease (`-snes_ksp_ew_version 2 -snes_ksp_ew_rtol0 1e-3 -snes_ksp_ew_alpha 2`) saved more
/// Krylov iterations (385) but its looser later solves moved the support reaction by 3e-2 (with
/// `-snes_ksp_ew -snes_ksp_ew_gamma 0.9 -snes_ksp_ew_rtolmax 1e-3` besides). On a tiny specimen (the tests'
/// 360-point CT) the first solve to 1e-3 can cost a step a third Newton iteration.
///
/// The last Jacobian kept near the solution (`-mpm_keep_jacobian_below 1e-4`) saves its fill in the
/// third iteration of the cracked steps (0.93x their time) but not over a whole run: the paper-size CT
/// took 637-646 s against 627 s, two or three more steps sent to the fallback by stalled ILU solves
/// (`docs/benchmarks.md`, "The Jacobian kept near the solution"). Not a default.
const NEWTON_RTOL_INERTIA: &str = "-snes_rtol 1e-6 -snes_stol 0 -mpm_first_ksp_rtol 1e-3";

/// Newton's relative tolerance of the other classes: 1e-8. With exact LU solves a looser Newton saves
/// little; on the field split of the stiffness-dominated CT at 0.035 m/s, 1e-6 took 0.88x the Newton
/// iterations and 0.84x the time but moved the kinetic energy's history by 3.2e-6, above issue 45's
/// bound of 1e-6 (`docs/benchmarks.md`, "Newton to the linear solves' tolerance").
const NEWTON_RTOL: &str = "-snes_rtol 1e-8";

/// On one process: GMRES preconditioned by ILU(0) (pivots shifted away from zero), factored at the first Newton
/// iteration of a step and every third one. With the Jacobian stored by node blocks
/// (`petsc::matrix_type_for`) a factorisation of the widened CPDI pattern costs about five GMRES iterations,
/// and reusing it within the step pays: the half-resolution CT at 4.3 m/s to 1 ms took 356 s instead of
/// 399 s (0.89x) for 1.29x the Krylov iterations, 40 cracked steps 0.92x (`docs/benchmarks.md`, "Reusing the
/// factorisation within a step"). With the former point-wise storage and the stale-factorisation bug of
/// the block storage, the same lag had measured as a loss. With several threads the solver replaces this
/// ILU(0) by its own on one overlapping part of the grid per thread (`ilu::SchwarzIlu`; `solver::system`,
/// `-mpm_threaded_ilu 0` keeps PETSc's); on one thread its own takes the place of PETSc's inside the block.
const INERTIA: &str = "-snes_lag_preconditioner 3 -ksp_type gmres -ksp_rtol 1e-6 -ksp_max_it 1000 \
     -pc_type bjacobi -sub_pc_type ilu -sub_pc_factor_shift_type nonzero";

/// On several processes in 2D: `INERTIA`'s GMRES and lag, with ILU(0) on overlapping subdomains (additive
/// Schwarz, one layer of overlap) instead of one ILU per process. Block Jacobi drops the coupling between
/// the processes' bands, and it shows in both counts: on the first 40 steps of the half-resolution CT at
/// 4.3 m/s one process takes 95 Newton / 502 Krylov iterations, block Jacobi on 2 and 4 processes 116 / 788
/// and 117 / 952 (GMRES stopped on a preconditioned residual the bands make poor, so Newton needs more
/// steps), the overlap 95 / 503 and 93 / 500; on 20 cracked steps at 1 mm (2 processes) 41 / 487 against
/// 40 / 331 (one process: 40 / 317). On one process the overlap buys nothing and its sub-matrix copy costs
/// (PCSetUp 2.1 against 1.3 s in 60 steps), so `INERTIA` stays (`docs/benchmarks.md`, "Processes: the
/// iterations of one process on several"). Each process's subdomain is factored and solved by the
/// solver's own ILU(0) in place of PETSc's (`Snes::use_threaded_ilu_on_subdomains`).
const INERTIA_PROCESSES: &str = "-snes_lag_preconditioner 3 -ksp_type gmres -ksp_rtol 1e-6 \
     -ksp_max_it 1000 -pc_type asm -pc_asm_overlap 1 -sub_pc_type ilu -sub_pc_factor_shift_type nonzero";

/// In 3D (a plate): GMRES preconditioned by ILU(0) on overlapping subdomains (additive Schwarz, one layer
/// of overlap; on one process this is `INERTIA`'s ILU of the whole matrix), factored at the first Newton
/// iteration of a step and every second one. A 3D block row has about 500 nonzeros against about 80 in 2D,
/// so a factorisation costs many GMRES iterations, and reusing it within the step pays where in 2D it did
/// not: on the first 50 steps of the 3D demo (`configs/ct-3d-demo.toml`, 2 processes) the PETSc time fell
/// from 62.3 to 36.8 s with the same Krylov iterations (598 against 601). Overlap, because the processes'
/// bands are cut across y and so through the notch plane: block Jacobi's ILU drops the coupling across
/// the ligament (1914 Krylov iterations against 601 in those steps, and two steps passed to the fallback).
const INERTIA_3D: &str = "-snes_lag_preconditioner 2 -ksp_type gmres -ksp_rtol 1e-6 -ksp_max_it 1000 \
     -pc_type asm -pc_asm_overlap 1 -sub_pc_type ilu -sub_pc_factor_shift_type nonzero";

/// GMRES with the geometric multigrid on the background grid (`src/multigrid.rs`: levels by coarsening
/// the grid by 2 until a level has at most 2000 unknowns, Galerkin coarse operators, one symmetric SOR
/// sweep before and after the coarse correction, LU on the coarsest level), the hierarchy's operators
/// formed anew at the first Newton iteration of a step and every third one, and each linear solve stopped
/// when its true residual has fallen by 1e-3 (GMRES preconditioned from the right, so that it measures the
/// residual itself: the preconditioned one of left preconditioning asked about 40 % more iterations for
/// the same Newton steps). Newton then converges linearly at about that rate, which costs fewer V-cycles
/// than solving each Newton step to 1e-6 or than Eisenstat-Walker's adaptive forcing (the former default:
/// 4.2 Newton iterations per step on the elastic cantilever, the early ones stopped after 1-3 V-cycles at
/// a residual barely reduced). Whole runs of the cantilever, 10 steps, interleaved: 1e-3 from the left
/// 0.878x the time of Eisenstat-Walker at 40,960 points and 0.873x at 163,840; from the right a further
/// 0.891x and 0.830x (31 Newton and 139 Krylov iterations per ten steps at 163,840 points, against 44 and
/// 216; `docs/benchmarks.md`, "Linear solves to 1e-3 under the multigrid").
/// The multigrid keeps about 6 Krylov iterations per Newton iteration from 10,240 to 163,840 points where
/// BoomerAMG (strength threshold 0.5, aggressive coarsening: the former default, one option set away,
/// `docs/solvers.md`) needs 14-16.
const STIFFNESS_MG: &str = "-snes_lag_preconditioner 3 -ksp_type gmres -ksp_pc_side right -ksp_rtol 1e-3 \
     -ksp_max_it 500 -pc_type mg -mg_levels_ksp_type richardson -mg_levels_ksp_max_it 1 \
     -mg_levels_pc_type sor";

/// GMRES preconditioned block by block (a multiplicative field split of the interleaved unknowns): the
/// displacements by hypre's BoomerAMG (HMIS coarsening, extended+i interpolation, at most 4 weights per
/// row, the usual settings for 2D elasticity), eta_bar by ILU(0) per process (the Helmholtz block is
/// mass-dominated); the split set up afresh at the first Newton iteration of a step and every third one
/// (against every second: the half-size CT at 0.035 m/s, 2 mm cells, 1000 steps to 10 ms in 0.92x the
/// time, 0.89-0.95 over 2 pairs of whole runs, the same Newton and 0.4 % more Krylov iterations, histories
/// within 1.4e-9 and the same crack; `docs/benchmarks.md`, "Where the CT's step goes"). On the paper-size CT at 0.035 m/s (localizing activity, contact plates) it took 10.4 s of solver time
/// where the lagged MUMPS LU took 16.0 (first 4 steps) and 24.2 s where the LU took 41.3 (4 steps with a
/// 55 mm crack, same Newton iterations), in half the memory (0.78 against 1.5 GB); the coupled tangent of a
/// softening point can be indefinite, and a step whose GMRES fails goes to the fallback solver, a fresh
/// MUMPS LU at every Newton iteration (`docs/solvers.md`). The splits are the index sets `u` and `eta_bar`
/// that the solver attaches to the preconditioner, so `-fieldsplit_u_*` and `-fieldsplit_eta_bar_*` options
/// change them. GMRES is preconditioned from the right, so that its 1e-6 applies to the true residual
/// rather than to the split's preconditioned one: the half-size CT at 0.035 m/s to 10 ms took 411 instead
/// of 513 s in its steps (0.80x; 30,451 against 35,945 Krylov and 3204 against 3324 Newton iterations,
/// the same crack, histories within 3e-8; first 50 steps interleaved 0.891x; `docs/benchmarks.md`, "The
/// field split preconditioned from the right").
const STIFFNESS_FIELD_SPLIT: &str = "-snes_lag_preconditioner 3 -ksp_type gmres -ksp_pc_side right -ksp_rtol 1e-6 \
     -ksp_max_it 500 -pc_type fieldsplit -pc_fieldsplit_type multiplicative \
     -fieldsplit_u_ksp_type preonly -fieldsplit_u_pc_type hypre -fieldsplit_u_pc_hypre_type boomeramg \
     -fieldsplit_u_pc_hypre_boomeramg_strong_threshold 0.5 -fieldsplit_u_pc_hypre_boomeramg_agg_nl 1 \
     -fieldsplit_u_pc_hypre_boomeramg_coarsen_type HMIS -fieldsplit_u_pc_hypre_boomeramg_interp_type ext+i \
     -fieldsplit_u_pc_hypre_boomeramg_P_max 4 \
     -fieldsplit_eta_bar_ksp_type preonly -fieldsplit_eta_bar_pc_type bjacobi \
     -fieldsplit_eta_bar_sub_pc_type ilu";

/// On a set-up turned inside the grid (`grid.rotation`): the Jacobian stored point-wise, so that ILU(0)
/// factors scalar pivots (`petsc::matrix_type_for` would choose node blocks), and GMRES
/// preconditioned from the right, so that it stops on the true residual. The oblique faces leave nodes
/// with a sliver of support, whose small pivots make ILU(0) poor there: with the block storage the
/// factorisation fails (the half-size CT at 1 mm cells turned by 30 deg sent 28 of its first 97 steps to
/// the fallback and stopped at 90 us; at 2 mm 14 of the first 40 steps), and with point pivots but left
/// preconditioning the preconditioned residual hides what the true one keeps, and Newton's line search
/// fails (2 mm: 8 of the first 40 steps, 9 of 250). With both: no step retried at 2 mm in 250 steps or at
/// 1 mm in 120, and at 1 mm 3712 instead of 5079 Krylov iterations (`docs/results.md`, "Refinement to
/// 0.5 mm on the half-size CT").
const TURNED: &str = "-mat_type aij -ksp_pc_side right";

/// Newton with MUMPS LU, a new factorisation every iteration.
const QUASI_STATIC: &str = "-ksp_type preonly -pc_type lu -pc_factor_mat_solver_type mumps";

/// Options prefix of the fallback solver.
pub const FALLBACK_PREFIX: &str = "fallback_";

/// Options of the fallback solver (prefix [`FALLBACK_PREFIX`]) tried at the same time step when the main
/// one's linear solver fails (a factorisation, GMRES, the line search), before the step is halved: Newton with a fresh MUMPS LU every iteration (pivoting copes with the
/// indefinite tangents of strongly softening material), with MUMPS's null-pivot detection (`ICNTL(24) = 1`):
/// late in the paper-size CT at 4.3 m/s with contact plates the Jacobian became numerically singular
/// (MUMPS `INFOG(1) = -10`) and the step failed down to dt = 1.6e-8 s; with the detection the same step
/// converged in 3 Newton iterations at 0.25 us and the run went on (`docs/results.md`). Newton still
/// judges convergence on the true residual.
///
/// The factors are kept out of core (`ICNTL(22) = 1`, in the run's output directory:
/// [`out_of_core_directory`]). In core they set a run's peak memory: at the end of the paper-size CT at
/// 4.3 m/s (120,534 unknowns, 73 nonzeros per row) MUMPS allocates 907 MB for 82 M factor entries against
/// 151 MB out of core, and three steps that went to the fallback peaked at 2166 MB against 972 MB (the main
/// solver's steps alone: 687 MB), for about 1.5 s more per fallback step (`docs/benchmarks.md`, "The
/// fallback's factors out of core"). The fallback solves a few steps per run, so the time does not count
/// and the memory does.
pub const FALLBACK: &str = "-fallback_snes_rtol 1e-8 -fallback_snes_atol 1e-8 -fallback_snes_max_it 25 \
     -fallback_ksp_type preonly -fallback_pc_type lu -fallback_pc_factor_mat_solver_type mumps \
     -fallback_mat_mumps_icntl_24 1 -fallback_mat_mumps_icntl_22 1";

/// The option naming the directory of the fallback's out-of-core factors (without its dash).
const OUT_OF_CORE_DIRECTORY: &str = "fallback_mat_mumps_ooc_tmpdir";

/// MUMPS keeps at most this many bytes of a directory name (`OOC_TMPDIR`).
const OUT_OF_CORE_DIRECTORY_LEN: usize = 255;

/// Puts the fallback's out-of-core factors ([`FALLBACK`]) in `dir` (the run's output directory once it
/// exists, a disk the user chose for the results; MUMPS's own default is `/tmp`, which is memory on systems
/// that mount it as tmpfs) unless the option is set already or the name is too long for MUMPS, in which
/// case its default stays. MUMPS removes its files when the solver is destroyed; those of a killed run are removed with the
/// run's other temporaries (`rundir::is_temporary`). Returns the option's name if it set it.
pub fn out_of_core_directory(
    session: &SessionGuard,
    dir: &std::path::Path,
) -> Result<Option<String>, petsc::PetscError> {
    let name = dir.to_string_lossy();
    if name.len() > OUT_OF_CORE_DIRECTORY_LEN || petsc::has_option(session, OUT_OF_CORE_DIRECTORY)?
    {
        return Ok(None);
    }
    petsc::set_option(session, OUT_OF_CORE_DIRECTORY, Some(&name))?;
    Ok(Some(format!("-{OUT_OF_CORE_DIRECTORY}")))
}

/// The ratio `r = rho h^2 / (beta dt^2 M)` of the model, or `None` for a quasi-static model: the smallest
/// over the bodies of their own `rho / M` (density, P-wave modulus `M = K + 4G/3`), so that a stiff and
/// heavy second body (a steel insert) does not mix its modulus with the concrete's density.
pub fn inertia_ratio<const D: usize>(setup: &Setup<D>) -> Option<f64> {
    if setup.params.time.quasi_static {
        return None;
    }
    let p = &setup.particles;
    let mut rho = vec![f64::INFINITY; setup.params.materials.len()];
    for i in (0..p.len()).filter(|&i| p.vol0[i] > 0.0) {
        let b = p.body[i] as usize;
        rho[b] = rho[b].min(p.mass[i] / p.vol0[i]);
    }
    let rho_over_modulus = setup
        .params
        .materials
        .iter()
        .zip(&rho)
        .filter(|(_, r)| r.is_finite())
        .map(|(m, r)| r / p_wave_modulus(m))
        .fold(f64::INFINITY, f64::min);
    let time = &setup.params.time;
    Some(ratio(
        rho_over_modulus,
        setup.params.grid.cell_size(),
        time.beta,
        time.dt,
    ))
}

/// The P-wave modulus `M = K + 4G/3` of a material (MPa).
pub fn p_wave_modulus(material: &Material) -> f64 {
    let e = material.elastic_moduli();
    e.bulk + 4.0 * e.shear / 3.0
}

/// `r = (rho / M) h^2 / (beta dt^2)` from the density over the P-wave modulus (t/mm^3 per MPa, s^2/mm^2),
/// the cell size `h` (mm), Newmark's `beta` and the step `dt` (s).
pub fn ratio(rho_over_modulus: f64, h: f64, beta: f64, dt: f64) -> f64 {
    rho_over_modulus * h * h / (beta * dt * dt)
}

impl StepClass {
    /// The class of steps with the inertia ratio `ratio` (`None`: quasi-static).
    pub fn of(ratio: Option<f64>) -> Self {
        match ratio {
            None => Self::QuasiStatic,
            Some(ratio) if ratio >= STIFFNESS_DOMINATED_BELOW => Self::InertiaDominated { ratio },
            Some(ratio) => Self::StiffnessDominated { ratio },
        }
    }
}

/// The class of the model's steps.
pub fn classify<const D: usize>(setup: &Setup<D>) -> StepClass {
    StepClass::of(inertia_ratio(setup))
}

/// The default options of the main solver for a class of steps in `D` dimensions (2 or 3: a plate) on
/// `processes` processes; `gradient` tells whether the model solves for eta_bar too, `frame` how the
/// set-up sits in the grid.
pub fn main_options<const D: usize>(
    class: StepClass,
    gradient: bool,
    frame: Frame,
    processes: usize,
) -> String {
    let solver = match class {
        StepClass::InertiaDominated { .. } if D == 3 => INERTIA_3D,
        StepClass::InertiaDominated { .. } if processes > 1 => INERTIA_PROCESSES,
        StepClass::InertiaDominated { .. } => INERTIA,
        StepClass::StiffnessDominated { .. } if gradient => STIFFNESS_FIELD_SPLIT,
        StepClass::StiffnessDominated { .. } => STIFFNESS_MG,
        StepClass::QuasiStatic => QUASI_STATIC,
    };
    let rtol = match class {
        StepClass::InertiaDominated { .. } => NEWTON_RTOL_INERTIA,
        _ => NEWTON_RTOL,
    };
    match frame.degrees() {
        Some(_) => format!("{NEWTON} {rtol} {solver} {TURNED}"),
        None => format!("{NEWTON} {rtol} {solver}"),
    }
}

/// Applies the defaults of the model's class and the fallback solver to the options database (options
/// already set, from the config or the command line, win), makes the model retry failed steps with the
/// fallback solver (prefix [`FALLBACK_PREFIX`]) and returns the names of the options it set,
/// e.g. `-ksp_type`, so that those a user's choice made irrelevant are not reported as unused. A lagged
/// preconditioner only makes sense inside a Krylov method: under `-ksp_type preonly` (a user's direct
/// solve) the default lag is withdrawn, so that Newton keeps a fresh factorisation every iteration.
/// The dimension `D` of the set-up (3: a plate) chooses among the defaults.
pub fn apply<const D: usize>(
    session: &SessionGuard,
    setup: &mut Setup<D>,
) -> Result<(StepClass, Vec<String>), petsc::PetscError> {
    setup.params.fallback_prefix = Some(FALLBACK_PREFIX.into());
    let class = classify(setup);
    let gradient = setup.params.materials.iter().any(|m| m.is_nonlocal());
    let processes = session.size();
    let options = main_options::<D>(class, gradient, setup.params.frame, processes);
    if let Some(degrees) = setup.params.frame.degrees() {
        tracing::info!(
            "the set-up is turned by {degrees} deg inside the grid: point-wise ILU(0), GMRES \
             preconditioned from the right ({TURNED})"
        );
    }
    let mut applied: Vec<String> = petsc::apply_default_options(session, &options)?
        .into_iter()
        .chain(petsc::apply_default_options(session, FALLBACK)?)
        .map(|(name, _)| format!("-{name}"))
        .collect();
    let lag = "-snes_lag_preconditioner".to_owned();
    if applied.contains(&lag)
        && petsc::option_string(session, "ksp_type")?.as_deref() == Some("preonly")
    {
        petsc::set_option(session, "snes_lag_preconditioner", Some("1"))?;
        applied.retain(|o| *o != lag);
    }
    // The defaults precondition GMRES from the right; another Krylov method given instead (CG and MINRES
    // take the left side only, FGMRES the right) keeps PETSc's side for it.
    let side = "-ksp_pc_side".to_owned();
    if applied.contains(&side)
        && petsc::option_string(session, "ksp_type")?.as_deref() != Some("gmres")
    {
        petsc::clear_option(session, "ksp_pc_side")?;
        applied.retain(|o| *o != side);
    }
    // A different preconditioner set in the config or on the command line replaces the class's.
    let own_pc = options
        .split_whitespace()
        .skip_while(|o| *o != "-pc_type")
        .nth(1)
        .map(str::to_owned);
    match petsc::option_string(session, "pc_type")? {
        Some(pc) if !applied.iter().any(|o| o == "-pc_type") && Some(&pc) != own_pc.as_ref() => {
            tracing::info!(
                "solver for {}: replaced by the given -pc_type {pc}",
                describe::<D>(class, gradient, processes)
            )
        }
        _ => tracing::info!(
            "default solver for {}",
            describe::<D>(class, gradient, processes)
        ),
    }
    Ok((class, applied))
}

/// A one-line description for the run's log of the default solver of `class` in `D` dimensions on
/// `processes` processes.
pub fn describe<const D: usize>(class: StepClass, gradient: bool, processes: usize) -> String {
    let solver = match class {
        StepClass::InertiaDominated { .. } if D == 3 => {
            "GMRES + ILU(0) on overlapping subdomains, factored every second Newton iteration"
        }
        StepClass::InertiaDominated { .. } if processes > 1 => {
            "GMRES + ILU(0) on overlapping subdomains"
        }
        StepClass::InertiaDominated { .. } => "GMRES + ILU(0)",
        StepClass::StiffnessDominated { .. } if gradient => {
            "GMRES + field split (BoomerAMG on the displacements, ILU(0) on eta_bar)"
        }
        StepClass::StiffnessDominated { .. } => {
            "GMRES (to a relative 1e-3) + geometric multigrid on the background grid"
        }
        StepClass::QuasiStatic => "MUMPS LU",
    };
    match class {
        StepClass::InertiaDominated { ratio } => {
            format!("inertia-dominated steps (r = {ratio:.3}): {solver}")
        }
        StepClass::StiffnessDominated { ratio } => {
            format!("stiffness-dominated steps (r = {ratio:.2e}): {solver}")
        }
        StepClass::QuasiStatic => format!("quasi-static steps: {solver}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::RunConfig;
    use std::path::Path;

    fn class_of(config: &str) -> StepClass {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(config);
        let cfg = RunConfig::from_file(&path).expect("config");
        classify(&crate::scenario::build(&cfg).expect("model"))
    }

    #[test]
    fn the_ct_test_is_inertia_dominated_and_the_cantilever_stiffness_dominated() {
        // CT: rho h^2 / (beta dt^2 (K + 4G/3)) = 2.4e-9 / (0.25e-12 * 39088.7) = 0.2456 (4 mm demo cells: 16x).
        match class_of("configs/ct-demo.toml") {
            StepClass::InertiaDominated { ratio } => {
                assert!((ratio - 16.0 * 0.24559).abs() < 1e-3, "{ratio}")
            }
            c => panic!("{c:?}"),
        }
        // Cantilever: 1e-9 * 3.125^2 / (0.25 * 4e-6 * 134.615) = 7.25e-5.
        match class_of("configs/bench/cantilever-41k.toml") {
            StepClass::StiffnessDominated { ratio } => {
                assert!((ratio - 7.2545e-5).abs() < 1e-8, "{ratio}")
            }
            c => panic!("{c:?}"),
        }
        assert_eq!(
            class_of("configs/crosscheck-cantilever.toml"),
            StepClass::QuasiStatic
        );
        let lu = main_options::<2>(StepClass::QuasiStatic, true, Frame::IDENTITY, 1);
        assert!(
            lu.contains("mumps") && lu.contains("-snes_rtol 1e-8"),
            "{lu}"
        );
        // A plate: overlapping subdomains and a factorisation kept for two Newton iterations.
        let inertia = StepClass::InertiaDominated { ratio: 1.0 };
        let ilu = main_options::<2>(inertia, true, Frame::IDENTITY, 1);
        // Newton to the tolerance of its GMRES solves, and never converged on a small step alone.
        assert!(
            ilu.contains("-pc_type bjacobi")
                && ilu.contains("-snes_rtol 1e-6")
                && ilu.contains("-snes_stol 0")
                && ilu.contains("-ksp_rtol 1e-6"),
            "{ilu}"
        );
        // On several processes: overlapping subdomains, so that the iterations do not grow with them.
        let bands = main_options::<2>(inertia, true, Frame::IDENTITY, 2);
        assert!(
            bands.contains("-pc_type asm -pc_asm_overlap 1")
                && bands.contains("-snes_lag_preconditioner 3"),
            "{bands}"
        );
        // A set-up turned inside the grid: point-wise storage (block ILU(0) breaks down there), and only there.
        assert!(!main_options::<2>(inertia, true, Frame::IDENTITY, 1).contains("-mat_type"));
        let turned = main_options::<2>(inertia, true, Frame::from_degrees(30.0), 1);
        assert!(
            turned.ends_with("-mat_type aij -ksp_pc_side right"),
            "{turned}"
        );
        let plate = main_options::<3>(inertia, true, Frame::IDENTITY, 2);
        assert!(
            plate.contains("-pc_type asm -pc_asm_overlap 1")
                && plate.contains("-snes_lag_preconditioner 2"),
            "{plate}"
        );
        let mg = main_options::<2>(
            StepClass::StiffnessDominated { ratio: 1e-4 },
            false,
            Frame::IDENTITY,
            1,
        );
        assert!(
            mg.contains("-pc_type mg") && mg.contains("-ksp_rtol 1e-3"),
            "{mg}"
        );
        // The coupled system: the solver's named splits, displacements by AMG, eta_bar by ILU.
        let split = main_options::<2>(
            StepClass::StiffnessDominated { ratio: 1e-4 },
            true,
            Frame::IDENTITY,
            1,
        );
        for o in [
            "-pc_type fieldsplit",
            "-fieldsplit_u_pc_type hypre",
            "-fieldsplit_eta_bar_sub_pc_type ilu",
        ] {
            assert!(split.contains(o), "{o} in {split}");
        }
    }
}
