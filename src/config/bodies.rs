//! The sections of what is simulated besides the CT generator: `[[body]]`, `[[constraint]]`, `[[load]]`
//! and `[[rigid_body]]` (with its `contact`), with their checks and the rule for the names that become
//! history.csv columns.

use super::{
    Check, ConfigError, DENSITY_ALLOWED, LOAD_FORCE_MAX, SPEED_ALLOWED, TIME_ALLOWED, density_ok,
    finite, shown, speed_ok, time_ok,
};
use crate::csg::{BodyShape, PlaneGeometry};
use crate::geometry::{BOUNDARY_TOL, Body, Geometry};
use crate::input::BadValue;
use crate::material::{Material, MaterialConfig};
use crate::particles::lattice;
use nalgebra::SVector;
use serde::Deserialize;

/// `[[body]]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySection {
    /// Name.
    pub name: String,
    /// Density (t/mm^3), e.g. 2.4e-9 for concrete.
    pub density: f64,
    /// Geometry: the union of include regions minus exclude regions, or primitives of the plane or of
    /// space combined by union, intersection and difference ([`crate::csg`]).
    pub geometry: BodyGeometry,
    /// Constitutive law.
    pub material: MaterialConfig,
    /// Initial velocity (mm/s).
    #[serde(default)]
    pub initial_velocity: [f64; 2],
    /// The body has its own velocity field on the grid and meets the specimen (the first body) only
    /// through frictionless unilateral contact; default false: it shares the specimen's grid nodes
    /// (bonded where they touch).
    #[serde(default)]
    pub own_field: bool,
}

/// A `[[body]]`'s geometry as written: the `include` and `exclude` lists of plane regions (read at
/// once), or a geometry of [`crate::csg`] (read, with errors that name its keys, by
/// [`BodySection::shape`]).
#[derive(Debug, Clone, Deserialize)]
#[serde(try_from = "toml::Value")]
pub enum BodyGeometry {
    /// `{ include = [...], exclude = [...] }`.
    Lists(Geometry),
    /// Any other table: a primitive or an operation over geometries.
    Shape(toml::Value),
}

impl TryFrom<toml::Value> for BodyGeometry {
    type Error = String;

    /// The lists when the table has `include` or `exclude`, else the table as it is.
    fn try_from(v: toml::Value) -> Result<Self, String> {
        let lists = v
            .as_table()
            .is_some_and(|t| t.contains_key("include") || t.contains_key("exclude"));
        match lists {
            true => v
                .try_into()
                .map(BodyGeometry::Lists)
                .map_err(|e: toml::de::Error| e.message().trim().replace('\n', " ")),
            false => Ok(BodyGeometry::Shape(v)),
        }
    }
}

impl BodySection {
    /// The geometry of this body, the `i`-th `[[body]]`: the lists as they are (checked by
    /// [`Geometry::validate`]), or a [`crate::csg`] geometry read and checked, errors naming the key
    /// under `body[i].geometry`.
    pub fn shape(&self, i: usize) -> Result<BodyShape, BadValue> {
        match &self.geometry {
            BodyGeometry::Lists(g) => Ok(BodyShape::Plane(PlaneGeometry::Lists(g.clone()))),
            BodyGeometry::Shape(v) => BodyShape::parse(v, &format!("body[{i}].geometry")),
        }
    }
}

/// Motion of one component: "free", "fixed" or `{ velocity = v }` (mm/s).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(try_from = "toml::Value")]
pub enum MotionSpec {
    /// "free" or "fixed".
    Keyword(Keyword),
    /// Prescribed velocity.
    Velocity {
        /// mm/s.
        velocity: f64,
    },
}

/// Keywords of [`MotionSpec`].
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Keyword {
    /// Not constrained.
    Free,
    /// Zero velocity.
    Fixed,
}

impl TryFrom<toml::Value> for MotionSpec {
    type Error = String;

    /// The forms of a component's motion; anything else is refused with the allowed forms listed.
    fn try_from(v: toml::Value) -> Result<Self, String> {
        let velocity = match &v {
            toml::Value::String(s) if s == "free" => return Ok(Keyword::Free.into()),
            toml::Value::String(s) if s == "fixed" => return Ok(Keyword::Fixed.into()),
            toml::Value::Table(t) if t.len() == 1 => t.get("velocity"),
            _ => None,
        };
        match velocity {
            Some(toml::Value::Float(f)) => Ok(MotionSpec::Velocity { velocity: *f }),
            Some(toml::Value::Integer(i)) => Ok(MotionSpec::Velocity {
                velocity: *i as f64,
            }),
            _ => Err(format!(
                "{v}: a component's motion is \"free\", \"fixed\" or {{ velocity = v }} (mm/s)"
            )),
        }
    }
}

