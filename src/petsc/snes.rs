//! PETSc SNES (Newton and friends) driving a Rust [`NonlinearProblem`]; its KSP/PC are chosen at run time
//! through the options database (`-ksp_type`, `-pc_type`, `-pc_factor_mat_solver_type mumps`, ...).
//!
//! The residual/Jacobian contract: PETSc may evaluate the residual at any state (line search,
//! finite-difference Jacobians, `-snes_mf_operator`, `-snes_test_jacobian`), so a problem must compute
//! both from `x` alone and commit nothing inside a callback.

use super::{
    IndexSet, LAST_ERROR, Matrix, Result, SessionGuard, ThreadedOperator, Vector, check, create,
    cstring, sys, to_petsc_int,
};
use std::cell::Cell;
use std::ffi::{CStr, c_char, c_void};
use std::panic::{AssertUnwindSafe, catch_unwind};

/// What a residual or Jacobian evaluation can report instead of success.
#[derive(Debug, Clone)]
pub enum CallbackError {
    /// The state is outside the problem's domain (det F <= 0, a point left the grid, NaN): SNES is told
    /// (`SNESSetFunctionDomainError`), stops with `DIVERGED_FUNCTION_DOMAIN`, and the caller may retry.
    Domain(String),
    /// An unrecoverable failure: SNESSolve returns an error carrying this message.
    Fatal(String),
}

/// A nonlinear system R(x) = 0 with its Jacobian, evaluated by Rust code.
pub trait NonlinearProblem {
    /// Writes R(x) into `f` (both distributed like the solution vector).
    fn residual(&mut self, x: &Vector, f: &mut Vector) -> std::result::Result<(), CallbackError>;
    /// Assembles dR/dx at `x` into `jac` (the preconditioning matrix).
    fn jacobian(&mut self, x: &Vector, jac: &mut Matrix) -> std::result::Result<(), CallbackError>;
    /// Called at every iteration of the linear solver of a [`Snes::solve`], on every process at the same
    /// iteration: an error (of either kind) ends the solve at once, as a fatal one. Nothing by default.
    fn linear_iteration(&mut self) -> std::result::Result<(), CallbackError> {
        Ok(())
    }
}

/// Statistics of one [`Snes::solve`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolveInfo {
    /// Nonlinear (Newton) iterations.
    pub iterations: usize,
    /// Linear (KSP) iterations summed over the Newton iterations.
    pub linear_iterations: usize,
    /// PETSc's `SNESConvergedReason` code (> 0 converged, < 0 diverged).
    pub reason: i32,
    /// The reason as PETSc names it, e.g. `CONVERGED_FNORM_RELATIVE`.
    pub reason_name: String,
    /// Residual norm at each Newton iteration, starting with the initial one.
    pub residual_norms: Vec<f64>,
    /// Messages of domain errors reported by the problem during the solve.
    pub domain_errors: Vec<String>,
}

impl SolveInfo {
    /// True if SNES reports convergence.
    pub fn converged(&self) -> bool {
        self.reason > 0
    }
}

/// SNES convergence tolerances (`-snes_atol`, `-snes_rtol`, `-snes_stol`, `-snes_max_it`,
/// `-snes_max_funcs`); residual norms in the units of the scaled residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerances {
    /// Absolute tolerance on the residual norm.
    pub atol: f64,
    /// Tolerance on the residual norm relative to the solve's initial one.
    pub rtol: f64,
    /// Tolerance on the Newton update relative to the solution.
    pub stol: f64,
    /// Most Newton iterations.
    pub max_it: sys::PetscInt,
    /// Most residual evaluations.
    pub max_f: sys::PetscInt,
}

/// A PETSc SNES with its options prefix.
pub struct Snes {
    raw: sys::SNES,
    residual: Option<Vector>,
    configured: bool,
    /// The context of the solve in progress (null between solves) for the linear solver's monitor,
    /// which is registered once with this box's address ([`linear_monitor_cb`]).
    monitored: Option<Box<Cell<*mut c_void>>>,
    /// The Krylov solver's operator where it is not the Jacobian itself ([`Snes::set_operator`]).
    operator: Option<ThreadedOperator>,
    /// The state of the stall test of [`converged_cb`] (registered once with this box's address).
    stall: Box<Stall>,
    /// PETSc's preconditioners to become the solver's own threaded ones at the next Jacobian
    /// ([`Snes::use_threaded_ilu_on_subdomains`], [`Snes::use_threaded_sor_on_levels`]); `None` once done
    /// or not asked.
    replacement: Option<Replacement>,
    /// How many subdomains' ILU(0) or levels' SOR the last replacement made the threaded ones.
    threaded: usize,
    /// The linear solver's relative tolerance at the first Newton iteration of a solve
    /// ([`Snes::set_first_linear_rtol`]); `None`: the configured one at every iteration.
    first_linear_rtol: Option<f64>,
    /// The residual norm, relative to the solve's first, below which a Newton iteration keeps the last
    /// Jacobian ([`Snes::set_keep_jacobian_below`]); `None`: a Jacobian at every iteration.
    keep_jacobian_below: Option<f64>,
}

