//! Builds a run ([`Setup`]) from a checked configuration in two stages: the [`Plan`] (the bodies with
//! their regions, materials and velocity fields, the compact tension (CT) specimen of the source paper
//! and its plates, no points: what preflight's memory estimate reads), then the seeded bodies, rigid
//! bodies and background grid ([`Plan::build`]); with `[extrusion]` the plane set-up is extruded to a
//! plate ([`build_run`]).

use crate::boundary::{Motion, NodalLoad, NodeBox, RigidBody};
use crate::config::{
    ConfigError, ConstraintSection, ContactSection, CtSection, Keyword, LoadIntroduction,
    LoadSection, Materials, MotionSpec, NotchTip, RigidBodySection, RunConfig,
};
use crate::contact::Contact;
use crate::csg::{BodyShape, PlaneGeometry};
use crate::geometry::{Body, Geometry, Region, Seeding};
use crate::grid::Grid;
use crate::input::{BadValue, shown};
use crate::material::Material;
use crate::model::PathControl;
use crate::model::{Method, Parameters, Setup};
use crate::particles::{ParticleError, Particles, SeedingParameter};
use crate::solver_defaults;
use crate::space::{Frame, lift3};
use nalgebra::{Vector2, Vector3};
use std::collections::HashMap;

mod banded;
mod extrusion;
pub use banded::build_run_on;

/// Failure to build a run from a valid configuration.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// A value of the configuration that cannot be built, named by its key: a body's geometry that holds
    /// no material point, a cell size or points per cell that cannot seed a body, a grid with too many
    /// nodes, a constraint box that holds no grid node, a plate that cannot be extruded.
    #[error(transparent)]
    Input(#[from] BadValue),
    /// A body whose material the configuration's checks did not build (a configuration changed after
    /// it was read).
    #[error("{what}: no material was built for it (a configuration changed after it was checked)")]
    Material {
        /// Which material (`ct.material`, `body[0]`, ...).
        what: String,
    },
    /// Seeding in bands on several processes failed ([`build_run_on`]).
    #[error("seeding the processes' bands: {0}")]
    Processes(String),
}

impl ScenarioError {
    /// This error as bad input in the configuration `file` (with its overrides): a refused value with
    /// its key, anything else as a failed build.
    pub fn in_file(self, file: &str) -> ConfigError {
        match self {
            ScenarioError::Input(bad) => ConfigError::in_file(file, bad),
            e => ConfigError::Build {
                file: file.to_owned(),
                message: e.to_string(),
            },
        }
    }
}

/// Whether the box `[min, max]` (mm, with the solver's 1e-9 mm tolerance) contains a node of `grid`.
fn box_holds_a_node(grid: &Grid, min: [f64; 2], max: [f64; 2]) -> bool {
    let (o, h) = (grid.origin(), grid.cell_size());
    let n = [grid.nx() as f64, grid.ny() as f64];
    (0..2).all(|k| {
        let first = ((min[k] - 1e-9 - o[k]) / h).ceil().max(0.0);
        let last = ((max[k] + 1e-9 - o[k]) / h).floor().min(n[k]);
        first <= last
    })
}

/// The notch cut out of the CT plate: a strip from beyond the left edge to the tip, square-ended
/// (`flat`) or ended by a semicircle of radius `notch_width / 2` whose apex is at `notch_length` (`round`).
fn notch(ct: &CtSection) -> Vec<Region> {
    let (mid, half) = (0.5 * ct.height, 0.5 * ct.notch_width);
    let strip = Region::Rect {
        min: [-1.0, mid - half],
        max: [ct.straight_faces_end(), mid + half],
    };
    match ct.notch_tip {
        NotchTip::Flat => vec![strip],
        NotchTip::Round => vec![
            strip,
            Region::Disk {
                centre: [ct.straight_faces_end(), mid],
                radius: half,
            },
        ],
    }
}

/// A deformable body before seeding.
struct BodyDef {
    /// The configuration key its geometry comes from (`body[1].geometry`, `ct`), for errors.
    key: String,
    name: String,
    geometry: BodyShape,
    density: f64,
    material: Material,
    velocity: Vector2<f64>,
    /// Its own velocity field (contact with the specimen) instead of the specimen's.
    own_field: bool,
}