impl From<Keyword> for MotionSpec {
    fn from(k: Keyword) -> Self {
        MotionSpec::Keyword(k)
    }
}

impl Default for MotionSpec {
    fn default() -> Self {
        MotionSpec::Keyword(Keyword::Free)
    }
}

impl MotionSpec {
    /// As the solver's motion.
    pub fn motion(self) -> crate::boundary::Motion {
        use crate::boundary::Motion;
        match self {
            MotionSpec::Keyword(Keyword::Free) => Motion::Free,
            MotionSpec::Keyword(Keyword::Fixed) => Motion::Velocity(0.0),
            MotionSpec::Velocity { velocity } => Motion::Velocity(velocity),
        }
    }
}

/// `[[constraint]]`: grid nodes in a box.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstraintSection {
    /// Name (reaction-force columns).
    pub name: String,
    /// Box lower-left corner (mm).
    pub min: [f64; 2],
    /// Box upper-right corner (mm).
    pub max: [f64; 2],
    /// x component.
    #[serde(default)]
    pub x: MotionSpec,
    /// y component.
    #[serde(default)]
    pub y: MotionSpec,
    /// Prescribed velocities rise linearly from zero over this time (s); default 0 (a step).
    #[serde(default)]
    pub rise_time: f64,
}

/// `[[load]]`: a force distributed over the grid nodes on a segment as a uniform traction.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadSection {
    /// Name (history columns `NAME_ux, NAME_uy, NAME_fx, NAME_fy`).
    pub name: String,
    /// Start of the segment (mm); the segment lies on a grid line (horizontal or vertical).
    pub from: [f64; 2],
    /// End of the segment (mm).
    pub to: [f64; 2],
    /// Resultant force (N per mm thickness).
    pub force: [f64; 2],
    /// The force rises linearly from zero over this time (s); default 0 (applied at once).
    #[serde(default)]
    pub rise_time: f64,
}

/// `[[rigid_body]]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigidBodySection {
    /// Name (reaction-force columns).
    pub name: String,
    /// Geometry of the body.
    pub geometry: Geometry,
    /// x component.
    #[serde(default)]
    pub x: MotionSpec,
    /// y component.
    #[serde(default)]
    pub y: MotionSpec,
    /// Prescribed velocities rise linearly from zero over this time (s); default 0 (a step).
    #[serde(default)]
    pub rise_time: f64,
    /// Unilateral contact with the specimen instead of gluing (default: glued).
    #[serde(default)]
    pub contact: Option<ContactSection>,
    /// The `[[body]]` with `own_field = true` it holds or pushes (by name); default: the specimen and
    /// the bodies that share its nodes.
    #[serde(default)]
    pub acts_on: Option<String>,
}

/// `contact = { normal = [nx, ny], friction = mu, pin = [x, y] }` of a `[[rigid_body]]`: the device pushes
/// on the specimen through its flat face with the outward normal `normal` (from the device into the
/// specimen; normalised), never pulls, with Coulomb friction `friction` (-, default 0), and, with `pin`
/// (mm), is driven at the pin and turns freely about it.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactSection {
    /// Outward normal of the contact face (from the device into the specimen).
    pub normal: [f64; 2],
    /// Coulomb friction coefficient (-), default 0 (frictionless).
    #[serde(default)]
    pub friction: f64,
    /// Pin position at t = 0 (mm); none: the device only translates.
    #[serde(default)]
    pub pin: Option<[f64; 2]>,
}

/// Refuses two `[[body]]` regions that overlap (their points would be seeded twice there): a test on a
/// lattice of points at most half a cell `h` (mm) apart over the intersection of each pair's bounding
/// boxes (at most 200 per direction in the plane, 40 in space), off the boxes' edges so that bodies that
/// only touch pass. `shapes` are the bodies' geometries; with a plate of `thickness` (mm, `[extrusion]`)
/// a pair with a geometry of space is tested in space, the plane one extruded over the plate.
pub(super) fn check_overlaps(
    bodies: &[BodySection],
    shapes: &[BodyShape],
    h: f64,
    thickness: Option<f64>,
    c: Check,
) -> Result<(), ConfigError> {
    for (j, b) in shapes.iter().enumerate() {
        for (i, a) in shapes[..j].iter().enumerate() {
            let inside = match (a, b, thickness) {
                (BodyShape::Plane(a), BodyShape::Plane(b), _) => plane_overlap(a, b, h),
                (a, b, Some(t)) => space_overlap(a, b, h, t),
                _ => None,
            };
            if let Some(x) = inside {
                return Err(c.bad(
                    &format!("body[{j}].geometry"),
                    format!("(overlaps body[{i}] `{}` at {x} mm)", bodies[i].name),
                    "a region no other [[body]] covers: the points of both would be seeded there \
                     (give one an exclude region, or subtract the other with a difference)",
                ));
            }
        }
    }
    Ok(())
}

