//! Post-processing of the benchmark runs of `docs/validation.md`: reads a finished run of a configuration in
//! `configs/benchmarks/` (its `history.csv` and last `fields_*.h5`), converts the load set's reaction to
//! the specimen's load in kN, draws the load-displacement curve with the reference range and the final
//! damage map, measures the crack path, and prints the rows of the comparison tables.
//!
//! ```sh
//! mpm-concrete run configs/benchmarks/l-panel.toml --output runs/l-panel
//! cargo run --release --example validation -- l-panel runs/l-panel --out docs/img
//! mpm-concrete run configs/benchmarks/petersson-3pb.toml --output runs/petersson-3pb
//! cargo run --release --example validation -- petersson-3pb runs/petersson-3pb --out docs/img
//! mpm-concrete run configs/benchmarks/offset-notch-3pb.toml --output runs/offset-notch-3pb
//! cargo run --release --example validation -- offset-notch-3pb runs/offset-notch-3pb --out docs/img
//! ```
//!
//! Writes `<out>/validation-<bench>-force.png`, `<out>/validation-<bench>-damage.png` and
//! `<out>/validation-<bench>.json`. Units: mm, N (kN in the tables and plots), MPa.

use mpm_concrete::plot::{LinePlot, ScatterField};
use serde_json::json;
use std::path::{Path, PathBuf};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Damage from which a point counts as cracked (the crack metrics of the CT use the same threshold).
const CRACKED: f64 = 0.9;