/// The set-up a configuration runs: the plane one, or the plate it is extruded to (`[extrusion]`).
pub enum RunSetup {
    /// Plane strain (no `[extrusion]`).
    Plane(Setup<2>),
    /// The plane set-up extruded to a plate of finite thickness, run in 3D.
    Plate(Setup<3>),
}

/// The run of `plan` in the dimensions it runs in: [`Plan::build`], then with `[extrusion]` the
/// extrusion to the plate, the bodies with a geometry of space seeded in space among the extruded ones
/// (in the order of the bodies).
pub fn build_run(plan: Plan<'_>) -> Result<RunSetup, ScenarioError> {
    let extrusion = plan.config().extrusion.clone();
    let (plane, solids) = plan.build_parts()?;
    match &extrusion {
        None => no_solids(&solids).map(|()| RunSetup::Plane(plane)),
        Some(e) => {
            let mut plate = plane.extrude(e.thickness)?;
            if !solids.is_empty() {
                plate.particles = merge_by_body(&plate.particles, &solids).map_err(|e| {
                    BadValue::new(
                        "body",
                        "(the bodies' points)",
                        format!("bodies seeded alike: {e}"),
                    )
                })?;
            }
            Ok(RunSetup::Plate(plate))
        }
    }
}

/// Refuses points of bodies with a geometry of space in a plane run (the configuration's checks
/// refuse such bodies without `[extrusion]`).
fn no_solids(solids: &Particles<3>) -> Result<(), ScenarioError> {
    match solids.is_empty() {
        true => Ok(()),
        false => Err(BadValue::new(
            "extrusion",
            "(none)",
            "an [extrusion] section for the bodies with a geometry of space (a run in 3D)",
        )
        .into()),
    }
}

/// The points of `a` and `b` (each in the order of the bodies) as one set in the order of the bodies,
/// the points of a body keeping their order; ids numbered anew from 0.
fn merge_by_body(a: &Particles<3>, b: &Particles<3>) -> Result<Particles<3>, ParticleError> {
    let last = a.body.iter().chain(&b.body).copied().max().unwrap_or(0);
    let mut out = Particles::new();
    for tag in 0..=last {
        for set in [a, b] {
            let keep: Vec<bool> = set.body.iter().map(|&t| t == tag).collect();
            if keep.contains(&true) {
                let mut part = set.clone();
                part.retain(&keep);
                out.append(&part)?;
            }
        }
    }
    out.id = (0..out.len() as u64).collect();
    Ok(out)
}

/// The plane set-up described by `cfg` (options prefix: none, so plain `-snes_*` options apply):
/// [`plan`], then [`Plan::build`].
pub fn build(cfg: &RunConfig) -> Result<Setup, ScenarioError> {
    plan(cfg)?.build()
}

/// The CT specimen's plane body (a geometry of `include` and `exclude` lists).
fn plane_lists(include: Vec<Region>, exclude: Vec<Region>) -> BodyShape {
    BodyShape::Plane(PlaneGeometry::Lists(Geometry { include, exclude }))
}

/// A configuration's run before seeding: its deformable bodies (regions, density, the material the
/// checks built, initial velocity, velocity field) and its rigid bodies (the configuration's, then the
/// CT's plates), without points. Preflight's memory estimate and [`Plan::build`] read the same plan.
pub struct Plan<'c> {
    /// The checked configuration.
    cfg: &'c RunConfig,
    /// The deformable bodies in tag order (the CT's concrete and inserts first).
    bodies: Vec<BodyDef>,
    /// The rigid bodies: the configuration's, then the CT's two plates.
    rigid: Vec<RigidBodySection>,
    /// The configuration key of each rigid body's geometry, for errors.
    rigid_keys: Vec<String>,
}

/// The plan of the run described by `cfg`.
pub fn plan(cfg: &RunConfig) -> Result<Plan<'_>, ScenarioError> {
    let mut bodies = Vec::new();
    let mut rigid: Vec<RigidBodySection> = cfg.rigid_body.clone();
    let built = cfg.materials();
    if let Some(ct) = &cfg.ct {
        let (ct_bodies, plates) = ct_specimen(ct, built)?;
        bodies.extend(ct_bodies);
        rigid.extend(plates);
    }
    for (i, b) in cfg.body.iter().enumerate() {
        bodies.push(BodyDef {
            key: format!("body[{i}].geometry"),
            name: b.name.clone(),
            geometry: b.shape(i)?,
            density: b.density,
            material: built_material(built.bodies.get(i), &format!("body[{i}] ({})", b.name))?,
            velocity: Vector2::new(b.initial_velocity[0], b.initial_velocity[1]),
            own_field: b.own_field,
        });
    }
    let rigid_keys = (0..rigid.len())
        .map(|i| match i < cfg.rigid_body.len() {
            true => format!("rigid_body[{i}].geometry"),
            false => "ct.plate_thickness".to_owned(),
        })
        .collect();
    Ok(Plan {
        cfg,
        bodies,
        rigid,
        rigid_keys,
    })
}

