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
//! Each iteration is globalised by a backtracking line search on `|R(x, k)|` along the curve
//! `x0 + t a + dk(t) b` on which the constraint holds exactly (the full step `t = 1` first).
//!
//! Hooks in the step: `Step::plan` builds the [`PathStep`], `Step::solve` calls [`newton`] (the
//! bordered Newton instead of SNES's with path following), `Step::finish` scales the sets' increments by `k` and reports the
//! [`PathPoint`]. The gauge they read, the measured points and the load factor's reference set fixed at
//! t = 0, is the model's ([`Gauge`](crate::model::Gauge), made by `Model::new` in
//! [`crate::model::path`]).

use super::problem::StepProblem;
use super::report::{PathPoint, StepError};
use super::step::Step;
use super::system::OwnedRows;
use crate::petsc::{
    CallbackError, Matrix, NonlinearProblem, PetscError, SessionGuard, Snes, SolveInfo, Vector,
};

/// The control of one step attempt: the opening's coefficients on the unknowns and its target.
pub(super) struct PathStep {
    /// `c`: the opening increment `c . x` as a function of all unknowns (dense, in
    /// [`DofMap`](crate::dofs::DofMap) order).
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
        let processes = self.processes(session);
        processes.sum(&mut coefficients)?;
        processes.sum(&mut found)?;
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
        self.processes(session).sum(&mut sum)?;
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
    outcome: Outcome,
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
    /// Residual `R(x, k)`, its negative (also scratch for the full step), and the solutions `a = J^-1 (-R)`, `b = J^-1 q`.
    r: Vector,
    rhs: Vector,
    a: Vector,
    b: Vector,
    /// `q = s p`: the nominal prescribed increments on the constrained rows, scaled.
    q: Vector,
    /// The opening's coefficients.
    c: Vector,
    /// The unknowns at the start of the iteration (the line search's origin).
    x0: Vector,
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

    /// The scalars of the iteration's line search at `x` with the opening increment `target` (mm),
    /// after [`Bordering::solve`]; a fatal error when the opening does not respond to the load
    /// (`c . b = 0`).
    fn search(&self, x: &Vector, target: f64) -> Result<Search, PetscError> {
        let cb = self.c.dot(&self.b)?;
        if cb.is_nan() || cb.abs() <= 1e-300 {
            return Err(fatal(
                "path following: the measured opening does not respond to the prescribed motion \
                 (c . K^-1 q = 0); measure across the crack that the moving sets open"
                    .into(),
            ));
        }
        let (gap, ca) = (target - self.c.dot(x)?, self.c.dot(&self.a)?);
        Ok(Search {
            gap,
            ca,
            cb,
            dk: (gap - ca) / cb,
        })
    }

    /// The plain Newton update: moves `x` by `a + dk b` and the ratio by `dk`, halving the step while
    /// the residual meets a point outside the material's domain (messages into `domain`); the new
    /// residual norm, or the failure after 8 halvings.
    fn advance<const D: usize>(
        &mut self,
        problem: &mut StepProblem<'_, '_, D>,
        x: &mut Vector,
        (path, dk): (&mut PathStep, f64),
        domain: &mut Vec<String>,
    ) -> Result<Result<f64, Outcome>, PetscError> {
        self.a.axpy(dk, &self.b)?;
        let mut step = 1.0;
        loop {
            x.axpy(step, &self.a)?;
            match residual(problem, x, &mut self.r, &self.q, path.ratio + step * dk)? {
                Ok(n) => {
                    path.ratio += step * dk;
                    return Ok(Ok(n));
                }
                Err(m) => {
                    x.axpy(-step, &self.a)?;
                    domain.push(m);
                    if step <= 1.0 / 256.0 {
                        return Ok(Err(DOMAIN));
                    }
                    step *= 0.5;
                }
            }
        }
    }

