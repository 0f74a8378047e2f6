//! The `material-driver` command: one material point along a load path of
//! [`crate::material::driver`], written as CSV (one row per step, header with units) and as a PNG of
//! the stress-strain curve, with the implied uniaxial strengths of a microplane material.
//!
//! Units: MPa (stresses), strains dimensionless.

use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};

use clap::builder::{PossibleValuesParser, TypedValueParser};

use crate::material::driver::{
    EtaBarPath, PathKind, PathPoint, Strengths, peak, run_path, uniaxial_strengths,
};
use crate::material::{Material, MaterialConfig, MaterialError, MicroplaneConfig, Preset};
use crate::plot::{LinePlot, PlotError};

/// Failure of the `material-driver` command.
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    /// The material update or the path failed.
    #[error(transparent)]
    Material(#[from] MaterialError),
    /// Invalid arguments.
    #[error("material-point driver: {0}")]
    Argument(String),
    /// Reading a configuration file failed.
    #[error("cannot read material config `{path}`: {message}")]
    Config {
        /// The config file.
        path: String,
        /// Why it failed.
        message: String,
    },
    /// Writing output failed.
    #[error("cannot write `{path}`: {message}")]
    Io {
        /// The output file.
        path: String,
        /// Why it failed.
        message: String,
    },
    /// Plotting failed.
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// A command-line value that is one of `all`, written as `name(value)`; the names are listed in the help.
fn named<T: Copy + Send + Sync + 'static>(
    all: &'static [T],
    name: fn(T) -> &'static str,
) -> impl TypedValueParser<Value = T> {
    PossibleValuesParser::new(all.iter().map(|&v| name(v))).map(move |given| {
        *all.iter()
            .find(|&&v| name(v) == given)
            .expect("a listed value")
    })
}

/// Stress-strain plot of a path (nominal and Cauchy stress of the controlled component).
pub fn path_plot(points: &[PathPoint], kind: PathKind, title: &str) -> LinePlot {
    let (i, j) = kind.stress_component();
    let (x_label, y_label) = if kind == PathKind::PureShear {
        ("shear strain 2 F12 [-]", "shear stress [MPa]")
    } else {
        ("nominal strain F11 - 1 [-]", "stress 11 [MPa]")
    };
    LinePlot::new(title, x_label, y_label)
        .with_series(
            "P (1st Piola)",
            points.iter().map(|p| (p.control, p.p[(i, j)])).collect(),
        )
        .with_series(
            "sigma (Cauchy)",
            points
                .iter()
                .map(|p| (p.control, p.sigma[(i, j)]))
                .collect(),
        )
}

/// Writes the path as CSV (header with units).
pub fn write_csv(points: &[PathPoint], path: &Path) -> Result<(), DriverError> {
    let io = |e: std::io::Error| DriverError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(io)?;
    }
    let mut w = std::io::BufWriter::new(std::fs::File::create(path).map_err(io)?);
    writeln!(
        w,
        "step,control_strain[-],F11[-],F22[-],F33[-],F12[-],P11[MPa],P22[MPa],P33[MPa],P12[MPa],\
         sigma11[MPa],sigma22[MPa],sigma33[MPa],sigma12[MPa],eta[-],eta_bar[-],damage[-],energy[MPa],newton_iterations"
    )
    .map_err(io)?;
    for (k, p) in points.iter().enumerate() {
        // F11, F22, F33 in full precision (stretches near 1), every other component as {:e}.
        write!(w, "{k},{:e}", p.control).map_err(io)?;
        for (i, j) in COMPONENTS {
            let f = p.f[(i, j)];
            if i == j {
                write!(w, ",{f:.12}")
            } else {
                write!(w, ",{f:e}")
            }
            .map_err(io)?;
        }
        for m in [&p.p, &p.sigma] {
            for ij in COMPONENTS {
                write!(w, ",{:e}", m[ij]).map_err(io)?;
            }
        }
        let scalars = [p.eta, p.eta_bar, p.damage, p.energy];
        for v in scalars {
            write!(w, ",{v:e}").map_err(io)?;
        }
        writeln!(w, ",{}", p.iterations).map_err(io)?;
    }
    w.flush().map_err(io)
}

