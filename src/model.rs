//! The run split the way it lives through the time steps (spec Sec. 1):
//! - [`Model`]: what defines the run and never changes while it runs (grid, materials, interpolator,
//!   time integration, constraints, loading devices, loads, solver policy);
//! - [`State`]: what a checkpoint holds (the material points with their history, the rigid bodies'
//!   points, the FEM mode's nodal state, time and the counters of the devices);
//! - the per-step scratch (shape-function tables, grid fields, unknowns, assembler, PETSc objects) is the
//!   solver's [`Workspace`](crate::solver::Workspace).
//!
//! A step is [`advance`](crate::solver::advance)`(&Model, &mut State, &mut Workspace, ..)`; output and
//! checkpoints read `&State`. Path following's control and the gauge the model derives from it are in
//! [`path`]; a plane set-up becomes a plate in the construction code (`Setup::extrude`,
//! `src/scenario/extrusion.rs`). Units: mm, s, N, MPa, t (tonne).

use crate::boundary::{Motion, NodalLoad, NodeBox, RigidBody};
use crate::contact::ContactMemory;
use crate::dofs::FieldLayout;
use crate::grid::Grid;
use crate::input::BadValue;
use crate::material::{Constitutive, Material};
use crate::particles::Particles;
use crate::shape::{ShapeError, ShapeKind, ShapeTable};
use crate::space::Frame;
use nalgebra::SVector;

pub mod path;
pub use path::{Gauge, PathControl};

/// Time integration settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeIntegration {
    /// Nominal time step (s).
    pub dt: f64,
    /// Smallest time step the halving may reach before the run stops (s).
    pub dt_min: f64,
    /// Newmark beta (> 0; 1/4 = trapezoidal rule).
    pub beta: f64,
    /// Newmark gamma (1/2: no numerical damping).
    pub gamma: f64,
    /// Drop inertia (static equilibrium each step, loads ramped with time).
    pub quasi_static: bool,
    /// How a dynamic run starts in acceleration (ignored quasi-statically and on resume).
    pub initial_acceleration: InitialAcceleration,
}

impl TimeIntegration {
    /// The nominal time step (s) of a run that does not set one: the CT demo's.
    pub const DEFAULT_DT: f64 = 1e-6;
    /// Unless set, the retry halving stops below `dt / DT_MIN_DIVISOR` (-): six halvings.
    pub const DT_MIN_DIVISOR: f64 = 64.0;
    /// Newmark beta of the trapezoidal rule (-).
    pub const DEFAULT_BETA: f64 = 0.25;
    /// Newmark gamma without numerical damping (-).
    pub const DEFAULT_GAMMA: f64 = 0.5;

    /// Dynamic steps of `dt` (s) by the trapezoidal rule, halved on failure down to
    /// `dt / DT_MIN_DIVISOR`, starting from the consistent acceleration: the defaults of `[time]` for
    /// that `dt`.
    pub fn with_dt(dt: f64) -> Self {
        Self {
            dt,
            dt_min: dt / Self::DT_MIN_DIVISOR,
            beta: Self::DEFAULT_BETA,
            gamma: Self::DEFAULT_GAMMA,
            quasi_static: false,
            initial_acceleration: InitialAcceleration::default(),
        }
    }
}

impl Default for TimeIntegration {
    /// [`TimeIntegration::with_dt`] of [`TimeIntegration::DEFAULT_DT`].
    fn default() -> Self {
        Self::with_dt(Self::DEFAULT_DT)
    }
}

/// The acceleration a dynamic run starts with (`[time] initial_acceleration`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize)]
#[serde(try_from = "String")]
pub enum InitialAcceleration {
    /// `M a_0 = f_ext(0) - f_int(u_0)` on the grid before the first step, constrained components with the
    /// acceleration of their prescribed motion, carried to the points: a load applied at t = 0 acts from
    /// the first step on.
    #[default]
    Consistent,
    /// `a_0 = 0`: the run starts at rest in acceleration, and a load applied at t = 0 is felt about half a
    /// step late.
    Zero,
}

