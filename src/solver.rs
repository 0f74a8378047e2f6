//! The implicit MPM time step (spec Sec. 1): shape functions at `t_n`, P2G, unknown numbering and
//! constraints, Newton on the coupled (du, eta_bar) system through PETSc SNES, G2P and commit; with
//! time-step halving when a step fails.
//!
//! Committed state (particles, time) is only modified after SNES converges: a failed attempt leaves the
//! simulation exactly as it was, so it can be retried with a smaller time step.

use crate::assembly::{Assembler, AssemblyError, Newmark, StepInput};
use crate::boundary::{Motion, prescribed_acceleration, prescribed_increment};
use crate::contact::{self, BodyContact, ContactNode, DeviceContact, NodePair, NodeStatus};
use crate::dofs::{DofMap, INACTIVE};
use crate::grid::Grid;
use crate::material::{Constitutive, Material};
use crate::model::{FemReference, InitialAcceleration, Method, Model, Setup, State};
use crate::particles::Particles;
use crate::partition::{self, Partition};
use crate::petsc::{
    self, BlockCsr, CallbackError, GatherAll, IndexSet, LogEvent, Matrix, NonlinearProblem,
    PetscInt, SessionGuard, Snes, SolveInfo, Tolerances, Vector,
};
use crate::shape::{ShapeError, ShapeKind, ShapeTable};
use crate::space::{from_xy, rotation_xy, xy};
use crate::transfer::{self, GridState, StepSolution, TransferError};
use nalgebra::{SMatrix, SVector, Vector2};
use std::ops::Range;
use std::time::Instant;

/// Why a step attempt did not converge (nothing was committed).
struct Failure {
    /// What happened, for the log and the final error.
    reason: String,
    /// The linear solver failed (a factorisation, GMRES, or the line search along its direction): another
    /// linear solver may succeed at the same time step. Otherwise Newton itself ran out of iterations,
    /// met a point outside its domain or the contact set did not settle: only a smaller step helps.
    linear: bool,
}

/// Converged steps in a row, without a retry, after which a reduced time step is doubled again: doubling
/// at once after a halved step made the crack onset of the 0.035 m/s CT fail every other attempt.
const GROW_AFTER: usize = 3;

/// Most SNES solves of one step attempt while the contact active set and the pin rotations settle.
const MAX_CONTACT_SOLVES: usize = 30;

/// Scale of constrained rows and of the Helmholtz rows (MPa): the largest P-wave modulus `K + 4G/3`.
fn row_scale(materials: &[Material]) -> f64 {
    materials
        .iter()
        .map(|m| {
            let e = m.elastic_moduli();
            e.bulk + 4.0 * e.shear / 3.0
        })
        .fold(0.0, f64::max)
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
    /// No material point carries mass.
    #[error("the model has no material points")]
    Empty,
    /// The run definition is inconsistent (e.g. a load off the grid lines, FEM with a non-linear
    /// interpolator).
    #[error("{0}")]
    Setup(String),
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
    /// Kinetic energy of the points at t = 0 (N mm; in 2D per mm thickness):
    /// `dissipated = W + E_0 - K - Psi`.
    #[serde(default)]
    pub initial_energy: f64,
}

/// The per-step scratch of the time step, reused from step to step: shape-function tables, grid fields,
/// the unknowns and their constraints, the assembler's buffers and the PETSc objects. Nothing in it
/// outlives a step's meaning: a workspace may be dropped and rebuilt between steps (a resumed run
/// starts with a fresh one) without changing the results.
#[derive(Default)]
pub struct Workspace<const D: usize = 2> {
    /// Shape functions of the points in the step's configuration.
    table: ShapeTable<D>,
    /// Shape functions of the rigid bodies' points (MPM mode; FEM mode uses the reference ones).
    rigid_tables: Vec<ShapeTable<D>>,
    /// Grid mass, velocity and acceleration from P2G.
    grid_state: GridState<D>,
    /// The unknowns and their constraints.
    dofs: DofMap,
    /// Per node copy, its partner in contact between bodies ([`INACTIVE`]: none; empty: one field).
    partners: Vec<u32>,
    assembler: Assembler<D>,
    /// PETSc objects reused while the pattern does not change.
    system: Option<LinearSystem>,
    /// PETSc log events `MPMSetup` (shape functions, P2G, pattern) and `MPMAssembly` (residuals and
    /// Jacobians), registered at the first step.
    events: Option<[LogEvent; 2]>,
    /// The processes' bands of cell rows (MPM on several processes), set at the first step.
    partition: Option<Partition>,
    /// This process's own points during a step: the first `own_points` of the state's points; the
    /// others are copies of other processes' points (ghosts), dropped at the end of the attempt.
    own_points: usize,
    /// Points migrated and ghosts received at the start of the step, summed over the processes.
    moved: [usize; 2],
}

impl<const D: usize> Workspace<D> {
    /// An empty workspace; its buffers grow at the first step.
    pub fn new() -> Self {
        Self::default()
    }
}

/// A running simulation: the model, its state and the workspace of its steps.
pub struct Simulation<const D: usize = 2> {
    /// What defines the run.
    pub model: Model<D>,
    /// The committed state.
    pub state: State<D>,
    workspace: Workspace<D>,
}

/// Per load, its active grid nodes and their shares of the resultant (summing to 1).
type LoadNodes = Vec<Vec<(usize, f64)>>;

/// What `Step::prepare` sets up for one step attempt, owned so that the later phases can borrow
/// the simulation freely.
struct StepPlan<const D: usize> {
    /// Time step of the attempt (s) and the time it reaches.
    dt: f64,
    t_new: f64,
    /// Prescribed increment per constraint set and component (mm), boxes first, then rigid bodies.
    set_du: Vec<[Option<f64>; D]>,
    /// The constrained unknowns of each set.
    sets: Vec<Vec<usize>>,
    /// Per rigid body: translation increment (mm), in-plane pin position (mm; `None` without a pin) and
    /// rotation increment about the pin (rad, in the x-y plane; settled with the contact active set).
    translations: Vec<SVector<f64, D>>,
    pins: Vec<Option<Vector2<f64>>>,
    dtheta: Vec<f64>,
    /// Per rigid body, its contact with the specimen (`None` without contact) and its face length (mm).
    devices: Vec<Option<DeviceContact>>,
    face_lengths: Vec<f64>,
    /// Contact between the specimen and bodies of other velocity fields.
    bodies: BodyContact<D>,
    /// Inertia and applied forces of the step, and the nodes of each load.
    loading: Loading<D>,
    load_nodes: LoadNodes,
    /// Whether the PETSc objects were built anew for this step.
    new_pattern: bool,
    /// Wall time of the preparation (s).
    setup_time: f64,
}

/// Inertia and applied forces of a step: what the assembler needs besides the points and the grid.
struct Loading<const D: usize> {
    /// Newmark parameters (`None`: quasi-static).
    newmark: Option<Newmark>,
    /// The body-force factor of a quasi-static ramp.
    load_factor: f64,
    /// Applied nodal forces at `t_n+1` (N, in 2D per mm thickness, one per grid node; empty without loads).
    nodal_force: Vec<SVector<f64, D>>,
}

/// What `Step::solve` hands to `Step::finish`.
struct Solved {
    /// SNES statistics over all solves of the step.
    info: SolveInfo,
    /// Physical residual `f_int + M a - f_ext` at the solution, per unknown (N; in 2D per mm thickness).
    phys: Vec<f64>,
    /// Wall time of the solves (s) and of the residual and Jacobian evaluations in them (s).
    solve_time: f64,
    assembly_time: f64,
    /// Residual and Jacobian evaluations.
    evaluations: [usize; 2],
    /// SNES solves of the step (more than one while a contact active set or a pin rotation settles).
    contact_solves: usize,
}

/// The nonlinear problem of one step, handed to SNES.
struct StepProblem<'a, 'b, const D: usize> {
    input: &'a StepInput<'b, D>,
    /// PETSc log event of the residual and Jacobian evaluations (shown by `-log_view`).
    event: LogEvent,
    assembler: &'a mut Assembler<D>,
    /// Wall time spent in residual and Jacobian evaluations (s).
    assembly_time: f64,
    /// Residual and Jacobian evaluations.
    residuals: usize,
    jacobians: usize,
    /// The contact devices of the step (closed nodes get constraint rows).
    contact: &'a [Option<DeviceContact>],
    /// Contact between bodies (closed pairs get constraint rows).
    bodies: &'a BodyContact<D>,
    /// Scale of the constraint rows (MPa).
    row_scale: f64,
    /// The block rows this process owns.
    owned: &'a OwnedRows,
    /// For the processes' agreement on domain errors.
    session: &'a SessionGuard,
    /// The residual of all unknowns (this process hands PETSc its own rows).
    scratch: Vec<f64>,
}

impl<const D: usize> NonlinearProblem for StepProblem<'_, '_, D> {
    fn residual(&mut self, x: &Vector, f: &mut Vector) -> Result<(), CallbackError> {
        let _event = self.event.begin();
        let t = Instant::now();
        let fatal = |e: petsc::PetscError| CallbackError::Fatal(e.to_string());
        let (asm, input, owned) = (&mut *self.assembler, self.input, self.owned);
        let (contact, s) = (self.contact, self.row_scale);
        let nf = input.dofs.unknowns_per_node();
        let r = &mut self.scratch;
        let xs = owned.gather(x).map_err(fatal)?;
        // Only this process's rows: the points in their support, the rows themselves.
        let local = asm.evaluate_owned(input, &xs).and_then(|()| {
            r.resize(xs.len(), 0.0);
            asm.residual_rows(input, &xs, r, false, owned.rows.clone())
        });
        let result = agree(self.session, local).and_then(|()| {
            for d in contact.iter().flatten() {
                d.residual_rows(&xs, r, nf, s);
            }
            self.bodies.residual_rows(&xs, r, nf, s);
            f.write(|out| out.copy_from_slice(&r[owned.scalars()]))
                .map_err(fatal)
        });
        self.assembly_time += t.elapsed().as_secs_f64();
        self.residuals += 1;
        result
    }

    fn jacobian(&mut self, x: &Vector, jac: &mut Matrix) -> Result<(), CallbackError> {
        let _event = self.event.begin();
        let t = Instant::now();
        let fatal = |e: petsc::PetscError| CallbackError::Fatal(e.to_string());
        let (asm, input, owned) = (&mut *self.assembler, self.input, self.owned);
        let xs = owned.gather(x).map_err(fatal)?;
        agree(self.session, asm.evaluate_owned(input, &xs))?;
        let (contact, bodies, s) = (self.contact, self.bodies, self.row_scale);
        let (pattern, own) = (owned.pattern(), owned.rows.clone());
        let r = jac
            .fill_block_rows(&pattern, |values, layout| {
                asm.jacobian_into(input, own.clone(), values, layout);
                let nf = input.dofs.unknowns_per_node();
                let row_of = |a: usize| {
                    let l = a.checked_sub(own.start).filter(|&l| l < own.len())?;
                    let (lo, hi) = (pattern.row_ptr[l], pattern.row_ptr[l + 1]);
                    let diag = pattern.cols[lo..hi]
                        .binary_search(&(a as u32))
                        .expect("diagonal block in the pattern");
                    Some((lo * nf * nf, hi - lo, diag))
                };
                for d in contact.iter().flatten() {
                    d.jacobian_rows(nf, s, row_of, values, |ncols, i, pos, k| {
                        layout.offset(ncols, nf, i, pos, k)
                    });
                }
                bodies.jacobian_rows(nf, s, row_of, values, |ncols, i, pos, k| {
                    layout.offset(ncols, nf, i, pos, k)
                });
            })
            .map_err(fatal);
        self.assembly_time += t.elapsed().as_secs_f64();
        self.jacobians += 1;
        r
    }
}

