//! Draws `docs/img/shape-cpdi.png`: a 5 x 5 mm patch of the background grid (h = 1 mm), one CPDI1 material
//! point whose square domain (1 point per cell, half-edges 0.5 mm) has been deformed by
//! `F = [[1.3, 0.5], [0.2, 1.1]]`, its four corners, and its support nodes coloured and labelled by `S_Ip`.
//!
//! Run: `cargo run --release --example cpdi_figure [output.png]` (default `docs/img/shape-cpdi.png`).

use std::error::Error;

use nalgebra::{Matrix2, Vector2};
use plotters::prelude::*;

use mpm_concrete::grid::Grid;
use mpm_concrete::particles::Particles;
use mpm_concrete::shape::{ShapeKind, ShapeTable};

fn main() -> Result<(), Box<dyn Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "docs/img/shape-cpdi.png".into());
    let grid = Grid::new(Vector2::zeros(), 1.0, [5, 5])?;

    // One point, domain deformed by F: r_p = F r_p^0, corners x_p -+ r1 -+ r2.
    let f = Matrix2::new(1.3, 0.5, 0.2, 1.1);
    let mut particles = Particles::new();
    particles.push(
        Vector2::new(2.45, 2.4),
        1.0,
        2.4e-9,
        Matrix2::identity() * 0.5,
        0,
    );
    particles.set_deformation(0, f);

    let mut table = ShapeTable::new();
    table.compute(ShapeKind::Cpdi1, &grid, &particles)?;
    let weights = table.weights(0);
    let s_max = weights.iter().map(|w| w.value).fold(0.0, f64::max);

    let root = BitMapBackend::new(&out, (900, 900)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "CPDI1 shape functions: {} support nodes, coloured by S_Ip",
                weights.len()
            ),
            ("sans-serif", 26),
        )
        .margin(20)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(-0.3..5.3, -0.3..5.3)?;
    chart
        .configure_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .x_labels(6)
        .y_labels(6)
        .label_style(("sans-serif", 18))
        .axis_desc_style(("sans-serif", 20))
        .disable_mesh()
        .draw()?;

    let line = ShapeStyle::from(&BLACK.mix(0.35)).stroke_width(1);
    for k in 0..=5 {
        let c = f64::from(k);
        chart.draw_series(LineSeries::new([(c, 0.0), (c, 5.0)], line))?;
        chart.draw_series(LineSeries::new([(0.0, c), (5.0, c)], line))?;
    }

    let corners = particles.corners(0);
    let pts: Vec<(f64, f64)> = corners.iter().map(|c| (c.x, c.y)).collect();
    chart.draw_series([Polygon::new(pts.clone(), BLUE.mix(0.15).filled())])?;
    chart.draw_series([PathElement::new(
        [pts.clone(), vec![pts[0]]].concat(),
        BLUE.stroke_width(3),
    )])?;
    for (c, &(x, y)) in pts.iter().enumerate() {
        chart.draw_series([Circle::new((x, y), 6, BLUE.filled())])?;
        chart.draw_series([Text::new(
            format!("x{}", c + 1),
            (x + 0.06, y - 0.06),
            ("sans-serif", 22).into_font(),
        )])?;
    }
    let xp = particles.x[0];
    chart.draw_series([Cross::new((xp.x, xp.y), 9, RED.stroke_width(3))])?;
    chart.draw_series([Text::new(
        "x_p",
        (xp.x + 0.08, xp.y + 0.16),
        ("sans-serif", 22).into_font().color(&RED),
    )])?;

    for w in weights {
        let xi = grid.node_position(w.node as usize);
        let colour = ViridisRGB::get_color_normalized(w.value, 0.0, s_max);
        chart.draw_series([Circle::new((xi.x, xi.y), 14, colour.filled())])?;
        chart.draw_series([Circle::new((xi.x, xi.y), 14, BLACK.stroke_width(1))])?;
        chart.draw_series([Text::new(
            format!("{:.3}", w.value),
            (xi.x + 0.08, xi.y + 0.22),
            ("sans-serif", 18).into_font(),
        )])?;
    }
    chart.draw_series([Text::new(
        "F = [[1.3, 0.5], [0.2, 1.1]],  r_i = F r_i^0;  colour: viridis from 0 (dark) to max S_Ip (yellow)",
        (0.0, -0.2),
        ("sans-serif", 17).into_font(),
    )])?;
    root.present()?;
    println!(
        "wrote {out}: {} support nodes, sum S = {:.15}",
        weights.len(),
        weights.iter().map(|w| w.value).sum::<f64>()
    );
    Ok(())
}
