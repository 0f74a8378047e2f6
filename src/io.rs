//! Results of a run, written as it goes and never left half-written (every file is written to a
//! temporary name and renamed into place):
//!
//! * `history.csv`: per step time, solver statistics, reactions and prescribed displacements of every
//!   constraint set, energies (header states the units);
//! * `fields_NNNNNN.h5` + `fields.xdmf`: point fields at output steps (position, displacement, velocity,
//!   Cauchy stress, damage, eta_bar, history maximum); open `fields.xdmf` in ParaView;
//! * `damage_NNNNNN.png`: damage maps; `force_time.png`, `force_displacement.png`: reaction curves;
//! * `crack.json`: crack metrics at every output step (see [`crate::crack`]) when a notch tip is known.

use crate::crack::{self, CrackCriteria, CrackState};
use crate::plot::{LinePlot, ScatterField, Series};
use crate::solver::{Simulation, StepReport};
use nalgebra::Vector2;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Output failure, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// File system error.
    #[error("{path}: {source}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// HDF5 error.
    #[error("{path}: HDF5: {message}")]
    Hdf5 {
        /// File.
        path: String,
        /// Cause.
        message: String,
    },
    /// Plotting error.
    #[error("{path}: {message}")]
    Plot {
        /// File.
        path: String,
        /// Cause.
        message: String,
    },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> OutputError + '_ {
    move |source| OutputError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// Writes `bytes` to `path` atomically (temporary file in the same directory, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    let tmp = tmp_name(path);
    std::fs::write(&tmp, bytes).map_err(io_err(&tmp))?;
    std::fs::rename(&tmp, path).map_err(io_err(path))
}

fn tmp_name(path: &Path) -> PathBuf {
    let mut name = path
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(".tmp");
    path.with_file_name(name)
}

/// One written snapshot (for the XDMF index).
#[derive(serde::Serialize, serde::Deserialize)]
struct Snapshot {
    step: usize,
    time: f64,
    file: String,
}

/// The output directory of a run.
pub struct RunOutput {
    dir: PathBuf,
    title: String,
    rows: Vec<StepReport>,
    snapshots: Vec<Snapshot>,
    initial_position: Vec<Vector2<f64>>,
    /// Notch tip (mm) and criteria of the crack metrics, if tracked.
    crack: Option<(Vector2<f64>, CrackCriteria)>,
    cracks: Vec<CrackState>,
}

impl RunOutput {
    /// Creates (or reuses) `dir`, keeps a copy of the configuration text as `config.toml`.
    pub fn create(
        dir: &Path,
        title: &str,
        config_text: &str,
        sim: &Simulation,
    ) -> Result<Self, OutputError> {
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        write_atomic(&dir.join("config.toml"), config_text.as_bytes())?;
        Ok(Self {
            dir: dir.to_owned(),
            title: title.to_owned(),
            rows: Vec::new(),
            snapshots: Vec::new(),
            initial_position: sim.setup.particles.x.clone(),
            crack: None,
            cracks: Vec::new(),
        })
    }