/// A domain error (an inverted point, a failed material update) on any process, reported on all: SNES
/// takes domain errors collectively, and with each process evaluating the points of its own rows only
/// one of them may meet it.
fn agree(session: &SessionGuard, local: Result<(), AssemblyError>) -> Result<(), CallbackError> {
    let any = session.any(local.is_err());
    match local {
        Err(e) => Err(CallbackError::Domain(e.to_string())),
        Ok(()) if any => Err(CallbackError::Domain(
            "a point of another process left its domain".into(),
        )),
        Ok(()) => Ok(()),
    }
}

/// A result of this process's points agreed on by every process before the next collective call: with
/// the points shared out (`shared`), a point's failure (it left the grid, its domain inverted) is met
/// only by the processes that hold it. The failing processes keep their error, the others return
/// [`StepError::OtherProcess`], so that all leave the step together.
fn agreed<T>(
    session: &SessionGuard,
    shared: bool,
    local: Result<T, StepError>,
) -> Result<T, StepError> {
    if !shared {
        return local;
    }
    let failed = session.any(local.is_err());
    match local {
        Ok(_) if failed => Err(StepError::OtherProcess),
        r => r,
    }
}

/// Completes a residual `r` over all unknowns that this process evaluated from its own points and
/// ghosts (`shared`): its own block rows `rows` are complete, the others partial; they are zeroed and
/// the vectors summed over the processes, so that every process holds every row (the same bits on
/// each). Without shared points every process evaluated every row: nothing to do.
fn complete_rows(
    session: &SessionGuard,
    shared: bool,
    rows: Range<usize>,
    nf: usize,
    r: &mut [f64],
) -> Result<(), StepError> {
    if !shared {
        return Ok(());
    }
    r[..rows.start * nf].fill(0.0);
    r[rows.end * nf..].fill(0.0);
    session.sum(r)?;
    Ok(())
}

/// The block rows (active nodes, in [`DofMap`] order) of the Jacobian and the unknowns this process
/// owns: a contiguous range ([`Step::own_rows`]). The process evaluates the points in their support
/// (its own and the ghosts of MPM on several processes, all points in FEM mode) at the gathered
/// unknowns and hands PETSc its own rows; PETSc's vectors, matrix and solvers are distributed.
struct OwnedRows {
    /// Owned block rows.
    rows: Range<usize>,
    /// Their pattern (row pointers from 0, global block columns).
    row_ptr: Vec<usize>,
    cols: Vec<u32>,
    /// Unknowns per node.
    nf: usize,
    /// More than one process: the gather of all unknowns for every evaluation (built once with the
    /// vector layout).
    gather: Option<GatherAll>,
}

impl OwnedRows {
    /// The block rows `rows` (from [`Step::own_rows`]) with their pattern.
    fn new<const D: usize>(asm: &Assembler<D>, rows: Range<usize>, nf: usize) -> Self {
        let (mut row_ptr, mut cols) = (Vec::new(), Vec::new());
        asm.block_rows_pattern(rows.clone(), &mut row_ptr, &mut cols);
        Self {
            rows,
            row_ptr,
            cols,
            nf,
            gather: None,
        }
    }

    /// The owned part of the pattern.
    fn pattern(&self) -> BlockCsr<'_> {
        BlockCsr {
            first: self.rows.start,
            bs: self.nf,
            row_ptr: &self.row_ptr,
            cols: &self.cols,
        }
    }

    /// The owned unknowns (indices into the vector of all unknowns).
    fn scalars(&self) -> Range<usize> {
        self.rows.start * self.nf..self.rows.end * self.nf
    }

    /// All unknowns of the distributed vector `x`, in [`DofMap`] order, on every process.
    fn gather(&self, x: &Vector) -> Result<Vec<f64>, petsc::PetscError> {
        match &self.gather {
            Some(g) => g.gather(x),
            None => x.read(|v| v.to_vec()),
        }
    }

    /// Writes this process's part of `all` (every unknown) into the distributed `x`.
    fn scatter(&self, all: &[f64], x: &mut Vector) -> Result<(), petsc::PetscError> {
        x.write(|v| v.copy_from_slice(&all[self.scalars()]))
    }
}

/// The PETSc objects of the implicit step: the unknowns, the Jacobian with its block pattern, and the
/// SNES (with its KSP and PC). They are kept from step to step while the active nodes and the pattern
/// stay the same (at 1 us steps particles rarely cross a cell boundary), so the matrix structure, the
/// symbolic factorisation of ILU/LU and the solver set-up are reused; a changed pattern rebuilds them.
struct LinearSystem {
    /// Options prefix of the SNES.
    prefix: Option<String>,
    /// Active grid nodes the objects were built for.
    active: Vec<u32>,
    /// The rows of this process, with the pattern the objects were built for.
    owned: OwnedRows,
    x: Vector,
    jac: Matrix,
    snes: Snes,
    /// The SNES tolerances from the options database, restored at the start of every step attempt (the
    /// contact re-solves of a step run with a raised absolute tolerance).
    tolerances: Tolerances,
    /// The lag of the preconditioner from the options database (`-snes_lag_preconditioner`).
    lag: PetscInt,
    /// Nonzero entries of the whole Jacobian (over all processes).
    nonzeros: usize,
}

impl LinearSystem {
    /// True if the objects fit the step's unknowns and the pattern of this process's rows (the other
    /// rows of a process holding part of the points are partial; every process decides on its own
    /// rows, and the objects are rebuilt if any process's no longer fit).
    fn fits<const D: usize>(
        &self,
        prefix: Option<&str>,
        dofs: &DofMap,
        asm: &Assembler<D>,
    ) -> bool {
        if self.prefix.as_deref() != prefix || self.active != dofs.active_nodes() {
            return false;
        }
        let (p, rows) = (asm.block_pattern(), self.owned.rows.clone());
        let base = p.row_ptr[rows.start];
        p.row_ptr[rows.start..=rows.end]
            .iter()
            .map(|r| r - base)
            .eq(self.owned.row_ptr.iter().copied())
            && p.cols[base..p.row_ptr[rows.end]] == self.owned.cols[..]
    }

    /// New objects for the step's pattern: vector, matrix (exact structure, the rigid-body near-null
    /// space of the displacement block for algebraic multigrid), SNES configured from the options
    /// database with the (u, eta_bar) index sets for `-pc_type fieldsplit`.
    fn new<const D: usize>(
        session: &SessionGuard,
        prefix: Option<&str>,
        grid: &Grid<D>,
        dofs: &DofMap,
        asm: &Assembler<D>,
        rows: Range<usize>,
    ) -> Result<Self, StepError> {
        let nf = dofs.unknowns_per_node();
        let mut owned = OwnedRows::new(asm, rows, nf);
        let mut nonzeros = [(owned.cols.len() * nf * nf) as f64];
        session.sum(&mut nonzeros)?;
        let n = owned.scalars().len();
        let x = Vector::new(session, n, nf)?;
        if session.size() > 1 {
            owned.gather = Some(GatherAll::new(&x)?);
        }
        let first = x.ownership_range()?.start;
        if first != owned.scalars().start {
            return Err(StepError::Setup(format!(
                "PETSc placed this process's unknowns at {first}, not at {}",
                owned.scalars().start
            )));
        }
        // AIJ with the block size set (inode kernels). `-mat_type baij` makes ILU, triangular solves and
        // products 1.4-1.8x faster at the paper's size, but its block ILU(0) (no pivot shift) failed in 3
        // of 1000 steps of the half-resolution CT at 4.3 m/s where point ILU(0) with a nonzero shift passes
        // (docs/benchmarks.md); GAMG and the field split need AIJ anyway.
        let mut jac = Matrix::new(session, n, nf)?;
        jac.set_block_pattern(&owned.pattern())?;
        // Near-null space of the displacement block (the D translations and the rotations: 3 modes in 2D,
        // 6 in 3D) for algebraic multigrid (-pc_type gamg / hypre); other preconditioners ignore it.
        let rotations = D * (D - 1) / 2;
        let mut modes = (0..D + rotations)
            .map(|_| Vector::new(session, n, nf))
            .collect::<Result<Vec<_>, _>>()?;
        for (k, mode) in modes.iter_mut().enumerate() {
            mode.write(|m| {
                m.fill(0.0);
                for (a, &node) in dofs.active_nodes()[owned.rows.clone()].iter().enumerate() {
                    let x = grid.node_position(node as usize);
                    let u = rigid_mode(k, &x);
                    m[a * nf..a * nf + D].copy_from_slice(u.as_slice());
                }
            })?;
        }
        jac.set_near_null_space(&mut modes)?;
        let mut snes = Snes::new(session, prefix)?;
        snes.set_from_options()?;
        if let Some(e) = dofs.layout().eta_bar() {
            // Field index sets for `-pc_type fieldsplit` (names: `-fieldsplit_u_*`, `-fieldsplit_eta_bar_*`).
            let (u, eb): (Vec<i32>, Vec<i32>) = (0..n)
                .map(|i| (first + i) as i32)
                .partition(|i| (*i as usize - first) % nf != e);
            let is_u = IndexSet::new(session, &u)?.with_block_size(dofs.layout().dim())?;
            let is_eb = IndexSet::new(session, &eb)?;
            snes.set_fieldsplit(&[("u", &is_u), ("eta_bar", &is_eb)])?;
        }
        let tolerances = snes.tolerances()?;
        let lag = snes.lag_preconditioner()?;
        Ok(Self {
            prefix: prefix.map(str::to_owned),
            active: dofs.active_nodes().to_vec(),
            owned,
            x,
            jac,
            snes,
            tolerances,
            lag,
            nonzeros: nonzeros[0] as usize,
        })
    }
}

/// Rigid-body mode `k` of the displacement at `x` (mm): the translations along the axes (`k < D`), then
/// the rotations (2D: about z; 3D: about x, y and z).
fn rigid_mode<const D: usize>(k: usize, x: &SVector<f64, D>) -> SVector<f64, D> {
    let mut u = SVector::zeros();
    if k < D {
        u[k] = 1.0;
        return u;
    }
    // Rotation in the plane of axes (i, j): u_i = -x_j, u_j = x_i.
    let (i, j) = match (D, k - D) {
        (2, _) => (0, 1),
        (_, 0) => (1, 2),
        (_, 1) => (2, 0),
        _ => (0, 1),
    };
    u[i] = -x[j];
    u[j] = x[i];
    u
}

