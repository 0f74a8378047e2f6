//! Results of a run, written as it goes and never left half-written (every file is written to a
//! temporary name and renamed into place):
//!
//! * `history.csv`: per step time, solver statistics, reactions and prescribed displacements of every
//!   constraint set, energies (header states the units);
//! * `fields_NNNNNN.h5` + `fields.xdmf`: point fields at output steps ([`FIELDS`]: position,
//!   displacement, velocity, Cauchy stress, damage, eta_bar, history maximum), each dataset with `units`
//!   and `description` attributes; open `fields.xdmf` in ParaView (`docs/paraview.md`);
//! * `damage_NNNNNN.png`: damage maps; `force_time.png`, `force_displacement.png`: reaction curves;
//! * `crack.json`: crack metrics at every output step (see [`crate::crack`]) when a notch tip is known,
//!   with `crack_length.png` and `band_width.png` drawn from them.

mod cracks;
mod provenance;
mod shared;

use crate::crack::{self, CrackCriteria, CrackState};
use crate::model::{Model, State};
pub use crate::output_file::{OutputError, write_atomic};
use crate::output_file::{exchange_err, io_err, tmp_name};
use crate::plot::{LinePlot, ScatterField, Series};
use crate::schema::{file, history};
use crate::solver::StepReport;
use crate::space::{Frame, xy};
pub use cracks::remeasure_cracks;
use cracks::{mid_z, save_line_plot, section_layer, speed_summary, write_crack_json};
use hdf5_metno::types::VarLenUnicode;
use nalgebra::{SVector, Vector2};
pub use shared::{Layout, PointRows, SharedCrc, SharedFile, SharedState};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Units system of the output files (attribute `units` of every `fields_NNNNNN.h5`).
pub const UNITS: &str = "mm, s, N, MPa, t";

/// How a point field is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// One value per point: a dataset of shape (N).
    Scalar,
    /// x, y, z per point: a dataset of shape (N, 3), z = 0 in the plane problems.
    Vector,
}

/// A dataset of the snapshot files `fields_NNNNNN.h5`, with its `units` and `description` attributes.
#[derive(Debug, Clone, Copy)]
pub struct Field {
    /// Dataset name, also the array name in ParaView.
    pub name: &'static str,
    /// Scalar or vector.
    pub kind: Kind,
    /// Units (`-` for dimensionless).
    pub units: &'static str,
    /// Meaning.
    pub description: &'static str,
}

impl Field {
    /// Values per point and their layout in the dataset: (N) for a scalar, (N, 3) for a vector.
    fn shape(&self) -> (usize, Layout) {
        match self.kind {
            Kind::Scalar => (1, Layout::Flat),
            Kind::Vector => (3, Layout::Rows),
        }
    }
}

/// The connectivity's values of this process's points in their local order: their ids, their rows.
fn connectivity<const D: usize>(shared: &SharedState<D>) -> Vec<i64> {
    shared
        .state
        .particles
        .id
        .iter()
        .map(|&i| i as i64)
        .collect()
}

/// The point indices 0..N-1 (int64, shape (N)): the XDMF topology, one vertex cell per material point,
/// without which ParaView's default reader makes no cells and its Surface representation draws nothing.
pub const CONNECTIVITY: Field = Field {
    name: "connectivity",
    kind: Kind::Scalar,
    units: "-",
    description: "point indices 0..N-1: the XDMF Polyvertex topology, one vertex cell per material point",
};

