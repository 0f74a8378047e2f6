//! Construction of a plate from a plane set-up (`[extrusion]`, `docs/configuration.md`): every point,
//! of the specimen and of the rigid bodies, becomes a column of points through the thickness, the grid
//! gets the plate's cells in z with a margin, and the boxes, rigid bodies, body force and path control
//! are carried into 3D ([`Setup::extrude`]). [`build_run`](super::build_run) extrudes the whole plane
//! set-up, [`build_run_on`](super::build_run_on) a process's band of it. Units: mm.

use crate::boundary::{Motion, NodeBox, RigidBody};
use crate::grid::Grid;
use crate::input::BadValue;
use crate::model::{Method, Parameters, PathControl, Setup};
use crate::particles::Particles;
use crate::space::Frame;
use nalgebra::{Matrix3, SVector};

/// The cell layers of the plate of `thickness` (mm) that `plane` is extruded to, after checking what an
/// extrusion needs: a thickness that is a positive multiple of the cell size, MPM, no nodal loads and,
/// quasi-statically, a glued rigid body that holds the plate in z.
fn extrusion_layers(plane: &Parameters<2>, thickness: f64) -> Result<f64, BadValue> {
    let h = plane.grid.cell_size();
    let layers = (thickness / h).round();
    if !(thickness.is_finite() && thickness > 0.0 && layers >= 1.0)
        || (layers * h - thickness).abs() > 1e-9 * thickness
    {
        return Err(BadValue::new(
            "extrusion.thickness",
            thickness.to_string(),
            format!("a positive multiple of the cell size h = {h} mm"),
        ));
    }
    if plane.method == Method::Fem {
        return Err(BadValue::new(
            "shape.method",
            "\"fem\"",
            "\"mpm\" with [extrusion] (the FEM mode is plane only)",
        ));
    }
    if !plane.loads.is_empty() {
        return Err(BadValue::new(
            "load",
            format!("{} [[load]]", plane.loads.len()),
            "none with [extrusion] (nodal loads along grid lines are plane; load a plate with boxes \
             or rigid bodies)",
        ));
    }
    // The faces are free and devices in contact push in the plane: only a glued rigid body holds the
    // plate in z. Inertia does that in a dynamic run; a quasi-static one would be singular.
    if plane.time.quasi_static && plane.rigid.iter().all(|r| r.contact.is_some()) {
        return Err(BadValue::new(
            "time.quasi_static",
            "true",
            "false with [extrusion] unless a rigid body is glued (no contact): a quasi-static plate \
             needs its motion in z held",
        ));
    }
    Ok(layers)
}

/// Cells of empty grid beyond the plate's faces in z of an extruded set-up (the B-spline support reaches
/// 1.5 cells beyond a point).
const EXTRUSION_MARGIN: usize = 2;

