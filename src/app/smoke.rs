//! A small nonlinear problem that exercises the whole PETSc layer: a square lattice of geometrically
//! nonlinear springs (a cantilever block clamped on the left, loaded on the right) coupled one way to a
//! nonlinear scalar field, 3 unknowns per node (u_x, u_y, phi) interleaved like the MPM's
//! (u_x, u_y, eta_bar). Its Jacobian is non-symmetric, like the gradient-enhanced damage problem.
//!
//! For spring s between nodes a and b with rest length L, stiffness k and current vector
//! d = X_b + u_b - X_a - u_a, l = |d|:
//!   R^u_b += k (l - L) d / l,   R^u_a -= k (l - L) d / l,
//!   R^phi_a += c (phi_a - phi_b) - g (l - L)^2 / 2,  and symmetrically for b;
//! per node: R^phi += phi + phi^3, R^u -= f_ext; clamped nodes: R^u = k u.
//!
//! Each process evaluates the springs whose first node it owns on a gathered copy of x and adds its
//! contributions with global indices, so the problem runs unchanged under `mpirun -n N`.

use super::{bad, share_cores};
use crate::petsc::{
    self, CallbackError, Matrix, NonlinearProblem, PetscInt, Session, SessionGuard, Snes,
    SolveInfo, Vector,
};
use crate::preflight;
use anyhow::{Context, Result};
use nalgebra::{Matrix2, Vector2};

/// Parameters of the lattice.
#[derive(Debug, Clone, Copy)]
pub struct SmokeParams {
    /// Nodes per side.
    pub n: usize,
    /// Axial spring stiffness (diagonal springs get half).
    pub k: f64,
    /// Diffusion coefficient of phi.
    pub c: f64,
    /// Source gain of phi from the spring stretch.
    pub g: f64,
    /// Downward load per node on the right edge.
    pub load: f64,
}

impl Default for SmokeParams {
    fn default() -> Self {
        Self {
            n: 12,
            k: 1.0,
            c: 0.5,
            g: 50.0,
            load: 0.001,
        }
    }
}

/// The lattice problem (positions, springs, the rows owned by this process).
pub struct SmokeProblem {
    p: SmokeParams,
    /// Springs (a, b, stiffness) whose node `a` this process owns.
    springs: Vec<(usize, usize, f64)>,
    /// Nodes owned by this process.
    owned: std::ops::Range<usize>,
    /// COO values, reused across Newton iterations.
    values: Vec<f64>,
    /// Scratch for residual indices/values.
    idx: Vec<PetscInt>,
    val: Vec<f64>,
}

const DOF: usize = 3;

impl SmokeProblem {
    fn position(&self, node: usize) -> Vector2<f64> {
        Vector2::new((node % self.p.n) as f64, (node / self.p.n) as f64)
    }

    fn clamped(&self, node: usize) -> bool {
        node % self.p.n == 0
    }

    /// The problem, with nodes split over processes like `x` (block size 3).
    pub fn new(p: SmokeParams, x: &Vector) -> petsc::Result<Self> {
        let r = x.ownership_range()?;
        let owned = r.start / DOF..r.end / DOF;
        let n = p.n;
        let mut springs = Vec::new();
        for a in owned.clone() {
            let (i, j) = (a % n, a / n);
            let mut add = |di: isize, dj: isize, k: f64| {
                let (bi, bj) = (i as isize + di, j as isize + dj);
                if bi >= 0 && bj >= 0 && (bi as usize) < n && (bj as usize) < n {
                    springs.push((a, bi as usize + bj as usize * n, k));
                }
            };
            add(1, 0, p.k);
            add(0, 1, p.k);
            add(1, 1, 0.5 * p.k);
            add(-1, 1, 0.5 * p.k);
        }
        Ok(Self {
            p,
            springs,
            owned,
            values: Vec::new(),
            idx: Vec::new(),
            val: Vec::new(),
        })
    }

    /// Number of unknowns on this process.
    pub fn local_size(p: &SmokeParams, rank: usize, size: usize) -> usize {
        let nodes = p.n * p.n;
        let base = nodes / size;
        DOF * (base + usize::from(rank < nodes % size))
    }

    fn u_row(&self, node: usize, c: usize) -> PetscInt {
        if self.clamped(node) {
            -1
        } else {
            (DOF * node + c) as PetscInt
        }
    }

    /// The COO pattern: per spring the 6x6 coupling of (a, b), then per owned node its diagonal.
    pub fn pattern(&self) -> (Vec<PetscInt>, Vec<PetscInt>) {
        let (mut rows, mut cols) = (Vec::new(), Vec::new());
        for &(a, b, _) in &self.springs {
            for &ra in &[a, b] {
                for rc in 0..DOF {
                    let row = if rc < 2 {
                        self.u_row(ra, rc)
                    } else {
                        (DOF * ra + rc) as PetscInt
                    };
                    for &ca in &[a, b] {
                        for cc in 0..DOF {
                            rows.push(row);
                            cols.push((DOF * ca + cc) as PetscInt);
                        }
                    }
                }
            }
        }
        for node in self.owned.clone() {
            for c in 0..DOF {
                rows.push((DOF * node + c) as PetscInt);
                cols.push((DOF * node + c) as PetscInt);
            }
        }
        (rows, cols)
    }