/// The point fields of a snapshot (float64); `position` is the XDMF geometry, the others its attributes.
pub const FIELDS: [Field; 15] = [
    Field {
        name: "position",
        kind: Kind::Vector,
        units: "mm",
        description: "current position of the material point (z = 0 in 2D)",
    },
    Field {
        name: "displacement",
        kind: Kind::Vector,
        units: "mm",
        description: "displacement from the position at the start of the run (z = 0 in 2D)",
    },
    Field {
        name: "velocity",
        kind: Kind::Vector,
        units: "mm/s",
        description: "velocity of the material point (z = 0 in 2D)",
    },
    Field {
        name: "sigma_xx",
        kind: Kind::Scalar,
        units: "MPa",
        description: "Cauchy stress, xx component",
    },
    Field {
        name: "sigma_yy",
        kind: Kind::Scalar,
        units: "MPa",
        description: "Cauchy stress, yy component",
    },
    Field {
        name: "sigma_xy",
        kind: Kind::Scalar,
        units: "MPa",
        description: "Cauchy stress, xy component",
    },
    Field {
        name: "sigma_zz",
        kind: Kind::Scalar,
        units: "MPa",
        description: "Cauchy stress, zz component (out of plane in 2D, plane strain)",
    },
    Field {
        name: "sigma_xz",
        kind: Kind::Scalar,
        units: "MPa",
        description: "Cauchy stress, xz component (0 in 2D)",
    },
    Field {
        name: "sigma_yz",
        kind: Kind::Scalar,
        units: "MPa",
        description: "Cauchy stress, yz component (0 in 2D)",
    },
    Field {
        name: "damage",
        kind: Kind::Scalar,
        units: "-",
        description: "scalar damage, 0 intact to 1 fully damaged",
    },
    Field {
        name: "eta_bar",
        kind: Kind::Scalar,
        units: "-",
        description: "nonlocal equivalent strain interpolated from the grid",
    },
    Field {
        name: "history_max",
        kind: Kind::Scalar,
        units: "-",
        description: "largest history variable of the material law (microplane: max over the \
                      microplanes of the history strain gamma_I; 0 for history-free laws)",
    },
    Field {
        name: "dissipated_tension",
        kind: Kind::Scalar,
        units: "MPa",
        description: "energy dissipated per reference volume by microplanes under tensile normal strain",
    },
    Field {
        name: "dissipated_compression",
        kind: Kind::Scalar,
        units: "MPa",
        description: "energy dissipated per reference volume by microplanes under compressive normal \
                      strain",
    },
    Field {
        name: "nonlocal_damage",
        kind: Kind::Scalar,
        units: "-",
        description: "damage gained while the local equivalent strain was below gamma_0 (carried in by \
                      the nonlocal field only)",
    },
];

/// The points of a snapshot's section gathered on process 0, in the order of their ids.
struct SectionPoints {
    /// Positions in the specimen's frame (mm).
    x: Vec<Vector2<f64>>,
    damage: Vec<f64>,
    nonlocal_damage: Vec<f64>,
    /// 3D: the z (mm) of the section's layer.
    layer: Option<f64>,
}

/// x, y, z (z = 0 in 2D) of the points at `x` with the ids `ids`, in the order of the ids (0..N-1, once
/// each).
pub fn positions_by_id<const D: usize>(ids: &[u64], x: &[SVector<f64, D>]) -> Vec<[f64; 3]> {
    let mut out = vec![[0.0; 3]; x.len()];
    for (&id, x) in ids.iter().zip(x) {
        out[id as usize] = xyz(x);
    }
    out
}

/// A point as x, y, z (mm; z = 0 in 2D).
fn xyz<const D: usize>(x: &SVector<f64, D>) -> [f64; 3] {
    std::array::from_fn(|d| if d < D { x[d] } else { 0.0 })
}

/// The XDMF index of the snapshots of `n` points: a temporal collection of point clouds, one vertex cell
/// per point (explicit connectivity), vectors with 3 components.
fn xdmf(snapshots: &[Snapshot], n: usize) -> String {
    let mut s = String::from("<?xml version=\"1.0\" ?>\n<!-- units: ");
    s.push_str(UNITS);
    for f in [&CONNECTIVITY].into_iter().chain(&FIELDS) {
        let _ = write!(s, "; {} {}", f.name, f.units);
    }
    s.push_str(" -->\n<Xdmf Version=\"3.0\">\n <Domain>\n  <Grid Name=\"material_points\" GridType=\"Collection\" CollectionType=\"Temporal\">\n");
    let item = |file: &str, name: &str, dims: &str, number: &str| {
        format!(
            "<DataItem Dimensions=\"{dims}\" NumberType=\"{number}\" Precision=\"8\" Format=\"HDF\">{file}:/{name}</DataItem>"
        )
    };
    let float = |file: &str, field: &Field| match field.kind {
        Kind::Scalar => item(file, field.name, &n.to_string(), "Float"),
        Kind::Vector => item(file, field.name, &format!("{n} 3"), "Float"),
    };
    let (geometry, attributes) = FIELDS.split_first().expect("position first");
    for snap in snapshots {
        let f = &snap.file;
        let _ = writeln!(
            s,
            "   <Grid Name=\"step_{:06}\" GridType=\"Uniform\">",
            snap.step
        );
        let _ = writeln!(s, "    <Time Value=\"{:.9e}\"/>", snap.time);
        let _ = writeln!(
            s,
            "    <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"{n}\" NodesPerElement=\"1\">{}</Topology>",
            item(f, CONNECTIVITY.name, &n.to_string(), "Int")
        );
        let _ = writeln!(
            s,
            "    <Geometry GeometryType=\"XYZ\">{}</Geometry>",
            float(f, geometry)
        );
        for a in attributes {
            let kind = match a.kind {
                Kind::Scalar => "Scalar",
                Kind::Vector => "Vector",
            };
            let _ = writeln!(
                s,
                "    <Attribute Name=\"{}\" AttributeType=\"{kind}\" Center=\"Node\">{}</Attribute>",
                a.name,
                float(f, a)
            );
        }
        s.push_str("   </Grid>\n");
    }
    s.push_str("  </Grid>\n </Domain>\n</Xdmf>\n");
    s
}