impl TryFrom<String> for InitialAcceleration {
    type Error = String;

    fn try_from(name: String) -> Result<Self, String> {
        match name.as_str() {
            "consistent" => Ok(Self::Consistent),
            "zero" => Ok(Self::Zero),
            _ => Err(format!(
                "field `time.initial_acceleration` = \"{name}\": \"consistent\" (M a_0 = f_ext - f_int at \
                 t = 0, the default) or \"zero\" (start at rest in acceleration)"
            )),
        }
    }
}

/// How the material points and the grid relate.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Material point method: shape functions at the current point positions on a grid that is reset to
    /// its reference position every step (updated Lagrangian).
    #[default]
    Mpm,
    /// Finite elements on the grid cells: points fixed at the cells' Gauss points, bilinear shape functions
    /// of the reference configuration, gradients pushed forward with `F_n` (so `F = I + sum_I u_I (x)
    /// grad_X N_I`, total Lagrangian) and nodal velocity and acceleration carried from step to step
    /// (no grid reset).
    Fem,
}

/// Nodes with `m_I <= DEFAULT_MASS_TOLERANCE * max_J m_J` carry no unknowns unless a run sets its own
/// fraction (-).
pub const DEFAULT_MASS_TOLERANCE: f64 = 1e-6;

/// What defines a run and stays fixed while it runs, apart from the points: the grid, the materials,
/// the interpolator, time integration, constraints, devices, loads and solver prefixes. A scenario fills
/// it in [`Setup`]; [`Model`] keeps it.
pub struct Parameters<const D: usize = 2> {
    /// Background grid.
    pub grid: Grid<D>,
    /// One constitutive law per body tag.
    pub materials: Vec<Material>,
    /// The velocity field of each body tag on the grid (multi-velocity-field contact): bodies of field
    /// 0 share the grid's nodes (bonded), a body of a field `f >= 1` has its own copies of the nodes and
    /// meets the bodies of field 0 through frictionless unilateral contact (`docs/theory.md`, "Contact
    /// between bodies"). Empty in a [`Setup`]: every body on field 0; in a [`Model`] one entry per
    /// material.
    pub fields: Vec<u16>,
    /// Interpolator.
    pub shape: ShapeKind,
    /// The CPDI interpolators' corner hold (cell widths, `[shape] corner_hold`,
    /// [`crate::shape::DEFAULT_CORNER_HOLD`]).
    pub corner_hold: f64,
    /// Time integration.
    pub time: TimeIntegration,
    /// Body force per unit mass (mm/s^2), e.g. gravity `(0, -9810)`.
    pub body_force: SVector<f64, D>,
    /// Quasi-static runs ramp the body force linearly to its full value over this time (s); 0 = at once.
    pub body_force_ramp: f64,
    /// Node-box constraints.
    pub boxes: Vec<NodeBox<D>>,
    /// Rigid loading bodies (their points move with them: [`State::rigid`]).
    pub rigid: Vec<RigidBody<D>>,
    /// Applied forces.
    pub loads: Vec<NodalLoad<D>>,
    /// MPM or FEM on the grid cells.
    pub method: Method,
    /// Options prefix of the SNES (None: plain `-snes_*`).
    pub options_prefix: Option<String>,
    /// Nodes with `m_I <= mass_tolerance * max_J m_J` carry no unknowns.
    pub mass_tolerance: f64,
    /// Options prefix of a fallback SNES (e.g. with a direct solver) tried at the same time step when the
    /// main one's linear solver fails, before the time step is halved; None: halve at once.
    pub fallback_prefix: Option<String>,
    /// Path following of a quasi-static run (indirect displacement control); None: the prescribed
    /// motion follows time.
    pub path: Option<PathControl<D>>,
    /// The specimen's frame on the grid (`grid.rotation`): the set-up was turned by it inside the
    /// axis-aligned grid, and results are reported back through it. The identity in 3D.
    pub frame: Frame,
}