impl Plan<'_> {
    /// The configuration the plan was made from.
    pub fn config(&self) -> &RunConfig {
        self.cfg
    }

    /// The steps' inertia ratio `r` before anything is seeded (`None`: quasi-static), from the densities
    /// and P-wave moduli of the deformable bodies as [`solver_defaults::inertia_ratio`] takes it from the
    /// seeded points.
    pub fn inertia_ratio(&self) -> Option<f64> {
        let time = &self.cfg.time;
        if time.quasi_static {
            return None;
        }
        let rho_over_modulus = self
            .bodies
            .iter()
            .map(|b| b.density / solver_defaults::p_wave_modulus(&b.material))
            .fold(f64::INFINITY, f64::min);
        Some(solver_defaults::ratio(
            rho_over_modulus,
            self.cfg.grid.cell_size,
            time.beta,
            time.dt,
        ))
    }

    /// The material points of the plane set-up, deformable and rigid, as seeding will place them
    /// (counted, none stored; [`Seeding::count`]: an estimate for a lattice too large to count); the
    /// bodies with a geometry of space are [`Plan::space_points`].
    pub fn points(&self) -> Result<f64, ScenarioError> {
        let seeder = Seeder::new(self.cfg);
        let mut n = self.body_points(&seeder, false)?;
        for (r, key) in self.rigid.iter().zip(&self.rigid_keys) {
            n += seeder.count((key, &r.name), &r.geometry, 1.0)?;
        }
        Ok(n)
    }

    /// The material points of the bodies with a geometry of space, counted as [`Plan::points`].
    pub fn space_points(&self) -> Result<f64, ScenarioError> {
        self.body_points(&Seeder::new(self.cfg), true)
    }

    /// The points of the deformable bodies with a geometry of space (`space`) or of the plane.
    fn body_points(&self, seeder: &Seeder, space: bool) -> Result<f64, ScenarioError> {
        let mut n = 0.0;
        for b in &self.bodies {
            let id = (b.key.as_str(), b.name.as_str());
            n += match (&b.geometry, space) {
                (BodyShape::Plane(g), false) => seeder.count(id, g, b.density)?,
                (BodyShape::Space(s), true) => seeder.count(id, s, b.density)?,
                _ => 0.0,
            };
        }
        Ok(n)
    }

    /// The bounding box of the include regions of every body and rigid body in the plane (mm), the
    /// geometries of space projected on it.
    pub fn extent(&self) -> Option<(Vector2<f64>, Vector2<f64>)> {
        let bodies = self.bodies.iter().filter_map(|b| b.geometry.plane_bounds());
        bodies
            .chain(self.rigid.iter().filter_map(|r| r.geometry.bounding_box()))
            .reduce(|(lo, hi), (l, h)| (lo.inf(&l), hi.sup(&h)))
    }

    /// The velocity fields of the bodies: field 0 and one per body with its own.
    pub fn num_fields(&self) -> usize {
        1 + velocity_fields(&self.bodies).1.len()
    }

    /// The plane set-up: the bodies and rigid bodies seeded, the grid that covers them, the node boxes,
    /// the loads and the time integration of the configuration. Refuses bodies with a geometry of space
    /// ([`build_run`] runs them).
    pub fn build(self) -> Result<Setup, ScenarioError> {
        let (setup, solids) = self.build_parts()?;
        no_solids(&solids)?;
        Ok(setup)
    }

    /// [`Plan::build`], the bodies with a geometry of space seeded apart in space (in the order of the
    /// bodies, tagged by body) and the grid covering them too in the plane.
    fn build_parts(self) -> Result<(Setup, Particles<3>), ScenarioError> {
        let Plan {
            cfg,
            bodies,
            rigid,
            rigid_keys,
        } = self;
        let (fields, field_of) = velocity_fields(&bodies);
        let seeder = Seeder::new(cfg);
        let (particles, materials, solids) = seeder.bodies(bodies)?;
        let (rigid, rigid_points) = seeder.rigid_bodies(&rigid, &rigid_keys, &field_of)?;
        let mut seeded = Seeded {
            particles,
            materials,
            fields,
            rigid,
            rigid_points,
        };
        let frame = cfg.grid.frame();
        if !frame.is_identity() {
            seeded.turn(&frame);
        }
        let in_plane = solids.x.iter().map(|x| x.xy());
        let bounds = bounds(seeded.particles.x.iter().copied().chain(in_plane));
        Ok((seeded.setup(cfg, bounds)?, solids))
    }
}