/// A point (shown) of two plane geometries' common material: [`check_overlaps`].
fn plane_overlap(a: &PlaneGeometry, b: &PlaneGeometry, h: f64) -> Option<String> {
    let ((alo, ahi), (blo, bhi)) = (a.bounding_box()?, b.bounding_box()?);
    let (lo, hi) = (alo.sup(&blo), ahi.inf(&bhi));
    let extent = hi - lo;
    if extent.x <= 0.0 || extent.y <= 0.0 {
        return None;
    }
    let n = extent.map(|e| (2.0 * e / h).ceil().clamp(1.0, 200.0) as usize);
    let step = extent.component_div(&n.map(|k| k as f64));
    (0..n.x)
        .flat_map(|u| (0..n.y).map(move |v| (u, v)))
        .find_map(|(u, v)| {
            let x =
                lo + step.component_mul(&nalgebra::Vector2::new(u as f64 + 0.5, v as f64 + 0.5));
            (a.contains(&x) && b.contains(&x)).then_some(x)
        })
        .map(|x| format!("({:.3}, {:.3})", x.x, x.y))
}

/// A point (shown) of two bodies' common material in space, a plane geometry extruded over the plate's
/// `thickness` (mm): [`check_overlaps`].
fn space_overlap(a: &BodyShape, b: &BodyShape, h: f64, thickness: f64) -> Option<String> {
    let ((alo, ahi), (blo, bhi)) = (a.space_bounds(thickness)?, b.space_bounds(thickness)?);
    let (lo, hi) = (alo.sup(&blo), ahi.inf(&bhi));
    let extent = hi - lo;
    if extent.iter().any(|e| *e <= 0.0) {
        return None;
    }
    let n: [usize; 3] =
        std::array::from_fn(|d| (2.0 * extent[d] / h).ceil().clamp(1.0, 40.0) as usize);
    lattice(n)
        .map(|k| {
            SVector::<f64, 3>::from_fn(|d, _| lo[d] + extent[d] / n[d] as f64 * (k[d] as f64 + 0.5))
        })
        .find(|x| a.contains_in_space(x, thickness) && b.contains_in_space(x, thickness))
        .map(|x| format!("({:.3}, {:.3}, {:.3})", x.x, x.y, x.z))
}

/// Refuses the geometry of space `shape` of `body[i]` without a plate (`thickness`, mm, of
/// `[extrusion]`) or beyond its `0 <= z <= thickness`.
fn check_space_body(
    shape: &BodyShape,
    i: usize,
    thickness: Option<f64>,
    c: Check,
) -> Result<(), ConfigError> {
    let BodyShape::Space(s) = shape else {
        return Ok(());
    };
    let key = format!("body[{i}].geometry");
    let Some(t) = thickness else {
        return Err(c.bad(
            &key,
            "(a geometry of space)".into(),
            "a plane geometry (rect, polygon, disk, half-plane), or [extrusion] with a thickness for \
             a run in 3D, the geometry of space within its 0 <= z <= thickness",
        ));
    };
    let (lo, hi) = s.bounds();
    if lo.z < -BOUNDARY_TOL || hi.z > t + BOUNDARY_TOL {
        return Err(c.bad(
            &key,
            format!(
                "(a geometry of space from z = {} to {} mm)",
                shown(lo.z),
                shown(hi.z)
            ),
            &format!(
                "one within 0 <= z <= extrusion.thickness = {} mm, the z extent of the run (the \
                 plane parts, rigid bodies and constraints, are extruded over it): raise \
                 extrusion.thickness or move the body",
                shown(t)
            ),
        ));
    }
    Ok(())
}

