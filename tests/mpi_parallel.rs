//! Runs on several processes: the lattice problem gives the same solution under `mpirun -n 2` as in
//! serial (the residual and Jacobian assembled with global indices, entries owned by the other process
//! included); `run` of the CT demo on 2 and 3 processes gives the serial history and restarts across
//! process counts; points that cross from one process's band to another keep their state.

use std::process::Command;

fn solution(mut cmd: Command) -> Vec<f64> {
    let out = cmd
        .output()
        .expect("failed to start (is Open MPI's mpirun installed? scripts/install-deps.sh)");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "run failed: {}\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let line = stdout
        .lines()
        .find(|l| l.starts_with('['))
        .expect("no solution printed");
    serde_json::from_str(line).expect("solution is JSON")
}

#[test]
fn two_processes_match_serial() {
    let exe = env!("CARGO_BIN_EXE_mpm-concrete");
    let args = [
        "smoke",
        "--n",
        "9",
        "--print-solution",
        "-snes_rtol",
        "1e-12",
        "-snes_atol",
        "1e-14",
    ];
    let mut serial = Command::new(exe);
    serial.args(args);
    let mut parallel = Command::new("mpirun");
    parallel
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .args(["--oversubscribe", "-n", "2", exe])
        .args(args);
    let (a, b) = (solution(serial), solution(parallel));
    assert_eq!(a.len(), b.len());
    let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = a
        .iter()
        .zip(&b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    assert!(
        scale > 1e-3 && diff <= 1e-9 * scale,
        "serial vs 2 ranks: max diff {diff:e} (scale {scale:e})"
    );
}

/// The columns of a run's history.csv by name.
fn history(dir: &std::path::Path) -> std::collections::HashMap<String, Vec<f64>> {
    let text = std::fs::read_to_string(dir.join("history.csv")).expect("history.csv");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let names: Vec<String> = lines
        .next()
        .expect("header")
        .split(',')
        .map(str::to_owned)
        .collect();
    let mut columns: std::collections::HashMap<String, Vec<f64>> = Default::default();
    for line in lines {
        for (name, v) in names.iter().zip(line.split(',')) {
            if let Ok(v) = v.parse::<f64>() {
                columns.entry(name.clone()).or_default().push(v);
            }
        }
    }
    columns
}

/// `|a - b| / |a|` in the L2 norm.
fn rel_l2(a: &[f64], b: &[f64]) -> f64 {
    let norm = a.iter().map(|v| v * v).sum::<f64>().sqrt();
    let diff = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt();
    diff / norm
}

/// Runs `config` (relative to the repository) to step `steps` on `ranks` processes (1: without mpirun)
/// into `out`, with `extra` arguments (e.g. `--resume`); returns (stdout, stderr).
fn run(
    config: &str,
    ranks: usize,
    steps: usize,
    out: &std::path::Path,
    extra: &[&str],
) -> (String, String) {
    let config = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(config);
    let exe = env!("CARGO_BIN_EXE_mpm-concrete");
    let mut cmd = if ranks == 1 {
        Command::new(exe)
    } else {
        let mut c = Command::new("mpirun");
        c.env("OMPI_ALLOW_RUN_AS_ROOT", "1")
            .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
            .args(["--oversubscribe", "-n", &ranks.to_string(), exe]);
        c
    };
    let o = cmd
        .arg("run")
        .arg(&config)
        .args(["--quiet", "--steps", &steps.to_string()])
        .args(extra)
        .arg("--output")
        .arg(out)
        .output()
        .expect("failed to start (is Open MPI's mpirun installed? scripts/install-deps.sh)");
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{ranks} processes {extra:?}: {err}");
    (String::from_utf8_lossy(&o.stdout).into_owned(), err)
}

/// The CT demo ([`run`]); returns stderr.
fn ct_demo(ranks: usize, steps: usize, out: &std::path::Path, extra: &[&str]) -> String {
    run("configs/ct-demo.toml", ranks, steps, out, extra).1
}

/// `mpirun -n 2` and `-n 3` of the CT demo (30 steps, the damage starting) give one set of outputs and
/// the history of the serial run: every process takes the same steps on the whole model while PETSc's
/// vectors, matrix and solvers are distributed. The results are not bitwise equal: with more processes
/// the ILU(0) is factored on more, overlapping subdomains, so GMRES stops (at its relative tolerance 1e-6)
/// at other iterates and Newton (at 1e-8) at another converged solution. Bounds: relative L2 distance of
/// the force and energy histories <= 1e-6 (measured: <= 5e-8); the iterations those of one process: the
/// Newton iterations within 5 % of serial (measured: equal, 64) and the Krylov iterations within 15 %
/// (measured: +7 % and +0 %; block Jacobi, one ILU per process without overlap, took 2.3x and 1.7x, and
/// 6 % and 13 % more Newton iterations).
#[test]
fn run_on_two_and_three_processes_matches_serial() {
    let base = std::env::temp_dir().join(format!("mpmc-mpi-ct-{}", std::process::id()));
    let steps = 30;
    let serial_err = ct_demo(1, steps, &base.join("serial"), &[]);
    let serial = history(&base.join("serial"));
    let serial_points = points_per_process(&serial_err)[0];
    for ranks in [2, 3] {
        let dir = base.join(format!("ranks{ranks}"));
        let err = ct_demo(ranks, steps, &dir, &[]);
        let headers = err
            .lines()
            .filter(|l| l.contains("material points"))
            .count();
        assert_eq!(headers, 1, "one process reports: {err}");
        assert!(err.contains(&format!("{ranks} processes")), "{err}");
        // Each process seeded its own band: the counts sum to the serial run's, each about 1/P of it.
        let counts = points_per_process(&err);
        assert_eq!(counts.len(), ranks, "{err}");
        let total: usize = counts.iter().sum();
        assert_eq!(total, serial_points, "{err}");
        for n in &counts {
            let share = *n as f64 / total as f64;
            assert!((share - 1.0 / ranks as f64).abs() < 0.05, "{counts:?}");
        }
        // The seeded points, written into the step-0 file, are the serial run's: every dataset with
        // the same values in the same order, bit for bit; later files hold the same datasets.
        let fields =
            |d: &std::path::Path, step: &str| datasets(&d.join(format!("fields_{step}.h5")));
        let (a, b) = (
            fields(&base.join("serial"), "000000"),
            fields(&dir, "000000"),
        );
        assert_eq!(a, b, "{ranks} processes: step-0 fields differ from serial");
        let shape = |m: std::collections::BTreeMap<String, Vec<f64>>| -> Vec<(String, usize)> {
            m.into_iter().map(|(k, v)| (k, v.len())).collect()
        };
        let (a, b) = (
            fields(&base.join("serial"), "000030"),
            fields(&dir, "000030"),
        );
        assert_eq!(shape(a), shape(b), "{ranks} processes: step-30 datasets");
        // Every process wrote its points into the shared files: their checksums, put together from the
        // processes' parts, are those of the files' contents (`crack` verifies each snapshot's against
        // its datasets and run.json before it re-measures; a resumed run verifies the checkpoint's).
        let o = Command::new(env!("CARGO_BIN_EXE_mpm-concrete"))
            .arg("crack")
            .arg(&dir)
            .output()
            .expect("crack");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{ranks} processes: {err}");
        for file in [
            "fields_000000.h5",
            "fields_000030.h5",
            "fields.xdmf",
            "checkpoint.h5",
            "run.json",
        ] {
            assert!(
                dir.join(file).is_file(),
                "{ranks} processes: {file} missing"
            );
        }
        let leftovers: Vec<_> = std::fs::read_dir(&dir)
            .expect("output")
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
            .collect();
        assert!(leftovers.is_empty(), "{leftovers:?}");
        let parallel = history(&dir);
        assert_eq!(parallel["step"].len(), steps, "{ranks} processes: steps");
        for name in [
            "loading_plate_fy",
            "kinetic_energy",
            "stored_energy",
            "external_work",
            "dissipated_energy",
            "contact_loss",
            "transfer_loss",
        ] {
            let (a, b) = (&serial[name], &parallel[name]);
            assert!(a.iter().any(|v| *v != 0.0), "{name} must not vanish");
            let d = rel_l2(a, b);
            assert!(
                d <= 1e-6,
                "{ranks} processes: {name} relative L2 distance {d:e}"
            );
        }
        // The crack front of every step (process 0 measures the cracked points of all processes).
        for name in ["crack_length", "crack_tip_x", "crack_tip_y", "crack_bands"] {
            assert_eq!(serial[name], parallel[name], "{ranks} processes: {name}");
        }
        let total =
            |h: &std::collections::HashMap<String, Vec<f64>>, c: &str| -> f64 { h[c].iter().sum() };
        for (column, bound) in [("newton_its", 0.05), ("linear_its", 0.15)] {
            let (ns, np) = (total(&serial, column), total(&parallel, column));
            assert!(
                (np - ns).abs() <= bound * ns,
                "{ranks} processes: {np} {column} against {ns} in serial"
            );
        }
    }
    // A checkpoint written by 2 processes continues on 1, one written by 1 continues on 2 (the state is
    // whole in either): both reach the same history to step 40.
    let resume = |ranks: usize, dir: &std::path::Path| {
        ct_demo(ranks, 40, dir, &["--resume"]);
        history(dir)
    };
    let (from_two, from_one) = (
        resume(1, &base.join("ranks2")),
        resume(2, &base.join("serial")),
    );
    assert_eq!(from_two["step"].len(), 40);
    assert_eq!(from_one["step"].len(), 40);
    let d = rel_l2(&from_one["loading_plate_fy"], &from_two["loading_plate_fy"]);
    assert!(d <= 1e-6, "resumed runs differ: {d:e}");
    std::fs::remove_dir_all(&base).ok();
}

/// The points each process holds after seeding, from the run line (`N material points` on one process,
/// `N (a + b + .. per process) material points` on several).
fn points_per_process(stderr: &str) -> Vec<usize> {
    let line = stderr
        .lines()
        .find(|l| l.contains("material points"))
        .unwrap_or_else(|| panic!("no run line: {stderr}"));
    let text = line.split(": ").nth(1).expect("name: ...");
    let text = text.split(" material points").next().expect("points");
    match text.split_once('(') {
        None => vec![text.trim().parse().expect("a count")],
        Some((_, each)) => each
            .trim_end_matches(" per process)")
            .split(" + ")
            .map(|n| n.trim().parse().expect("a count"))
            .collect(),
    }
}

/// Every dataset of a fields file (`fields_NNNNNN.h5`) by name, flattened (the connectivity's integers
/// as floats).
fn datasets(file: &std::path::Path) -> std::collections::BTreeMap<String, Vec<f64>> {
    let f = hdf5_metno::File::open(file).expect("fields file");
    let names = f.member_names().expect("datasets");
    assert!(names.len() > 5, "{}: {names:?}", file.display());
    names
        .into_iter()
        .map(|name| {
            let ds = f.dataset(&name).expect("dataset");
            let values = match name.as_str() {
                "connectivity" => ds
                    .read_raw::<i64>()
                    .map(|v| v.iter().map(|&i| i as f64).collect()),
                _ => ds.read_raw::<f64>(),
            };
            let values = values.unwrap_or_else(|e| panic!("{}: {name}: {e}", file.display()));
            (name, values)
        })
        .collect()
}

/// A point dataset of a fields file (`fields_NNNNNN.h5`), flattened.
fn point_field(file: &std::path::Path, name: &str) -> Vec<f64> {
    let f = hdf5_metno::File::open(file).expect("fields file");
    f.dataset(name)
        .and_then(|d| d.read_raw::<f64>())
        .unwrap_or_else(|e| panic!("{}: {name}: {e}", file.display()))
}

/// The largest `|a - b|` over the largest `|a|`.
fn rel_max(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    diff / scale
}

/// A checkpoint of the crossing block (`tests/data/mpi-crossing.toml`) written on 2 processes (each
/// seeded its own band) at step 20 resumes on 1 and on 3 processes, and both reach the uninterrupted
/// serial run's step 40 to 1e-9 in every point's position, velocity and stress and in the histories.
#[test]
fn a_checkpoint_written_on_two_processes_resumes_on_one_and_three() {
    let base = std::env::temp_dir().join(format!("mpmc-mpi-restart-{}", std::process::id()));
    let config = "tests/data/mpi-crossing.toml";
    run(config, 1, 40, &base.join("serial"), &[]);
    let (_, err) = run(config, 2, 20, &base.join("two"), &[]);
    assert_eq!(points_per_process(&err).len(), 2, "{err}");
    let last = "fields_000040.h5";
    let serial = history(&base.join("serial"));
    for ranks in [1, 3] {
        let dir = base.join(format!("two-then-{ranks}"));
        std::fs::create_dir_all(&dir).expect("copy");
        for entry in std::fs::read_dir(base.join("two")).expect("run directory") {
            let entry = entry.expect("entry");
            if entry.file_type().expect("type").is_file() {
                std::fs::copy(entry.path(), dir.join(entry.file_name())).expect("copy");
            }
        }
        run(config, ranks, 40, &dir, &["--resume"]);
        let resumed = history(&dir);
        assert_eq!(resumed["step"].len(), 40, "2 -> {ranks} processes: steps");
        for name in ["wall_fy", "kinetic_energy", "stored_energy"] {
            let d = rel_l2(&serial[name], &resumed[name]);
            assert!(d <= 1e-9, "2 -> {ranks} processes: {name} differs by {d:e}");
        }
        for name in ["position", "velocity", "sigma_yy", "sigma_xy"] {
            let a = point_field(&base.join("serial").join(last), name);
            let b = point_field(&dir.join(last), name);
            let d = rel_max(&a, &b);
            assert!(d <= 1e-9, "2 -> {ranks} processes: {name} differs by {d:e}");
        }
    }
    std::fs::remove_dir_all(&base).ok();
}

/// A block flying into a wall (`tests/data/mpi-crossing.toml`) on 2 and 3 processes: its points cross
/// the processes' bands (the run reports how many moved) and every point ends, in the files each
/// process writes its points into in the serial order, where the serial run puts it, with its velocity and stress: a point
/// that lost part of its state on the way (its deformation gradient, its domain, its history) or a
/// process missing a ghost (an incomplete row) would be off by far more than the bounds. The solver is
/// MUMPS LU with tight Newton tolerances, so the runs differ by round-off in the factorisation and in
/// the sums over processes (measured: <= 3e-13 relative, 200 and 400 points moved on 2 and 3
/// processes); bounds 1e-9.
#[test]
fn points_crossing_between_processes_keep_their_state() {
    let base = std::env::temp_dir().join(format!("mpmc-mpi-crossing-{}", std::process::id()));
    let config = "tests/data/mpi-crossing.toml";
    let steps = 40;
    run(config, 1, steps, &base.join("serial"), &[]);
    let serial = history(&base.join("serial"));
    let kinetic = &serial["kinetic_energy"];
    let least = kinetic.iter().fold(f64::INFINITY, |m, &k| m.min(k));
    assert!(
        least < 0.2 * kinetic[0],
        "the block must hit the wall: kinetic energy {} down to {least} only",
        kinetic[0]
    );
    // Before the impact (step 14) the block flies free: the balance W + E_0 - K - Psi, with the kinetic
    // energy E_0 it started with, dissipates nothing.
    let flying = serial["dissipated_energy"][..12]
        .iter()
        .fold(0.0f64, |m, d| m.max(d.abs()));
    assert!(
        flying <= 1e-9 * kinetic[0],
        "free flight dissipated {flying} of {}",
        kinetic[0]
    );
    let last = format!("fields_{steps:06}.h5");
    for ranks in [2, 3] {
        let dir = base.join(format!("ranks{ranks}"));
        let (stdout, _) = run(config, ranks, steps, &dir, &[]);
        let moved: usize = stdout
            .lines()
            .find(|l| l.contains("points between processes"))
            .and_then(|l| l.split('|').nth(2))
            .and_then(|c| c.split_whitespace().next())
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("{ranks} processes: no count of moved points in\n{stdout}"));
        assert!(moved >= 40, "{ranks} processes: only {moved} points moved");
        let parallel = history(&dir);
        // (The held wall does no work: external_work stays 0.)
        for name in ["wall_fy", "kinetic_energy", "stored_energy"] {
            let d = rel_l2(&serial[name], &parallel[name]);
            assert!(
                d <= 1e-9,
                "{ranks} processes: {name} relative L2 distance {d:e}"
            );
        }
        for name in ["position", "velocity", "sigma_yy", "sigma_xy"] {
            let (a, b) = (
                point_field(&base.join("serial").join(&last), name),
                point_field(&dir.join(&last), name),
            );
            let d = rel_max(&a, &b);
            assert!(
                d <= 1e-9,
                "{ranks} processes: point field {name} differs by {d:e}"
            );
        }
    }
    std::fs::remove_dir_all(&base).ok();
}

