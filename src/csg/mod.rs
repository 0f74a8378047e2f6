//! Constructive solid geometry for the configuration's `[[body]]` sections (mm): primitives of the plane
//! (rect, polygon, disk, half-plane) or of space (box, cylinder, sphere, half-space, prism: a plane
//! geometry extruded over a z range), combined by union, intersection and difference nested to any depth
//! ([`Shape`]); a body's geometry is plane or spatial by its primitives ([`BodyShape`]).
//!
//! In TOML a geometry is a primitive `{ type = "box", min = [0, 0, 0], max = [60, 15, 15] }` or one
//! operation over a list of geometries: `{ union = [...] }`, `{ intersection = [...] }` or
//! `{ difference = [a, b, ...] }` (`a` minus `b` minus ...). docs/configuration.md lists the keys.
//!
//! Boundaries, as for [`crate::geometry`]: every node has a closure and an interior, within
//! [`BOUNDARY_TOL`]; a union's is the union of its operands', an intersection's the intersection, and a
//! difference `a - b` has the closure `closure(a) \ interior(b)` and the interior `interior(a) \
//! closure(b)`. A point is material when it lies in the closure of the root, so a point on the face of a
//! hole is kept, as with the `exclude` regions of [`crate::geometry::Geometry`].

mod primitives;
#[cfg(test)]
mod tests;

pub use primitives::{HalfSpace, PlanePrimitive, SpacePrimitive};

use crate::geometry::{BOUNDARY_TOL, Body, Geometry, GeometryError};
use crate::input::BadValue;
use nalgebra::SVector;

/// A primitive of a [`Shape`] in `D` dimensions.
pub trait Primitive<const D: usize>: Sized {
    /// The values of its `type` key, as a configuration writes them.
    const TYPES: &'static [&'static str];
    /// What to say of a `type` of the other dimension (e.g. a `box` in a plane geometry).
    const OTHER_DIMENSION: &'static str;
    /// The primitive from its TOML table at the key `key` (whose `type` is one of [`Self::TYPES`]),
    /// checked ([`Self::check`]).
    fn parse(table: &toml::Value, key: &str) -> Result<Self, BadValue>;
    /// Checks the values (finite, positive radii, corners in order); errors name the key below `key`.
    fn check(&self, key: &str) -> Result<(), BadValue>;
    /// Bounding box `(min, max)` (mm), infinite where the primitive is unbounded.
    fn bounds(&self) -> (SVector<f64, D>, SVector<f64, D>);
    /// Whether `x` (mm) lies in the closed primitive (boundary included, within [`BOUNDARY_TOL`]).
    fn in_closure(&self, x: &SVector<f64, D>) -> bool;
    /// Whether `x` (mm) lies in the open interior (at least [`BOUNDARY_TOL`] inside).
    fn in_interior(&self, x: &SVector<f64, D>) -> bool;
}

/// A geometry in `D` dimensions: a primitive or an operation over geometries.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape<P, const D: usize> {
    /// A primitive.
    Primitive(P),
    /// The points of any operand (at least one).
    Union(Vec<Shape<P, D>>),
    /// The points of every operand (at least one).
    Intersection(Vec<Shape<P, D>>),
    /// The points of the first operand in none of the others (at least two operands).
    Difference(Vec<Shape<P, D>>),
}

/// A plane geometry (x, y).
pub type PlaneShape = Shape<PlanePrimitive, 2>;
/// A geometry of space (x, y, z).
pub type SpaceShape = Shape<SpacePrimitive, 3>;

/// The operations of a [`Shape`], as keys of a TOML table.
const OPERATIONS: [&str; 3] = ["union", "intersection", "difference"];

/// What a geometry table may be, for the errors.
const NODE_FORMS: &str = "a primitive { type = \"...\", ... } or one operation over a list of \
                          geometries: { union = [...] }, { intersection = [...] } or { difference = \
                          [a, b, ...] } (a minus b minus ...)";

/// A value as an error shows it, shortened to 80 characters.
pub(crate) fn value_shown(v: &toml::Value) -> String {
    let s = v.to_string();
    match s.char_indices().nth(80) {
        Some((i, _)) => format!("{} ...", &s[..i]),
        None => s,
    }
}

