//! The crack's records of a run: crack.json, the crack plots, the section layer of a plate whose points
//! the crack is measured on, and the re-measurement of a finished run from its snapshots.

use super::provenance::{Provenance, unreadable};
use crate::crack::{self, CrackCriteria, CrackState, Front};
use crate::output_file::{OutputError, io_err, write_atomic};
use crate::plot::LinePlot;
use crate::schema::file;
use crate::solver::StepReport;
use crate::space::Frame;
use nalgebra::Vector2;
use std::path::Path;

/// The crack-tip speed (mm/s) of a step reaching `length` (mm) at `time` (s) after the recorded steps
/// `rows` ([`crack::tip_speed`] over the steps within its window).
pub(super) fn speed_after(rows: &[StepReport], time: f64, length: f64) -> f64 {
    let earlier = rows
        .iter()
        .rev()
        .take_while(|r| r.crack.is_some())
        .enumerate()
        .take_while(|(k, r)| {
            *k + 1 < crack::SPEED_MIN_SAMPLES || time - r.time <= crack::SPEED_WINDOW * (1.0 + 1e-9)
        })
        .count();
    let mut samples: Vec<(f64, f64)> = rows[rows.len() - earlier..]
        .iter()
        .filter_map(|r| r.crack.map(|c| (r.time, c.length)))
        .collect();
    samples.push((time, length));
    crack::tip_speed(&samples)
}

/// The tip speed's summary in `crack.json` from the fronts of the recorded steps `rows`: the peak speed,
/// the speed at the first step with two or more bands, both also as fractions of the Rayleigh speed
/// `rayleigh` (mm/s) of the specimen's material.
pub(super) fn speed_summary(rows: &[StepReport], rayleigh: Option<f64>) -> serde_json::Value {
    let fronts: Vec<(f64, Front)> = rows
        .iter()
        .filter_map(|r| r.crack.map(|c| (r.time, c)))
        .collect();
    let peak = fronts.iter().max_by(|a, b| a.1.speed.total_cmp(&b.1.speed));
    let branch = fronts.iter().find(|(_, f)| f.bands >= 2);
    let fraction = |v: f64| rayleigh.map(|c| v / c);
    serde_json::json!({
        "definition": format!(
            "tip: the crack point farthest from the notch tip, every step; speed: least-squares slope \
             of the crack length over the steps of the last {} us (at least {} steps); Rayleigh speed: \
             Viktorov's c_R = c_S (0.862 + 1.14 nu)/(1 + nu) of the concrete's K, G and density",
            crack::SPEED_WINDOW * 1e6,
            crack::SPEED_MIN_SAMPLES
        ),
        "rayleigh_speed": rayleigh,
        "peak_speed": peak.map(|p| p.1.speed),
        "peak_time": peak.map(|p| p.0),
        "peak_fraction_of_rayleigh": peak.and_then(|p| fraction(p.1.speed)),
        "branch_time": branch.map(|b| b.0),
        "branch_speed": branch.map(|b| b.1.speed),
        "branch_fraction_of_rayleigh": branch.and_then(|b| fraction(b.1.speed)),
    })
}

/// `crack_speed.png`: the tip speed (m/s) and the crack length at every step of `rows` with a front.
fn speed_plot(dir: &Path, rows: &[StepReport]) -> Result<(), OutputError> {
    let points = |value: fn(&Front) -> f64| -> Vec<(f64, f64)> {
        rows.iter()
            .filter_map(|r| r.crack.map(|c| (r.time * 1e6, value(&c))))
            .collect()
    };
    let speed = points(|f| f.speed * 1e-3);
    if speed.is_empty() {
        return Ok(());
    }
    save_line_plot(
        &LinePlot::new(
            "crack tip speed (slope of the length over 10 us) and crack length",
            "time [us]",
            "speed [m/s]; length [mm]",
        )
        .with_series("tip speed [m/s]", speed)
        .with_series("crack length [mm]", points(|f| f.length)),
        &dir.join(file::CRACK_SPEED),
    )
}