/// A point leaving the grid is met only by the processes holding it: all processes stop after the same
/// step (no process left waiting in a collective call), the one holding it names the point by its
/// number in the whole set (as the serial run does), and the last converged state is saved once.
#[test]
fn a_point_failing_on_one_process_stops_every_process() {
    let base = std::env::temp_dir().join(format!("mpmc-mpi-leave-{}", std::process::id()));
    std::fs::create_dir_all(&base).expect("temp dir");
    let crossing = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mpi-crossing.toml"),
    )
    .expect("config");
    // No wall, 0.8 mm per step, one cell of margin: the top row leaves the grid at step 3.
    let free = &crossing[..crossing.find("[[constraint]]").expect("the wall")];
    let config = free
        .replace("margin_cells = 3", "margin_cells = 1")
        .replace("[0.0, 4.0e4]", "[0.0, 4.0e5]");
    let path = base.join("leave.toml");
    std::fs::write(&path, config).expect("write config");
    let exe = env!("CARGO_BIN_EXE_mpm-concrete");
    let out = Command::new("timeout")
        .args(["120", "mpirun", "--oversubscribe", "-n", "2", exe, "run"])
        .arg(&path)
        .arg("--quiet")
        .arg("--output")
        .arg(base.join("run"))
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .output()
        .expect("failed to start timeout/mpirun");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_ne!(out.status.code(), Some(124), "the processes hung:\n{err}");
    assert!(!out.status.success(), "the run must fail:\n{err}");
    assert!(
        err.contains("material point 3120") && err.contains("outside the grid"),
        "the holding process names the point as the serial run does:\n{err}"
    );
    assert!(
        err.contains("another process failed"),
        "the other process says why it stopped:\n{err}"
    );
    let run = base.join("run");
    assert!(run.join("checkpoint.h5").is_file() && run.join("fields_000002.h5").is_file());
    std::fs::remove_dir_all(&base).ok();
}