/// Which of PETSc's preconditioners inside the Krylov solver's the first Jacobian of a solve replaces by
/// the solver's own threaded ones (PETSc makes them from assembled values at the first set-up).
#[derive(Clone, Copy, Debug)]
enum Replacement {
    /// The ILU(0) of each subdomain of block Jacobi or additive Schwarz, for Jacobians of this block
    /// size (`petsc::preconditioner::threaded_ilu_on_subdomains`).
    SubdomainIlu(usize),
    /// The symmetric SOR of each level of the multigrid (`petsc::smoother::threaded_sor_on_levels`).
    LevelSor,
}

/// What [`converged_cb`] keeps between the iterations of a solve.
#[derive(Default)]
struct Stall {
    /// The residual norm of the previous iteration.
    previous: Cell<f64>,
    /// Iterations in a row that left the residual norm unchanged.
    unchanged: Cell<sys::PetscInt>,
}

/// Relative change of the residual norm below which a Newton iteration made no progress: the solve
/// stops there as a linear-solver failure ([`converged_cb`]).
pub const STALLED: f64 = 1e-10;

struct Context<'a> {
    problem: &'a mut dyn NonlinearProblem,
    fatal: Option<String>,
    domain: Vec<String>,
    /// [`Snes::replacement`] for this solve, taken by the first Jacobian.
    replacement: Option<Replacement>,
    /// How many subdomains or levels the first Jacobian's replacement reached.
    threaded: Option<usize>,
    /// The linear solver's relative tolerance at the first Newton iteration and at the others
    /// ([`update_cb`]).
    linear_rtol: Option<(f64, f64)>,
    /// [`Snes::set_keep_jacobian_below`] for this solve, with the residual norm at its first Jacobian.
    keep_jacobian: Option<KeepJacobian>,
}

/// When a Newton iteration keeps the last Jacobian ([`jacobian_cb`]).
#[derive(Clone, Copy, Debug)]
struct KeepJacobian {
    /// Residual norm relative to the solve's first below which the Jacobian is kept.
    below: f64,
    /// The residual norm at the solve's first Newton iteration.
    first: f64,
    /// The residual norm at the previous Newton iteration.
    previous: f64,
}

/// The least reduction of the residual norm by the last Newton iteration for the next to keep its
/// Jacobian: an iteration that did not converge fast (a stall, a line search's short step) is followed
/// by a fresh Jacobian, as without the option.
const KEEP_AFTER_REDUCTION: f64 = 0.1;

/// PETSc's generic user error code (`PETSC_ERR_USER`).
const ERR_USER: sys::PetscErrorCode = 83;

impl Replacement {
    /// Replaces the preconditioners inside `ksp`'s (operators `a`, `p`); how many it replaced.
    ///
    /// # Safety
    /// `ksp`, `a` and `p` are valid; `p` holds assembled values.
    unsafe fn install(self, ksp: sys::KSP, a: sys::Mat, p: sys::Mat) -> Result<usize> {
        // SAFETY: the caller's promise.
        unsafe {
            match self {
                Self::SubdomainIlu(bs) => {
                    super::preconditioner::threaded_ilu_on_subdomains(ksp, a, p, bs)
                }
                Self::LevelSor => super::smoother::threaded_sor_on_levels(ksp, a, p),
            }
        }
    }
}

impl Snes {
    /// A SNES whose options are read with `prefix` (e.g. `Some("smoke_")` reads `-smoke_snes_rtol`); the
    /// program's main solver uses no prefix so that plain `-snes_*`/`-ksp_*`/`-pc_*` options apply.
    pub fn new(_s: &SessionGuard, prefix: Option<&str>) -> Result<Self> {
        // The wrapper destroys it on drop.
        let raw = create(sys::SNESCreate, "SNESCreate")?;
        let snes = Self {
            raw,
            residual: None,
            configured: false,
            monitored: None,
            operator: None,
            stall: Box::default(),
            replacement: None,
            threaded: 0,
            first_linear_rtol: None,
            keep_jacobian_below: None,
        };
        if let Some(p) = prefix {
            let c = cstring(p)?;
            check(
                unsafe { sys::SNESSetOptionsPrefix(snes.raw, c.as_ptr()) },
                "SNESSetOptionsPrefix",
            )?;
        }
        // Keep the residual history of every solve (PETSc allocates it).
        check(
            unsafe {
                sys::SNESSetConvergenceHistory(
                    snes.raw,
                    std::ptr::null_mut(),
                    std::ptr::null_mut(),
                    sys::mpmc_petsc_decide(),
                    sys::PetscBool_PETSC_TRUE,
                )
            },
            "SNESSetConvergenceHistory",
        )?;
        // PETSc's tests, and a stalled iteration ended at once (the box lives as long as the SNES).
        let stall: *const Stall = &*snes.stall;
        check(
            unsafe {
                sys::SNESSetConvergenceTest(
                    snes.raw,
                    Some(converged_cb),
                    stall.cast_mut().cast(),
                    None,
                )
            },
            "SNESSetConvergenceTest",
        )?;
        Ok(snes)
    }

