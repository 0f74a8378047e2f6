//! The bodies to seed, as regions of the plane (mm): rectangles, polygons and disks combined into a
//! [`Geometry`] (the union of the `include` regions minus the `exclude` regions), boxes in any dimension
//! ([`BoxBody`]), and the [`Body`] interface that [`crate::particles::Particles::seed`] fills with points
//! (the solids of space are in [`crate::solids`], primitives of the plane and of space combined by union,
//! intersection and difference in [`crate::csg`]); the seeding parameters ([`Seeding`]).
//!
//! Boundaries: include regions are closed and exclude regions are open, i.e. a point exactly on a boundary
//! (within [`BOUNDARY_TOL`]) counts as material: the body is the closure of the union of the includes minus
//! the interiors of the excludes.

use nalgebra::{SVector, Vector2};
use serde::Deserialize;
use thiserror::Error;

/// Distance (mm) within which a point counts as lying on a region boundary.
pub const BOUNDARY_TOL: f64 = 1e-9;

/// A region of the plane (mm).
///
/// In TOML: `{ type = "rect", min = [0.0, 0.0], max = [200.0, 200.0] }`,
/// `{ type = "polygon", vertices = [[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]] }` or
/// `{ type = "disk", centre = [105.0, 100.0], radius = 5.0 }`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum Region {
    /// Axis-aligned rectangle `[min_x, max_x] x [min_y, max_y]` (mm).
    Rect {
        /// Lower-left corner (mm).
        min: [f64; 2],
        /// Upper-right corner (mm).
        max: [f64; 2],
    },
    /// Simple polygon, vertices in either orientation, not repeated at the end (mm). Inside by the even-odd
    /// rule.
    Polygon {
        /// At least three vertices (mm).
        vertices: Vec<[f64; 2]>,
    },
    /// Disk `|x - centre| <= radius` (mm), e.g. the round tip of a sawn notch.
    Disk {
        /// Centre (mm).
        centre: [f64; 2],
        /// Radius (mm), positive.
        radius: f64,
    },
}

/// The body to seed: the union of `include` minus the union of `exclude`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Geometry {
    /// Regions that hold material (at least one).
    pub include: Vec<Region>,
    /// Regions cut out of the material (e.g. a notch); optional.
    #[serde(default)]
    pub exclude: Vec<Region>,
}

/// Parameters of [`Particles::seed`](crate::particles::Particles::seed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Seeding {
    /// Background-grid cell size `h` (mm).
    pub h: f64,
    /// Points per cell and direction `n` (`n x n` points per cell), >= 1.
    pub points_per_cell: usize,
    /// Mass density `rho` (t/mm^3), e.g. 2.4e-9 for concrete.
    pub density: f64,
    /// Body tag of the seeded points (e.g. 0 concrete, 1 loading plate).
    pub body: u16,
}

#[cfg(test)]
impl Seeding {
    /// `n` points per cell and direction on cells of `h` (mm), concrete's density 2.4e-9 t/mm^3, body 0.
    pub(crate) fn concrete(h: f64, n: usize) -> Self {
        Self {
            h,
            points_per_cell: n,
            density: 2.4e-9,
            body: 0,
        }
    }
}

/// A malformed geometry: no include region, or a bad region.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GeometryError {
    /// The geometry has no include region.
    #[error("empty geometry: at least one include region is needed")]
    EmptyGeometry,
    /// A region is malformed.
    #[error("{list} region {index}: {reason}")]
    InvalidRegion {
        /// `"include"` or `"exclude"`.
        list: &'static str,
        /// Index in that list.
        index: usize,
        /// What is wrong.
        reason: String,
    },
    /// A node of a [`crate::csg::Shape`] is malformed, or the whole is unbounded or empty.
    #[error("{key}: {reason}")]
    InvalidShape {
        /// The key of the node at fault (`geometry.difference[1].radius`).
        key: String,
        /// What is wrong.
        reason: String,
    },
}

