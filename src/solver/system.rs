//! The linear system of a step on PETSc: the unknowns' vector, the Jacobian with its block pattern and the
//! SNES ([`LinearSystem`]), the block rows this process owns ([`OwnedRows`]) and the rigid-body modes for
//! algebraic multigrid.

use super::report::StepError;
use crate::assembly::Assembler;
use crate::dofs::DofMap;
use crate::grid::Grid;
use crate::multigrid::Hierarchy;
use crate::petsc::{
    self, BlockCsr, GatherRange, IndexSet, Matrix, PetscInt, SessionGuard, Snes, ThreadedOperator,
    Tolerances, Vector,
};
use nalgebra::SVector;
use std::ops::Range;

/// The block rows (active nodes, in [`DofMap`] order) of the Jacobian and the unknowns this process owns: a
/// contiguous range (`Step::own_rows`). The process evaluates the points in their
/// support (its own and the ghosts of MPM on several processes, all points in FEM mode) at the gathered
/// unknowns and hands PETSc its own rows; PETSc's vectors, matrix and solvers are distributed.
pub(super) struct OwnedRows {
    /// Owned block rows.
    pub(super) rows: Range<usize>,
    /// Their pattern (row pointers from 0, global block columns).
    pub(super) row_ptr: Vec<usize>,
    pub(super) cols: Vec<u32>,
    /// Unknowns per node.
    pub(super) nf: usize,
    /// All unknowns of the step (over all processes).
    pub(super) total: usize,
    /// More than one process: the gather of the unknowns this process reads at an evaluation
    /// (`processes::unknowns_window`), rebuilt when the window moves
    /// ([`OwnedRows::set_window`]).
    pub(super) window: Option<GatherRange>,
}

impl OwnedRows {
    /// The block rows `rows` (from `Step::own_rows`) with their pattern, of `total`
    /// unknowns.
    pub(super) fn new<const D: usize>(
        asm: &Assembler<D>,
        rows: Range<usize>,
        nf: usize,
        total: usize,
    ) -> Self {
        let (mut row_ptr, mut cols) = (Vec::new(), Vec::new());
        asm.block_rows_pattern(rows.clone(), &mut row_ptr, &mut cols);
        Self {
            rows,
            row_ptr,
            cols,
            nf,
            total,
            window: None,
        }
    }

    /// The owned part of the pattern.
    pub(super) fn pattern(&self) -> BlockCsr<'_> {
        BlockCsr {
            first: self.rows.start,
            bs: self.nf,
            row_ptr: &self.row_ptr,
            cols: &self.cols,
        }
    }

    /// The owned unknowns (indices into the vector of all unknowns).
    pub(super) fn scalars(&self) -> Range<usize> {
        self.rows.start * self.nf..self.rows.end * self.nf
    }

    /// The unknowns of the distributed vector `x` that this process reads at an evaluation, in a vector
    /// of all unknowns in [`DofMap`] order: those of its window ([`OwnedRows::set_window`]), zeros
    /// elsewhere; all of them on one process (no window).
    pub(super) fn gather(&self, x: &Vector) -> Result<Vec<f64>, petsc::PetscError> {
        match &self.window {
            Some(w) => {
                let mut all = vec![0.0; self.total];
                w.gather_into(x, &mut all)?;
                Ok(all)
            }
            None => x.read(|v| v.to_vec()),
        }
    }

    /// The unknowns of the solution `x` that this process reads after a solve: those of its window
    /// ([`OwnedRows::gather`]) and the unknowns `read` (the same list on every process: the constrained
    /// and contact rows, whose statuses every process evaluates), each from its owner through one sum
    /// over the processes (the others adding zeros: the same bits on every process). Zeros elsewhere.
    /// Collective on several processes.
    pub(super) fn gather_solution(
        &self,
        session: &SessionGuard,
        x: &Vector,
        read: &[usize],
    ) -> Result<Vec<f64>, petsc::PetscError> {
        let mut all = self.gather(x)?;
        if self.window.is_none() {
            return Ok(all);
        }
        let own = self.scalars();
        let mut values = x.read(|mine| {
            read.iter()
                .map(|&d| match own.contains(&d) {
                    true => mine[d - own.start],
                    false => 0.0,
                })
                .collect::<Vec<f64>>()
        })?;
        session.sum(&mut values)?;
        for (&d, v) in read.iter().zip(values) {
            all[d] = v;
        }
        Ok(all)
    }

    /// On more than one process: the gather of the unknowns `window()` (indices in [`DofMap`] order,
    /// from `processes::unknowns_window`, read only there) for the evaluations of the step, built anew
    /// if any process's window moved (collective).
    pub(super) fn set_window(
        &mut self,
        session: &SessionGuard,
        x: &Vector,
        window: impl FnOnce() -> Range<usize>,
    ) -> Result<(), petsc::PetscError> {
        if session.size() == 1 {
            return Ok(());
        }
        let window = window();
        let same = self.window.as_ref().is_some_and(|w| w.range() == window);
        if session.any(!same) {
            self.window = None; // free the old scatter first
            self.window = Some(GatherRange::new(session, x, window)?);
        }
        Ok(())
    }

    /// Writes this process's part of `all` (every unknown) into the distributed `x`.
    pub(super) fn scatter(&self, all: &[f64], x: &mut Vector) -> Result<(), petsc::PetscError> {
        x.write(|v| v.copy_from_slice(&all[self.scalars()]))
    }
}