/// Writes `crack.json` of the crack states `cracks` into `dir` (write, then rename), with the tip-speed
/// summary `every_step` ([`speed_summary`]) and `crack_speed.png` of the steps `rows` (none: not drawn).
pub(super) fn write_crack_json(
    dir: &Path,
    plate: bool,
    tip: Vector2<f64>,
    criteria: &CrackCriteria,
    cracks: &[CrackState],
    (rows, every_step): (&[StepReport], serde_json::Value),
) -> Result<(), OutputError> {
    let speeds: Vec<f64> = cracks
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
        "units": format!("length mm, time s, speed mm/s, angles degrees against the notch axis (+x), \
                  counter-clockwise positive, energies {}", if plate {
                      "N mm (of the whole plate; the other metrics of its section layer)"
                  } else {
                      "N mm per mm of thickness"
                  }),
        "notch_tip": [tip.x, tip.y],
        "criteria": criteria,
        "states": cracks,
        "tip_speed_between_states": speeds,
        "tip_speed_every_step": every_step,
        "final_classification": cracks.last().map(|c| c.classification.clone()),
    });
    let path = dir.join(file::CRACK);
    let text = serde_json::to_string_pretty(&json).map_err(|e| OutputError::Plot {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    write_atomic(&path, text.as_bytes())?;
    crack_plots(dir, cracks)?;
    speed_plot(dir, rows)
}

/// Draws `plot` into the PNG `path`, naming the file in an error.
pub(super) fn save_line_plot(plot: &LinePlot, path: &Path) -> Result<(), OutputError> {
    plot.save_png(path).map_err(|e| OutputError::Plot {
        path: path.display().to_string(),
        message: e.to_string(),
    })
}

/// `crack_length.png` and `band_width.png`: the crack length and the width of the `d >= 0.9` zone across
/// the bands (median and largest crossing) and of the regularised zone `d >= 0.5` (median) at the output
/// steps.
fn crack_plots(dir: &Path, cracks: &[CrackState]) -> Result<(), OutputError> {
    let points = |value: fn(&CrackState) -> f64| -> Vec<(f64, f64)> {
        cracks.iter().map(|c| (c.time * 1e6, value(c))).collect()
    };
    let save = |plot: LinePlot, file: &str| save_line_plot(&plot, &dir.join(file));
    save(
        LinePlot::new(
            "crack length",
            "time [us]",
            "length of the d >= 0.9 zone [mm]",
        )
        .with_series("", points(|c| c.length)),
        file::CRACK_LENGTH,
    )?;
    save(
        LinePlot::new(
            "width of the damage bands across the band",
            "time [us]",
            "width [mm]",
        )
        .with_series("d >= 0.9, median of the stations", points(|c| c.band_width))
        .with_series("d >= 0.9, largest crossing", points(|c| c.band_width_max))
        .with_series("d >= 0.5, median of the stations", points(|c| c.zone_width)),
        file::BAND_WIDTH,
    )
}

/// Re-measures the crack metrics of a finished CT run in `dir` from its snapshots `fields_*.h5` with the
/// criteria of this version (`config.toml` of the run gives the notch and the grid) and rewrites
/// `crack.json`. The specimen's dissipation totals need the points' volumes, which the snapshots do not
/// hold: they are kept from the old `crack.json` (matched by time) when it has them.
pub fn remeasure_cracks(dir: &Path) -> Result<Vec<CrackState>, OutputError> {
    let run_err = |path: &Path, message: String| OutputError::Run {
        path: path.display().to_string(),
        message,
    };
    let config_path = dir.join(file::CONFIG);
    let text = crate::input::read_text_input(&config_path).map_err(refused_input)?;
    let cfg = crate::config::RunConfig::from_str_named(&text, &config_path.display().to_string())
        .map_err(|e| run_err(&config_path, e.to_string()))?;
    let Some(ct) = &cfg.ct else {
        return Err(run_err(
            &config_path,
            "not a CT run (no [ct] section): crack metrics need the notch".into(),
        ));
    };
    let h = cfg.grid.cell_size;
    let how = Measure {
        tip: Vector2::new(ct.notch_length, 0.5 * ct.height),
        h,
        spacing: h / cfg.shape.points_per_cell as f64,
        criteria: CrackCriteria::for_notch(ct.notch_width, h),
        section_z: cfg.extrusion.as_ref().map(|e| e.section_z),
        frame: cfg.grid.frame(),
    };
    // The old crack.json may be absent or hold no states; one that is no regular file is refused.
    let old_json = match crate::input::read_text_input(&dir.join(file::CRACK)) {
        Ok(t) => serde_json::from_str::<serde_json::Value>(&t).ok(),
        Err(e) if e.is_missing() => None,
        Err(e) => return Err(refused_input(e)),
    };
    let old: Vec<CrackState> = old_json
        .as_ref()
        .and_then(|v| serde_json::from_value(v["states"].clone()).ok())
        .unwrap_or_default();
    // The tip speeds of the steps are not in the snapshots: kept from the old crack.json.
    let speeds = old_json.map_or(serde_json::Value::Null, |v| {
        v["tip_speed_every_step"].clone()
    });
    let provenance = Provenance::of(dir)?;
    let mut states = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io_err(dir))? {
        let path = entry.map_err(io_err(dir))?.path();
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
        if !name.is_some_and(|n| n.starts_with(file::FIELDS.0) && n.ends_with(file::FIELDS.1)) {
            continue;
        }
        let mut state = measure_snapshot(&path, &how, &provenance)?;
        let time = state.time;
        if let Some(o) = old
            .iter()
            .find(|o| (o.time - time).abs() <= 1e-12 * time.abs().max(1.0))
        {
            state.dissipated = o.dissipated;
        }
        states.push(state);
    }
    if states.is_empty() {
        return Err(run_err(dir, "no snapshots fields_*.h5".into()));
    }
    states.sort_by(|a, b| a.time.total_cmp(&b.time));
    write_crack_json(
        dir,
        cfg.extrusion.is_some(),
        how.tip,
        &how.criteria,
        &states,
        (&[], speeds),
    )?;
    Ok(states)
}