impl Region {
    pub(crate) fn validate(&self) -> Result<(), String> {
        let finite = |p: &[f64; 2]| p[0].is_finite() && p[1].is_finite();
        match self {
            Region::Rect { min, max } => {
                if !(finite(min) && finite(max)) {
                    return Err("rect corners must be finite".into());
                }
                if !(min[0] < max[0] && min[1] < max[1]) {
                    return Err(format!(
                        "rect needs min < max, got min = {min:?}, max = {max:?}"
                    ));
                }
            }
            Region::Polygon { vertices } => {
                if vertices.len() < 3 {
                    return Err(format!(
                        "polygon needs at least 3 vertices, got {}",
                        vertices.len()
                    ));
                }
                if !vertices.iter().all(finite) {
                    return Err("polygon vertices must be finite".into());
                }
                if let Some((k, l, x)) = polygon_crossing(vertices) {
                    let n = vertices.len();
                    return Err(format!(
                        "polygon edges {k} (vertices {k} to {}) and {l} (vertices {l} to {}) meet at \
                         ({:.3}, {:.3}) mm: a simple polygon, whose edges meet only their neighbours at \
                         shared vertices",
                        (k + 1) % n,
                        (l + 1) % n,
                        x.x,
                        x.y
                    ));
                }
            }
            Region::Disk { centre, radius } => {
                if !(finite(centre) && radius.is_finite() && *radius > 0.0) {
                    return Err(format!(
                        "disk needs a finite centre and a positive radius, got centre = {centre:?}, \
                         radius = {radius}"
                    ));
                }
            }
        }
        Ok(())
    }

    /// Bounding box `(min, max)` (mm).
    pub fn bounding_box(&self) -> (Vector2<f64>, Vector2<f64>) {
        match self {
            Region::Rect { min, max } => (Vector2::from(*min), Vector2::from(*max)),
            Region::Polygon { vertices } => vertices.iter().fold(
                (
                    Vector2::repeat(f64::INFINITY),
                    Vector2::repeat(f64::NEG_INFINITY),
                ),
                |(lo, hi), v| {
                    let v = Vector2::from(*v);
                    (lo.inf(&v), hi.sup(&v))
                },
            ),
            Region::Disk { centre, radius } => (
                Vector2::from(*centre).add_scalar(-radius),
                Vector2::from(*centre).add_scalar(*radius),
            ),
        }
    }