/// The seeded parts of a plane set-up before its grid: the deformable bodies' points (all of them, or
/// this process's band), their materials and velocity fields, the rigid bodies and their points.
struct Seeded {
    particles: Particles,
    materials: Vec<Material>,
    fields: Vec<u16>,
    rigid: Vec<RigidBody>,
    rigid_points: Vec<Particles>,
}

impl Seeded {
    /// The parts turned by `frame` inside the grid.
    fn turn(&mut self, frame: &Frame) {
        turn_points(frame, &mut self.particles);
        let rigid_points = self.rigid_points.iter_mut();
        rigid_points.for_each(|p| turn_points(frame, p));
        self.rigid
            .iter_mut()
            .for_each(|r| turn_rigid_body(frame, r));
    }

    /// The plane set-up of `cfg` from these parts: the grid covering the bodies' points (within
    /// `body_bounds`, mm: of every point, also where this process holds a band only) and the rigid
    /// bodies' points, the node boxes, the loads and the time integration.
    fn setup(self, cfg: &RunConfig, body_bounds: Bounds) -> Result<Setup, ScenarioError> {
        let frame = cfg.grid.frame();
        warn_far_rigid_body(cfg, body_bounds, &self.rigid_points);
        let grid = covering_grid(cfg, body_bounds, &self.rigid_points)?;
        let boxes = node_boxes(&cfg.constraint, &grid, cfg.grid.cell_size)?;
        Ok(Setup {
            // The solver prefixes keep their defaults: they are the solver's, not the file's.
            params: Parameters {
                fields: self.fields,
                body_force: frame.to_grid(Vector2::new(cfg.body_force[0], cfg.body_force[1])),
                body_force_ramp: cfg.body_force_ramp,
                boxes,
                rigid: self.rigid,
                loads: cfg.load.iter().map(nodal_load).collect(),
                method: cfg.shape.method,
                mass_tolerance: cfg.grid.mass_tolerance,
                corner_hold: cfg.shape.corner_hold,
                path: cfg.path.as_ref().map(|p| PathControl {
                    from: frame.to_grid(Vector2::from(p.from)),
                    to: frame.to_grid(Vector2::from(p.to)),
                    direction: frame.to_grid(Vector2::from(p.direction())),
                    increment: p.increment,
                }),
                frame,
                ..Parameters::new(grid, self.materials, cfg.shape.kind, cfg.time.integration())
            },
            particles: self.particles,
            rigid_points: self.rigid_points,
        })
    }
}

/// A bounding box in the plane (mm): lower and upper corner, `(+inf, -inf)` per axis for no point.
type Bounds = (Vector2<f64>, Vector2<f64>);

/// The bounding box of `points` (mm).
fn bounds(points: impl Iterator<Item = Vector2<f64>>) -> Bounds {
    points.fold(
        (
            Vector2::repeat(f64::INFINITY),
            Vector2::repeat(f64::NEG_INFINITY),
        ),
        |(lo, hi), x| (lo.inf(&x), hi.sup(&x)),
    )
}

/// The points of a set-up turned by `frame` inside the grid: positions, velocities, accelerations, CPDI
/// half-edges and corners by `R`, the deformation gradient and the stress by `R . R^T`.
fn turn_points(frame: &Frame, p: &mut Particles) {
    let r = frame.matrix();
    let rt = r.transpose();
    let vectors = p.x.iter_mut().chain(&mut p.v).chain(&mut p.a);
    vectors.chain(&mut p.corners).for_each(|x| *x = r * *x);
    p.r.iter_mut().chain(&mut p.r0).for_each(|m| *m = r * *m);
    p.f.iter_mut().for_each(|f| *f = r * *f * rt);
    let r3 = lift3(&r);
    p.stress
        .iter_mut()
        .for_each(|s| *s = r3 * *s * r3.transpose());
}