impl<P: Primitive<D>, const D: usize> Shape<P, D> {
    /// The geometry of the TOML value `v` at the configuration key `key` (e.g. `body[1].geometry`),
    /// every primitive checked; errors name the key of the value at fault
    /// (`body[1].geometry.difference[0].radius`).
    pub fn parse(v: &toml::Value, key: &str) -> Result<Self, BadValue> {
        let table = v
            .as_table()
            .ok_or_else(|| BadValue::new(key, value_shown(v), NODE_FORMS))?;
        let ops: Vec<&str> = OPERATIONS
            .into_iter()
            .filter(|op| table.contains_key(*op))
            .collect();
        match (table.get("type"), ops.as_slice()) {
            (Some(kind), []) => {
                let name = kind.as_str().unwrap_or_default();
                if !P::TYPES.contains(&name) {
                    return Err(BadValue::new(
                        format!("{key}.type"),
                        value_shown(kind),
                        format!(
                            "one of {:?} ({}), or an operation: {NODE_FORMS}",
                            P::TYPES,
                            P::OTHER_DIMENSION
                        ),
                    ));
                }
                P::parse(v, key).map(Shape::Primitive)
            }
            (None, [op]) if table.len() == 1 => {
                let key = format!("{key}.{op}");
                let items = table[*op].as_array().ok_or_else(|| {
                    BadValue::new(&key, value_shown(&table[*op]), "a list of geometries")
                })?;
                let operands = items
                    .iter()
                    .enumerate()
                    .map(|(i, item)| Self::parse(item, &format!("{key}[{i}]")))
                    .collect::<Result<Vec<_>, _>>()?;
                let shape = match *op {
                    "union" => Shape::Union(operands),
                    "intersection" => Shape::Intersection(operands),
                    _ => Shape::Difference(operands),
                };
                shape.check_operands(&key)?;
                Ok(shape)
            }
            _ => {
                let keys: Vec<&str> = table.keys().map(String::as_str).collect();
                Err(BadValue::new(
                    key,
                    format!("a table with the keys {keys:?}"),
                    NODE_FORMS,
                ))
            }
        }
    }

    /// Refuses an operation with too few operands (`key`: the operation's key).
    fn check_operands(&self, key: &str) -> Result<(), BadValue> {
        let (operands, least, what) = match self {
            Shape::Primitive(_) => return Ok(()),
            Shape::Union(c) => (c, 1, "at least one geometry"),
            Shape::Intersection(c) => (c, 1, "at least one geometry"),
            Shape::Difference(c) => (c, 2, "at least two geometries: the first minus the others"),
        };
        match operands.len() >= least {
            true => Ok(()),
            false => Err(BadValue::new(
                key,
                format!("{} geometries", operands.len()),
                what,
            )),
        }
    }

    /// The operation's name and operands; `None` for a primitive.
    fn operation(&self) -> Option<(&'static str, &[Self])> {
        match self {
            Shape::Primitive(_) => None,
            Shape::Union(c) => Some(("union", c)),
            Shape::Intersection(c) => Some(("intersection", c)),
            Shape::Difference(c) => Some(("difference", c)),
        }
    }

    /// Checks every primitive and operation below `key`, then that the whole is bounded and its bounding
    /// box not empty: a half-space alone holds material without end, and operands that do not meet hold
    /// none.
    pub fn check(&self, key: &str) -> Result<(), BadValue> {
        self.check_nodes(key)?;
        let (lo, hi) = self.bounds();
        if (0..D).any(|d| !(lo[d].is_finite() && hi[d].is_finite())) {
            return Err(BadValue::new(
                key,
                "an unbounded geometry",
                "a bounded one: a half-space (half-plane) holds material without end; intersect it with \
                 a bounded geometry, e.g. { intersection = [{ type = \"box\", ... }, { type = \
                 \"half-space\", ... }] }, or subtract it from one",
            ));
        }
        if (0..D).any(|d| lo[d] > hi[d]) {
            return Err(BadValue::new(
                key,
                "a geometry with no material",
                format!(
                    "one that holds material (the operands of an intersection here do not meet: its \
                     bounding box runs from {:?} to {:?} mm)",
                    lo.as_slice(),
                    hi.as_slice()
                ),
            ));
        }
        Ok(())
    }