/// The 3D CT demo (`configs/ct-3d-demo.toml`, an 8 mm plate, 39,120 points) on 2 processes: the serial
/// history within the solvers' tolerance, and the plate cut across its height, not its thickness: each
/// process receives copies of the points within a few cells of its band's edge only (a cut across the
/// 2 cells of thickness would copy every point to the other process).
#[test]
fn a_plate_is_cut_across_its_height_and_matches_serial() {
    let base = std::env::temp_dir().join(format!("mpmc-mpi-plate-{}", std::process::id()));
    let config = "configs/ct-3d-demo.toml";
    let steps = 4;
    run(config, 1, steps, &base.join("serial"), &[]);
    let (stdout, err) = run(config, 2, steps, &base.join("ranks2"), &[]);
    assert!(err.contains("a 8 mm plate (3D)"), "{err}");
    let ghosts: f64 = stdout
        .lines()
        .find(|l| l.contains("ghost copies per step"))
        .and_then(|l| l.split(';').nth(1))
        .and_then(|c| c.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no ghost count in\n{stdout}"));
    assert!(
        ghosts > 0.0 && ghosts < 0.25 * 39_120.0,
        "{ghosts} ghost copies per step of 39,120 points"
    );
    let (serial, parallel) = (history(&base.join("serial")), history(&base.join("ranks2")));
    for name in ["loading_plate_fy", "kinetic_energy", "stored_energy"] {
        let (a, b) = (&serial[name], &parallel[name]);
        assert!(a.iter().any(|v| *v != 0.0), "{name} must not vanish");
        let d = rel_l2(a, b);
        assert!(d <= 1e-6, "2 processes: {name} relative L2 distance {d:e}");
    }
    std::fs::remove_dir_all(&base).ok();
}

/// The nodal sums (P2G, the `eta_bar` projection) travel between neighbouring processes only, on the
/// rows their points reach: widening the empty margin of the CT demo's grid from 3 to 20 cells (5,032
/// more nodes, no more points) adds next to nothing to the bytes a process sends per step, where a sum
/// over the whole grid would add the margin's nodal values (6 per node, 241 kB per step) to every
/// process.
#[test]
fn nodal_sums_do_not_grow_with_the_grid() {
    let dir = std::env::temp_dir().join(format!("mpm-bytes-{}", std::process::id()));
    let last_step_bytes = |margin: usize| {
        let out = dir.join(format!("m{margin}"));
        let set = format!("grid.margin_cells={margin}");
        ct_demo(2, 3, &out, &["--set", &set]);
        let h = history(&out);
        let sent = h
            .get("bytes_sent")
            .expect("a bytes_sent column on 2 processes");
        // The last step (the first also carries the initial acceleration's sums).
        *sent.last().expect("3 steps")
    };
    let (small, wide) = (last_step_bytes(3), last_step_bytes(20));
    let _ = std::fs::remove_dir_all(&dir);
    let nodes = |cells: usize| ((cells + 1) * (cells + 1)) as f64;
    // The demo's specimen spans 50 cells of 4 mm: 56 cells with 3 on each side, 90 with 20.
    let margin_sums = (nodes(90) - nodes(56)) * 6.0 * 8.0;
    assert!(
        wide - small < 0.25 * margin_sums,
        "bytes per step {small} with a 3-cell margin, {wide} with 20: the margin's {margin_sums} B \
         of nodal sums travel"
    );
}

/// The geometric multigrid (`-pc_type mg`) on the coupled (u, eta_bar) system of the CT demo on 1 and 2
/// processes (each process holds its own rows of every level's interpolation, the coarse nodes in the
/// bands of its fine nodes) and on the 3D plate: the histories of the default solver within the solvers'
/// tolerance.
#[test]
fn multigrid_on_the_coupled_system_in_2d_and_3d_and_on_two_processes_matches_the_default() {
    let base = std::env::temp_dir().join(format!("mpmc-mpi-mg-{}", std::process::id()));
    let mg = ["--set", "run.petsc_options=\"-pc_type mg\""];
    let cases = [
        ("configs/ct-demo.toml", 4, "loading_plate_fy", 2),
        ("configs/ct-3d-demo.toml", 2, "loading_plate_fy", 1),
    ];
    for (k, (config, steps, column, ranks)) in cases.into_iter().enumerate() {
        let reference = base.join(format!("default{k}"));
        run(config, 1, steps, &reference, &[]);
        let reference = history(&reference);
        for p in 1..=ranks {
            let dir = base.join(format!("mg{k}-{p}"));
            run(config, p, steps, &dir, &mg);
            let h = history(&dir);
            for name in [column, "kinetic_energy", "stored_energy"] {
                let (a, b) = (&reference[name], &h[name]);
                assert!(a.iter().any(|v| *v != 0.0), "{name} must not vanish");
                let d = rel_l2(a, b);
                assert!(
                    d <= 1e-6,
                    "{config} with MG on {p} processes: {name} off by {d:e}"
                );
            }
        }
    }
    std::fs::remove_dir_all(&base).ok();
}

/// `run --processes 2` starts the program on two processes itself: the same run as `mpirun -n 2`, bit for
/// bit (the same decomposition and the same solvers), and a launcher that started another number of
/// processes than `--processes` asks for is refused before any work (exit code 2).
#[test]
fn processes_flag_starts_the_launcher_itself() {
    let base = std::env::temp_dir().join(format!("mpmc-mpi-flag-{}", std::process::id()));
    let steps = 5;
    ct_demo(2, steps, &base.join("mpirun"), &[]);
    let err = ct_demo(1, steps, &base.join("flag"), &["--processes", "2"]);
    assert!(err.contains("2 processes"), "{err}");
    let (a, b) = (history(&base.join("mpirun")), history(&base.join("flag")));
    for name in [
        "loading_plate_fy",
        "kinetic_energy",
        "newton_its",
        "linear_its",
    ] {
        assert_eq!(a[name], b[name], "{name}");
    }
    let config = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/ct-demo.toml");
    let o = Command::new(env!("CARGO_BIN_EXE_mpm-concrete"))
        .env("OMPI_COMM_WORLD_SIZE", "3")
        .arg("run")
        .arg(&config)
        .args(["--processes", "2", "--output"])
        .arg(base.join("refused"))
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("the launcher started 3 processes"), "{err}");
    assert!(!base.join("refused").exists());
    std::fs::remove_dir_all(&base).ok();
}

