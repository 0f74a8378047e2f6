//! The time loop of a run and its records. Every process writes its points into the snapshots' and
//! checkpoints' HDF5 files, process 0 the rest; every write at a step is agreed by
//! all processes before the next collective step ([`agreed`]), so that they all stop after the same step
//! (on a signal, a step that fails for good or a failed write) and none ends while process 0 is still
//! writing (an MPI launcher kills the other processes when one ends with an error). At an output step the
//! checkpoint is written before the point fields of the same step, so a write that fails (a full disk)
//! leaves a state to resume.

use crate::app::{FailedElsewhere, error_line};
use crate::checkpoint;
use crate::config::RunConfig;
use crate::crack;
use crate::io::{RunOutput, SharedState};
use crate::model::State;
use crate::petsc::SessionGuard;
use crate::rundir::{DirLock, RunIdentity, RunRecord};
use crate::solver::{Interrupt, Simulation, StepError, StepReport};
use anyhow::{Context, Result};
use indicatif::ProgressBar;
use nalgebra::Vector2;
use std::path::Path;

/// `result` agreed by every process: an error on one is an error on all (on the others a
/// [`FailedElsewhere`]). Collective, so also a barrier.
pub(super) fn agreed<T>(session: &SessionGuard, result: Result<T>) -> Result<T> {
    let failed = session.any(result.is_err());
    match result {
        Ok(_) if failed => Err(FailedElsewhere.into()),
        other => other,
    }
}

/// The records of a run in progress: its output and its run.json, and where they go.
pub(super) struct Records<'a> {
    /// The lock of the output directory, held until the run ends (process 0).
    pub(super) _lock: Option<DirLock>,
    pub(super) cfg: &'a RunConfig,
    pub(super) dir: &'a Path,
    pub(super) identity: &'a RunIdentity,
    /// This process writes (process 0).
    pub(super) root: bool,
    pub(super) out: RunOutput,
    pub(super) record: RunRecord,
    /// The step of the checkpoint in the directory (process 0; None while there is none).
    pub(super) checkpoint: Option<usize>,
}