    /// Spring state: d, l, and the unit direction.
    fn spring(&self, x: &[f64], a: usize, b: usize) -> (Vector2<f64>, f64, f64) {
        let ua = Vector2::new(x[DOF * a], x[DOF * a + 1]);
        let ub = Vector2::new(x[DOF * b], x[DOF * b + 1]);
        let rest = self.position(b) - self.position(a);
        let d = rest + ub - ua;
        (d, d.norm(), rest.norm())
    }
}

impl NonlinearProblem for SmokeProblem {
    fn residual(&mut self, x: &Vector, f: &mut Vector) -> Result<(), CallbackError> {
        let all = x
            .gather_all()
            .map_err(|e| CallbackError::Fatal(e.to_string()))?;
        if all.iter().any(|v| !v.is_finite()) {
            return Err(CallbackError::Domain("non-finite unknown".into()));
        }
        self.idx.clear();
        self.val.clear();
        for si in 0..self.springs.len() {
            let (a, b, k) = self.springs[si];
            let (d, l, rest) = self.spring(&all, a, b);
            let force = k * (l - rest) / l * d;
            let src = 0.5 * self.p.g * (l - rest).powi(2);
            let (pa, pb) = (all[DOF * a + 2], all[DOF * b + 2]);
            for (node, sign, dphi) in [(a, -1.0, pa - pb), (b, 1.0, pb - pa)] {
                for c in 0..2 {
                    self.idx.push(self.u_row(node, c));
                    self.val.push(sign * force[c]);
                }
                self.idx.push((DOF * node + 2) as PetscInt);
                self.val.push(self.p.c * dphi - src);
            }
        }
        for node in self.owned.clone() {
            let phi = all[DOF * node + 2];
            self.idx.push((DOF * node + 2) as PetscInt);
            self.val.push(phi + phi.powi(3));
            for c in 0..2 {
                let u = all[DOF * node + c];
                let r = if self.clamped(node) {
                    self.p.k * u
                } else if c == 1 && node % self.p.n == self.p.n - 1 {
                    self.p.load
                } else {
                    0.0
                };
                self.idx.push((DOF * node + c) as PetscInt);
                self.val.push(r);
            }
        }
        let fatal = |e: petsc::PetscError| CallbackError::Fatal(e.to_string());
        f.set_all(0.0).map_err(fatal)?;
        f.add_values(&self.idx, &self.val).map_err(fatal)?;
        f.assemble().map_err(fatal)
    }

    fn jacobian(&mut self, x: &Vector, jac: &mut Matrix) -> Result<(), CallbackError> {
        let all = x
            .gather_all()
            .map_err(|e| CallbackError::Fatal(e.to_string()))?;
        self.values.clear();
        for si in 0..self.springs.len() {
            let (a, b, k) = self.springs[si];
            let (d, l, rest) = self.spring(&all, a, b);
            let n = d / l;
            // d(force)/d(u_b) for force = k (l - L) n.
            let kb: Matrix2<f64> = k
                * (n * n.transpose() + (l - rest) / l * (Matrix2::identity() - n * n.transpose()));
            // d(src)/d(u_b) = g (l - L) n.
            let ds = self.p.g * (l - rest) * n;
            for (ri, sign) in [(0usize, -1.0), (1, 1.0)] {
                for rc in 0..DOF {
                    for (ci, csign) in [(0usize, -1.0), (1, 1.0)] {
                        for cc in 0..DOF {
                            let v = match (rc < 2, cc < 2) {
                                (true, true) => sign * csign * kb[(rc, cc)],
                                (true, false) => 0.0,
                                (false, true) => -csign * ds[cc],
                                (false, false) => {
                                    if (ri == 0) == (ci == 0) {
                                        self.p.c
                                    } else {
                                        -self.p.c
                                    }
                                }
                            };
                            self.values.push(v);
                        }
                    }
                }
            }
        }
        for node in self.owned.clone() {
            let phi = all[DOF * node + 2];
            let ku = if self.clamped(node) { self.p.k } else { 0.0 };
            self.values
                .extend_from_slice(&[ku, ku, 1.0 + 3.0 * phi * phi]);
        }
        jac.set_values_coo(&self.values)
            .map_err(|e| CallbackError::Fatal(e.to_string()))
    }
}

/// Result of [`solve`]: the solver statistics and the solution gathered on every process.
pub struct SmokeResult {
    /// SNES statistics.
    pub info: SolveInfo,
    /// Solution in global order (u_x, u_y, phi per node).
    pub solution: Vec<f64>,
    /// Solver combination, e.g. "newtonls / preonly / lu".
    pub solver: String,
}