/// The tensor components written per point, in column order: 11, 22, 33, 12.
const COMPONENTS: [(usize, usize); 4] = [(0, 0), (1, 1), (2, 2), (0, 1)];

/// Command-line arguments of the `material-driver` subcommand.
#[derive(clap::Args, Clone, Debug)]
pub struct DriverArgs {
    /// TOML file with the material: a `[material]` table or the section's keys at top level
    /// (`model = "microplane"`, ...). Overrides `--preset`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Microplane parameter preset used when no config is given.
    #[arg(long, default_value = "paper", value_parser = named(&Preset::ALL, Preset::name))]
    pub preset: Preset,
    /// Load path.
    #[arg(long, default_value = "uniaxial-tension", value_parser = named(&PathKind::ALL, PathKind::name))]
    pub path: PathKind,
    /// Magnitude of the control strain at the end of the path (default: 10 gamma_0, 40 gamma_0 in
    /// compression; 0.01 for elastic materials).
    #[arg(long, allow_negative_numbers = true)]
    pub max_strain: Option<f64>,
    /// Number of load steps.
    #[arg(long, default_value_t = 400)]
    pub steps: usize,
    /// Prescribe `eta_bar = eta_bar_max |eps|/max_strain` instead of the local `eta_bar = eta`.
    #[arg(long, allow_negative_numbers = true)]
    pub eta_bar_max: Option<f64>,
    /// Output directory for `<name>.csv` and `<name>.png`.
    #[arg(long, default_value = "out/material-driver")]
    pub out: PathBuf,
    /// File stem of the outputs (default: the path name).
    #[arg(long)]
    pub name: Option<String>,
    /// Steps of each of the two monotonic runs that measure the implied uniaxial strengths.
    #[arg(long, default_value_t = 2000)]
    pub strength_steps: usize,
}

/// What [`run_driver`] did and measured.
#[derive(Clone, Debug)]
pub struct DriverSummary {
    /// The path driven.
    pub path: PathKind,
    /// The CSV written (one row per load step).
    pub csv: PathBuf,
    /// The stress-strain plot written.
    pub png: PathBuf,
    /// Peak magnitude of the controlled stress component along the path (MPa).
    pub peak_stress: f64,
    /// Control strain at the peak.
    pub strain_at_peak: f64,
    /// Output damage at the end of the path.
    pub final_damage: f64,
    /// Implied uniaxial strengths (microplane only).
    pub strengths: Option<Strengths>,
}

impl DriverError {
    /// The driver's input was bad (its arguments, the material configuration), not the work.
    pub fn is_bad_input(&self) -> bool {
        matches!(
            self,
            DriverError::Argument(_)
                | DriverError::Config { .. }
                | DriverError::Material(MaterialError::DriverArgument(_))
        )
    }
}

impl fmt::Display for DriverSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "path {}: {} / {}",
            self.path.name(),
            self.csv.display(),
            self.png.display()
        )?;
        writeln!(
            f,
            "  peak |stress| {:.4} MPa at strain {:.4e}; final damage {:.4}",
            self.peak_stress, self.strain_at_peak, self.final_damage
        )?;
        if let Some(s) = &self.strengths {
            writeln!(
                f,
                "  implied uniaxial strengths: tensile {:.3} MPa (at {:.3e}), compressive {:.3} MPa (at {:.3e}), ratio {:.3}",
                s.tensile,
                s.tensile_strain,
                s.compressive,
                s.compressive_strain,
                s.compressive / s.tensile
            )?;
        }
        Ok(())
    }
}

/// Reads a material config file (`[material]` table or top-level keys).
pub fn read_material_config(path: &Path) -> Result<MaterialConfig, DriverError> {
    let err = |message: String| DriverError::Config {
        path: path.display().to_string(),
        message,
    };
    let text = crate::input::read_text_input(path).map_err(|e| err(e.reason()))?;
    let table: toml::Table = toml::from_str(&text).map_err(|e| err(one_line(&e, &text)))?;
    let section = match table.get("material") {
        Some(toml::Value::Table(t)) => t.clone(),
        Some(_) => return Err(err("`material` must be a table".into())),
        None => table,
    };
    section
        .try_into()
        .map_err(|e: toml::de::Error| err(one_line(&e, "")))
}