impl Records<'_> {
    /// Keeps the current state of `sim`: [`Records::keep`]. Collective.
    fn save<const D: usize>(&mut self, session: &SessionGuard, sim: &Simulation<D>) -> Result<()> {
        self.keep(session, &sim.state)
    }

    /// Writes `state` (this process's points; every process writes its own into the shared files): the
    /// checkpoint, then the snapshot (point fields, crack, damage map), the force plots and run.json, which
    /// follows the checkpoint so that a run killed outright shows how far it got. Collective, each part
    /// agreed ([`agreed`]) before the next.
    pub(super) fn keep<const D: usize>(
        &mut self,
        session: &SessionGuard,
        state: &State<D>,
    ) -> Result<()> {
        let shared = SharedState::new(session, state).context("sharing out the points' rows");
        let shared = agreed(session, shared)?;
        let noted = self.out.note_snapshot(&shared).map_err(anyhow::Error::from);
        agreed(session, noted)?;
        let checkpoint = self.write_checkpoint(&shared);
        agreed(session, checkpoint)?;
        let snapshot = self.write_snapshot(&shared);
        agreed(session, snapshot)
    }

    /// The checkpoint of the state of `shared` (a resumed run writes the snapshot of its step if its
    /// files are missing). Collective.
    fn write_checkpoint<const D: usize>(&mut self, shared: &SharedState<D>) -> Result<()> {
        checkpoint::save(self.dir, shared, &self.out, self.identity)?;
        self.checkpoint = Some(shared.state.counters.step);
        Ok(())
    }

    /// The rest of [`Records::keep`]: the snapshot (collective), then on process 0 the force plots and
    /// run.json.
    fn write_snapshot<const D: usize>(&mut self, shared: &SharedState<D>) -> Result<()> {
        self.out.write_snapshot(shared)?;
        if !self.root {
            return Ok(());
        }
        let state = shared.state;
        self.out.force_plots()?;
        self.record.snapshots = Some(self.out.snapshot_records());
        self.record.steps_done = state.counters.step;
        self.record.time_reached = state.counters.time;
        self.record.write(self.dir)?;
        Ok(())
    }

    /// Closes run.json with `status` and the note `why` (and a note on an early end or reduced steps,
    /// which also goes into history.csv); returns the latter note. Collective ([`agreed`]).
    pub(super) fn finish<const D: usize>(
        &mut self,
        session: &SessionGuard,
        sim: &Simulation<D>,
        status: &str,
        why: Option<String>,
    ) -> Result<Option<String>> {
        let cfg = self.cfg;
        let taken: Vec<f64> = self.out.rows().iter().map(|r| r.dt).collect();
        let note = time_note(&taken, sim.state.counters.time, cfg.run.steps, cfg.time.dt);
        let record = &mut self.record;
        record.status = status.into();
        record.holder = None;
        record.steps_done = sim.state.counters.step;
        record.time_reached = sim.state.counters.time;
        record.reduced_steps = reduced_steps(&taken, cfg.time.dt);
        record.note = match (&why, &note) {
            (Some(w), Some(n)) => Some(format!("{w}; {n}")),
            (w, n) => w.clone().or(n.clone()),
        };
        let written = if self.root {
            match &record.note {
                Some(n) => append_history_note(self.dir, n),
                None => Ok(()),
            }
            .and_then(|()| Ok(record.write(self.dir)?))
        } else {
            Ok(())
        };
        agreed(session, written).map(|()| note)
    }

    /// A write that failed (`error`, agreed by all processes) at the state of `sim`: run.json says
    /// `failed` (as far as it can still be written) and the error says where the state to resume is, with
    /// the command `hint` that resumes it. Collective.
    pub(super) fn abandon<const D: usize>(
        &mut self,
        session: &SessionGuard,
        sim: &Simulation<D>,
        error: anyhow::Error,
        hint: &str,
    ) -> anyhow::Error {
        if !self.root {
            session.any(false);
            return error;
        }
        let resume = match self.checkpoint {
            Some(k) => format!(
                "the checkpoint of step {k} is in {}: to continue once the cause is fixed (e.g. space \
                 freed): {hint}",
                self.dir.display()
            ),
            None => {
                "no checkpoint was written: start the run again with --overwrite once the cause \
                     is fixed (e.g. space freed)"
                    .to_owned()
            }
        };
        let message = format!(
            "writing the output after step {} failed: {}; {resume}",
            sim.state.counters.step,
            error_line(&error)
        );
        let record = &mut self.record;
        record.status = "failed".into();
        record.holder = None;
        record.steps_done = sim.state.counters.step;
        record.time_reached = sim.state.counters.time;
        record.note = Some(message.clone());
        let closed = record.write(self.dir);
        // The others wait until run.json is written.
        session.any(false);
        match closed {
            Ok(()) => anyhow::anyhow!(message),
            Err(e) => anyhow::anyhow!("{message}; run.json could not be closed either: {e}"),
        }
    }
}

/// The time loop's surroundings: the session, the progress display, the Ctrl-C flag and the command
/// that resumes the run.
pub(super) struct Steps<'a> {
    pub(super) session: &'a SessionGuard,
    pub(super) bar: &'a ProgressBar,
    /// Requested by the handler of SIGINT, SIGTERM and SIGHUP (an MPI launcher forwards Ctrl-C to the
    /// processes as SIGTERM); the steps watch it too ([`Simulation::watch`]).
    pub(super) interrupted: &'a Interrupt,
    pub(super) hint: &'a str,
    pub(super) quiet: bool,
}