/// A load across the processes' bands (the cantilever's tip load over its whole height, cut in two by
/// the bands of 2 processes): its displacement and the external work it does are the serial run's. Each
/// process reads after a solve only the unknowns its points reach and those every process evaluates, so
/// a load's nodes must be among the latter (before they were, the load's mean displacement on 2
/// processes was 0.81 of serial).
#[test]
fn a_load_across_the_bands_moves_as_in_serial() {
    let base = std::env::temp_dir().join(format!("mpmc-mpi-load-{}", std::process::id()));
    let config = "configs/crosscheck-cantilever.toml";
    run(config, 1, 1, &base.join("serial"), &[]);
    let (_, err) = run(config, 2, 1, &base.join("two"), &[]);
    assert_eq!(points_per_process(&err).len(), 2, "{err}");
    let (serial, two) = (history(&base.join("serial")), history(&base.join("two")));
    for name in ["tip_uy", "external_work"] {
        let (a, b) = (serial[name][0], two[name][0]);
        assert!(a.abs() > 1e-3, "{name} = {a} must not vanish");
        assert!(
            (a - b).abs() <= 1e-9 * a.abs(),
            "{name}: {b} on 2 processes against {a} in serial"
        );
    }
    std::fs::remove_dir_all(&base).ok();
}