    /// Places `x` at the fraction `t` of the iteration from `x0`: `x0 + t a + dk(t) b` with
    /// `dk(t) = (g - t c.a) / (c.b)` ([`Search`]), so that the constraint holds exactly for every `t`;
    /// the full step is `x0 + a + dk b` as the plain bordered Newton takes it. Returns `dk(t)`.
    fn place(&mut self, x: &mut Vector, s: &Search, t: f64) -> Result<f64, PetscError> {
        x.copy_from(&self.x0)?;
        if t == 1.0 {
            self.rhs.copy_from(&self.a)?;
            self.rhs.axpy(s.dk, &self.b)?;
            x.axpy(1.0, &self.rhs)?;
            return Ok(s.dk);
        }
        let dk = (s.gap - t * s.ca) / s.cb;
        x.axpy(t, &self.a)?;
        x.axpy(dk, &self.b)?;
        Ok(dk)
    }

    /// The line search of one iteration from `x0` (copied from `x`) along the bordered direction with
    /// the constraint kept exact ([`Bordering::place`]), on the merit `phi(t) = |R(t)|^2`, whose slope at
    /// `t = 0` is `-2 |R_0|^2` (the linearised residual is `(1 - t) R_0` for every `dk`, since
    /// `J b = q`). The full step is tried first and accepted when `phi(1) <= (1 - 2 alpha) phi(0)`
    /// (Armijo, `alpha` = [`ARMIJO`]); otherwise `t` backtracks to the minimiser of the quadratic through
    /// `phi(0)`, `phi'(0)` and `phi(t)`, kept within `[t/10, t/2]`, and is halved where the residual
    /// meets a point outside the material's domain (messages into `domain`), down to [`MIN_STEP`]. If no
    /// `t` satisfies Armijo, the tried `t` of least `|R|` is taken when it lowers `|R|` at all. Returns
    /// the new `|R|` (with `x`, `R` and `path.ratio` at the accepted point), or the SNES-like failure.
    fn line_search<const D: usize>(
        &mut self,
        problem: &mut StepProblem<'_, '_, D>,
        x: &mut Vector,
        (path, s, norm0): (&mut PathStep, &Search, f64),
        domain: &mut Vec<String>,
    ) -> Result<Result<f64, Outcome>, PetscError> {
        self.x0.copy_from(x)?;
        let phi0 = norm0 * norm0;
        let (mut t, mut best) = (1.0f64, None::<(f64, f64)>);
        loop {
            let dk = self.place(x, s, t)?;
            let next = match residual(problem, x, &mut self.r, &self.q, path.ratio + dk)? {
                Ok(n) if n.is_finite() => {
                    if n * n <= (1.0 - 2.0 * ARMIJO * t) * phi0 {
                        path.ratio += dk;
                        return Ok(Ok(n));
                    }
                    if best.is_none_or(|(_, b)| n < b) {
                        best = Some((t, n));
                    }
                    let tq = phi0 * t * t / (n * n - phi0 + 2.0 * phi0 * t);
                    tq.clamp(0.1 * t, 0.5 * t)
                }
                Ok(_) => 0.5 * t,
                Err(m) => {
                    domain.push(m);
                    0.5 * t
                }
            };
            if next < MIN_STEP {
                break;
            }
            t = next;
        }
        match best {
            Some((t, n)) if n < norm0 => {
                let dk = self.place(x, s, t)?;
                let again = residual(problem, x, &mut self.r, &self.q, path.ratio + dk)?;
                path.ratio += dk;
                Ok(again.map_err(|m| {
                    domain.push(m);
                    DOMAIN
                }))
            }
            _ => {
                x.copy_from(&self.x0)?;
                let tried_domain = best.is_none() && !domain.is_empty();
                Ok(Err(if tried_domain { DOMAIN } else { LINE_SEARCH }))
            }
        }
    }
}

