//! A run's output directory belongs to one run. The run's identity (a fingerprint of its effective
//! configuration, the program version and the PETSc options) is written to `run.json` when the run starts
//! and into every checkpoint; a new run refuses a directory that holds another run's results unless told
//! to overwrite them (which removes only the files the program writes) or to resume. A run holds an
//! advisory lock ([`lock`], `flock` on the directory) for its life, so a second run into the same
//! directory is refused while the first is running, also with `--overwrite` or `--resume`.

use crate::input::InputProblem;
use crate::output_file::{OutputError, write_atomic};
use crate::schema::file;
use std::collections::BTreeMap;
use std::path::Path;

/// The run record in the output directory.
pub const RUN_FILE: &str = file::RUN;

/// Whether `name` is a file the program writes into a run directory: `run.json`, `config.toml`,
/// `history.csv`, `fields.xdmf`, `fields_NNNNNN.h5`, `damage_NNNNNN.png`, `force_time.png`,
/// `force_displacement.png`, `crack.json`, `checkpoint.h5` (see `io` and `checkpoint`),
/// or the temporary copy of one of them that an interrupted write leaves behind ([`is_temporary`]).
pub fn is_program_file(name: &str) -> bool {
    is_result_file(name) || is_temporary(name)
}

/// Whether `name` is one of the files of [`is_program_file`] other than a temporary.
fn is_result_file(name: &str) -> bool {
    let numbered = |prefix: &str, suffix: &str| {
        name.strip_prefix(prefix)
            .and_then(|r| r.strip_suffix(suffix))
            .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
    };
    [
        file::RUN,
        file::CONFIG,
        file::HISTORY,
        file::FIELDS_INDEX,
        file::FORCE_TIME,
        file::FORCE_DISPLACEMENT,
        file::CRACK,
        file::CRACK_LENGTH,
        file::BAND_WIDTH,
        file::CRACK_SPEED,
        file::CHECKPOINT,
    ]
    .contains(&name)
        || numbered(file::FIELDS.0, file::FIELDS.1)
        || numbered(file::DAMAGE_MAP.0, file::DAMAGE_MAP.1)
}

/// Whether `name` is the temporary copy of a program file that a write in progress (or one interrupted by
/// a kill or a full disk) leaves: `NAME.tmp` (files written through [`write_atomic`]) or
/// `.STEM.tmp-PID.png` (the plots, [`crate::plot`]), or a file of the fallback solver's out-of-core factors
/// that a killed run leaves, `mumps_RANK_XXXXXX` (`solver_defaults::out_of_core_directory`).
pub fn is_temporary(name: &str) -> bool {
    if let Some(base) = name.strip_suffix(".tmp") {
        return is_result_file(base);
    }
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    let factors = name
        .strip_prefix("mumps_")
        .and_then(|r| r.split_once('_'))
        .is_some_and(|(rank, tag)| {
            digits(rank) && tag.len() == 6 && tag.bytes().all(|b| b.is_ascii_alphanumeric())
        });
    if factors {
        return true;
    }
    let plot = name
        .strip_prefix('.')
        .and_then(|n| n.strip_suffix(".png"))
        .and_then(|n| n.rsplit_once(".tmp-"));
    plot.is_some_and(|(stem, pid)| {
        !pid.is_empty()
            && pid.bytes().all(|b| b.is_ascii_digit())
            && is_result_file(&format!("{stem}.png"))
    })
}

/// Removes the temporaries ([`is_temporary`]) from `dir`, which this process holds the lock of (so no
/// other run is writing them); returns how many.
pub fn remove_temporaries(dir: &Path) -> Result<usize, String> {
    remove_matching(dir, is_temporary)
}

/// The process that holds a run directory ([`lock`]), as run.json names it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Holder {
    /// Process id (of process 0 under an MPI launcher).
    pub pid: u32,
    /// Host name.
    pub host: String,
}

impl Holder {
    /// This process.
    pub fn this_process() -> Self {
        let host = nix::unistd::gethostname()
            .ok()
            .map(|h| h.to_string_lossy().into_owned())
            .filter(|h| !h.is_empty())
            .unwrap_or_else(|| "an unknown host".into());
        Self {
            pid: std::process::id(),
            host,
        }
    }
}

/// The advisory lock of a run directory, held until dropped; the system releases it when the process
/// ends in any way (also by kill -9), so a lock is never stale.
#[derive(Debug)]
pub struct DirLock {
    _lock: nix::fcntl::Flock<std::fs::File>,
}