/// A benchmark: how its load set's history becomes the specimen's load and displacement, and its
/// reference peak load.
struct Bench {
    /// Name of the configuration (`configs/benchmarks/<name>.toml`).
    name: &'static str,
    /// The `history.csv` column on the x-axis (mm): the load point's `load_uy` or the path control's
    /// `path_opening` (the crack-mouth opening of the offset-notched beam).
    x_column: &'static str,
    /// Specimen load in kN per N/mm of the plane run's `load_fy` (thickness, symmetry and sign).
    force_scale: f64,
    /// Sign that makes the load point's displacement positive.
    displacement_sign: f64,
    /// Reference range of the peak load (kN) and its legend entry.
    reference_peak: (f64, f64, &'static str),
    /// x-axis label of the load-displacement plot.
    x_label: &'static str,
    /// The crack path's strips (see [`crack_path`]): axis, from, to (mm), and the table's heading.
    path: (usize, f64, f64, &'static str),
    /// Measured reference curves (x in mm, load in kN) drawn with the run, each with its legend entry.
    curves: &'static [(&'static str, &'static [[f64; 2]])],
}

/// The offset-notched beam's experimental load-CMOD band (Garcia-Alvarez, Gettu & Carol 2012, Sadhana
/// 37(1) 187-205), as digitised in `examples/data/mixed_mode_fracture.csv` of the MIT-licensed
/// `mark-hobbs/pypd` (columns `cmod, load_min, load_max`), sampled here: CMOD (mm), the two bounding
/// curves (N). The first curve ends at 0.127 mm; `OFFSET_NOTCH_TAIL` continues the second.
const OFFSET_NOTCH_BAND: [[f64; 3]; 34] = [
    [0.0000, 10.0, 19.0],
    [0.0025, 982.0, 797.0],
    [0.0050, 2257.0, 2040.0],
    [0.0075, 3533.0, 3285.0],
    [0.0100, 4324.0, 4238.0],
    [0.0125, 4525.0, 4654.0],
    [0.0150, 4687.0, 5105.0],
    [0.0175, 4834.0, 5355.0],
    [0.0186, 4894.0, 5361.0],
    [0.0200, 4866.0, 5377.0],
    [0.0211, 4846.0, 5405.0],
    [0.0225, 4819.0, 5212.0],
    [0.0250, 4664.0, 5085.0],
    [0.0275, 4411.0, 4865.0],
    [0.0300, 4230.0, 4731.0],
    [0.0350, 3839.0, 4494.0],
    [0.0400, 3553.0, 4291.0],
    [0.0450, 3343.0, 4019.0],
    [0.0500, 3025.0, 3692.0],
    [0.0550, 2760.0, 3478.0],
    [0.0600, 2552.0, 3269.0],
    [0.0650, 2263.0, 3051.0],
    [0.0700, 2078.0, 2875.0],
    [0.0750, 1927.0, 2719.0],
    [0.0800, 1805.0, 2597.0],
    [0.0850, 1693.0, 2476.0],
    [0.0900, 1544.0, 2386.0],
    [0.0950, 1434.0, 2320.0],
    [0.1000, 1342.0, 2226.0],
    [0.1050, 1275.0, 2134.0],
    [0.1100, 1204.0, 2059.0],
    [0.1150, 1122.0, 1978.0],
    [0.1200, 1076.0, 1892.0],
    [0.1250, 1015.0, 1813.0],
];

/// The second bounding curve of [`OFFSET_NOTCH_BAND`] beyond 0.127 mm: CMOD (mm), load (N).
const OFFSET_NOTCH_TAIL: [[f64; 2]; 13] = [
    [0.1300, 1747.0],
    [0.1400, 1599.0],
    [0.1500, 1526.0],
    [0.1600, 1428.0],
    [0.1700, 1342.0],
    [0.1800, 1276.0],
    [0.1900, 1199.0],
    [0.2000, 1148.0],
    [0.2100, 1069.0],
    [0.2200, 1021.0],
    [0.2300, 936.0],
    [0.2400, 892.0],
    [0.2500, 827.0],
];

/// One bounding curve of the offset-notched beam's band in kN: `k` = 1 or 2 (the band's column), the
/// second continued by the tail.
const fn band_curve<const N: usize>(k: usize) -> [[f64; 2]; N] {
    let mut out = [[0.0; 2]; N];
    let mut i = 0;
    while i < N {
        out[i] = if i < OFFSET_NOTCH_BAND.len() {
            [OFFSET_NOTCH_BAND[i][0], OFFSET_NOTCH_BAND[i][k] / 1000.0]
        } else {
            let t = OFFSET_NOTCH_TAIL[i - OFFSET_NOTCH_BAND.len()];
            [t[0], t[1] / 1000.0]
        };
        i += 1;
    }
    out
}

/// The band's first curve (kN).
const OFFSET_NOTCH_LOWER: [[f64; 2]; 34] = band_curve(1);
/// The band's second curve with its tail (kN).
const OFFSET_NOTCH_UPPER: [[f64; 2]; 47] = band_curve(2);

const BENCHES: [Bench; 3] = [
    Bench {
        name: "l-panel",
        x_column: "load_uy",
        force_scale: 100.0 / 1000.0,
        displacement_sign: 1.0,
        reference_peak: (6.0, 8.0, "experimental peak range (Winkler et al.)"),
        x_label: "upward displacement of the load point [mm]",
        // From the re-entrant corner (250, 250) towards the panel's left face, in vertical strips.
        path: (
            0,
            250.0,
            0.0,
            "| x [mm] | cracked y from [mm] | mean y [mm] | to [mm] |",
        ),
        curves: &[],
    },
    Bench {
        name: "petersson-3pb",
        x_column: "load_uy",
        force_scale: -2.0 * 50.0 / 1000.0,
        displacement_sign: -1.0,
        reference_peak: (0.75, 0.80, "experimental peak range (Petersson)"),
        x_label: "load-point deflection [mm]",
        // From the notch tip (1000, 100) up the beam, in horizontal strips.
        path: (
            1,
            100.0,
            200.0,
            "| y [mm] | cracked x from [mm] | mean x [mm] | to [mm] |",
        ),
        curves: &[],
    },
    Bench {
        name: "offset-notch-3pb",
        x_column: "path_opening",
        force_scale: -50.0 / 1000.0,
        displacement_sign: 1.0,
        reference_peak: (
            4.89,
            5.41,
            "experimental peak range (Garcia-Alvarez et al.)",
        ),
        x_label: "crack-mouth opening (CMOD, 20 mm gauge) [mm]",
        // From the notch tip (75, 20) up towards the load at (125, 80), in horizontal strips.
        path: (
            1,
            20.0,
            80.0,
            "| y [mm] | cracked x from [mm] | mean x [mm] | to [mm] |",
        ),
        curves: &[
            ("experiment, first bounding curve", &OFFSET_NOTCH_LOWER),
            ("experiment, second bounding curve", &OFFSET_NOTCH_UPPER),
        ],
    },
];

/// The columns `names` of a run's `history.csv`, one vector per name.
fn history(dir: &Path, names: &[&str]) -> Result<Vec<Vec<f64>>> {
    let path = dir.join("history.csv");
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut lines = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty());
    let header: Vec<&str> = lines
        .next()
        .ok_or("empty history.csv")?
        .split(',')
        .collect();
    let index: Vec<usize> = names
        .iter()
        .map(|n| {
            header
                .iter()
                .position(|h| h == n)
                .ok_or_else(|| format!("{}: no column `{n}`", path.display()))
        })
        .collect::<std::result::Result<_, _>>()?;
    let mut columns = vec![Vec::new(); names.len()];
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        for (c, &k) in columns.iter_mut().zip(&index) {
            c.push(cells.get(k).ok_or("short row")?.parse::<f64>()?);
        }
    }
    Ok(columns)
}

