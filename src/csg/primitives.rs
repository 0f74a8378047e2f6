//! The primitives of [`super::Shape`] (mm): in the plane the regions of [`crate::geometry`] (rect,
//! polygon, disk) and the half-plane; in space the box and the cylinder of [`crate::solids`], the sphere,
//! the half-space and the prism (a plane [`PlaneShape`] extruded over a z range).

use super::{PlaneShape, Primitive, value_shown};
use crate::geometry::{BOUNDARY_TOL, Region};
use crate::input::{BadValue, shown};
use crate::solids::Solid;
use nalgebra::{SVector, Vector2, Vector3};
use serde::Deserialize;
use serde::de::DeserializeOwned;

/// The half-space `(x - point) . normal <= 0` (mm): the side of the plane through `point` away from
/// its outward unit `normal`; a half-plane in 2D.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HalfSpace<const D: usize> {
    /// A point of the bounding plane (mm).
    pub point: SVector<f64, D>,
    /// Outward unit normal.
    pub normal: SVector<f64, D>,
}

impl<const D: usize> HalfSpace<D> {
    /// The half-space through `point` with the outward `normal` (normalised); the keys of the error
    /// are `key.point` and `key.normal`.
    fn new(point: [f64; D], normal: [f64; D], key: &str) -> Result<Self, BadValue> {
        let (point, normal) = (SVector::from(point), SVector::from(normal));
        let h = Self { point, normal };
        h.check(key)?;
        Ok(Self {
            point,
            normal: normal.normalize(),
        })
    }

    /// A finite point and a finite non-zero normal.
    fn check(&self, key: &str) -> Result<(), BadValue> {
        finite(self.point.as_slice(), &format!("{key}.point"))?;
        let n = self.normal.norm();
        if !(n.is_finite() && n > 0.0) {
            return Err(BadValue::new(
                format!("{key}.normal"),
                format!("{:?}", self.normal.as_slice()),
                "a finite non-zero vector, the outward normal (pointing away from the material)",
            ));
        }
        Ok(())
    }

    /// Signed distance (mm) from the bounding plane, positive outside.
    fn height(&self, x: &SVector<f64, D>) -> f64 {
        (x - self.point).dot(&self.normal)
    }
}

/// Refuses a non-finite component of the vector at `key`.
fn finite(v: &[f64], key: &str) -> Result<(), BadValue> {
    match v.iter().all(|c| c.is_finite()) {
        true => Ok(()),
        false => Err(BadValue::new(
            key,
            format!("{v:?}"),
            "finite components (mm)",
        )),
    }
}

/// Refuses a radius that is not finite and > 0 (mm) at `key`.
fn radius_ok(radius: f64, key: &str) -> Result<(), BadValue> {
    match radius.is_finite() && radius > 0.0 {
        true => Ok(()),
        false => Err(BadValue::new(key, shown(radius), "a radius > 0 (mm)")),
    }
}

/// Refuses corners `min`, `max` of a rect or box (at `key`) that are not finite or not in order.
fn corners_ok(min: &[f64], max: &[f64], key: &str) -> Result<(), BadValue> {
    finite(min, &format!("{key}.min"))?;
    finite(max, &format!("{key}.max"))?;
    match min.iter().zip(max).all(|(a, b)| a < b) {
        true => Ok(()),
        false => Err(BadValue::new(
            format!("{key}.max"),
            format!("{max:?} with min = {min:?}"),
            "max > min in every direction (mm): an inverted or flat box holds no material",
        )),
    }
}

/// Refuses a vector of the table at `key` whose length is not `d` (`z` ranges: 2; a prism's `section`
/// is checked as a plane geometry of its own), then reads the table as `T`.
fn read<T: DeserializeOwned>(v: &toml::Value, key: &str, d: usize) -> Result<T, BadValue> {
    let numeric = |x: &toml::Value| matches!(x, toml::Value::Integer(_) | toml::Value::Float(_));
    let length_ok = |x: &toml::Value, k: &str, want: usize| match x.as_array() {
        Some(items) if !items.is_empty() && items.iter().all(numeric) && items.len() != want => {
            Err(BadValue::new(
                k,
                value_shown(x),
                format!("{want} components (mm), not {}", items.len()),
            ))
        }
        _ => Ok(()),
    };
    for (k, x) in v.as_table().into_iter().flatten() {
        let at = format!("{key}.{k}");
        match k.as_str() {
            "section" => {}
            "z" => length_ok(x, &at, 2)?,
            _ => {
                length_ok(x, &at, d)?;
                for (i, item) in x.as_array().into_iter().flatten().enumerate() {
                    length_ok(item, &format!("{at}[{i}]"), d)?;
                }
            }
        }
    }
    v.clone()
        .try_into::<T>()
        .map_err(|e| BadValue::new(key, value_shown(v), e.message().trim().replace('\n', " ")))
}

