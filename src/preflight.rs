//! Checks that run before a simulation starts, so that a run that cannot work fails at once with one line
//! instead of after its first step or with an allocation failure: the values of common PETSc options and
//! the memory the run will need.

use crate::input::BadValue;
use crate::scenario::{Plan, ScenarioError};
use nalgebra::Vector2;
use std::path::Path;

/// What the value of a checked PETSc option must be.
#[derive(Debug, Clone, Copy)]
enum Allowed {
    /// A relative tolerance: a number in [0, 1).
    Fraction,
    /// A number >= 0.
    NonNegative,
    /// An integer >= 1.
    Count,
    /// An integer >= 0.
    NonNegativeCount,
}

/// Checked options, matched against the end of an option's name so that prefixed copies
/// (`-fallback_snes_max_it`, `-sub_ksp_rtol`, `-fieldsplit_u_ksp_max_it`) are checked too. PETSc's own
/// limits, except that an iteration limit must allow at least one iteration (with 0 every step fails).
const CHECKED: [(&str, Allowed); 12] = [
    ("ksp_rtol", Allowed::Fraction),
    ("mpm_keep_jacobian_below", Allowed::Fraction),
    ("snes_rtol", Allowed::Fraction),
    ("ksp_atol", Allowed::NonNegative),
    ("snes_atol", Allowed::NonNegative),
    ("snes_stol", Allowed::NonNegative),
    ("pc_factor_shift_amount", Allowed::NonNegative),
    ("ksp_max_it", Allowed::Count),
    ("snes_max_it", Allowed::Count),
    ("ksp_gmres_restart", Allowed::Count),
    ("snes_linesearch_max_it", Allowed::Count),
    ("pc_factor_levels", Allowed::NonNegativeCount),
];

/// Words PETSc accepts in place of a number.
const KEYWORDS: [&str; 6] = [
    "default",
    "petsc_default",
    "decide",
    "petsc_decide",
    "determine",
    "petsc_determine",
];

/// A refused value of a common PETSc option ([`check_petsc_options`]): the option as written, the value
/// that follows it (`None`: none does) and what is allowed.
#[derive(Debug, Clone, PartialEq)]
pub struct OptionError {
    /// The option as written, e.g. `-fallback_snes_max_it`.
    pub option: String,
    /// The value given; `None` when no value follows the option.
    pub value: Option<String>,
    /// What the value must be, e.g. `an integer >= 1`.
    pub allowed: &'static str,
}

impl std::fmt::Display for OptionError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Self {
            option, allowed, ..
        } = self;
        match &self.value {
            None => write!(f, "PETSc option {option} needs a value: {allowed}"),
            Some(value) => write!(
                f,
                "PETSc option {option} {value}: the value must be {allowed}"
            ),
        }
    }
}

impl std::error::Error for OptionError {}

impl OptionError {
    /// This error as a refused value of the configuration key `key` (e.g. `run.petsc_options`), which
    /// holds the options string: the option with its value, and what the option's value must be.
    pub fn at_key(&self, key: &str) -> BadValue {
        let (option, allowed) = (&self.option, self.allowed);
        match &self.value {
            None => BadValue::new(key, option, format!("a value after {option}: {allowed}")),
            Some(value) => BadValue::new(
                key,
                format!("{option} {value}"),
                format!("the value of {option} must be {allowed}"),
            ),
        }
    }
}

/// Checks the values of the common numeric PETSc options in `options` (a PETSc options string, e.g.
/// `-ksp_rtol 1e-6 -snes_max_it 25`); the error names the option, its value and what is allowed.
pub fn check_petsc_options(options: &str) -> Result<(), OptionError> {
    let tokens: Vec<&str> = options.split_whitespace().collect();
    let is_name = |t: &str| {
        t.strip_prefix('-')
            .and_then(|r| r.chars().next())
            .is_some_and(|c| c.is_ascii_alphabetic())
    };
    for (i, token) in tokens.iter().enumerate() {
        if !is_name(token) {
            continue;
        }
        let name = &token[1..];
        let Some(&(_, allowed)) = CHECKED
            .iter()
            .find(|(key, _)| name == *key || name.ends_with(&format!("_{key}")))
        else {
            continue;
        };
        let value = tokens.get(i + 1).filter(|v| !is_name(v));
        let what = match allowed {
            Allowed::Fraction => "a number in [0, 1)",
            Allowed::NonNegative => "a number >= 0",
            Allowed::Count => "an integer >= 1",
            Allowed::NonNegativeCount => "an integer >= 0",
        };
        let refused = |value: Option<&str>| OptionError {
            option: (*token).to_owned(),
            value: value.map(str::to_owned),
            allowed: what,
        };
        let Some(value) = value else {
            return Err(refused(None));
        };
        if KEYWORDS.contains(&value.to_ascii_lowercase().as_str()) {
            continue;
        }
        let ok = match (allowed, value.parse::<f64>()) {
            (_, Err(_)) => false,
            (Allowed::Fraction, Ok(v)) => (0.0..1.0).contains(&v),
            (Allowed::NonNegative, Ok(v)) => v.is_finite() && v >= 0.0,
            (Allowed::Count, Ok(v)) => v.fract() == 0.0 && (1.0..=i32::MAX as f64).contains(&v),
            (Allowed::NonNegativeCount, Ok(v)) => {
                v.fract() == 0.0 && (0.0..=i32::MAX as f64).contains(&v)
            }
        };
        if !ok {
            return Err(refused(Some(value)));
        }
    }
    Ok(())
}

