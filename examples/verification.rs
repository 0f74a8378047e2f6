//! Verification problems of `spec/02-benchmarks.md` (V1, V2, V3, V6) at documentation size, with plots.
//!
//! ```text
//! cargo run --release --example verification [-- <output dir, default docs/img>]
//! ```
//!
//! Writes `verification-*.png` and `verification-results.json` (all numbers quoted in
//! `docs/verification.md`) into the output directory. The tests in `tests/verification_*.rs` run the same
//! problems at smaller size with asserted bounds. Units: mm, s, N, MPa, t unless stated otherwise (V2's
//! large-deformation column uses AMPLE's numbers, which are only consistent among themselves).

use mpm_concrete::boundary::{Motion, NodeBox};
use mpm_concrete::geometry::{Geometry, Region, Seeding};
use mpm_concrete::grid::Grid;
use mpm_concrete::material::{Material, MaterialConfig};
use mpm_concrete::model::{Parameters, Setup, TimeIntegration};
use mpm_concrete::particles::Particles;
use mpm_concrete::petsc::{self, Session, SessionGuard};
use mpm_concrete::plot::{LinePlot, Series};
use mpm_concrete::shape::ShapeKind;
use mpm_concrete::solver::Simulation;
use nalgebra::Vector2;
use serde_json::{Value, json};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

const FAR: f64 = 1e6;

fn strip(min: [f64; 2], max: [f64; 2], h: f64, rho: f64) -> Result<Particles> {
    let geometry = Geometry {
        include: vec![Region::Rect { min, max }],
        exclude: vec![],
    };
    Ok(Particles::seed(
        &geometry,
        &Seeding {
            h,
            points_per_cell: 2,
            density: rho,
            body: 0,
        },
    )?)
}

fn node_box(name: &str, min: [f64; 2], max: [f64; 2], motion: [Motion; 2]) -> NodeBox {
    NodeBox {
        name: name.into(),
        min: Vector2::from(min),
        max: Vector2::from(max),
        motion,
        rise_time: 0.0,
    }
}

/// A run without constraints or loads yet; `prefix` selects the problem's SNES options (see `main`).
fn setup(
    grid: Grid,
    particles: Particles,
    material: Material,
    shape: ShapeKind,
    time: TimeIntegration,
    prefix: &str,
) -> Setup {
    Setup::of(
        Parameters {
            options_prefix: Some(prefix.into()),
            ..Parameters::new(grid, vec![material], shape, time)
        },
        particles,
    )
}

/// Slope of log(err) against log(h) between the last two sizes.
fn order(points: &[(f64, f64)]) -> f64 {
    let [.., (h1, e1), (h2, e2)] = points else {
        return f64::NAN;
    };
    (e1 / e2).ln() / (h1 / h2).ln()
}

// ---------------------------------------------------------------------------------------------------
// V1: axial vibration of a bar (L = 25, E = 100, rho = 1, nu = 0; consistent units).