/// One written snapshot (for the XDMF index and run.json's list of snapshots).
#[derive(serde::Serialize, serde::Deserialize)]
struct Snapshot {
    step: usize,
    time: f64,
    file: String,
    /// The run's identity ([`crate::rundir::RunIdentity::id`]) in the file (absent in the checkpoints
    /// of earlier versions).
    #[serde(default)]
    run: Option<String>,
    /// [`fields_checksum`] of the file's point fields (absent as `run`).
    #[serde(default)]
    checksum: Option<String>,
}

/// The attribute of a snapshot holding the identity of the run that wrote it.
pub const RUN_ID_ATTR: &str = "run_id";
/// The attribute of a snapshot holding [`fields_checksum`] of its point fields as written.
pub const CHECKSUM_ATTR: &str = "fields_crc32";

/// CRC-32 (8 hex digits) of a snapshot's point fields: the bytes (little-endian) of `connectivity`,
/// then of the datasets of [`FIELDS`] in that order, `fields`.
pub fn fields_checksum(connectivity: &[i64], fields: &[&[f64]]) -> String {
    let mut h = crc32fast::Hasher::new();
    for c in connectivity {
        h.update(&c.to_le_bytes());
    }
    for values in fields {
        for v in *values {
            h.update(&v.to_le_bytes());
        }
    }
    format!("{:08x}", h.finalize())
}

/// The output directory of a run.
pub struct RunOutput {
    dir: PathBuf,
    title: String,
    /// The configuration text (TOML), stored in every snapshot file.
    config_text: String,
    /// The run's identity ([`crate::rundir::RunIdentity::id`]), stored in every snapshot file.
    run_id: Option<String>,
    rows: Vec<StepReport>,
    snapshots: Vec<Snapshot>,
    /// Positions at t = 0 as x, y, z (z = 0 in 2D), for the displacement field (mm).
    initial_position: Vec<[f64; 3]>,
    /// Cell size of the background grid (mm), the resolution of the crack metrics and the damage maps.
    cell_size: f64,
    /// False for the records of a run whose files another process writes.
    writes: bool,
    /// Notch tip (mm) and criteria of the crack metrics, if tracked.
    crack: Option<(Vector2<f64>, CrackCriteria)>,
    cracks: Vec<CrackState>,
    /// Rayleigh wave speed of the specimen's material (mm/s), the scale of the crack-tip speeds.
    rayleigh: Option<f64>,
    /// 2 or 3: a 3D run's forces are N and its energies N mm (of the whole plate), a 2D run's per mm of
    /// thickness.
    dimension: usize,
    /// 3D: the z (mm) of the section whose layer of points the crack metrics and damage maps show;
    /// `None`: the middle of the points' initial z range.
    section_z: Option<f64>,
    /// The specimen's frame on the grid (`grid.rotation`): reactions, displacements, crack metrics and
    /// damage maps are reported in the specimen's frame.
    frame: Frame,
    /// Process 0: the section's points of the snapshot noted last and its step, for its damage map.
    noted_section: Option<(usize, SectionPoints)>,
}

impl RunOutput {
    /// Creates (or reuses) `dir`, keeps a copy of the configuration text as `config.toml`; displacements
    /// are measured from the points of `initial` (the whole state at t = 0 of `model`, on one process).
    pub fn create<const D: usize>(
        dir: &Path,
        title: &str,
        config_text: &str,
        model: &Model<D>,
        initial: &State<D>,
    ) -> Result<Self, OutputError> {
        let positions = positions_by_id(&initial.particles.id, &initial.particles.x);
        Self::for_process(
            dir,
            (title, config_text),
            (model.params.grid.cell_size(), D),
            positions,
            true,
        )
    }