impl<const D: usize> Parameters<D> {
    /// The parameters of a run on `grid` with `materials` (one per body tag), with the defaults of a
    /// configuration file for the rest: no constraints, rigid bodies, loads or body force, MPM, nodes
    /// with `m_I <=` [`DEFAULT_MASS_TOLERANCE`] `max m` without unknowns, the main solver's options without a prefix and no
    /// fallback solver. Set the other fields with struct-update syntax:
    /// `Parameters { boxes, ..Parameters::new(grid, materials, shape, time) }`.
    pub fn new(
        grid: Grid<D>,
        materials: Vec<Material>,
        shape: ShapeKind,
        time: TimeIntegration,
    ) -> Self {
        Self {
            grid,
            materials,
            fields: Vec::new(),
            shape,
            corner_hold: crate::shape::DEFAULT_CORNER_HOLD,
            time,
            body_force: SVector::zeros(),
            body_force_ramp: 0.0,
            boxes: Vec::new(),
            rigid: Vec::new(),
            loads: Vec::new(),
            method: Method::Mpm,
            options_prefix: None,
            mass_tolerance: DEFAULT_MASS_TOLERANCE,
            fallback_prefix: None,
            path: None,
            frame: Frame::IDENTITY,
        }
    }
}

/// A run as a scenario builds it: the model's parameters and the bodies at t = 0.
/// [`Model::new`] splits it into [`Model`] and [`State`].
pub struct Setup<const D: usize = 2> {
    /// Everything but the points (kept by the [`Model`]).
    pub params: Parameters<D>,
    /// Deformable material points (body tag = index into `params.materials`).
    pub particles: Particles<D>,
    /// The points of each rigid body at t = 0 (one per entry of `params.rigid`; only positions and
    /// domains are used).
    pub rigid_points: Vec<Particles<D>>,
}

impl<const D: usize> Setup<D> {
    /// The deformable points `particles` (body tag = index into `materials`) on `grid`, with the
    /// defaults of [`Parameters::new`] and no rigid bodies.
    pub fn new(
        grid: Grid<D>,
        particles: Particles<D>,
        materials: Vec<Material>,
        shape: ShapeKind,
        time: TimeIntegration,
    ) -> Self {
        Self::of(Parameters::new(grid, materials, shape, time), particles)
    }

    /// The deformable points `particles` with `params`, and no rigid bodies' points.
    pub fn of(params: Parameters<D>, particles: Particles<D>) -> Self {
        Self {
            params,
            particles,
            rigid_points: Vec::new(),
        }
    }
}

/// What defines a run and stays fixed while it runs: the parameters and what the model derives from them.
pub struct Model<const D: usize = 2> {
    /// The run's parameters (those of the [`Setup`], with one velocity field per material).
    pub params: Parameters<D>,
    /// Node shares of every load (see [`NodalLoad::shares`]).
    pub(crate) load_shares: Vec<Vec<(usize, f64)>>,
    /// FEM mode: the shape functions of the reference configuration (that of t = 0).
    pub(crate) fem: Option<FemReference<D>>,
    /// Path following: the measured points and the load factor's reference set.
    pub(crate) path: Option<Gauge<D>>,
}

/// The FEM mode's reference shape functions, fixed at t = 0.
#[derive(Debug, Clone)]
pub(crate) struct FemReference<const D: usize> {
    /// `N_I(X_p)` and `grad_X N_I(X_p)` at the reference Gauss points.
    pub(crate) points: ShapeTable<D>,
    /// The rigid bodies' points on the grid (glued bodies constrain these nodes in every step).
    pub(crate) rigid: Vec<ShapeTable<D>>,
}

impl<const D: usize> Model<D> {
    /// The unknowns of a node: the `D` displacement components, and `eta_bar` if any material is
    /// gradient-enhanced.
    pub fn layout(&self) -> FieldLayout {
        FieldLayout::new(D, self.params.materials.iter().any(Material::is_nonlocal))
    }

    /// Number of velocity fields (1 without contact between deformable bodies).
    pub fn num_fields(&self) -> usize {
        self.params
            .fields
            .iter()
            .map(|&f| f as usize + 1)
            .max()
            .unwrap_or(1)
    }