/// The cell size (mm) of the run in `dir`, from its effective configuration `config.toml` (the file with
/// the `--set` overrides): the crack path's strips and the damage map's squares.
fn cell_size(dir: &Path) -> Result<f64> {
    let path = dir.join("config.toml");
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let config: toml::Table = toml::from_str(&text)?;
    config
        .get("grid")
        .and_then(|g| g.get("cell_size"))
        .and_then(toml::Value::as_float)
        .ok_or_else(|| format!("{}: no grid.cell_size", path.display()).into())
}

/// Positions (x, y) and damage of the points in the run's last snapshot.
fn last_snapshot(dir: &Path) -> Result<(Vec<[f64; 2]>, Vec<f64>, PathBuf)> {
    let mut snapshots: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("fields_") && n.ends_with(".h5"))
        })
        .collect();
    snapshots.sort();
    let path = snapshots.pop().ok_or("no fields_*.h5 in the run")?;
    let file = hdf5_metno::File::open(&path)?;
    let damage: Vec<f64> = file.dataset("damage")?.read_raw()?;
    let position: Vec<f64> = file.dataset("position")?.read_raw()?;
    if position.len() != 3 * damage.len() {
        return Err(format!("{}: position is not 3 values per point", path.display()).into());
    }
    let x = position.chunks_exact(3).map(|p| [p[0], p[1]]).collect();
    Ok((x, damage, path))
}

/// The crack path, strip by strip across the crack: for every strip of one cell (its centre along
/// `axis`, mm) between `from` and `to` that holds cracked points, the smallest, mean and largest
/// coordinate of those points in the other direction (mm). `axis` 0: vertical strips (a crack running
/// along x, the L-panel's), 1: horizontal strips (the beam's crack running up).
fn crack_path(
    x: &[[f64; 2]],
    damage: &[f64],
    h: f64,
    axis: usize,
    from: f64,
    to: f64,
) -> Vec<[f64; 4]> {
    let other = 1 - axis;
    let mut strips = Vec::new();
    let mut c = from.min(to) + 0.5 * h;
    while c < from.max(to) {
        let across: Vec<f64> = x
            .iter()
            .zip(damage)
            .filter(|(p, d)| **d >= CRACKED && (p[axis] - c).abs() < 0.5 * h)
            .map(|(p, _)| p[other])
            .collect();
        if !across.is_empty() {
            let mean = across.iter().sum::<f64>() / across.len() as f64;
            let lo = across.iter().copied().fold(f64::MAX, f64::min);
            let hi = across.iter().copied().fold(f64::MIN, f64::max);
            strips.push([c, lo, mean, hi]);
        }
        c += h;
    }
    if from > to {
        strips.reverse();
    }
    strips
}

/// A load-displacement curve (mm, kN) and the run's counts: steps, Newton iterations, summed wall time
/// (s), final damage dissipation (N mm per mm thickness).
type Curve = (Vec<(f64, f64)>, [f64; 4]);

/// The load-displacement curve of a run, from the origin, with the run's counts.
fn load_curve(bench: &Bench, dir: &Path) -> Result<Curve> {
    let names = [
        bench.x_column,
        "load_fy",
        "newton_its",
        "wall_total",
        "damage_dissipation",
    ];
    let cols = history(dir, &names)?;
    let curve = std::iter::once((0.0, 0.0))
        .chain(
            cols[0]
                .iter()
                .zip(&cols[1])
                .map(|(u, f)| (bench.displacement_sign * u, bench.force_scale * f)),
        )
        .collect();
    let counts = [
        cols[0].len() as f64,
        cols[2].iter().sum(),
        cols[3].iter().sum(),
        cols[4].last().copied().unwrap_or(0.0),
    ];
    Ok((curve, counts))
}