/// A rigid body of a set-up turned by `frame`: its velocity, contact normal and pin turned (the
/// configuration's checks let through only motions free or prescribed in both components).
fn turn_rigid_body(frame: &Frame, body: &mut RigidBody) {
    if let [Motion::Velocity(vx), Motion::Velocity(vy)] = body.motion {
        let v = frame.to_grid(Vector2::new(vx, vy));
        body.motion = [Motion::Velocity(v.x), Motion::Velocity(v.y)];
    }
    if let Some(c) = &mut body.contact {
        c.normal = frame.to_grid(c.normal);
        c.pin = c.pin.map(|pin| frame.to_grid(pin));
    }
}

/// A material the configuration's checks built (`what` names it in the error when there is none).
fn built_material(material: Option<&Material>, what: &str) -> Result<Material, ScenarioError> {
    material.cloned().ok_or_else(|| ScenarioError::Material {
        what: what.to_owned(),
    })
}

/// The CT specimen's deformable bodies (the concrete, and with `load_introduction = "inserts"` the two
/// steel inserts) and its two plates, the loading plate first; `built` holds their materials.
fn ct_specimen(
    ct: &CtSection,
    built: &Materials,
) -> Result<(Vec<BodyDef>, [RigidBodySection; 2]), ScenarioError> {
    let mut bodies = vec![BodyDef {
        key: "ct".into(),
        name: "concrete".into(),
        geometry: plane_lists(
            vec![Region::Rect {
                min: [0.0, 0.0],
                max: [ct.width, ct.height],
            }],
            notch(ct),
        ),
        density: ct.density,
        material: built_material(built.concrete.as_ref(), "ct.material")?,
        velocity: Vector2::zeros(),
        own_field: false,
    }];
    let (inserts, faces) = ct_inserts(ct, built)?;
    let acts_on = [0, 1].map(|k| inserts.get(k).map(|b: &BodyDef| b.name.clone()));
    bodies.extend(inserts);
    Ok((bodies, ct_plates(ct, faces, acts_on)))
}

/// The steel inserts on the notch faces (none unless `load_introduction = "inserts"`), each on its own
/// velocity field, and the faces the plates then push on (y of the loading and the support face, mm): the
/// inserts' inner faces, or the notch faces; `built` holds the inserts' material.
fn ct_inserts(
    ct: &CtSection,
    built: &Materials,
) -> Result<(Vec<BodyDef>, [f64; 2]), ScenarioError> {
    let (mid, half) = (0.5 * ct.height, 0.5 * ct.notch_width);
    let (lower, upper) = (mid - half, mid + half);
    let ti = match ct.load_introduction {
        LoadIntroduction::Inserts => ct.insert_thickness.unwrap_or(0.0),
        _ => 0.0,
    };
    let (load_face, support_face) = (lower + ti, upper - ti);
    let mut inserts = Vec::new();
    if ti > 0.0 {
        let [a, b] = ct.load_zone;
        let [sa, sb] = ct.support_zone.unwrap_or(ct.load_zone);
        for (name, min, max) in [
            ("loading_insert", [a, lower], [b, load_face]),
            ("support_insert", [sa, support_face], [sb, upper]),
        ] {
            inserts.push(BodyDef {
                key: "ct.insert_thickness".into(),
                name: name.into(),
                geometry: plane_lists(vec![Region::Rect { min, max }], vec![]),
                density: ct.insert_density,
                material: built_material(built.insert.as_ref(), "ct.insert_material")?,
                velocity: Vector2::zeros(),
                own_field: true,
            });
        }
    }
    Ok((inserts, [load_face, support_face]))
}

