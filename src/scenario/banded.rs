//! Seeding where the points live (`docs/theory.md`, "Processes"): on `P` processes each one seeds only
//! the points of its own band of cell rows ([`crate::partition`]), so that no process holds the whole
//! set. The bands come from the points per cell row, counted first without storing any point: each
//! process counts every `P`-th layer of each body's seeding lattice and the counts are summed. A process
//! then seeds the layers of its band and numbers its points as the whole seeding would (the points of a
//! body are seeded layer by layer, so a band's points are one run of ids per body): the same points with
//! the same data, order and ids as a process keeps from the whole set ([`crate::partition::keep_own`]).
//! A plate (`[extrusion]`) extrudes its band of plane points ([`Setup::extrude`]); its points are
//! numbered as in the whole plate.

use super::*;
use crate::grid::SLOWEST_AXIS;
use crate::model::Method;
use crate::partition::Partition;
use crate::petsc::SessionGuard;
use crate::seeding::LayerCounts;
use std::ops::Range;

/// [`build_run`] on the processes of `session`: on more than one, when the configuration allows it
/// (MPM with plane bodies on one velocity field, no turned grid, no path following) and not
/// `resuming` (a checkpoint holds every point), each process seeds its own band only. Returns the
/// set-up and whether its points are this process's band (else every point). Collective.
pub fn build_run_on(
    plan: Plan<'_>,
    session: &SessionGuard,
    resuming: bool,
) -> Result<(RunSetup, bool), ScenarioError> {
    if !resuming && plan.seeds_in_bands(session.size()) {
        let extrusion = plan.config().extrusion.clone();
        if let Some(setup) = plan.build_band(session)? {
            let setup = match extrusion {
                None => RunSetup::Plane(setup),
                Some(e) => RunSetup::Plate(extrude_band(setup, e.thickness)?),
            };
            return Ok((setup, true));
        }
    }
    build_run(plan).map(|setup| (setup, false))
}

/// The band `setup` extruded to the plate of `thickness` (mm) as [`Setup::extrude`] extrudes the whole
/// set: every plane point becomes `c` points through the thickness (the same `c` for all, seeded alike),
/// so plane point `i` becomes points `c i .. c i + c - 1`, numbered here as in the whole plate.
fn extrude_band(setup: Setup, thickness: f64) -> Result<Setup<3>, ScenarioError> {
    let plane_ids = setup.particles.id.clone();
    let mut plate = setup.extrude(thickness)?;
    let copies = plate.particles.len() / plane_ids.len().max(1);
    if plate.particles.len() != copies * plane_ids.len() {
        return Err(ScenarioError::Processes(format!(
            "{} plate points from {} plane points: not the same number through the thickness for each",
            plate.particles.len(),
            plane_ids.len()
        )));
    }
    let c = copies as u64;
    plate.particles.id = plane_ids
        .iter()
        .flat_map(|&i| (0..c).map(move |k| c * i + k))
        .collect();
    Ok(plate)
}

/// A body's points per layer of its seeding lattice, summed over the processes.
struct Counted {
    /// The body's seeding.
    seeding: Seeding,
    /// Its layers and their points.
    layers: LayerCounts<2>,
}