impl Steps<'_> {
    /// Records the first step's result `step` and advances until the requested step, a step that fails
    /// for good, a failed write or an interruption (all an error, after the state is saved if it can be).
    pub(super) fn run<const D: usize>(
        &self,
        records: &mut Records,
        sim: &mut Simulation<D>,
        mut step: Result<StepReport, StepError>,
    ) -> Result<()> {
        let steps = records.cfg.run.steps;
        loop {
            let mut report = match step {
                Ok(r) => r,
                // Not a failure: the step did not get the time to end.
                Err(StepError::Interrupted { step, .. }) => {
                    return Err(self.interrupt(records, sim, Some(step)));
                }
                Err(e) => return Err(self.failed(records, sim, &e)),
            };
            let front = crack_front(self.session, &records.out, &sim.state);
            report.crack = agreed(self.session, front)?;
            self.show(&report, records.root);
            let recorded = records.out.record(report).map_err(anyhow::Error::from);
            if let Err(e) = agreed(self.session, recorded) {
                return Err(records.abandon(self.session, sim, e, self.hint));
            }
            let every = records.cfg.run.output_every;
            // Every process stops after the same step (a signal may reach them at different steps, or
            // only some of them).
            let stop = self.session.any(self.interrupted.requested());
            if stop && sim.state.counters.step < steps {
                return Err(self.interrupt(records, sim, None));
            }
            if (every > 0 && sim.state.counters.step % every == 0)
                || sim.state.counters.step == steps
            {
                if let Err(e) = records.save(self.session, sim) {
                    return Err(records.abandon(self.session, sim, e, self.hint));
                }
            }
            if sim.state.counters.step >= steps {
                return Ok(());
            }
            step = sim.advance(self.session);
        }
    }

    /// The end of an interrupted run (`abandoned`: the step that was abandoned unfinished, if any), in
    /// the second or so that an MPI launcher leaves the processes after it forwarded the signal: the
    /// checkpoint of the last finished step (unless the directory holds it already), then run.json
    /// closed as `interrupted`; the step's snapshot is left to the resumed run, which writes a missing
    /// one. Process 0's error says how to continue. Collective.
    fn interrupt<const D: usize>(
        &self,
        records: &mut Records,
        sim: &Simulation<D>,
        abandoned: Option<usize>,
    ) -> anyhow::Error {
        self.bar.abandon();
        let (session, done) = (self.session, sim.state.counters.step);
        if session.any(records.root && records.checkpoint != Some(done)) {
            let shared =
                SharedState::new(session, &sim.state).context("sharing out the points' rows");
            let saved = agreed(session, shared).and_then(|shared| {
                let written = records.write_checkpoint(&shared);
                agreed(session, written)
            });
            if let Err(e) = saved {
                return records.abandon(session, sim, e, self.hint);
            }
        }
        let why = match abandoned {
            None => format!("interrupted after step {done}"),
            Some(k) => format!("interrupted after step {done} (step {k} was abandoned unfinished)"),
        };
        if let Err(e) = records.finish(session, sim, "interrupted", Some(why.clone())) {
            return e;
        }
        if !records.root {
            return FailedElsewhere.into();
        }
        anyhow::anyhow!(
            "{why}; the state is saved in {}: continue with {}",
            records.dir.display(),
            self.hint
        )
    }

    /// A step's line: on the progress bar, and on standard error (process 0) with `--quiet` or where no
    /// bar is drawn.
    fn show(&self, report: &StepReport, root: bool) {
        let msg = format!(
            "t = {:.2} us, Newton {}, KSP {}, {}",
            report.time * 1e6,
            report.solve.iterations,
            report.solve.linear_iterations,
            report.solve.reason_name
        );
        // Log lines where no bar is drawn: --quiet, or stderr not a terminal (a file, or the pipe of
        // an MPI launcher).
        if (self.quiet || self.bar.is_hidden()) && root {
            eprintln!("step {}: {msg}, {:.2} s", report.step, report.wall_total);
        }
        self.bar.set_message(msg);
        self.bar.inc(1);
    }

    /// A step that failed for good: saves the last converged state and closes the records; the error
    /// says how to continue.
    fn failed<const D: usize>(
        &self,
        records: &mut Records,
        sim: &Simulation<D>,
        e: &StepError,
    ) -> anyhow::Error {
        self.bar.abandon();
        if let Err(saving) = records.save(self.session, sim) {
            return records.abandon(self.session, sim, saving, self.hint);
        }
        let why = format!(
            "step {} failed: {}",
            sim.state.counters.step + 1,
            e.to_string().trim()
        );
        if let Err(closing) = records.finish(self.session, sim, "failed", Some(why)) {
            return closing;
        }
        anyhow::anyhow!(
            "{}; the last converged state (step {}, t = {:e} s) is saved in {} with a checkpoint; \
             to continue (e.g. with other solver options): {}",
            e.to_string().trim(),
            sim.state.counters.step,
            sim.state.counters.time,
            records.dir.display(),
            self.hint
        )
    }
}

