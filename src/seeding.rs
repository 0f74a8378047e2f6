//! Seeding: the material points of a body ([`crate::geometry`]) on the lattice of grid cells, for the
//! material point method ([`Particles::seed`]) and for the FEM mode ([`Particles::seed_gauss`])
//! (spec `01-model.md`, Sec. 2; `03-ct-test.md` for the CT plate).
//!
//! [`Particles::seed`] fills the cells `[i h, (i + 1) h] x [j h, (j + 1) h]` of the lattice of multiples of
//! `h` (the lattice [`crate::grid::Grid::covering`] snaps to) with `n x n` points at
//! `((i + (a + 1/2)/n) h, (j + (b + 1/2)/n) h)`, `a, b = 0..n`, each with volume `V_p^0 = h^2 / n^2`, mass
//! `m_p = rho V_p^0` and the initial CPDI domain = its square sub-cell: `r1^0 = (h/(2n), 0)`,
//! `r2^0 = (0, h/(2n))`.
//!
//! A point is kept if it lies in the union of the `include` regions and in none of the `exclude` regions
//! (boundaries within [`crate::geometry::BOUNDARY_TOL`] count as material, [`crate::geometry`]). With region edges on grid
//! lines (the CT plate and notch) no seeded point lies on a boundary, so the rule only matters for unusual
//! geometry.

use crate::geometry::{Body, GeometryError, Seeding};
use crate::particles::{ParticleError, Particles, SeedingParameter, lattice};
use nalgebra::{SMatrix, SVector};

impl<const D: usize> Particles<D> {
    /// Seeds `n^D` points per cell of the lattice of multiples of `h` (module docs) into the material of
    /// `geometry`: points at `(i + (a + 1/2)/n) h` per direction, volume `(h/n)^D`, half-edges `h/(2n)`
    /// along the axes. Errors for an invalid geometry or seeding, and when no point is material.
    pub fn seed<B: Body<D>>(geometry: &B, seeding: &Seeding) -> Result<Self, ParticleError> {
        let vol0 = (seeding.h / seeding.points_per_cell as f64).powi(D as i32);
        Self::seeded(geometry, seeding, |cells, push| {
            each_point(geometry, seeding, cells, |x| push(x, vol0))
        })
    }

    /// FEM mode seeding: the `n^D` Gauss points (`n` = 1, 2 or 3) of every lattice cell whose centre is
    /// material, with the Gauss weights times the cell's volume as `V_p^0` (so that sums over points
    /// integrate polynomials of degree `2n - 1` per direction exactly). Half-edges `h/(2n)`.
    pub fn seed_gauss<B: Body<D>>(geometry: &B, seeding: &Seeding) -> Result<Self, ParticleError> {
        let (h, n) = (seeding.h, seeding.points_per_cell);
        let g = 1.0 / 3.0_f64.sqrt();
        let q = 0.6_f64.sqrt();
        let rule: &[(f64, f64)] = match n {
            1 => &[(0.0, 2.0)],
            2 => &[(-g, 1.0), (g, 1.0)],
            3 => &[(-q, 5.0 / 9.0), (0.0, 8.0 / 9.0), (q, 5.0 / 9.0)],
            _ => {
                return Err(ParticleError::InvalidSeeding {
                    parameter: SeedingParameter::PointsPerCell,
                    reason: format!("{n} Gauss points per direction: 1, 2 or 3 are available"),
                });
            }
        };
        Self::seeded(geometry, seeding, |cells, push| {
            each_material_cell(geometry, h, cells, |centre| {
                for sub in lattice::<D>([n; D]) {
                    let x = centre + SVector::from_fn(|d, _| 0.5 * h * rule[sub[d]].0);
                    let vol = (0..D).map(|d| rule[sub[d]].1 * 0.5 * h).product::<f64>();
                    push(x, vol);
                }
            })
        })
    }