    /// Grid node copies over all fields: field `f`'s copy of grid node `I` is node `I + f N` (the
    /// node ids of the shape-function table, the grid state and the unknowns).
    pub fn field_nodes(&self) -> usize {
        self.params.grid.num_nodes() * self.num_fields()
    }

    /// The constraint set of rigid body `k` (index into [`Parameters::rigid`]): its entry in the per-set lists
    /// of reactions and displacements (report order: node boxes, rigid bodies, loads).
    pub fn rigid_set(&self, k: usize) -> usize {
        self.params.boxes.len() + k
    }

    /// Names of the constraint sets in report order: node boxes, rigid bodies, loads.
    pub fn set_names(&self) -> Vec<String> {
        self.params
            .boxes
            .iter()
            .map(|b| b.name.clone())
            .chain(self.params.rigid.iter().map(|r| r.name.clone()))
            .chain(self.params.loads.iter().map(|l| l.name.clone()))
            .collect()
    }
}

/// Why a set-up cannot become a model (checked by [`Model::new`]).
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// No material point carries mass.
    #[error("the model has no material points")]
    Empty,
    /// The set-up is inconsistent (a device in contact without prescribed motion, a load off the grid
    /// lines, FEM with a non-linear interpolator, ...): the key, the value and what is allowed.
    #[error(transparent)]
    Invalid(#[from] BadValue),
    /// The FEM mode's reference shape functions could not be evaluated (a point outside the grid).
    #[error(transparent)]
    Shape(#[from] ShapeError),
}

impl<const D: usize> Model<D> {
    /// The model of a scenario's `setup` and the state at t = 0 (virgin material history), after checking
    /// what the step relies on: material points exist, devices in contact have both motion components
    /// prescribed, a unit normal and a friction coefficient >= 0, loads lie on grid lines, the FEM mode
    /// uses the linear interpolator, bodies on their own velocity fields use an interpolator that keeps
    /// the fields apart.
    pub fn new(mut setup: Setup<D>) -> Result<(Self, State<D>), ModelError> {
        setup.params.fields = setup.checked_fields()?;
        setup.check_devices()?;
        let params = &setup.params;
        let load_shares = params
            .loads
            .iter()
            .enumerate()
            .map(|(i, l)| {
                l.shares(&params.grid).map_err(|allowed| {
                    let (from, to) = (l.from.as_slice(), l.to.as_slice());
                    BadValue::new(
                        format!("load[{i}]"),
                        format!("`{}` from {from:?} to {to:?}", l.name),
                        allowed,
                    )
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let fem = setup.fem_reference()?;
        let path = (params.path.as_ref())
            .map(|c| Gauge::new(c, params, &setup.particles))
            .transpose()?;
        let Setup {
            params,
            mut particles,
            rigid_points,
        } = setup;
        let materials = &params.materials;
        let stride = materials.iter().map(|m| m.history_len()).max().unwrap_or(0);
        particles.resize_history(stride, 0.0);
        for p in 0..particles.len() {
            let m = &materials[particles.body[p] as usize];
            let h = particles.history_mut(p);
            m.init_history(&mut h[..m.history_len()]);
        }
        let nsets = params.boxes.len() + params.rigid.len() + params.loads.len();
        let mut state = State::new(particles, rigid_points, nsets, params.time.dt);
        if params.time.quasi_static {
            // Without inertia the points' velocities carry no energy (they are zeroed after the first step).
            state.counters.initial_energy = 0.0;
        }
        let model = Self {
            params,
            load_shares,
            fem,
            path,
        };
        Ok((model, state))
    }
}

impl<const D: usize> Setup<D> {
    /// The velocity field of each body tag (all on field 0 if none are given), after checking that there
    /// are points, one set of points per rigid body, one field per material, an interpolator that keeps
    /// several fields apart and rigid bodies on existing fields.
    fn checked_fields(&self) -> Result<Vec<u16>, ModelError> {
        if self.particles.is_empty() {
            return Err(ModelError::Empty);
        }
        let (rigid, materials) = (&self.params.rigid, &self.params.materials);
        if self.rigid_points.len() != rigid.len() {
            return Err(BadValue::new(
                "rigid_points",
                format!("{} sets of points", self.rigid_points.len()),
                format!("one set of points per rigid body ({})", rigid.len()),
            )
            .into());
        }
        let fields = match self.params.fields.is_empty() {
            true => vec![0; materials.len()],
            false => self.params.fields.clone(),
        };
        if fields.len() != materials.len() {
            return Err(BadValue::new(
                "fields",
                format!("{} velocity fields", fields.len()),
                format!("one per material, i.e. per body tag ({})", materials.len()),
            )
            .into());
        }
        let nfields = fields.iter().map(|&f| f as usize + 1).max().unwrap_or(1);
        let (method, shape) = (self.params.method, self.params.shape);
        if nfields > 1 && (shape == ShapeKind::Cpdi2 || method == Method::Fem) {
            let (key, value) = match method {
                Method::Fem => ("shape.method", "\"fem\"".to_owned()),
                Method::Mpm => ("shape.kind", format!("\"{}\"", shape.name())),
            };
            return Err(BadValue::new(
                key,
                value,
                "MPM with the linear, GIMP, CPDI1 or B-spline interpolator where a body has its own \
                 velocity field (contact between bodies; CPDI2 moves its corners on one field)",
            )
            .into());
        }
        if let Some(rb) = rigid.iter().find(|r| r.field as usize >= nfields) {
            return Err(BadValue::new(
                format!("rigid_body.{}.acts_on", rb.name),
                format!("velocity field {}", rb.field),
                format!("a velocity field of the bodies (they use {nfields})"),
            )
            .into());
        }
        Ok(fields)
    }

    /// Devices in contact need both motion components prescribed, a unit normal and a friction
    /// coefficient >= 0.
    fn check_devices(&self) -> Result<(), ModelError> {
        for rb in &self.params.rigid {
            if let Some(c) = &rb.contact {
                let prescribed = rb.motion.iter().all(|m| matches!(m, Motion::Velocity(_)));
                let unit = (c.normal.norm() - 1.0).abs() < 1e-12;
                if !(prescribed && unit && c.friction.is_finite() && c.friction >= 0.0) {
                    return Err(BadValue::new(
                        format!("rigid_body.{}.contact", rb.name),
                        format!(
                            "normal {:?}, friction {}, motion {:?}",
                            c.normal.as_slice(),
                            c.friction,
                            rb.motion
                        ),
                        "a device in contact needs both motion components prescribed (\"fixed\" or a \
                         velocity), a unit normal and a friction coefficient >= 0",
                    )
                    .into());
                }
            }
        }
        Ok(())
    }

    /// The FEM mode's reference shape functions (of the configuration at construction; the rigid bodies'
    /// nodes are fixed there too); `None` in MPM mode. FEM needs the linear interpolator.
    fn fem_reference(&self) -> Result<Option<FemReference<D>>, ModelError> {
        if self.params.method == Method::Mpm {
            return Ok(None);
        }
        if self.params.shape != ShapeKind::Linear {
            return Err(BadValue::new(
                "shape.kind",
                format!("\"{}\"", self.params.shape.name()),
                "\"linear\" (bilinear) in the FEM mode (shape.method = \"fem\")",
            )
            .into());
        }
        let table = |points: &Particles<D>| {
            let mut t = ShapeTable::new();
            t.compute(ShapeKind::Linear, &self.params.grid, points)
                .map(|()| t)
        };
        let points = table(&self.particles)?;
        let rigid = self
            .rigid_points
            .iter()
            .map(table)
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Some(FemReference { points, rigid }))
    }
}

/// What a checkpoint holds: everything of a run that changes from step to step.
#[derive(Debug, Clone)]
pub struct State<const D: usize = 2> {
    /// Deformable material points with their history (body tag = index into [`Parameters::materials`]).
    pub particles: Particles<D>,
    /// The points of each rigid body of [`Parameters::rigid`] where the body has moved them.
    pub rigid: Vec<Particles<D>>,
    /// Time, step, energies and what the constraint sets and devices carry from step to step.
    pub counters: Counters<D>,
    /// FEM mode: the nodal velocity and acceleration carried to the next step (None in MPM mode and
    /// before the first step).
    pub fem_nodal: Option<NodalState<D>>,
    /// `particles` holds this process's own points only (MPM on several processes, from the first
    /// step on; [`crate::partition`]); false: every point. Not checkpointed: a checkpoint holds every
    /// point, each process's written at the rows of their ids ([`crate::io::SharedState`]).
    pub distributed: bool,
}

/// The counters of a running simulation besides the points (the header of a checkpoint).
#[derive(Debug, Clone, PartialEq)]
pub struct Counters<const D: usize = 2> {
    /// Time reached (s).
    pub time: f64,
    /// Steps completed.
    pub step: usize,
    /// Time step to try next (s).
    pub dt: f64,
    /// Steps in a row that converged at their first try (a reduced `dt` grows again after a few).
    pub calm_steps: usize,
    /// Work of reactions and body forces so far (N mm; in 2D per mm thickness).
    pub external_work: f64,
    /// Kinetic energy of the points at t = 0 (N mm, in 2D per mm thickness; bodies start stress-free): with
    /// the external work, the energy the run has been given (`dissipated = W + E_0 - K - Psi`).
    pub initial_energy: f64,
    /// Accumulated prescribed displacement per constraint set and component (mm), in report order.
    pub accumulated: Vec<[f64; D]>,
    /// Last reactions per constraint set and component (N, in 2D per mm thickness; the trapezoidal work
    /// increment).
    pub last_reactions: Vec<[f64; D]>,
    /// What the contact sets carry from one step to the next (the rigid bodies' rotations about their
    /// pins, the last active sets).
    pub contact: ContactMemory,
    /// Where the energy went so far ([`EnergyBooks`]).
    pub books: EnergyBooks,
}

/// The energy books of a run (N mm; in 2D per mm thickness), sums over the steps so far: with the
/// external work `W`, the initial kinetic energy `E_0`, the kinetic energy `K` and the stored energy `Psi`,
/// the remainder `W + E_0 - K - Psi - damage - erosion - contact` is what the grid transfer and the time
/// integration took out ([`EnergyBooks::remainder`]); of it, `transfer` is the grid transfer's share, measured
/// ([`EnergyBooks::integration_remainder`] the rest).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EnergyBooks {
    /// Energy released by damage: per step `sum_p V^0 sum_I 6 w_I (psi_0,I^n + psi_0,I)/2 (d_I - d_I^n)`,
    /// the trapezoidal rule in the undamaged plane energy `psi_0`.
    pub damage: f64,
    /// Stored energy of eroded points, taken out of `Psi` in the step after their damage reached
    /// `erosion_damage` (they keep their mass and kinetic energy).
    pub erosion: f64,
    /// Stored energy of the points eroded in the last step, which the next step takes out of `Psi`.
    pub eroding: f64,
    /// Kinetic energy lost at the inelastic impacts of closed contact constraints: per node and step
    /// `m/2 |v_Newmark - v_device|^2 - m/2 |v - v_device|^2` against a device, `m_a m_b/(2 (m_a + m_b))
    /// (v_a - v_b)^2` in the normal direction between bodies.
    pub contact: f64,
    /// Kinetic energy the grid transfer took out (MPM, dynamic): per step the points' kinetic energy less
    /// the grid's after P2G, `K_p^n - K_I^n`, minus the same difference after G2P, `K_p^n+1 - K_I^n+1`
    /// (`K_I = sum_I m_I/2 |v_I|^2` with the lumped nodal masses and the Newmark nodal velocities), so
    /// that `W + E_0 - K_p - ...` of the points and the grid's own books differ by exactly this sum. Zero
    /// in FEM mode and quasi-statically (zero in checkpoints that predate it).
    #[serde(default)]
    pub transfer: f64,
    /// Work of the points' stresses by the time integration's trapezoidal rule: per step `sum_p V^0
    /// (P_n + P) : (F - F_n) / 2` ([`crate::assembly::Assembler::stress_work`]), so that
    /// [`EnergyBooks::law_remainder`] is what the rule took out of the law's books and the rest of the
    /// integration remainder the grid's. `None` in a run resumed from a checkpoint that predates it
    /// (its sum from t = 0 is unknown; the columns stay empty).
    #[serde(default)]
    pub stress_work: Option<f64>,
    /// The part of `stress_work` done in the step after a point eroded by the half of its last stress
    /// that the trapezoidal rule still charges (the point carries none at the step's end); `None` as
    /// `stress_work`.
    #[serde(default)]
    pub eroded_work: Option<f64>,
}

impl EnergyBooks {
    /// `W + E_0 - K - Psi - damage - erosion - contact` for the external work `work`, the initial
    /// kinetic energy `initial`, the kinetic energy `kinetic` and the stored energy `stored` (N mm).
    pub fn remainder(&self, work: f64, initial: f64, kinetic: f64, stored: f64) -> f64 {
        work + initial - kinetic - stored - self.damage - self.erosion - self.contact
    }

    /// The [`EnergyBooks::remainder`] less the grid transfer's share: what the time integration on the
    /// grid (Newmark, the time rule of the damage dissipation) and the solver tolerances took out (N mm).
    pub fn integration_remainder(&self, work: f64, initial: f64, kinetic: f64, stored: f64) -> f64 {
        self.remainder(work, initial, kinetic, stored) - self.transfer
    }

    /// The part of the integration remainder that the time rule of the stresses took: their
    /// trapezoidal work less what the law stored (`stored`, N mm) and released, `stress_work - Psi -
    /// damage - erosion` (N mm). Zero for a law integrated exactly along the step (a linear elastic
    /// one); the rest of [`EnergyBooks::integration_remainder`] is the grid's (Newmark's start from the
    /// projected acceleration, contact, the solver tolerances).
    pub fn law_remainder(&self, stored: f64) -> Option<f64> {
        self.stress_work
            .map(|w| w - stored - self.damage - self.erosion)
    }

    /// The books of a run that starts now: every sum zero.
    pub fn start() -> Self {
        Self {
            stress_work: Some(0.0),
            eroded_work: Some(0.0),
            ..Self::default()
        }
    }
}

impl<const D: usize> State<D> {
    /// The state at t = 0 of `particles` and the rigid bodies' points, with `nsets` constraint sets
    /// (boxes, rigid bodies, loads) and a first time step `dt` (s).
    pub fn new(particles: Particles<D>, rigid: Vec<Particles<D>>, nsets: usize, dt: f64) -> Self {
        let nrigid = rigid.len();
        let initial_energy = (0..particles.len())
            .map(|p| 0.5 * particles.mass[p] * particles.v[p].norm_squared())
            .sum();
        let counters = Counters {
            time: 0.0,
            step: 0,
            dt,
            calm_steps: 0,
            external_work: 0.0,
            initial_energy,
            accumulated: vec![[0.0; D]; nsets],
            last_reactions: vec![[0.0; D]; nsets],
            contact: ContactMemory::new(nrigid),
            books: EnergyBooks::start(),
        };
        Self {
            particles,
            rigid,
            counters,
            fem_nodal: None,
            distributed: false,
        }
    }

    /// This state without its points (the counters, the rigid bodies and the points' column widths):
    /// what a process that writes no points takes into the collective writes of the output.
    pub fn without_points(&self) -> Self {
        Self {
            particles: self.particles.empty_like(),
            rigid: self.rigid.clone(),
            counters: self.counters.clone(),
            fem_nodal: self.fem_nodal.clone(),
            distributed: false,
        }
    }
}

/// Nodal velocity (mm/s) and acceleration (mm/s^2), one per grid node.
pub type NodalState<const D: usize = 2> = (Vec<SVector<f64, D>>, Vec<SVector<f64, D>>);