/// The CT's loading and support plates on the faces at `faces` (y, mm), acting on the bodies `acts_on`
/// (the inserts; none: the concrete).
fn ct_plates(
    ct: &CtSection,
    [load_face, support_face]: [f64; 2],
    acts_on: [Option<String>; 2],
) -> [RigidBodySection; 2] {
    let [a, b] = ct.load_zone;
    let [sa, sb] = ct.support_zone.unwrap_or(ct.load_zone);
    let t = ct.plate_thickness;
    let (down, up) = if ct.symmetric {
        (-0.5 * ct.loading_rate, 0.5 * ct.loading_rate)
    } else {
        (-ct.loading_rate, 0.0)
    };
    let velocity = |v: f64| MotionSpec::Velocity { velocity: v };
    // The plates' x motion: glued, the loading plate is x-free and the support holds x (a clamp),
    // both x-free when symmetric (mirror images of each other); in contact both are driven in x at
    // zero velocity, which holds nothing unless friction acts (mirror-identical either way).
    let (x_load, x_support) = match (ct.load_introduction, ct.symmetric) {
        (LoadIntroduction::Glued, false) => (Keyword::Free.into(), Keyword::Fixed.into()),
        (LoadIntroduction::Glued, true) => (Keyword::Free.into(), Keyword::Free.into()),
        _ => (velocity(0.0), velocity(0.0)),
    };
    // Contact: outward normals from the plates into the concrete; pins on the plates' mid-lines (or at
    // pin_x), pin_offset into the plates from their faces.
    let offset = ct.pin_offset.unwrap_or(0.5 * t);
    let contact = |normal: [f64; 2], pin: [f64; 2]| match ct.load_introduction {
        LoadIntroduction::Glued => None,
        LoadIntroduction::Contact => Some(ContactSection {
            normal,
            friction: ct.friction,
            pin: None,
        }),
        LoadIntroduction::Pin | LoadIntroduction::Inserts => Some(ContactSection {
            normal,
            friction: ct.friction,
            pin: Some(pin),
        }),
    };
    let [load_on, support_on] = acts_on;
    let plate = |name: &str, min, max, x, y, contact, acts_on| RigidBodySection {
        name: name.into(),
        geometry: Geometry {
            include: vec![Region::Rect { min, max }],
            exclude: vec![],
        },
        x,
        y: velocity(y),
        rise_time: ct.rise_time,
        contact,
        acts_on,
    };
    [
        plate(
            "loading_plate",
            [a, load_face],
            [b, load_face + t],
            x_load,
            down,
            contact(
                [0.0, -1.0],
                [ct.pin_x.unwrap_or(0.5 * (a + b)), load_face + offset],
            ),
            load_on,
        ),
        plate(
            "support_plate",
            [sa, support_face - t],
            [sb, support_face],
            x_support,
            up,
            contact(
                [0.0, 1.0],
                [ct.pin_x.unwrap_or(0.5 * (sa + sb)), support_face - offset],
            ),
            support_on,
        ),
    ]
}

/// The velocity field of each body, 0 for the specimen and the bodies bonded to it, 1, 2, ... for the
/// bodies with their own (in order), and the fields of the latter by name.
fn velocity_fields(bodies: &[BodyDef]) -> (Vec<u16>, HashMap<String, u16>) {
    let mut fields = Vec::with_capacity(bodies.len());
    let mut field_of = HashMap::new();
    for body in bodies {
        let f = if body.own_field {
            field_of.len() as u16 + 1
        } else {
            0
        };
        if body.own_field {
            field_of.insert(body.name.clone(), f);
        }
        fields.push(f);
    }
    (fields, field_of)
}

/// Seeds the bodies of a configuration: cell size, points per cell and the seeding of its method.
struct Seeder {
    /// Cell size h (mm).
    h: f64,
    /// Points per cell and direction.
    ppc: usize,
    /// Points at the Gauss points of the cells (FEM) instead of in the cells (MPM).
    gauss: bool,
}

impl Seeder {
    /// The seeding of `cfg`.
    fn new(cfg: &RunConfig) -> Self {
        Self {
            h: cfg.grid.cell_size,
            ppc: cfg.shape.points_per_cell,
            gauss: cfg.shape.method == Method::Fem,
        }
    }

    /// The seeding of a body of `density` (t/mm^3) tagged `body`.
    fn seeding(&self, density: f64, body: u16) -> Seeding {
        Seeding {
            h: self.h,
            points_per_cell: self.ppc,
            density,
            body,
        }
    }

    /// The number of points of `geometry` with `density`, as [`Seeder::points`] seeds them (an estimate
    /// for a lattice too large to count, [`Seeding::count`]); `key` and `name` name the body in errors.
    fn count<const D: usize, B: Body<D>>(
        &self,
        (key, name): (&str, &str),
        geometry: &B,
        density: f64,
    ) -> Result<f64, BadValue> {
        self.seeding(density, 0)
            .count(geometry, self.gauss)
            .map_err(|e| self.refused((key, name), e))
    }