    /// The points of a seeding on the checked lattice of `geometry` ([`checked_lattice`]): `place` hands
    /// each point's position (mm) and initial volume `V_p^0` (mm^3) to its `push`, which gives it the mass
    /// `rho V_p^0`, the body tag and half-edges `h/(2n)` along the axes. Errors for an invalid geometry or
    /// seeding, and when no point is material.
    fn seeded<B: Body<D>>(
        geometry: &B,
        seeding: &Seeding,
        place: impl FnOnce(([f64; D], [usize; D]), &mut dyn FnMut(SVector<f64, D>, f64)),
    ) -> Result<Self, ParticleError> {
        let cells = checked_lattice(geometry, seeding)?;
        let half_edge = seeding.h / (2.0 * seeding.points_per_cell as f64);
        let r0 = SMatrix::<f64, D, D>::identity() * half_edge;
        let mut particles = Self::new();
        place(cells, &mut |x, vol| {
            particles.push(x, vol, seeding.density * vol, r0, seeding.body)
        });
        if particles.is_empty() {
            return Err(ParticleError::NoPoints);
        }
        Ok(particles)
    }
}

/// Most candidate points [`Seeding::count`] visits; a larger lattice is counted coarser.
const COUNT_LIMIT: f64 = 2e7;

impl Seeding {
    /// The number of points that seeding `geometry` places ([`Particles::seed`], or with `gauss`
    /// [`Particles::seed_gauss`]), counted on the same lattice without storing any. A lattice of more
    /// than 2e7 candidate points is counted on a lattice `k` times coarser per direction and the count
    /// scaled by `k^D`: an estimate, for runs too large to seed. Errors for an invalid geometry or
    /// seeding; none when no point is material (0).
    pub fn count<const D: usize, B: Body<D>>(
        &self,
        geometry: &B,
        gauss: bool,
    ) -> Result<f64, ParticleError> {
        let (_, counts) = cell_lattice(geometry, self)?;
        let per_cell = (self.points_per_cell as f64).powi(D as i32);
        let candidates = counts.iter().product::<f64>() * per_cell;
        let k = (candidates / COUNT_LIMIT)
            .powf(1.0 / D as f64)
            .ceil()
            .max(1.0);
        let coarse = Seeding {
            h: k * self.h,
            ..*self
        };
        let cells = checked_lattice(geometry, &coarse)?;
        let mut n = 0.0;
        match gauss {
            false => each_point(geometry, &coarse, cells, |_| n += 1.0),
            true => each_material_cell(geometry, coarse.h, cells, |_| n += per_cell),
        }
        Ok(n * k.powi(D as i32))
    }
}

/// The material points of MPM seeding per layer of lattice cells (a layer: the cells of one index along
/// the lattice's last axis, `y` in the plane), counted without storing any, for the processes that seed
/// in bands ([`Particles::seed_layers`]).
#[derive(Debug, Clone, PartialEq)]
pub struct LayerCounts<const D: usize> {
    /// The lattice's first layer, in cells (its lower face at `first h`, mm).
    pub first: f64,
    /// Material points per layer (0 for the layers not counted).
    pub counts: Vec<f64>,
    /// The bounding box of the counted points (mm): `(+inf, -inf)` per axis when none was counted.
    pub bounds: (SVector<f64, D>, SVector<f64, D>),
}

