//! What a step reports: its statistics and results ([`StepReport`]), and why it or the run failed
//! ([`StepError`]; an attempt that only needs a smaller step is a `Failure`).

use crate::assembly::AssemblyError;
use crate::model::{EnergyBooks, ModelError};
use crate::petsc::{self, SolveInfo};
use crate::shape::ShapeError;
use crate::transfer::TransferError;

/// Why a step attempt did not converge (nothing was committed).
pub(super) struct Failure {
    /// What happened, for the log and the final error.
    pub(super) reason: String,
    /// The linear solver failed (a factorisation, GMRES, or the line search along its direction): another
    /// linear solver may succeed at the same time step. Otherwise Newton itself ran out of iterations,
    /// met a point outside its domain or the contact set did not settle: only a smaller step helps.
    pub(super) linear: bool,
}

/// Failure of a step or a run.
#[derive(Debug, thiserror::Error)]
pub enum StepError {
    /// Shape functions could not be evaluated (a particle or corner left the grid).
    #[error(transparent)]
    Shape(#[from] ShapeError),
    /// P2G/G2P failed.
    #[error(transparent)]
    Transfer(#[from] TransferError),
    /// PETSc failed (bad options, errors in callbacks).
    #[error(transparent)]
    Petsc(#[from] petsc::PetscError),
    /// Evaluation failed outside SNES.
    #[error(transparent)]
    Assembly(#[from] AssemblyError),
    /// Newton did not converge even with the smallest time step.
    #[error(
        "step {step} at t = {time:e} s did not converge down to dt = {dt:e} s (dt_min {dt_min:e} s): {reason}"
    )]
    Diverged {
        /// Step number.
        step: usize,
        /// Time at the start of the step (s).
        time: f64,
        /// Last time step tried (s).
        dt: f64,
        /// Configured minimum (s).
        dt_min: f64,
        /// SNES reason or domain error.
        reason: String,
    },
    /// The set-up cannot become a model ([`Model::new`](crate::model::Model::new)).
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The step met an inconsistency of the run's definition (a load whose segment carries no mass,
    /// contact between bodies on several processes, a grid node shared by three bodies).
    #[error("{0}")]
    Setup(String),
    /// The step was abandoned on an interrupt ([`Interrupt`](super::interrupt::Interrupt)) before it converged, on every
    /// process at the same evaluation: nothing was committed, the state is that of the last finished step.
    /// Not a failure of the step: it is not retried.
    #[error(
        "step {step} at t = {time:e} s was abandoned on an interrupt; nothing of it was committed"
    )]
    Interrupted {
        /// Step number.
        step: usize,
        /// Time at the start of the step (s).
        time: f64,
    },
    /// With the points shared out over processes: another process's point failed in this step (that
    /// process reports which).
    #[error("a point held by another process failed in this step (that process names it)")]
    OtherProcess,
}

/// Per-step statistics and results.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepReport {
    /// Step number (1-based).
    pub step: usize,
    /// Time at the end of the step (s).
    pub time: f64,
    /// Time step used (s).
    pub dt: f64,
    /// Attempts (1 if the first try converged; each retry halves dt).
    pub attempts: usize,
    /// SNES statistics of the converged attempt.
    pub solve: SolveInfo,
    /// Unknowns and Jacobian nonzeros.
    pub unknowns: usize,
    /// Jacobian nonzeros.
    pub nonzeros: usize,
    /// Reaction force per constraint set, `(name, [R_x, R_y(, R_z)])` (N; in 2D per mm thickness).
    pub reactions: Vec<(String, Vec<f64>)>,
    /// Mean prescribed displacement of each constraint set, `(name, [u_x, u_y(, u_z)])` (mm).
    pub displacements: Vec<(String, Vec<f64>)>,
    /// Kinetic energy `sum 1/2 m v^2` (N mm; in 2D per mm thickness).
    pub kinetic_energy: f64,
    /// Stored energy `sum V^0 Psi` (N mm; in 2D per mm thickness).
    pub stored_energy: f64,
    /// Work of the constraint reactions and body forces so far (N mm; in 2D per mm thickness).
    pub external_work: f64,
    /// Wall time of the set-up (shape functions, P2G, pattern), of the SNES solve and in total (s).
    pub wall_setup: f64,
    /// Wall time of the SNES solve (s), of which `wall_assembly` was spent evaluating residuals and
    /// Jacobians in Rust; the rest is PETSc (linear solves, line search).
    pub wall_solve: f64,
    /// Wall time of residual and Jacobian evaluations during the solve (s).
    pub wall_assembly: f64,
    /// Residual and Jacobian evaluations during the solve.
    pub evaluations: [usize; 2],
    /// Wall time of the whole step (s), its failed attempts included (the other wall times are those of
    /// the converged attempt).
    pub wall_total: f64,
    /// True if the step's Jacobian pattern differed from the last step's, so the PETSc objects (matrix,
    /// SNES, preconditioner) were built anew; false if they were reused.
    #[serde(default)]
    pub new_pattern: bool,
    /// Rotation of every pinned device about its pin since t = 0, `(name, theta)` (rad,
    /// counter-clockwise positive).
    #[serde(default)]
    pub rotations: Vec<(String, f64)>,
    /// SNES solves of the converged attempt (more than 1 while a contact active set or a pin rotation
    /// was being settled).
    #[serde(default)]
    pub contact_solves: usize,
    /// MPM on several processes: points that moved to another process at the start of the step, and
    /// ghost copies the processes received (sums over the processes; 0 on one process).
    #[serde(default)]
    pub migrated: usize,
    /// See [`StepReport::migrated`].
    #[serde(default)]
    pub ghosts: usize,
    /// MPM on several processes: bytes (B) each process sent in the step through the program's own
    /// exchanges (points, nodal sums, residual rows, gathers of the unknowns; PETSc's own traffic in its
    /// solvers is not counted: [`crate::petsc::Session::bytes_sent`]), one per process; empty on one
    /// process.
    #[serde(default)]
    pub bytes_sent: Vec<u64>,
    /// Of [`StepReport::bytes_sent`], the bytes of the gathers of the unknowns for the residual and
    /// Jacobian evaluations, one per process.
    #[serde(default)]
    pub bytes_unknowns: Vec<u64>,
    /// Kinetic energy of the points at t = 0 (N mm; in 2D per mm thickness):
    /// `dissipated = W + E_0 - K - Psi`.
    #[serde(default)]
    pub initial_energy: f64,
    /// The energy books after the step: damage, erosion, contact losses (N mm; in 2D per mm thickness).
    #[serde(default)]
    pub books: EnergyBooks,
    /// The crack front after the step (CT runs; filled in by the run, not the step: the solver leaves
    /// it `None`).
    #[serde(default)]
    pub crack: Option<crate::crack::Front>,
    /// Path following: the load factor, the measured opening and the step's ratio after the step.
    #[serde(default)]
    pub path: Option<PathPoint>,
}

/// Where the path is after a step: the load factor and the opening.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PathPoint {
    /// Load factor (s): the reference set has moved its velocity times this.
    pub lambda: f64,
    /// The measured opening (mm).
    pub opening: f64,
    /// The step's prescribed motion over its nominal one (`k`; < 0 on a snap-back).
    pub ratio: f64,
}