    /// Reads the options database (command line, config defaults). Called by the first
    /// [`Snes::solve`] if not called before; call it explicitly before [`Snes::set_fieldsplit`].
    pub fn set_from_options(&mut self) -> Result<()> {
        // SAFETY: valid SNES.
        check(
            unsafe { sys::SNESSetFromOptions(self.raw) },
            "SNESSetFromOptions",
        )?;
        self.configured = true;
        Ok(())
    }

    /// The convergence tolerances in use (after [`Snes::set_from_options`]).
    pub fn tolerances(&self) -> Result<Tolerances> {
        let (mut atol, mut rtol, mut stol, mut max_it, mut max_f) = (0.0, 0.0, 0.0, 0, 0);
        // SAFETY: valid SNES, out-parameters.
        check(
            unsafe {
                sys::SNESGetTolerances(
                    self.raw,
                    &mut atol,
                    &mut rtol,
                    &mut stol,
                    &mut max_it,
                    &mut max_f,
                )
            },
            "SNESGetTolerances",
        )?;
        Ok(Tolerances {
            atol,
            rtol,
            stol,
            max_it,
            max_f,
        })
    }

    /// Sets all convergence tolerances (each value explicitly, so the meaning of `PETSC_DEFAULT`, which
    /// changed between PETSc versions, never matters).
    pub fn set_tolerances(&mut self, t: &Tolerances) -> Result<()> {
        // SAFETY: valid SNES.
        check(
            unsafe { sys::SNESSetTolerances(self.raw, t.atol, t.rtol, t.stol, t.max_it, t.max_f) },
            "SNESSetTolerances",
        )
    }

    /// Solves the linear system of the first Newton iteration of every solve to the relative tolerance
    /// `rtol` only (or the configured one if that is looser), and those of the later iterations to the
    /// configured one (`None`: the configured one everywhere). Eisenstat-Walker's forcing
    /// (`-snes_ksp_ew`) sets every iteration's tolerance inside the Krylov solve and so overrides it.
    /// The first iteration of an inertia-dominated step carries the prescribed motion and the contact
    /// of the devices into the interior, and its residual is left at a few thousandths of
    /// where it started by the nonlinearity, whatever the linear solve reaches; the later iterations
    /// converge quadratically from there on solves to the configured tolerance, as before
    /// (`docs/theory.md`, "Solver defaults").
    pub fn set_first_linear_rtol(&mut self, rtol: Option<f64>) {
        self.first_linear_rtol = rtol;
    }

    /// Keeps the last Jacobian (and so the operator GMRES multiplies by) for the Newton iterations whose
    /// residual norm is below `below` times the solve's first and a tenth of the previous iteration's
    /// (`None`: a Jacobian at every iteration). Near the solution the tangent hardly changes between
    /// iterates: an inertia-dominated step goes 3460 -> 10 -> 0.04 -> 3e-7 in three iterations (the
    /// paper-size CT), and its third iteration reaches the tolerance as well with the second's Jacobian
    /// at the cost of a residual evaluation only (`docs/benchmarks.md`, "The Jacobian kept near the
    /// solution": faster cracked steps, not a faster whole run).
    pub fn set_keep_jacobian_below(&mut self, below: Option<f64>) {
        self.keep_jacobian_below = below;
    }

    /// The linear solver's relative tolerance (`-ksp_rtol`).
    fn linear_rtol(&self) -> Result<f64> {
        let mut rtol = 0.0;
        // SAFETY: valid KSP; out-parameters (null: not asked).
        check(
            unsafe {
                sys::KSPGetTolerances(
                    self.ksp()?,
                    &mut rtol,
                    std::ptr::null_mut(),
                    std::ptr::null_mut(),
                    std::ptr::null_mut(),
                )
            },
            "KSPGetTolerances",
        )?;
        Ok(rtol)
    }

    /// Sets the linear solver's relative tolerance, the others unchanged.
    fn set_linear_rtol(&self, rtol: f64) -> Result<()> {
        // SAFETY: valid KSP.
        unsafe { set_ksp_rtol(self.ksp()?, rtol) }
    }

    /// The lag of the preconditioner (`-snes_lag_preconditioner`): 1 builds it at every Newton
    /// iteration, `k > 1` at every k-th, -1 never again.
    pub fn lag_preconditioner(&self) -> Result<sys::PetscInt> {
        let mut lag = 0;
        // SAFETY: valid SNES, out-parameter.
        check(
            unsafe { sys::SNESGetLagPreconditioner(self.raw, &mut lag) },
            "SNESGetLagPreconditioner",
        )?;
        Ok(lag)
    }

    /// Sets the lag of the preconditioner (see [`Snes::lag_preconditioner`]).
    pub fn set_lag_preconditioner(&mut self, lag: sys::PetscInt) -> Result<()> {
        // SAFETY: valid SNES.
        check(
            unsafe { sys::SNESSetLagPreconditioner(self.raw, lag) },
            "SNESSetLagPreconditioner",
        )
    }

