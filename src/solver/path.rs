//! Path following of quasi-static runs by indirect displacement control (`docs/theory.md`, "Path
//! following"): the prescribed motion of a step is `k` times its nominal increment, `k` an unknown of the
//! step besides the displacements, and one more equation holds the opening between two material points
//! (e.g. the crack-mouth opening) to its prescribed increment. The bordered Newton system
//!
//! ```text
//! [ J    -q ] [dx]   [ -R              ]      R(x, k) = R_ref(x) + (1 - k) q
//! [ c^T   0 ] [dk] = [ dw - c . x      ]      q = s p on the constrained rows (p: nominal increments)
//! ```
//!
//! is solved by the two-solve bordering algorithm with the step's own KSP and Jacobian: `J a = -R`,
//! `J b = q`, `dk = (dw - c.x - c.a) / c.b`, `dx = a + dk b`. With the opening growing monotonically the
//! path is followed through snap-backs, where the prescribed displacement itself decreases (`k < 0`).
//!
//! Hooks in the step: `Step::plan` builds the [`PathStep`], `Step::solve` calls [`newton`] (the
//! bordered Newton instead of SNES's with path following), `Step::finish` scales the sets' increments by `k` and reports the
//! [`PathPoint`].

use super::*;
use crate::petsc::PetscError;
use system::OwnedRows;

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

/// The control of one step attempt: the opening's coefficients on the unknowns and its target.
pub(super) struct PathStep {
    /// `c`: the opening increment `c . x` as a function of all unknowns (dense, in [`DofMap`] order).
    coefficients: Vec<f64>,
    /// The opening increment of the step (mm).
    target: f64,
    /// The ratio `k` of the step's prescribed motion to its nominal one (the last iterate's).
    pub(super) ratio: f64,
}

impl<const D: usize> Step<'_, D> {
    /// The control of an attempt of `dt` (s): the opening's coefficients from the measured points'
    /// shape functions (`du_p = sum_I S_Ip du_I`; summed over the processes), the target `increment
    /// dt / dt_nominal`. `None` without path following.
    pub(super) fn path_step(
        &self,
        session: &SessionGuard,
        dt: f64,
    ) -> Result<Option<PathStep>, StepError> {
        let Some(gauge) = &self.model.path else {
            return Ok(None);
        };
        let (dofs, table) = (&self.work.dofs, &self.work.table);
        let nf = dofs.unknowns_per_node();
        let mut coefficients = vec![0.0; dofs.len()];
        let ps = &self.state.particles;
        let mut found = [0.0; 2];
        for p in 0..self.own_point_count() {
            let Some(end) = gauge.ids.iter().position(|&id| id == ps.id[p]) else {
                continue;
            };
            found[end] = 1.0;
            let sign = if end == 0 { -1.0 } else { 1.0 };
            for w in table.weights(p) {
                if let Some(a) = dofs.active_index(w.node as usize) {
                    for c in 0..D {
                        coefficients[a * nf + c] += sign * w.value * gauge.direction[c];
                    }
                }
            }
        }
        if self.state.distributed {
            session.sum(&mut coefficients)?;
            session.sum(&mut found)?;
        }
        if found != [1.0, 1.0] {
            return Err(StepError::Setup(format!(
                "path following: the measured points {:?} are not among the points (eroded or lost?)",
                gauge.ids
            )));
        }
        Ok(Some(PathStep {
            coefficients,
            target: gauge.increment * dt / self.model.params.time.dt,
            ratio: 1.0,
        }))
    }

    /// Where the path is after the committed step: the load factor from the reference set's
    /// accumulated motion, the opening from the measured points' positions, the step's ratio.
    pub(super) fn path_point(
        &self,
        session: &SessionGuard,
        path: Option<&PathStep>,
    ) -> Result<Option<PathPoint>, StepError> {
        let (Some(gauge), Some(path)) = (&self.model.path, path) else {
            return Ok(None);
        };
        let (set, c, v) = gauge.reference;
        let ps = &self.state.particles;
        let mut sum = [0.0; 1];
        for p in 0..self.own_point_count() {
            if let Some(end) = gauge.ids.iter().position(|&id| id == ps.id[p]) {
                let sign = if end == 0 { -1.0 } else { 1.0 };
                sum[0] += sign * gauge.direction.dot(&ps.x[p]);
            }
        }
        if self.state.distributed {
            session.sum(&mut sum)?;
        }
        Ok(Some(PathPoint {
            lambda: self.state.counters.accumulated[set][c] / v,
            opening: sum[0] - gauge.initial,
            ratio: path.ratio,
        }))
    }
}

