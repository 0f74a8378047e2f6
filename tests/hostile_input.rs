//! Inputs a hostile user tries, on the real binary and a tiny CT specimen (360 points): extreme finite
//! values, vectors of the wrong length, a self-crossing polygon, a grid coarser than the bodies, a grid
//! with too many nodes, a body that holds no point, options
//! named as the user typed them, whole tables replaced by `--set`, corrupt or locked run directories for
//! `crack` and `--resume`, `material-driver`'s output and configuration, clap's usage errors, a path
//! gauge point off the body, finite elements on a turned grid and a 100 KB `--set` value. Each is
//! refused with exit code 2 and one line (two for a usage error: the error and where the help is), and
//! nothing is written.
//!
//! Units: mm, s, N, MPa, t.

mod binary;

use binary::{BLOCK, record, refused, run, scratch, stderr, succeeds};
use std::process::Command;

#[test]
fn extreme_values_odd_vectors_and_whole_tables_are_refused_before_anything_is_written() {
    let dir = scratch("hostile", "values", &[("block.toml", BLOCK)]);
    // (config, --set overrides or other arguments, what the error line must name)
    let cases: Vec<(&str, Vec<&str>, Vec<&str>)> = vec![
        (
            "tiny.toml",
            vec!["--set", "time.dt=1e300"],
            vec!["tiny.toml", "`time.dt` = 1e300", "[1e-12, 1000] s"],
        ),
        (
            "tiny.toml",
            vec!["--set", "ct.material.bulk_modulus=1e308"],
            vec!["`ct.material.bulk_modulus` = 1e308", "[1e-6, 1e7] MPa"],
        ),
        (
            "tiny.toml",
            vec!["--set", "ct.density=1e300"],
            vec!["`ct.density` = 1e300", "[1e-15, 1e-6] t/mm^3"],
        ),
        (
            "tiny.toml",
            vec!["--set", "ct.loading_rate=-4300"],
            vec!["`ct.loading_rate` = -4300", "> 0", "direction is fixed"],
        ),
        (
            "block.toml",
            vec!["--set", "body_force=[0,1,2,3]"],
            vec![
                "`body_force` = [0, 1, 2, 3]",
                "2 components (x, y), not 4",
                "2D",
            ],
        ),
        (
            "block.toml",
            vec!["--set", "body[0].initial_velocity=[1.0,0.0,0.0]"],
            vec!["`body[0].initial_velocity`", "not 3"],
        ),
        (
            "block.toml",
            vec!["--set", "constraint[0].max=[11.0]"],
            vec!["`constraint[0].max`", "not 1"],
        ),
        (
            "block.toml",
            vec![
                "--set",
                "body[0].geometry={include=[{type=\"polygon\",vertices=[[0.0,0.0],[10.0,10.0],[10.0,0.0],[0.0,10.0]]}]}",
            ],
            vec![
                "`body[0].geometry` = (body \"b\")",
                "edges 0 (vertices 0 to 1) and 2 (vertices 2 to 3) meet at (5.000, 5.000) mm",
            ],
        ),
        (
            "tiny.toml",
            vec!["--set", "grid.cell_size=1e300"],
            vec![
                "`grid.cell_size` = 1e300",
                "at most 160 mm",
                "4e-299 x 4e-299 cells",
            ],
        ),
        (
            "tiny.toml",
            vec!["--steps", "18446744073709551615"],
            vec![
                "--steps 18446744073709551615",
                "from 1 to 9223372036854775807",
            ],
        ),
        (
            "tiny.toml",
            vec!["--set", "ct=5"],
            vec![
                "--set ct=5",
                "`ct` is a table",
                "--set ct.loading_rate=...",
                "width",
            ],
        ),
        (
            "tiny.toml",
            vec!["--set", "time.dt_min=1e-300"],
            vec!["`time.dt_min` = 1e-300", "1e-12 <= dt_min <= dt"],
        ),
        (
            "block.toml",
            vec!["--set", "body[0]=5"],
            vec![
                "`body[0]` is an entry of [[body]]",
                "--set body[0].name=...",
            ],
        ),
        (
            "block.toml",
            vec!["--allow-large", "--set", "grid.margin_cells=100000000"],
            vec![
                "`grid.margin_cells` = 100000000",
                "200000005 x 200000005 cells",
                "too many nodes",
            ],
        ),
        (
            "block.toml",
            vec![
                "--set",
                "body[0].geometry.exclude=[{type=\"rect\",min=[-1.0,-1.0],max=[11.0,11.0]}]",
            ],
            vec!["`body[0].geometry` = `b`", "(this one holds none)"],
        ),
        (
            "block.toml",
            vec!["--set", "extrusion=5"],
            vec![
                "`extrusion` is a table ([extrusion])",
                "extrusion.thickness",
            ],
        ),
    ];
    for (config, extra, needles) in &cases {
        let mut args = vec!["run", config, "--quiet", "--output", "out"];
        args.extend(extra);
        let line = refused(&run(&dir, &args), needles);
        assert!(!dir.join("out").exists(), "{args:?} wrote out/: {line}");
    }
    // A configuration that is a FIFO would block the read; bad options in PETSc's environment variable.
    let fifo = Command::new("mkfifo").arg(dir.join("fifo.toml")).status();
    assert!(fifo.is_ok_and(|s| s.success()), "mkfifo");
    refused(
        &run(&dir, &["run", "fifo.toml", "--output", "out"]),
        &[
            "fifo.toml: is a FIFO (named pipe), not a regular file: an input must be a regular file of at most 64 MiB",
        ],
    );
    let env = Command::new(binary::EXE)
        .current_dir(&dir)
        .env("PETSC_OPTIONS", "-ksp_rtol -5")
        .args(["run", "tiny.toml", "--quiet", "--output", "out"])
        .output()
        .expect("start mpm-concrete");
    refused(
        &env,
        &[
            "environment variable PETSC_OPTIONS",
            "-ksp_rtol -5",
            "[0, 1)",
        ],
    );
    assert!(!dir.join("out").exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// A block under a load on its top edge: the `[[load]]` keys.
const LOADED: &str = r#"
[[load]]
name = "top"
from = [0.0, 10.0]
to = [10.0, 10.0]
force = [0.0, -1.0]
"#;

#[test]
fn damage_parameters_times_loads_and_names_beyond_any_real_run_are_refused() {
    let block = format!("{BLOCK}{LOADED}");
    let dir = scratch("hostile", "bounds", &[("block.toml", &block)]);
    let long = format!("run.name=\"{}\"", "n".repeat(256));
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        (
            "tiny.toml",
            "ct.material.gamma_0=1e300".into(),
            vec!["`ct.material.gamma_0` = 1e300", "0 < gamma_0 <= 0.1"],
        ),
        (
            "tiny.toml",
            "ct.material.beta=1e300".into(),
            vec!["`ct.material.beta` = 1e300", "0 <= beta <= 1e7"],
        ),
        (
            "tiny.toml",
            "ct.material.c=1e300".into(),
            vec!["`ct.material.c` = 1e300", "0 <= c <= 1e6 (mm^2"],
        ),
        (
            "tiny.toml",
            "ct.material.k_r=1e300".into(),
            vec!["`ct.material.k_r` = 1e300", "1 < k_r <= 1000"],
        ),
        (
            "tiny.toml",
            "ct.rise_time=1e300".into(),
            vec!["`ct.rise_time` = 1e300", "[0, 1000] s"],
        ),
        (
            "block.toml",
            "load[0].force=[1e300,0.0]".into(),
            vec!["`load[0] (top).from/to/force`", "at most 1e9 N"],
        ),
        (
            "tiny.toml",
            "run.name=\"a\u{202e}b\"".into(),
            vec!["`run.name` = \"a\\u{202e}b\"", "invisible format"],
        ),
        (
            "tiny.toml",
            long,
            vec!["`run.name` = \"nnnn", "(256 bytes)", "at most 255 bytes"],
        ),
    ];
    for (config, set, needles) in &cases {
        let args = ["run", config, "--quiet", "--output", "out", "--set", set];
        let line = refused(&run(&dir, &args), needles);
        assert!(!dir.join("out").exists(), "{args:?} wrote out/: {line}");
    }
    // The smoke lattice's springs diverge beyond a load of about 0.07 per node.
    refused(
        &run(&dir, &["smoke", "--load", "1e300"]),
        &["--load", "|load| <= 0.05"],
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn crack_refuses_an_unreadable_snapshot_and_a_directory_a_run_still_holds() {
    let dir = scratch("hostile", "crack", &[]);
    succeeds(&run(
        &dir,
        &["run", "tiny.toml", "--quiet", "--output", "d"],
    ));
    let d = dir.join("d");
    let crack_json = std::fs::read(d.join("crack.json")).expect("crack.json");
    // Random bytes instead of a snapshot: bad input, crack.json untouched.
    let noise: Vec<u8> = (0..3000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
        .collect();
    std::fs::write(d.join("fields_000002.h5"), noise).unwrap();
    refused(
        &run(&dir, &["crack", "d"]),
        &[
            "fields_000002.h5",
            "not readable as a snapshot",
            "crack.json is unchanged",
        ],
    );
    assert_eq!(std::fs::read(d.join("crack.json")).unwrap(), crack_json);
    // A run still writing into the directory (its lock held): refused, crack.json untouched.
    let lock = mpm_concrete::rundir::lock(&d).expect("lock");
    refused(
        &run(&dir, &["crack", "d"]),
        &[
            "another run is writing into this directory",
            "then re-measure",
        ],
    );
    drop(lock);
    assert_eq!(std::fs::read(d.join("crack.json")).unwrap(), crack_json);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn resume_names_a_checkpoint_that_is_a_directory_and_ignores_a_garbage_record_aloud() {
    let dir = scratch("hostile", "resume", &[]);
    succeeds(&run(
        &dir,
        &["run", "tiny.toml", "--quiet", "--output", "d"],
    ));
    std::fs::write(dir.join("d/run.json"), "garbage").unwrap();
    let resumed = run(
        &dir,
        &[
            "run",
            "tiny.toml",
            "--quiet",
            "--output",
            "d",
            "--resume",
            "--steps",
            "6",
        ],
    );
    succeeds(&resumed);
    assert!(
        stderr(&resumed).contains("d/run.json: not a run record")
            && stderr(&resumed).contains("ignored"),
        "{}",
        stderr(&resumed)
    );
    assert_eq!(record(&dir.join("d")).steps_done, 6);
    std::fs::remove_file(dir.join("d/checkpoint.h5")).unwrap();
    std::fs::create_dir(dir.join("d/checkpoint.h5")).unwrap();
    refused(
        &run(
            &dir,
            &[
                "run",
                "tiny.toml",
                "--quiet",
                "--output",
                "d",
                "--resume",
                "--steps",
                "8",
            ],
        ),
        &["d/checkpoint.h5: is a directory, not a regular file"],
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn material_driver_and_usage_errors_are_short() {
    let dir = scratch("hostile", "usage", &[("a_file", "")]);
    std::fs::write(dir.join("mat.toml"), "model = \"svk\"\nyoungs_modulus = \n").unwrap();
    refused(
        &run(&dir, &["material-driver", "--out", "a_file"]),
        &["--out a_file: exists and is not a directory"],
    );
    for config in ["mat.toml", "tiny.toml"] {
        let o = run(
            &dir,
            &["material-driver", "--config", config, "--out", "out"],
        );
        refused(&o, &["cannot read material config"]);
        assert_eq!(stderr(&o).lines().count(), 1, "{}", stderr(&o));
    }
    assert!(!dir.join("out").exists());
    // Usage errors: the error line (with clap's continuation folded in) and where the help is.
    let usage: Vec<(Vec<&str>, &str, &str)> = vec![
        (vec!["run"], "<CONFIG>", "try 'mpm-concrete run --help'"),
        (
            vec!["run", "tiny.toml", "--steps", "-1"],
            "'-1'",
            "run --help",
        ),
        (
            vec!["material-driver", "--path", "shear"],
            "[possible values: uniaxial-tension",
            "material-driver --help",
        ),
        (vec!["bogus"], "'bogus'", "try 'mpm-concrete --help'"),
        (
            vec!["run", "tiny.toml", "--resume", "--overwrite"],
            "cannot be used with",
            "run --help",
        ),
    ];
    for (args, error, help) in &usage {
        let o = run(&dir, args);
        let err = stderr(&o);
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(lines.len(), 2, "{args:?}: {err}");
        assert!(
            lines[0].starts_with("error: ") && lines[0].contains(error),
            "{err}"
        );
        assert!(lines[1].contains(help), "{err}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A 10 x 4 mm block on 1 mm cells, held at x = 0 and pulled at x = 10 under path following of the
/// elongation between the points nearest [2, 2] and [8, 2] (`tests/path_following.rs`).
const PATH_BLOCK: &str = r#"
[run]
name = "path-block"
steps = 1
[time]
dt = 1.0
quasi_static = true
[grid]
cell_size = 1.0
[[body]]
name = "block"
density = 1e-9
geometry = { include = [{ type = "rect", min = [0.0, 0.0], max = [10.0, 4.0] }] }
material = { model = "svk", youngs_modulus = 1000.0, poisson_ratio = 0.2 }
[[constraint]]
name = "held"
min = [-1.0, -1.0]
max = [0.0, 5.0]
x = "fixed"
y = "fixed"
[[constraint]]
name = "pulled"
min = [10.0, -1.0]
max = [11.0, 5.0]
x = { velocity = 1e-3 }
[path]
from = [2.0, 2.0]
to = [8.0, 2.0]
increment = 1e-3
"#;

#[test]
fn a_gauge_point_off_the_body_and_finite_elements_on_a_turned_grid_are_refused() {
    let dir = scratch("hostile", "gauge", &[("path.toml", PATH_BLOCK)]);
    // The gauge's ends may lie on the body's edge (its nearest points are half a spacing inside) ...
    succeeds(&run(
        &dir,
        &[
            "run",
            "path.toml",
            "--quiet",
            "--output",
            "edge",
            "--set",
            "path.to=[10.0,4.0]",
        ],
    ));
    // ... but not 500 mm off it: the nearest points would be measured silently. Finite elements are
    // the grid's cells and cannot be turned (a CT in contact is turned otherwise).
    let cases: Vec<(&str, Vec<&str>, Vec<&str>)> = vec![
        (
            "path.toml",
            vec!["--set", "path.to=[500.0,2.0]"],
            vec![
                "path.toml",
                "`path.to` = [500.0, 2.0] mm",
                "within one cell (grid.cell_size = 1 mm) of a material point",
                "490.250 mm away at (9.750, 1.750)",
            ],
        ),
        (
            "path.toml",
            vec!["--set", "path.from=[2.0,-3.0]"],
            vec!["`path.from` = [2.0, -3.0] mm", "a point in a body"],
        ),
        (
            "tiny.toml",
            vec![
                "--set",
                "shape.method=\"fem\"",
                "--set",
                "shape.kind=\"linear\"",
                "--set",
                "ct.load_introduction=\"contact\"",
                "--set",
                "grid.rotation=30",
            ],
            vec!["`grid.rotation` = 30", "0 with shape.method = \"fem\""],
        ),
    ];
    for (config, extra, needles) in &cases {
        let mut args = vec!["run", config, "--quiet", "--output", "out"];
        args.extend(extra);
        refused(&run(&dir, &args), needles);
        assert!(!dir.join("out").exists(), "{args:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn resume_takes_a_default_spelled_out_and_errors_cut_a_huge_set_value() {
    let dir = scratch("hostile", "echo", &[]);
    let args = ["run", "tiny.toml", "--quiet", "--output", "d"];
    succeeds(&run(&dir, &[&args[..], &["--steps", "2"]].concat()));
    // grid.rotation = 0 is the default: the same physics as the run's.
    let same = ["--steps", "4", "--resume", "--set", "grid.rotation=0"];
    succeeds(&run(&dir, &[&args[..], &same].concat()));
    assert_eq!(record(&dir.join("d")).steps_done, 4);
    let other = ["--steps", "6", "--resume", "--set", "ct.loading_rate=4000"];
    refused(
        &run(&dir, &[&args[..], &other].concat()),
        &[
            "other physics",
            "ct.loading_rate: 4300.0 in the checkpoint, 4000.0 now",
        ],
    );
    // A 100 KB value is shown by its first 80 characters and its length.
    let digits = format!("grid.cell_size={}", "1".repeat(100_000));
    let ones = vec!["1"; 30_000].join(",");
    let vector = format!("body_force=[{ones}]");
    for set in [&digits, &vector] {
        let o = run(&dir, &["run", "tiny.toml", "--output", "e", "--set", set]);
        let line = refused(&o, &[&format!("... ({} bytes)", set.len())]);
        assert!(line.len() < 600, "{} bytes: {}", line.len(), &line[..600]);
    }
    assert!(!dir.join("e").exists());
    std::fs::remove_dir_all(&dir).ok();
}