    /// The output of one process of a run (the only one in a serial run): in `dir` (created, with
    /// `config.toml`, where this process `writes` the run's files, process 0), of the run `title` with the
    /// configuration `config_text`, on a grid of `cell_size` mm in `dimension` dimensions; displacements
    /// are measured from `initial_position` (x, y, z of every point at t = 0, by id). The processes that
    /// do not write record the steps and take part in the snapshots' and checkpoints' collective writes.
    pub fn for_process(
        dir: &Path,
        (title, config_text): (&str, &str),
        (cell_size, dimension): (f64, usize),
        initial_position: Vec<[f64; 3]>,
        writes: bool,
    ) -> Result<Self, OutputError> {
        if writes {
            std::fs::create_dir_all(dir).map_err(io_err(dir))?;
            write_atomic(&dir.join(file::CONFIG), config_text.as_bytes())?;
        }
        Ok(Self {
            dir: dir.to_owned(),
            title: title.to_owned(),
            config_text: config_text.to_owned(),
            run_id: None,
            rows: Vec::new(),
            snapshots: Vec::new(),
            initial_position,
            cell_size,
            writes,
            crack: None,
            cracks: Vec::new(),
            rayleigh: None,
            dimension,
            section_z: None,
            frame: Frame::IDENTITY,
            noted_section: None,
        })
    }

    /// The identity of the run ([`crate::rundir::RunIdentity::id`]) that its snapshots carry.
    pub fn set_run_id(&mut self, id: &str) {
        self.run_id = Some(id.to_owned());
    }

    /// The snapshots recorded so far, for run.json.
    pub fn snapshot_records(&self) -> Vec<crate::rundir::SnapshotRecord> {
        self.snapshots
            .iter()
            .map(|s| crate::rundir::SnapshotRecord {
                file: s.file.clone(),
                step: s.step,
                run: s.run.clone(),
                checksum: s.checksum.clone(),
            })
            .collect()
    }

    /// A set-up turned inside the grid by `frame`: report its results in the specimen's frame.
    pub fn set_frame(&mut self, frame: Frame) {
        self.frame = frame;
    }

    /// 3D: measure the crack and draw the damage maps on the layer of points seeded nearest `z` (mm)
    /// instead of the middle one.
    pub fn set_section(&mut self, z: f64) {
        self.section_z = Some(z);
    }

    /// The points of `state` (local indices) that the crack metrics and damage maps show: every point in
    /// 2D, in 3D the layer of points seeded nearest the section plane (by their initial z, so that a layer
    /// stays one as the plate deforms), and that plane's z.
    fn section<const D: usize>(&self, state: &State<D>) -> (Vec<usize>, Option<f64>) {
        let p = &state.particles;
        if D < 3 {
            return ((0..p.len()).collect(), None);
        }
        let z0: Vec<f64> = self.initial_position.iter().map(|x| x[2]).collect();
        let (layer, ids) = section_layer(&z0, self.section_z.unwrap_or_else(|| mid_z(&z0)));
        let mut in_layer = vec![false; z0.len()];
        ids.into_iter().for_each(|i| in_layer[i] = true);
        let points = (0..p.len())
            .filter(|&k| in_layer[p.id[k] as usize])
            .collect();
        (points, Some(layer))
    }

    /// Measures the crack grown from `notch_tip` (mm) at every snapshot and writes `crack.json`; the
    /// tip speeds of the steps are compared with `rayleigh`, the Rayleigh speed of the specimen (mm/s).
    pub fn track_crack(&mut self, notch_tip: Vector2<f64>, criteria: CrackCriteria, rayleigh: f64) {
        self.crack = Some((notch_tip, criteria));
        self.rayleigh = Some(rayleigh);
    }

    /// The notch tip (mm), the criteria, the cell size (mm) and the specimen's frame on the grid (the
    /// crack is measured on the points' positions turned into it) of the crack metrics, if tracked.
    pub fn crack_tracking(&self) -> Option<(Vector2<f64>, CrackCriteria, f64, Frame)> {
        self.crack
            .map(|(tip, c)| (tip, c, self.cell_size, self.frame))
    }

    /// What the output has recorded (steps, snapshots, crack states), for a checkpoint.
    pub fn records_json(&self) -> serde_json::Value {
        serde_json::json!({ "rows": self.rows, "snapshots": self.snapshots, "cracks": self.cracks })
    }

    /// Restores the records of a checkpoint.
    pub fn restore_records(&mut self, v: &serde_json::Value) -> Result<(), serde_json::Error> {
        self.rows = serde_json::from_value(v["rows"].clone())?;
        self.snapshots = serde_json::from_value(v["snapshots"].clone())?;
        self.cracks = serde_json::from_value(v["cracks"].clone())?;
        Ok(())
    }

    /// Crack states measured so far.
    pub fn cracks(&self) -> &[CrackState] {
        &self.cracks
    }

