//! Regions of space for seeding 3D bodies (mm): boxes, cylinders and prisms (a plane [`Region`] extruded
//! along z), combined like the plane [`Geometry`](crate::geometry::Geometry): the body is the closure of
//! the union of the `include` solids minus the interiors of the `exclude` solids, with boundaries taken
//! within [`BOUNDARY_TOL`].
//!
//! In TOML: `{ type = "box", min = [0.0, 0.0, 0.0], max = [200.0, 200.0, 50.0] }`,
//! `{ type = "cylinder", base = [100.0, 100.0, 0.0], axis = [0.0, 0.0, 50.0], radius = 5.0 }` or
//! `{ type = "prism", z = [0.0, 50.0], section = { type = "disk", centre = [0.0, 0.0], radius = 5.0 } }`.

use nalgebra::{Vector2, Vector3};
use serde::Deserialize;

use crate::geometry::{BOUNDARY_TOL, Body, GeometryError, Region, validate_lists};

/// A solid region of space (mm).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum Solid {
    /// Axis-aligned box `[min, max]` (mm).
    Box {
        /// Lowest corner (mm).
        min: [f64; 3],
        /// Highest corner (mm).
        max: [f64; 3],
    },
    /// Circular cylinder from `base` to `base + axis` with `radius` (mm).
    Cylinder {
        /// Centre of the first end face (mm).
        base: [f64; 3],
        /// Axis vector from the first to the second end face (mm), non-zero.
        axis: [f64; 3],
        /// Radius (mm), positive.
        radius: f64,
    },
    /// The plane region `section` (in x, y) extruded over `z[0] <= z <= z[1]` (mm).
    Prism {
        /// Cross-section in the x-y plane.
        section: Region,
        /// Extent in z (mm), `z[0] < z[1]`.
        z: [f64; 2],
    },
}

impl Solid {
    /// Checks the values (finite, positive radius, corners and z range in order).
    pub(crate) fn validate(&self) -> Result<(), String> {
        let finite = |v: &[f64]| v.iter().all(|c| c.is_finite());
        match self {
            Solid::Box { min, max } => {
                if !(finite(min) && finite(max) && (0..3).all(|d| min[d] < max[d])) {
                    return Err(format!(
                        "box needs finite corners with min < max, got min = {min:?}, max = {max:?}"
                    ));
                }
            }
            Solid::Cylinder { base, axis, radius } => {
                let length = Vector3::from(*axis).norm();
                if !(finite(base)
                    && finite(axis)
                    && length > 0.0
                    && radius.is_finite()
                    && *radius > 0.0)
                {
                    return Err(format!(
                        "cylinder needs a finite base, a non-zero axis and a positive radius, got base = \
                         {base:?}, axis = {axis:?}, radius = {radius}"
                    ));
                }
            }
            Solid::Prism { section, z } => {
                section.validate()?;
                if !(finite(z) && z[0] < z[1]) {
                    return Err(format!("prism needs z = [z0, z1] with z0 < z1, got {z:?}"));
                }
            }
        }
        Ok(())
    }

    /// Bounding box `(min, max)` (mm).
    pub fn bounding_box(&self) -> (Vector3<f64>, Vector3<f64>) {
        match self {
            Solid::Box { min, max } => (Vector3::from(*min), Vector3::from(*max)),
            Solid::Cylinder { base, axis, radius } => {
                let (a, b) = (
                    Vector3::from(*base),
                    Vector3::from(*base) + Vector3::from(*axis),
                );
                // Per direction, the end disks reach radius * sqrt(1 - n_d^2) beyond the end centres.
                let n = Vector3::from(*axis).normalize();
                let reach = n.map(|c| radius * (1.0 - c * c).max(0.0).sqrt());
                (a.inf(&b) - reach, a.sup(&b) + reach)
            }
            Solid::Prism { section, z } => {
                let (lo, hi) = section.bounding_box();
                (
                    Vector3::new(lo.x, lo.y, z[0]),
                    Vector3::new(hi.x, hi.y, z[1]),
                )
            }
        }
    }