impl<const D: usize> Simulation<D> {
    /// A simulation at t = 0 with virgin material history: `setup` split into [`Model`] and [`State`],
    /// with an empty [`Workspace`].
    pub fn new(setup: Setup<D>) -> Result<Self, StepError> {
        let (model, state) = split(setup)?;
        Ok(Self {
            model,
            state,
            workspace: Workspace::new(),
        })
    }

    /// Advances one step: [`advance`] on the simulation's parts.
    pub fn advance(&mut self, session: &SessionGuard) -> Result<StepReport, StepError> {
        advance(&self.model, &mut self.state, &mut self.workspace, session)
    }
}

/// Splits a scenario's `setup` into the model and the state at t = 0 (virgin material history), after
/// checking what the step relies on: material points exist, devices in contact have both motion
/// components prescribed, a unit normal and a friction coefficient >= 0, loads lie on grid lines, the FEM
/// mode uses the linear interpolator.
pub fn split<const D: usize>(setup: Setup<D>) -> Result<(Model<D>, State<D>), StepError> {
    let Setup {
        grid,
        mut particles,
        materials,
        fields,
        shape,
        time,
        body_force,
        body_force_ramp,
        boxes,
        rigid,
        rigid_points,
        loads,
        method,
        options_prefix,
        mass_tolerance,
        fallback_prefix,
    } = setup;
    if particles.is_empty() {
        return Err(StepError::Empty);
    }
    if rigid_points.len() != rigid.len() {
        return Err(StepError::Setup(format!(
            "{} rigid bodies but {} sets of rigid-body points",
            rigid.len(),
            rigid_points.len()
        )));
    }
    let fields = if fields.is_empty() {
        vec![0; materials.len()]
    } else {
        fields
    };
    if fields.len() != materials.len() {
        return Err(StepError::Setup(format!(
            "{} velocity fields for {} materials (one per body tag)",
            fields.len(),
            materials.len()
        )));
    }
    let nfields = fields.iter().map(|&f| f as usize + 1).max().unwrap_or(1);
    if nfields > 1 && (shape == ShapeKind::Cpdi2 || method == Method::Fem) {
        return Err(StepError::Setup(
            "contact between bodies (a body with its own velocity field) needs MPM with the linear, \
             GIMP, CPDI1 or B-spline interpolator (CPDI2 moves its corners on one field)"
                .into(),
        ));
    }
    if let Some(rb) = rigid.iter().find(|r| r.field as usize >= nfields) {
        return Err(StepError::Setup(format!(
            "rigid body `{}` acts on velocity field {}, but the bodies use {nfields}",
            rb.name, rb.field
        )));
    }
    let stride = materials.iter().map(|m| m.history_len()).max().unwrap_or(0);
    particles.resize_history(stride, 0.0);
    for p in 0..particles.len() {
        let m = &materials[particles.body[p] as usize];
        let h = particles.history_mut(p);
        m.init_history(&mut h[..m.history_len()]);
    }
    for rb in &rigid {
        if let Some(c) = &rb.contact {
            let prescribed = rb.motion.iter().all(|m| matches!(m, Motion::Velocity(_)));
            let unit = (c.normal.norm() - 1.0).abs() < 1e-12;
            if !(prescribed && unit && c.friction.is_finite() && c.friction >= 0.0) {
                return Err(StepError::Setup(format!(
                    "rigid body `{}`: a device in contact needs both motion components prescribed \
                     (\"fixed\" or a velocity), a unit normal and a friction coefficient >= 0",
                    rb.name
                )));
            }
        }
    }
    let load_shares = loads
        .iter()
        .map(|l| l.shares(&grid))
        .collect::<Result<Vec<_>, _>>()
        .map_err(StepError::Setup)?;
    let fem = match method {
        Method::Mpm => None,
        Method::Fem => {
            if shape != ShapeKind::Linear {
                return Err(StepError::Setup(format!(
                    "the FEM mode needs the linear (bilinear) interpolator, not `{}`",
                    shape.name()
                )));
            }
            // The reference configuration is the configuration at construction; the rigid bodies'
            // nodes are fixed there too.
            let mut points = ShapeTable::new();
            points.compute(ShapeKind::Linear, &grid, &particles)?;
            let rigid = rigid_points
                .iter()
                .map(|rp| {
                    let mut t = ShapeTable::new();
                    t.compute(ShapeKind::Linear, &grid, rp).map(|()| t)
                })
                .collect::<Result<Vec<_>, _>>()?;
            Some(FemReference { points, rigid })
        }
    };
    let nsets = boxes.len() + rigid.len() + loads.len();
    let mut state = State::new(particles, rigid_points, nsets, time.dt);
    if time.quasi_static {
        // Without inertia the points' velocities carry no energy (they are zeroed after the first step).
        state.initial_energy = 0.0;
    }
    let model = Model {
        grid,
        materials,
        fields,
        shape,
        time,
        body_force,
        body_force_ramp,
        boxes,
        rigid,
        loads,
        method,
        options_prefix,
        mass_tolerance,
        fallback_prefix,
        load_shares,
        fem,
    };
    Ok((model, state))
}

/// Advances `state` by one step of (at most) `state.dt` on `model`, with the scratch of `workspace`:
/// halving the step on failure down to `dt_min` (after a failure of the linear solver the fallback solver
/// is tried first at the same step); a reduced step is doubled again, up to the nominal `dt`, after
/// [`GROW_AFTER`] steps in a row converged at their first try. The first step of a dynamic run starts with the consistent initial
/// acceleration unless `initial_acceleration` is [`InitialAcceleration::Zero`] (computed into `state`
/// before the first attempt). A failed attempt leaves `state` as it was.
pub fn advance<const D: usize>(
    model: &Model<D>,
    state: &mut State<D>,
    workspace: &mut Workspace<D>,
    session: &SessionGuard,
) -> Result<StepReport, StepError> {
    Step {
        m: model,
        st: state,
        ws: workspace,
    }
    .advance(session)
}

/// One step in progress: the model, the state it advances and the workspace it uses.
struct Step<'a, const D: usize> {
    m: &'a Model<D>,
    st: &'a mut State<D>,
    ws: &'a mut Workspace<D>,
}

