//! Builds a run ([`Setup`]) from a configuration: seeds the bodies, the rigid bodies and the background
//! grid, and the compact tension (CT) specimen of the source paper.

use crate::boundary::{NodalLoad, NodeBox, RigidBody};
use crate::config::{
    ConstraintSection, ContactSection, CtSection, Keyword, LoadIntroduction, MotionSpec, NotchTip,
    RigidBodySection, RunConfig,
};
use crate::contact::Contact;
use crate::grid::{Grid, GridError};
use crate::material::{Material, MaterialError};
use crate::model::{Method, Setup, TimeIntegration};
use crate::particles::{Geometry, ParticleError, Particles, Region, Seeding};
use nalgebra::Vector2;

/// Failure to build a run from a valid configuration.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// Seeding failed (e.g. a geometry with no material).
    #[error("{what}: {source}")]
    Seeding {
        /// Which body.
        what: String,
        /// Cause.
        source: ParticleError,
    },
    /// A body's geometry holds no grid cell centre: no material point.
    #[error(
        "{what}: the geometry contains no material point at cell size {h} mm with {ppc}x{ppc} points per cell"
    )]
    NoMaterial {
        /// Which body.
        what: String,
        /// Cell size (mm).
        h: f64,
        /// Points per cell and direction.
        ppc: usize,
    },
    /// Invalid material.
    #[error("{what}: {source}")]
    Material {
        /// Which body.
        what: String,
        /// Cause.
        source: MaterialError,
    },
    /// Grid construction failed.
    #[error(transparent)]
    Grid(#[from] GridError),
    /// A constraint box contains no grid node, so it would constrain nothing.
    #[error(
        "constraint `{name}`: the box {min:?}..{max:?} mm holds no grid node (the grid spans {lo:?}..{hi:?} mm with nodes every {h} mm)"
    )]
    EmptyBox {
        /// Constraint name.
        name: String,
        /// Box corners (mm).
        min: [f64; 2],
        /// Box corners (mm).
        max: [f64; 2],
        /// Grid extent (mm).
        lo: [f64; 2],
        /// Grid extent (mm).
        hi: [f64; 2],
        /// Cell size (mm).
        h: f64,
    },
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
    name: String,
    geometry: Geometry,
    density: f64,
    material: Material,
    velocity: Vector2<f64>,
    /// Its own velocity field (contact with the specimen) instead of the specimen's.
    own_field: bool,
}