/// The PETSc options whose value is a file PETSc reads at its start (`PetscInitialize`).
const OPTIONS_FILES: [&str; 2] = ["-options_file", "-options_file_yaml"];

/// Checks the files that `-options_file` and `-options_file_yaml` name among the PETSc options `options`
/// (the command line's PETSc arguments, `PETSC_OPTIONS` or a study set's options) before PETSc reads
/// them: each must be a regular file of at most [`crate::input::TEXT_INPUT_MAX`] bytes
/// ([`crate::input::check_input_file`]), so that a FIFO cannot block PETSc's start and `/dev/zero` or a
/// huge file cannot exhaust the memory. The error names the option, the file and the limit.
pub fn check_options_files<'a>(options: impl IntoIterator<Item = &'a str>) -> Result<(), String> {
    let mut tokens = options.into_iter();
    while let Some(token) = tokens.next() {
        if !OPTIONS_FILES.contains(&token) {
            continue;
        }
        let Some(file) = tokens.next().filter(|f| !f.starts_with('-')) else {
            return Err(format!(
                "PETSc option {token} needs a value: the options file to read"
            ));
        };
        crate::input::check_input_file(Path::new(file), crate::input::TEXT_INPUT_MAX)
            .map_err(|e| format!("PETSc option {token} {e}"))?;
    }
    Ok(())
}

/// Process baseline (program, PETSc, MPI, HDF5 libraries) in bytes.
pub const BASE_BYTES: f64 = 60e6;
/// Bytes per material point over a run: the points' state, shape-function tables, the Jacobian and the
/// linear solver (including the MUMPS LU of the fallback). Calibrated on the CT specimen: 155,600 points
/// (1 mm cells) peak at about 850 MB; 39,120 points (2 mm) at 195 MB with GMRES/ILU and 246 MB with
/// MUMPS; 9,780 points (4 mm) at 89-100 MB.
pub const BYTES_PER_POINT: f64 = 5.2e3;
/// Bytes per material point of a 3D run (`[extrusion]`): supports of 27-64 nodes and 4 x 4 Jacobian
/// blocks. Calibrated on the 3D CT demo (39,120 points, 8 mm plate): 758 MB serial with GMRES/ILU, 831 MB
/// on process 0 of 2 (which builds the whole model), 1150 MB with MUMPS LU.
pub const BYTES_PER_POINT_3D: f64 = 20e3;
/// Bytes per background-grid node (nodal state and unknown numbering); measured as the growth of the
/// peak with the grid margin (120,000 extra nodes: +17 MB).
pub const BYTES_PER_NODE: f64 = 150.0;

/// Estimated size of a run, from its plan (before any point is seeded).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MemoryNeed {
    /// Material points (deformable and rigid), counted on the seeding lattice.
    pub points: f64,
    /// Background-grid nodes.
    pub nodes: f64,
    /// Peak resident memory (bytes).
    pub bytes: f64,
}

/// The memory the run of `plan` will need at its peak: its points as seeding will place them, the nodes
/// of the grid over the bodies' bounding box (one copy per velocity field) and, with `[extrusion]`, the
/// plate's layers of points and nodes.
pub fn memory_need(plan: &Plan) -> Result<MemoryNeed, ScenarioError> {
    let cfg = plan.config();
    let h = cfg.grid.cell_size;
    let (lo, hi) = plan
        .extent()
        .unwrap_or((Vector2::zeros(), Vector2::zeros()));
    let margin = 2.0 * cfg.grid.margin_cells.max(1) as f64 + 1.0;
    let nodes = plan.num_fields() as f64
        * ((hi.x - lo.x) / h + margin).max(1.0)
        * ((hi.y - lo.y) / h + margin).max(1.0);
    let plane_points = plan.points()?;
    // A plate: a layer of points per point spacing through the thickness, the plate's node layers plus
    // the extrusion's margin of 2 cells on both faces; the bodies of space as seeded.
    let (points, nodes, per_point) = match &cfg.extrusion {
        Some(e) => (
            plane_points * e.thickness * cfg.shape.points_per_cell as f64 / h
                + plan.space_points()?,
            nodes * (e.thickness / h + 5.0),
            BYTES_PER_POINT_3D,
        ),
        None => (plane_points, nodes, BYTES_PER_POINT),
    };
    Ok(MemoryNeed {
        points,
        nodes,
        bytes: BASE_BYTES + per_point * points + BYTES_PER_NODE * nodes,
    })
}

