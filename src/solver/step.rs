//! The hub of a step: [`Step`], the step in progress (the model, the state it advances and its
//! workspace), to which the step's phases add their methods, and [`Workspace`], the scratch that a step
//! reuses from the last. The step's control (its attempts) is `control.rs`.

use super::interrupt::Interrupt;
use super::system::LinearSystem;
use crate::assembly::Assembler;
use crate::dofs::DofMap;
use crate::model::{Model, State};
use crate::partition::{NodalWindows, Partition};
use crate::petsc::LogEvent;
use crate::shape::ShapeTable;
use crate::transfer::GridState;
use std::sync::Arc;

/// The per-step scratch of the time step, reused from step to step: shape-function tables, grid fields,
/// the unknowns and their constraints, the assembler's buffers and the PETSc objects. Nothing in it
/// outlives a step's meaning: a workspace may be dropped and rebuilt between steps (a resumed run
/// starts with a fresh one) without changing the results.
#[derive(Default)]
pub struct Workspace<const D: usize = 2> {
    /// Shape functions of the points in the step's configuration.
    pub(super) table: ShapeTable<D>,
    /// Shape functions of the rigid bodies' points (MPM mode; FEM mode uses the reference ones).
    pub(super) rigid_tables: Vec<ShapeTable<D>>,
    /// Grid mass, velocity and acceleration from P2G.
    pub(super) grid_state: GridState<D>,
    /// The unknowns and their constraints.
    pub(super) dofs: DofMap,
    /// Per node copy, its partner in contact between bodies ([`INACTIVE`](crate::dofs::INACTIVE): none;
    /// empty: one field).
    pub(super) partners: Vec<u32>,
    pub(super) assembler: Assembler<D>,
    /// PETSc objects reused while the pattern does not change.
    pub(super) system: Option<LinearSystem>,
    /// PETSc log events `MPMSetup` (shape functions, P2G, pattern) and `MPMAssembly` (residuals and
    /// Jacobians), registered at the first step.
    pub(super) events: Option<[LogEvent; 2]>,
    /// The processes' bands of cell rows (MPM on several processes), set at the first step.
    pub(super) partition: Option<Partition>,
    /// This process's own points during a step: the first `own_points` of the state's points; the
    /// others are copies of other processes' points (ghosts), dropped at the end of the attempt.
    pub(super) own_points: usize,
    /// Points migrated and ghosts received at the start of the step, summed over the processes.
    pub(super) moved: [usize; 2],
    /// MPM on several processes: the node rows of the step's nodal sums on every process (P2G and the
    /// `eta_bar` projection are summed over neighbouring processes only).
    pub(super) windows: Option<NodalWindows>,
    /// The request to stop that the steps watch (`Simulation::watch`).
    pub(super) interrupt: Option<Arc<Interrupt>>,
}

impl<const D: usize> Workspace<D> {
    /// An empty workspace; its buffers grow at the first step.
    pub fn new() -> Self {
        Self::default()
    }
}

/// One step in progress: the model, the state it advances and the workspace it uses. The step's phases
/// add its methods, each in its own file (`prepare.rs`, `solve.rs`, `finish.rs`, ...).
pub(super) struct Step<'a, const D: usize> {
    /// What defines the run.
    pub(super) model: &'a Model<D>,
    /// The committed state, changed only when an attempt converges.
    pub(super) state: &'a mut State<D>,
    /// The step's scratch.
    pub(super) work: &'a mut Workspace<D>,
}