    /// Position along the axis (`t` in `[0, 1]` between the end faces, scaled by the axis length) and the
    /// distance from the axis of `x`, for a cylinder.
    fn cylinder_coords(base: &[f64; 3], axis: &[f64; 3], x: &Vector3<f64>) -> (f64, f64, f64) {
        let (b, a) = (Vector3::from(*base), Vector3::from(*axis));
        let length = a.norm();
        let t = (x - b).dot(&a) / length;
        let radial = (x - b - a * (t / length)).norm();
        (t, length, radial)
    }

    /// Whether `x` lies in the closed solid (boundary included, within [`BOUNDARY_TOL`]).
    pub fn in_closure(&self, x: &Vector3<f64>) -> bool {
        let tol = BOUNDARY_TOL;
        match self {
            Solid::Box { min, max } => (0..3).all(|d| x[d] >= min[d] - tol && x[d] <= max[d] + tol),
            Solid::Cylinder { base, axis, radius } => {
                let (t, length, radial) = Self::cylinder_coords(base, axis, x);
                t >= -tol && t <= length + tol && radial <= radius + tol
            }
            Solid::Prism { section, z } => {
                x.z >= z[0] - tol && x.z <= z[1] + tol && section.in_closure(Vector2::new(x.x, x.y))
            }
        }
    }

    /// Whether `x` lies in the open interior (at least [`BOUNDARY_TOL`] inside every face).
    pub fn in_interior(&self, x: &Vector3<f64>) -> bool {
        let tol = BOUNDARY_TOL;
        match self {
            Solid::Box { min, max } => (0..3).all(|d| x[d] > min[d] + tol && x[d] < max[d] - tol),
            Solid::Cylinder { base, axis, radius } => {
                let (t, length, radial) = Self::cylinder_coords(base, axis, x);
                t > tol && t < length - tol && radial < radius - tol
            }
            Solid::Prism { section, z } => {
                x.z > z[0] + tol && x.z < z[1] - tol && section.in_interior(Vector2::new(x.x, x.y))
            }
        }
    }
}

/// A 3D body to seed: the union of `include` minus the union of `exclude`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Solids {
    /// Solids that hold material (at least one).
    pub include: Vec<Solid>,
    /// Solids cut out of the material (e.g. a notch); optional.
    #[serde(default)]
    pub exclude: Vec<Solid>,
}

impl Body<3> for Solids {
    fn validate(&self) -> Result<(), GeometryError> {
        validate_lists(&self.include, &self.exclude, Solid::validate)
    }

    fn contains(&self, x: &Vector3<f64>) -> bool {
        self.include.iter().any(|s| s.in_closure(x))
            && !self.exclude.iter().any(|s| s.in_interior(x))
    }