impl Setup<2> {
    /// The plane set-up extruded to a plate of `thickness` (mm) along z, `0 <= z <= thickness`: every
    /// material point (specimen and rigid bodies) becomes a column of points through the thickness at the
    /// spacing of its own in-plane domain (`2 r^0_xx`: 2 points per cell and direction as seeded, so
    /// `2^3` per cell), with its volume and mass per mm of thickness times that spacing; the grid gets the
    /// plate's cells in z plus a margin of 2 cells on both faces. The plate's faces are free: node boxes
    /// keep z free; rigid bodies (loading plates) hold z fixed (glued ones at their nodes; a device in
    /// contact pushes in the x-y plane, its pin along z). The thickness must be a multiple of the cell
    /// size; FEM mode, nodal loads along grid lines (2D segments) and a quasi-static plate that nothing
    /// holds in z (no glued rigid body) are refused.
    pub fn extrude(self, thickness: f64) -> Result<Setup<3>, BadValue> {
        let Setup {
            params: plane,
            particles,
            rigid_points,
        } = self;
        let h = plane.grid.cell_size();
        let layers = extrusion_layers(&plane, thickness)?;
        let g = &plane.grid;
        let origin = g.origin();
        let margin = EXTRUSION_MARGIN as f64 * h;
        let grid = Grid::new(
            SVector::from([origin.x, origin.y, -margin]),
            h,
            [g.nx(), g.ny(), layers as usize + 2 * EXTRUSION_MARGIN],
        )
        .map_err(|e| {
            BadValue::new(
                "extrusion.thickness",
                thickness.to_string(),
                format!("a plate whose grid can be built ({e})"),
            )
        })?;
        let rigid_points = rigid_points
            .iter()
            .map(|p| extrude_points(p, thickness))
            .collect::<Result<Vec<_>, _>>()?;
        let far = f64::INFINITY;
        let boxes = plane
            .boxes
            .into_iter()
            .map(|b| NodeBox {
                name: b.name,
                min: SVector::from([b.min.x, b.min.y, -far]),
                max: SVector::from([b.max.x, b.max.y, far]),
                motion: [b.motion[0], b.motion[1], Motion::Free],
                rise_time: b.rise_time,
            })
            .collect();
        let rigid = plane
            .rigid
            .into_iter()
            .map(|r| RigidBody {
                name: r.name,
                motion: [r.motion[0], r.motion[1], Motion::Velocity(0.0)],
                rise_time: r.rise_time,
                contact: r.contact,
                field: r.field,
            })
            .collect();
        // Every field written out: a new setting of the plane set-up must say how it reaches the plate.
        let params = Parameters {
            grid,
            materials: plane.materials,
            fields: plane.fields,
            shape: plane.shape,
            corner_hold: plane.corner_hold,
            time: plane.time,
            body_force: SVector::from([plane.body_force.x, plane.body_force.y, 0.0]),
            body_force_ramp: plane.body_force_ramp,
            boxes,
            rigid,
            loads: Vec::new(),
            method: plane.method,
            options_prefix: plane.options_prefix,
            mass_tolerance: plane.mass_tolerance,
            fallback_prefix: plane.fallback_prefix,
            path: plane.path.map(|p| PathControl {
                from: SVector::from([p.from.x, p.from.y, 0.5 * thickness]),
                to: SVector::from([p.to.x, p.to.y, 0.5 * thickness]),
                direction: SVector::from([p.direction.x, p.direction.y, 0.0]),
                increment: p.increment,
            }),
            // A turned set-up is plane only (the configuration refuses a turned plate).
            frame: Frame::IDENTITY,
        };
        let particles = extrude_points(&particles, thickness)?;
        Ok(Setup {
            params,
            particles,
            rigid_points,
        })
    }
}

/// The points of `plane` repeated through `0 <= z <= thickness` (mm) at the spacing `2 r^0_xx` of each
/// point's undeformed domain, at rest and undeformed as [`Particles::push`] makes them.
fn extrude_points(plane: &Particles, thickness: f64) -> Result<Particles<3>, BadValue> {
    let mut out = Particles::<3>::new();
    for p in 0..plane.len() {
        let (r0, x, v) = (plane.r0[p], plane.x[p], plane.v[p]);
        let spacing = 2.0 * r0[(0, 0)];
        let count = (thickness / spacing).round();
        if !(spacing > 0.0 && count >= 1.0)
            || (count * spacing - thickness).abs() > 1e-9 * thickness
        {
            return Err(BadValue::new(
                "extrusion.thickness",
                thickness.to_string(),
                format!("a multiple of the spacing {spacing} mm of every point"),
            ));
        }
        let r = Matrix3::new(
            r0[(0, 0)],
            r0[(0, 1)],
            0.0,
            r0[(1, 0)],
            r0[(1, 1)],
            0.0,
            0.0,
            0.0,
            0.5 * spacing,
        );
        for k in 0..count as usize {
            let z = (k as f64 + 0.5) * spacing;
            out.push(
                SVector::from([x.x, x.y, z]),
                plane.vol0[p] * spacing,
                plane.mass[p] * spacing,
                r,
                plane.body[p],
            );
            let q = out.len() - 1;
            out.v[q] = SVector::from([v.x, v.y, 0.0]);
        }
    }
    Ok(out)
}