/// The PETSc objects of the implicit step: the unknowns, the Jacobian with its block pattern, and the
/// SNES (with its KSP and PC). They are kept from step to step while the active nodes and the pattern
/// stay the same (at 1 us steps particles rarely cross a cell boundary), so the matrix structure, the
/// symbolic factorisation of ILU/LU and the solver set-up are reused; a changed pattern rebuilds them.
pub(super) struct LinearSystem {
    /// Options prefix of the SNES.
    pub(super) prefix: Option<String>,
    /// Active grid nodes the objects were built for.
    pub(super) active: Vec<u32>,
    /// The rows of this process, with the pattern the objects were built for.
    pub(super) owned: OwnedRows,
    pub(super) x: Vector,
    pub(super) jac: Matrix,
    pub(super) snes: Snes,
    /// The SNES tolerances from the options database, restored at the start of every step attempt (the
    /// contact re-solves of a step run with a raised absolute tolerance).
    pub(super) tolerances: Tolerances,
    /// The lag of the preconditioner from the options database (`-snes_lag_preconditioner`).
    pub(super) lag: PetscInt,
    /// Nonzero entries of the whole Jacobian (over all processes).
    pub(super) nonzeros: usize,
    /// With the geometric multigrid (`-pc_type mg`): the constrained unknowns its interpolation was
    /// built for.
    pub(super) multigrid: Option<Vec<bool>>,
}

