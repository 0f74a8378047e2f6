//! The snap-back of the library bar followed by path following (`docs/theory.md`, "Path following"):
//! the bar of `tests/path_following.rs` (100 mm, weak centre zone at section 0.9, Table 1's microplane
//! material with c_0 = 9 mm^2, localizing R = 0.45), the elongation of a 31 mm gauge across the weak zone
//! growing by 0.5 um per step, on cells of h = 2, 1 and 0.5 mm, until the end stress falls below 5 % of
//! its peak (Table 1's alpha = 0.98 leaves 2 % of the weak zone's strength, 3 % of the bar's peak).
//! Draws the end stress over the bar's elongation `2 u_end` and over the gauge's `w` into
//! `docs/img/path-bar.png` (or the directory given as the first argument) and prints, per grid, the
//! Newton iterations of every step (`its/attempts`, the attempts > 1 when a step was halved).
//!
//! ```text
//! cargo run --release --example path_bar [OUT_DIR] [H_MM ...]
//! ```

use anyhow::Result;
use mpm_concrete::bar::{BarPath, BarSpec, BarStep, bar_simulation};
use mpm_concrete::material::MicroplaneConfig;
use mpm_concrete::petsc::{self, Session, SessionGuard};
use mpm_concrete::plot::LinePlot;
use std::path::PathBuf;

/// The curves of one run: (2 u_end, sigma) and (w, sigma), mm and MPa.
type Curves = (Vec<(f64, f64)>, Vec<(f64, f64)>);

/// Runs the bar on cells of `h` (mm) until separation (5 % of the peak stress), 1000 steps or a failed
/// step (reported, the curves so far kept).
fn run(s: &SessionGuard, h: f64) -> Result<Curves> {
    let material: MicroplaneConfig = toml::from_str(
        "preset = \"paper\"\nc = 9.0\n\
         gradient_activity = { kind = \"localizing\", residual = 0.45, decay = 0.0 }\n",
    )?;
    let spec = BarSpec {
        speed: 5e-3,
        rise: 0.0,
        dt: 1.0,
        quasi_static: true,
        options_prefix: "pb_".into(),
        path: Some(BarPath {
            gauge: 31.0,
            increment: 5e-4,
        }),
        ..BarSpec::regularisation()
    };
    let mut sim = bar_simulation(&spec, h, &material)?;
    let (mut elongation, mut opening) = (vec![(0.0, 0.0)], vec![(0.0, 0.0)]);
    let (mut peak, mut its, mut halved) = (0.0f64, Vec::new(), 0);
    for _ in 0..1000 {
        let r = match sim.advance(s) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("h = {h} mm: step {} failed: {e}", its.len() + 1);
                break;
            }
        };
        let b = BarStep::of(&r, h);
        let w = r.path.map_or(0.0, |p| p.opening);
        elongation.push((2.0 * b.end_displacement, b.stress));
        opening.push((w, b.stress));
        its.push(format!("{}/{}", r.solve.iterations, r.attempts));
        halved += usize::from(r.attempts > 1);
        peak = peak.max(b.stress);
        if b.stress < 0.05 * peak {
            break;
        }
    }
    let last = opening.last().map_or((0.0, 0.0), |p| *p);
    eprintln!(
        "h = {h} mm: peak {peak:.3} MPa, {} steps ({halved} retried), final w = {:.4e} mm at {:.3} MPa\n  \
         Newton iterations/attempts per step: {}",
        its.len(),
        last.0,
        last.1,
        its.join(" ")
    );
    Ok((elongation, opening))
}

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let out = args
        .next()
        .map_or_else(|| PathBuf::from("docs/img"), PathBuf::from);
    let sizes: Vec<f64> = args.map(|a| a.parse()).collect::<Result<_, _>>()?;
    let sizes = if sizes.is_empty() {
        vec![2.0, 1.0, 0.5]
    } else {
        sizes
    };
    std::fs::create_dir_all(&out)?;
    let s = Session::get()?;
    petsc::apply_default_options(
        &s,
        "-pb_ksp_type preonly -pb_pc_type lu -pb_pc_factor_mat_solver_type mumps \
         -pb_snes_rtol 1e-9 -pb_snes_atol 1e-9 -pb_snes_stol 0 -pb_snes_max_it 30",
    )?;
    let mut plot = LinePlot::new(
        "Bar under path following: end stress over the bar's and the gauge's elongation",
        "elongation [mm]: 2 u_end (bar), w (31 mm gauge)",
        "sigma [MPa]",
    );
    for h in sizes {
        let (elongation, opening) = run(&s, h)?;
        plot = plot
            .with_series(format!("h = {h} mm: 2 u_end"), elongation)
            .with_series(format!("h = {h} mm: w"), opening);
    }
    let path = out.join("path-bar.png");
    plot.save_png(&path)?;
    eprintln!("wrote {}", path.display());
    Ok(())
}