fn v1(s: &SessionGuard, out: &Path) -> Result<Value> {
    let (l, v0) = (25.0, 0.1);
    let b1 = PI / (2.0 * l);
    let w1 = b1 * 10.0;
    let period = 2.0 * PI / w1;
    let mut plot = LinePlot::new(
        "V1 axial bar: centre-of-mass velocity",
        "t / T [-]",
        "v_cm [mm/s]",
    );
    let amplitude = v0 / (b1 * l);
    plot.series.push(Series {
        name: "exact".into(),
        points: (0..=400)
            .map(|k| {
                (
                    k as f64 / 200.0,
                    amplitude * (2.0 * PI * k as f64 / 200.0).cos(),
                )
            })
            .collect(),
    });
    let mut results = Vec::new();
    for (kind, cells) in [
        (ShapeKind::Linear, 16),
        (ShapeKind::Cpdi1, 16),
        (ShapeKind::Cpdi1, 32),
    ] {
        let h = l / cells as f64;
        let mut particles = strip([0.0, 0.0], [l, h], h, 1.0)?;
        for p in 0..particles.len() {
            particles.v[p] = Vector2::new(v0 * (b1 * particles.x[p].x).sin(), 0.0);
        }
        let grid = Grid::covering(Vector2::zeros(), Vector2::new(l, h), h, 2)?;
        let dt = period / 100.0;
        let mut st = setup(
            grid,
            particles,
            MaterialConfig::build_toml(
                "model = \"linear_elastic\"\nyoungs_modulus = 100.0\npoisson_ratio = 0.0",
            )?,
            kind,
            TimeIntegration {
                dt,
                dt_min: dt,
                ..TimeIntegration::default()
            },
            "v1_",
        );
        st.params.boxes = vec![
            node_box(
                "rollers",
                [-FAR, -FAR],
                [FAR, FAR],
                [Motion::Free, Motion::Velocity(0.0)],
            ),
            node_box(
                "fixed end",
                [-FAR, -FAR],
                [1e-9, FAR],
                [Motion::Velocity(0.0); 2],
            ),
        ];
        let mut sim = Simulation::new(st)?;
        let mass: f64 = sim.state.particles.mass.iter().sum();
        let mut curve = vec![(0.0, amplitude)];
        let mut max_err = 0.0f64;
        for _ in 0..200 {
            sim.advance(s)?;
            let p = &sim.state.particles;
            let vcm = p.mass.iter().zip(&p.v).map(|(m, v)| m * v.x).sum::<f64>() / mass;
            max_err = max_err
                .max((vcm - amplitude * (w1 * sim.state.counters.time).cos()).abs() / amplitude);
            curve.push((sim.state.counters.time / period, vcm));
        }
        println!(
            "V1 {} {cells} cells: max |v_cm error| / amplitude over two periods = {max_err:.4}",
            kind.name()
        );
        plot.series.push(Series {
            name: format!("{} {cells} cells", kind.name()),
            points: curve,
        });
        results.push(
            json!({ "shape": kind.name(), "cells": cells, "max_error_over_amplitude": max_err }),
        );
    }
    plot.save_png(out.join("verification-v1-bar.png"))?;
    Ok(Value::Array(results))
}

// ---------------------------------------------------------------------------------------------------
// V2: column under self-weight, one cell wide, rollers on the sides and the base.

/// Column data: height, Young's modulus, density, gravity.
#[derive(Clone, Copy)]
struct Column {
    height: f64,
    e: f64,
    rho: f64,
    g: f64,
}

/// Final state of a column run: initial heights Y, Cauchy sigma_yy and vertical displacement per point.
struct ColumnResult {
    y0: Vec<f64>,
    vol0: Vec<f64>,
    syy: Vec<f64>,
    uy: Vec<f64>,
}

impl ColumnResult {
    /// Normalised L2 error of sigma_yy against -rho g (H - Y) (exact for any elastic law: equilibrium of
    /// the weight above a point of a laterally confined column, whose cross-section does not change).
    fn stress_error(&self, c: &Column) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for k in 0..self.y0.len() {
            let exact = -c.rho * c.g * (c.height - self.y0[k]);
            num += self.vol0[k] * (self.syy[k] - exact).powi(2);
            den += self.vol0[k] * exact * exact;
        }
        (num / den).sqrt()
    }
}

fn column(
    s: &SessionGuard,
    c: &Column,
    law: &str,
    kind: ShapeKind,
    cells: usize,
    load_steps: usize,
) -> Result<ColumnResult> {
    let h = c.height / cells as f64;
    let particles = strip([0.0, 0.0], [h, c.height], h, c.rho)?;
    let y0: Vec<f64> = particles.x.iter().map(|x| x.y).collect();
    let vol0 = particles.vol0.clone();
    let grid = Grid::covering(Vector2::zeros(), Vector2::new(h, c.height), h, 2)?;
    let mut st = setup(
        grid,
        particles,
        MaterialConfig::build_toml(&format!(
            "model = \"{law}\"\nyoungs_modulus = {}\npoisson_ratio = 0.0",
            c.e
        ))?,
        kind,
        TimeIntegration {
            dt: 1.0,
            dt_min: 1.0 / 16.0,
            quasi_static: true,
            ..TimeIntegration::default()
        },
        "v2_",
    );
    st.params.body_force = Vector2::new(0.0, -c.g);
    st.params.body_force_ramp = load_steps as f64;
    st.params.boxes = vec![
        node_box(
            "side rollers",
            [-FAR, -FAR],
            [FAR, FAR],
            [Motion::Velocity(0.0), Motion::Free],
        ),
        node_box("base", [-FAR, -FAR], [FAR, 0.0], [Motion::Velocity(0.0); 2]),
    ];
    let mut sim = Simulation::new(st)?;
    while sim.state.counters.time < load_steps as f64 + 1.0 - 1e-9 {
        sim.advance(s)?;
    }
    let p = &sim.state.particles;
    Ok(ColumnResult {
        syy: p.stress.iter().map(|t| t[(1, 1)]).collect(),
        uy: p.x.iter().zip(&y0).map(|(x, y)| x.y - y).collect(),
        y0,
        vol0,
    })
}

