//! Boundary conditions and loads of the implicit step: constrained node boxes, rigid bodies (glued or in
//! contact, `src/contact/`), nodal loads along grid lines, and the prescribed motion (a velocity that
//! rises linearly from zero) that drives them.
//!
//! Units: mm, s, N (in 2D per mm thickness), MPa. Generic over the space dimension `D` (2 by default).

use crate::contact::Contact;
use crate::grid::Grid;
use nalgebra::SVector;

/// A force on the grid nodes of a segment, distributed as a uniform traction (consistent nodal forces of
/// the hat functions along the grid line).
#[derive(Debug, Clone, PartialEq)]
pub struct NodalLoad<const D: usize = 2> {
    /// Name (history columns).
    pub name: String,
    /// Segment end points (mm), on one grid line (parallel to an axis).
    pub from: SVector<f64, D>,
    /// See `from`.
    pub to: SVector<f64, D>,
    /// Resultant force (N; in 2D per mm thickness).
    pub force: SVector<f64, D>,
    /// Linear rise from zero over this time (s); 0 = applied at once.
    pub rise_time: f64,
}

impl<const D: usize> NodalLoad<D> {
    /// The load factor in [0, 1] at time `t` (s).
    pub fn factor(&self, t: f64) -> f64 {
        if self.rise_time > 0.0 {
            (t / self.rise_time).clamp(0.0, 1.0)
        } else {
            1.0
        }
    }

    /// Share of the resultant carried by each grid node on the segment: the integral of the node's hat
    /// function along the segment divided by the segment length. Grid nodes only (the shares of nodes
    /// without unknowns are redistributed by the caller). The error says what segment is allowed.
    pub fn shares(&self, grid: &Grid<D>) -> Result<Vec<(usize, f64)>, String> {
        let h = grid.cell_size();
        let o = grid.origin();
        let d = self.to - self.from;
        // The segment runs along the last direction in which its ends differ (along x if it is a point).
        let along = (0..D).rev().find(|&k| d[k] != 0.0).unwrap_or(0);
        let off_line = (0..D).filter(|&k| k != along).any(|k| {
            let line = (self.from[k] - o[k]) / h;
            d[k] != 0.0 || (line - line.round()).abs() > 1e-6
        });
        if off_line {
            return Err(format!(
                "a segment on a grid line (parallel to an axis, the other coordinates multiples of h = \
                 {h} mm from the grid origin)"
            ));
        }
        let (a, b) = (
            self.from[along].min(self.to[along]),
            self.from[along].max(self.to[along]),
        );
        let count = grid.cells();
        let mut node = [0_usize; D];
        for k in (0..D).filter(|&k| k != along) {
            let line = ((self.from[k] - o[k]) / h).round() as i64;
            if line < 0 || line > count[k] as i64 {
                return Err("a segment inside the grid".into());
            }
            node[k] = line as usize;
        }
        let first = (((a - o[along]) / h).floor() as i64).max(0);
        let last = (((b - o[along]) / h).ceil() as i64).min(count[along] as i64);
        let mut shares = Vec::new();
        for k in first..=last {
            let c = o[along] + k as f64 * h;
            let w = hat_integral(a, b, c, h) / (b - a);
            if w > 0.0 {
                node[along] = k as usize;
                shares.push((grid.node_at(node), w));
            }
        }
        Ok(shares)
    }
}

/// `int_a^b max(0, 1 - |s - c| / h) ds`.
fn hat_integral(a: f64, b: f64, c: f64, h: f64) -> f64 {
    // Antiderivative of the hat, G(s) = int_{c-h}^{s} hat, for s clamped to [c - h, c + h].
    let g = |s: f64| {
        let t = ((s - c) / h).clamp(-1.0, 1.0);
        if t <= 0.0 {
            0.5 * h * (1.0 + t) * (1.0 + t)
        } else {
            h - 0.5 * h * (1.0 - t) * (1.0 - t)
        }
    };
    g(b) - g(a)
}

/// Which velocity a constrained component follows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Motion {
    /// Not constrained.
    Free,
    /// Prescribed velocity (mm/s); 0 = fixed.
    Velocity(f64),
}

/// Grid nodes inside an axis-aligned box (mm), constrained per component.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeBox<const D: usize = 2> {
    /// Name used in reports (reaction force columns).
    pub name: String,
    /// Lowest corner (mm).
    pub min: SVector<f64, D>,
    /// Highest corner (mm).
    pub max: SVector<f64, D>,
    /// Motion of each displacement component.
    pub motion: [Motion; D],
    /// Prescribed velocities rise linearly from zero over this time (s); 0 = a velocity step.
    pub rise_time: f64,
}