    /// The points of `geometry` with `density`, tagged `body`; `key` and `name` name the body in errors.
    fn points<const D: usize, B: Body<D>>(
        &self,
        id: (&str, &str),
        geometry: &B,
        density: f64,
        body: u16,
    ) -> Result<Particles<D>, BadValue> {
        let seeding = self.seeding(density, body);
        let seeded = match self.gauss {
            true => Particles::seed_gauss(geometry, &seeding),
            false => Particles::seed(geometry, &seeding),
        };
        seeded.map_err(|e| self.refused(id, e))
    }

    /// The refused value behind the seeding error `e` of the body `key` (its geometry's configuration
    /// key) named `name`: the body's geometry, or the cell size or points per cell that cannot seed it.
    fn refused(&self, (key, name): (&str, &str), e: ParticleError) -> BadValue {
        let body = format!("`{name}`");
        let ppc = self.ppc;
        match e {
            ParticleError::NoPoints => BadValue::new(
                key,
                body,
                format!(
                    "a geometry that holds a material point at cell size {} mm with {ppc}x{ppc} points \
                     per cell (this one holds none)",
                    self.h
                ),
            ),
            ParticleError::InvalidSeeding {
                parameter: SeedingParameter::CellSize,
                reason,
            } => BadValue::new(
                "grid.cell_size",
                shown(self.h),
                format!("a cell size that can seed {key} ({body}): {reason}"),
            ),
            ParticleError::InvalidSeeding {
                parameter: SeedingParameter::PointsPerCell,
                reason,
            } => BadValue::new(
                "shape.points_per_cell",
                ppc.to_string(),
                format!("points per cell that can seed {key} ({body}): {reason}"),
            ),
            e => BadValue::new(key, body, format!("a body that can be seeded: {e}")),
        }
    }

    /// The deformable bodies' points (tagged by body, with their initial velocities) and materials: the
    /// points of the plane bodies, and apart those of the bodies with a geometry of space.
    fn bodies(
        &self,
        bodies: Vec<BodyDef>,
    ) -> Result<(Particles, Vec<Material>, Particles<3>), ScenarioError> {
        let mut particles = Particles::new();
        let mut solids = Particles::<3>::new();
        let mut materials = Vec::new();
        for (tag, body) in bodies.into_iter().enumerate() {
            let id = (body.key.as_str(), body.name.as_str());
            let appended = match &body.geometry {
                BodyShape::Plane(g) => {
                    let mut p = self.points(id, g, body.density, tag as u16)?;
                    p.v.iter_mut().for_each(|v| *v = body.velocity);
                    particles.append(&p)
                }
                BodyShape::Space(s) => {
                    let mut p = self.points(id, s, body.density, tag as u16)?;
                    let v = Vector3::new(body.velocity.x, body.velocity.y, 0.0);
                    p.v.iter_mut().for_each(|pv| *pv = v);
                    solids.append(&p)
                }
            };
            appended.map_err(|e| self.refused(id, e))?;
            materials.push(body.material);
        }
        Ok((particles, materials, solids))
    }

    /// The rigid bodies of `defs` and their points (`keys`: the configuration key of each one's geometry);
    /// `field_of` gives the velocity field of the bodies they
    /// may act on.
    fn rigid_bodies(
        &self,
        defs: &[RigidBodySection],
        keys: &[String],
        field_of: &HashMap<String, u16>,
    ) -> Result<(Vec<RigidBody>, Vec<Particles>), ScenarioError> {
        let (mut rigid, mut rigid_points) = (Vec::new(), Vec::new());
        for (r, key) in defs.iter().zip(keys) {
            rigid_points.push(self.points((key, &r.name), &r.geometry, 1.0, 0)?);
            rigid.push(RigidBody {
                name: r.name.clone(),
                motion: [r.x.motion(), r.y.motion()],
                rise_time: r.rise_time,
                field: r
                    .acts_on
                    .as_ref()
                    .and_then(|name| field_of.get(name).copied())
                    .unwrap_or(0),
                contact: r.contact.as_ref().map(|c| Contact {
                    normal: Vector2::from(c.normal).normalize(),
                    friction: c.friction,
                    pin: c.pin.map(Vector2::from),
                }),
            });
        }
        Ok((rigid, rigid_points))
    }
}