    /// Names the fields for `-pc_type fieldsplit` (ignored by other preconditioners).
    pub fn set_fieldsplit(&mut self, fields: &[(&str, &IndexSet)]) -> Result<()> {
        let pc = self.pc()?;
        for (name, is) in fields {
            let c = cstring(name)?;
            // SAFETY: valid PC and IS; PETSc takes a reference to the IS.
            check(
                unsafe { sys::PCFieldSplitSetIS(pc, c.as_ptr(), is.raw) },
                "PCFieldSplitSetIS",
            )?;
        }
        Ok(())
    }

    /// The preconditioner's type as set so far (from the options database), e.g. `"mg"`, or `None`.
    pub fn pc_type(&self) -> Result<Option<String>> {
        let mut t: *const c_char = std::ptr::null();
        // SAFETY: PETSc returns a pointer to its own type-name string (or null if unset).
        check(unsafe { sys::PCGetType(self.pc()?, &mut t) }, "PCGetType")?;
        Ok((!t.is_null()).then(|| {
            // SAFETY: non-null NUL-terminated string owned by PETSc.
            unsafe { CStr::from_ptr(t) }.to_string_lossy().into_owned()
        }))
    }

    /// Makes the preconditioner (of type `mg`) a multigrid over `interpolations.len() + 1` levels:
    /// `interpolations[l]` maps level `l + 1` to level `l`, level 0 being the Jacobian's (PETSc counts
    /// the other way, the finest level last). The coarse operators are Galerkin products `P^T A P`
    /// (MatPtAP), formed at every set-up of the preconditioner from the assembled Jacobian (the
    /// preconditioning matrix, on which every level works: the Krylov solver's operator may be a shell,
    /// [`Snes::set_operator`]). The smoothers and the
    /// coarse solve keep PETSc's defaults and read `-mg_levels_*` and `-mg_coarse_*` (with the SNES
    /// prefix) when the preconditioner is set up.
    pub fn set_multigrid(&mut self, interpolations: &[Matrix]) -> Result<()> {
        let pc = self.pc()?;
        let levels = to_petsc_int(interpolations.len() + 1, "PCMGSetLevels")?;
        // SAFETY: valid PC of type mg; no communicators given (all levels on the PC's).
        check(
            unsafe { sys::PCMGSetLevels(pc, levels, std::ptr::null_mut()) },
            "PCMGSetLevels",
        )?;
        check(
            unsafe { sys::PCMGSetGalerkin(pc, sys::PCMGGalerkinType_PC_MG_GALERKIN_BOTH) },
            "PCMGSetGalerkin",
        )?;
        // Every level on the assembled Jacobian, even under `-pc_use_amat` (set with the options
        // before this): the Krylov solver's operator may be a shell without the entries the Galerkin
        // products need.
        // SAFETY: valid PC.
        check(
            unsafe { sys::PCSetUseAmat(pc, sys::PetscBool_PETSC_FALSE) },
            "PCSetUseAmat",
        )?;
        for (l, p) in interpolations.iter().enumerate() {
            let level = levels - 1 - l as sys::PetscInt;
            // SAFETY: valid PC and matrix; PETSc takes its own reference.
            check(
                unsafe { sys::PCMGSetInterpolation(pc, level, p.raw) },
                "PCMGSetInterpolation",
            )?;
        }
        Ok(())
    }

    pub(super) fn ksp(&self) -> Result<sys::KSP> {
        let mut ksp = std::ptr::null_mut();
        // SAFETY: out-parameter, borrowed reference.
        check(unsafe { sys::SNESGetKSP(self.raw, &mut ksp) }, "SNESGetKSP")?;
        Ok(ksp)
    }

    pub(super) fn pc(&self) -> Result<sys::PC> {
        let mut pc = std::ptr::null_mut();
        // SAFETY: out-parameter, borrowed reference.
        check(unsafe { sys::KSPGetPC(self.ksp()?, &mut pc) }, "KSPGetPC")?;
        Ok(pc)
    }

    /// The solver combination in use, e.g. `"newtonls / preonly / lu"`.
    pub fn describe(&self) -> Result<String> {
        let mut snes_t: *const c_char = std::ptr::null();
        let mut ksp_t: *const c_char = std::ptr::null();
        let mut pc_t: *const c_char = std::ptr::null();
        // SAFETY: PETSc returns pointers to its own type-name strings (or null if unset).
        unsafe {
            check(sys::SNESGetType(self.raw, &mut snes_t), "SNESGetType")?;
            check(sys::KSPGetType(self.ksp()?, &mut ksp_t), "KSPGetType")?;
            check(sys::PCGetType(self.pc()?, &mut pc_t), "PCGetType")?;
        }
        let name = |p: *const c_char| {
            if p.is_null() {
                "default".to_owned()
            } else {
                // SAFETY: non-null NUL-terminated string owned by PETSc.
                unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
            }
        };
        Ok(format!(
            "{} / {} / {}",
            name(snes_t),
            name(ksp_t),
            name(pc_t)
        ))
    }

    /// Makes `operator` the Krylov solver's operator in later solves: its product is the Jacobian's
    /// (computed on all threads), while the preconditioner is still built from the Jacobian.
    pub fn set_operator(&mut self, operator: ThreadedOperator) {
        self.operator = Some(operator);
    }