/// The crack front of `state` in a run that tracks the crack (`None` otherwise): with the points shared
/// out, every process sends the positions of its points with damage at the threshold to process 0, which
/// measures the front ([`crack::front`]; the others return `None`, they write nothing) on the positions
/// turned into the specimen's frame, as the snapshots' crack metrics. In 3D the points of every layer
/// count, projected onto the plane. Collective.
fn crack_front<const D: usize>(
    session: &SessionGuard,
    out: &RunOutput,
    state: &State<D>,
) -> Result<Option<crack::Front>> {
    let Some((notch_tip, criteria, h, frame)) = out.crack_tracking() else {
        return Ok(None);
    };
    let p = &state.particles;
    let mut cracked: Vec<f64> = Vec::new();
    for (x, &d) in p.x.iter().zip(&p.damage) {
        if d >= criteria.damage_threshold {
            cracked.extend([x[0], x[1]]);
        }
    }
    if state.distributed && session.size() > 1 {
        let mut counts = vec![0; session.size()];
        counts[0] = cracked.len() / 2;
        cracked = session
            .exchange(2, &counts, &cracked)
            .context("gathering the cracked points on process 0")?;
        if session.rank() != 0 {
            return Ok(None);
        }
    }
    let x: Vec<Vector2<f64>> = cracked
        .chunks_exact(2)
        .map(|c| frame.to_specimen(Vector2::new(c[0], c[1])))
        .collect();
    let damage = vec![criteria.damage_threshold; x.len()];
    Ok(Some(crack::front(&x, &damage, notch_tip, h, &criteria)))
}

/// Steps (their time steps `taken`) that took less than the nominal time step `dt`.
fn reduced_steps(taken: &[f64], dt: f64) -> usize {
    taken.iter().filter(|&&t| t < dt * (1.0 - 1e-9)).count()
}

/// A sentence when a run whose steps took `taken` reached less than its requested end time (steps x dt)
/// or took reduced steps.
fn time_note(taken: &[f64], time: f64, steps: usize, dt: f64) -> Option<String> {
    let end = steps as f64 * dt;
    let reduced = reduced_steps(taken, dt);
    if time >= end * (1.0 - 1e-9) && reduced == 0 {
        return None;
    }
    let smallest = taken.iter().copied().fold(f64::INFINITY, f64::min);
    let mut note = format!(
        "the run ended at t = {:.4} us, before its requested end time {:.4} us ({steps} steps of {:.4} us)",
        time * 1e6,
        end * 1e6,
        dt * 1e6
    );
    if reduced > 0 {
        note += &format!(
            "; {reduced} of {} steps took a reduced time step (down to {:.4} us)",
            taken.len(),
            smallest * 1e6
        );
    }
    Some(note)
}

/// Appends `# note` to the run's history.csv, if it has one (the next rewrite of the history, by a resumed
/// run, drops it).
fn append_history_note(dir: &Path, note: &str) -> Result<()> {
    use std::io::Write as _;
    let path = dir.join(crate::schema::file::HISTORY);
    if !path.exists() {
        return Ok(());
    }
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(&path)
        .with_context(|| format!("{}: appending a note", path.display()))?;
    writeln!(f, "# {note}").with_context(|| format!("{}: appending a note", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_time_note_tells_an_early_end_and_reduced_steps() {
        let full = [1e-6; 4];
        assert_eq!(time_note(&full, 4e-6, 4, 1e-6), None);
        let halved = [1e-6, 0.5e-6, 0.25e-6, 0.5e-6];
        let note = time_note(&halved, 2.25e-6, 4, 1e-6).expect("note");
        assert!(
            note.contains("t = 2.2500 us, before its requested end time 4.0000 us")
                && note.contains("3 of 4 steps took a reduced time step (down to 0.2500 us)"),
            "{note}"
        );
        assert!(time_note(&full[..2], 2e-6, 4, 1e-6).is_some());
    }
}
