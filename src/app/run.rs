//! `run`: a simulation described by a configuration file, from the checks of its input to the final
//! table. Everything that can be checked is checked before anything is written (`prepare`, then the
//! first step, which validates the PETSc set-up); then the output directory belongs to the run, which
//! records every step, writes the point fields and a checkpoint at the output cadence, on Ctrl-C and when a
//! step fails for good, and keeps run.json up to date.
//!
//! On several processes every one holds the whole model and its own share of the points (from the first
//! step on), the unknowns and PETSc's solvers are distributed (docs/theory.md, "Processes"); every
//! process writes its points into the snapshots' and checkpoints' HDF5 files, process 0 the rest.

mod resume;
mod steps;
mod summary;

use super::args::launcher_rank;
use super::{bad, launch, processes_per_node, share_cores};
use crate::checkpoint;
use crate::config::{self, ConfigError, RunConfig};
use crate::io::RunOutput;
use crate::model::{ModelError, Setup, State};
use crate::petsc::{self, Session, SessionGuard};
use crate::preflight;
use crate::rundir::{self, DirLock, Holder, RunIdentity, RunRecord};
use crate::scenario::{self, Plan, RunSetup};
use crate::schema::file;
use crate::solver::{Interrupt, Simulation, StepError, StepReport};
use crate::solver_defaults::{self, FALLBACK_PREFIX, StepClass};
use anyhow::{Context, Result};
use indicatif::ProgressBar;
use resume::{check_resume, command_line, refusal, resume_command};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use steps::{Records, Steps, agreed};
use summary::summary;

/// PETSc error codes that mean the options asked for something impossible (wrong argument, out of
/// range, unsupported, incompatible, unknown type).
const PETSC_INPUT_ERRORS: [i32; 5] = [56, 62, 63, 75, 86];

/// The arguments of `run`.
#[derive(clap::Args)]
pub struct RunFlags {
    /// Configuration file.
    pub config: PathBuf,
    /// Override `run.steps`.
    #[arg(long)]
    pub steps: Option<usize>,
    /// Override the output directory.
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// No progress bar (log lines instead).
    #[arg(long)]
    pub quiet: bool,
    /// Continue from the checkpoint in the output directory (written at every output step, on Ctrl-C
    /// and when a step fails for good). Only the `[run]` section (steps, output cadence, PETSc options)
    /// may differ from the checkpointed run.
    #[arg(long, conflicts_with = "overwrite")]
    pub resume: bool,
    /// Replace the results of another run in the output directory (removes the files the program
    /// writes there, nothing else) instead of refusing to start.
    #[arg(long)]
    pub overwrite: bool,
    /// Start even if the estimated memory need exceeds the memory available.
    #[arg(long)]
    pub allow_large: bool,
    /// Override a config value, `key=value` with a dotted key and a TOML value (repeatable), e.g.
    /// `--set shape.method=fem --set shape.kind=linear --set grid.cell_size=2.5`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Run on N processes: the program starts itself N times under `mpirun -n N` (or the launcher named
    /// in `MPIEXEC`), each process using its share of the cores for its point loops. Under a launcher
    /// already, N must be the number of processes it started. Without it a run of stiffness-dominated
    /// steps starts itself on a process per core, any other on one process with threads
    /// (docs/configuration.md); `--processes 1` keeps one process.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub processes: Option<u32>,
}

/// How the run was invoked: the arguments (for run.json and the resume hint) and the flags that act after
/// the checks.
struct Invocation<'a> {
    /// The program's arguments.
    own: &'a [String],
    /// PETSc's arguments, starting with the program name.
    petsc: &'a [String],
    /// The configuration file as given.
    file: String,
    /// `--quiet`.
    quiet: bool,
    /// `--overwrite`.
    overwrite: bool,
}

/// A run that passed the checks that need no PETSc.
struct Prepared {
    cfg: RunConfig,
    /// `--set` overrides, `--steps` as `run.steps=N`.
    overrides: Vec<String>,
    /// The effective configuration (canonical TOML).
    effective: String,
    identity: RunIdentity,
    /// The output directory.
    dir: PathBuf,
    /// The checkpoint a `--resume` continues from.
    resume_from: Option<checkpoint::Header>,
    /// The lock of the output directory, if it existed (process 0; a new directory is locked when it is
    /// created).
    lock: Option<DirLock>,
    /// Process 0's refusal of the output directory when it could not take its lock (another run holds
    /// it): every process ends with it once PETSc has started ([`refuse_if_locked_out`]).
    locked_out: Option<String>,
}