    fn bounding_box(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        self.include
            .iter()
            .map(Solid::bounding_box)
            .reduce(|(lo, hi), (l, h)| (lo.inf(&l), hi.sup(&h)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Seeding;
    use crate::particles::{ParticleError, Particles};

    #[test]
    fn a_notched_plate_seeds_its_volume_and_mass() {
        let plate: Solids = toml::from_str(
            r#"
            include = [{ type = "box", min = [0.0, 0.0, 0.0], max = [20.0, 20.0, 5.0] }]
            exclude = [{ type = "box", min = [0.0, 9.0, -1.0], max = [11.0, 11.0, 6.0] }]
            "#,
        )
        .unwrap();
        let p = Particles::<3>::seed(&plate, &Seeding::concrete(1.0, 2)).unwrap();
        let volume = 20.0 * 20.0 * 5.0 - 11.0 * 2.0 * 5.0;
        assert_eq!(p.len(), 8 * volume as usize);
        assert!((p.vol0.iter().sum::<f64>() - volume).abs() < 1e-9);
        assert!((p.mass.iter().sum::<f64>() / (2.4e-9 * volume) - 1.0).abs() < 1e-12);
        assert_eq!(p.x[0], Vector3::new(0.25, 0.25, 0.25));
        assert_eq!(p.corners(0)[7], Vector3::new(0.5, 0.5, 0.5));
        assert_eq!(p.corners(0)[0], Vector3::zeros());
        assert!((p.point_spacing() - 0.5).abs() < 1e-12);
        assert!(p.x.iter().all(|x| !(x.x < 11.0 && x.y > 9.0 && x.y < 11.0)));
        let (lo, hi) = p.bounding_box().unwrap();
        assert_eq!((lo, hi), (Vector3::zeros(), Vector3::new(20.0, 20.0, 5.0)));
        // A record carries a 3D point whole.
        let mut records = Vec::new();
        p.pack(17, &mut records);
        assert_eq!(records.len(), p.record_width());
        assert_eq!(p.record_id(&records), 17);
        let mut q = p.empty_like();
        q.unpack(&records);
        assert_eq!(
            (q.x[0], q.r[0], q.corners(0)),
            (p.x[17], p.r[17], p.corners(17))
        );
        let widths: usize = p.state_columns().iter().map(|c| c.1).sum();
        assert_eq!(widths, 3 * 3 + 3 * 3 + 1 + 9 + 9 + 24 + 1 + 1 + 2 + 1);
    }

    #[test]
    fn cylinders_and_prisms_hold_their_volume() {
        let bodies: Solids = toml::from_str(
            r#"
            include = [
                { type = "cylinder", base = [0.0, 0.0, 0.0], axis = [0.0, 0.0, 8.0], radius = 5.0 },
                { type = "prism", z = [20.0, 24.0], section = { type = "disk", centre = [0.0, 0.0], radius = 5.0 } },
            ]
            "#,
        )
        .unwrap();
        let p = Particles::<3>::seed(&bodies, &Seeding::concrete(0.5, 2)).unwrap();
        let exact = std::f64::consts::PI * 25.0 * (8.0 + 4.0);
        let volume: f64 = p.vol0.iter().sum();
        assert!((volume / exact - 1.0).abs() < 0.01, "{volume} vs {exact}");
        // A tilted cylinder: the bounding box and the volume follow the axis.
        let tilted = Solid::Cylinder {
            base: [0.0, 0.0, 0.0],
            axis: [6.0, 0.0, 8.0],
            radius: 2.0,
        };
        let (lo, hi) = tilted.bounding_box();
        assert!((lo.x + 2.0 * 0.8).abs() < 1e-12 && (hi.z - 8.0 - 2.0 * 0.6).abs() < 1e-12);
        let body = Solids {
            include: vec![tilted],
            exclude: vec![],
        };
        let p = Particles::<3>::seed(&body, &Seeding::concrete(0.25, 2)).unwrap();
        let exact = std::f64::consts::PI * 4.0 * 10.0;
        let volume: f64 = p.vol0.iter().sum();
        assert!((volume / exact - 1.0).abs() < 0.01, "{volume} vs {exact}");
    }

    #[test]
    fn bad_solids_are_errors_naming_the_list_and_index() {
        let bad: Solids = toml::from_str(
            r#"
            include = [{ type = "box", min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }]
            exclude = [{ type = "cylinder", base = [0.0, 0.0, 0.0], axis = [0.0, 0.0, 0.0], radius = 1.0 }]
            "#,
        )
        .unwrap();
        let e = Particles::<3>::seed(&bad, &Seeding::concrete(1.0, 2)).unwrap_err();
        assert!(
            matches!(
                e,
                ParticleError::Geometry(GeometryError::InvalidRegion {
                    list: "exclude",
                    index: 0,
                    ..
                })
            ),
            "{e}"
        );
        assert!(toml::from_str::<Solids>(r#"include = [{ type = "sphere", r = 1.0 }]"#).is_err());
        assert!(
            toml::from_str::<Solids>(
                r#"include = [{ type = "box", min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0], z = 1 }]"#
            )
            .is_err()
        );
        let empty = Solids {
            include: vec![],
            exclude: vec![],
        };
        assert_eq!(
            Particles::<3>::seed(&empty, &Seeding::concrete(1.0, 2)),
            Err(ParticleError::Geometry(GeometryError::EmptyGeometry))
        );
    }
}
