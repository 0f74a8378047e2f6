//! The table a run prints at its end: steps, time reached, iterations, costs, reactions, the crack.

use crate::io::RunOutput;
use crate::solver::StepReport;

/// Final table: steps, time reached, iterations, times, memory, reactions; `note` says that the run ended
/// before its requested end time.
pub(super) fn summary(out: &RunOutput, wall: f64, note: Option<&str>) {
    let rows = out.rows();
    println!("\n| quantity | value |\n|---|---|");
    summary_steps(rows, note);
    summary_costs(rows, wall);
    summary_results(out);
}

/// The summary's rows on the steps: how many, the time reached, the iterations, contact solves and points
/// between processes.
fn summary_steps(rows: &[StepReport], note: Option<&str>) {
    let newton: usize = rows.iter().map(|r| r.solve.iterations).sum();
    let linear: usize = rows.iter().map(|r| r.solve.linear_iterations).sum();
    let retries: usize = rows.iter().map(|r| r.attempts - 1).sum();
    let per_step = |n: usize| n as f64 / rows.len().max(1) as f64;
    println!(
        "| steps | {} ({} retried with the fallback solver or a smaller dt) |",
        rows.len(),
        retries
    );
    let time = rows.last().map_or(0.0, |r| r.time);
    match note {
        Some(n) => println!("| time reached | **{:.4} us**: {n} |", time * 1e6),
        None => println!(
            "| time reached | {:.4} us, the requested end time |",
            time * 1e6
        ),
    }
    println!(
        "| Newton iterations | {newton} ({:.2} per step) |",
        per_step(newton)
    );
    println!("| linear iterations | {linear} |");
    let contact: usize = rows.iter().map(|r| r.contact_solves).sum();
    if contact > rows.len() {
        println!(
            "| contact solves | {contact} ({:.2} per step: SNES solves while the contact active sets and \
             pin rotations settled) |",
            per_step(contact)
        );
    }
    let ghosts: usize = rows.iter().map(|r| r.ghosts).sum();
    if ghosts > 0 {
        let migrated: usize = rows.iter().map(|r| r.migrated).sum();
        println!(
            "| points between processes | {migrated} moved to another process; {:.0} ghost copies per step |",
            per_step(ghosts)
        );
    }
    summary_bytes(rows);
}

/// The summary's row on the bytes the processes sent (runs on several processes): per process and step,
/// the mean over the steps, and of them the gathers of the unknowns.
fn summary_bytes(rows: &[StepReport]) {
    let size = rows.iter().map(|r| r.bytes_sent.len()).max().unwrap_or(0);
    if size == 0 {
        return;
    }
    let mean = |of: fn(&StepReport) -> &[u64], p: usize| {
        let total: u64 = rows.iter().filter_map(|r| of(r).get(p)).sum();
        total as f64 / rows.len() as f64 / 1e3
    };
    let per: Vec<String> = (0..size)
        .map(|p| {
            format!(
                "{:.1} ({:.1})",
                mean(|r| &r.bytes_sent, p),
                mean(|r| &r.bytes_unknowns, p)
            )
        })
        .collect();
    println!(
        "| bytes sent per process and step | {} kB (in brackets: of them the gathers of the unknowns; \
         the program's own exchanges, not PETSc's solver traffic) |",
        per.join(", ")
    );
}

/// The summary's rows on the costs: wall times (`wall` this process's) and peak memory.
fn summary_costs(rows: &[StepReport], wall: f64) {
    let assembly: f64 = rows.iter().map(|r| r.wall_assembly).sum();
    let solve: f64 = rows.iter().map(|r| r.wall_solve - r.wall_assembly).sum();
    let setup: f64 = rows.iter().map(|r| r.wall_setup).sum();
    // The steps' times cover the whole run, also the part before a resume; `wall` is this process's.
    let steps_wall: f64 = rows.iter().map(|r| r.wall_total).sum();
    println!(
        "| wall time | {steps_wall:.1} s in the steps (set-up {setup:.1} s, assembly {assembly:.1} s, PETSc solve \
         {solve:.1} s); {wall:.1} s in this process |"
    );
    println!("| peak memory | {:.0} MB |", peak_rss_mb());
}

/// The summary's rows on the results: final reactions, the crack, the output directory.
fn summary_results(out: &RunOutput) {
    if let Some(last) = out.rows().last() {
        for (name, f) in &last.reactions {
            let components: Vec<String> = f.iter().map(|v| format!("{v:.4e}")).collect();
            // A 3D run's reactions are of the whole plate, a 2D run's per mm of thickness.
            let units = if f.len() == 3 { "N" } else { "N/mm" };
            println!(
                "| final reaction `{name}` | ({}) {units} |",
                components.join(", ")
            );
        }
    }
    if let Some(c) = out.cracks().last() {
        let angles = match c.bands.is_empty() {
            true => "-".to_owned(),
            false => format!("{} deg", c.band_angles()),
        };
        println!(
            "| crack | {} (length {:.1} mm, bands at {angles}; criteria in crack.json) |",
            c.classification, c.length,
        );
    }
    println!("| output | {} |", out.dir().display());
}

/// Peak resident set size of this process (MB), from /proc.
fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .and_then(|v| v.parse::<f64>().ok())
            })
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}