/// Takes the lock of the existing directory `dir` without waiting (`flock` on the directory itself, so
/// that a refused run writes nothing); the error names the run that holds it.
pub fn lock(dir: &Path) -> Result<DirLock, String> {
    let file = std::fs::File::open(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    match nix::fcntl::Flock::lock(file, nix::fcntl::FlockArg::LockExclusiveNonblock) {
        Ok(lock) => Ok(DirLock { _lock: lock }),
        Err((_, nix::errno::Errno::EWOULDBLOCK)) => Err(format!(
            "{}: another run is writing into this directory ({}): wait until it has ended, or give \
             another --output",
            dir.display(),
            holder_of(dir)
        )),
        Err((_, e)) => Err(format!("{}: cannot lock the directory: {e}", dir.display())),
    }
}

/// The run that holds `dir`, as its run.json says.
fn holder_of(dir: &Path) -> String {
    let record: Option<RunRecord> = crate::input::read_text_input(&dir.join(RUN_FILE))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok());
    match record {
        Some(RunRecord {
            holder: Some(h),
            status,
            config_file,
            steps_done,
            steps_requested,
            ..
        }) if status == "running" => format!(
            "process {} on {}, config {config_file}, at step {steps_done} of {steps_requested}",
            h.pid, h.host
        ),
        _ => "a run that is starting and has not written its run.json yet".into(),
    }
}

/// What a directory holds of a run.
#[derive(Debug, Default)]
pub struct Contents {
    /// Program files other than `config.toml` (a lone copy of a configuration is no result), sorted.
    pub results: Vec<String>,
    /// The run record, if present and readable.
    pub record: Option<RunRecord>,
}

/// Lists the program's files in `dir` (empty when `dir` does not exist).
pub fn inspect(dir: &Path) -> Result<Contents, String> {
    if !dir.exists() {
        return Ok(Contents::default());
    }
    if !dir.is_dir() {
        return Err(format!(
            "{}: exists and is not a directory (give another --output)",
            dir.display()
        ));
    }
    let mut results = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))? {
        let entry = entry.map_err(|e| format!("{}: {e}", dir.display()))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if is_program_file(&name) && name != file::CONFIG && entry.path().is_file() {
            results.push(name);
        }
    }
    results.sort();
    // A run.json that is no regular file below the limit of inputs (a FIFO, a device) is refused, not
    // read; one that is absent or no run record leaves the record unknown.
    let record = match crate::input::read_text_input(&dir.join(RUN_FILE)) {
        Ok(text) => serde_json::from_str(&text).ok(),
        Err(e)
            if matches!(
                e.problem,
                InputProblem::Missing | InputProblem::Unreadable(_)
            ) =>
        {
            None
        }
        Err(e) => return Err(e.to_string()),
    };
    Ok(Contents { results, record })
}

/// Removes the program's files from `dir` (nothing else); returns how many.
pub fn remove_program_files(dir: &Path) -> Result<usize, String> {
    remove_matching(dir, is_program_file)
}