/// Plots, tables and the JSON summary of the run in `dir` into `out`.
fn report(bench: &Bench, dir: &Path, out: &Path) -> Result<()> {
    let name = bench.name;
    let (curve, [steps, newton, wall, dissipation]) = load_curve(bench, dir)?;
    let h = cell_size(dir)?;
    let (u_peak, f_peak) = curve
        .iter()
        .copied()
        .fold((0.0, f64::MIN), |a, p| if p.1 > a.1 { p } else { a });
    let (u_end, f_end) = *curve.last().ok_or("no steps")?;
    let (lo, hi, label) = bench.reference_peak;
    let mut plot = LinePlot::new(
        format!("{name}: load against displacement"),
        bench.x_label,
        "load [kN]",
    )
    .with_series(format!("this code (plane strain, {h} mm cells)"), curve)
    .with_series(format!("{label}: {lo} kN"), vec![(0.0, lo), (u_end, lo)])
    .with_series(format!("{label}: {hi} kN"), vec![(0.0, hi), (u_end, hi)]);
    for (legend, points) in bench.curves {
        plot = plot.with_series(*legend, points.iter().map(|p| (p[0], p[1])).collect());
    }
    plot.save_png(out.join(format!("validation-{name}-force.png")))?;
    let (x, damage, snapshot) = last_snapshot(dir)?;
    ScatterField {
        title: format!("{name}: damage at {u_end:.3} mm"),
        x: x.iter().map(|p| p[0]).collect(),
        y: x.iter().map(|p| p[1]).collect(),
        value: damage.clone(),
        value_label: "damage [-]".into(),
        range: Some((0.0, 1.0)),
        point_size: 0.5 * h,
    }
    .save_png(out.join(format!("validation-{name}-damage.png")))?;
    let (axis, from, to, heading) = bench.path;
    let strips = crack_path(&x, &damage, h, axis, from, to);
    println!(
        "{name}: peak {f_peak:.3} kN at {u_peak:.4} mm (reference {lo}-{hi} kN); end {f_end:.3} kN at \
         {u_end:.4} mm; {steps} steps, {newton} Newton iterations, wall {wall:.0} s; damage dissipation \
         {dissipation:.3} N mm/mm; snapshot {}",
        snapshot.display()
    );
    println!("{heading}\n|---|---|---|---|");
    for r in &strips {
        println!("| {:.1} | {:.1} | {:.1} | {:.1} |", r[0], r[1], r[2], r[3]);
    }
    let strips: Vec<_> = strips
        .iter()
        .map(|r| json!({"centre": r[0], "min": r[1], "mean": r[2], "max": r[3]}))
        .collect();
    let summary = json!({
        "benchmark": name,
        "run": dir.display().to_string(),
        "units": "kN, mm, N mm per mm thickness, s",
        "peak_load": f_peak,
        "displacement_at_peak": u_peak,
        "end": {"displacement": u_end, "load": f_end},
        "reference_peak_range": [lo, hi],
        "x_column": bench.x_column,
        "cell_size": h,
        "steps": steps,
        "newton_iterations": newton,
        "wall_time_sum": wall,
        "damage_dissipation": dissipation,
        "crack_path": {"strips_along": if axis == 0 { "x" } else { "y" }, "strips": strips},
    });
    let path = out.join(format!("validation-{name}.json"));
    std::fs::write(path, serde_json::to_string_pretty(&summary)? + "\n")?;
    Ok(())
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: validation <l-panel|petersson-3pb|offset-notch-3pb> RUN_DIR [--out DIR]";
    let (name, dir) = match (args.first(), args.get(1)) {
        (Some(n), Some(d)) => (n.as_str(), PathBuf::from(d)),
        _ => return Err(usage.into()),
    };
    let out = match args.get(2).map(String::as_str) {
        Some("--out") => PathBuf::from(args.get(3).ok_or(usage)?),
        Some(other) => return Err(format!("unknown argument `{other}`; {usage}").into()),
        None => dir.clone(),
    };
    let bench = BENCHES
        .iter()
        .find(|b| b.name == name)
        .ok_or_else(|| format!("unknown benchmark `{name}`; {usage}"))?;
    std::fs::create_dir_all(&out)?;
    report(bench, &dir, &out)
}