/// `e`, an input that every process refuses before PETSc starts, or in its place on process 0 the refusal
/// `locked_out` of an output directory that another run holds: the lock comes first, as on one process.
fn lock_first(locked_out: Option<&str>, e: anyhow::Error) -> anyhow::Error {
    match locked_out {
        Some(refusal) => bad(refusal),
        None => e,
    }
}

/// `run CONFIG`: checks the input (`own_args` the program's arguments, `petsc_args` PETSc's, starting with
/// the program name) and the memory the run's plan needs, starts PETSc and runs the simulation in 2D, or
/// in 3D with `[extrusion]`.
pub fn run(own_args: &[String], petsc_args: &[String], flags: RunFlags) -> Result<()> {
    let path = flags.config.as_path();
    let prepared = prepare(path, &flags, petsc_args)?;
    let file = path.display().to_string();
    let label = config::source_label(&file, &prepared.overrides);
    let held_first = |e| lock_first(prepared.locked_out.as_deref(), e);
    let plan = scenario::plan(&prepared.cfg).map_err(|e| held_first(bad(e.in_file(&label))))?;
    check_memory(&plan, &label, flags.allow_large).map_err(held_first)?;
    let session = Session::initialize(petsc_args).context("starting PETSc")?;
    let session = refuse_if_locked_out(session, &prepared)?;
    share_cores(&session);
    let invocation = Invocation {
        own: own_args,
        petsc: petsc_args,
        file: file.clone(),
        quiet: flags.quiet,
        overwrite: flags.overwrite,
    };
    let file = &invocation.file;
    petsc::apply_default_options(&session, &prepared.cfg.run.petsc_options)
        .map_err(|e| bad(format!("{file}: run.petsc_options: {e}")))?;
    // A plane set-up, or the plate it is extruded to ([extrusion]): the same run in 2D or 3D.
    // On several processes each seeds its own band of points where it can (`shared`).
    let resuming = prepared.resume_from.is_some();
    let built = scenario::build_run_on(plan, &session, resuming);
    let (setup, shared) = agreed(&session, built.map_err(|e| bad(e.in_file(&label))))?;
    match setup {
        RunSetup::Plane(setup) => simulate(&session, &invocation, prepared, (setup, shared))?,
        RunSetup::Plate(setup) => simulate(&session, &invocation, prepared, (setup, shared))?,
    }
    Session::finalize(session)?;
    Ok(())
}