/// The memory a new process can use: the smaller of `MemAvailable` in /proc/meminfo and the free part
/// of the cgroup's `memory.max`.
#[derive(Debug, Clone, PartialEq)]
pub struct MemoryLimit {
    /// Bytes.
    pub bytes: f64,
    /// Where the number comes from.
    pub source: &'static str,
}

/// The current limit, or `None` where /proc/meminfo cannot be read.
pub fn memory_limit() -> Option<MemoryLimit> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok()?;
    let available = meminfo
        .lines()
        .find_map(|l| l.strip_prefix("MemAvailable:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|kb| kb.parse::<f64>().ok())?
        * 1024.0;
    let read = |file: &str| {
        std::fs::read_to_string(format!("/sys/fs/cgroup/{file}"))
            .ok()
            .and_then(|s| s.trim().parse::<f64>().ok())
    };
    let cgroup = read("memory.max").map(|max| max - read("memory.current").unwrap_or(0.0));
    Some(match cgroup {
        Some(free) if free < available => MemoryLimit {
            bytes: free,
            source: "the cgroup's memory.max less memory.current",
        },
        _ => MemoryLimit {
            bytes: available,
            source: "MemAvailable in /proc/meminfo",
        },
    })
}

/// Bytes in a short human form (`850 MB`, `330 GB`).
pub fn human_bytes(b: f64) -> String {
    if b >= 1e12 {
        format!("{:.1} TB", b / 1e12)
    } else if b >= 1e9 {
        format!("{:.1} GB", b / 1e9)
    } else {
        format!("{:.0} MB", b / 1e6)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::RunConfig;

    #[test]
    fn common_option_values_are_checked_with_prefixes() {
        for good in [
            "",
            "-ksp_rtol 1e-6 -snes_max_it 25 -snes_monitor",
            "-fallback_snes_max_it 50 -sub_pc_factor_levels 0 -ksp_rtol 0",
            "-snes_atol default -log_view :log.txt -x -1.5",
        ] {
            assert_eq!(check_petsc_options(good), Ok(()), "{good}");
        }
        for (bad, needle) in [
            (
                "-ksp_rtol -5",
                "-ksp_rtol -5: the value must be a number in [0, 1)",
            ),
            ("-ksp_rtol 1", "[0, 1)"),
            (
                "-snes_max_it -3",
                "-snes_max_it -3: the value must be an integer >= 1",
            ),
            ("-fallback_snes_max_it 0", "-fallback_snes_max_it 0"),
            ("-ksp_max_it 2.5", "an integer >= 1"),
            ("-snes_atol nan", "a number >= 0"),
            ("-snes_stol abc", "-snes_stol abc"),
            ("-ksp_rtol -snes_monitor", "-ksp_rtol needs a value"),
            ("-snes_max_it", "-snes_max_it needs a value"),
        ] {
            let e = check_petsc_options(bad).expect_err(bad).to_string();
            assert!(e.contains(needle), "{bad}: {e}");
        }
    }

    #[test]
    fn the_memory_estimate_matches_the_measured_ct_runs() {
        let ct = |h: f64| {
            RunConfig::from_str_named(
                &format!(
                    "[run]\nname = \"m\"\nsteps = 1\n[grid]\ncell_size = {h:?}\n[ct]\nloading_rate = 4300.0\n\
                     material = {{ model = \"microplane\", preset = \"paper\" }}\n"
                ),
                "m.toml",
            )
            .expect("config")
        };
        let need = |cfg: &RunConfig| {
            memory_need(&crate::scenario::plan(cfg).expect("plan")).expect("need")
        };
        let full = need(&ct(1.0));
        // 155,600 points of concrete and 480 of the two rigid plates.
        assert_eq!(full.points, 156_080.0, "{full:?}");
        assert!((0.85e9..1.0e9).contains(&full.bytes), "{full:?}");
        let tiny_cells = need(&ct(0.05));
        assert!(tiny_cells.bytes > 3e11, "{tiny_cells:?}");
        assert_eq!(human_bytes(tiny_cells.bytes).split(' ').nth(1), Some("GB"));
        // The 3D demo (8 mm plate of 4 mm cells: 4 layers of points) peaked at 758-831 MB; the paper's
        // CT as a 50 mm plate (15.6 million points) needs hundreds of GB.
        let plate = |h: f64, thickness: f64| {
            let mut cfg = ct(h);
            cfg.extrusion = Some(crate::config::ExtrusionSection {
                thickness,
                section_z: None,
            });
            need(&cfg)
        };
        let demo = plate(4.0, 8.0);
        assert_eq!(demo.points, 4.0 * need(&ct(4.0)).points, "{demo:?}");
        assert!((0.7e9..1.0e9).contains(&demo.bytes), "{demo:?}");
        assert!(plate(1.0, 50.0).bytes > 2e11);
    }

    #[test]
    fn the_memory_limit_is_read_from_proc_meminfo() {
        let limit = memory_limit().expect("/proc/meminfo");
        assert!(limit.bytes > 0.0, "{limit:?}");
    }
}