impl Plan<'_> {
    /// Whether the points can be seeded in bands on `processes` processes: MPM with bodies of the plane
    /// (extruded or not; no body of space, no turned grid), every body on the specimen's velocity field
    /// and no path following (its gauge picks the points nearest two places among all). Otherwise every
    /// process seeds every point and keeps its own at the first step.
    fn seeds_in_bands(&self, processes: usize) -> bool {
        let cfg = self.cfg;
        let plane = |b: &BodyDef| matches!(b.geometry, BodyShape::Plane(_)) && !b.own_field;
        processes > 1
            && cfg.shape.method == Method::Mpm
            && cfg.path.is_none()
            && cfg.grid.frame().is_identity()
            && self.bodies.iter().all(plane)
    }

    /// The plane set-up with this process's band of points, or `None` where a band would hold no point
    /// of some body (then the solver's defaults, chosen from the bodies present, could differ between
    /// processes: every process seeds every point instead) or the grid has fewer cell rows than there
    /// are processes (the first step says so). Collective.
    fn build_band(&self, session: &SessionGuard) -> Result<Option<Setup>, ScenarioError> {
        let seeder = Seeder::new(self.cfg);
        let counted = self.count_layers(&seeder, session)?;
        let (fields, field_of) = velocity_fields(&self.bodies);
        let (rigid, rigid_points) =
            seeder.rigid_bodies(&self.rigid, &self.rigid_keys, &field_of)?;
        let body_bounds = counted
            .iter()
            .fold(bounds(std::iter::empty()), |(lo, hi), c| {
                let (l, h) = c.layers.bounds;
                (lo.inf(&l), hi.sup(&h))
            });
        let grid = covering_grid(self.cfg, body_bounds, &rigid_points)?;
        let rows_of = |c: &Counted| -> Vec<usize> {
            let h = grid.cell_size();
            let y = |j: usize| (c.layers.first + j as f64 + 0.5) * h;
            let layers = 0..c.layers.counts.len();
            layers.map(|j| Partition::row_of(&grid, y(j))).collect()
        };
        let rows: Vec<Vec<usize>> = counted.iter().map(rows_of).collect();
        let mut row_counts = vec![0.0; grid.cells()[SLOWEST_AXIS]];
        for (c, rows) in counted.iter().zip(&rows) {
            for (n, &row) in c.layers.counts.iter().zip(rows) {
                row_counts[row] += n;
            }
        }
        let Ok(part) = Partition::from_row_counts(session, &grid, &row_counts) else {
            return Ok(None);
        };
        let every_band_holds_every_body = counted.iter().zip(&rows).all(|(c, rows)| {
            held_per_band(&part, &grid, session.size(), &c.layers.counts, rows)
                .iter()
                .all(|&n| n > 0.0)
        });
        if !every_band_holds_every_body {
            return Ok(None);
        }
        let ranges: Vec<Range<usize>> = rows.iter().map(|r| band_layers(&part, &grid, r)).collect();
        let particles = self.seed_bands(&seeder, &counted, &ranges)?;
        let seeded = Seeded {
            particles,
            materials: self.bodies.iter().map(|b| b.material.clone()).collect(),
            fields,
            rigid,
            rigid_points,
        };
        seeded.setup(self.cfg, body_bounds).map(Some)
    }

    /// Each body's [`LayerCounts`] summed over the processes (each counts every `P`-th layer), with the
    /// bounding box of all its points; a body without points is refused as in a serial run. Collective.
    fn count_layers(
        &self,
        seeder: &Seeder,
        session: &SessionGuard,
    ) -> Result<Vec<Counted>, ScenarioError> {
        let (rank, size) = (session.rank(), session.size());
        let mut counted = Vec::with_capacity(self.bodies.len());
        for (tag, b) in self.bodies.iter().enumerate() {
            let g = plane_geometry(b)?;
            let seeding = seeder.seeding(b.density, tag as u16);
            let layers = seeding
                .layer_counts(g, |j| j % size == rank)
                .map_err(|e| seeder.refused((&b.key, &b.name), e))?;
            counted.push(Counted { seeding, layers });
        }
        let mut sums: Vec<f64> = counted
            .iter()
            .flat_map(|c| c.layers.counts.clone())
            .collect();
        let mut extremes: Vec<f64> = counted
            .iter()
            .flat_map(|c| {
                let (lo, hi) = c.layers.bounds;
                [lo.x, lo.y, -hi.x, -hi.y]
            })
            .collect();
        session.sum(&mut sums).map_err(build_error)?;
        session.min(&mut extremes).map_err(build_error)?;
        let mut sums = sums.into_iter();
        for ((c, e), b) in counted.iter_mut().zip(extremes.chunks(4)).zip(&self.bodies) {
            c.layers
                .counts
                .iter_mut()
                .for_each(|n| *n = sums.next().unwrap_or(0.0));
            c.layers.bounds = (Vector2::new(e[0], e[1]), Vector2::new(-e[2], -e[3]));
            if c.layers.counts.iter().sum::<f64>() == 0.0 {
                return Err(seeder
                    .refused((&b.key, &b.name), ParticleError::NoPoints)
                    .into());
            }
        }
        Ok(counted)
    }

    /// The points of the layers `ranges` of each body (tagged, with its initial velocity), numbered as
    /// the whole seeding numbers them: after every point of the bodies before and of the layers below.
    fn seed_bands(
        &self,
        seeder: &Seeder,
        counted: &[Counted],
        ranges: &[Range<usize>],
    ) -> Result<Particles, ScenarioError> {
        let mut particles = Particles::new();
        let mut ids = Vec::new();
        let mut before = 0.0;
        for ((b, c), range) in self.bodies.iter().zip(counted).zip(ranges) {
            let g = plane_geometry(b)?;
            let refused = |e| seeder.refused((&b.key, &b.name), e);
            let mut p = Particles::seed_layers(g, &c.seeding, range.clone()).map_err(refused)?;
            p.v.iter_mut().for_each(|v| *v = b.velocity);
            let first = before + c.layers.counts[..range.start].iter().sum::<f64>();
            ids.extend((0..p.len() as u64).map(|i| first as u64 + i));
            particles.append(&p).map_err(refused)?;
            before += c.layers.counts.iter().sum::<f64>();
        }
        particles.id = ids;
        Ok(particles)
    }
}

/// The layers (of one body's seeding lattice; `rows`: the grid's cell row of each) whose points this
/// process owns: the layers are in the order of their rows, so the owned ones are one range.
fn band_layers(part: &Partition, grid: &Grid, rows: &[usize]) -> Range<usize> {
    let own = |j: &usize| owner_of_row(part, grid, rows[*j]) == part.rank();
    let mut owned = (0..rows.len()).filter(own);
    match owned.next() {
        Some(first) => first..owned.next_back().unwrap_or(first) + 1,
        None => 0..0,
    }
}

/// The points of `counts` (per layer; `rows`: the grid's cell row of each layer) in each band.
fn held_per_band(
    part: &Partition,
    grid: &Grid,
    processes: usize,
    counts: &[f64],
    rows: &[usize],
) -> Vec<f64> {
    let mut held = vec![0.0; processes];
    for (n, &row) in counts.iter().zip(rows) {
        held[owner_of_row(part, grid, row)] += n;
    }
    held
}

/// The process owning the cell row `row` of `grid` (through the height of its middle).
fn owner_of_row(part: &Partition, grid: &Grid, row: usize) -> usize {
    let y = grid.origin().y + (row as f64 + 0.5) * grid.cell_size();
    part.owner(Vector2::new(grid.origin().x, y))
}

/// The geometry of a plane body ([`Plan::seeds_in_bands`] admits no other).
fn plane_geometry(b: &BodyDef) -> Result<&PlaneGeometry, ScenarioError> {
    match &b.geometry {
        BodyShape::Plane(g) => Ok(g),
        BodyShape::Space(_) => Err(ScenarioError::Processes(format!(
            "{} ({}) is a body of space: seeded in bands in the plane only",
            b.key, b.name
        ))),
    }
}

/// A failed collective while seeding, as a failed build.
fn build_error(e: crate::petsc::PetscError) -> ScenarioError {
    ScenarioError::Processes(format!("summing the points per layer: {e}"))
}