/// Removes the files of `dir` whose names `remove` accepts; returns how many.
fn remove_matching(dir: &Path, remove: fn(&str) -> bool) -> Result<usize, String> {
    if !dir.is_dir() {
        return Ok(0);
    }
    let mut removed = 0;
    for entry in std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))? {
        let path = entry.map_err(|e| format!("{}: {e}", dir.display()))?.path();
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
        if name.is_some_and(|n| remove(&n)) && path.is_file() {
            std::fs::remove_file(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// The program version: the crate version and, when the program was built from a git checkout, `git
/// describe` of that checkout (e.g. `0.1.0 (fd683b6-dirty)`).
pub fn version() -> String {
    match option_env!("MPMC_GIT_DESCRIBE") {
        Some(d) if !d.is_empty() => format!("{} ({d})", env!("CARGO_PKG_VERSION")),
        _ => env!("CARGO_PKG_VERSION").to_owned(),
    }
}

/// CRC-32 of `bytes` as 8 hex digits.
pub fn fingerprint(bytes: &[u8]) -> String {
    format!("{:08x}", crc32fast::hash(bytes))
}

/// The identity of a run.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunIdentity {
    /// Fingerprint of the version, the configuration and the PETSc options.
    pub id: String,
    /// Fingerprint of the physics: the configuration without its `[run]` section (run control).
    pub physics: String,
    /// Program version ([`version`]).
    pub version: String,
    /// The effective configuration (the file with the command line's overrides) in canonical TOML.
    pub config: String,
    /// The PETSc options: the configuration's `run.petsc_options`, then the command line's.
    pub petsc_options: String,
}

impl RunIdentity {
    /// The identity of a run of the effective configuration `config` (canonical TOML, see
    /// [`crate::config::RunConfig::load`]) with `petsc_options`, by this program.
    pub fn new(config: &str, petsc_options: &str) -> Self {
        let version = version();
        let physics = fingerprint(
            toml::to_string(&physics_table(config))
                .unwrap_or_default()
                .as_bytes(),
        );
        let id = fingerprint(format!("{version}\n{config}\n{petsc_options}").as_bytes());
        Self {
            id,
            physics,
            version,
            config: config.to_owned(),
            petsc_options: petsc_options.to_owned(),
        }
    }

    /// The physics settings that differ between `self` (e.g. a checkpoint's) and `now`, one entry per key:
    /// `ct.loading_rate: 4300.0 in the checkpoint, 35.0 now`.
    pub fn physics_changes(&self, now: &RunIdentity) -> Vec<String> {
        let (mut a, mut b) = (BTreeMap::new(), BTreeMap::new());
        flatten("", &toml::Value::Table(physics_table(&self.config)), &mut a);
        flatten("", &toml::Value::Table(physics_table(&now.config)), &mut b);
        let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
        // A default spelled out on one side only (`--set grid.rotation=0`) changes nothing.
        let spelled_out = |k: &str| match (a.contains_key(k), b.contains_key(k)) {
            (true, false) => crate::config::holds_default(&self.config, k),
            (false, true) => crate::config::holds_default(&now.config, k),
            _ => false,
        };
        keys.into_iter()
            .filter(|k| a.get(*k) != b.get(*k) && !spelled_out(k))
            .map(|k| {
                let show = |v: Option<&String>| v.cloned().unwrap_or_else(|| "absent".into());
                format!(
                    "{k}: {} in the checkpoint, {} now",
                    show(a.get(k)),
                    show(b.get(k))
                )
            })
            .collect()
    }
}

/// The configuration without its `[run]` section, integers as floats (so `4` and `4.0` are the same).
fn physics_table(config: &str) -> toml::Table {
    fn floats(v: toml::Value) -> toml::Value {
        match v {
            toml::Value::Integer(i) => toml::Value::Float(i as f64),
            toml::Value::Array(a) => toml::Value::Array(a.into_iter().map(floats).collect()),
            toml::Value::Table(t) => {
                toml::Value::Table(t.into_iter().map(|(k, v)| (k, floats(v))).collect())
            }
            other => other,
        }
    }
    let mut table: toml::Table = toml::from_str(config).unwrap_or_default();
    table.remove("run");
    match floats(toml::Value::Table(table)) {
        toml::Value::Table(t) => t,
        _ => toml::Table::new(),
    }
}

/// Leaves of a TOML value under dotted keys (`body[0].density`); arrays of plain values are leaves.
fn flatten(prefix: &str, v: &toml::Value, out: &mut BTreeMap<String, String>) {
    let join = |k: &str| {
        if prefix.is_empty() {
            k.to_owned()
        } else {
            format!("{prefix}.{k}")
        }
    };
    match v {
        toml::Value::Table(t) => {
            for (k, v) in t {
                flatten(&join(k), v, out);
            }
        }
        toml::Value::Array(a) if a.iter().any(|e| e.is_table()) => {
            for (i, e) in a.iter().enumerate() {
                flatten(&format!("{prefix}[{i}]"), e, out);
            }
        }
        leaf => {
            out.insert(prefix.to_owned(), show(leaf));
        }
    }
}

/// A TOML value as written in a message: floats in Rust's shortest form (`2.4e-9`, not `0.0000000024`).
fn show(v: &toml::Value) -> String {
    match v {
        toml::Value::Float(f) => format!("{f:?}"),
        toml::Value::Array(a) => format!("[{}]", a.iter().map(show).collect::<Vec<_>>().join(", ")),
        other => other.to_string(),
    }
}

/// `run.json`: who wrote the directory, with what, and how far the run got.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunRecord {
    /// The run's identity.
    pub identity: RunIdentity,
    /// The command line of the latest start or resumption.
    pub command: String,
    /// Configuration file as given.
    pub config_file: String,
    /// `--set` overrides (and `--steps` as `run.steps=N`).
    pub overrides: Vec<String>,
    /// Start of the latest invocation (seconds since 1970).
    pub started_unix: u64,
    /// Step of the checkpoint the latest invocation resumed from.
    pub resumed_from_step: Option<usize>,
    /// `running`, `finished`, `interrupted` or `failed`.
    pub status: String,
    /// Steps completed (while running: at the last checkpoint).
    pub steps_done: usize,
    /// Steps requested.
    pub steps_requested: usize,
    /// Time reached (s).
    pub time_reached: f64,
    /// Requested end time: steps x nominal dt (s).
    pub time_requested: f64,
    /// Steps that took less than the nominal dt (time-step halving).
    pub reduced_steps: usize,
    /// What happened, in a sentence (why a run stopped; that it ended before its end time).
    pub note: Option<String>,
    /// The process that holds the directory while the run is running ([`lock`]).
    #[serde(default)]
    pub holder: Option<Holder>,
    /// The snapshots `fields_NNNNNN.h5` written so far, as written; absent in the records of runs written
    /// before snapshots carried their identity (whose snapshots are read unverified).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub snapshots: Option<Vec<SnapshotRecord>>,
}

/// A snapshot as it was written, in run.json and (run id, step, checksum) in the file's attributes.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SnapshotRecord {
    /// File name in the run directory.
    pub file: String,
    /// Step of the snapshot.
    pub step: usize,
    /// The [`RunIdentity::id`] of the run that wrote it (absent: written by an earlier version of the
    /// program, before a resumption).
    pub run: Option<String>,
    /// CRC-32 of its point fields as written (see `io::fields_checksum`; absent as `run`).
    pub checksum: Option<String>,
}