    /// Makes the ILU(0) of each subdomain of block Jacobi or additive Schwarz (`-pc_type bjacobi` or
    /// `asm`, `-sub_pc_type ilu`) the solver's own threaded one for a Jacobian of block size `bs`
    /// (`petsc::preconditioner::threaded_ilu_on_subdomains`), at the first Jacobian of the next solve
    /// (PETSc makes the subdomains' matrices from assembled values). Nothing changes where it does not
    /// apply (another preconditioner, point-wise storage).
    pub fn use_threaded_ilu_on_subdomains(&mut self, bs: usize) {
        self.replacement = Some(Replacement::SubdomainIlu(bs));
    }

    /// Makes the symmetric SOR of each level of the multigrid (`-pc_type mg`, `-mg_levels_pc_type sor`)
    /// the solver's own sweep on all threads (`petsc::smoother::threaded_sor_on_levels`), at the first
    /// Jacobian of the next solve (PETSc makes the levels' smoothers at the first set-up). Nothing
    /// changes where it does not apply (another preconditioner or smoother, several processes).
    pub fn use_threaded_sor_on_levels(&mut self) {
        self.replacement = Some(Replacement::LevelSor);
    }

    /// Replaces PETSc's preconditioners now if [`Snes::use_threaded_ilu_on_subdomains`] or
    /// [`Snes::use_threaded_sor_on_levels`] asked for it, with the Krylov solver's operators `a` and `p`
    /// (assembled).
    pub(super) fn install_replacement(&mut self, a: sys::Mat, p: sys::Mat) -> Result<()> {
        if let Some(replacement) = self.replacement.take() {
            // SAFETY: the SNES's own KSP; the caller's matrices are valid and assembled.
            self.threaded = unsafe { replacement.install(self.ksp()?, a, p) }?;
        }
        Ok(())
    }

    /// How many of this process's subdomains (ILU(0)) or multigrid levels (SOR) precondition with the
    /// solver's own threaded kernels after [`Snes::use_threaded_ilu_on_subdomains`] or
    /// [`Snes::use_threaded_sor_on_levels`] (0 before the first Jacobian, or where it did not apply).
    pub fn threaded_preconditioners(&self) -> usize {
        self.threaded
    }

    /// Solves `problem` from the initial guess in `x` (overwritten by the solution), assembling the
    /// Jacobian into `jac`. PETSc failures (bad options, errors raised in callbacks) are `Err`; a solve
    /// that simply does not converge is `Ok` with [`SolveInfo::converged`] false.
    pub fn solve(
        &mut self,
        problem: &mut dyn NonlinearProblem,
        x: &mut Vector,
        jac: &mut Matrix,
    ) -> Result<SolveInfo> {
        if self.residual.is_none() {
            self.residual = Some(x.duplicate()?);
        }
        let r = self
            .residual
            .as_ref()
            .map_or(std::ptr::null_mut(), |v| v.raw);
        let mut ctx = Context {
            problem,
            fatal: None,
            domain: Vec::new(),
            replacement: self.replacement,
            threaded: None,
            linear_rtol: None,
            keep_jacobian: self.keep_jacobian_below.map(|below| KeepJacobian {
                below,
                first: f64::INFINITY,
                previous: f64::INFINITY,
            }),
        };
        if let Some(first) = self.first_linear_rtol {
            // The configured tolerance is the options' (read once they are applied); a first solve
            // never tighter than it.
            if !self.configured {
                self.set_from_options()?;
            }
            let rest = self.linear_rtol()?;
            ctx.linear_rtol = Some((first.max(rest), rest));
        }
        let ctx_ptr = (&mut ctx as *mut Context).cast::<c_void>();
        *LAST_ERROR.lock().unwrap_or_else(|e| e.into_inner()) = None;
        // SAFETY: ctx outlives SNESSolve, the only place PETSc calls the callbacks; they are re-set on
        // every solve, so PETSc never calls a stale context.
        let result = unsafe {
            check(
                sys::SNESSetFunction(self.raw, r, Some(residual_cb), ctx_ptr),
                "SNESSetFunction",
            )
            .and_then(|()| {
                check(
                    sys::SNESSetJacobian(
                        self.raw,
                        self.operator.as_ref().map_or(jac.raw, |o| o.shell.raw),
                        jac.raw,
                        Some(jacobian_cb),
                        ctx_ptr,
                    ),
                    "SNESSetJacobian",
                )
            })
            .and_then(|()| {
                if self.configured {
                    Ok(())
                } else {
                    self.set_from_options()
                }
            })
            .and_then(|()| self.monitor_linear_solver())
            .and_then(|()| {
                let update = ctx.linear_rtol.map(|_| update_cb as UpdateFn);
                check(sys::SNESSetUpdate(self.raw, update), "SNESSetUpdate")
            })
            .and_then(|()| {
                if let Some(slot) = &self.monitored {
                    slot.set(ctx_ptr);
                }
                let solved = check(
                    sys::SNESSolve(self.raw, std::ptr::null_mut(), x.raw),
                    "SNESSolve",
                );
                if let Some(slot) = &self.monitored {
                    slot.set(std::ptr::null_mut());
                }
                solved
            })
        };
        if ctx.replacement.is_none() {
            self.replacement = None;
        }
        // The configured tolerance again for whoever reads it after the solve (a failure to restore it
        // does not hide the solve's own error).
        if let Some((_, rest)) = ctx.linear_rtol {
            let restored = self.set_linear_rtol(rest);
            if result.is_ok() {
                restored?;
            }
        }
        if let Some(n) = ctx.threaded {
            self.threaded = n;
        }
        if let Err(mut e) = result {
            if let Some(msg) = ctx.fatal.take() {
                e.message = msg;
            }
            return Err(e);
        }
        self.info(ctx.domain)
    }