/// Warns when a rigid body far from the bodies (within `(blo, bhi)`, mm) makes the covering grid more than
/// 16 times the cells the bodies alone need (the unknowns and the memory grow with it). Called once per
/// set-up, by [`Seeded::setup`], whatever grids were built before it (the bands are cut on the same grid).
fn warn_far_rigid_body(cfg: &RunConfig, (blo, bhi): Bounds, rigid_points: &[Particles]) {
    let (rlo, rhi) = bounds(rigid_points.iter().flat_map(|r| r.x.iter().copied()));
    let (lo, hi) = (blo.inf(&rlo), bhi.sup(&rhi));
    let (h, margin) = (cfg.grid.cell_size, cfg.grid.margin_cells.max(1));
    let cells = |lo: Vector2<f64>, hi: Vector2<f64>| {
        ((hi - lo) / h).map(|e| e.ceil().max(1.0) as usize + 2 * margin)
    };
    let (all, own) = (cells(lo, hi), cells(blo, bhi));
    if blo.x.is_finite() && rlo.x.is_finite() && all.product() > 16 * own.product() {
        tracing::warn!(
            "the grid is {}x{} cells, the bodies alone need {}x{}: a [[rigid_body]] lies far from them \
             (the grid covers every rigid body's points; place it nearer the bodies)",
            all.x,
            all.y,
            own.x,
            own.y
        );
    }
}

/// The grid that covers the points of the bodies (within `(blo, bhi)`, mm: the plane ones and, in the
/// plane, those of space) and of the rigid bodies with `grid.margin_cells` (at least one) empty cells
/// around them.
fn covering_grid(
    cfg: &RunConfig,
    (blo, bhi): Bounds,
    rigid_points: &[Particles],
) -> Result<Grid, ScenarioError> {
    let (rlo, rhi) = bounds(rigid_points.iter().flat_map(|r| r.x.iter().copied()));
    let (lo, hi) = (blo.inf(&rlo), bhi.sup(&rhi));
    let (h, margin) = (cfg.grid.cell_size, cfg.grid.margin_cells.max(1));
    Grid::covering(lo, hi, h, margin).map_err(|e| {
        // The margin or the cell size, whichever makes the most of the grid's cells.
        let body_cells = ((hi - lo) / h).max();
        let (key, value) = match 2.0 * margin as f64 >= body_cells {
            true => ("grid.margin_cells", margin.to_string()),
            false => ("grid.cell_size", shown(h)),
        };
        BadValue::new(key, value, format!("a grid that can be built: {e}")).into()
    })
}

/// The node boxes of the `[[constraint]]` sections; each must hold a node of `grid` (cell size `h`, mm).
fn node_boxes(
    constraints: &[ConstraintSection],
    grid: &Grid,
    h: f64,
) -> Result<Vec<NodeBox>, ScenarioError> {
    if let Some((i, c)) = constraints
        .iter()
        .enumerate()
        .find(|(_, c)| !box_holds_a_node(grid, c.min, c.max))
    {
        let (lo, hi) = (grid.origin(), grid.upper());
        return Err(BadValue::new(
            format!("constraint[{i}]"),
            format!("`{}`, the box {:?}..{:?} mm", c.name, c.min, c.max),
            format!(
                "a box that holds a grid node (this one holds no grid node: the grid spans {:?}..{:?} mm \
                 with nodes every {h} mm)",
                [lo.x, lo.y],
                [hi.x, hi.y]
            ),
        )
        .into());
    }
    Ok(constraints
        .iter()
        .map(|c| NodeBox {
            name: c.name.clone(),
            min: Vector2::new(c.min[0], c.min[1]),
            max: Vector2::new(c.max[0], c.max[1]),
            motion: [c.x.motion(), c.y.motion()],
            rise_time: c.rise_time,
        })
        .collect())
}

/// The nodal load of a `[[load]]` section.
fn nodal_load(l: &LoadSection) -> NodalLoad {
    NodalLoad {
        name: l.name.clone(),
        from: Vector2::from(l.from),
        to: Vector2::from(l.to),
        force: Vector2::from(l.force),
        rise_time: l.rise_time,
    }
}