    /// Whether `x` lies on the boundary, within [`BOUNDARY_TOL`].
    pub fn on_boundary(&self, x: Vector2<f64>) -> bool {
        match self {
            Region::Rect { min, max } => {
                let inside_tol =
                    (0..2).all(|k| x[k] >= min[k] - BOUNDARY_TOL && x[k] <= max[k] + BOUNDARY_TOL);
                let near_edge = (0..2).any(|k| {
                    (x[k] - min[k]).abs() <= BOUNDARY_TOL || (x[k] - max[k]).abs() <= BOUNDARY_TOL
                });
                inside_tol && near_edge
            }
            Region::Polygon { vertices } => polygon_edges(vertices).any(|(a, b)| {
                let ab = b - a;
                let t = ((x - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
                let d = if t.is_finite() {
                    (a + ab * t - x).norm()
                } else {
                    (a - x).norm()
                };
                d <= BOUNDARY_TOL
            }),
            Region::Disk { centre, radius } => {
                ((x - Vector2::from(*centre)).norm() - radius).abs() <= BOUNDARY_TOL
            }
        }
    }

    /// Whether `x` lies in the open interior (boundary excluded).
    pub fn in_interior(&self, x: Vector2<f64>) -> bool {
        if self.on_boundary(x) {
            return false;
        }
        match self {
            Region::Rect { min, max } => (0..2).all(|k| x[k] > min[k] && x[k] < max[k]),
            Region::Polygon { vertices } => {
                // Even-odd crossing test along +x.
                polygon_edges(vertices)
                    .filter(|(a, b)| {
                        (a.y > x.y) != (b.y > x.y)
                            && x.x < a.x + (x.y - a.y) * (b.x - a.x) / (b.y - a.y)
                    })
                    .count()
                    % 2
                    == 1
            }
            Region::Disk { centre, radius } => (x - Vector2::from(*centre)).norm() < *radius,
        }
    }

    /// Whether `x` lies in the closed region (boundary included).
    pub fn in_closure(&self, x: Vector2<f64>) -> bool {
        self.on_boundary(x) || self.in_interior(x)
    }
}

/// The first pair of edges `(k, l)` of a polygon that are not neighbours and meet (cross, touch or
/// overlap), with a point they share; edge `k` runs from vertex `k` to vertex `k + 1` (the last one back to
/// vertex 0).
fn polygon_crossing(vertices: &[[f64; 2]]) -> Option<(usize, usize, Vector2<f64>)> {
    let edges: Vec<_> = polygon_edges(vertices).collect();
    let n = edges.len();
    (0..n)
        .flat_map(|k| (k + 2..n).map(move |l| (k, l)))
        .filter(|&(k, l)| !(k == 0 && l == n - 1))
        .find_map(|(k, l)| segments_meet(edges[k], edges[l]).map(|x| (k, l, x)))
}

/// A point the closed segments `a`-`b` and `c`-`d` share, if they meet.
fn segments_meet(
    (a, b): (Vector2<f64>, Vector2<f64>),
    (c, d): (Vector2<f64>, Vector2<f64>),
) -> Option<Vector2<f64>> {
    let cross = |u: Vector2<f64>, v: Vector2<f64>| u.x * v.y - u.y * v.x;
    let (ab, cd) = (b - a, d - c);
    let (o1, o2) = (cross(ab, c - a), cross(ab, d - a));
    let (o3, o4) = (cross(cd, a - c), cross(cd, b - c));
    let apart = |p: f64, q: f64| (p > 0.0 && q > 0.0) || (p < 0.0 && q < 0.0);
    if apart(o1, o2) || apart(o3, o4) {
        return None;
    }
    if o1 == 0.0 && o2 == 0.0 {
        // Collinear: they meet where their extents overlap.
        let within = |p: Vector2<f64>, (u, v): (Vector2<f64>, Vector2<f64>)| {
            (0..2).all(|i| p[i] >= u[i].min(v[i]) && p[i] <= u[i].max(v[i]))
        };
        return [c, d, a, b]
            .into_iter()
            .zip([(a, b), (a, b), (c, d), (c, d)])
            .find_map(|(p, seg)| within(p, seg).then_some(p));
    }
    let t = o3 / (o3 - o4);
    Some(a + ab * if t.is_finite() { t } else { 0.0 })
}

fn polygon_edges(vertices: &[[f64; 2]]) -> impl Iterator<Item = (Vector2<f64>, Vector2<f64>)> + '_ {
    let n = vertices.len();
    (0..n).map(move |k| {
        (
            Vector2::from(vertices[k]),
            Vector2::from(vertices[(k + 1) % n]),
        )
    })
}

impl Geometry {
    /// Checks every region; an empty `include` list is an error.
    pub fn validate(&self) -> Result<(), GeometryError> {
        validate_lists(&self.include, &self.exclude, Region::validate)
    }

    /// Whether `x` is material: in the closure of some include region and in the interior of no exclude
    /// region.
    pub fn contains(&self, x: Vector2<f64>) -> bool {
        self.include.iter().any(|r| r.in_closure(x))
            && !self.exclude.iter().any(|r| r.in_interior(x))
    }

    /// Bounding box of the include regions (mm); `None` without include regions.
    pub fn bounding_box(&self) -> Option<(Vector2<f64>, Vector2<f64>)> {
        self.include
            .iter()
            .map(Region::bounding_box)
            .reduce(|(lo, hi), (l, h)| (lo.inf(&l), hi.sup(&h)))
    }
}

/// A body to seed in `D` dimensions: [`Geometry`] in the plane, [`crate::solids::Solids`] in space.
pub trait Body<const D: usize> {
    /// Checks every region; a body without include regions is an error.
    fn validate(&self) -> Result<(), GeometryError>;
    /// Whether `x` (mm) is material.
    fn contains(&self, x: &SVector<f64, D>) -> bool;
    /// Bounding box of the include regions (mm); `None` without include regions.
    fn bounding_box(&self) -> Option<(SVector<f64, D>, SVector<f64, D>)>;
}

/// A closed axis-aligned box `[min, max]` (mm) in `D` dimensions as a body to seed: a block, a bar, a
/// column.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxBody<const D: usize> {
    /// Lowest corner (mm).
    pub min: SVector<f64, D>,
    /// Highest corner (mm).
    pub max: SVector<f64, D>,
}