impl RunRecord {
    /// Writes `dir/run.json`.
    pub fn write(&self, dir: &Path) -> Result<(), OutputError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| OutputError::Io {
            path: dir.join(RUN_FILE).display().to_string(),
            source: std::io::Error::other(e),
        })?;
        write_atomic(&dir.join(RUN_FILE), text.as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::{RunIdentity, is_program_file};

    #[test]
    fn program_files_are_recognised_and_nothing_else() {
        for name in [
            "run.json",
            "config.toml",
            "history.csv",
            "fields.xdmf",
            "fields_000050.h5",
            "fields_000050.h5.tmp",
            "damage_000000.png",
            "force_time.png",
            "force_displacement.png",
            "crack.json",
            "checkpoint.h5",
            "checkpoint.h5.tmp",
            ".crack_length.tmp-4711.png",
            ".damage_000002.tmp-12.png",
            "mumps_0_IjXPaZ",
            "mumps_12_a1B2c3",
        ] {
            assert!(is_program_file(name), "{name}");
        }
        for name in [
            "notes.txt",
            "fields_.h5",
            "fields_12a.h5",
            "damage_1.jpg",
            "my_config.toml",
            "log_view.txt",
            "history.csv.bak",
            ".notes.tmp-12.png",
            "notes.tmp",
            ".crack_length.tmp-.png",
            "mumps_0_IjXPa",
            "mumps__IjXPaZ",
            "mumps_0_IjX.aZ",
            "mumps_notes.txt",
        ] {
            assert!(!is_program_file(name), "{name}");
        }
    }

    #[test]
    fn physics_changes_name_the_keys_and_ignore_run_control() {
        let a = RunIdentity::new(
            "[run]\nname = \"a\"\nsteps = 20\n[ct]\nloading_rate = 4300.0\nload_zone = [0.0, 30.0]\n\
             [[body]]\ndensity = 2.4e-9\n",
            "",
        );
        let same = RunIdentity::new(
            "[run]\nname = \"b\"\nsteps = 40\n[ct]\nloading_rate = 4300\nload_zone = [0, 30]\n\
             [[body]]\ndensity = 2.4e-9\n",
            "-snes_monitor",
        );
        assert_eq!(a.physics, same.physics);
        assert_ne!(a.id, same.id);
        assert!(a.physics_changes(&same).is_empty());
        let other = RunIdentity::new(
            "[run]\nname = \"a\"\nsteps = 20\n[ct]\nloading_rate = 35.0\nload_zone = [0.0, 30.0]\n\
             symmetric = true\n[[body]]\ndensity = 2.5e-9\n",
            "",
        );
        assert_ne!(a.physics, other.physics);
        assert_eq!(
            a.physics_changes(&other),
            [
                "body[0].density: 2.4e-9 in the checkpoint, 2.5e-9 now",
                "ct.loading_rate: 4300.0 in the checkpoint, 35.0 now",
                "ct.symmetric: absent in the checkpoint, true now",
            ]
        );
    }
}