impl LinearSystem {
    /// True if the objects fit the step's unknowns and the pattern of this process's rows (the other
    /// rows of a process holding part of the points are partial; every process decides on its own
    /// rows, and the objects are rebuilt if any process's no longer fit).
    pub(super) fn fits<const D: usize>(
        &self,
        prefix: Option<&str>,
        dofs: &DofMap,
        asm: &Assembler<D>,
    ) -> bool {
        if self.prefix.as_deref() != prefix || self.active != dofs.active_nodes() {
            return false;
        }
        if self.multigrid.as_ref().is_some_and(|c| {
            c.iter()
                .enumerate()
                .any(|(i, &c)| c != dofs.is_constrained(i))
        }) {
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
    pub(super) fn new<const D: usize>(
        session: &SessionGuard,
        prefix: Option<&str>,
        grid: &Grid<D>,
        dofs: &DofMap,
        asm: &Assembler<D>,
        rows: Range<usize>,
    ) -> Result<Self, StepError> {
        let nf = dofs.unknowns_per_node();
        let owned = OwnedRows::new(asm, rows, nf, dofs.len());
        let mut nonzeros = [(owned.cols.len() * nf * nf) as f64];
        session.sum(&mut nonzeros)?;
        let n = owned.scalars().len();
        let x = Vector::new(session, n, nf)?;
        let first = x.ownership_range()?.start;
        if first != owned.scalars().start {
            return Err(StepError::Setup(format!(
                "PETSc placed this process's unknowns at {first}, not at {}",
                owned.scalars().start
            )));
        }
        let mut snes = Snes::new(session, prefix)?;
        snes.set_from_options()?;
        // The storage that suits the preconditioner (`-mat_type` overrides it).
        let pc = snes.pc_type()?;
        let sub_pc =
            petsc::option_string(session, &format!("{}sub_pc_type", prefix.unwrap_or("")))?;
        let kind = petsc::matrix_type_for(pc.as_deref(), sub_pc.as_deref());
        let mut jac = Matrix::with_type(session, n, nf, kind)?;
        jac.set_block_pattern(&owned.pattern())?;
        // The Krylov solver's products by the solver's kernel, on all threads (PETSc's own run on one
        // core, and 2.25x slower there); on several processes over each process's diagonal part. The
        // multigrid's levels, residuals and Galerkin products work on the assembled Jacobian.
        if flag(session, "mpm_threaded_operator")? {
            if let Some(op) = ThreadedOperator::over(&jac, &owned.pattern())? {
                snes.set_operator(op);
            }
        }
        // ILU(0) on all threads (`ilu::SchwarzIlu`, one overlapping subdomain per thread) in place of
        // PETSc's one-core ILU(0) of the whole matrix (`ilu`, or block Jacobi or additive Schwarz with
        // one block per process). Declined by `petsc::use_threaded_ilu` for the matrices of several
        // processes and for one thread: there the same ILU(0) takes the place of PETSc's inside each
        // process's subdomain of block Jacobi or additive Schwarz, about twice as fast per core.
        let ilu_options = match (pc.as_deref(), sub_pc.as_deref()) {
            (Some("bjacobi" | "asm"), None | Some("ilu")) => Some("sub_"),
            (Some("ilu"), _) => Some(""),
            _ => None,
        };
        if let Some(sub) = ilu_options
            && plain_ilu(session, prefix, sub)?
            && flag(session, "mpm_threaded_ilu")?
            && !petsc::use_threaded_ilu(&snes, &jac, &owned.pattern())?
            && sub == "sub_"
        {
            snes.use_threaded_ilu_on_subdomains(nf);
        }
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
        if let Some(e) = dofs.layout().eta_bar() {
            // Field index sets for `-pc_type fieldsplit` (names: `-fieldsplit_u_*`, `-fieldsplit_eta_bar_*`).
            let (u, eb): (Vec<i32>, Vec<i32>) = (0..n)
                .map(|i| (first + i) as i32)
                .partition(|i| (*i as usize - first) % nf != e);
            let is_u = IndexSet::new(session, &u)?.with_block_size(dofs.layout().dim())?;
            let is_eb = IndexSet::new(session, &eb)?;
            snes.set_fieldsplit(&[("u", &is_u), ("eta_bar", &is_eb)])?;
        }
        let multigrid = if snes.pc_type()?.as_deref() == Some("mg") {
            let levels = mg_levels(session, prefix)?;
            let hierarchy = Hierarchy::build(grid, dofs, levels);
            snes.set_multigrid(&interpolations(session, &hierarchy, owned.rows.clone())?)?;
            // Each level's symmetric SOR on all threads in place of PETSc's one-core sweep.
            if flag(session, "mpm_threaded_sor")? {
                snes.use_threaded_sor_on_levels();
            }
            Some(constrained(dofs))
        } else {
            None
        };
        newton_options(&mut snes, session, prefix)?;
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
            multigrid,
        })
    }
}

/// The solver's own Newton options: the first iteration's linear tolerance, `-[PREFIX]mpm_first_ksp_rtol`
/// (unset or 0: `-ksp_rtol` at every iteration), and the relative residual below which an iteration keeps
/// the last Jacobian, `-[PREFIX]mpm_keep_jacobian_below` (unset or 0: a Jacobian at every iteration).
fn newton_options(
    snes: &mut Snes,
    session: &SessionGuard,
    prefix: Option<&str>,
) -> Result<(), StepError> {
    snes.set_first_linear_rtol(fraction(
        session,
        prefix,
        "mpm_first_ksp_rtol",
        "a relative tolerance",
    )?);
    snes.set_keep_jacobian_below(fraction(
        session,
        prefix,
        "mpm_keep_jacobian_below",
        "a relative residual norm",
    )?);
    Ok(())
}

/// The option `-[PREFIX]NAME R` with `0 <= R < 1` (`what` in its error): `None` where it is unset or 0.
fn fraction(
    session: &SessionGuard,
    prefix: Option<&str>,
    name: &str,
    what: &str,
) -> Result<Option<f64>, StepError> {
    let name = format!("{}{name}", prefix.unwrap_or(""));
    let Some(v) = petsc::option_string(session, &name)? else {
        return Ok(None);
    };
    match v.parse::<f64>() {
        Ok(r) if (0.0..1.0).contains(&r) => Ok((r > 0.0).then_some(r)),
        _ => Err(StepError::Setup(format!(
            "-{name} {v}: allowed is {what} from 0 (off) to below 1"
        ))),
    }
}