/// A TOML error on one line: `line L: message` when it points into `text`, else the message alone.
fn one_line(e: &toml::de::Error, text: &str) -> String {
    let message = e.message().trim().replace('\n', " ");
    match e.span().and_then(|s| text.get(..s.start)) {
        Some(before) if !text.is_empty() => {
            format!("line {}: {message}", before.matches('\n').count() + 1)
        }
        _ => message,
    }
}

/// Most load steps of a path or of a strength search (each holds one row of the curve).
const MAX_STEPS: usize = 1_000_000;

/// Refuses arguments that would fail after writing, or write elsewhere than `--out`, before any work.
fn check_args(args: &DriverArgs) -> Result<(), DriverError> {
    for (option, n) in [
        ("--steps", args.steps),
        ("--strength-steps", args.strength_steps),
    ] {
        if !(1..=MAX_STEPS).contains(&n) {
            return Err(DriverError::Argument(format!(
                "{option} {n}: a number of load steps in 1..={MAX_STEPS}"
            )));
        }
    }
    if let Some(max) = args.eta_bar_max
        && !(max.is_finite() && max >= 0.0)
    {
        return Err(DriverError::Argument(format!(
            "--eta-bar-max {max}: a finite nonlocal equivalent strain >= 0"
        )));
    }
    if args.out.exists() && !args.out.is_dir() {
        return Err(DriverError::Argument(format!(
            "--out {}: exists and is not a directory (give another --out)",
            args.out.display()
        )));
    }
    if let Some(name) = &args.name
        && (name.is_empty() || name.contains(['/', '\\']) || name.starts_with('.'))
    {
        return Err(DriverError::Argument(format!(
            "--name {name:?}: a non-empty file name without / or \\ that does not start with a dot \
             (it names NAME.csv and NAME.png in --out)"
        )));
    }
    Ok(())
}