impl Seeding {
    /// [`LayerCounts`] of MPM seeding ([`Particles::seed`]) of `geometry`, over the layers for which
    /// `counted` is true (e.g. every `P`-th one: processes share the count, then sum it). Errors as
    /// [`Particles::seed`] for an invalid geometry or seeding; none when no point is material.
    pub fn layer_counts<const D: usize, B: Body<D>>(
        &self,
        geometry: &B,
        counted: impl Fn(usize) -> bool,
    ) -> Result<LayerCounts<D>, ParticleError> {
        let (first, counts) = checked_lattice(geometry, self)?;
        let last = D - 1;
        let mut out: LayerCounts<D> = LayerCounts {
            first: first[last],
            counts: vec![0.0; counts[last]],
            bounds: (
                SVector::repeat(f64::INFINITY),
                SVector::repeat(f64::NEG_INFINITY),
            ),
        };
        for layer in (0..counts[last]).filter(|&j| counted(j)) {
            let (lo, hi): &mut (SVector<f64, D>, SVector<f64, D>) = &mut out.bounds;
            let mut n = 0.0;
            each_point(
                geometry,
                self,
                layers(first, counts, layer..layer + 1),
                |x| {
                    n += 1.0;
                    *lo = lo.inf(&x);
                    *hi = hi.sup(&x);
                },
            );
            out.counts[layer] = n;
        }
        Ok(out)
    }
}

impl<const D: usize> Particles<D> {
    /// MPM seeding ([`Particles::seed`]) of the cell layers `range` of the lattice only (layers as in
    /// [`LayerCounts`]): the same points with the same data, in the same order, as the whole seeding
    /// holds them; ids numbered from 0 (the caller offsets them by the points of the layers below). No
    /// error when no point is material (a band may hold none of a body).
    pub fn seed_layers<B: Body<D>>(
        geometry: &B,
        seeding: &Seeding,
        range: std::ops::Range<usize>,
    ) -> Result<Self, ParticleError> {
        let (first, counts) = checked_lattice(geometry, seeding)?;
        let range = range.start.min(counts[D - 1])..range.end.min(counts[D - 1]);
        let vol0 = (seeding.h / seeding.points_per_cell as f64).powi(D as i32);
        let half_edge = seeding.h / (2.0 * seeding.points_per_cell as f64);
        let r0 = SMatrix::<f64, D, D>::identity() * half_edge;
        let mut particles = Self::new();
        each_point(geometry, seeding, layers(first, counts, range), |x| {
            particles.push(x, vol0, seeding.density * vol0, r0, seeding.body)
        });
        Ok(particles)
    }
}

/// The lattice `(first, counts)` narrowed to the layers `range` along its last axis (cell units: the
/// first cell and the cell counts, as [`checked_lattice`]).
fn layers<const D: usize>(
    mut first: [f64; D],
    mut counts: [usize; D],
    range: std::ops::Range<usize>,
) -> ([f64; D], [usize; D]) {
    first[D - 1] += range.start as f64;
    counts[D - 1] = range.len();
    (first, counts)
}

/// Each material point of MPM seeding (module docs) on the lattice `cells` ([`checked_lattice`]).
fn each_point<const D: usize, B: Body<D>>(
    geometry: &B,
    seeding: &Seeding,
    (first, counts): ([f64; D], [usize; D]),
    mut keep: impl FnMut(SVector<f64, D>),
) {
    let (h, n) = (seeding.h, seeding.points_per_cell);
    let nf = n as f64;
    for cell in lattice::<D>(counts) {
        for sub in lattice::<D>([n; D]) {
            let x = SVector::from_fn(|d, _| {
                (first[d] + cell[d] as f64 + (sub[d] as f64 + 0.5) / nf) * h
            });
            if geometry.contains(&x) {
                keep(x);
            }
        }
    }
}

/// The centre of each cell of the lattice `cells` ([`checked_lattice`], cell size `h`) that is material.
fn each_material_cell<const D: usize, B: Body<D>>(
    geometry: &B,
    h: f64,
    (first, counts): ([f64; D], [usize; D]),
    mut keep: impl FnMut(SVector<f64, D>),
) {
    for cell in lattice::<D>(counts) {
        let centre = SVector::from_fn(|d, _| (first[d] + cell[d] as f64 + 0.5) * h);
        if geometry.contains(&centre) {
            keep(centre);
        }
    }
}