    fn write_cracks(&self) -> Result<(), OutputError> {
        let Some((tip, criteria)) = &self.crack else {
            return Ok(());
        };
        write_crack_json(
            &self.dir,
            self.dimension == 3,
            *tip,
            criteria,
            &self.cracks,
            (&self.rows, speed_summary(&self.rows, self.rayleigh)),
        )
    }

    /// True if this process writes the run's files (process 0).
    pub fn writes(&self) -> bool {
        self.writes
    }

    /// Output directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Records a step (its reactions and displacements turned into the specimen's frame, its crack
    /// front's tip speed completed from the steps before, [`crack::tip_speed`]) and rewrites
    /// `history.csv`.
    pub fn record(&mut self, mut report: StepReport) -> Result<(), OutputError> {
        let vectors = report.reactions.iter_mut().chain(&mut report.displacements);
        vectors.for_each(|(_, v)| self.frame.components_to_specimen(v));
        if let Some(front) = &mut report.crack {
            front.speed = cracks::speed_after(&self.rows, report.time, front.length);
        }
        self.rows.push(report);
        if !self.writes {
            return Ok(());
        }
        self.write_history()
    }

    /// The recorded steps.
    pub fn rows(&self) -> &[StepReport] {
        &self.rows
    }

    fn write_history(&self) -> Result<(), OutputError> {
        let mut s = String::new();
        s.push_str(&history::units_line(self.dimension));
        if let Some(degrees) = self.frame.degrees() {
            let _ = writeln!(
                s,
                "# frame: the set-up ran turned by {degrees} deg inside the grid (grid.rotation); displacements \
                 and forces are turned back into the specimen's frame"
            );
        }
        // Rows of a run resumed from an older checkpoint have no front: their crack fields stay empty.
        let tip = self.rows.iter().any(|r| r.crack.is_some());
        let bytes = self.rows.iter().any(|r| !r.bytes_sent.is_empty());
        let path = self.rows.iter().any(|r| r.path.is_some());
        let after: Vec<&history::Column> = [
            Some(&history::TRAILING[..]),
            tip.then_some(&history::CRACK[..]),
            bytes.then_some(&history::BYTES[..]),
            path.then_some(&history::PATH[..]),
        ]
        .into_iter()
        .flatten()
        .flatten()
        .collect();
        let mut columns: Vec<String> = history::LEADING.iter().map(|c| c.name.into()).collect();
        if let Some(r) = self.rows.first() {
            for (name, _) in &r.reactions {
                columns.extend(history::reaction_columns(name, self.dimension));
            }
            for (name, _) in &r.rotations {
                columns.push(history::rotation_column(name));
            }
        }
        columns.extend(after.iter().map(|c| c.name.to_string()));
        s.push_str(&columns.join(","));
        s.push('\n');
        for r in &self.rows {
            history_row(&mut s, r, &after);
        }
        write_atomic(&self.dir.join(file::HISTORY), s.as_bytes())
    }

    /// Writes the point fields of the current state (HDF5 + XDMF index), measures the crack (if tracked) and
    /// draws a damage map (PNG); in 3D both of the section layer ([`RunOutput::set_section`]): records
    /// the snapshot ([`RunOutput::note_snapshot`]), then writes it ([`RunOutput::write_snapshot`]).
    /// Collective.
    pub fn snapshot<const D: usize>(&mut self, shared: &SharedState<D>) -> Result<(), OutputError> {
        self.note_snapshot(shared)?;
        self.write_snapshot(shared)
    }