/// Checks the `[[body]]` sections and returns their materials and geometries; `ct`: the run has a `[ct]`
/// section (whose bodies' names are taken, and whose concrete is the specimen); `thickness`: the plate's
/// of `[extrusion]` (mm), which geometries of space need.
pub(super) fn validate_bodies(
    bodies: &[BodySection],
    ct: bool,
    thickness: Option<f64>,
    c: Check,
) -> Result<(Vec<Material>, Vec<BodyShape>), ConfigError> {
    let mut materials = Vec::with_capacity(bodies.len());
    let mut shapes = Vec::with_capacity(bodies.len());
    for (i, b) in bodies.iter().enumerate() {
        if b.name.trim().is_empty() {
            return Err(c.bad(&format!("body[{i}].name"), "\"\"".into(), "a name"));
        }
        // Names are unique (`acts_on` refers to them), and [ct] names its own bodies.
        let reserved: &[&str] = if ct {
            &["concrete", "loading_insert", "support_insert"]
        } else {
            &[]
        };
        if reserved.contains(&b.name.as_str()) || bodies[..i].iter().any(|o| o.name == b.name) {
            return Err(c.bad(
                &format!("body[{i}].name"),
                format!("{:?}", b.name),
                &format!("a name no other body has (with [ct] also not one of {reserved:?})"),
            ));
        }
        if !density_ok(b.density) {
            return Err(c.bad(
                &format!("body[{i}].density"),
                shown(b.density),
                DENSITY_ALLOWED,
            ));
        }
        if !speed_ok(&b.initial_velocity) {
            return Err(c.bad(
                &format!("body[{i}].initial_velocity"),
                format!("{:?}", b.initial_velocity),
                SPEED_ALLOWED,
            ));
        }
        let shape = b.shape(i).map_err(|e| ConfigError::in_file(c.file, e))?;
        if let BodyShape::Plane(PlaneGeometry::Lists(g)) = &shape {
            g.validate().map_err(|e| {
                c.bad(
                    &format!("body[{i}].geometry"),
                    format!("(body {:?})", b.name),
                    &e.to_string(),
                )
            })?;
        }
        check_space_body(&shape, i, thickness, c)?;
        shapes.push(shape);
        materials.push(
            b.material
                .build()
                .map_err(|e| c.material(&format!("body[{i}].material"), &e))?,
        );
        if b.own_field && i == 0 && !ct {
            return Err(c.bad(
                "body[0].own_field",
                "true".into(),
                "false: the first body is the specimen, which the bodies with their own field meet \
                 in contact",
            ));
        }
    }
    Ok((materials, shapes))
}

/// Checks the motions `x` and `y` of the section `field` and the time `rise_time` over which they rise.
fn validate_motion(
    c: Check,
    field: &str,
    [x, y]: [&MotionSpec; 2],
    rise_time: f64,
) -> Result<(), ConfigError> {
    for (axis, m) in [("x", x), ("y", y)] {
        let ok = match m {
            MotionSpec::Velocity { velocity } => speed_ok(&[*velocity]),
            MotionSpec::Keyword(_) => true,
        };
        if !ok {
            return Err(c.bad(
                &format!("{field}.{axis}"),
                format!("{m:?}"),
                "\"free\", \"fixed\" or { velocity = v } with a finite v of at most 1e7 mm/s (10 \
                 km/s) in magnitude",
            ));
        }
    }
    if !time_ok(rise_time) {
        return Err(c.bad(
            &format!("{field}.rise_time"),
            shown(rise_time),
            TIME_ALLOWED,
        ));
    }
    Ok(())
}

impl ConstraintSection {
    /// Checks the `i`-th `[[constraint]]`.
    pub(super) fn validate(&self, c: Check, i: usize) -> Result<(), ConfigError> {
        let field = format!("constraint[{i}]");
        if !finite(&self.min) || !finite(&self.max) || (0..2).any(|k| self.min[k] > self.max[k]) {
            return Err(c.bad(
                &format!("{field}.min/max"),
                format!("{:?}/{:?}", self.min, self.max),
                "finite corners with min <= max in both directions (mm)",
            ));
        }
        validate_motion(c, &field, [&self.x, &self.y], self.rise_time)
    }
}

