//! Runs on several processes: the lattice problem gives the same solution under `mpirun -n 2` as in
//! serial (the residual and Jacobian assembled with global indices, entries owned by the other process
//! included), and `run` of the CT demo on 2 and 3 processes gives the serial history.

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

/// Runs the CT demo to step `steps` on `ranks` processes (1: without mpirun) into `out`, with `extra`
/// arguments (e.g. `--resume`); returns stderr.
fn ct_demo(ranks: usize, steps: usize, out: &std::path::Path, extra: &[&str]) -> String {
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/ct-demo.toml");
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
        .args(["run", config, "--quiet", "--steps", &steps.to_string()])
        .args(extra)
        .arg("--output")
        .arg(out)
        .output()
        .expect("failed to start (is Open MPI's mpirun installed? scripts/install-deps.sh)");
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{ranks} processes {extra:?}: {err}");
    err
}

/// `mpirun -n 2` and `-n 3` of the CT demo (30 steps, the damage starting) give one set of outputs and
/// the history of the serial run: every process takes the same steps on the whole model while PETSc's
/// vectors, matrix and solvers are distributed. The results are not bitwise equal: with more processes
/// block Jacobi has more, smaller ILU blocks, so GMRES stops (at its relative tolerance 1e-6) at other
/// iterates and Newton (at 1e-8) at another converged solution. Bounds: relative L2 distance of the force
/// and energy histories <= 1e-6 (measured: <= 5e-8) and total Newton iterations within 25 % of serial
/// (measured: +10 to +15 %).
#[test]
fn run_on_two_and_three_processes_matches_serial() {
    let base = std::env::temp_dir().join(format!("mpmc-mpi-ct-{}", std::process::id()));
    let steps = 30;
    ct_demo(1, steps, &base.join("serial"), &[]);
    let serial = history(&base.join("serial"));
    for ranks in [2, 3] {
        let dir = base.join(format!("ranks{ranks}"));
        let err = ct_demo(ranks, steps, &dir, &[]);
        let headers = err
            .lines()
            .filter(|l| l.contains("material points"))
            .count();
        assert_eq!(headers, 1, "one process reports: {err}");
        assert!(err.contains(&format!("{ranks} processes")), "{err}");
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
        ] {
            let (a, b) = (&serial[name], &parallel[name]);
            assert!(a.iter().any(|v| *v != 0.0), "{name} must not vanish");
            let d = rel_l2(a, b);
            assert!(
                d <= 1e-6,
                "{ranks} processes: {name} relative L2 distance {d:e}"
            );
        }
        let newton = |h: &std::collections::HashMap<String, Vec<f64>>| -> f64 {
            h["newton_its"].iter().sum()
        };
        let (ns, np) = (newton(&serial), newton(&parallel));
        assert!(
            (np - ns).abs() <= 0.25 * ns,
            "{ranks} processes: {np} Newton iterations against {ns} in serial"
        );
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