/// SNES's reason code and name of a bordered Newton's end.
type Outcome = (i32, &'static str);

/// A residual outside the material's domain at every tried step.
const DOMAIN: Outcome = (-1, "DIVERGED_FUNCTION_DOMAIN");

/// A residual that is not a number (without a domain error).
const FNORM_NAN: Outcome = (-4, "DIVERGED_FNORM_NAN");

/// No step along the direction lowers the residual.
const LINE_SEARCH: Outcome = (-6, "DIVERGED_LINE_SEARCH");

/// Armijo's sufficient-decrease parameter `alpha` of the line search (PETSc's `bt` default).
const ARMIJO: f64 = 1e-4;

/// The smallest step fraction `t` the line search tries (2^-10).
const MIN_STEP: f64 = 1.0 / 1024.0;

/// The scalars of one iteration's line search: `dk(t) = (gap - t ca) / cb`.
struct Search {
    /// `g = dw - c . x0`: what the constraint misses at the iteration's start (mm).
    gap: f64,
    /// `c . a` (mm).
    ca: f64,
    /// `c . b` (mm per unit of `k`).
    cb: f64,
    /// `dk(1)`, the full step's change of the ratio.
    dk: f64,
}

/// Newton on the step's equations and the path constraint from the guess in `x` (overwritten) and the
/// ratio `path.ratio` (updated), by the bordering algorithm with the KSP of `snes` (its options, its
/// preconditioner) and the Jacobian `jac`; converged when `|R| <= max(atol, rtol |R_0|)` with SNES's
/// tolerances, at most `max_it` iterations. First the plain bordered Newton (full steps, a step that
/// meets a point outside the material's domain halved up to 8 times); if it ends in `DIVERGED_MAX_IT`
/// or `DIVERGED_FUNCTION_DOMAIN`, the attempt is repeated from the same guess with every iteration
/// globalised by the line search of [`Bordering::line_search`] (the iterations and messages of both
/// count). Failures are reported as SNES would (`DIVERGED_LINEAR_SOLVE`, `DIVERGED_MAX_IT`,
/// `DIVERGED_LINE_SEARCH`, `DIVERGED_FUNCTION_DOMAIN`, `DIVERGED_JACOBIAN_DOMAIN`): the step is
/// retried with half the increment.
fn bordered_newton<const D: usize>(
    snes: &mut Snes,
    problem: &mut StepProblem<'_, '_, D>,
    x: &mut Vector,
    jac: &mut Matrix,
    path: &mut PathStep,
) -> Result<SolveInfo, PetscError> {
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
        x0: x.duplicate()?,
    };
    let mut guess = x.duplicate()?;
    guess.copy_from(x)?;
    let ratio = path.ratio;
    let plain = iterate(snes, problem, (x, jac), (path, &mut v), false)?;
    // DIVERGED_MAX_IT or DIVERGED_FUNCTION_DOMAIN after at least one iteration.
    let rescuable = (plain.reason == -5 || plain.reason == DOMAIN.0) && plain.iterations > 0;
    if !rescuable {
        return Ok(plain);
    }
    x.copy_from(&guess)?;
    path.ratio = ratio;
    let mut searched = iterate(snes, problem, (x, jac), (path, &mut v), true)?;
    searched.iterations += plain.iterations;
    searched.linear_iterations += plain.linear_iterations;
    let mut norms = plain.residual_norms;
    norms.append(&mut searched.residual_norms);
    searched.residual_norms = norms;
    let mut domain = plain.domain_errors;
    domain.append(&mut searched.domain_errors);
    searched.domain_errors = domain;
    Ok(searched)
}

/// The bordered Newton iterations of [`bordered_newton`] from `x` and `path.ratio`, with the line
/// search in every iteration (`globalised`) or plain full steps ([`Bordering::advance`]).
fn iterate<const D: usize>(
    snes: &mut Snes,
    problem: &mut StepProblem<'_, '_, D>,
    (x, jac): (&mut Vector, &mut Matrix),
    (path, v): (&mut PathStep, &mut Bordering),
    globalised: bool,
) -> Result<SolveInfo, PetscError> {
    let tol = snes.tolerances()?;
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
            break if domain.is_empty() { FNORM_NAN } else { DOMAIN };
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
        let search = v.search(x, path.target)?;
        let moved = if globalised {
            v.line_search(problem, x, (path, &search, norm), &mut domain)?
        } else {
            v.advance(problem, x, (path, search.dk), &mut domain)?
        };
        match moved {
            Ok(n) => norm = n,
            Err(failed) => break failed,
        }
        norms.push(norm);
    };
    Ok(info((its, lits), norms, &domain, outcome))
}