impl RigidBodySection {
    /// Checks the `i`-th `[[rigid_body]]` of a run with the deformable bodies `bodies`.
    pub(super) fn validate(
        &self,
        c: Check,
        i: usize,
        bodies: &[BodySection],
    ) -> Result<(), ConfigError> {
        let field = format!("rigid_body[{i}]");
        if let Some(name) = &self.acts_on
            && !bodies.iter().any(|b| b.own_field && &b.name == name)
        {
            let own: Vec<&str> = bodies
                .iter()
                .filter(|b| b.own_field)
                .map(|b| b.name.as_str())
                .collect();
            return Err(c.bad(
                &format!("{field}.acts_on"),
                format!("{name:?}"),
                &format!("the name of a [[body]] with own_field = true: {own:?}"),
            ));
        }
        self.geometry
            .validate()
            .map_err(|e| c.bad(&format!("{field}.geometry"), String::new(), &e.to_string()))?;
        validate_motion(c, &field, [&self.x, &self.y], self.rise_time)?;
        match &self.contact {
            Some(contact) => contact.validate(c, &field, [&self.x, &self.y]),
            None => Ok(()),
        }
    }
}

impl ContactSection {
    /// Checks the `contact` of the rigid body `field` that moves with `motion` (x, y).
    fn validate(&self, c: Check, field: &str, motion: [&MotionSpec; 2]) -> Result<(), ConfigError> {
        let norm = (self.normal[0] * self.normal[0] + self.normal[1] * self.normal[1]).sqrt();
        if !(finite(&self.normal) && norm > 0.0) {
            return Err(c.bad(
                &format!("{field}.contact.normal"),
                format!("{:?}", self.normal),
                "a finite non-zero vector, the outward normal of the contact face (from the \
                 device into the specimen)",
            ));
        }
        if !(self.friction.is_finite() && self.friction >= 0.0) {
            return Err(c.bad(
                &format!("{field}.contact.friction"),
                shown(self.friction),
                "a Coulomb coefficient >= 0 (0 = frictionless)",
            ));
        }
        if self.pin.is_some_and(|p| !finite(&p)) {
            return Err(c.bad(
                &format!("{field}.contact.pin"),
                format!("{:?}", self.pin),
                "a finite point (mm)",
            ));
        }
        for (axis, m) in [("x", motion[0]), ("y", motion[1])] {
            if !matches!(
                m,
                MotionSpec::Velocity { .. } | MotionSpec::Keyword(Keyword::Fixed)
            ) {
                return Err(c.bad(
                    &format!("{field}.{axis}"),
                    format!("{m:?}"),
                    "\"fixed\" or { velocity = v }: a device in contact is driven in both \
                     directions (a free component would need the device's mass)",
                ));
            }
        }
        Ok(())
    }
}

impl LoadSection {
    /// Checks the `i`-th `[[load]]`.
    pub(super) fn validate(&self, c: Check, i: usize) -> Result<(), ConfigError> {
        let axis_aligned = self.from[0] == self.to[0] || self.from[1] == self.to[1];
        if !finite(&self.from)
            || !finite(&self.to)
            || !self
                .force
                .iter()
                .all(|f| f.is_finite() && f.abs() <= LOAD_FORCE_MAX)
            || !axis_aligned
            || self.from == self.to
        {
            return Err(c.bad(
                &format!("load[{i}] ({}).from/to/force", self.name),
                format!("{:?}/{:?}/{:?}", self.from, self.to, self.force),
                "finite values, force components of at most 1e9 N and a horizontal or vertical segment of non-zero length (mm)",
            ));
        }
        if !time_ok(self.rise_time) {
            return Err(c.bad(
                &format!("load[{i}] ({}).rise_time", self.name),
                shown(self.rise_time),
                TIME_ALLOWED,
            ));
        }
        Ok(())
    }
}

/// Checks the names of the constraint sets, rigid bodies and loads, which name history.csv columns:
/// `sets` holds (section, name) in the order of the file ([ct] first with its two plates).
pub(super) fn validate_names(c: Check, sets: &[(String, &str)]) -> Result<(), ConfigError> {
    for (k, (field, name)) in sets.iter().enumerate() {
        let column_safe = |ch: char| ch.is_ascii_alphanumeric() || "_-.".contains(ch);
        if name.is_empty() || !name.chars().all(column_safe) {
            return Err(c.bad(
                &format!("{field}.name"),
                format!("{name:?}"),
                "letters, digits, _, - or . (it names columns of history.csv)",
            ));
        }
        if let Some((other, _)) = sets[..k].iter().find(|(_, n)| n == name) {
            return Err(c.bad(
                &format!("{field}.name"),
                format!("{name:?}"),
                &format!(
                    "a name not used by {other} (the names of constraints, rigid bodies and loads are history.csv columns{})",
                    if other == "ct" {
                        "; [ct] uses loading_plate and support_plate"
                    } else {
                        ""
                    }
                ),
            ));
        }
    }
    Ok(())
}