/// A plane primitive as written.
#[derive(Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
enum PlaneSpec {
    Rect { min: [f64; 2], max: [f64; 2] },
    Polygon { vertices: Vec<[f64; 2]> },
    Disk { centre: [f64; 2], radius: f64 },
    HalfPlane { point: [f64; 2], normal: [f64; 2] },
}

/// A primitive of a plane geometry.
#[derive(Debug, Clone, PartialEq)]
pub enum PlanePrimitive {
    /// A rect, polygon or disk.
    Region(Region),
    /// A half-plane.
    HalfPlane(HalfSpace<2>),
}

impl Primitive<2> for PlanePrimitive {
    const TYPES: &'static [&'static str] = &["rect", "polygon", "disk", "half-plane"];
    const OTHER_DIMENSION: &'static str = "the primitives of a plane geometry; a geometry is of \
                                           space when its first primitive is a box, cylinder, sphere, \
                                           half-space or prism";

    fn parse(table: &toml::Value, key: &str) -> Result<Self, BadValue> {
        let p = match read::<PlaneSpec>(table, key, 2)? {
            PlaneSpec::Rect { min, max } => PlanePrimitive::Region(Region::Rect { min, max }),
            PlaneSpec::Polygon { vertices } => PlanePrimitive::Region(Region::Polygon { vertices }),
            PlaneSpec::Disk { centre, radius } => {
                PlanePrimitive::Region(Region::Disk { centre, radius })
            }
            PlaneSpec::HalfPlane { point, normal } => {
                PlanePrimitive::HalfPlane(HalfSpace::new(point, normal, key)?)
            }
        };
        p.check(key)?;
        Ok(p)
    }

    fn check(&self, key: &str) -> Result<(), BadValue> {
        match self {
            PlanePrimitive::Region(Region::Rect { min, max }) => corners_ok(min, max, key),
            PlanePrimitive::Region(Region::Disk { centre, radius }) => {
                finite(centre, &format!("{key}.centre"))?;
                radius_ok(*radius, &format!("{key}.radius"))
            }
            PlanePrimitive::Region(polygon) => polygon.validate().map_err(|reason| {
                BadValue::new(format!("{key}.vertices"), "(the polygon)", reason)
            }),
            PlanePrimitive::HalfPlane(h) => h.check(key),
        }
    }

    fn bounds(&self) -> (Vector2<f64>, Vector2<f64>) {
        match self {
            PlanePrimitive::Region(r) => r.bounding_box(),
            PlanePrimitive::HalfPlane(_) => unbounded(),
        }
    }

    fn in_closure(&self, x: &Vector2<f64>) -> bool {
        match self {
            PlanePrimitive::Region(r) => r.in_closure(*x),
            PlanePrimitive::HalfPlane(h) => h.height(x) <= BOUNDARY_TOL,
        }
    }

    fn in_interior(&self, x: &Vector2<f64>) -> bool {
        match self {
            PlanePrimitive::Region(r) => r.in_interior(*x),
            PlanePrimitive::HalfPlane(h) => h.height(x) < -BOUNDARY_TOL,
        }
    }
}

/// The bounding box of all space.
fn unbounded<const D: usize>() -> (SVector<f64, D>, SVector<f64, D>) {
    (
        SVector::repeat(f64::NEG_INFINITY),
        SVector::repeat(f64::INFINITY),
    )
}

/// A primitive of space as written.
#[derive(Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
enum SpaceSpec {
    Box {
        min: [f64; 3],
        max: [f64; 3],
    },
    Cylinder {
        from: [f64; 3],
        to: [f64; 3],
        radius: f64,
    },
    Sphere {
        centre: [f64; 3],
        radius: f64,
    },
    HalfSpace {
        point: [f64; 3],
        normal: [f64; 3],
    },
    Prism {
        section: toml::Value,
        z: [f64; 2],
    },
}

/// A primitive of a geometry of space.
#[derive(Debug, Clone, PartialEq)]
pub enum SpacePrimitive {
    /// A box or a cylinder ([`Solid::Box`], [`Solid::Cylinder`]).
    Solid(Solid),
    /// The ball `|x - centre| <= radius` (mm).
    Sphere {
        /// Centre (mm).
        centre: Vector3<f64>,
        /// Radius (mm), > 0.
        radius: f64,
    },
    /// A half-space.
    HalfSpace(HalfSpace<3>),
    /// The plane geometry `section` (x, y) extruded over `z[0] <= z <= z[1]` (mm).
    Prism {
        /// Cross-section in the x-y plane.
        section: PlaneShape,
        /// Extent in z (mm), `z[0] < z[1]`.
        z: [f64; 2],
    },
}