/// The cells of the lattice of multiples of `h` that cover the body's bounding box: the first cell (in cell
/// units) and the cell count per direction. Checks the body and the seeding parameters.
fn cell_lattice<const D: usize, B: Body<D>>(
    geometry: &B,
    seeding: &Seeding,
) -> Result<([f64; D], [f64; D]), ParticleError> {
    geometry.validate()?;
    let Seeding {
        h,
        points_per_cell: n,
        density,
        ..
    } = *seeding;
    let bad = |parameter, reason: String| Err(ParticleError::InvalidSeeding { parameter, reason });
    if !(h.is_finite() && h > 0.0) {
        return bad(
            SeedingParameter::CellSize,
            format!("cell size h = {h} mm must be positive"),
        );
    }
    if n == 0 {
        return bad(
            SeedingParameter::PointsPerCell,
            "points_per_cell must be at least 1".into(),
        );
    }
    if !(density.is_finite() && density > 0.0) {
        return bad(
            SeedingParameter::Density,
            format!("density = {density} t/mm^3 must be positive"),
        );
    }
    let (lo, hi) = geometry
        .bounding_box()
        .ok_or(GeometryError::EmptyGeometry)?;
    let first: [f64; D] = std::array::from_fn(|d| (lo[d] / h).floor());
    let counts: [f64; D] = std::array::from_fn(|d| (hi[d] / h).ceil() - first[d]);
    Ok((first, counts))
}