    /// Registers [`linear_monitor_cb`] with the linear solver, once (PETSc keeps a monitor for the life
    /// of the KSP, and registering one per solve would pile them up).
    fn monitor_linear_solver(&mut self) -> Result<()> {
        if self.monitored.is_some() {
            return Ok(());
        }
        let slot = Box::new(Cell::new(std::ptr::null_mut::<c_void>()));
        let slot_ptr = std::ptr::from_ref::<Cell<*mut c_void>>(&slot)
            .cast_mut()
            .cast::<c_void>();
        // SAFETY: valid KSP; the box outlives the SNES and its KSP (dropped after SNESDestroy).
        check(
            unsafe { sys::KSPMonitorSet(self.ksp()?, Some(linear_monitor_cb), slot_ptr, None) },
            "KSPMonitorSet",
        )?;
        self.monitored = Some(slot);
        Ok(())
    }

    fn info(&self, domain_errors: Vec<String>) -> Result<SolveInfo> {
        let (mut its, mut lits, mut reason) = (0, 0, 0);
        let mut name: *const c_char = std::ptr::null();
        let mut hist: *mut f64 = std::ptr::null_mut();
        let mut hist_its: *mut sys::PetscInt = std::ptr::null_mut();
        let mut nhist = 0;
        // SAFETY: out-parameters; the history arrays belong to the SNES and are copied immediately.
        unsafe {
            check(
                sys::SNESGetIterationNumber(self.raw, &mut its),
                "SNESGetIterationNumber",
            )?;
            check(
                sys::SNESGetLinearSolveIterations(self.raw, &mut lits),
                "SNESGetLinearSolveIterations",
            )?;
            check(
                sys::SNESGetConvergedReason(self.raw, &mut reason),
                "SNESGetConvergedReason",
            )?;
            check(
                sys::SNESGetConvergedReasonString(self.raw, &mut name),
                "SNESGetConvergedReasonString",
            )?;
            check(
                sys::SNESGetConvergenceHistory(self.raw, &mut hist, &mut hist_its, &mut nhist),
                "SNESGetConvergenceHistory",
            )?;
        }
        let residual_norms = if hist.is_null() || nhist <= 0 {
            Vec::new()
        } else {
            // SAFETY: PETSc reports nhist valid entries.
            unsafe { std::slice::from_raw_parts(hist, nhist as usize) }.to_vec()
        };
        // SAFETY: null or a static string owned by PETSc.
        let reason_name = unsafe { super::reason_name(name, reason) };
        Ok(SolveInfo {
            iterations: its as usize,
            linear_iterations: lits as usize,
            reason,
            reason_name,
            residual_norms,
            domain_errors,
        })
    }
}

impl Drop for Snes {
    fn drop(&mut self) {
        // SAFETY: we own the SNES.
        unsafe { sys::SNESDestroy(&mut self.raw) };
    }
}

fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".to_owned())
}

/// Runs a callback body, turning Rust errors and panics into PETSc's conventions.
///
/// # Safety
/// `ctx` must point to the live `Context` of the current solve.
unsafe fn guarded(
    snes: sys::SNES,
    ctx: *mut c_void,
    domain_error: unsafe extern "C" fn(sys::SNES) -> sys::PetscErrorCode,
    body: impl FnOnce(&mut dyn NonlinearProblem) -> std::result::Result<(), CallbackError>,
) -> sys::PetscErrorCode {
    // SAFETY: guaranteed by the caller.
    let ctx = unsafe { &mut *ctx.cast::<Context>() };
    match catch_unwind(AssertUnwindSafe(|| body(ctx.problem))) {
        Ok(Ok(())) => 0,
        Ok(Err(CallbackError::Domain(msg))) => {
            ctx.domain.push(msg);
            // SAFETY: valid SNES handed to the callback.
            unsafe { domain_error(snes) }
        }
        Ok(Err(CallbackError::Fatal(msg))) => {
            ctx.fatal = Some(msg);
            ERR_USER
        }
        Err(p) => {
            ctx.fatal = Some(format!(
                "panic in a SNES callback: {}",
                panic_message(p.as_ref())
            ));
            ERR_USER
        }
    }
}