/// A switch of the options database (`-NAME`): on unless it says 0, false or no. `mpm_threaded_operator`:
/// the Krylov solver multiplies by the Jacobian on all threads (`petsc::ThreadedOperator`);
/// `mpm_threaded_ilu`: ILU(0) factored and applied on all threads (`petsc::use_threaded_ilu`);
/// `mpm_threaded_sor`: the multigrid's symmetric SOR swept on all threads (`crate::sor`).
fn flag(session: &SessionGuard, name: &str) -> Result<bool, StepError> {
    Ok(match petsc::option_string(session, name)?.as_deref() {
        None | Some("" | "1" | "true" | "yes") => true,
        Some("0" | "false" | "no") => false,
        Some(v) => {
            return Err(StepError::Setup(format!(
                "-{name} {v}: allowed are true, false, 1, 0, yes, no"
            )));
        }
    })
}

/// True if the ILU(0) preconditioner (options `-{sub}pc_factor_*`: `sub_` under block Jacobi and
/// additive Schwarz) asks for nothing the threaded ILU(0) does not do: one block per process (no
/// `-pc_bjacobi_blocks`, `-pc_asm_blocks`, `-pc_asm_local_blocks`), no fill levels
/// (`-{sub}pc_factor_levels` 0), the natural ordering.
fn plain_ilu(session: &SessionGuard, prefix: Option<&str>, sub: &str) -> Result<bool, StepError> {
    let p = prefix.unwrap_or("");
    let opt = |name: &str| petsc::option_string(session, &format!("{p}{name}"));
    Ok(opt("pc_bjacobi_blocks")?.is_none()
        && opt("pc_asm_blocks")?.is_none()
        && opt("pc_asm_local_blocks")?.is_none()
        && matches!(
            opt(&format!("{sub}pc_factor_levels"))?.as_deref(),
            None | Some("0")
        )
        && matches!(
            opt(&format!("{sub}pc_factor_mat_ordering_type"))?.as_deref(),
            None | Some("natural")
        ))
}

/// The number of multigrid levels the options database asks for (`-pc_mg_levels` with the SNES prefix),
/// or `None` for as many as [`Hierarchy::build`] makes.
fn mg_levels(session: &SessionGuard, prefix: Option<&str>) -> Result<Option<usize>, StepError> {
    let name = format!("{}pc_mg_levels", prefix.unwrap_or(""));
    match petsc::option_string(session, &name)? {
        None => Ok(None),
        Some(v) => match v.parse::<usize>() {
            Ok(n) if n >= 1 => Ok(Some(n)),
            _ => Err(StepError::Setup(format!(
                "-{name} {v}: the number of multigrid levels must be a whole number of at least 1"
            ))),
        },
    }
}

/// Which unknowns are constrained (the multigrid's interpolation depends on them).
fn constrained(dofs: &DofMap) -> Vec<bool> {
    (0..dofs.len()).map(|i| dofs.is_constrained(i)).collect()
}

/// The interpolations of `hierarchy` as PETSc matrices, each process holding the rows of its own
/// unknowns on the finer level (level 0: the block rows `rows`) and owning the columns of its coarse
/// nodes ([`Hierarchy::owned_starts`]).
fn interpolations<const D: usize>(
    session: &SessionGuard,
    hierarchy: &Hierarchy<D>,
    rows: Range<usize>,
) -> Result<Vec<Matrix>, StepError> {
    let (rank, size) = (session.rank(), session.size());
    let mut firsts = vec![0.0; size];
    firsts[rank] = rows.start as f64;
    session.sum(&mut firsts)?;
    let mut starts: Vec<usize> = firsts.iter().map(|&f| f as usize).collect();
    starts.push(hierarchy.levels[0].active.len());
    let owned = hierarchy.owned_starts(&starts);
    let nf = hierarchy.unknowns_per_node;
    let mut mats = Vec::with_capacity(hierarchy.interpolations.len());
    for (l, p) in hierarchy.interpolations.iter().enumerate() {
        let (fine, coarse) = (&owned[l], &owned[l + 1]);
        let own = fine[rank] * nf..fine[rank + 1] * nf;
        let (mut i, mut j, mut w) = (Vec::new(), Vec::new(), Vec::new());
        for r in own.clone() {
            for (c, v) in p.row(r) {
                i.push(r as PetscInt);
                j.push(c as PetscInt);
                w.push(v);
            }
        }
        let local_cols = (coarse[rank + 1] - coarse[rank]) * nf;
        mats.push(Matrix::rectangular(
            session,
            (own.len(), local_cols),
            nf,
            &i,
            &j,
            &w,
        )?);
    }
    Ok(mats)
}

/// Rigid-body mode `k` of the displacement at `x` (mm): the translations along the axes (`k < D`), then
/// the rotations (2D: about z; 3D: about x, y and z).
pub(super) fn rigid_mode<const D: usize>(k: usize, x: &SVector<f64, D>) -> SVector<f64, D> {
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