/// The run described by `cfg` (options prefix: none, so plain `-snes_*` options apply).
pub fn build(cfg: &RunConfig) -> Result<Setup, ScenarioError> {
    let h = cfg.grid.cell_size;
    let ppc = cfg.shape.points_per_cell;
    let seed = match cfg.shape.method {
        Method::Mpm => Particles::seed,
        Method::Fem => Particles::seed_gauss,
    };
    let mut bodies = Vec::new();
    let mut constraints: Vec<ConstraintSection> = cfg.constraint.clone();
    let mut rigid_defs: Vec<RigidBodySection> = cfg.rigid_body.clone();
    if let Some(ct) = &cfg.ct {
        let (mid, half) = (0.5 * ct.height, 0.5 * ct.notch_width);
        let (lower, upper) = (mid - half, mid + half);
        bodies.push(BodyDef {
            name: "concrete".into(),
            geometry: Geometry {
                include: vec![Region::Rect {
                    min: [0.0, 0.0],
                    max: [ct.width, ct.height],
                }],
                exclude: notch(ct),
            },
            density: ct.density,
            material: ct
                .material
                .build()
                .map_err(|source| ScenarioError::Material {
                    what: "ct.material".into(),
                    source,
                })?,
            velocity: Vector2::zeros(),
            own_field: false,
        });
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
        // Steel inserts on the notch faces, each on its own velocity field; the plates then push on the
        // inserts' inner faces.
        let ti = match ct.load_introduction {
            LoadIntroduction::Inserts => ct.insert_thickness.unwrap_or(0.0),
            _ => 0.0,
        };
        let (load_face, support_face) = (lower + ti, upper - ti);
        let mut acts_on = [None, None];
        if ti > 0.0 {
            for (k, (name, min, max)) in [
                ("loading_insert", [a, lower], [b, load_face]),
                ("support_insert", [sa, support_face], [sb, upper]),
            ]
            .into_iter()
            .enumerate()
            {
                bodies.push(BodyDef {
                    name: name.into(),
                    geometry: Geometry {
                        include: vec![Region::Rect { min, max }],
                        exclude: vec![],
                    },
                    density: ct.insert_density,
                    material: ct.insert_material.build().map_err(|source| {
                        ScenarioError::Material {
                            what: "ct.insert_material".into(),
                            source,
                        }
                    })?,
                    velocity: Vector2::zeros(),
                    own_field: true,
                });
                acts_on[k] = Some(name.to_string());
            }
        }
        rigid_defs.push(RigidBodySection {
            name: "loading_plate".into(),
            geometry: Geometry {
                include: vec![Region::Rect {
                    min: [a, load_face],
                    max: [b, load_face + t],
                }],
                exclude: vec![],
            },
            x: x_load,
            y: velocity(down),
            rise_time: ct.rise_time,
            contact: contact(
                [0.0, -1.0],
                [ct.pin_x.unwrap_or(0.5 * (a + b)), load_face + offset],
            ),
            acts_on: acts_on[0].clone(),
        });
        rigid_defs.push(RigidBodySection {
            name: "support_plate".into(),
            geometry: Geometry {
                include: vec![Region::Rect {
                    min: [sa, support_face - t],
                    max: [sb, support_face],
                }],
                exclude: vec![],
            },
            x: x_support,
            y: velocity(up),
            rise_time: ct.rise_time,
            contact: contact(
                [0.0, 1.0],
                [ct.pin_x.unwrap_or(0.5 * (sa + sb)), support_face - offset],
            ),
            acts_on: acts_on[1].clone(),
        });
    }
    for (i, b) in cfg.body.iter().enumerate() {
        bodies.push(BodyDef {
            name: b.name.clone(),
            geometry: b.geometry.clone(),
            density: b.density,
            material: b
                .material
                .build()
                .map_err(|source| ScenarioError::Material {
                    what: format!("body[{i}] ({})", b.name),
                    source,
                })?,
            velocity: Vector2::new(b.initial_velocity[0], b.initial_velocity[1]),
            own_field: b.own_field,
        });
    }
    // Velocity fields: 0 for the specimen and the bodies bonded to it, 1, 2, ... for the bodies with
    // their own (in order).
    let mut fields = Vec::with_capacity(bodies.len());
    let mut field_of = std::collections::HashMap::new();
    for body in &bodies {
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
    let mut particles = Particles::new();
    let mut materials = Vec::new();
    for (tag, body) in bodies.into_iter().enumerate() {
        let what = format!("body `{}`", body.name);
        let seeding = Seeding {
            h,
            points_per_cell: ppc,
            density: body.density,
            body: tag as u16,
        };
        let mut p = seed(&body.geometry, &seeding).map_err(|source| ScenarioError::Seeding {
            what: what.clone(),
            source,
        })?;
        if p.is_empty() {
            return Err(ScenarioError::NoMaterial { what, h, ppc });
        }
        p.v.iter_mut().for_each(|v| *v = body.velocity);
        particles
            .append(&p)
            .map_err(|source| ScenarioError::Seeding { what, source })?;
        materials.push(body.material);
    }
    let (mut rigid, mut rigid_points) = (Vec::new(), Vec::new());
    for r in &rigid_defs {
        let what = format!("rigid body `{}`", r.name);
        let seeding = Seeding {
            h,
            points_per_cell: ppc,
            density: 1.0,
            body: 0,
        };
        let p = seed(&r.geometry, &seeding).map_err(|source| ScenarioError::Seeding {
            what: what.clone(),
            source,
        })?;
        if p.is_empty() {
            return Err(ScenarioError::NoMaterial { what, h, ppc });
        }
        rigid_points.push(p);
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
    let mut lo = Vector2::repeat(f64::INFINITY);
    let mut hi = Vector2::repeat(f64::NEG_INFINITY);
    for x in particles
        .x
        .iter()
        .chain(rigid_points.iter().flat_map(|r| r.x.iter()))
    {
        lo = lo.inf(x);
        hi = hi.sup(x);
    }
    let grid = Grid::covering(lo, hi, h, cfg.grid.margin_cells.max(1))?;
    if let Some(c) = constraints
        .iter()
        .find(|c| !box_holds_a_node(&grid, c.min, c.max))
    {
        let (lo, hi) = (grid.origin(), grid.upper());
        return Err(ScenarioError::EmptyBox {
            name: c.name.clone(),
            min: c.min,
            max: c.max,
            lo: [lo.x, lo.y],
            hi: [hi.x, hi.y],
            h,
        });
    }
    let boxes = constraints
        .drain(..)
        .map(|c| NodeBox {
            name: c.name,
            min: Vector2::new(c.min[0], c.min[1]),
            max: Vector2::new(c.max[0], c.max[1]),
            motion: [c.x.motion(), c.y.motion()],
            rise_time: c.rise_time,
        })
        .collect();
    let t = &cfg.time;
    Ok(Setup {
        grid,
        particles,
        materials,
        fields,
        shape: cfg.shape.kind,
        time: TimeIntegration {
            dt: t.dt,
            dt_min: t.dt_min.unwrap_or(t.dt / 64.0),
            beta: t.beta,
            gamma: t.gamma,
            quasi_static: t.quasi_static,
            initial_acceleration: t.initial_acceleration,
        },
        body_force: Vector2::new(cfg.body_force[0], cfg.body_force[1]),
        body_force_ramp: cfg.body_force_ramp,
        boxes,
        rigid,
        rigid_points,
        loads: cfg
            .load
            .iter()
            .map(|l| NodalLoad {
                name: l.name.clone(),
                from: Vector2::from(l.from),
                to: Vector2::from(l.to),
                force: Vector2::from(l.force),
                rise_time: l.rise_time,
            })
            .collect(),
        method: cfg.shape.method,
        options_prefix: None,
        mass_tolerance: cfg.grid.mass_tolerance,
        fallback_prefix: None,
    })
}