/// Principal branch of Lambert's W for x >= 0 (Newton on w e^w = x).
fn lambert_w0(x: f64) -> f64 {
    let mut w = (1.0 + x).ln();
    for _ in 0..50 {
        let ew = w.exp();
        w -= (w * ew - x) / (ew * (w + 1.0));
    }
    w
}

/// u(Y) = int_0^Y (lambda(Y') - 1) dY' with the stretch `lambda(q)`, q = rho g (H - Y')/E (Simpson).
fn settlement(c: &Column, y: f64, lambda: impl Fn(f64) -> f64) -> f64 {
    let n = 2000;
    let dy = y / n as f64;
    let f = |yy: f64| lambda(c.rho * c.g * (c.height - yy) / c.e) - 1.0;
    let mut sum = f(0.0) + f(y);
    for k in 1..n {
        sum += f(k as f64 * dy) * if k % 2 == 1 { 4.0 } else { 2.0 };
    }
    sum * dy / 3.0
}

/// Neo-Hookean with nu = 0 (lambda = 0, mu = E/2) in confined compression: sigma = mu (l - 1/l), so
/// l = sqrt(q^2 + 1) - q. Hencky (tau = E ln l): l = exp(-W0(q)).
fn neo_hookean_stretch(q: f64) -> f64 {
    (q * q + 1.0).sqrt() - q
}

fn hencky_stretch(q: f64) -> f64 {
    (-lambert_w0(q)).exp()
}