/// The number of processes a plain `run` (no `--processes`, not under a launcher) starts itself on
/// ([`launch::processes_for`]), with the inertia ratio of its steps; `None` where it runs here: one
/// process is the faster, `RAYON_NUM_THREADS` chose threads, no launcher is installed, the user's PETSc
/// options (`petsc_args`, the configuration's `run.petsc_options`, `PETSC_OPTIONS`) choose the
/// preconditioner (`-pc_type`: e.g. `ilu`, which PETSc has for one process only), bodies move on their
/// own velocity fields (one process only), or the input is bad (which the run itself then reports).
pub fn automatic_processes(flags: &RunFlags, petsc_args: &[String]) -> Option<(usize, f64)> {
    if std::env::var_os("RAYON_NUM_THREADS").is_some() || !launch::launcher_found() {
        return None;
    }
    let mut overrides = flags.set.clone();
    if let Some(n) = flags.steps {
        overrides.push(format!("run.steps={n}"));
    }
    let (cfg, _) = RunConfig::load(&flags.config, &overrides).ok()?;
    let environment = std::env::var("PETSC_OPTIONS").unwrap_or_default();
    let chosen = petsc_args
        .iter()
        .map(String::as_str)
        .chain(cfg.run.petsc_options.split_whitespace())
        .chain(environment.split_whitespace())
        .any(|o| o == "-pc_type");
    let plan = scenario::plan(&cfg).ok()?;
    if chosen || plan.num_fields() > 1 {
        return None;
    }
    let ratio = plan.inertia_ratio()?;
    let need = preflight::memory_need(&plan).ok()?;
    let machine = launch::Machine {
        class: StepClass::of(Some(ratio)),
        points: need.points,
        bytes: need.bytes,
        available: preflight::memory_limit().map(|l| l.bytes),
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    Some((launch::processes_for(machine), ratio)).filter(|(n, _)| *n > 1)
}

/// The checks of the input before the run's plan: the configuration with its overrides (--steps is
/// run.steps), the PETSc option values, the output directory or the checkpoint to resume.
fn prepare(path: &Path, flags: &RunFlags, petsc_args: &[String]) -> Result<Prepared> {
    let file = path.display().to_string();
    if flags.steps == Some(0) {
        return Err(bad("--steps must be at least 1"));
    }
    // --steps N reaches the configuration as run.steps=N, a TOML integer: at most i64::MAX.
    if let Some(n) = flags.steps.filter(|&n| i64::try_from(n).is_err()) {
        return Err(bad(format!(
            "--steps {n}: a number of steps from 1 to {}",
            i64::MAX
        )));
    }
    let mut overrides = flags.set.clone();
    if let Some(n) = flags.steps {
        overrides.push(format!("run.steps={n}"));
    }
    let (cfg, effective) = RunConfig::load(path, &overrides).map_err(bad)?;
    preflight::check_petsc_options(&cfg.run.petsc_options).map_err(|e| {
        let label = config::source_label(&file, &overrides);
        bad(ConfigError::in_file(&label, e.at_key("run.petsc_options")))
    })?;
    let command_options = petsc_args[1..].join(" ");
    preflight::check_petsc_options(&command_options)
        .map_err(|e| bad(format!("command line: {e}")))?;
    // PETSc also reads options from the environment.
    if let Ok(env) = std::env::var("PETSC_OPTIONS") {
        preflight::check_petsc_options(&env)
            .map_err(|e| bad(format!("environment variable PETSC_OPTIONS: {e}")))?;
    }
    let dir = flags.output.clone().unwrap_or_else(|| cfg.output_dir());
    let petsc_options = format!("{} {command_options}", cfg.run.petsc_options)
        .trim()
        .to_owned();
    let identity = RunIdentity::new(&effective, &petsc_options);
    let contents = rundir::inspect(&dir).map_err(bad)?;
    // Another run writing into the directory comes first: neither --overwrite nor --resume may touch it.
    // Process 0 alone takes the lock, so a refusal is not yet returned here: the input the other
    // processes refuse before PETSc starts, process 0 refuses with the lock's refusal instead; the rest
    // are told once PETSc has started ([`refuse_if_locked_out`]), so that every process ends alike.
    let (lock, locked_out) =
        match (launcher_rank() == 0 && dir.is_dir()).then(|| rundir::lock(&dir)) {
            Some(Ok(lock)) => (Some(lock), None),
            Some(Err(refusal)) => (None, Some(refusal)),
            None => (None, None),
        };
    let held_first = |e| lock_first(locked_out.as_deref(), e);
    let resume_from = if flags.resume {
        Some(check_resume(&dir, &identity, cfg.run.steps).map_err(held_first)?)
    } else {
        if !contents.results.is_empty() && !flags.overwrite {
            return Err(held_first(bad(refusal(&dir, &contents, &identity))));
        }
        None
    };
    Ok(Prepared {
        cfg,
        overrides,
        effective,
        identity,
        dir,
        resume_from,
        lock,
        locked_out,
    })
}

/// The session of a run whose output directory process 0 could lock. Process 0 alone knows whether
/// another run holds the directory: if it does, every process finishes PETSc and ends with the refusal
/// (exit code 2), which process 0 reports; the others end without a word, as they do with bad input that
/// every process meets. Collective.
fn refuse_if_locked_out(session: SessionGuard, prepared: &Prepared) -> Result<SessionGuard> {
    // Reported before the processes agree: once one of them has ended with an error, the launcher may
    // end the others at any moment.
    if let Some(refusal) = &prepared.locked_out {
        eprintln!("error: {refusal}");
    }
    if !session.any(prepared.locked_out.is_some()) {
        return Ok(session);
    }
    // The refusal is what the user must learn, also if PETSc fails to finish.
    Session::finalize(session).ok();
    Err(bad(""))
}

/// Refuses a run whose estimated memory need exceeds the memory available, unless `allow_large`; `label`
/// names the configuration.
fn check_memory(plan: &Plan, label: &str, allow_large: bool) -> Result<()> {
    // Where the points are not seeded in bands every process builds the whole model before it keeps its
    // share of the points: each process on this node may peak near a serial run's memory.
    let mut need = preflight::memory_need(plan).map_err(|e| bad(format!("{label}: {e}")))?;
    // Points are numbered with 32 bits: more cannot be seeded, however much memory there is.
    if need.points > u32::MAX as f64 {
        return Err(bad(format!(
            "{label}: the run would have about {:.3e} material points, more than the {:.3e} the program \
             can number (also with --allow-large): use a larger grid.cell_size or fewer \
             shape.points_per_cell",
            need.points,
            u32::MAX as f64
        )));
    }
    need.bytes *= processes_per_node().unwrap_or(1) as f64;
    if let Some(limit) = preflight::memory_limit()
        && need.bytes > limit.bytes
        && !allow_large
    {
        return Err(bad(format!(
            "{label}: the run needs about {} of memory ({:.3e} material points, {:.3e} grid nodes), more \
             than the {} available ({}): use a larger grid.cell_size or fewer shape.points_per_cell, or \
             --allow-large to start anyway",
            preflight::human_bytes(need.bytes),
            need.points,
            need.nodes,
            preflight::human_bytes(limit.bytes),
            limit.source
        )));
    }
    Ok(())
}

/// The run of a prepared configuration from its `setup` in `D` dimensions (`shared`: the set-up holds
/// this process's band of points only).
fn simulate<const D: usize>(
    session: &SessionGuard,
    invocation: &Invocation,
    mut prepared: Prepared,
    (setup, shared): (Setup<D>, bool),
) -> Result<()> {
    let lock = prepared.lock.take();
    let (cfg, file) = (&prepared.cfg, &invocation.file);
    let root = session.rank() == 0;
    let (mut sim, mut defaults) = build(session, setup, file)?;
    if shared {
        share_out(session, &mut sim)?;
    }
    // The output's reference state (initial positions, the step-0 fields) is the state at step 0 as
    // built, also for a resumed run: each process's points where they are shared out; where they are
    // not, every point on process 0, which writes them, and none on the others (which take part in the
    // collective writes with the counters).
    let built = if root || sim.state.distributed {
        sim.state.clone()
    } else {
        sim.state.without_points()
    };
    let positions = initial_positions(session, &sim.state)?;
    let resumed = resume(session, &prepared, &mut sim)?;
    let interrupted = on_signal(root)?;
    sim.watch(interrupted.clone());
    let counts = points_per_process(session, &sim.state)?;
    if root {
        announce(session, cfg, &sim, (&counts, &prepared.dir));
    }
    let bar = progress_bar(
        invocation.quiet || !root,
        cfg.run.steps,
        sim.state.counters.step,
    );
    let started = std::time::Instant::now();
    // A PETSc logging stage for the time loop, so -log_view separates it from the set-up.
    let _stage = session.push_stage(session.register_stage("MPM time steps")?)?;
    // The first step sets up PETSc's solvers, which read (and so validate) the options: until it has
    // passed, nothing is written.
    let step = sim.advance(session);
    if let Err(e) = check_first_step(session, &step, &defaults, file) {
        bar.abandon();
        return Err(e);
    }
    let opened = open_output(invocation, &prepared, &sim, (root, lock), positions);
    let mut records = agreed(session, opened)?;
    // The output directory exists from here on: the fallback's factors go there from the next step on
    // (in the first step, before anything is written, to MUMPS's default directory).
    defaults.extend(solver_defaults::out_of_core_directory(
        session,
        &prepared.dir,
    )?);
    let hint = resume_command(invocation.own, invocation.petsc, &prepared.dir);
    // The starting state: a fresh run's step 0 (its checkpoint, then its fields), or a resumed run's
    // checkpoint state if the fields of that step are missing.
    let start = if prepared.resume_from.is_some() {
        resumed.as_ref()
    } else {
        Some(&built)
    };
    if let Some(start) = start
        && let Err(e) = records.keep(session, start)
    {
        bar.abandon();
        return Err(records.abandon(session, &sim, e, &hint));
    }
    drop((built, resumed));
    let steps = Steps {
        session,
        bar: &bar,
        interrupted: &interrupted,
        hint: &hint,
        quiet: invocation.quiet,
    };
    steps.run(&mut records, &mut sim, step)?;
    bar.finish();
    let note = records.finish(session, &sim, "finished", None)?;
    if !root {
        return Ok(());
    }
    summary(
        &records.out,
        started.elapsed().as_secs_f64(),
        note.as_deref(),
    );
    if let Some(n) = note {
        eprintln!("warning: {n}");
    }
    report_unused_fallback(session, &defaults)
}

/// x, y, z of every point at step 0 (`built`, this process's points; all of them where they are not
/// shared out), by id, on every process: the reference of the displacements and of a 3D section (3
/// values per point on each process). Collective where the points are shared out (each process sends
/// its points' positions to all).
fn initial_positions<const D: usize>(
    session: &SessionGuard,
    built: &State<D>,
) -> Result<Vec<[f64; 3]>> {
    let p = &built.particles;
    if !built.distributed {
        return Ok(crate::io::positions_by_id(&p.id, &p.x));
    }
    let mine: Vec<f64> = (0..p.len())
        .flat_map(|k| {
            let mut r = [p.id[k] as f64, 0.0, 0.0, 0.0];
            r[1..=D].copy_from_slice(p.x[k].as_slice());
            r
        })
        .collect();
    let size = session.size();
    let send = mine.repeat(size);
    let received = session.exchange(4, &vec![p.len(); size], &send);
    let received = agreed(
        session,
        received.context("sharing the initial positions with every process"),
    )?;
    let mut positions = vec![[0.0; 3]; received.len() / 4];
    for r in received.chunks_exact(4) {
        positions[r[0] as usize] = [r[1], r[2], r[3]];
    }
    Ok(positions)
}

/// Loads the checkpoint of a resumed run into `sim`; returns a copy of the loaded state if the fields of
/// its step are missing (a write failed after the checkpoint; as process 0 sees the directory), to be
/// written again. Collective.
fn resume<const D: usize>(
    session: &SessionGuard,
    prepared: &Prepared,
    sim: &mut Simulation<D>,
) -> Result<Option<State<D>>> {
    if prepared.resume_from.is_none() {
        return Ok(None);
    }
    let loaded = checkpoint::load(&prepared.dir, &sim.model, &mut sim.state).map_err(bad);
    steps::agreed(session, loaded)?;
    let root = session.rank() == 0;
    if root {
        eprintln!(
            "resuming at step {} (t = {:e} s)",
            sim.state.counters.step, sim.state.counters.time
        );
    }
    let fields = file::numbered(file::FIELDS, sim.state.counters.step);
    let missing = session.any(root && !prepared.dir.join(fields).is_file());
    Ok(missing.then(|| {
        if root {
            sim.state.clone()
        } else {
            sim.state.without_points()
        }
    }))
}

/// Notes SIGINT (Ctrl-C), SIGTERM (what an MPI launcher sends the processes on Ctrl-C) and SIGHUP: the
/// run finishes the current step if it ends within [`crate::solver::FINISH_WITHIN`], else abandons it
/// (every process at the same evaluation), saves the last finished step and stops. The first signal is
/// acknowledged on process 0 (`root`).
fn on_signal(root: bool) -> Result<Arc<Interrupt>> {
    let interrupt = Arc::new(Interrupt::new());
    let noted = interrupt.clone();
    ctrlc::set_handler(move || {
        if noted.request() && root {
            eprintln!(
                "signal received: stopping; the last finished step is saved with a checkpoint \
                 (a step that does not end at once is abandoned)"
            );
        }
    })
    .context("installing the signal handler")?;
    Ok(interrupt)
}

/// The simulation of `setup` (of the file `file`) with its solver defaults applied, and the defaults'
/// option names: those a user's solver choice makes irrelevant (e.g. the MUMPS option under -pc_type
/// hypre) must not be reported as unused.
fn build<const D: usize>(
    session: &SessionGuard,
    mut setup: Setup<D>,
    file: &str,
) -> Result<(Simulation<D>, Vec<String>)> {
    // The solver defaults follow the kind of step (docs/solvers.md).
    let (_, defaults) = solver_defaults::apply(session, &mut setup)?;
    let sim = Simulation::new(setup).map_err(|e| {
        bad(match e {
            StepError::Model(ModelError::Invalid(value)) => ConfigError::in_file(file, value),
            e => ConfigError::Build {
                file: file.to_owned(),
                message: e.to_string(),
            },
        })
    })?;
    Ok((sim, defaults))
}

/// Marks the state of a simulation built from this process's band of points ([`scenario::build_run_on`])
/// as shared out, with the initial kinetic energy summed over the processes. Collective.
fn share_out<const D: usize>(session: &SessionGuard, sim: &mut Simulation<D>) -> Result<()> {
    sim.state.distributed = true;
    let mut energy = [sim.state.counters.initial_energy];
    session.sum(&mut energy)?;
    sim.state.counters.initial_energy = energy[0];
    Ok(())
}

/// The material points each process holds (all of them on each while they are not shared out), in
/// process order. Collective.
fn points_per_process<const D: usize>(
    session: &SessionGuard,
    state: &State<D>,
) -> Result<Vec<usize>> {
    let mut counts = vec![0.0; session.size()];
    counts[session.rank()] = state.particles.len() as f64;
    session.sum(&mut counts)?;
    Ok(counts.into_iter().map(|n| n as usize).collect())
}

/// The run's one-line description on standard error: points (with the points each process holds when
/// they are shared out, `counts`), grid, steps, unknowns, processes, output in `dir`.
fn announce<const D: usize>(
    session: &SessionGuard,
    cfg: &RunConfig,
    sim: &Simulation<D>,
    (counts, dir): (&[usize], &Path),
) {
    let grid = &sim.model.params.grid;
    let cells: Vec<String> = grid.cells().iter().map(usize::to_string).collect();
    let points = match sim.state.distributed {
        true => {
            let each: Vec<String> = counts.iter().map(usize::to_string).collect();
            let total: usize = counts.iter().sum();
            format!("{total} ({} per process)", each.join(" + "))
        }
        false => sim.state.particles.len().to_string(),
    };
    eprintln!(
        "{}: {} material points, grid {} cells of {} mm{}, {} steps of {:e} s, {} unknowns per node, {}output in {}",
        cfg.run.name,
        points,
        cells.join("x"),
        grid.cell_size(),
        match &cfg.extrusion {
            Some(e) => format!(", a {} mm plate (3D)", e.thickness),
            None => String::new(),
        },
        cfg.run.steps,
        cfg.time.dt,
        sim.model.layout().per_node(),
        match session.size() {
            1 => String::new(),
            n => format!("{n} processes, "),
        },
        dir.display()
    );
}

/// The progress bar over `steps` steps, at step `done`; `hidden` for quiet runs and processes other
/// than 0.
fn progress_bar(hidden: bool, steps: usize, done: usize) -> ProgressBar {
    let bar = if hidden {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(steps as u64)
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{bar:30} {pos}/{len} steps  {msg}  [{elapsed_precise} < {eta_precise}]",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar.set_position(done as u64);
    bar
}

/// Bad input that the first step revealed: PETSc options that no solver used (other than the solver
/// defaults `defaults` and the fallback solver's), options PETSc refused, or a set-up the solver refused.
/// A step that failed otherwise is left to the time loop.
fn check_first_step(
    session: &SessionGuard,
    step: &Result<StepReport, StepError>,
    defaults: &[String],
    file: &str,
) -> Result<()> {
    match step {
        Ok(_) => {
            let mut unused = petsc::unused_options(session)?;
            unused.retain(|o| {
                !defaults.contains(o) && !o.starts_with(&format!("-{FALLBACK_PREFIX}"))
            });
            if !unused.is_empty() {
                return Err(bad(format!(
                    "unknown or unused PETSc option(s): {} (check the spelling; -help lists the options); \
                     nothing was written",
                    unused.join(" ")
                )));
            }
        }
        Err(StepError::Petsc(e)) => {
            let message = format!("the first step failed in PETSc: {e}; nothing was written");
            return Err(if PETSC_INPUT_ERRORS.contains(&e.code) {
                bad(message)
            } else {
                anyhow::anyhow!(message)
            });
        }
        Err(e @ StepError::Setup(_)) => {
            return Err(bad(format!("{file}: {e}; nothing was written")));
        }
        // Process 0 reports it.
        Err(StepError::Interrupted { .. }) if session.rank() != 0 => {
            return Err(crate::app::FailedElsewhere.into());
        }
        Err(StepError::Interrupted { .. }) => {
            return Err(anyhow::anyhow!(
                "interrupted in the first step, before anything was written"
            ));
        }
        Err(_) => {}
    }
    Ok(())
}

/// The output: the directory now belongs to this run (on process 0, `root`, it holds `lock` of the
/// directory, taken here if the directory is new). Removes an earlier run's files (--overwrite) and the
/// temporaries of an interrupted write, writes the effective configuration and run.json, and sets up the
/// output of this process with the points' positions at step 0, `initial_position` (by id; a resumed run
/// restores its records).
fn open_output<'a, const D: usize>(
    invocation: &Invocation,
    prepared: &'a Prepared,
    sim: &Simulation<D>,
    (root, lock): (bool, Option<DirLock>),
    initial_position: Vec<[f64; 3]>,
) -> Result<Records<'a>> {
    let Prepared { cfg, dir, .. } = prepared;
    let lock = match lock {
        None if root => {
            std::fs::create_dir_all(dir).map_err(|e| {
                bad(format!(
                    "{}: cannot create the output directory: {e} (give another --output); nothing \
                     was written",
                    dir.display()
                ))
            })?;
            Some(rundir::lock(dir).map_err(bad)?)
        }
        lock => lock,
    };
    if root {
        rundir::remove_temporaries(dir).map_err(anyhow::Error::msg)?;
    }
    if invocation.overwrite && root {
        let removed = rundir::remove_program_files(dir).map_err(anyhow::Error::msg)?;
        if removed > 0 {
            eprintln!(
                "--overwrite: removed {removed} files of the earlier run from {}",
                dir.display()
            );
        }
    }
    let config_copy = format!(
        "# The effective configuration of the run in this directory: {}.\n\
         # Canonical form (sorted keys; the file's comments are not kept).\n\n{}",
        config::source_label(&invocation.file, &prepared.overrides),
        prepared.effective
    );
    let mut out = RunOutput::for_process(
        dir,
        (&cfg.run.name, &config_copy),
        (sim.model.params.grid.cell_size(), D),
        initial_position,
        root,
    )?;
    if let Some(z) = cfg.extrusion.as_ref().and_then(|e| e.section_z) {
        out.set_section(z);
    }
    out.set_frame(sim.model.params.frame);
    if let Some(ct) = &cfg.ct {
        let concrete = ct.material.build().context("ct.material")?.elastic_moduli();
        out.track_crack(
            nalgebra::Vector2::new(ct.notch_length, 0.5 * ct.height),
            crate::crack::CrackCriteria::for_notch(ct.notch_width, cfg.grid.cell_size),
            crate::crack::rayleigh_speed(concrete.bulk, concrete.shear, ct.density),
        );
    }
    out.set_run_id(&prepared.identity.id);
    if let Some(header) = &prepared.resume_from {
        header
            .restore_records(&mut out)
            .context("restoring the output's records from the checkpoint")?;
    }
    let mut record = new_record(invocation, prepared);
    record.snapshots = Some(out.snapshot_records());
    if root {
        record.write(dir)?;
    }
    Ok(Records {
        _lock: lock,
        cfg,
        dir,
        identity: &prepared.identity,
        root,
        out,
        record,
        checkpoint: prepared.resume_from.as_ref().map(|h| h.counters.step),
    })
}