    /// Records the snapshot of the state (its fields file with the checksum of its fields, the crack
    /// measured on it) without writing it, so that a checkpoint of the same step, written before the
    /// snapshot's files, lists it. Collective: the checksum is put together from every process's points,
    /// the section's points are gathered on process 0, which records.
    pub fn note_snapshot<const D: usize>(
        &mut self,
        shared: &SharedState<D>,
    ) -> Result<(), OutputError> {
        let state = shared.state;
        let name = file::numbered(file::FIELDS, state.counters.step);
        let checksum = self.checksum(shared, &self.dir.join(&name))?;
        let section = self.gather_section(shared)?;
        let mut dissipated = shared.rows.order().iter().fold([0.0; 2], |a, &k| {
            let d = state.particles.dissipated[k];
            [a[0] + d[0], a[1] + d[1]]
        });
        shared
            .session
            .sum(&mut dissipated)
            .map_err(exchange_err(&self.dir.join(file::CRACK)))?;
        if !self.writes {
            return Ok(());
        }
        self.snapshots.retain(|s| s.step != state.counters.step);
        self.snapshots.push(Snapshot {
            step: state.counters.step,
            time: state.counters.time,
            file: name,
            run: self.run_id.clone(),
            checksum: Some(checksum),
        });
        let Some(section) = section else {
            return Ok(());
        };
        let Some((tip, criteria)) = &self.crack else {
            self.noted_section = Some((state.counters.step, section));
            return Ok(());
        };
        let mut measured = crack::measure(
            &section.x,
            &section.damage,
            *tip,
            self.cell_size,
            state.particles.point_spacing(),
            criteria,
            state.counters.time,
        );
        measured.dissipated = dissipated;
        measured.nonlocal_points = section
            .damage
            .iter()
            .zip(&section.nonlocal_damage)
            .filter(|&(&d, &nl)| d >= criteria.damage_threshold && nl >= 0.5 * d)
            .count();
        self.cracks.retain(|c| c.time != measured.time);
        self.cracks.push(measured);
        self.noted_section = Some((state.counters.step, section));
        Ok(())
    }

    /// The points of the section ([`RunOutput::section`]) of every process, in the order of their ids, on
    /// process 0 (`None` on the others). Collective.
    fn gather_section<const D: usize>(
        &self,
        shared: &SharedState<D>,
    ) -> Result<Option<SectionPoints>, OutputError> {
        let (session, p) = (shared.session, &shared.state.particles);
        let (section, layer) = self.section(shared.state);
        let written: std::collections::HashSet<usize> =
            shared.rows.order().iter().copied().collect();
        let mut send = Vec::new();
        for &k in section.iter().filter(|k| written.contains(k)) {
            let x = self.frame.to_specimen(xy(&p.x[k]));
            send.extend([p.id[k] as f64, x.x, x.y, p.damage[k], p.nonlocal_damage[k]]);
        }
        let mut counts = vec![0; session.size()];
        counts[0] = send.len() / 5;
        let path = self
            .dir
            .join(file::numbered(file::DAMAGE_MAP, shared.state.counters.step));
        let received = session
            .exchange(5, &counts, &send)
            .map_err(exchange_err(&path))?;
        if session.rank() != 0 {
            return Ok(None);
        }
        let mut records: Vec<&[f64]> = received.chunks_exact(5).collect();
        records.sort_by(|a, b| a[0].total_cmp(&b[0]));
        Ok(Some(SectionPoints {
            x: records.iter().map(|r| Vector2::new(r[1], r[2])).collect(),
            damage: records.iter().map(|r| r[3]).collect(),
            nonlocal_damage: records.iter().map(|r| r[4]).collect(),
            layer,
        }))
    }

    /// Writes the snapshot of the state that [`RunOutput::note_snapshot`] recorded: `fields_<step>.h5`
    /// (every process its points, into a temporary that process 0 completes and renames into place once
    /// all have written), `fields.xdmf` for ParaView, `crack.json` (if the crack is tracked) and the
    /// damage map (process 0). Collective.
    pub fn write_snapshot<const D: usize>(
        &mut self,
        shared: &SharedState<D>,
    ) -> Result<(), OutputError> {
        let state = shared.state;
        let path = self
            .dir
            .join(file::numbered(file::FIELDS, state.counters.step));
        let tmp = tmp_name(&path);
        let written = self.write_point_fields(&tmp, shared).and_then(|()| {
            if self.writes {
                self.describe_h5(&tmp, state)
            } else {
                Ok(())
            }
        });
        if let Err(e) = written {
            // A full disk leaves no half-written temporary behind.
            if self.writes {
                let _ = std::fs::remove_file(&tmp);
            }
            return Err(OutputError::hdf5(&path, &e));
        }
        if !self.writes {
            return Ok(());
        }
        std::fs::rename(&tmp, &path).map_err(io_err(&path))?;
        self.write_xdmf(shared.rows.total())?;
        self.write_cracks()?;
        let map = self
            .dir
            .join(file::numbered(file::DAMAGE_MAP, state.counters.step));
        match self.noted_section.take() {
            Some((step, section)) if step == state.counters.step => {
                self.damage_map(state, &section, &map)
            }
            _ => Err(OutputError::Run {
                path: map.display().to_string(),
                message: "the snapshot was not noted before it was written".into(),
            }),
        }
    }