fn v2(s: &SessionGuard, out: &Path) -> Result<Value> {
    // Small strain: rho g H / E = 1e-6 (mm, MPa, t/mm^3, mm/s^2).
    let small = Column {
        height: 50.0,
        e: 1e4,
        rho: 2e-5,
        g: 10.0,
    };
    let mut plot = LinePlot::new(
        "V2 self-weight column, small strain",
        "ln(cell size h [mm])",
        "ln(normalised L2 error of sigma_yy)",
    );
    let mut small_results = Vec::new();
    for kind in ShapeKind::ALL {
        let mut pts = Vec::new();
        for cells in [4, 8, 16, 32, 64] {
            let r = column(s, &small, "linear_elastic", kind, cells, 4)?;
            pts.push((small.height / cells as f64, r.stress_error(&small)));
        }
        let p = order(&pts);
        println!(
            "V2 small strain {}: errors {:?}, observed order {p:.2}",
            kind.name(),
            pts.iter().map(|x| x.1).collect::<Vec<_>>()
        );
        small_results.push(json!({ "shape": kind.name(), "h_error": pts, "order": p }));
        plot.series.push(Series {
            name: format!("{} (order {p:.2})", kind.name()),
            points: pts.iter().map(|(h, e)| (h.ln(), e.ln())).collect(),
        });
    }
    plot.save_png(out.join("verification-v2-convergence.png"))?;

    // Large deformation, AMPLE's setting (H = 50, E = 1e4, rho = 80, g = 10: rho g H / E = 4), neo-Hookean.
    let large = Column {
        height: 50.0,
        e: 1e4,
        rho: 80.0,
        g: 10.0,
    };
    let exact_top_nh = settlement(&large, large.height, neo_hookean_stretch);
    let exact_top_hencky = settlement(&large, large.height, hencky_stretch);
    println!(
        "V2 large deformation closed forms: top settlement neo-Hookean {exact_top_nh:.3}, Hencky {exact_top_hencky:.3}"
    );
    let mut large_plot = LinePlot::new(
        "V2 column, rho g H / E = 4, neo-Hookean: error vs h",
        "ln(cell size h)",
        "ln(normalised L2 error of sigma_yy)",
    );
    let mut profile = LinePlot::new(
        "V2 column, rho g H / E = 4, neo-Hookean, 16 cells",
        "initial height Y",
        "sigma_yy",
    );
    profile.series.push(Series {
        name: "exact".into(),
        points: vec![
            (0.0, -large.rho * large.g * large.height),
            (large.height, 0.0),
        ],
    });
    let mut large_results = Vec::new();
    for kind in ShapeKind::ALL {
        let mut pts = Vec::new();
        let mut top = Vec::new();
        for cells in [8, 16, 32, 64] {
            let r = match column(s, &large, "neo_hookean", kind, cells, 40) {
                Ok(r) => r,
                Err(e) => {
                    println!(
                        "V2 large deformation {} {cells} cells: failed: {e}",
                        kind.name()
                    );
                    continue;
                }
            };
            // Top points: the highest initial row, compared with the closed form at their own Y.
            let y_top = r.y0.iter().copied().fold(f64::MIN, f64::max);
            let ks: Vec<usize> = (0..r.y0.len())
                .filter(|&k| r.y0[k] > y_top - 1e-9)
                .collect();
            let u = ks.iter().map(|&k| r.uy[k]).sum::<f64>() / ks.len() as f64;
            let exact = settlement(&large, y_top, neo_hookean_stretch);
            top.push(json!({ "cells": cells, "y_top": y_top, "u_top": u, "u_exact": exact }));
            pts.push((large.height / cells as f64, r.stress_error(&large)));
            if cells == 16 {
                let mut curve: Vec<(f64, f64)> =
                    r.y0.iter().copied().zip(r.syy.iter().copied()).collect();
                curve.sort_by(|a, b| a.0.total_cmp(&b.0));
                profile.series.push(Series {
                    name: kind.name().into(),
                    points: curve,
                });
                println!(
                    "V2 large deformation {} 16 cells: top-row settlement {u:.3} (closed form at Y = {y_top}: {exact:.3})",
                    kind.name()
                );
            }
        }
        let p = order(&pts);
        println!(
            "V2 large deformation {}: errors {:?}, order (last two) {p:.2}",
            kind.name(),
            pts.iter().map(|x| x.1).collect::<Vec<_>>()
        );
        large_plot.series.push(Series {
            name: kind.name().into(),
            points: pts.iter().map(|(h, e)| (h.ln(), e.ln())).collect(),
        });
        large_results
            .push(json!({ "shape": kind.name(), "h_error": pts, "order_last_two": p, "top": top }));
    }
    large_plot.save_png(out.join("verification-v2-large-convergence.png"))?;
    profile.save_png(out.join("verification-v2-large-profile.png"))?;
    Ok(json!({
        "small_strain": small_results,
        "large_deformation": {
            "closed_form_top_settlement_neo_hookean": exact_top_nh,
            "closed_form_top_settlement_hencky": exact_top_hencky,
            "runs": large_results,
        },
    }))
}

// ---------------------------------------------------------------------------------------------------
// V3: plane wave in uniaxial strain, concrete, v0 = 1000 mm/s.

