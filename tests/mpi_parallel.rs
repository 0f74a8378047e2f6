//! The lattice problem gives the same solution under `mpirun -n 2` as in serial: the residual and
//! Jacobian are assembled with global indices, entries owned by the other process included.

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

/// `run` is serial until the distributed core lands: under `mpirun -n 2` it refuses with one message (from
/// rank 0) and writes nothing, instead of two processes racing on the same output files.
#[test]
fn run_refuses_more_than_one_process() {
    let dir = std::env::temp_dir().join(format!("mpmc-mpi-run-{}", std::process::id()));
    let out = dir.join("out");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/ct-demo.toml");
    let o = Command::new("mpirun")
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .args([
            "--oversubscribe",
            "-n",
            "2",
            env!("CARGO_BIN_EXE_mpm-concrete"),
        ])
        .args(["run", config, "--steps", "1", "--output"])
        .arg(&out)
        .output()
        .expect("failed to start mpirun");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    let refusals = err
        .lines()
        .filter(|l| l.starts_with("error: `run` works on one process, not 2"))
        .count();
    assert_eq!(refusals, 1, "{err}");
    assert!(!out.exists(), "nothing may be written");
    std::fs::remove_dir_all(&dir).ok();
}