/// The linear solver's monitor: [`NonlinearProblem::linear_iteration`] of the solve in progress, whose
/// context `slot` (a `Cell` of [`Snes`]) holds (nothing between solves).
unsafe extern "C" fn linear_monitor_cb(
    _ksp: sys::KSP,
    _iteration: sys::PetscInt,
    _norm: sys::PetscReal,
    slot: *mut c_void,
) -> sys::PetscErrorCode {
    // SAFETY: `slot` is the box registered by `monitor_linear_solver`, alive as long as the KSP.
    let ctx = unsafe { &*slot.cast::<Cell<*mut c_void>>() }.get();
    if ctx.is_null() {
        return 0;
    }
    // SAFETY: set only during SNESSolve, to the live `Context` of that solve; no other callback of the
    // solve runs at the same time.
    let ctx = unsafe { &mut *ctx.cast::<Context>() };
    match catch_unwind(AssertUnwindSafe(|| ctx.problem.linear_iteration())) {
        Ok(Ok(())) => 0,
        Ok(Err(CallbackError::Domain(msg) | CallbackError::Fatal(msg))) => {
            ctx.fatal = Some(msg);
            ERR_USER
        }
        Err(p) => {
            ctx.fatal = Some(format!(
                "panic in the linear solver's monitor: {}",
                panic_message(p.as_ref())
            ));
            ERR_USER
        }
    }
}

/// `SNESSetUpdate`'s callback.
type UpdateFn = unsafe extern "C" fn(sys::SNES, sys::PetscInt) -> sys::PetscErrorCode;

/// Sets the relative tolerance of `ksp`, its other tolerances unchanged (`PETSC_DEFAULT`).
///
/// # Safety
/// `ksp` is valid.
unsafe fn set_ksp_rtol(ksp: sys::KSP, rtol: f64) -> Result<()> {
    const KEEP: f64 = -2.0; // PETSC_DEFAULT: keeps the current value (PETSc 3.18)
    // SAFETY: the caller's promise.
    check(
        unsafe { sys::KSPSetTolerances(ksp, rtol, KEEP, KEEP, -2) },
        "KSPSetTolerances",
    )
}

/// Before each Newton iteration `step` (PETSc's `SNESSetUpdate`): the linear solver's relative
/// tolerance of that iteration, from the solve's context ([`Snes::set_first_linear_rtol`]).
unsafe extern "C" fn update_cb(snes: sys::SNES, step: sys::PetscInt) -> sys::PetscErrorCode {
    let mut ctx: *mut c_void = std::ptr::null_mut();
    let mut ksp: sys::KSP = std::ptr::null_mut();
    // SAFETY: PETSc's SNES during SNESSolve; the function's context is the solve's `Context`, alive
    // until SNESSolve returns (set with the function at every solve).
    unsafe {
        let code = sys::SNESGetFunction(snes, std::ptr::null_mut(), std::ptr::null_mut(), &mut ctx);
        if code != 0 || ctx.is_null() {
            return if code != 0 { code } else { ERR_USER };
        }
        let Some((first, rest)) = (*ctx.cast::<Context>()).linear_rtol else {
            return 0;
        };
        let code = sys::SNESGetKSP(snes, &mut ksp);
        if code != 0 {
            return code;
        }
        match set_ksp_rtol(ksp, if step == 0 { first } else { rest }) {
            Ok(()) => 0,
            Err(e) => e.code,
        }
    }
}

/// PETSc's default convergence test, and for Newton with line search (`newtonls`, the default) one more:
/// iterations that leave the residual norm unchanged to a relative [`STALLED`], as many in a row as the
/// preconditioner's lag (so that one of them had a preconditioner built at the stalled state), end the
/// solve as `DIVERGED_LINEAR_SOLVE`. Newton's next iteration would start from the same state with the same
/// Jacobian and preconditioner and change nothing either: GMRES preconditioned from the left can
/// "converge" through an ILU(0) with a tiny pivot to a step that changes nothing (the paper-size CT at
/// 4.3 m/s, step 373), and Newton used to run to its 25 iterations before the caller saw the stall.
/// Another linear solver (the step's fallback) may then succeed at the same dt. Other SNES types are
/// left to PETSc's test: the trust region asks it again after a rejected step, at an unchanged norm.
unsafe extern "C" fn converged_cb(
    snes: sys::SNES,
    it: sys::PetscInt,
    xnorm: sys::PetscReal,
    snorm: sys::PetscReal,
    fnorm: sys::PetscReal,
    reason: *mut sys::SNESConvergedReason,
    stall: *mut c_void,
) -> sys::PetscErrorCode {
    // SAFETY: PETSc passes a valid SNES and reason; `stall` is the box registered in `Snes::new`, alive
    // as long as the SNES.
    unsafe {
        let code =
            sys::SNESConvergedDefault(snes, it, xnorm, snorm, fnorm, reason, std::ptr::null_mut());
        if code != 0 {
            return code;
        }
        let stall = &*stall.cast::<Stall>();
        let unchanged = it > 0 && (fnorm - stall.previous.get()).abs() <= STALLED * fnorm.abs();
        stall.unchanged.set(if unchanged {
            stall.unchanged.get() + 1
        } else {
            0
        });
        stall.previous.set(fnorm);
        if !unchanged || *reason != sys::SNESConvergedReason_SNES_CONVERGED_ITERATING {
            return 0;
        }
        let mut kind: sys::SNESType = std::ptr::null();
        let mut lag: sys::PetscInt = 1;
        let code = sys::SNESGetType(snes, &mut kind);
        if code != 0 {
            return code;
        }
        let code = sys::SNESGetLagPreconditioner(snes, &mut lag);
        if code != 0 {
            return code;
        }
        let newton = !kind.is_null() && CStr::from_ptr(kind).to_bytes() == b"newtonls";
        if newton && stall.unchanged.get() >= lag.max(1) {
            *reason = sys::SNESConvergedReason_SNES_DIVERGED_LINEAR_SOLVE;
        }
    }
    0
}