fn v3(s: &SessionGuard, out: &Path) -> Result<Value> {
    let (k, g, rho, v0, length) = (18750.0, 15254.0, 2.4e-9, 1000.0, 200.0);
    let m = k + 4.0 * g / 3.0;
    let c = f64::sqrt(m / rho);
    let sxx = -rho * c * v0;
    let mut plot = LinePlot::new(
        "V3 plane wave, concrete, v0 = 1 m/s, h = 2 mm",
        "x [mm]",
        "sigma_xx [MPa]",
    );
    let mut results = Vec::new();
    let mut front = 0.0;
    for (kind, courant) in [
        (ShapeKind::Cpdi1, 1.0),
        (ShapeKind::Cpdi1, 0.5),
        (ShapeKind::Linear, 1.0),
    ] {
        let h = 2.0;
        let particles = strip([0.0, 0.0], [length, h], h, rho)?;
        let grid = Grid::covering(Vector2::zeros(), Vector2::new(length, h), h, 2)?;
        let dt = courant * h / c;
        let mut st = setup(
            grid,
            particles,
            MaterialConfig::build_toml(&format!(
                "model = \"linear_elastic\"\nbulk_modulus = {k}\nshear_modulus = {g}"
            ))?,
            kind,
            TimeIntegration {
                dt,
                dt_min: dt,
                ..TimeIntegration::default()
            },
            "v3_",
        );
        st.params.boxes = vec![
            node_box(
                "rollers",
                [-FAR, -FAR],
                [FAR, FAR],
                [Motion::Free, Motion::Velocity(0.0)],
            ),
            node_box(
                "piston",
                [-FAR, -FAR],
                [1e-9, FAR],
                [Motion::Velocity(v0), Motion::Velocity(0.0)],
            ),
        ];
        let mut sim = Simulation::new(st)?;
        let steps = (0.75 * length / (c * dt)).round() as usize;
        for _ in 0..steps {
            sim.advance(s)?;
        }
        front = c * sim.state.counters.time;
        let p = &sim.state.particles;
        let window: Vec<usize> = (0..p.len())
            .filter(|&q| p.x[q].x > 0.25 * length && p.x[q].x < front - 0.25 * length)
            .collect();
        let mean = |f: &dyn Fn(usize) -> f64| {
            window.iter().map(|&q| f(q)).sum::<f64>() / window.len() as f64
        };
        let (ev, es) = (
            (mean(&|q| p.v[q].x) - v0) / v0,
            (mean(&|q| p.stress[q][(0, 0)]) - sxx) / sxx.abs(),
        );
        let syy_exact = (k - 2.0 * g / 3.0) / m * sxx;
        let ey = (mean(&|q| p.stress[q][(1, 1)]) - syy_exact) / syy_exact.abs();
        let overshoot = p.stress.iter().map(|t| t[(0, 0)]).fold(0.0f64, f64::min) / sxx - 1.0;
        println!(
            "V3 {} Courant {courant}: mean errors v {ev:+.4}, sigma_xx {es:+.4}, sigma_yy {ey:+.4}; peak overshoot {overshoot:.3}",
            kind.name()
        );
        results.push(json!({ "shape": kind.name(), "courant": courant, "error_v": ev, "error_sxx": es, "error_syy": ey, "peak_overshoot": overshoot }));
        let mut curve: Vec<(f64, f64)> =
            p.x.iter()
                .zip(&p.stress)
                .filter(|(x, _)| x.y < 0.5 * h)
                .map(|(x, t)| (x.x, t[(0, 0)]))
                .collect();
        curve.sort_by(|a, b| a.0.total_cmp(&b.0));
        plot.series.push(Series {
            name: format!("{} Courant {courant}", kind.name()),
            points: curve,
        });
    }
    plot.series.insert(
        0,
        Series {
            name: "exact".into(),
            points: vec![(0.0, sxx), (front, sxx), (front, 0.0), (length, 0.0)],
        },
    );
    plot.save_png(out.join("verification-v3-wave.png"))?;
    Ok(json!({ "c_L": c, "sigma_xx_exact": sxx, "runs": results }))
}

// ---------------------------------------------------------------------------------------------------
// V6: plane-strain cantilever L = 1000 mm, H = 100 mm, E = 30000 MPa, nu = 0.2, rho = 2.4e-9 t/mm^3.