/// Runs the driver: builds the material, follows the path, writes CSV and PNG, measures strengths.
pub fn run_driver(args: &DriverArgs) -> Result<DriverSummary, DriverError> {
    check_args(args)?;
    let config = match &args.config {
        Some(p) => read_material_config(p)?,
        None => MaterialConfig::Microplane(MicroplaneConfig::preset(args.preset)),
    };
    let material = config
        .build()
        .map_err(|e| DriverError::Argument(format!("the material: {e}")))?;
    let max_strain = match (args.max_strain, &material) {
        (Some(m), _) => m,
        (None, Material::Microplane(m)) => {
            let g0 = m.params().gamma_0;
            if args.path.sign() < 0.0 {
                40.0 * g0
            } else {
                10.0 * g0
            }
        }
        (None, _) => 0.01,
    };
    let eta_bar_path = match args.eta_bar_max {
        Some(max) => EtaBarPath::Prescribed { max },
        None => EtaBarPath::Local,
    };
    let points = run_path(&material, args.path, max_strain, args.steps, eta_bar_path)?;
    // The path's own arguments are checked by run_path: the directory is made once they have passed.
    std::fs::create_dir_all(&args.out).map_err(|e| {
        DriverError::Argument(format!(
            "--out {}: cannot create the output directory: {e} (give another --out)",
            args.out.display()
        ))
    })?;
    let name = args
        .name
        .clone()
        .unwrap_or_else(|| args.path.name().to_string());
    let csv = args.out.join(format!("{name}.csv"));
    let png = args.out.join(format!("{name}.png"));
    write_csv(&points, &csv)?;
    let source = match &args.config {
        Some(p) => p.display().to_string(),
        None => format!("preset {}", args.preset.name()),
    };
    path_plot(
        &points,
        args.path,
        &format!("{} ({source})", args.path.name()),
    )
    .save_png(&png)?;
    let (peak_stress, strain_at_peak) = peak(&points, args.path);
    Ok(DriverSummary {
        path: args.path,
        csv,
        png,
        peak_stress,
        strain_at_peak,
        final_damage: points.last().map_or(0.0, |p| p.damage),
        strengths: uniaxial_strengths(&material, args.strength_steps)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: DriverArgs,
    }

    #[test]
    fn presets_and_paths_parse_by_their_names() {
        let cli = Cli::try_parse_from([
            "material-driver",
            "--preset",
            "paper_gamma0_1.25e-4_scaled",
            "--path",
            "pure-shear",
        ])
        .unwrap();
        assert_eq!(cli.args.preset, Preset::PaperGamma0LowScaled);
        assert_eq!(cli.args.path, PathKind::PureShear);
        let defaults = Cli::try_parse_from(["material-driver"]).unwrap();
        assert_eq!(defaults.args.preset, Preset::Paper);
        assert_eq!(defaults.args.path, PathKind::UniaxialTension);
        for p in Preset::ALL {
            let c = Cli::try_parse_from(["material-driver", "--preset", p.name()]).unwrap();
            assert_eq!(c.args.preset, p);
        }
        let e = Cli::try_parse_from(["material-driver", "--path", "nope"])
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("nope") && e.contains("pure-shear"), "{e}");
    }

    #[test]
    fn run_driver_writes_csv_png_and_reads_config() {
        let dir = std::env::temp_dir().join(format!("mpm_concrete_driver_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cfg = dir.join("m.toml");
        std::fs::write(&cfg, "[material]\nmodel = \"microplane\"\npreset = \"paper_gamma0_1.25e-4\"\nquadrature = \"bo33\"\n").unwrap();
        let args = DriverArgs {
            config: Some(cfg),
            preset: Preset::Paper,
            path: PathKind::UniaxialTension,
            max_strain: Some(6e-4),
            steps: 40,
            eta_bar_max: None,
            out: dir.clone(),
            name: Some("t".into()),
            strength_steps: 100,
        };
        let s = run_driver(&args).unwrap();
        assert!(s.csv.exists() && s.png.exists());
        let text = std::fs::read_to_string(&s.csv).unwrap();
        assert!(text.starts_with("step,control_strain[-]"));
        assert_eq!(text.lines().count(), 42);
        let st = s.strengths.unwrap();
        assert!(st.tensile > 1.0 && st.compressive > st.tensile);
        assert!(s.to_string().contains("implied uniaxial strengths"));
        std::fs::write(dir.join("bad.toml"), "model = \"microplane\"\nbogus = 1\n").unwrap();
        let bad = DriverArgs {
            config: Some(dir.join("bad.toml")),
            ..args
        };
        assert!(matches!(run_driver(&bad), Err(DriverError::Config { .. })));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn arguments_that_would_fail_late_or_write_elsewhere_are_refused_before_any_work() {
        let dir = std::env::temp_dir().join(format!("mpm_concrete_refused_{}", std::process::id()));
        let good = DriverArgs {
            config: None,
            preset: Preset::Paper,
            path: PathKind::UniaxialTension,
            max_strain: None,
            steps: 3,
            eta_bar_max: None,
            out: dir.clone(),
            name: None,
            strength_steps: 3,
        };
        let cases = [
            (
                "--steps",
                DriverArgs {
                    steps: usize::MAX,
                    ..good.clone()
                },
            ),
            (
                "--strength-steps",
                DriverArgs {
                    strength_steps: 0,
                    ..good.clone()
                },
            ),
            (
                "--eta-bar-max",
                DriverArgs {
                    eta_bar_max: Some(-1.0),
                    ..good.clone()
                },
            ),
            (
                "--name",
                DriverArgs {
                    name: Some("../../evil".into()),
                    ..good.clone()
                },
            ),
            (
                "--name",
                DriverArgs {
                    name: Some(String::new()),
                    ..good.clone()
                },
            ),
        ];
        for (option, args) in cases {
            match run_driver(&args) {
                Err(DriverError::Argument(m)) => assert!(m.starts_with(option), "{m}"),
                other => panic!("{option}: expected a refusal, got {other:?}"),
            }
        }
        assert!(!dir.exists(), "nothing written");
    }
}