    /// Measures the crack grown from `notch_tip` (mm) at every snapshot and writes `crack.json`.
    pub fn track_crack(&mut self, notch_tip: Vector2<f64>, criteria: CrackCriteria) {
        self.crack = Some((notch_tip, criteria));
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
        let speeds: Vec<f64> = self
            .cracks
            .windows(2)
            .map(|w| {
                if w[1].time > w[0].time {
                    (w[1].length - w[0].length) / (w[1].time - w[0].time)
                } else {
                    0.0
                }
            })
            .collect();
        let json = serde_json::json!({
            "units": "length mm, time s, speed mm/s, angles degrees against the notch axis (+x), counter-clockwise positive",
            "notch_tip": [tip.x, tip.y],
            "criteria": criteria,
            "states": self.cracks,
            "tip_speed_between_states": speeds,
            "final_classification": self.cracks.last().map(|c| c.classification.clone()),
        });
        let path = self.dir.join("crack.json");
        let text = serde_json::to_string_pretty(&json).map_err(|e| OutputError::Plot {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        write_atomic(&path, text.as_bytes())
    }

    /// Output directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Records a step and rewrites `history.csv`.
    pub fn record(&mut self, report: StepReport) -> Result<(), OutputError> {
        self.rows.push(report);
        self.write_history()
    }

    /// The recorded steps.
    pub fn rows(&self) -> &[StepReport] {
        &self.rows
    }

    fn write_history(&self) -> Result<(), OutputError> {
        let mut s = String::new();
        s.push_str("# units: time s, dt s, displacement mm, force N per mm thickness, energy N mm per mm thickness, wall s\n");
        s.push_str("step,time,dt,attempts,newton_its,linear_its,reason,residual_initial,residual_final,unknowns");
        if let Some(r) = self.rows.first() {
            for (name, _) in &r.reactions {
                let _ = write!(s, ",{name}_ux,{name}_uy,{name}_fx,{name}_fy");
            }
        }
        s.push_str(",kinetic_energy,stored_energy,external_work,dissipated_energy,wall_setup,wall_assembly,wall_solve,wall_total,new_pattern\n");
        for r in &self.rows {
            let norms = &r.solve.residual_norms;
            let _ = write!(
                s,
                "{},{:.9e},{:.6e},{},{},{},{},{:.6e},{:.6e},{}",
                r.step,
                r.time,
                r.dt,
                r.attempts,
                r.solve.iterations,
                r.solve.linear_iterations,
                r.solve.reason_name,
                norms.first().copied().unwrap_or(f64::NAN),
                norms.last().copied().unwrap_or(f64::NAN),
                r.unknowns
            );
            for ((_, f), (_, u)) in r.reactions.iter().zip(&r.displacements) {
                let _ = write!(s, ",{:.9e},{:.9e},{:.9e},{:.9e}", u[0], u[1], f[0], f[1]);
            }
            let dissipated = r.external_work - r.kinetic_energy - r.stored_energy;
            let _ = writeln!(
                s,
                ",{:.9e},{:.9e},{:.9e},{:.9e},{:.4e},{:.4e},{:.4e},{:.4e},{}",
                r.kinetic_energy,
                r.stored_energy,
                r.external_work,
                dissipated,
                r.wall_setup,
                r.wall_assembly,
                r.wall_solve,
                r.wall_total,
                u8::from(r.new_pattern)
            );
        }
        write_atomic(&self.dir.join("history.csv"), s.as_bytes())
    }

    /// Writes the point fields of the current state (HDF5 + XDMF index) and a damage map (PNG).
    pub fn snapshot(&mut self, sim: &Simulation) -> Result<(), OutputError> {
        let file = format!("fields_{:06}.h5", sim.step);
        let path = self.dir.join(&file);
        let tmp = tmp_name(&path);
        self.write_h5(&tmp, sim).map_err(|e| OutputError::Hdf5 {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        std::fs::rename(&tmp, &path).map_err(io_err(&path))?;
        self.snapshots.retain(|s| s.step != sim.step);
        self.snapshots.push(Snapshot {
            step: sim.step,
            time: sim.time,
            file,
        });
        self.write_xdmf(sim.setup.particles.len())?;
        if let Some((tip, criteria)) = &self.crack {
            let p = &sim.setup.particles;
            let state = crack::measure(
                &p.x,
                &p.damage,
                *tip,
                sim.setup.grid.cell_size(),
                criteria,
                sim.time,
            );
            self.cracks.retain(|c| c.time != state.time);
            self.cracks.push(state);
            self.write_cracks()?;
        }
        self.damage_map(sim, &self.dir.join(format!("damage_{:06}.png", sim.step)))
    }

    fn write_h5(&self, path: &Path, sim: &Simulation) -> hdf5_metno::Result<()> {
        let p = &sim.setup.particles;
        let n = p.len();
        let f = hdf5_metno::File::create(path)?;
        let vec2 = |v: &mut dyn Iterator<Item = Vector2<f64>>| -> ndarray::Array2<f64> {
            let flat: Vec<f64> = v.flat_map(|x| [x.x, x.y]).collect();
            ndarray::Array2::from_shape_vec((n, 2), flat).expect("n x 2")
        };
        f.new_dataset_builder()
            .with_data(&vec2(&mut p.x.iter().copied()))
            .create("position")?;
        let disp = vec2(&mut p.x.iter().zip(&self.initial_position).map(|(x, x0)| x - x0));
        f.new_dataset_builder()
            .with_data(&disp)
            .create("displacement")?;
        f.new_dataset_builder()
            .with_data(&vec2(&mut p.v.iter().copied()))
            .create("velocity")?;
        let comp = |i: usize, j: usize| p.stress.iter().map(|s| s[(i, j)]).collect::<Vec<f64>>();
        f.new_dataset_builder()
            .with_data(&comp(0, 0))
            .create("sigma_xx")?;
        f.new_dataset_builder()
            .with_data(&comp(1, 1))
            .create("sigma_yy")?;
        f.new_dataset_builder()
            .with_data(&comp(0, 1))
            .create("sigma_xy")?;
        f.new_dataset_builder()
            .with_data(&comp(2, 2))
            .create("sigma_zz")?;
        f.new_dataset_builder()
            .with_data(&p.damage)
            .create("damage")?;
        f.new_dataset_builder()
            .with_data(&p.eta_bar)
            .create("eta_bar")?;
        let hmax: Vec<f64> = (0..n)
            .map(|i| p.history(i).iter().copied().fold(0.0, f64::max))
            .collect();
        f.new_dataset_builder()
            .with_data(&hmax)
            .create("history_max")?;
        f.new_attr::<f64>()
            .create("time_s")?
            .write_scalar(&sim.time)?;
        f.new_attr::<u64>()
            .create("step")?
            .write_scalar(&(sim.step as u64))?;
        Ok(())
    }

    fn write_xdmf(&self, n: usize) -> Result<(), OutputError> {
        let mut s = String::from(
            "<?xml version=\"1.0\" ?>\n<!-- units: mm, s, N, MPa -->\n<Xdmf Version=\"3.0\">\n <Domain>\n  <Grid Name=\"material_points\" GridType=\"Collection\" CollectionType=\"Temporal\">\n",
        );
        let item = |file: &str, name: &str, dims: &str| {
            format!(
                "<DataItem Dimensions=\"{dims}\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">{file}:/{name}</DataItem>"
            )
        };
        for snap in &self.snapshots {
            let f = &snap.file;
            let _ = writeln!(
                s,
                "   <Grid Name=\"step_{:06}\" GridType=\"Uniform\">",
                snap.step
            );
            let _ = writeln!(s, "    <Time Value=\"{:.9e}\"/>", snap.time);
            let _ = writeln!(
                s,
                "    <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"{n}\" NodesPerElement=\"1\"/>"
            );
            let _ = writeln!(
                s,
                "    <Geometry GeometryType=\"XY\">{}</Geometry>",
                item(f, "position", &format!("{n} 2"))
            );
            for v in ["displacement", "velocity"] {
                let _ = writeln!(
                    s,
                    "    <Attribute Name=\"{v}\" AttributeType=\"Vector\" Center=\"Node\">{}</Attribute>",
                    item(f, v, &format!("{n} 2"))
                );
            }
            for a in [
                "sigma_xx",
                "sigma_yy",
                "sigma_xy",
                "sigma_zz",
                "damage",
                "eta_bar",
                "history_max",
            ] {
                let _ = writeln!(
                    s,
                    "    <Attribute Name=\"{a}\" AttributeType=\"Scalar\" Center=\"Node\">{}</Attribute>",
                    item(f, a, &n.to_string())
                );
            }
            s.push_str("   </Grid>\n");
        }
        s.push_str("  </Grid>\n </Domain>\n</Xdmf>\n");
        write_atomic(&self.dir.join("fields.xdmf"), s.as_bytes())
    }

    /// Damage map of the current state.
    pub fn damage_map(&self, sim: &Simulation, path: &Path) -> Result<(), OutputError> {
        let p = &sim.setup.particles;
        let h = sim.setup.grid.cell_size();
        let plot = ScatterField {
            title: format!("{}: damage at t = {:.1} us", self.title, sim.time * 1e6),
            x: p.x.iter().map(|x| x.x).collect(),
            y: p.x.iter().map(|x| x.y).collect(),
            value: p.damage.clone(),
            value_label: "damage [-]".into(),
            range: Some((0.0, 1.0)),
            point_size: h / 2.0,
        };
        plot.save_png(path).map_err(|e| OutputError::Plot {
            path: path.display().to_string(),
            message: e.to_string(),
        })
    }

    /// Reaction force against time and against the prescribed displacement, one curve per constraint set
    /// that moves (y components; N per mm thickness).
    pub fn force_plots(&self) -> Result<(), OutputError> {
        let Some(first) = self.rows.first() else {
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
        let save = |plot: LinePlot, file: &str| {
            let path = self.dir.join(file);
            plot.save_png(&path).map_err(|e| OutputError::Plot {
                path: path.display().to_string(),
                message: e.to_string(),
            })
        };
        save(
            LinePlot {
                title: format!("{}: reaction force", self.title),
                x_label: "time [us]".into(),
                y_label: "reaction F_y [N/mm]".into(),
                series: vs_t,
            },
            "force_time.png",
        )?;
        if !vs_u.is_empty() {
            save(
                LinePlot {
                    title: format!("{}: reaction force vs load-point displacement", self.title),
                    x_label: "|u_y| of the constraint [mm]".into(),
                    y_label: "reaction F_y [N/mm]".into(),
                    series: vs_u,
                },
                "force_displacement.png",
            )?;
        }
        Ok(())
    }
}