impl<const D: usize> BoxBody<D> {
    /// The box `[0, size]` (mm).
    pub fn from_origin(size: SVector<f64, D>) -> Self {
        Self {
            min: SVector::zeros(),
            max: size,
        }
    }
}

impl<const D: usize> Body<D> for BoxBody<D> {
    fn validate(&self) -> Result<(), GeometryError> {
        let ok = (0..D).all(|d| self.min[d].is_finite() && self.max[d].is_finite())
            && (0..D).all(|d| self.min[d] < self.max[d]);
        if ok {
            Ok(())
        } else {
            Err(GeometryError::InvalidRegion {
                list: "include",
                index: 0,
                reason: format!(
                    "box needs finite corners with min < max, got min = {:?}, max = {:?}",
                    self.min.as_slice(),
                    self.max.as_slice()
                ),
            })
        }
    }

    fn contains(&self, x: &SVector<f64, D>) -> bool {
        (0..D).all(|d| x[d] >= self.min[d] - BOUNDARY_TOL && x[d] <= self.max[d] + BOUNDARY_TOL)
    }

    fn bounding_box(&self) -> Option<(SVector<f64, D>, SVector<f64, D>)> {
        Some((self.min, self.max))
    }
}

/// Checks the `include` (at least one) and `exclude` regions of a body with `check`, naming the list and
/// the index of the first bad region.
pub(crate) fn validate_lists<R>(
    include: &[R],
    exclude: &[R],
    check: impl Fn(&R) -> Result<(), String>,
) -> Result<(), GeometryError> {
    if include.is_empty() {
        return Err(GeometryError::EmptyGeometry);
    }
    for (list, regions) in [("include", include), ("exclude", exclude)] {
        for (index, r) in regions.iter().enumerate() {
            check(r).map_err(|reason| GeometryError::InvalidRegion {
                list,
                index,
                reason,
            })?;
        }
    }
    Ok(())
}

impl Body<2> for Geometry {
    fn validate(&self) -> Result<(), GeometryError> {
        Geometry::validate(self)
    }

    fn contains(&self, x: &Vector2<f64>) -> bool {
        Geometry::contains(self, *x)
    }

    fn bounding_box(&self) -> Option<(Vector2<f64>, Vector2<f64>)> {
        Geometry::bounding_box(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn polygon(vertices: &[[f64; 2]]) -> Region {
        Region::Polygon {
            vertices: vertices.to_vec(),
        }
    }

    #[test]
    fn a_self_crossing_polygon_is_refused_naming_its_edges() {
        // A bow tie: edges 0 (0,0)-(10,10) and 2 (10,0)-(0,10) cross at (5, 5).
        let e = polygon(&[[0.0, 0.0], [10.0, 10.0], [10.0, 0.0], [0.0, 10.0]])
            .validate()
            .unwrap_err();
        assert!(
            e.contains("edges 0 (vertices 0 to 1) and 2 (vertices 2 to 3) meet at (5.000, 5.000)"),
            "{e}"
        );
        // A fourth vertex on a non-adjacent edge touches it (5, 0); one at (10, -5) makes a spike that
        // folds back over an edge.
        for fourth in [[5.0, 0.0], [10.0, -5.0]] {
            let bad = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], fourth, [0.0, 10.0]];
            assert!(polygon(&bad).validate().is_err(), "{fourth:?}");
        }
        // Simple polygons pass, convex or not, in either orientation.
        let l_shape = [
            [0.0, 0.0],
            [10.0, 0.0],
            [10.0, 4.0],
            [4.0, 4.0],
            [4.0, 10.0],
            [0.0, 10.0],
        ];
        assert_eq!(polygon(&l_shape).validate(), Ok(()));
        let reversed: Vec<[f64; 2]> = l_shape.iter().rev().copied().collect();
        assert_eq!(polygon(&reversed).validate(), Ok(()));
        assert_eq!(
            polygon(&[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]).validate(),
            Ok(())
        );
    }
}