    /// The point datasets of the snapshot (connectivity and [`FIELDS`]), every process writing its
    /// points into the new file `path` ([`SharedFile`]). Collective.
    fn write_point_fields<const D: usize>(
        &self,
        path: &Path,
        shared: &SharedState<D>,
    ) -> hdf5_metno::Result<()> {
        let rows = &shared.rows;
        let mut f = SharedFile::create(shared.session, path, rows);
        f.column(CONNECTIVITY.name, (1, Layout::Flat), &connectivity(shared));
        for (field, values) in FIELDS.iter().zip(self.point_values(shared)) {
            f.column(field.name, field.shape(), &values);
        }
        f.close(shared.session)
    }

    /// Process 0, after every process has written the point datasets: the attributes of the snapshot
    /// file `path` (what it is, the units, the run, its configuration, time, step and checksum; units and
    /// meaning of every dataset).
    fn describe_h5<const D: usize>(&self, path: &Path, state: &State<D>) -> hdf5_metno::Result<()> {
        let f = hdf5_metno::File::open_rw(path)?;
        let text = |s: &str| {
            s.parse::<VarLenUnicode>()
                .map_err(|e| hdf5_metno::Error::from(e.to_string().as_str()))
        };
        let put_text = |loc: &hdf5_metno::Location, name: &str, value: &str| {
            loc.new_attr::<VarLenUnicode>()
                .create(name)?
                .write_scalar(&text(value)?)
        };
        put_text(
            &f,
            "description",
            "mpm-concrete point fields of the material points at one output step; fields.xdmf indexes \
             the snapshots for ParaView",
        )?;
        put_text(&f, "units", UNITS)?;
        put_text(&f, "run_name", &self.title)?;
        put_text(&f, "config", &self.config_text)?;
        f.new_attr::<f64>()
            .create("time_s")?
            .write_scalar(&state.counters.time)?;
        f.new_attr::<u64>()
            .create("step")?
            .write_scalar(&(state.counters.step as u64))?;
        if let Some(id) = &self.run_id {
            put_text(&f, RUN_ID_ATTR, id)?;
        }
        let checksum = self
            .snapshots
            .iter()
            .find(|s| s.step == state.counters.step)
            .and_then(|s| s.checksum.clone())
            .ok_or_else(|| {
                hdf5_metno::Error::from("the snapshot was not noted before it was written")
            })?;
        put_text(&f, CHECKSUM_ATTR, &checksum)?;
        for field in std::iter::once(&CONNECTIVITY).chain(&FIELDS) {
            let ds = f.dataset(field.name)?;
            put_text(&ds, "units", field.units)?;
            put_text(&ds, "description", field.description)?;
        }
        f.flush()
    }

    /// [`fields_checksum`] of the snapshot of the state (for the file `path`), put together from every
    /// process's points ([`SharedCrc`]). Collective.
    fn checksum<const D: usize>(
        &self,
        shared: &SharedState<D>,
        path: &Path,
    ) -> Result<String, OutputError> {
        let mut crc = SharedCrc::new();
        crc.column(&shared.rows, 1, &connectivity(shared), i64::to_le_bytes);
        for (field, values) in FIELDS.iter().zip(self.point_values(shared)) {
            crc.column(&shared.rows, field.shape().0, &values, f64::to_le_bytes);
        }
        let crc = crc.finish(shared.session).map_err(exchange_err(path))?;
        Ok(format!("{crc:08x}"))
    }

    /// The values of [`FIELDS`] of this process's points in the current state, in that order: vectors as
    /// x, y, z per point (z = 0 in 2D); none on a process that writes no points.
    fn point_values<const D: usize>(&self, shared: &SharedState<D>) -> [Vec<f64>; FIELDS.len()] {
        if shared.rows.order().is_empty() {
            return std::array::from_fn(|_| Vec::new());
        }
        let p = &shared.state.particles;
        let comp = |i: usize, j: usize| p.stress.iter().map(|s| s[(i, j)]).collect::<Vec<f64>>();
        let displacement = p.x.iter().zip(&p.id).flat_map(|(x, &id)| {
            let (x, x0) = (xyz(x), self.initial_position[id as usize]);
            [x[0] - x0[0], x[1] - x0[1], x[2] - x0[2]]
        });
        [
            p.x.iter().flat_map(xyz).collect(),
            displacement.collect(),
            p.v.iter().flat_map(xyz).collect(),
            comp(0, 0),
            comp(1, 1),
            comp(0, 1),
            comp(2, 2),
            comp(0, 2),
            comp(1, 2),
            p.damage.clone(),
            p.eta_bar.clone(),
            (0..p.len())
                .map(|i| p.history(i).iter().copied().fold(0.0, f64::max))
                .collect(),
            p.dissipated
                .iter()
                .zip(&p.vol0)
                .map(|(d, v)| d[0] / v)
                .collect(),
            p.dissipated
                .iter()
                .zip(&p.vol0)
                .map(|(d, v)| d[1] / v)
                .collect(),
            p.nonlocal_damage.clone(),
        ]
    }