impl Primitive<3> for SpacePrimitive {
    const TYPES: &'static [&'static str] = &["box", "cylinder", "sphere", "half-space", "prism"];
    const OTHER_DIMENSION: &'static str = "the primitives of a geometry of space, whose first \
                                           primitive is one of them; a plane primitive enters it as the \
                                           section of a prism";

    fn parse(table: &toml::Value, key: &str) -> Result<Self, BadValue> {
        let p = match read::<SpaceSpec>(table, key, 3)? {
            SpaceSpec::Box { min, max } => SpacePrimitive::Solid(Solid::Box { min, max }),
            SpaceSpec::Cylinder { from, to, radius } => SpacePrimitive::Solid(Solid::Cylinder {
                base: from,
                axis: [0, 1, 2].map(|d| to[d] - from[d]),
                radius,
            }),
            SpaceSpec::Sphere { centre, radius } => SpacePrimitive::Sphere {
                centre: Vector3::from(centre),
                radius,
            },
            SpaceSpec::HalfSpace { point, normal } => {
                SpacePrimitive::HalfSpace(HalfSpace::new(point, normal, key)?)
            }
            SpaceSpec::Prism { section, z } => SpacePrimitive::Prism {
                section: PlaneShape::parse(&section, &format!("{key}.section"))?,
                z,
            },
        };
        p.check(key)?;
        Ok(p)
    }

    fn check(&self, key: &str) -> Result<(), BadValue> {
        match self {
            SpacePrimitive::Solid(Solid::Box { min, max }) => corners_ok(min, max, key),
            SpacePrimitive::Solid(Solid::Cylinder { base, axis, radius }) => {
                finite(base, &format!("{key}.from"))?;
                let length = Vector3::from(*axis).norm();
                if !(length.is_finite() && length > 0.0) {
                    return Err(BadValue::new(
                        format!("{key}.to"),
                        "the end point `from` (or an infinite one)",
                        "a finite end point other than `from`: the cylinder's axis runs from `from` \
                         to `to`",
                    ));
                }
                radius_ok(*radius, &format!("{key}.radius"))
            }
            SpacePrimitive::Solid(prism) => prism
                .validate()
                .map_err(|reason| BadValue::new(key, "(the prism)", reason)),
            SpacePrimitive::Sphere { centre, radius } => {
                finite(centre.as_slice(), &format!("{key}.centre"))?;
                radius_ok(*radius, &format!("{key}.radius"))
            }
            SpacePrimitive::HalfSpace(h) => h.check(key),
            SpacePrimitive::Prism { section, z } => {
                section.check_nodes(&format!("{key}.section"))?;
                match z[0].is_finite() && z[1].is_finite() && z[0] < z[1] {
                    true => Ok(()),
                    false => Err(BadValue::new(
                        format!("{key}.z"),
                        format!("{z:?}"),
                        "[z0, z1] with z0 < z1 (mm)",
                    )),
                }
            }
        }
    }

    fn bounds(&self) -> (Vector3<f64>, Vector3<f64>) {
        match self {
            SpacePrimitive::Solid(s) => s.bounding_box(),
            SpacePrimitive::Sphere { centre, radius } => {
                (centre.add_scalar(-radius), centre.add_scalar(*radius))
            }
            SpacePrimitive::HalfSpace(_) => unbounded(),
            SpacePrimitive::Prism { section, z } => {
                let (lo, hi) = section.bounds();
                (
                    Vector3::new(lo.x, lo.y, z[0]),
                    Vector3::new(hi.x, hi.y, z[1]),
                )
            }
        }
    }

    fn in_closure(&self, x: &Vector3<f64>) -> bool {
        let tol = BOUNDARY_TOL;
        match self {
            SpacePrimitive::Solid(s) => s.in_closure(x),
            SpacePrimitive::Sphere { centre, radius } => (x - centre).norm() <= radius + tol,
            SpacePrimitive::HalfSpace(h) => h.height(x) <= tol,
            SpacePrimitive::Prism { section, z } => {
                x.z >= z[0] - tol && x.z <= z[1] + tol && section.in_closure(&x.xy())
            }
        }
    }

    fn in_interior(&self, x: &Vector3<f64>) -> bool {
        let tol = BOUNDARY_TOL;
        match self {
            SpacePrimitive::Solid(s) => s.in_interior(x),
            SpacePrimitive::Sphere { centre, radius } => (x - centre).norm() < radius - tol,
            SpacePrimitive::HalfSpace(h) => h.height(x) < -tol,
            SpacePrimitive::Prism { section, z } => {
                x.z > z[0] + tol && x.z < z[1] - tol && section.in_interior(&x.xy())
            }
        }
    }
}