    /// [`Self::check`] without the checks of the whole.
    fn check_nodes(&self, key: &str) -> Result<(), BadValue> {
        match self.operation() {
            None => match self {
                Shape::Primitive(p) => p.check(key),
                _ => Ok(()),
            },
            Some((op, operands)) => {
                let key = format!("{key}.{op}");
                self.check_operands(&key)?;
                operands
                    .iter()
                    .enumerate()
                    .try_for_each(|(i, s)| s.check_nodes(&format!("{key}[{i}]")))
            }
        }
    }

    /// Bounding box `(min, max)` (mm): a union's spans its operands', an intersection's is the overlap of
    /// theirs (empty, `min > max`, when they do not meet), a difference's the first operand's; infinite
    /// where unbounded.
    pub fn bounds(&self) -> (SVector<f64, D>, SVector<f64, D>) {
        let all = |c: &[Self], lo: f64, hi: f64, union: bool| {
            let start: (SVector<f64, D>, SVector<f64, D>) =
                (SVector::repeat(lo), SVector::repeat(hi));
            c.iter()
                .map(Self::bounds)
                .fold(start, |(a, b), (l, h)| match union {
                    true => (a.inf(&l), b.sup(&h)),
                    false => (a.sup(&l), b.inf(&h)),
                })
        };
        match self {
            Shape::Primitive(p) => p.bounds(),
            Shape::Union(c) => all(c, f64::INFINITY, f64::NEG_INFINITY, true),
            Shape::Intersection(c) => all(c, f64::NEG_INFINITY, f64::INFINITY, false),
            Shape::Difference(c) => c[0].bounds(),
        }
    }

    /// Whether `x` (mm) lies in the closure (module docs).
    pub fn in_closure(&self, x: &SVector<f64, D>) -> bool {
        self.holds(x, true)
    }

    /// Whether `x` (mm) lies in the interior (module docs).
    pub fn in_interior(&self, x: &SVector<f64, D>) -> bool {
        self.holds(x, false)
    }

    /// Whether `x` (mm) lies in the closure (`closed`) or the interior: a difference takes the closure
    /// of its first operand minus the interiors of the others, and the other way round.
    fn holds(&self, x: &SVector<f64, D>, closed: bool) -> bool {
        match self {
            Shape::Primitive(p) if closed => p.in_closure(x),
            Shape::Primitive(p) => p.in_interior(x),
            Shape::Union(c) => c.iter().any(|s| s.holds(x, closed)),
            Shape::Intersection(c) => c.iter().all(|s| s.holds(x, closed)),
            Shape::Difference(c) => {
                c[0].holds(x, closed) && !c[1..].iter().any(|s| s.holds(x, !closed))
            }
        }
    }
}

impl<P: Primitive<D>, const D: usize> Body<D> for Shape<P, D> {
    /// [`Shape::check`] at the key `geometry`.
    fn validate(&self) -> Result<(), GeometryError> {
        self.check("geometry")
            .map_err(|bad| GeometryError::InvalidShape {
                key: bad.key,
                reason: format!("{}: {}", bad.value, bad.allowed),
            })
    }

    fn contains(&self, x: &SVector<f64, D>) -> bool {
        self.in_closure(x)
    }

    fn bounding_box(&self) -> Option<(SVector<f64, D>, SVector<f64, D>)> {
        let (lo, hi) = self.bounds();
        (0..D)
            .all(|d| lo[d].is_finite() && hi[d].is_finite() && lo[d] <= hi[d])
            .then_some((lo, hi))
    }
}

/// A plane body's geometry: the `include` and `exclude` lists ([`Geometry`]) or a [`PlaneShape`].
#[derive(Debug, Clone, PartialEq)]
pub enum PlaneGeometry {
    /// The union of `include` minus the union of `exclude`.
    Lists(Geometry),
    /// Primitives combined by union, intersection and difference.
    Shape(PlaneShape),
}