/// A rigid body of particles (e.g. a steel loading plate) moving with a prescribed velocity; its points
/// are part of the run's state ([`State::rigid`](crate::model::State::rigid)). Glued
/// (`contact = None`): every grid node in the support of its particles follows it in the constrained
/// components each step. In contact ([`Contact`]): it pushes on the specimen through unilateral contact
/// on its face (and, with a pin, turns freely about the pin).
#[derive(Debug, Clone)]
pub struct RigidBody<const D: usize = 2> {
    /// Name used in reports.
    pub name: String,
    /// Motion of each displacement component.
    pub motion: [Motion; D],
    /// Prescribed velocities rise linearly from zero over this time (s); 0 = a velocity step.
    pub rise_time: f64,
    /// Unilateral contact instead of gluing (both motion components must then be prescribed).
    pub contact: Option<Contact>,
    /// The velocity field it holds or pushes ([`Parameters::fields`](crate::model::Parameters::fields); 0: the
    /// specimen's).
    pub field: u16,
}

/// Displacement of a component moving with velocity `v` that rises linearly over `rise` from 0, between
/// `t` and `t + dt`: `v (g(t + dt) - g(t))` with `g(t) = t^2/(2 rise)` for `t < rise`, else `t - rise/2`.
pub fn prescribed_increment(v: f64, rise: f64, t: f64, dt: f64) -> f64 {
    let g = |t: f64| {
        if rise > 0.0 && t < rise {
            t * t / (2.0 * rise)
        } else {
            t - 0.5 * rise.max(0.0)
        }
    };
    v * (g(t + dt) - g(t))
}

/// Acceleration (mm/s^2) just after `t` of a component whose velocity rises linearly from 0 to `v` over
/// `rise`: `v / rise` during the rise, 0 after it. A velocity step (`rise = 0`) gets 0: its jump at t = 0
/// is an impulse that no finite acceleration represents (the prescribed increments carry it), and 0 is
/// the acceleration just after the jump.
pub fn prescribed_acceleration(v: f64, rise: f64, t: f64) -> f64 {
    if rise > 0.0 && t < rise {
        v / rise
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    #[test]
    fn hat_integral_matches_quadrature() {
        let h = 2.0;
        for &(a, b, c) in &[
            (0.0, 10.0, 4.0),
            (0.0, 10.0, 0.0),
            (0.0, 10.0, 10.0),
            (0.5, 3.0, 2.0),
            (3.1, 3.3, 2.0),
            (0.0, 1.0, 5.0),
        ] {
            let n = 200_000;
            let ds = (b - a) / n as f64;
            let q: f64 = (0..n)
                .map(|k| {
                    let s = a + (k as f64 + 0.5) * ds;
                    (1.0 - (s - c).abs() / h).max(0.0) * ds
                })
                .sum();
            assert!((hat_integral(a, b, c, h) - q).abs() < 1e-6, "{a} {b} {c}");
        }
    }

    #[test]
    fn prescribed_acceleration_is_that_of_the_prescribed_increments() {
        let (v, rise, dt) = (4300.0, 1e-5, 1e-6);
        // From rest with constant acceleration a: du = a dt^2 / 2 in the first step.
        let a = prescribed_acceleration(v, rise, 0.0);
        assert!((a - v / rise).abs() < 1e-9 * a);
        let du = prescribed_increment(v, rise, 0.0, dt);
        assert!((du - 0.5 * a * dt * dt).abs() < 1e-12 * du);
        // Inside the rise: the second difference of the prescribed path.
        let t = 4e-6;
        let d2 = (prescribed_increment(v, rise, t, dt) - prescribed_increment(v, rise, t - dt, dt))
            / (dt * dt);
        assert!((d2 - prescribed_acceleration(v, rise, t)).abs() < 1e-6 * a);
        // After the rise and for a velocity step: constant velocity.
        assert_eq!(prescribed_acceleration(v, rise, 2.0 * rise), 0.0);
        assert_eq!(prescribed_acceleration(v, 0.0, 0.0), 0.0);
    }

    #[test]
    fn load_shares_are_the_consistent_nodal_forces() {
        let grid = Grid::new(Vector2::new(-2.0, -2.0), 1.0, [14, 8]).unwrap();
        let load = |from: [f64; 2], to: [f64; 2]| NodalLoad {
            name: "tip".into(),
            from: Vector2::from(from),
            to: Vector2::from(to),
            force: Vector2::new(0.0, -1.0),
            rise_time: 0.0,
        };
        // A vertical edge of 4 cells: end nodes 1/8, inner nodes 1/4.
        let shares = load([10.0, 0.0], [10.0, 4.0]).shares(&grid).unwrap();
        assert_eq!(shares.len(), 5);
        let sum: f64 = shares.iter().map(|s| s.1).sum();
        assert!((sum - 1.0).abs() < 1e-14);
        for &(node, w) in &shares {
            let x = grid.node_position(node);
            assert_eq!(x.x, 10.0);
            let end = x.y == 0.0 || x.y == 4.0;
            assert!(
                (w - if end { 0.125 } else { 0.25 }).abs() < 1e-14,
                "{x:?} {w}"
            );
        }
        // Reversed end points, horizontal: the same shares.
        let h = load([4.0, 2.0], [0.0, 2.0]).shares(&grid).unwrap();
        assert_eq!(h.len(), 5);
        // Off a grid line: an error naming the load.
        let e = load([10.5, 0.0], [10.5, 4.0]).shares(&grid).unwrap_err();
        assert!(e.contains("tip") && e.contains("grid line"), "{e}");
    }
}