    fn write_xdmf(&self, n: usize) -> Result<(), OutputError> {
        write_atomic(
            &self.dir.join(file::FIELDS_INDEX),
            xdmf(&self.snapshots, n).as_bytes(),
        )
    }

    /// Damage map of the points `section` (gathered, in the specimen's frame) of the current state (in
    /// 3D the layer at `section.layer`).
    fn damage_map<const D: usize>(
        &self,
        state: &State<D>,
        section: &SectionPoints,
        path: &Path,
    ) -> Result<(), OutputError> {
        let plane = match section.layer {
            Some(z) => format!(", layer z = {z:.1} mm"),
            None => String::new(),
        };
        let plot = ScatterField {
            title: format!(
                "{}: damage at t = {:.1} us{plane}",
                self.title,
                state.counters.time * 1e6
            ),
            x: section.x.iter().map(|x| x.x).collect(),
            y: section.x.iter().map(|x| x.y).collect(),
            value: section.damage.clone(),
            value_label: "damage [-]".into(),
            range: Some((0.0, 1.0)),
            point_size: self.cell_size / 2.0,
        };
        plot.save_png(path).map_err(|e| OutputError::Plot {
            path: path.display().to_string(),
            message: e.to_string(),
        })
    }

    fn force_label(&self) -> String {
        match self.dimension {
            3 => "reaction F_y [N]".into(),
            _ => "reaction F_y [N/mm]".into(),
        }
    }

    /// Reaction force against time and against the prescribed displacement, one curve per constraint set
    /// that moves (y components; N per mm thickness in 2D, N of the whole plate in 3D).
    pub fn force_plots(&self) -> Result<(), OutputError> {
        let Some(first) = self.rows.first().filter(|_| self.writes) else {
            return Ok(());
        };
        let mut vs_t = Vec::new();
        let mut vs_u = Vec::new();
        for (k, (name, _)) in first.reactions.iter().enumerate() {
            let pts_t: Vec<(f64, f64)> = self
                .rows
                .iter()
                .map(|r| (r.time * 1e6, r.reactions[k].1[1]))
                .collect();
            let pts_u: Vec<(f64, f64)> = self
                .rows
                .iter()
                .map(|r| (r.displacements[k].1[1].abs(), r.reactions[k].1[1]))
                .collect();
            vs_t.push(Series {
                name: name.clone(),
                points: pts_t,
            });
            if self.rows.iter().any(|r| r.displacements[k].1[1] != 0.0) {
                vs_u.push(Series {
                    name: name.clone(),
                    points: pts_u,
                });
            }
        }
        let save = |plot: LinePlot, file: &str| save_line_plot(&plot, &self.dir.join(file));
        // A run without constraints, devices or loads (a free body) has no force to plot.
        if vs_t.is_empty() {
            return Ok(());
        }
        save(
            LinePlot {
                title: format!("{}: reaction force", self.title),
                x_label: "time [us]".into(),
                y_label: self.force_label(),
                series: vs_t,
            },
            file::FORCE_TIME,
        )?;
        if !vs_u.is_empty() {
            save(
                LinePlot {
                    title: format!("{}: reaction force vs load-point displacement", self.title),
                    x_label: "|u_y| of the constraint [mm]".into(),
                    y_label: self.force_label(),
                    series: vs_u,
                },
                file::FORCE_DISPLACEMENT,
            )?;
        }
        Ok(())
    }
}

/// Appends the row of step `r` to `s`: the [`history::LEADING`] cells, the displacements and forces of
/// every set and the rotations of the pinned devices (`{:.9e}`), then the cells of the columns `after`.
fn history_row(s: &mut String, r: &StepReport, after: &[&history::Column]) {
    for (k, c) in history::LEADING.iter().enumerate() {
        if k > 0 {
            s.push(',');
        }
        (c.value)(r).write(s);
    }
    for ((_, f), (_, u)) in r.reactions.iter().zip(&r.displacements) {
        for v in u.iter().chain(f) {
            let _ = write!(s, ",{v:.9e}");
        }
    }
    for (_, theta) in &r.rotations {
        let _ = write!(s, ",{theta:.9e}");
    }
    for c in after {
        s.push(',');
        (c.value)(r).write(s);
    }
    s.push('\n');
}

#[cfg(test)]
mod tests;