/// A plain `run` of stiffness-dominated steps (the elastic cantilever at 40,960 points, PETSc's
/// multigrid) starts itself on a process per core, at least 10,000 points each; `--processes 1`,
/// `RAYON_NUM_THREADS` and a `-pc_type` of the user's keep one process with threads, and so does a run
/// of inertia-dominated steps.
#[test]
fn a_plain_run_of_stiffness_dominated_steps_starts_a_process_per_core() {
    let exe = env!("CARGO_BIN_EXE_mpm-concrete");
    let base = std::env::temp_dir().join(format!("mpmc-mpi-auto-{}", std::process::id()));
    let root = env!("CARGO_MANIFEST_DIR");
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let processes_of = |name: &str, config: &str, extra: &[&str], threads: Option<&str>| -> usize {
        let dir = base.join(name);
        let mut cmd = Command::new(exe);
        cmd.args([
            "run",
            &format!("{root}/{config}"),
            "--steps",
            "1",
            "--quiet",
        ])
        .arg("--output")
        .arg(&dir)
        .arg("--overwrite")
        .args(extra);
        if let Some(n) = threads {
            cmd.env("RAYON_NUM_THREADS", n);
        }
        let out = cmd.output().expect("run");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{config} {extra:?} failed:\n{stderr}");
        let header = stderr
            .lines()
            .find(|l| l.contains("material points"))
            .unwrap_or_else(|| panic!("no header line in:\n{stderr}"));
        header
            .split(", ")
            .find_map(|w| w.strip_suffix(" processes")?.parse().ok())
            .unwrap_or(1)
    };
    let cantilever = "configs/bench/cantilever-41k.toml";
    assert_eq!(processes_of("plain", cantilever, &[], None), cores.min(4));
    let one = ["--processes", "1"];
    assert_eq!(processes_of("one", cantilever, &one, None), 1);
    assert_eq!(processes_of("threads", cantilever, &[], Some("2")), 1);
    // The user chose the preconditioner: one process.
    let lu = ["-pc_type", "lu"];
    assert_eq!(processes_of("chosen", cantilever, &lu, None), 1);
    // The CT demo at 4.3 m/s: inertia-dominated, threads.
    assert_eq!(processes_of("ct", "configs/ct-demo.toml", &[], None), 1);
    std::fs::remove_dir_all(&base).ok();
}
