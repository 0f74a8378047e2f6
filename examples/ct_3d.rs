//! The CT test of a configuration as a plate of finite thickness: the configuration's plane set-up
//! (specimen, notch, loading plates in contact, supports) extruded along z ([`Setup::extrude`]) and run
//! with the same implicit step in 3D (`Simulation<3>`). Writes `history.csv` (time, plate force and
//! displacement, energies, Newton and linear iterations, wall time per step), the point fields at the
//! configuration's `output_every` steps (`fields_*.h5` and `fields.xdmf`: open the `.xdmf` in ParaView)
//! and the damage of the mid-plane and of the front face (`damage_mid.png`, `damage_face.png`) into the
//! output directory.
//! Runs on any number of MPI processes (the points are shared out in slabs across z; process 0 writes).
//!
//! ```text
//! cargo run --release --example ct_3d -- configs/ct-demo.toml [thickness mm, default 16] [steps] [out dir]
//! mpirun -n 2 target/release/examples/ct_3d configs/ct-demo.toml 16 300 target/ct_3d
//! ```
//!
//! PETSc options come from the configuration's `run.petsc_options` and the `PETSC_OPTIONS` environment
//! variable. Units: mm, s, N, MPa, t.
//!
//! [`Setup::extrude`]: mpm_concrete::model::Setup::extrude

use std::error::Error;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use mpm_concrete::config::RunConfig;
use mpm_concrete::io::RunOutput;
use mpm_concrete::model::State;
use mpm_concrete::partition;
use mpm_concrete::petsc::{self, Session};
use mpm_concrete::plot::ScatterField;
use mpm_concrete::scenario;
use mpm_concrete::solver::Simulation;

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: ct_3d CONFIG [THICKNESS mm] [STEPS] [OUTPUT DIR]";
    let config = PathBuf::from(args.first().ok_or(usage)?);
    let thickness: f64 = args.get(1).map_or(Ok(16.0), |s| s.parse())?;
    let cfg = RunConfig::from_file(&config)?;
    let steps: usize = args.get(2).map_or(Ok(cfg.run.steps), |s| s.parse())?;
    let out = PathBuf::from(args.get(3).map_or("target/ct_3d", String::as_str));
    let session = Session::get()?;
    let root = session.rank() == 0;
    let say = |line: String| {
        if root {
            println!("{line}");
        }
    };
    petsc::apply_default_options(&session, &cfg.run.petsc_options)?;
    // The plane set-up of the configuration, then the plate.
    let plane = scenario::build(&cfg)?;
    let h = plane.grid.cell_size();
    let mut sim = Simulation::new(plane.extrude(thickness)?)?;
    let title = format!("{} as a {thickness} mm plate (3D)", cfg.run.name);
    let mut output = match root {
        true => {
            let text = std::fs::read_to_string(&config)?;
            let mut o = RunOutput::create(&out, &title, &text, &sim.model, &sim.state)?;
            o.write_fields(&sim.state)?;
            Some(o)
        }
        false => None,
    };
    let points = sim.state.particles.len();
    let cells = sim.model.grid.cells();
    say(format!(
        "3D CT: {points} points, grid {} x {} x {} cells of {h} mm, thickness {thickness} mm, {steps} \
         steps on {} processes",
        cells[0],
        cells[1],
        cells[2],
        session.size()
    ));
    let mut history = String::from(
        "# 3D CT: plate force per mm of thickness (N/mm), plate displacement (mm), energies (N mm), wall (s)\n\
         step,time,force_x,force_y,plate_u_x,plate_u_y,kinetic,stored,external_work,newton,linear,unknowns,wall\n",
    );
    let started = Instant::now();
    for _ in 0..steps {
        let r = sim.advance(&session)?;
        // The loading plate is the first rigid body (after the node boxes): its reaction per thickness.
        let plate = sim.model.boxes.len();
        let (f, u) = match (r.reactions.get(plate), r.displacements.get(plate)) {
            (Some(f), Some(u)) => ([f.1[0], f.1[1]], [u.1[0], u.1[1]]),
            _ => ([0.0; 2], [0.0; 2]),
        };
        writeln!(
            history,
            "{},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{},{},{},{:.3}",
            r.step,
            r.time,
            f[0] / thickness,
            f[1] / thickness,
            u[0],
            u[1],
            r.kinetic_energy,
            r.stored_energy,
            r.external_work,
            r.solve.iterations,
            r.solve.linear_iterations,
            r.unknowns,
            r.wall_total
        )?;
        if r.step % cfg.run.output_every.max(1) == 0 || r.step == steps {
            // Collective: every point on process 0, which writes.
            if let (Some(state), Some(o)) = (
                partition::whole_state(&session, &sim.state)?,
                output.as_mut(),
            ) {
                o.write_fields(&state)?;
            }
        }
        if r.step % 10 == 0 || r.step == steps {
            say(format!(
                "step {:4}  t = {:.3e} s  plate force {:9.2} N/mm  Newton {}  linear {}  {:.2} s",
                r.step,
                r.time,
                f[1] / thickness,
                r.solve.iterations,
                r.solve.linear_iterations,
                r.wall_total
            ));
        }
    }
    let wall = started.elapsed().as_secs_f64();
    say(format!(
        "{steps} steps in {wall:.1} s ({:.2} s per step, {:.2} us per point and step)",
        wall / steps as f64,
        1e6 * wall / (steps * points) as f64
    ));
    // Every point on process 0 (collective), then the damage of the mid-plane and of the front face.
    if let Some(state) = partition::whole_state(&session, &sim.state)? {
        std::fs::write(out.join("history.csv"), history)?;
        let spacing = state.particles.point_spacing();
        // The layer nearest below the mid-plane, and the layer at the front face (z = 0).
        let mid = ((0.5 * thickness / spacing - 0.5).floor() + 0.5) * spacing;
        for (name, z) in [("mid", mid), ("face", 0.5 * spacing)] {
            let path = out.join(format!("damage_{name}.png"));
            draw_layer(&state, z, spacing, &path, name)?;
        }
        say(format!("wrote {}", out.display()));
    }
    Ok(())
}

/// The damage of the layer of points seeded at `z` (mm), drawn in the x-y plane (points move little in z:
/// the layer is the points within half a spacing).
fn draw_layer(
    state: &State<3>,
    z: f64,
    spacing: f64,
    path: &Path,
    name: &str,
) -> Result<(), Box<dyn Error>> {
    let p = &state.particles;
    let layer: Vec<usize> = (0..p.len())
        .filter(|&k| (p.x[k].z - z).abs() < 0.5 * spacing)
        .collect();
    ScatterField {
        title: format!(
            "3D CT, {name} layer (z = {z:.1} mm), t = {:.1} us",
            state.time * 1e6
        ),
        x: layer.iter().map(|&k| p.x[k].x).collect(),
        y: layer.iter().map(|&k| p.x[k].y).collect(),
        value: layer.iter().map(|&k| p.damage[k]).collect(),
        value_label: "damage [-]".into(),
        range: Some((0.0, 1.0)),
        point_size: spacing,
    }
    .save_png(path)?;
    Ok(())
}