fn v6(s: &SessionGuard, out: &Path) -> Result<Value> {
    let (length, height, e, nu, rho): (f64, f64, f64, f64, f64) =
        (1000.0, 100.0, 30000.0, 0.2, 2.4e-9);
    let bl = 1.875_104_068_711_961_f64;
    let w_exact = bl
        * bl
        * (e / (1.0 - nu * nu) * height.powi(3) / 12.0 / (rho * height * length.powi(4))).sqrt();
    let period = 2.0 * PI / w_exact;
    let sigma = (bl.cosh() + bl.cos()) / (bl.sinh() + bl.sin());
    let mode = |x: f64| {
        let b = bl * x / length;
        (b.cosh() - b.cos() - sigma * (b.sinh() - b.sin()))
            / (bl.cosh() - bl.cos() - sigma * (bl.sinh() - bl.sin()))
    };
    let v_tip = 10.0;
    let mut plot = LinePlot::new(
        "V6 cantilever L/H = 10: tip deflection",
        "t / T_EB [-]",
        "tip deflection [mm]",
    );
    plot.series.push(Series {
        name: "Euler-Bernoulli".into(),
        points: (0..=300)
            .map(|q| {
                let t = 2.0 * q as f64 / 300.0 * period;
                (t / period, v_tip / w_exact * (w_exact * t).sin())
            })
            .collect(),
    });
    let mut results = Vec::new();
    for kind in ShapeKind::ALL {
        for cells in [2, 4, 8] {
            let h = height / cells as f64;
            let mut particles = strip([0.0, 0.0], [length, height], h, rho)?;
            for q in 0..particles.len() {
                particles.v[q] = Vector2::new(0.0, v_tip * mode(particles.x[q].x));
            }
            let tip = (0..particles.len())
                .min_by(|&a, &b| {
                    let d = |q: usize| (particles.x[q] - Vector2::new(length, 0.5 * height)).norm();
                    d(a).total_cmp(&d(b))
                })
                .ok_or("no points")?;
            let y_tip0 = particles.x[tip].y;
            let grid = Grid::covering(Vector2::zeros(), Vector2::new(length, height), h, 2)?;
            let dt = period / 32.0;
            let mut st = setup(
                grid,
                particles,
                MaterialConfig::build_toml(&format!(
                    "model = \"linear_elastic\"\nyoungs_modulus = {e}\npoisson_ratio = {nu}"
                ))?,
                kind,
                TimeIntegration {
                    dt,
                    dt_min: dt,
                    ..TimeIntegration::default()
                },
                "v6_",
            );
            st.params.boxes = vec![node_box(
                "clamp",
                [-FAR, -FAR],
                [1e-9, FAR],
                [Motion::Velocity(0.0); 2],
            )];
            let mut sim = Simulation::new(st)?;
            let (mut t_prev, mut u_prev) = (0.0, 0.0);
            let mut crossings = Vec::new();
            let mut curve = vec![(0.0, 0.0)];
            for _ in 0..64 {
                sim.advance(s)?;
                let u = sim.state.particles.x[tip].y - y_tip0;
                if (u_prev > 0.0 && u <= 0.0) || (u_prev < 0.0 && u >= 0.0) {
                    crossings
                        .push(t_prev + (sim.state.counters.time - t_prev) * u_prev / (u_prev - u));
                }
                curve.push((sim.state.counters.time / period, u));
                (t_prev, u_prev) = (sim.state.counters.time, u);
            }
            let [first, .., last] = crossings[..] else {
                return Err("fewer than two zero crossings".into());
            };
            let w = PI * (crossings.len() - 1) as f64 / (last - first);
            let dev = w / w_exact - 1.0;
            println!(
                "V6 {} {cells} cells through the depth: w1 = {w:.2} rad/s, Euler-Bernoulli {w_exact:.2}, deviation {dev:+.4}",
                kind.name()
            );
            results.push(json!({ "shape": kind.name(), "cells_through_depth": cells, "w1": w, "deviation": dev }));
            if cells == 4 && matches!(kind, ShapeKind::Cpdi1 | ShapeKind::Bspline2) {
                plot.series.push(Series {
                    name: format!("{} 4 cells", kind.name()),
                    points: curve,
                });
            }
        }
    }
    plot.save_png(out.join("verification-v6-cantilever.png"))?;
    Ok(json!({ "w1_euler_bernoulli": w_exact, "runs": results }))
}

fn main() -> Result<()> {
    let out = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "docs/img".into()));
    let s = Session::get()?;
    // LU; Newton to 1e-10 relative, with an absolute floor per problem above the round-off of its nodal
    // forces (strains are computed as F - I, so a residual cannot fall below about 1e-16 E V / h).
    for (prefix, atol) in [("v1_", 1e-12), ("v2_", 1e-11), ("v3_", 1e-8), ("v6_", 1e-7)] {
        petsc::apply_default_options(
            &s,
            &format!(
                "-{prefix}ksp_type preonly -{prefix}pc_type lu -{prefix}snes_rtol 1e-10 -{prefix}snes_atol {atol}"
            ),
        )?;
    }
    let results = json!({
        "v1": v1(&s, &out)?,
        "v2": v2(&s, &out)?,
        "v3": v3(&s, &out)?,
        "v6": v6(&s, &out)?,
    });
    std::fs::create_dir_all(&out)?;
    std::fs::write(
        out.join("verification-results.json"),
        serde_json::to_string_pretty(&results)?,
    )?;
    println!("wrote {}", out.join("verification-results.json").display());
    Ok(())
}