/// The run.json of a run starting at step 0 or resuming at its checkpoint (its steps done are those of the
/// checkpoint it has, while running).
fn new_record(invocation: &Invocation, prepared: &Prepared) -> RunRecord {
    let cfg = &prepared.cfg;
    let start = prepared.resume_from.as_ref().map(|h| &h.counters);
    RunRecord {
        identity: prepared.identity.clone(),
        command: command_line(invocation.own, invocation.petsc),
        config_file: invocation.file.clone(),
        overrides: prepared.overrides.clone(),
        started_unix: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
        resumed_from_step: prepared.resume_from.as_ref().map(|h| h.counters.step),
        status: "running".into(),
        steps_done: start.map_or(0, |c| c.step),
        steps_requested: cfg.run.steps,
        time_reached: start.map_or(0.0, |c| c.time),
        time_requested: cfg.run.steps as f64 * cfg.time.dt,
        reduced_steps: 0,
        note: None,
        holder: Some(Holder::this_process()),
        snapshots: None,
    }
}

/// A note on the fallback solver's options that were never used (the fallback did not run, or the option
/// is misspelled), other than its defaults `defaults`.
fn report_unused_fallback(session: &SessionGuard, defaults: &[String]) -> Result<()> {
    let unused_fallback: Vec<String> = petsc::unused_options(session)?
        .into_iter()
        .filter(|o| o.starts_with(&format!("-{FALLBACK_PREFIX}")) && !defaults.contains(o))
        .collect();
    if !unused_fallback.is_empty() {
        eprintln!(
            "note: {} never used: the fallback solver did not run, or the option is misspelled",
            unused_fallback.join(" ")
        );
    }
    Ok(())
}