impl<const D: usize> Step<'_, D> {
    /// Advances one step of (at most) `self.st.dt` (the rules of [`advance`]). The first step of a
    /// dynamic run starts with the consistent initial acceleration unless `initial_acceleration` is
    /// [`InitialAcceleration::Zero`].
    pub fn advance(&mut self, session: &SessionGuard) -> Result<StepReport, StepError> {
        // Before the first step only: a resumed run continues with its checkpointed accelerations.
        let time = &self.m.time;
        if self.st.step == 0
            && !time.quasi_static
            && time.initial_acceleration == InitialAcceleration::Consistent
        {
            let r = self.initialize_acceleration(session);
            self.drop_ghosts();
            r?;
        }
        let started = Instant::now();
        let mut dt = self.st.dt;
        let mut attempts = 0;
        self.ws.moved = [0; 2];
        // The main solver first; after a linear-solver failure the fallback solver (if any) at the same
        // dt, then halving.
        let mut prefix = self.m.options_prefix.clone();
        loop {
            attempts += 1;
            let attempt = self.try_step(session, dt, prefix.as_deref());
            self.drop_ghosts();
            match attempt? {
                Ok(mut report) => {
                    report.attempts = attempts;
                    report.wall_total = started.elapsed().as_secs_f64();
                    // A reduced step is kept until GROW_AFTER steps in a row converged at the first try,
                    // then doubled (up to the nominal dt).
                    let st = &mut *self.st;
                    st.calm_steps = if attempts == 1 { st.calm_steps + 1 } else { 0 };
                    st.dt = dt;
                    if dt < self.m.time.dt && st.calm_steps >= GROW_AFTER {
                        st.dt = (dt * 2.0).min(self.m.time.dt);
                        st.calm_steps = 0;
                    }
                    return Ok(report);
                }
                Err(Failure { reason, linear }) => {
                    if let Some(fb) = &self.m.fallback_prefix
                        && linear
                        && prefix.as_deref() != Some(fb.as_str())
                    {
                        tracing::warn!(
                            "step {} at t = {:.6e} s: {reason}; retrying with the fallback solver (-{fb}*)",
                            self.st.step + 1,
                            self.st.time
                        );
                        prefix = Some(fb.clone());
                        continue;
                    }
                    let next = dt / 2.0;
                    if next < self.m.time.dt_min {
                        return Err(StepError::Diverged {
                            step: self.st.step + 1,
                            time: self.st.time,
                            dt,
                            dt_min: self.m.time.dt_min,
                            reason,
                        });
                    }
                    tracing::warn!(
                        "step {} at t = {:.6e} s: {reason}; retrying with dt = {next:.3e} s",
                        self.st.step + 1,
                        self.st.time
                    );
                    dt = next;
                }
            }
        }
    }

    /// One attempt: `Ok(Ok(report))` converged and committed, `Ok(Err(reason))` did not converge
    /// (nothing changed), `Err` a failure that a smaller step cannot fix. The attempt runs in three
    /// phases: `Step::prepare` (grid, unknowns, constraints, devices, loads, PETSc objects, first
    /// guess), `Step::solve` (SNES, repeated while the contact active set and the pin rotations
    /// settle) and `Step::finish` (reactions, accelerations, G2P, commit, report).
    fn try_step(
        &mut self,
        session: &SessionGuard,
        dt: f64,
        prefix: Option<&str>,
    ) -> Result<Result<StepReport, Failure>, StepError> {
        let t0 = Instant::now();
        let events = match self.ws.events {
            Some(e) => e,
            None => {
                let e = [
                    LogEvent::register(session, "MPMSetup")?,
                    LogEvent::register(session, "MPMAssembly")?,
                ];
                *self.ws.events.insert(e)
            }
        };
        let setup_guard = events[0].begin();
        let mut plan = self.prepare(session, dt, prefix)?;
        drop(setup_guard);
        plan.setup_time = t0.elapsed().as_secs_f64();
        let solved = match self.solve(session, &mut plan, events[1])? {
            Ok(solved) => solved,
            Err(failure) => return Ok(Err(failure)),
        };
        Ok(Ok(self.finish(session, plan, solved, t0)?))
    }

    /// The assembler's view of the step (borrows the simulation's parts field by field, so that the
    /// assembler and the PETSc objects stay free to be borrowed mutably beside it).
    fn step_input<'a>(
        model: &'a Model<D>,
        particles: &'a Particles<D>,
        table: &'a ShapeTable<D>,
        dofs: &'a DofMap,
        grid_state: &'a GridState<D>,
        loading: &'a Loading<D>,
        partners: &'a [u32],
    ) -> StepInput<'a, D> {
        StepInput {
            table,
            particles,
            materials: &model.materials,
            dofs,
            mass: &grid_state.mass,
            velocity: &grid_state.velocity,
            acceleration: &grid_state.acceleration,
            newmark: loading.newmark,
            body_force: model.body_force * loading.load_factor,
            nodal_force: &loading.nodal_force,
            row_scale: row_scale(&model.materials),
            partners,
        }
    }

    /// First phase of a step attempt: shape functions and P2G, the unknowns and their constraints, the
    /// contact devices and loads at `t_n+1`, the PETSc objects (kept if the pattern is unchanged) and the
    /// first guess of the solution.
    fn prepare(
        &mut self,
        session: &SessionGuard,
        dt: f64,
        prefix: Option<&str>,
    ) -> Result<StepPlan<D>, StepError> {
        if session.size() > 1 && self.m.num_fields() > 1 {
            return Err(StepError::Setup(
                "contact between bodies (a body with its own velocity field) runs on one process: \
                 its contact rows combine the rows of two node copies, which a process may not both own"
                    .into(),
            ));
        }
        self.project_to_grid(session)?;
        // Constraints: prescribed du per component and set (boxes first, then rigid bodies).
        let set_du =
            self.constraint_values(|v, rise| prescribed_increment(v, rise, self.st.time, dt));
        let sets = self.constrain(&set_du)?;
        // Contact devices: translation from the prescribed motion, rotation about the pin first guessed as
        // the last step's rate.
        let nb = self.m.boxes.len();
        let translations: Vec<SVector<f64, D>> = set_du[nb..]
            .iter()
            .map(|d| SVector::from_fn(|c, _| d[c].unwrap_or(0.0)))
            .collect();
        let pins: Vec<Option<Vector2<f64>>> =
            (0..self.m.rigid.len()).map(|k| self.pin_of(k)).collect();
        let dtheta: Vec<f64> = (0..self.m.rigid.len())
            .map(|k| match pins[k] {
                Some(_) => self.st.rotation_rates[k] * dt,
                None => 0.0,
            })
            .collect();
        let (devices, face_lengths) =
            self.contact_devices(session, &translations, &pins, &dtheta, dt)?;
        let bodies = self.body_pairs(&devices, dt)?;
        let t_new = self.st.time + dt;
        // Loads: the resultant at t_n+1 spread over the active nodes of each segment.
        let (nodal_force, load_nodes) = self.nodal_loads(t_new)?;
        let eta_bar = self.nodal_eta_bar(session)?;
        let s = self.m;
        let newmark = (!s.time.quasi_static).then_some(Newmark {
            beta: s.time.beta,
            gamma: s.time.gamma,
            dt,
        });
        let load_factor = if s.time.quasi_static && s.body_force_ramp > 0.0 {
            (t_new / s.body_force_ramp).min(1.0)
        } else {
            1.0
        };
        let plan = StepPlan {
            dt,
            t_new,
            set_du,
            sets,
            translations,
            pins,
            dtheta,
            devices,
            face_lengths,
            bodies,
            loading: Loading {
                newmark,
                load_factor,
                nodal_force,
            },
            load_nodes,
            new_pattern: false,
            setup_time: 0.0,
        };
        let input = Self::step_input(
            s,
            &self.st.particles,
            &self.ws.table,
            &self.ws.dofs,
            &self.ws.grid_state,
            &plan.loading,
            &self.ws.partners,
        );
        self.ws.assembler.begin_step(&input);
        // PETSc objects: kept from the last step if the unknowns and the pattern are unchanged (on every
        // process: with points shared out, each sees the pattern of its own points only).
        let fits = self
            .ws
            .system
            .as_ref()
            .is_some_and(|sys| sys.fits(prefix, &self.ws.dofs, &self.ws.assembler));
        let new_pattern = session.any(!fits);
        if new_pattern {
            self.ws.system = None; // free the old objects first
            let rows = self.own_rows(session);
            self.ws.system = Some(LinearSystem::new(
                session,
                prefix,
                &s.grid,
                &self.ws.dofs,
                &self.ws.assembler,
                rows,
            )?);
        }
        let LinearSystem {
            x,
            snes,
            tolerances,
            lag,
            owned,
            ..
        } = self.ws.system.as_mut().expect("linear system just built");
        // The first solve of an attempt runs with the configured tolerances and lag (the contact
        // re-solves of an earlier attempt may have changed both) and so starts with a fresh
        // preconditioner: PETSc rebuilds it at the first Newton iteration of every solve unless the lag
        // is -1 or persists (`-snes_lag_preconditioner_persists`, a user's choice, left alone).
        snes.set_tolerances(tolerances)?;
        if *lag > 1 {
            snes.set_lag_preconditioner(*lag)?;
        }
        // Initial guess: du = dt v_I + dt^2/2 a_I and the prescribed values for dynamics; zero everywhere
        // quasi-statically (the first Newton step is then the linear predictor that carries the prescribed
        // increments into the body); eta_bar from the particles (mass-weighted projection).
        let nf = self.ws.dofs.unknowns_per_node();
        let mut xs = vec![0.0; self.ws.dofs.len()];
        {
            for (a, &node) in self.ws.dofs.active_nodes().iter().enumerate() {
                let node = node as usize;
                let du = match newmark {
                    Some(_) => {
                        dt * self.ws.grid_state.velocity[node]
                            + 0.5 * dt * dt * self.ws.grid_state.acceleration[node]
                    }
                    None => SVector::zeros(),
                };
                xs[a * nf..a * nf + D].copy_from_slice(du.as_slice());
                if let Some(e) = self.ws.dofs.layout().eta_bar() {
                    xs[a * nf + e] = eta_bar[node];
                }
                for c in 0..nf {
                    if let (Some(v), Some(_)) = (self.ws.dofs.prescribed(a * nf + c), newmark) {
                        xs[a * nf + c] = v;
                    }
                }
            }
            for d in plan.devices.iter().flatten() {
                d.project_guess(&mut xs, nf);
            }
            let mass = &self.ws.grid_state.mass;
            plan.bodies.project_guess(&mut xs, nf, |node| mass[node]);
        }
        owned.scatter(&xs, x)?;
        Ok(StepPlan {
            new_pattern,
            ..plan
        })
    }

    /// Second phase: SNES from the prepared guess, repeated from the last solution while the contact
    /// active set and the rotation of pinned devices settle (`docs/theory.md`, "Contact with rigid
    /// devices"). `Ok(Err(reason))` if a solve fails (nothing committed).
    fn solve(
        &mut self,
        session: &SessionGuard,
        plan: &mut StepPlan<D>,
        assembly_event: LogEvent,
    ) -> Result<Result<Solved, Failure>, StepError> {
        let t1 = Instant::now();
        let step = self.st.step;
        let s = self.m;
        let shared = self.st.distributed;
        let particles = &self.st.particles;
        let Workspace {
            table,
            dofs,
            grid_state,
            assembler,
            system,
            partners,
            ..
        } = &mut *self.ws;
        let StepPlan {
            devices,
            bodies,
            dtheta,
            pins,
            translations,
            face_lengths,
            loading,
            ..
        } = plan;
        let input = Self::step_input(s, particles, table, dofs, grid_state, loading, partners);
        let grid = &s.grid;
        let nf = dofs.unknowns_per_node();
        let n = dofs.len();
        let LinearSystem {
            x,
            jac,
            snes,
            tolerances,
            lag,
            owned,
            ..
        } = system.as_mut().expect("prepared linear system");
        let h = grid.cell_size();
        let mut info_total: Option<SolveInfo> = None;
        let (mut assembly_time, mut evaluations) = (0.0, [0usize; 2]);
        let mut contact_iterations = 0;
        let mut seen: Vec<Vec<NodeStatus>> = Vec::new();
        let mut frozen = false;
        let mut secant: Vec<Option<(f64, f64)>> = vec![None; devices.len()];
        let mut phys = vec![0.0; n];
        // During the solves each process evaluates the points of its own rows; the physical residual
        // after each solve and the commit evaluate them all.
        assembler.restrict_to_rows(&input, owned.rows.clone());
        loop {
            contact_iterations += 1;
            let mut problem = StepProblem {
                input: &input,
                event: assembly_event,
                assembler: &mut *assembler,
                assembly_time: 0.0,
                residuals: 0,
                jacobians: 0,
                contact: devices.as_slice(),
                bodies,
                row_scale: input.row_scale,
                owned,
                session,
                scratch: Vec::new(),
            };
            let info = match snes.solve(&mut problem, x, jac) {
                Ok(info) => info,
                // A numerical failure inside PETSc (e.g. MUMPS failing on a nearly singular matrix) fails
                // this attempt like a diverged solve; the objects are rebuilt for the next attempt.
                Err(e) if e.is_numerical() => {
                    *system = None;
                    return Ok(Err(Failure {
                        reason: format!("SNES failed: {e}"),
                        linear: true,
                    }));
                }
                Err(e) => return Err(e.into()),
            };
            assembly_time += problem.assembly_time;
            evaluations[0] += problem.residuals;
            evaluations[1] += problem.jacobians;
            if !info.converged() {
                let why = info.domain_errors.last().cloned().unwrap_or_default();
                return Ok(Err(Failure {
                    reason: format!(
                        "SNES {} after {} iterations {why}",
                        info.reason_name, info.iterations
                    ),
                    linear: matches!(
                        info.reason_name.as_str(),
                        "DIVERGED_LINEAR_SOLVE" | "DIVERGED_LINE_SEARCH"
                    ),
                }));
            }
            let in_contact = devices.iter().any(Option::is_some) || !bodies.pairs.is_empty();
            if info_total.is_none() && in_contact {
                // Re-solves after a change of the contact active set are held to the step's own standard,
                // `|R| <= max(atol, rtol |R_0|)` with `R_0` the residual at the start of the first solve,
                // rather than to `rtol` times their own (often tiny) initial residual. Where the
                // preconditioner is lagged anyway (`lag > 1`, e.g. the multigrid of stiffness-dominated steps),
                // they keep the last one of the first solve (lag -1: never rebuilt; a lag that persists
                // through solves would carry its count into later steps): a changed active set changes a
                // few rows, which GMRES absorbs in a few iterations, far cheaper than a new set-up
                // (docs/theory.md, "Contact with rigid devices").
                let r0 = info.residual_norms.first().copied().unwrap_or(0.0);
                snes.set_tolerances(&Tolerances {
                    atol: tolerances.atol.max(tolerances.rtol * r0),
                    ..*tolerances
                })?;
                if *lag > 1 {
                    snes.set_lag_preconditioner(-1)?;
                }
            }
            info_total = Some(match info_total.take() {
                None => info,
                Some(mut t) => {
                    t.iterations += info.iterations;
                    t.linear_iterations += info.linear_iterations;
                    // The norms of all solves of the step in order: the first is the step's initial
                    // residual, the last its final one.
                    t.residual_norms.extend(info.residual_norms);
                    t
                }
            });
            if !in_contact {
                break;
            }
            // Physical residual: the force of the devices on the specimen at the contact nodes.
            let xs = owned.gather(x)?;
            let local = assembler
                .evaluate(&input, &xs)
                .and_then(|()| assembler.residual(&input, &xs, &mut phys, true));
            agreed(session, shared, local.map_err(StepError::from))?;
            complete_rows(session, shared, owned.rows.clone(), nf, &mut phys)?;
            let force_scale = devices
                .iter()
                .flatten()
                .flat_map(|d| d.nodes.iter())
                .filter(|c| c.status.closed())
                .map(|c| Vector2::new(phys[c.row * nf], phys[c.row * nf + 1]).norm())
                .fold(bodies.force_scale(&phys, nf), f64::max);
            let (force_tol, gap_tol) = (1e-6 * force_scale.max(1e-300), 1e-6 * h);
            let mut changes = 0;
            if !frozen {
                for d in devices.iter_mut().flatten() {
                    changes += d.update(&xs, &phys, nf, force_tol, gap_tol);
                }
                changes += bodies.update(&xs, &phys, nf, force_tol, gap_tol);
                let statuses: Vec<NodeStatus> = devices
                    .iter()
                    .flatten()
                    .flat_map(|d| d.nodes.iter().map(|c| c.status))
                    .chain(bodies.pairs.iter().map(|c| match c.closed {
                        true => NodeStatus::Slide,
                        false => NodeStatus::Open,
                    }))
                    .collect();
                if changes > 0 && seen.contains(&statuses) {
                    // A cycle of sets: keep the current one (only the pin rotations may still change).
                    // Logged at debug level: with pins and steel inserts it happens in a quarter of the
                    // steps (nodes at the edge of a face flipping on round-off), and the summary counts
                    // the contact solves.
                    tracing::debug!(
                        "step {}: the contact active set cycles; kept after {contact_iterations} solves",
                        step + 1
                    );
                    frozen = true;
                }
                seen.push(statuses);
            }
            // Pinned devices: the moment of the contact forces about the pin must vanish (secant in dtheta).
            let mut moments_ok = true;
            for (k, d) in devices.iter_mut().enumerate() {
                let (Some(d), Some(pin)) = (d.as_mut(), pins[k]) else {
                    continue;
                };
                let (f, m) = d.resultant(&phys, nf, |i| xy(&grid.node_position(i)), pin);
                // Balanced to 1e-5 of the force times the face length (the resultant within 1e-5 of the
                // face length from the pin), the force taken at least as `1e-4 s h` (a strain of 1e-4
                // over one cell): a device that barely touches (a support the wave has not reached, a
                // plate the arm flies away from) has a moment of round-off, discontinuous in `dtheta`
                // as nodes open and close, which the secant would chase until the step fails.
                let tol = 1e-5 * f.norm().max(1e-4 * input.row_scale * h) * face_lengths[k] + 1e-12;
                if m.abs() <= tol || d.nodes.iter().all(|c| !c.status.closed()) {
                    continue;
                }
                moments_ok = false;
                let th = dtheta[k];
                let next = match secant[k] {
                    Some((th0, m0)) if m != m0 => th - m * (th - th0) / (m - m0),
                    _ => th + (0.1 * th.abs()).max(1e-9),
                };
                secant[k] = Some((th, m));
                dtheta[k] = next;
                let r = contact::rotation(next) - nalgebra::Matrix2::identity();
                let du_t = xy(&translations[k]);
                for c in &mut d.nodes {
                    c.du_device = du_t + r * (xy(&grid.node_position(c.node)) - pin);
                }
            }
            if (changes == 0 || frozen) && moments_ok {
                break;
            }
            if contact_iterations >= MAX_CONTACT_SOLVES {
                return Ok(Err(Failure {
                    reason: format!(
                        "contact not settled after {contact_iterations} solves ({changes} status \
                         changes, moment balance {})",
                        if moments_ok { "met" } else { "not met" }
                    ),
                    linear: false,
                }));
            }
            let mut xs = owned.gather(x)?;
            for d in devices.iter().flatten() {
                d.project_guess(&mut xs, nf);
            }
            bodies.project_guess(&mut xs, nf, |node| grid_state.mass[node]);
            owned.scatter(&xs, x)?;
        }

        let info = info_total.expect("at least one solve");
        let solve_time = t1.elapsed().as_secs_f64();
        // Converged: the physical residual (device forces, reactions) at the solution; the assembler keeps
        // the nodal increments of this evaluation for `finish`.
        let xs = owned.gather(x)?;
        let local = assembler
            .evaluate(&input, &xs)
            .and_then(|()| assembler.residual(&input, &xs, &mut phys, true));
        agreed(session, shared, local.map_err(StepError::from))?;
        complete_rows(session, shared, owned.rows.clone(), nf, &mut phys)?;
        Ok(Ok(Solved {
            info,
            phys,
            solve_time,
            assembly_time,
            evaluations,
            contact_solves: contact_iterations,
        }))
    }

    /// Third phase: reactions and device forces, the new nodal accelerations, the work of the
    /// constraints, G2P and the commit of the material state, the motion of the rigid bodies; the report.
    fn finish(
        &mut self,
        session: &SessionGuard,
        plan: StepPlan<D>,
        solved: Solved,
        t0: Instant,
    ) -> Result<StepReport, StepError> {
        let StepPlan {
            dt,
            t_new,
            set_du,
            sets,
            pins,
            dtheta,
            devices,
            bodies,
            load_nodes,
            loading:
                Loading {
                    newmark,
                    load_factor,
                    ..
                },
            new_pattern,
            setup_time,
            ..
        } = plan;
        let Solved {
            info,
            phys,
            solve_time,
            assembly_time,
            evaluations,
            contact_solves,
        } = solved;
        let nf = self.ws.dofs.unknowns_per_node();
        let n = self.ws.dofs.len();
        let s = self.m;
        let grid = &s.grid;
        let mut reactions: Vec<[f64; D]> = sets
            .iter()
            .map(|dofs| {
                let mut r = [0.0; D];
                for &d in dofs {
                    r[d % nf] += phys[d];
                }
                r
            })
            .collect();
        for (k, d) in devices.iter().enumerate() {
            if let Some(d) = d {
                let pin = pins[k].unwrap_or_else(Vector2::zeros);
                let (f, _) = d.resultant(&phys, nf, |i| xy(&grid.node_position(i)), pin);
                let r = &mut reactions[s.boxes.len() + k];
                r[0] = f.x;
                r[1] = f.y;
            }
        }
        let nodes = s.field_nodes();
        let du_nodes = self.ws.assembler.nodal_du().to_vec();
        let mut acc_nodes = vec![SVector::<f64, D>::zeros(); nodes];
        if let Some(nm) = newmark {
            for &node in self.ws.dofs.active_nodes() {
                let node = node as usize;
                acc_nodes[node] = nm.acceleration(
                    du_nodes[node],
                    self.ws.grid_state.velocity[node],
                    self.ws.grid_state.acceleration[node],
                );
            }
            // Closed contact nodes leave the step with the device's velocity in the constrained
            // directions (a perfectly inelastic impact at the node, as in the grid contact of Bardenhagen
            // et al.). The trapezoidal rule alone would give `v_n+1 = 2 du/dt - v_n`: a node arriving at
            // the relative speed w would bounce off at -w, and the chatter of the face nodes against a
            // moving device pumped energy into the specimen (kinetic energy twice the device's work).
            // The device's reaction includes the impulse of that correction, m (a - a_Newmark), which
            // the following step's Newmark acceleration cancels again, so that the trapezoidal impulse
            // and work of the reaction stay the block's change of momentum and the device's work.
            let first = s.boxes.len();
            for (k, d) in devices.iter().enumerate() {
                let Some(d) = d else { continue };
                let (n, t) = (from_xy::<D>(d.normal), from_xy::<D>(d.tangent()));
                for c in d.nodes.iter().filter(|c| c.status.closed()) {
                    let (v, a) = (
                        self.ws.grid_state.velocity[c.node],
                        self.ws.grid_state.acceleration[c.node],
                    );
                    let target = from_xy::<D>(c.du_device) / dt;
                    // The acceleration that makes v_n + dt ((1 - gamma) a_n + gamma a) equal the target.
                    let fit = |e: SVector<f64, D>| {
                        (e.dot(&target) - e.dot(&v) - dt * (1.0 - nm.gamma) * e.dot(&a))
                            / (nm.gamma * dt)
                    };
                    let acc = &mut acc_nodes[c.node];
                    let before = *acc;
                    *acc += (fit(n) - n.dot(acc)) * n;
                    if c.status == NodeStatus::Stick {
                        *acc += (fit(t) - t.dot(acc)) * t;
                    }
                    let f = self.ws.grid_state.mass[c.node] * (*acc - before);
                    for (r, f) in reactions[first + k].iter_mut().zip(f.iter()) {
                        *r += f;
                    }
                }
            }
            // Closed pairs between bodies leave the step with one normal velocity, the mass-weighted mean
            // of the two copies' (the same perfectly inelastic impact); the two corrections are equal
            // and opposite impulses, so the momentum of the pair is kept.
            let gs = &self.ws.grid_state;
            for c in bodies.pairs.iter().filter(|c| c.closed) {
                let n = c.normal;
                let normal_velocity = |node: usize, acc: &SVector<f64, D>| {
                    n.dot(
                        &(gs.velocity[node]
                            + dt * ((1.0 - nm.gamma) * gs.acceleration[node] + nm.gamma * acc)),
                    )
                };
                let (va, vb) = (
                    normal_velocity(c.node_a, &acc_nodes[c.node_a]),
                    normal_velocity(c.node_b, &acc_nodes[c.node_b]),
                );
                let (ma, mb) = (gs.mass[c.node_a], gs.mass[c.node_b]);
                let common = (ma * va + mb * vb) / (ma + mb);
                acc_nodes[c.node_a] += n * ((common - va) / (nm.gamma * dt));
                acc_nodes[c.node_b] += n * ((common - vb) / (nm.gamma * dt));
            }
        }
        // Work of the constraints (trapezoidal in the set's reaction; every node of a set moves by the same
        // prescribed du) and of the body force (b . du weighted by nodal mass).
        let mut work = 0.0;
        let bf = s.body_force * load_factor;
        for &node in self.ws.dofs.active_nodes() {
            let node = node as usize;
            work += self.ws.grid_state.mass[node] * bf.dot(&du_nodes[node]);
        }
        let gamma = if newmark.is_some() { s.time.gamma } else { 0.0 };
        let sol = StepSolution {
            du: &du_nodes,
            acceleration: &acc_nodes,
            gamma,
            dt,
        };
        let mut displacements: Vec<[f64; D]> =
            set_du.iter().map(|d| d.map(|v| v.unwrap_or(0.0))).collect();
        for (load, nodes) in s.loads.iter().zip(&load_nodes) {
            // A load reports its resultant and the share-weighted mean displacement of its nodes.
            let f = load.force * load.factor(t_new);
            let du: SVector<f64, D> = nodes.iter().map(|&(n, w)| w * du_nodes[n]).sum();
            reactions.push(std::array::from_fn(|c| f[c]));
            displacements.push(std::array::from_fn(|c| du[c]));
        }
        for (k, (r, du)) in reactions.iter().zip(&displacements).enumerate() {
            for c in 0..D {
                work += 0.5 * (r[c] + self.st.last_reactions[k][c]) * du[c];
            }
        }
        let s = self.m;
        // The energies of this process's own points (the ghosts are other processes').
        let counted = self.own_point_count();
        let ps = &mut self.st.particles;
        // Eroded points (material `erosion_damage`) move with the grid but keep their deformation
        // gradient, volume and domain: a void does not deform, so it never inverts.
        let frozen: Vec<_> = (0..ps.len())
            .filter(|&p| s.materials[ps.body[p] as usize].is_eroded(ps.damage[p]))
            .map(|p| {
                (
                    p,
                    ps.x[p],
                    ps.f[p],
                    ps.r[p],
                    ps.vol[p],
                    ps.corners(p).to_vec(),
                )
            })
            .collect();
        let g2p = transfer::grid_to_particles(&self.ws.table, &s.grid, &sol, ps);
        agreed(session, self.st.distributed, g2p.map_err(StepError::from))?;
        for (p, x, f, r, vol, corners) in frozen {
            let shift = ps.x[p] - x;
            ps.f[p] = f;
            ps.r[p] = r;
            ps.vol[p] = vol;
            for (c, c0) in ps.corners_mut(p).iter_mut().zip(corners) {
                *c = c0 + shift;
            }
        }
        if s.fem.is_some() {
            let (mut v, a) = (self.ws.grid_state.velocity.clone(), acc_nodes.clone());
            if let Some(nm) = newmark {
                for &node in self.ws.dofs.active_nodes() {
                    let node = node as usize;
                    v[node] += nm.dt
                        * ((1.0 - nm.gamma) * self.ws.grid_state.acceleration[node]
                            + nm.gamma * a[node]);
                }
            } else {
                v.iter_mut().for_each(|v| *v = SVector::zeros());
            }
            self.st.fem_nodal = Some((v, a));
        }
        if s.time.quasi_static {
            ps.v.iter_mut().for_each(|v| *v = SVector::zeros());
            ps.a.iter_mut().for_each(|a| *a = SVector::zeros());
        }
        let stored = self.ws.assembler.commit(ps, &s.materials, counted);
        for (k, (rb, du)) in self
            .st
            .rigid
            .iter_mut()
            .zip(&displacements[s.boxes.len()..])
            .enumerate()
        {
            // x' = x + du + (R(dtheta) - I) (x - pin): translation with the pin, rotation about it (about
            // the pin's axis, z, in 3D).
            let dx = SVector::<f64, D>::from_fn(|c, _| du[c]);
            let pin = from_xy::<D>(pins[k].unwrap_or_else(Vector2::zeros));
            let r = rotation_xy::<D>(dtheta[k]) - SMatrix::<f64, D, D>::identity();
            let moved = |x: &mut SVector<f64, D>| *x += dx + r * (*x - pin);
            rb.x.iter_mut().for_each(moved);
            rb.corners.iter_mut().for_each(moved);
            self.st.rotations[k] += dtheta[k];
            self.st.rotation_rates[k] = dtheta[k] / dt;
            if let Some(d) = &devices[k] {
                self.st.contact_statuses[k] = d.nodes.iter().map(|c| (c.node, c.status)).collect();
            }
        }
        self.st.closed_pairs = bodies
            .pairs
            .iter()
            .filter(|c| c.closed)
            .map(|c| c.node_b)
            .collect();
        self.st.closed_pairs.sort_unstable();
        for (acc, du) in self.st.accumulated.iter_mut().zip(&displacements) {
            for c in 0..D {
                acc[c] += du[c];
            }
        }
        self.st.last_reactions = reactions.clone();
        self.st.external_work += work;
        self.st.time = t_new;
        self.st.step += 1;
        // Kinetic energy: of the points in MPM (the grid is discarded); of the lumped nodal masses in FEM
        // mode, the energy the Newmark scheme conserves there.
        let kinetic = match &self.st.fem_nodal {
            Some((v, _)) => self
                .ws
                .dofs
                .active_nodes()
                .iter()
                .map(|&n| 0.5 * self.ws.grid_state.mass[n as usize] * v[n as usize].norm_squared())
                .sum(),
            None => {
                let ps = &self.st.particles;
                (0..counted)
                    .map(|p| 0.5 * ps.mass[p] * ps.v[p].norm_squared())
                    .sum()
            }
        };
        let mut energies = [kinetic, stored];
        if self.st.distributed {
            session.sum(&mut energies)?;
        }
        let [kinetic, stored] = energies;
        let names = s.set_names();

        Ok(StepReport {
            step: self.st.step,
            time: self.st.time,
            dt,
            attempts: 1,
            solve: info,
            unknowns: n,
            nonzeros: self
                .ws
                .system
                .as_ref()
                .map_or_else(|| self.ws.assembler.nonzeros(), |sys| sys.nonzeros),
            reactions: names
                .iter()
                .cloned()
                .zip(reactions.iter().map(|r| r.to_vec()))
                .collect(),
            displacements: names
                .into_iter()
                .zip(self.st.accumulated.iter().map(|d| d.to_vec()))
                .collect(),
            kinetic_energy: kinetic,
            stored_energy: stored,
            external_work: self.st.external_work,
            initial_energy: self.st.initial_energy,
            wall_setup: setup_time,
            wall_solve: solve_time,
            wall_assembly: assembly_time,
            evaluations,
            wall_total: t0.elapsed().as_secs_f64(),
            new_pattern,
            rotations: s
                .rigid
                .iter()
                .enumerate()
                .filter(|(_, r)| r.contact.as_ref().is_some_and(|c| c.pin.is_some()))
                .map(|(k, r)| (r.name.clone(), self.st.rotations[k]))
                .collect(),
            contact_solves,
            migrated: self.ws.moved[0],
            ghosts: self.ws.moved[1],
        })
    }

    /// MPM on several processes: the points shared out (at the first step: each process keeps those of
    /// its band; later: the points that left a band migrate), then the ghosts appended.
    fn share_points(&mut self, session: &SessionGuard) -> Result<(), StepError> {
        let st = &mut *self.st;
        if self.ws.partition.is_none() {
            let p = Partition::balanced(session, &self.m.grid, &st.particles, !st.distributed)
                .map_err(StepError::Setup)?;
            self.ws.partition = Some(p);
        }
        let part = self.ws.partition.as_ref().expect("set above");
        let migrated = if st.distributed {
            partition::migrate(session, part, &mut st.particles)?
        } else {
            partition::keep_own(part, &mut st.particles);
            st.distributed = true;
            0
        };
        self.ws.own_points = st.particles.len();
        let ghosts = partition::add_ghosts(session, part, &mut st.particles)?;
        let mut moved = [migrated as f64, ghosts as f64];
        session.sum(&mut moved)?;
        // Points that migrated in any attempt of the step; the ghosts of the last attempt.
        self.ws.moved = [self.ws.moved[0] + moved[0] as usize, moved[1] as usize];
        Ok(())
    }

    /// This process's own points: the first of the state's (all of them unless shared out).
    fn own_point_count(&self) -> usize {
        if self.st.distributed {
            self.ws.own_points
        } else {
            self.st.particles.len()
        }
    }

    /// Drops the ghosts of the step (the state keeps this process's own points only).
    fn drop_ghosts(&mut self) {
        if self.st.distributed {
            self.st.particles.truncate(self.ws.own_points);
        }
    }

    /// The block rows this process owns: with the points shared out, the active nodes of its node
    /// rows ([`Partition::owned_nodes`]); otherwise an equal share of the active nodes.
    fn own_rows(&self, session: &SessionGuard) -> Range<usize> {
        let active = self.ws.dofs.active_nodes();
        match (&self.ws.partition, self.st.distributed) {
            (Some(part), true) => {
                let nodes = part.owned_nodes();
                let first = |n: usize| active.partition_point(|&a| (a as usize) < n);
                first(nodes.start)..first(nodes.end)
            }
            _ => {
                let (rank, size, n) = (session.rank(), session.size(), active.len());
                n * rank / size..n * (rank + 1) / size
            }
        }
    }

    /// Shape functions on the committed configuration, P2G (in FEM mode the carried nodal velocity and
    /// acceleration replace the projected ones) and the numbering of the unknowns, nothing constrained
    /// yet. MPM on several processes shares the points out first; P2G sums the own points' nodal values
    /// over the processes, so every process holds the whole grid state.
    fn project_to_grid(&mut self, session: &SessionGuard) -> Result<(), StepError> {
        let s = self.m;
        if session.size() > 1 && s.fem.is_none() {
            self.share_points(session)?;
        }
        let ps = &self.st.particles;
        let counted = self.own_point_count();
        let shared = self.st.distributed;
        let local = match &s.fem {
            None => self.ws.table.compute(s.shape, &s.grid, ps),
            Some(fem) => self.ws.table.push_forward(&fem.points, &ps.f),
        }
        .map_err(|e| StepError::from(e.renumbered(&ps.id)))
        .and_then(|()| match (&self.ws.partition, shared) {
            (Some(part), true) => part
                .check_reach(&self.ws.table, ps, counted)
                .map_err(StepError::Setup),
            _ => Ok(()),
        });
        agreed(session, shared, local)?;
        let fields = s.num_fields();
        if fields > 1 {
            let (nodes, body) = (s.grid.num_nodes(), &ps.body);
            self.ws
                .table
                .offset_fields(nodes, fields, |p| s.fields[body[p] as usize] as usize);
        }
        transfer::particles_to_grid_shared(
            &self.ws.table,
            ps,
            counted,
            &s.grid,
            s.mass_tolerance,
            &mut self.ws.grid_state,
            |sums| match shared {
                true => session.sum(sums).map_err(|e| e.to_string()),
                false => Ok(()),
            },
        )?;
        if let Some((v, a)) = &self.st.fem_nodal {
            // FEM: the nodal state carries over (the same nodes are active in every step).
            self.ws.grid_state.velocity.copy_from_slice(v);
            self.ws.grid_state.acceleration.copy_from_slice(a);
        }
        let layout = s.layout();
        self.ws.dofs.rebuild(&self.ws.grid_state.active, layout);
        Ok(())
    }

    /// Per constraint set (boxes first, then rigid bodies) and component: `value(v, rise_time)` for a
    /// component moving with velocity `v`, `None` for a free one.
    fn constraint_values(&self, value: impl Fn(f64, f64) -> f64) -> Vec<[Option<f64>; D]> {
        let s = self.m;
        s.boxes
            .iter()
            .map(|b| (b.motion, b.rise_time))
            .chain(s.rigid.iter().map(|r| (r.motion, r.rise_time)))
            .map(|(motion, rise)| {
                motion.map(|m| match m {
                    Motion::Free => None,
                    Motion::Velocity(v) => Some(value(v, rise)),
                })
            })
            .collect()
    }

    /// Prescribes `values` (one per set, as from `Step::constraint_values`) on the active nodes of
    /// every constraint set; returns each set's constrained unknowns.
    fn constrain(&mut self, values: &[[Option<f64>; D]]) -> Result<Vec<Vec<usize>>, StepError> {
        let s = self.m;
        let grid = &s.grid;
        let nf = self.ws.dofs.unknowns_per_node();
        let mut sets: Vec<Vec<usize>> = Vec::new();
        for (b, du) in s.boxes.iter().zip(values) {
            let mut dofs_of_set = Vec::new();
            // A box holds every body's copy of its nodes.
            for node in 0..s.field_nodes() {
                let x = grid.node_position(node);
                let inside = (0..D).all(|k| x[k] >= b.min[k] - 1e-9 && x[k] <= b.max[k] + 1e-9);
                if let (true, Some(a)) = (inside, self.ws.dofs.active_index(node)) {
                    for (c, d) in du.iter().enumerate() {
                        if let Some(d) = d {
                            self.ws.dofs.constrain(node, c, *d);
                            dofs_of_set.push(a * nf + c);
                        }
                    }
                }
            }
            sets.push(dofs_of_set);
        }
        let nrigid = s.rigid.len();
        self.ws.rigid_tables.resize_with(nrigid, ShapeTable::new);
        for (k, (rb, du)) in s.rigid.iter().zip(&values[s.boxes.len()..]).enumerate() {
            if rb.contact.is_some() {
                // In contact: constrained by the active set of the step, not here.
                sets.push(Vec::new());
                continue;
            }
            // Glued: the nodes under the body's points (of the reference configuration in FEM mode).
            let points = &self.st.rigid[k];
            let rt = match &s.fem {
                Some(fem) => &fem.rigid[k],
                None => {
                    self.ws.rigid_tables[k].compute(s.shape, grid, points)?;
                    &self.ws.rigid_tables[k]
                }
            };
            let mut dofs_of_set = Vec::new();
            // The copies of the nodes in the velocity field the body holds.
            let shift = rb.field as usize * grid.num_nodes();
            for p in 0..points.len() {
                for w in rt.weights(p) {
                    if w.value <= 0.0 {
                        continue;
                    }
                    let node = w.node as usize + shift;
                    if let Some(a) = self.ws.dofs.active_index(node) {
                        for (c, d) in du.iter().enumerate() {
                            if let Some(d) = d {
                                self.ws.dofs.constrain(node, c, *d);
                                dofs_of_set.push(a * nf + c);
                            }
                        }
                    }
                }
            }
            dofs_of_set.sort_unstable();
            dofs_of_set.dedup();
            sets.push(dofs_of_set);
        }
        Ok(sets)
    }

    /// Current pin (mm) of rigid body `k`: its pin at t = 0 moved with the accumulated translation;
    /// `None` without a pin.
    fn pin_of(&self, k: usize) -> Option<Vector2<f64>> {
        let s = self.m;
        let pin = s.rigid[k].contact.as_ref()?.pin?;
        let acc = self.st.accumulated[s.boxes.len() + k];
        Some(pin + Vector2::new(acc[0], acc[1]))
    }

    /// The contact devices of a step (`None` for glued rigid bodies) and the length of each device's
    /// face (mm): the contact nodes (active, unconstrained grid nodes of the node layer nearest to the
    /// face and within its extent) with their gaps at the start of the step, their first status (that of
    /// the last step, or closed if the node touches) and the device increment at the node for the
    /// translation `translations[k]` (mm) and the rotation `dtheta[k]` (rad) about `pins[k]` in a step of
    /// `dt` (s).
    fn contact_devices(
        &self,
        session: &SessionGuard,
        translations: &[SVector<f64, D>],
        pins: &[Option<Vector2<f64>>],
        dtheta: &[f64],
        dt: f64,
    ) -> Result<(Vec<Option<DeviceContact>>, Vec<f64>), StepError> {
        let s = self.m;
        let grid = &s.grid;
        let h = grid.cell_size();
        let nf = self.ws.dofs.unknowns_per_node();
        let mut devices = Vec::with_capacity(s.rigid.len());
        let mut lengths = Vec::with_capacity(s.rigid.len());
        let mut index = vec![usize::MAX; s.field_nodes()];
        for (k, rb) in s.rigid.iter().enumerate() {
            let Some(c) = &rb.contact else {
                devices.push(None);
                lengths.push(0.0);
                continue;
            };
            let n = contact::rotation(self.st.rotations[k]) * c.normal;
            let t = Vector2::new(-n.y, n.x);
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for x in self.st.rigid[k].corners.iter().map(xy) {
                for (j, v) in [n.dot(&x), t.dot(&x)].into_iter().enumerate() {
                    lo[j] = lo[j].min(v);
                    hi[j] = hi[j].max(v);
                }
            }
            // Face plane n . x = c_f; depth of the device along n.
            let (cf, depth) = (hi[0], hi[0] - lo[0]);
            let r = contact::rotation(dtheta[k]) - nalgebra::Matrix2::identity();
            let translation = xy(&translations[k]);
            let device_du = |x: Vector2<f64>| match pins[k] {
                Some(pin) => translation + r * (x - pin),
                None => translation,
            };
            let warm = &self.st.contact_statuses[k];
            let mut nodes = Vec::new();
            for (a, &node) in self.ws.dofs.active_nodes().iter().enumerate() {
                let node = node as usize;
                let x = xy(&grid.node_position(node));
                let tx = t.dot(&x);
                if node / grid.num_nodes() != rb.field as usize
                    || (n.dot(&x) - cf).abs() > 0.5 * h + 1e-9
                    || tx < lo[1] - 1e-9
                    || tx > hi[1] + 1e-9
                    || (0..D).any(|c| self.ws.dofs.is_constrained(a * nf + c))
                {
                    continue;
                }
                index[node] = nodes.len();
                nodes.push(ContactNode {
                    node,
                    row: a,
                    gap: f64::INFINITY,
                    du_device: device_du(x),
                    status: NodeStatus::Open,
                });
            }
            // Gap: from the face to the nearest corner of the specimen points (in front of the device's
            // back face) interpolating to the node.
            let p = &self.st.particles;
            for q in 0..p.len() {
                if n.dot(&xy(&p.x[q])) < cf - depth {
                    continue;
                }
                let near = p
                    .corners(q)
                    .iter()
                    .map(|c| n.dot(&xy(c)))
                    .fold(f64::INFINITY, f64::min);
                for w in self.ws.table.weights(q) {
                    let i = index[w.node as usize];
                    if w.value > 1e-12 && i != usize::MAX {
                        nodes[i].gap = nodes[i].gap.min(near - cf);
                    }
                }
            }
            // The nearest corner over every process's points.
            if self.st.distributed {
                let mut gaps: Vec<f64> = nodes.iter().map(|c| c.gap).collect();
                session.min(&mut gaps)?;
                for (c, g) in nodes.iter_mut().zip(gaps) {
                    c.gap = g;
                }
            }
            // An overlap found at the start of a step is held, not pushed back: a negative gap in the
            // constraint would move the node out by |g| within one step, work that no reaction force
            // accounts for (it made the kinetic and stored energy exceed the device's work in the CT).
            for c in &mut nodes {
                c.gap = c.gap.max(0.0);
            }
            let mut device = DeviceContact {
                normal: n,
                friction: c.friction,
                nodes,
            };
            let closed = device.closed_status();
            for c in &mut device.nodes {
                index[c.node] = usize::MAX;
                // A node that closes with friction slips if its predicted motion slides along the device
                // (sticking it would reverse its tangential velocity in the trapezoidal rule).
                let (v, a) = (
                    self.ws.grid_state.velocity[c.node],
                    self.ws.grid_state.acceleration[c.node],
                );
                let slide = t.dot(&(xy(&(dt * v + 0.5 * dt * dt * a)) - c.du_device));
                let fresh = if closed == NodeStatus::Stick && slide.abs() > 1e-9 * h {
                    NodeStatus::Slip(if slide > 0.0 { 1 } else { -1 })
                } else {
                    closed
                };
                c.status = match warm.iter().find(|(node, _)| *node == c.node) {
                    Some(&(_, status)) => status,
                    None if c.gap <= 1e-9 * h => fresh,
                    None => NodeStatus::Open,
                };
                if device.friction == 0.0 && c.status.closed() {
                    c.status = NodeStatus::Slide;
                }
            }
            devices.push(Some(device));
            lengths.push(hi[1] - lo[1]);
        }
        Ok((devices, lengths))
    }

    /// The contact pairs between the specimen (field 0) and the bodies of other velocity fields at the
    /// start of the step (`docs/theory.md`, "Contact between bodies"), and the partner of every node copy
    /// in `Workspace::partners` (for the pattern). A pair is a grid node whose copies in field 0 and in
    /// one other field are both active and free (no constraint, not a device's contact node). Its
    /// normal points from the specimen into the other body along the difference of the fields' nodal
    /// mass gradients `sum_p m_p grad S_Ip` (which point out of a body:
    /// the specimen's minus the other's); its gap is the distance along the normal from the farthest
    /// corner of the specimen's points to the nearest corner of the other body's points that
    /// interpolate to the node (held at 0 when they overlap, as for the devices). A pair starts closed
    /// if the predicted increments `dt v_I + dt^2/2 a_I` of its copies overlap, or if it touches and
    /// was closed at the end of the last step.
    fn body_pairs(
        &mut self,
        devices: &[Option<DeviceContact>],
        dt: f64,
    ) -> Result<BodyContact<D>, StepError> {
        let s = self.m;
        let fields = s.num_fields();
        self.ws.partners.clear();
        if fields == 1 {
            return Ok(BodyContact::default());
        }
        let grid = &s.grid;
        let (nodes, all, h) = (grid.num_nodes(), s.field_nodes(), grid.cell_size());
        let (p, table, dofs) = (&self.st.particles, &self.ws.table, &self.ws.dofs);
        let nf = dofs.unknowns_per_node();
        let mut grad_m = vec![SVector::<f64, D>::zeros(); all];
        for q in 0..p.len() {
            for w in table.weights(q) {
                grad_m[w.node as usize] += p.mass[q] * w.grad;
            }
        }
        // Copies held by a device stay with it.
        let mut taken = vec![false; all];
        for c in devices.iter().flatten().flat_map(|d| &d.nodes) {
            taken[c.node] = true;
        }
        let free = |node: usize| {
            dofs.active_index(node)
                .filter(|&a| !taken[node] && (0..D).all(|c| !dofs.is_constrained(a * nf + c)))
        };
        let mut pairs = Vec::new();
        let mut pair_of = vec![usize::MAX; all];
        for i in 0..nodes {
            if dofs.active_index(i).is_none() {
                continue;
            }
            let mut others = (1..fields)
                .map(|f| i + f * nodes)
                .filter(|&b| dofs.active_index(b).is_some());
            let Some(b) = others.next() else { continue };
            if others.next().is_some() {
                let x = grid.node_position(i);
                let at: Vec<String> = x.iter().map(|c| format!("{c:.3}")).collect();
                return Err(StepError::Setup(format!(
                    "the grid node at ({}) mm carries the specimen and two other bodies: contact is \
                     between the specimen and one body per node; keep the other bodies at least two \
                     cells apart",
                    at.join(", ")
                )));
            }
            let (Some(row_a), Some(row_b)) = (free(i), free(b)) else {
                continue;
            };
            // `sum_p m_p grad S_Ip` points out of a body at its boundary nodes.
            let g = grad_m[i] - grad_m[b];
            if g.norm() == 0.0 {
                continue;
            }
            pair_of[i] = pairs.len();
            pair_of[b] = pairs.len();
            pairs.push(NodePair {
                node_a: i,
                node_b: b,
                row_a,
                row_b,
                normal: g / g.norm(),
                gap: 0.0,
                closed: false,
            });
        }
        let mut far_a = vec![f64::NEG_INFINITY; pairs.len()];
        let mut near_b = vec![f64::INFINITY; pairs.len()];
        for q in 0..p.len() {
            for w in table.weights(q) {
                let k = pair_of[w.node as usize];
                if w.value <= 1e-12 || k == usize::MAX {
                    continue;
                }
                let n = pairs[k].normal;
                let along = p.corners(q).iter().map(|c| n.dot(c));
                if w.node as usize == pairs[k].node_a {
                    far_a[k] = along.fold(far_a[k], f64::max);
                } else {
                    near_b[k] = along.fold(near_b[k], f64::min);
                }
            }
        }
        self.ws.partners.resize(all, INACTIVE);
        let gs = &self.ws.grid_state;
        let predicted =
            |node: usize| dt * gs.velocity[node] + 0.5 * dt * dt * gs.acceleration[node];
        for (k, c) in pairs.iter_mut().enumerate() {
            c.gap = (near_b[k] - far_a[k]).max(0.0);
            let overlap = c.gap + c.normal.dot(&(predicted(c.node_b) - predicted(c.node_a)));
            let was_closed = self.st.closed_pairs.binary_search(&c.node_b).is_ok();
            c.closed = overlap < -1e-9 * h || (c.gap <= 1e-9 * h && was_closed);
            self.ws.partners[c.node_a] = c.node_b as u32;
            self.ws.partners[c.node_b] = c.node_a as u32;
        }
        Ok(BodyContact { pairs })
    }

    /// The loads at time `t` on the active nodes: the nodal forces (one per grid node; empty without
    /// loads) and, per load, its nodes with their shares renormalised to 1.
    fn nodal_loads(&self, t: f64) -> Result<(Vec<SVector<f64, D>>, LoadNodes), StepError> {
        let s = self.m;
        let mut nodal_force = Vec::new();
        let mut load_nodes = Vec::with_capacity(s.loads.len());
        for (load, shares) in s.loads.iter().zip(&self.m.load_shares) {
            let active: Vec<(usize, f64)> = shares
                .iter()
                .copied()
                .filter(|&(node, _)| self.ws.grid_state.active[node])
                .collect();
            let total: f64 = active.iter().map(|(_, w)| w).sum();
            if total <= 0.0 {
                return Err(StepError::Setup(format!(
                    "load `{}`: no node of its segment carries mass (is the segment on the body's \
                     boundary?)",
                    load.name
                )));
            }
            if nodal_force.is_empty() {
                nodal_force = vec![SVector::zeros(); s.grid.num_nodes()];
            }
            let f = load.force * load.factor(t);
            let active: Vec<(usize, f64)> =
                active.into_iter().map(|(n, w)| (n, w / total)).collect();
            for &(node, w) in &active {
                nodal_force[node] += w * f;
            }
            load_nodes.push(active);
        }
        Ok((nodal_force, load_nodes))
    }

    /// The points' `eta_bar` projected to the active nodes (mass-weighted), one per grid node; empty for
    /// a run without gradient enhancement.
    fn nodal_eta_bar(&self, session: &SessionGuard) -> Result<Vec<f64>, StepError> {
        if self.ws.dofs.layout().eta_bar().is_none() {
            return Ok(Vec::new());
        }
        let p = &self.st.particles;
        let mut eb = vec![0.0; self.ws.grid_state.mass.len()];
        for q in 0..self.own_point_count() {
            for w in self.ws.table.weights(q) {
                eb[w.node as usize] += w.value * p.mass[q] * p.eta_bar[q];
            }
        }
        if self.st.distributed {
            session.sum(&mut eb)?;
        }
        for &node in self.ws.dofs.active_nodes() {
            eb[node as usize] /= self.ws.grid_state.mass[node as usize];
        }
        Ok(eb)
    }

    /// The consistent initial acceleration of a dynamic run (`docs/theory.md`, "Initial acceleration"):
    /// on the grid at t = 0, `m_I a_I = f_ext,I - f_int,I` with the lumped mass, `f_ext` the body force
    /// and the loads at t = 0 and `f_int` the internal force of the points' state (the residual of a
    /// quasi-static step at `du = 0`); constrained components take the acceleration of their prescribed
    /// motion ([`prescribed_acceleration`]). Carried to the points with the G2P interpolation,
    /// `a_p = sum_I S_Ip a_I`; in FEM mode it is also the carried nodal acceleration. The result depends
    /// only on the state at t = 0, not on the points' previous `a_p`.
    fn initialize_acceleration(&mut self, session: &SessionGuard) -> Result<(), StepError> {
        self.project_to_grid(session)?;
        let t = self.st.time;
        let prescribed = self.constraint_values(|v, rise| prescribed_acceleration(v, rise, t));
        let sets = self.constrain(&prescribed)?;
        let (nodal_force, _) = self.nodal_loads(t)?;
        let eta_bar = self.nodal_eta_bar(session)?;
        let nf = self.ws.dofs.unknowns_per_node();
        let s = self.m;
        // No inertia and the full body force at t = 0.
        let loading = Loading {
            newmark: None,
            load_factor: 1.0,
            nodal_force,
        };
        let input = Self::step_input(
            s,
            &self.st.particles,
            &self.ws.table,
            &self.ws.dofs,
            &self.ws.grid_state,
            &loading,
            &[],
        );
        self.ws.assembler.begin_step(&input);
        let mut x = vec![0.0; self.ws.dofs.len()];
        if let Some(e) = self.ws.dofs.layout().eta_bar() {
            for (a, &node) in self.ws.dofs.active_nodes().iter().enumerate() {
                x[a * nf + e] = eta_bar[node as usize];
            }
        }
        // R = f_int - f_ext at du = 0 (no inertia), unbalanced forces in the constrained rows too.
        let mut r = vec![0.0; x.len()];
        let local = self
            .ws
            .assembler
            .evaluate(&input, &x)
            .and_then(|()| self.ws.assembler.residual(&input, &x, &mut r, true));
        agreed(session, self.st.distributed, local.map_err(StepError::from))?;
        let rows = self.own_rows(session);
        complete_rows(session, self.st.distributed, rows, nf, &mut r)?;
        let mut acc = vec![SVector::<f64, D>::zeros(); s.field_nodes()];
        for (a, &node) in self.ws.dofs.active_nodes().iter().enumerate() {
            let node = node as usize;
            let m = self.ws.grid_state.mass[node];
            acc[node] = SVector::from_fn(|c, _| {
                let d = a * nf + c;
                self.ws.dofs.prescribed(d).unwrap_or(-r[d] / m)
            });
        }
        // Devices in contact: a touching node whose free acceleration would carry it into the device takes
        // the device's normal acceleration (node by node: the lumped mass decouples them; friction is not
        // applied at t = 0).
        let nb = s.boxes.len();
        let device_acc: Vec<SVector<f64, D>> = prescribed[nb..]
            .iter()
            .map(|d| SVector::from_fn(|c, _| d[c].unwrap_or(0.0)))
            .collect();
        let pins: Vec<Option<Vector2<f64>>> = (0..s.rigid.len()).map(|k| self.pin_of(k)).collect();
        let (devices, _) =
            self.contact_devices(session, &device_acc, &pins, &vec![0.0; s.rigid.len()], 0.0)?;
        let mut contact_forces = vec![SVector::<f64, D>::zeros(); devices.len()];
        for (k, d) in devices.iter().enumerate() {
            let Some(d) = d else { continue };
            let n = from_xy::<D>(d.normal);
            for c in d.nodes.iter().filter(|c| c.status.closed()) {
                let push = n.dot(&(from_xy::<D>(c.du_device) - acc[c.node]));
                if push > 0.0 {
                    acc[c.node] += push * n;
                    let b = c.row * nf;
                    let m = self.ws.grid_state.mass[c.node];
                    contact_forces[k] +=
                        SVector::<f64, D>::from_column_slice(&r[b..b + D]) + m * acc[c.node];
                }
            }
        }
        // The reactions at t = 0, where the trapezoidal work of the first step starts: the unbalanced force
        // with the initial inertia in each constrained set, the applied resultant of each load.
        for (reaction, dofs) in self.st.last_reactions.iter_mut().zip(&sets) {
            *reaction = [0.0; D];
            for &d in dofs {
                let (node, c) = (self.ws.dofs.node(d / nf), d % nf);
                reaction[c] += r[d] + self.ws.grid_state.mass[node] * acc[node][c];
            }
        }
        for (k, f) in contact_forces.iter().enumerate() {
            if devices[k].is_some() {
                self.st.last_reactions[nb + k] = std::array::from_fn(|c| f[c]);
            }
        }
        for (reaction, load) in self.st.last_reactions[sets.len()..]
            .iter_mut()
            .zip(&s.loads)
        {
            let f = load.force * load.factor(t);
            *reaction = std::array::from_fn(|c| f[c]);
        }
        let table = &self.ws.table;
        for (p, ap) in self.st.particles.a.iter_mut().enumerate() {
            *ap = transfer::interpolate(table.weights(p), |i| acc[i]);
        }
        if self.m.fem.is_some() {
            self.st.fem_nodal = Some((self.ws.grid_state.velocity.clone(), acc));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pushed_forward_gradients_reproduce_the_deformed_configuration() {
        // FEM mode: with nodes at x_I = F X_I, sum_I x_I (x) grad_{X_n} S_Ip = I.
        let grid = Grid::new(Vector2::zeros(), 1.0, [4, 4]).unwrap();
        let mut p = Particles::new();
        let (r1, r2) = (Vector2::new(0.25, 0.0), Vector2::new(0.0, 0.25));
        for x in [Vector2::new(1.3, 2.2), Vector2::new(0.4, 0.7)] {
            p.push(x, 0.25, 0.25, nalgebra::Matrix2::from_columns(&[r1, r2]), 0);
        }
        let mut reference = ShapeTable::new();
        reference.compute(ShapeKind::Linear, &grid, &p).unwrap();
        let f = nalgebra::Matrix2::new(1.2, 0.3, -0.1, 0.9);
        let mut table = ShapeTable::new();
        table.push_forward(&reference, &[f, f]).unwrap();
        for q in 0..2 {
            let mut m = nalgebra::Matrix2::zeros();
            let mut sum = 0.0;
            for (w, w0) in table.weights(q).iter().zip(reference.weights(q)) {
                assert_eq!(w.value, w0.value);
                m += (f * grid.node_position(w.node as usize)) * w.grad.transpose();
                sum += w.value;
            }
            assert!((m - nalgebra::Matrix2::identity()).norm() < 1e-13, "{m}");
            assert!((sum - 1.0).abs() < 1e-14);
        }
        let inverted = nalgebra::Matrix2::new(-1.0, 0.0, 0.0, 1.0);
        assert!(matches!(
            table.push_forward(&reference, &[f, inverted]),
            Err(ShapeError::InvertedElement { particle: 1, .. })
        ));
    }
}