unsafe extern "C" fn residual_cb(
    snes: sys::SNES,
    x: sys::PetscVec,
    f: sys::PetscVec,
    ctx: *mut c_void,
) -> sys::PetscErrorCode {
    // SAFETY: PETSc hands valid vectors for the duration of the call; ctx is ours.
    unsafe {
        let x = Vector::borrowed(x);
        let mut f = Vector::borrowed(f);
        guarded(snes, ctx, sys::SNESSetFunctionDomainError, |p| {
            p.residual(&x, &mut f)
        })
    }
}

/// Whether this Newton iteration keeps the last Jacobian ([`Snes::set_keep_jacobian_below`]): its
/// residual norm below the set fraction of the solve's first and below [`KEEP_AFTER_REDUCTION`] of
/// the previous iteration's. The first iteration of a solve never keeps one (the matrix may hold
/// another solve's Jacobian).
///
/// # Safety
/// `snes` is the SNES in SNESSolve whose context is `ctx`.
unsafe fn keeps_jacobian(snes: sys::SNES, ctx: &mut Context) -> Result<bool> {
    let Some(keep) = ctx.keep_jacobian.as_mut() else {
        return Ok(false);
    };
    let mut its: sys::PetscInt = 0;
    let mut f: sys::PetscVec = std::ptr::null_mut();
    let mut norm = 0.0;
    // SAFETY: the caller's promise; PETSc's residual vector of the current iterate.
    unsafe {
        check(
            sys::SNESGetIterationNumber(snes, &mut its),
            "SNESGetIterationNumber",
        )?;
        check(
            sys::SNESGetFunction(snes, &mut f, std::ptr::null_mut(), std::ptr::null_mut()),
            "SNESGetFunction",
        )?;
        check(sys::VecNorm(f, sys::NormType_NORM_2, &mut norm), "VecNorm")?;
    }
    if its == 0 {
        keep.first = norm;
    }
    let kept =
        its > 0 && norm <= keep.below * keep.first && norm <= KEEP_AFTER_REDUCTION * keep.previous;
    keep.previous = norm;
    Ok(kept)
}

unsafe extern "C" fn jacobian_cb(
    snes: sys::SNES,
    x: sys::PetscVec,
    a: sys::Mat,
    p: sys::Mat,
    ctx: *mut c_void,
) -> sys::PetscErrorCode {
    // SAFETY: as in residual_cb.
    unsafe {
        match keeps_jacobian(snes, &mut *ctx.cast::<Context>()) {
            // A matrix-free operator (-snes_mf_operator) is still told the state changed: its
            // products difference the residual about the new iterate.
            Ok(true) if a != p => {
                return Matrix::borrowed(a)
                    .assemble()
                    .map_or_else(|e| e.code, |()| 0);
            }
            Ok(true) => return 0,
            Ok(false) => {}
            Err(e) => return e.code,
        }
        let x = Vector::borrowed(x);
        let mut pmat = Matrix::borrowed(p);
        let code = guarded(snes, ctx, sys::SNESSetJacobianDomainError, |prob| {
            prob.jacobian(&x, &mut pmat)
        });
        if code == 0 && a != p {
            // A matrix-free operator (-snes_mf_operator) only needs to be told the state changed.
            let mut amat = Matrix::borrowed(a);
            if let Err(e) = amat.assemble() {
                return e.code;
            }
        }
        // The first Jacobian of a solve asked to that succeeds: PETSc's subdomain ILU(0) or level SOR
        // replaced, now that `p` holds values.
        if code == 0
            && let Some(replacement) = (*ctx.cast::<Context>()).replacement.take()
        {
            let installed = std::panic::catch_unwind(|| {
                let mut ksp = std::ptr::null_mut();
                check(sys::SNESGetKSP(snes, &mut ksp), "SNESGetKSP")
                    .and_then(|()| replacement.install(ksp, a, p))
            });
            let c = &mut *ctx.cast::<Context>();
            match installed {
                Ok(Ok(n)) => c.threaded = Some(n),
                Ok(Err(e)) => {
                    c.fatal = Some(e.to_string());
                    return e.code;
                }
                Err(panic) => {
                    c.fatal = Some(panic_message(&*panic));
                    return ERR_USER;
                }
            }
        }
        code
    }
}

impl From<CallbackError> for super::PetscError {
    fn from(e: CallbackError) -> Self {
        let message = match e {
            CallbackError::Domain(m) | CallbackError::Fatal(m) => m,
        };
        super::PetscError {
            code: ERR_USER,
            call: "callback",
            message,
        }
    }
}