/// The sets' prescribed increments `set_du` of a step whose prescribed motion is `ratio` times the
/// nominal one.
pub(super) fn scale_increments<const D: usize>(set_du: &mut [[Option<f64>; D]], ratio: f64) {
    for d in set_du.iter_mut().flatten().flatten() {
        *d *= ratio;
    }
}

/// The residual `R(x, k) = R_ref(x) + (1 - k) q` of `problem` at `x` into `r`; a domain error is `Ok(Err)`.
fn residual<const D: usize>(
    problem: &mut StepProblem<'_, '_, D>,
    x: &Vector,
    r: &mut Vector,
    q: &Vector,
    ratio: f64,
) -> Result<Result<f64, String>, PetscError> {
    match problem.residual(x, r) {
        Ok(()) => {}
        Err(CallbackError::Domain(msg)) => return Ok(Err(msg)),
        Err(CallbackError::Fatal(msg)) => return Err(fatal(msg)),
    }
    r.axpy(1.0 - ratio, q)?;
    Ok(Ok(r.norm2()?))
}

/// A failure inside an evaluation that no smaller step can fix.
fn fatal(message: String) -> PetscError {
    PetscError {
        code: 83,
        call: "path-following Newton",
        message,
    }
}

/// A vector shaped like `like` holding this process's part of `all` (every unknown).
fn owned_vector(like: &Vector, owned: &OwnedRows, all: &[f64]) -> Result<Vector, PetscError> {
    let mut v = like.duplicate()?;
    owned.scatter(all, &mut v)?;
    Ok(v)
}

/// The bordered Newton's outcome as a [`SolveInfo`] (reason codes and names as SNES's; `domain`: the
/// messages of the iterates outside the material's domain).
fn info(
    (iterations, linear): (usize, usize),
    norms: Vec<f64>,
    domain: &[String],
    outcome: (i32, &str),
) -> SolveInfo {
    SolveInfo {
        iterations,
        linear_iterations: linear,
        reason: outcome.0,
        reason_name: outcome.1.to_owned(),
        residual_norms: norms,
        domain_errors: domain.to_vec(),
    }
}

/// The step's Newton solve: SNES's, or with path following (`path`) the bordered Newton
/// ([`bordered_newton`]).
pub(super) fn newton<const D: usize>(
    snes: &mut Snes,
    problem: &mut StepProblem<'_, '_, D>,
    x: &mut Vector,
    jac: &mut Matrix,
    path: Option<&mut PathStep>,
) -> Result<SolveInfo, PetscError> {
    match path {
        Some(p) => bordered_newton(snes, problem, x, jac, p),
        None => snes.solve(problem, x, jac),
    }
}

/// The vectors of the bordered Newton (this process's parts).
struct Bordering {
    /// Residual `R(x, k)`, its negative, and the solutions `a = J^-1 (-R)`, `b = J^-1 q`.
    r: Vector,
    rhs: Vector,
    a: Vector,
    b: Vector,
    /// `q = s p`: the nominal prescribed increments on the constrained rows, scaled.
    q: Vector,
    /// The opening's coefficients.
    c: Vector,
}

impl Bordering {
    /// Solves `J a = -R` and `J b = q` with the KSP of `snes`; the linear iterations, or `None` if a
    /// solve failed.
    fn solve(&mut self, snes: &mut Snes, jac: &Matrix) -> Result<Option<usize>, PetscError> {
        self.rhs.set_all(0.0)?;
        self.rhs.axpy(-1.0, &self.r)?;
        let mut its = 0;
        for (v, out) in [(&self.rhs, &mut self.a), (&self.q, &mut self.b)] {
            let ls = snes.linear_solve(jac, v, out)?;
            its += ls.iterations;
            if !ls.converged() {
                return Ok(None);
            }
        }
        Ok(Some(its))
    }

