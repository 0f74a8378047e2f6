//! A loading pin: a rigid plate pressed on the top face of an elastic cantilever near its tip, driven
//! down at its pin and free to turn about it, turns with the beam's slope under the load (beam theory),
//! where a plate without a pin cannot turn.
//!
//! Units: mm, s, N, MPa.

use mpm_concrete::config::RunConfig;
use mpm_concrete::petsc::{self, Session};
use mpm_concrete::scenario;
use mpm_concrete::solver::Simulation;

/// Cantilever 40 x 8 mm (E = 1000 MPa, nu = 0), clamped at x = 0; a 4 mm plate on its top face centred at
/// x = a = 36 mm, pushed down quasi-statically by 0.05 mm per step.
fn config(pin: bool) -> String {
    let pin = if pin { ", pin = [36.0, 9.0]" } else { "" };
    format!(
        r#"
[run]
name = "pin-cantilever"
steps = 1
[time]
dt = 1.0
quasi_static = true
[grid]
cell_size = 1.0
[shape]
kind = "cpdi1"
points_per_cell = 2
[[body]]
name = "beam"
density = 1.0e-9
geometry = {{ include = [{{ type = "rect", min = [0.0, 0.0], max = [40.0, 8.0] }}] }}
material = {{ model = "neo_hookean", youngs_modulus = 1000.0, poisson_ratio = 0.0 }}
[[constraint]]
name = "clamp"
min = [-0.1, -1.0]
max = [0.1, 9.0]
x = "fixed"
y = "fixed"
[[rigid_body]]
name = "pin"
geometry = {{ include = [{{ type = "rect", min = [34.0, 8.0], max = [38.0, 10.0] }}] }}
x = "fixed"
y = {{ velocity = -0.05 }}
contact = {{ normal = [0.0, -1.0]{pin} }}
"#
    )
}

#[test]
fn pin_loaded_cantilever_turns_like_beam_theory() {
    let s = Session::get().expect("PETSc");
    petsc::apply_default_options(
        &s,
        "-pin_ksp_type preonly -pin_pc_type lu -pin_snes_rtol 1e-10 -pin_snes_atol 1e-12",
    )
    .expect("options");
    let cfg = RunConfig::from_str_named(&config(true), "pin").expect("config");
    let mut setup = scenario::build(&cfg).expect("model");
    setup.params.options_prefix = Some("pin_".into());
    let mut sim = Simulation::new(setup).expect("simulation");
    let mut last = None;
    for _ in 0..4 {
        let r = sim.advance(&s).expect("step converges");
        let (name, f) = &r.reactions[1];
        assert_eq!(name, "pin");
        assert!(f[1] < 0.0, "the pin pushes the beam down: {f:?}");
        last = Some(r);
    }
    let r = last.unwrap();
    let w = -r.displacements[1].1[1];
    let theta = r.rotations[0].1;
    // Timoshenko cantilever under a point load P at x = a: w = P a^3/(3EI) + P a/(k G A) and the slope
    // of the loaded face there dw/dx = P a^2/(2EI) + P/(k G A) (k = 5/6, G = E/2 for nu = 0).
    let (a, hb, e) = (36.0, 8.0, 1000.0);
    let (ei, kga) = (e * hb * hb * hb / 12.0, 5.0 / 6.0 * 0.5 * e * hb);
    let ratio = (a * a / (2.0 * ei) + 1.0 / kga) / (a * a * a / (3.0 * ei) + a / kga);
    eprintln!(
        "pin displacement {w:.4} mm, rotation {theta:.5e} rad, theta/w {:.5} 1/mm vs beam theory \
         {ratio:.5} ({:+.2} %), force {:?} N/mm, solves {}",
        -theta / w,
        100.0 * (-theta / w / ratio - 1.0),
        r.reactions[1].1,
        r.contact_solves
    );
    assert!(
        theta < 0.0,
        "the plate turns clockwise with the beam: {theta}"
    );
    // The force of the same theory: P = w / (a^3/(3EI) + a/(k G A)) (measured -3.4 %).
    let p = w / (a * a * a / (3.0 * ei) + a / kga);
    let f = -r.reactions[1].1[1];
    assert!((f / p - 1.0).abs() < 0.1, "force {f} vs {p}");
    assert!(
        (-theta / w / ratio - 1.0).abs() < 0.1,
        "theta/w {} vs {ratio}",
        -theta / w
    );
}