/// How the crack is measured on a run's snapshots: the notch tip (mm), the cell size h and the point
/// spacing (mm), the criteria, for a plate the z of the section (`Some(None)`: the mid-plane), and the
/// specimen's frame on the grid.
struct Measure {
    tip: Vector2<f64>,
    h: f64,
    spacing: f64,
    criteria: CrackCriteria,
    section_z: Option<Option<f64>>,
    /// The specimen's frame on the grid (`grid.rotation`): the crack is measured in the specimen's.
    frame: Frame,
}

/// An input file of the run directory refused by [`crate::input::check_input_file`].
fn refused_input(e: crate::input::InputError) -> OutputError {
    OutputError::Run {
        message: e.reason(),
        path: e.path,
    }
}

/// The values of the dataset `name` of the snapshot `file` (at `path`), verified as a checkpoint's are:
/// finite, within `range` if given, and `per_point` values for each of `points` points (if given).
fn verified(
    file: &hdf5_metno::File,
    path: &Path,
    name: &str,
    range: Option<(f64, f64)>,
    shape: (usize, Option<usize>),
) -> Result<Vec<f64>, OutputError> {
    let values: Vec<f64> = file
        .dataset(name)
        .and_then(|d| d.read_raw())
        .map_err(|e| unreadable(path, &e))?;
    let corrupt = |what: String| OutputError::Run {
        path: path.display().to_string(),
        message: format!(
            "dataset `{name}` {what}: the snapshot is corrupt, nothing was re-measured and crack.json \
             is unchanged"
        ),
    };
    let (per_point, points) = shape;
    if points.is_some_and(|n| values.len() != per_point * n) || values.len() % per_point != 0 {
        return Err(corrupt(format!(
            "has {} values, not {per_point} per point",
            values.len()
        )));
    }
    let outside = |v: f64| !v.is_finite() || range.is_some_and(|(lo, hi)| v < lo || v > hi);
    if let Some(k) = values.iter().position(|&v| outside(v)) {
        let allowed = match range {
            Some((lo, hi)) => format!("values in [{lo}, {hi}]"),
            None => "finite values".into(),
        };
        return Err(corrupt(format!(
            "holds {} at point {} (allowed: {allowed})",
            values[k],
            k / per_point
        )));
    }
    Ok(values)
}