    /// Moves `x` by `a` (the update, with `b` folded in) and the ratio by `dk`, halving the step while
    /// the residual meets a point outside the material's domain (messages into `domain`); the new
    /// residual norm, or `None` after 8 halvings.
    fn advance<const D: usize>(
        &mut self,
        problem: &mut StepProblem<'_, '_, D>,
        x: &mut Vector,
        (path, dk): (&mut PathStep, f64),
        domain: &mut Vec<String>,
    ) -> Result<Option<f64>, PetscError> {
        let mut step = 1.0;
        loop {
            x.axpy(step, &self.a)?;
            match residual(problem, x, &mut self.r, &self.q, path.ratio + step * dk)? {
                Ok(n) => {
                    path.ratio += step * dk;
                    return Ok(Some(n));
                }
                Err(m) => {
                    x.axpy(-step, &self.a)?;
                    domain.push(m);
                    if step <= 1.0 / 256.0 {
                        return Ok(None);
                    }
                    step *= 0.5;
                }
            }
        }
    }
}

/// Newton on the step's equations and the path constraint from the guess in `x` (overwritten) and the
/// ratio `path.ratio` (updated), by the bordering algorithm with the KSP of `snes` (its options, its
/// preconditioner) and the Jacobian `jac`; converged when `|R| <= max(atol, rtol |R_0|)` with SNES's
/// tolerances, at most `max_it` iterations. A step along the direction that meets a point outside its
/// domain is halved (up to 8 times). Failures are reported as SNES would (`DIVERGED_LINEAR_SOLVE`,
/// `DIVERGED_MAX_IT`, `DIVERGED_FUNCTION_DOMAIN`, `DIVERGED_JACOBIAN_DOMAIN`): the step is retried
/// with half the increment.
fn bordered_newton<const D: usize>(
    snes: &mut Snes,
    problem: &mut StepProblem<'_, '_, D>,
    x: &mut Vector,
    jac: &mut Matrix,
    path: &mut PathStep,
) -> Result<SolveInfo, PetscError> {
    let tol = snes.tolerances()?;
    let (owned, dofs, s) = (problem.owned, problem.input.dofs, problem.row_scale);
    let nominal: Vec<f64> = (0..dofs.len())
        .map(|i| dofs.prescribed(i).map_or(0.0, |v| s * v))
        .collect();
    let mut v = Bordering {
        r: x.duplicate()?,
        rhs: x.duplicate()?,
        a: x.duplicate()?,
        b: x.duplicate()?,
        q: owned_vector(x, owned, &nominal)?,
        c: owned_vector(x, owned, &path.coefficients)?,
    };
    let mut domain = Vec::new();
    let mut norm = match residual(problem, x, &mut v.r, &v.q, path.ratio)? {
        Ok(n) => n,
        Err(m) => {
            domain.push(m);
            f64::NAN
        }
    };
    let mut norms = vec![norm];
    let goal = tol.atol.max(tol.rtol * norm);
    let (mut its, mut lits) = (0, 0);
    let outcome = loop {
        if !norm.is_finite() {
            break if domain.is_empty() {
                (-4, "DIVERGED_FNORM_NAN")
            } else {
                (-1, "DIVERGED_FUNCTION_DOMAIN")
            };
        }
        if norm <= goal && its > 0 {
            break if norm <= tol.atol {
                (2, "CONVERGED_FNORM_ABS")
            } else {
                (3, "CONVERGED_FNORM_RELATIVE")
            };
        }
        if its >= tol.max_it.max(1) as usize {
            break (-5, "DIVERGED_MAX_IT");
        }
        its += 1;
        match problem.jacobian(x, jac) {
            Ok(()) => {}
            Err(CallbackError::Domain(m)) => {
                domain.push(m);
                break (-10, "DIVERGED_JACOBIAN_DOMAIN");
            }
            Err(CallbackError::Fatal(m)) => return Err(fatal(m)),
        }
        let Some(l) = v.solve(snes, jac)? else {
            break (-3, "DIVERGED_LINEAR_SOLVE");
        };
        lits += l;
        let cb = v.c.dot(&v.b)?;
        if cb.is_nan() || cb.abs() <= 1e-300 {
            return Err(fatal(
                "path following: the measured opening does not respond to the prescribed motion \
                 (c . K^-1 q = 0); measure across the crack that the moving sets open"
                    .into(),
            ));
        }
        let dk = (path.target - v.c.dot(x)? - v.c.dot(&v.a)?) / cb;
        v.a.axpy(dk, &v.b)?;
        norm = v
            .advance(problem, x, (path, dk), &mut domain)?
            .unwrap_or(f64::NAN);
        norms.push(norm);
    };
    Ok(info((its, lits), norms, &domain, outcome))
}