/// Solves the lattice problem with the SNES options under `prefix` (None: the plain `-snes_*` options).
pub fn solve(s: &SessionGuard, p: SmokeParams, prefix: Option<&str>) -> petsc::Result<SmokeResult> {
    let local = SmokeProblem::local_size(&p, s.rank(), s.size());
    let mut x = Vector::new(s, local, DOF)?;
    x.set_all(0.0)?;
    let mut problem = SmokeProblem::new(p, &x)?;
    let mut jac = Matrix::new(s, local, DOF)?;
    let (rows, cols) = problem.pattern();
    jac.set_pattern_coo(&rows, &cols)?;
    let mut snes = Snes::new(s, prefix)?;
    snes.set_from_options()?;
    let info = snes.solve(&mut problem, &mut x, &mut jac)?;
    let solver = snes.describe()?;
    Ok(SmokeResult {
        info,
        solution: x.gather_all()?,
        solver,
    })
}

/// Column-by-column comparison of the assembled Jacobian with central differences of the residual
/// at the state `x0`; returns max |J - J_fd| / max |J| (serial runs).
pub fn jacobian_fd_error(s: &SessionGuard, p: SmokeParams, x0: &[f64]) -> petsc::Result<f64> {
    let n = x0.len();
    let mut x = Vector::new(s, n, DOF)?;
    x.write(|a| a.copy_from_slice(x0))?;
    let mut problem = SmokeProblem::new(p, &x)?;
    let mut jac = Matrix::new(s, n, DOF)?;
    let (rows, cols) = problem.pattern();
    jac.set_pattern_coo(&rows, &cols)?;
    problem.jacobian(&x, &mut jac)?;
    let (mut e, mut col, mut fp, mut fm) = (
        x.duplicate()?,
        x.duplicate()?,
        x.duplicate()?,
        x.duplicate()?,
    );
    let (mut max_diff, mut max_j) = (0.0f64, 0.0f64);
    let h = 1e-6;
    for j in 0..n {
        e.write(|a| {
            a.fill(0.0);
            a[j] = 1.0;
        })?;
        jac.mult(&e, &mut col)?;
        for (sign, f) in [(1.0, &mut fp), (-1.0, &mut fm)] {
            let mut xs = x.duplicate()?;
            xs.write(|a| {
                a.copy_from_slice(x0);
                a[j] += sign * h;
            })?;
            problem.residual(&xs, f)?;
        }
        let c = col.read(|a| a.to_vec())?;
        let (a, b) = (fp.read(|a| a.to_vec())?, fm.read(|a| a.to_vec())?);
        for i in 0..n {
            let fd = (a[i] - b[i]) / (2.0 * h);
            max_diff = max_diff.max((c[i] - fd).abs());
            max_j = max_j.max(c[i].abs());
        }
    }
    Ok(max_diff / max_j)
}

/// The largest `--load` per node of the smoke lattice (in the stiffness's units).
const LOAD_MAX: f64 = 0.05;

/// `smoke`: solves the `n` x `n` lattice under `load` with the PETSc options of the command line
/// (`petsc_args`, starting with the program name; default a direct solve), prints the solver's
/// statistics (and with `print_solution` the solution as JSON) and fails on unused options or when the
/// solve did not converge.
pub fn command(petsc_args: &[String], n: usize, load: f64, print_solution: bool) -> Result<()> {
    if n < 2 {
        return Err(bad(format!("--n must be at least 2 (got {n})")));
    }
    if load.is_nan() || load.abs() > LOAD_MAX {
        return Err(bad(format!(
            "--load must be a number with |load| <= {LOAD_MAX} (the springs converge up to about 0.07 \
             per node; got {load})"
        )));
    }
    preflight::check_petsc_options(&petsc_args[1..].join(" "))
        .map_err(|e| bad(format!("command line: {e}")))?;
    let session = Session::initialize(petsc_args).context("starting PETSc")?;
    share_cores(&session);
    smoke_test(&session, n, load, print_solution)?;
    Session::finalize(session)?;
    Ok(())
}

/// The lattice solve of [`command`] on a started PETSc session.
fn smoke_test(session: &SessionGuard, n: usize, load: f64, print_solution: bool) -> Result<()> {
    petsc::apply_default_options(session, "-ksp_type preonly -pc_type lu")?;
    let p = SmokeParams {
        n,
        load,
        ..SmokeParams::default()
    };
    let r = solve(session, p, None).context("solving the lattice problem")?;
    let norm = r.solution.iter().map(|v| v * v).sum::<f64>().sqrt();
    if session.rank() == 0 {
        println!(
            "lattice {n}x{n} ({} unknowns) on {} process(es), solver {}",
            r.solution.len(),
            session.size(),
            r.solver
        );
        println!(
            "{}: {} Newton iterations, {} linear iterations, |x| = {norm:.12e}",
            r.info.reason_name, r.info.iterations, r.info.linear_iterations
        );
        if print_solution {
            println!("{}", serde_json::to_string(&r.solution)?);
        }
    }
    let unused = petsc::unused_options(session)?;
    if !unused.is_empty() {
        return Err(bad(format!(
            "unknown or unused PETSc option(s): {} (check the spelling; -help lists the options)",
            unused.join(" ")
        )));
    }
    if !r.info.converged() {
        anyhow::bail!(
            "the lattice problem did not converge: {}",
            r.info.reason_name
        );
    }
    Ok(())
}