/// The crack state of the snapshot `path` (its time, damage and positions; for a plate on the section
/// layer), measured as `how` says; the snapshot's identity is checked first, the values it reads are
/// verified ([`verified`]) and then its checksum ([`Provenance`]).
fn measure_snapshot(
    path: &Path,
    how: &Measure,
    provenance: &Provenance,
) -> Result<CrackState, OutputError> {
    let h5 = |e: hdf5_metno::Error| unreadable(path, &e);
    crate::input::check_input_file(path, crate::input::DATA_INPUT_MAX).map_err(refused_input)?;
    let file = hdf5_metno::File::open(path).map_err(h5)?;
    provenance.check_identity(&file, path)?;
    let time: f64 = file
        .attr("time_s")
        .and_then(|a| a.read_scalar())
        .map_err(h5)?;
    if !time.is_finite() || time < 0.0 {
        return Err(OutputError::Run {
            path: path.display().to_string(),
            message: format!(
                "attribute `time_s` = {time}: the snapshot is corrupt (a time >= 0 s)"
            ),
        });
    }
    let damage = verified(&file, path, "damage", Some((0.0, 1.0)), (1, None))?;
    let points = Some(damage.len());
    let position = verified(&file, path, "position", None, (3, points))?;
    let width = 3;
    // A plate (3D run): the layer of the section, found by the points' initial z.
    let section: Vec<usize> = match how.section_z {
        Some(section_z) => {
            let displacement = verified(&file, path, "displacement", None, (3, points))?;
            let z0: Vec<f64> = position
                .chunks_exact(width)
                .zip(displacement.chunks_exact(width))
                .map(|(x, u)| x[2] - u[2])
                .collect();
            section_layer(&z0, section_z.unwrap_or_else(|| mid_z(&z0))).1
        }
        None => (0..damage.len()).collect(),
    };
    let x: Vec<Vector2<f64>> = section
        .iter()
        .map(|&k| {
            how.frame
                .to_specimen(Vector2::new(position[width * k], position[width * k + 1]))
        })
        .collect();
    let layer_damage: Vec<f64> = section.iter().map(|&k| damage[k]).collect();
    let mut state = crack::measure(
        &x,
        &layer_damage,
        how.tip,
        how.h,
        how.spacing,
        &how.criteria,
        time,
    );
    if file.dataset("nonlocal_damage").is_ok() {
        let nonlocal = verified(&file, path, "nonlocal_damage", None, (1, points))?;
        state.nonlocal_points = section
            .iter()
            .filter(|&&k| {
                damage[k] >= how.criteria.damage_threshold && nonlocal[k] >= 0.5 * damage[k]
            })
            .count();
    }
    provenance.check_checksum(&file, path)?;
    Ok(state)
}

/// The middle of the z range of `z0` (mm): the default section of a plate.
pub(super) fn mid_z(z0: &[f64]) -> f64 {
    let (lo, hi) = z0
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &z| {
            (a.min(z), b.max(z))
        });
    0.5 * (lo + hi)
}

/// The layer of points seeded nearest the plane `z` (mm), from the points' initial z `z0`: its z and the
/// points within a quarter of the layer spacing of it (the layers of a seeded plate are a point spacing
/// apart).
pub(super) fn section_layer(z0: &[f64], z: f64) -> (f64, Vec<usize>) {
    // Of two layers equally near (the mid-plane of an even number of layers), the lower one: "equally"
    // within 1e-9 mm, so that round-off in the seeded z does not decide.
    let nearest = z0
        .iter()
        .map(|w| (w - z).abs())
        .fold(f64::INFINITY, f64::min);
    let layer = z0
        .iter()
        .copied()
        .filter(|w| (w - z).abs() <= nearest + 1e-9)
        .fold(f64::INFINITY, f64::min);
    let layer = if layer.is_finite() { layer } else { z };
    let spacing = z0
        .iter()
        .map(|&w| (w - layer).abs())
        .filter(|&d| d > 1e-9 * layer.abs().max(1.0))
        .fold(f64::INFINITY, f64::min);
    let tol = if spacing.is_finite() {
        0.25 * spacing
    } else {
        1e-9
    };
    let points = (0..z0.len())
        .filter(|&k| (z0[k] - layer).abs() < tol)
        .collect();
    (layer, points)
}