impl Body<2> for PlaneGeometry {
    fn validate(&self) -> Result<(), GeometryError> {
        match self {
            PlaneGeometry::Lists(g) => g.validate(),
            PlaneGeometry::Shape(s) => Body::validate(s),
        }
    }

    fn contains(&self, x: &SVector<f64, 2>) -> bool {
        match self {
            PlaneGeometry::Lists(g) => g.contains(*x),
            PlaneGeometry::Shape(s) => s.in_closure(x),
        }
    }

    fn bounding_box(&self) -> Option<(SVector<f64, 2>, SVector<f64, 2>)> {
        match self {
            PlaneGeometry::Lists(g) => g.bounding_box(),
            PlaneGeometry::Shape(s) => Body::bounding_box(s),
        }
    }
}

/// A `[[body]]`'s geometry: plane (extruded along z with `[extrusion]`) or of space (with `[extrusion]`
/// only, within the plate's z range).
#[derive(Debug, Clone, PartialEq)]
pub enum BodyShape {
    /// A plane geometry.
    Plane(PlaneGeometry),
    /// A geometry of space.
    Space(SpaceShape),
}

impl BodyShape {
    /// The geometry of the TOML table `v` (not the `include`/`exclude` form) at the key `key`: of space
    /// when its first primitive (depth first, not counting a prism's section) is one of space, plane
    /// otherwise; checked ([`Shape::check`]).
    pub fn parse(v: &toml::Value, key: &str) -> Result<Self, BadValue> {
        let shape = match first_type(v).is_some_and(|t| SpacePrimitive::TYPES.contains(&t)) {
            true => BodyShape::Space(SpaceShape::parse(v, key)?),
            false => BodyShape::Plane(PlaneGeometry::Shape(PlaneShape::parse(v, key)?)),
        };
        match &shape {
            BodyShape::Space(s) => s.check(key)?,
            BodyShape::Plane(PlaneGeometry::Shape(s)) => s.check(key)?,
            BodyShape::Plane(PlaneGeometry::Lists(_)) => {}
        }
        Ok(shape)
    }

    /// The bounding box projected on the plane (x, y), mm; `None` for an unbounded or empty geometry.
    pub fn plane_bounds(&self) -> Option<(SVector<f64, 2>, SVector<f64, 2>)> {
        match self {
            BodyShape::Plane(g) => g.bounding_box(),
            BodyShape::Space(s) => Body::bounding_box(s).map(|(lo, hi)| (lo.xy(), hi.xy())),
        }
    }

    /// Whether `x` (mm) is material, a plane geometry being extruded over `0 <= z <= thickness`.
    pub fn contains_in_space(&self, x: &SVector<f64, 3>, thickness: f64) -> bool {
        match self {
            BodyShape::Plane(g) => {
                (-BOUNDARY_TOL..=thickness + BOUNDARY_TOL).contains(&x.z) && g.contains(&x.xy())
            }
            BodyShape::Space(s) => s.in_closure(x),
        }
    }

    /// The bounding box in space (mm), a plane geometry being extruded over `0 <= z <= thickness`.
    pub fn space_bounds(&self, thickness: f64) -> Option<(SVector<f64, 3>, SVector<f64, 3>)> {
        match self {
            BodyShape::Plane(g) => g.bounding_box().map(|(lo, hi)| {
                (
                    SVector::from([lo.x, lo.y, 0.0]),
                    SVector::from([hi.x, hi.y, thickness]),
                )
            }),
            BodyShape::Space(s) => Body::bounding_box(s),
        }
    }
}

/// The `type` of the first primitive of a geometry table, depth first through its operations.
fn first_type(v: &toml::Value) -> Option<&str> {
    let table = v.as_table()?;
    if let Some(t) = table.get("type") {
        return t.as_str();
    }
    OPERATIONS
        .iter()
        .filter_map(|op| table.get(*op)?.as_array())
        .flatten()
        .find_map(first_type)
}