/// [`cell_lattice`] with the cell counts as integers, after checking that the candidate points can be
/// numbered.
fn checked_lattice<const D: usize, B: Body<D>>(
    geometry: &B,
    seeding: &Seeding,
) -> Result<([f64; D], [usize; D]), ParticleError> {
    let (first, counts) = cell_lattice(geometry, seeding)?;
    let candidates =
        counts.iter().product::<f64>() * (seeding.points_per_cell as f64).powi(D as i32);
    if candidates.is_nan() || candidates > u32::MAX as f64 {
        return Err(ParticleError::InvalidSeeding {
            parameter: SeedingParameter::CellSize,
            reason: format!("{candidates} candidate points: cell size too small for the geometry"),
        });
    }
    Ok((first, counts.map(|c| c as usize)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Geometry, Region};
    use crate::particles::tests::{rect, rect_geometry};
    use nalgebra::{Matrix2, Vector2};

    /// The CT default plate: 200 x 200 mm minus a 110 x 10 mm notch from the left edge at mid-height.
    fn ct_geometry() -> Geometry {
        toml::from_str(
            r#"
            include = [{ type = "rect", min = [0.0, 0.0], max = [200.0, 200.0] }]
            exclude = [{ type = "rect", min = [0.0, 95.0], max = [110.0, 105.0] }]
            "#,
        )
        .unwrap()
    }

    #[test]
    fn particles_seed_ct_plate_count_volume_and_mass() {
        let p = Particles::seed(&ct_geometry(), &Seeding::concrete(1.0, 2)).unwrap();
        assert_eq!(p.len(), 4 * (40_000 - 1_100));
        assert_eq!(p.len(), 155_600);
        let vol: f64 = p.vol0.iter().sum();
        assert!((vol - (40_000.0 - 1_100.0)).abs() < 1e-8);
        let mass: f64 = p.mass.iter().sum();
        assert!((mass / (2.4e-9 * 38_900.0) - 1.0).abs() < 1e-10);
        assert!(
            p.x.iter()
                .all(|x| !(x.x < 110.0 && x.y > 95.0 && x.y < 105.0))
        );
        assert_eq!(p.x[0], Vector2::new(0.25, 0.25));
        assert_eq!(p.x[3], Vector2::new(0.75, 0.75));
        assert_eq!(p.r[0], Matrix2::identity() * 0.25);
        assert_eq!(
            p.corners(0),
            [
                Vector2::new(0.0, 0.0),
                Vector2::new(0.5, 0.0),
                Vector2::new(0.5, 0.5),
                Vector2::new(0.0, 0.5)
            ]
        );
        assert!(p.f.iter().all(|f| *f == Matrix2::identity()));
        let (lo, hi) = p.bounding_box().unwrap();
        assert_eq!(
            (lo, hi),
            (Vector2::new(0.0, 0.0), Vector2::new(200.0, 200.0))
        );
    }

    #[test]
    fn counting_finds_the_seeded_points_and_estimates_a_lattice_too_large_to_visit() {
        let plate = ct_geometry();
        for n in [1, 2, 3] {
            let seeding = Seeding::concrete(2.0, n);
            let seeded = Particles::seed(&plate, &seeding).unwrap().len() as f64;
            assert_eq!(seeding.count(&plate, false).unwrap(), seeded, "{n}");
            let gauss = Particles::seed_gauss(&plate, &seeding).unwrap().len() as f64;
            assert_eq!(seeding.count(&plate, true).unwrap(), gauss, "{n}");
        }
        // 1.6e9 candidates at 0.01 mm: counted on a lattice 9 times coarser, within 0.1 %.
        let fine = Seeding::concrete(0.01, 2).count(&plate, false).unwrap();
        let exact = 4.0 * (40_000.0 - 1_100.0) / 1e-4;
        assert!((fine / exact - 1.0).abs() < 1e-3, "{fine} against {exact}");
        // Beyond what can be numbered: a count all the same.
        assert!(Seeding::concrete(1e-6, 2).count(&plate, false).unwrap() > 1e16);
    }

    #[test]
    fn seeding_in_layers_gives_the_whole_seeding_piece_by_piece() {
        let plate = ct_geometry();
        let seeding = Seeding::concrete(2.0, 2);
        let whole = Particles::seed(&plate, &seeding).unwrap();
        // Counted by 3 processes, each every third layer, then summed.
        let shares: Vec<LayerCounts<2>> = (0..3)
            .map(|r| seeding.layer_counts(&plate, |j| j % 3 == r).unwrap())
            .collect();
        let counts: Vec<f64> = (0..shares[0].counts.len())
            .map(|j| shares.iter().map(|s| s.counts[j]).sum())
            .collect();
        assert_eq!(counts.iter().sum::<f64>(), whole.len() as f64);
        let (lo, hi) = shares.iter().fold(shares[0].bounds, |(lo, hi), s| {
            (lo.inf(&s.bounds.0), hi.sup(&s.bounds.1))
        });
        let x = &whole.x;
        let exact = x
            .iter()
            .fold((x[0], x[0]), |(l, h), p| (l.inf(p), h.sup(p)));
        assert_eq!((lo, hi), exact);
        assert_eq!(shares[0].first, 0.0);
        // Three bands of layers, seeded apart, hold the whole seeding's points in its order.
        let mut joined = Particles::new();
        for range in [0..30, 30..31, 31..200] {
            let band = Particles::seed_layers(&plate, &seeding, range.clone()).unwrap();
            let below: f64 = counts[..range.start.min(counts.len())].iter().sum();
            assert_eq!(joined.len() as f64, below);
            joined.append(&band).unwrap();
        }
        assert_eq!(joined, whole);
    }

    #[test]
    fn particles_seed_disk_counts_and_boundary_rule() {
        // A disk of radius 10 mm seeded at 0.25 mm spacing holds pi r^2 of material to the staircase error.
        let disk = Geometry {
            include: vec![Region::Disk {
                centre: [0.0, 0.0],
                radius: 10.0,
            }],
            exclude: vec![],
        };
        let p = Particles::seed(&disk, &Seeding::concrete(0.5, 2)).unwrap();
        let area: f64 = p.vol.iter().sum();
        assert!(
            (area / (std::f64::consts::PI * 100.0) - 1.0).abs() < 0.01,
            "{area}"
        );
        assert!(p.x.iter().all(|x| x.norm() <= 10.0));
        // Include regions are closed, exclude regions open: a point on the circle stays either way.
        let on = Vector2::new(3.0, 4.0);
        let r = Region::Disk {
            centre: [0.0, 0.0],
            radius: 5.0,
        };
        assert!(r.on_boundary(on) && r.in_closure(on) && !r.in_interior(on));
        assert!(r.in_interior(Vector2::new(3.0, 3.9)) && !r.in_closure(Vector2::new(3.0, 4.1)));
        let bad = Region::Disk {
            centre: [0.0, 0.0],
            radius: -1.0,
        };
        assert!(bad.validate().unwrap_err().contains("positive radius"));
    }

    #[test]
    fn particles_seed_polygon_and_boundary_rule() {
        // Right triangle with legs 4 mm: 1 point per cell at cell centres.
        let tri = Geometry {
            include: vec![Region::Polygon {
                vertices: vec![[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]],
            }],
            exclude: vec![],
        };
        let p = Particles::seed(&tri, &Seeding::concrete(1.0, 1)).unwrap();
        // Centres (i + 0.5, j + 0.5) with i + j + 1 <= 4: strictly inside for i + j <= 2 (6 points), on the
        // hypotenuse for i + j = 3 (4 points, kept because include regions are closed).
        assert_eq!(p.len(), 10);
        // A thin exclude strip whose boundary passes through point centres removes nothing on its boundary.
        let strip = Geometry {
            include: vec![rect([0.0, 0.0], [4.0, 4.0])],
            exclude: vec![rect([0.5, 0.0], [1.5, 4.0])],
        };
        let p = Particles::seed(&strip, &Seeding::concrete(1.0, 1)).unwrap();
        assert_eq!(p.len(), 16);
        let strip = Geometry {
            include: vec![rect([0.0, 0.0], [4.0, 4.0])],
            exclude: vec![rect([0.4, 0.0], [1.6, 4.0])],
        };
        assert_eq!(
            Particles::seed(&strip, &Seeding::concrete(1.0, 1))
                .unwrap()
                .len(),
            8
        );
    }

    #[test]
    fn particles_seed_errors() {
        let empty = Geometry {
            include: vec![],
            exclude: vec![],
        };
        assert_eq!(
            Particles::seed(&empty, &Seeding::concrete(1.0, 2)),
            Err(ParticleError::Geometry(GeometryError::EmptyGeometry))
        );
        let all_cut = Geometry {
            include: vec![rect([0.0, 0.0], [2.0, 2.0])],
            exclude: vec![rect([-1.0, -1.0], [3.0, 3.0])],
        };
        assert_eq!(
            Particles::seed(&all_cut, &Seeding::concrete(1.0, 2)),
            Err(ParticleError::NoPoints)
        );
        let bad_rect = rect_geometry([0.0, 0.0], [0.0, 2.0]);
        assert!(matches!(
            Particles::seed(&bad_rect, &Seeding::concrete(1.0, 2)),
            Err(ParticleError::Geometry(GeometryError::InvalidRegion {
                list: "include",
                index: 0,
                ..
            }))
        ));
        let bad_poly = Geometry {
            include: vec![rect([0.0, 0.0], [1.0, 1.0])],
            exclude: vec![Region::Polygon {
                vertices: vec![[0.0, 0.0], [1.0, 1.0]],
            }],
        };
        assert!(matches!(
            Particles::seed(&bad_poly, &Seeding::concrete(1.0, 2)),
            Err(ParticleError::Geometry(GeometryError::InvalidRegion {
                list: "exclude",
                index: 0,
                ..
            }))
        ));
        let g = ct_geometry();
        assert!(matches!(
            Particles::seed(&g, &Seeding::concrete(0.0, 2)),
            Err(ParticleError::InvalidSeeding { .. })
        ));
        assert!(matches!(
            Particles::seed(&g, &Seeding::concrete(1.0, 0)),
            Err(ParticleError::InvalidSeeding { .. })
        ));
        assert!(matches!(
            Particles::seed(&g, &Seeding::concrete(1e-9, 2)),
            Err(ParticleError::InvalidSeeding { .. })
        ));
    }

    #[test]
    fn particles_geometry_rejects_unknown_fields() {
        let unknown_region: Result<Geometry, _> = toml::from_str(
            r#"include = [{ type = "rect", min = [0.0, 0.0], max = [1.0, 1.0], maxx = 3 }]"#,
        );
        assert!(unknown_region.is_err());
        let unknown_top: Result<Geometry, _> = toml::from_str(
            r#"include = [{ type = "rect", min = [0.0, 0.0], max = [1.0, 1.0] }]
            excluded = []"#,
        );
        assert!(unknown_top.is_err());
        let unknown_kind: Result<Geometry, _> =
            toml::from_str(r#"include = [{ type = "circle", r = 1.0 }]"#);
        assert!(unknown_kind.is_err());
    }

    #[test]
    fn particles_append_and_history() {
        let g = ct_geometry();
        let mut concrete = Particles::seed(&g, &Seeding::concrete(2.0, 1)).unwrap();
        let plate_geom = rect_geometry([0.0, 90.0], [30.0, 95.0]);
        let plate = Particles::seed(
            &plate_geom,
            &Seeding {
                body: 1,
                density: 7.85e-9,
                ..Seeding::concrete(1.0, 2)
            },
        )
        .unwrap();
        assert_eq!(plate.len(), 30 * 5 * 4);
        concrete.resize_history(3, 1.25e-3);
        assert_eq!(
            concrete.append(&plate),
            Err(ParticleError::HistoryStrideMismatch { this: 3, other: 0 })
        );
        concrete.resize_history(0, 0.0);
        let n0 = concrete.len();
        concrete.append(&plate).unwrap();
        assert_eq!(concrete.len(), n0 + 600);
        assert_eq!(concrete.body.iter().filter(|&&b| b == 1).count(), 600);
        concrete.resize_history(2, 7.0);
        assert_eq!(concrete.history.len(), 2 * concrete.len());
        concrete.history_mut(5)[1] = 3.0;
        assert_eq!(concrete.history(5), &[7.0, 3.0]);
        assert_eq!(concrete.vol.len(), concrete.len());
        assert_eq!(concrete.stress.len(), concrete.len());
    }

    #[test]
    fn gauss_seeding_fills_whole_cells_with_exact_weights() {
        let g = ct_geometry();
        let h = 5.0;
        let area = 200.0 * 200.0 - 110.0 * 10.0;
        for n in 1..=3 {
            let p = Particles::seed_gauss(
                &g,
                &Seeding {
                    h,
                    points_per_cell: n,
                    density: 2.0,
                    body: 0,
                },
            )
            .unwrap();
            assert_eq!(p.len(), (area / (h * h)) as usize * n * n);
            let vol: f64 = p.vol0.iter().sum();
            assert!((vol - area).abs() < 1e-9 * area, "n = {n}: {vol}");
            // The rule integrates x^2 y^2 exactly over every cell (degree 2 per direction for n >= 2).
            if n >= 2 {
                let cells = [(0.0, 0.0), (195.0, 195.0)];
                for (x0, y0) in cells {
                    let exact = ((x0 + h).powi(3) - x0.powi(3)) / 3.0
                        * ((y0 + h).powi(3) - y0.powi(3))
                        / 3.0;
                    let q: f64 = (0..p.len())
                        .filter(|&i| {
                            let x = p.x[i];
                            x.x > x0 && x.x < x0 + h && x.y > y0 && x.y < y0 + h
                        })
                        .map(|i| p.vol0[i] * p.x[i].x.powi(2) * p.x[i].y.powi(2))
                        .sum();
                    assert!((q - exact).abs() < 1e-9 * exact, "n = {n}: {q} vs {exact}");
                }
            }
        }
        let four = Seeding {
            h,
            points_per_cell: 4,
            density: 2.0,
            body: 0,
        };
        assert!(matches!(
            Particles::seed_gauss(&g, &four),
            Err(ParticleError::InvalidSeeding { .. })
        ));
    }
}
