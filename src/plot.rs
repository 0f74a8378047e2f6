//! Small PNG plotting helpers on `plotters` (bitmap backend, system "sans-serif" font, e.g. DejaVu Sans).
//!
//! - [`LinePlot`]: x-y curves (stress-strain, force-displacement, energy histories).
//! - [`ScatterField`]: a scalar per point drawn as coloured squares (viridis) with a colour bar and an
//!   equal aspect ratio; coordinates in mm (damage or eta_bar maps over the material points).
//!
//! Files are written to a temporary sibling (`.<name>.tmp-<pid>.png`) and renamed into place, so a
//! reader never sees a half-written PNG.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

/// Plotting failure (invalid data, drawing backend, file system).
#[derive(Clone, Debug, thiserror::Error)]
pub enum PlotError {
    /// The data cannot be plotted (empty, mismatched lengths, no finite values).
    #[error("cannot plot `{title}`: {reason}")]
    InvalidData {
        /// The plot's title.
        title: String,
        /// What is wrong with the data.
        reason: String,
    },
    /// The drawing backend failed (font, encoder).
    #[error("drawing `{path}` failed: {message}")]
    Draw {
        /// The image file.
        path: String,
        /// The backend's message.
        message: String,
    },
    /// Renaming or creating the output file failed.
    #[error("cannot write `{path}`: {message}")]
    Io {
        /// The image file.
        path: String,
        /// The system's message.
        message: String,
    },
}

const FONT: &str = "sans-serif";

/// One named curve.
#[derive(Clone, Debug, Default)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// Points in drawing order; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
}

/// x-y line plot with a legend.
#[derive(Clone, Debug, Default)]
pub struct LinePlot {
    /// Title above the plot.
    pub title: String,
    /// x axis label, with unit, e.g. `"strain F11 - 1 [-]"`.
    pub x_label: String,
    /// y axis label, with unit, e.g. `"P11 [MPa]"`.
    pub y_label: String,
    /// The curves.
    pub series: Vec<Series>,
}

/// Scalar field over points, drawn as squares of side `point_size` (mm) coloured by `value`.
#[derive(Clone, Debug, Default)]
pub struct ScatterField {
    /// Title above the plot.
    pub title: String,
    /// x coordinates (mm).
    pub x: Vec<f64>,
    /// y coordinates (mm).
    pub y: Vec<f64>,
    /// Values, one per point.
    pub value: Vec<f64>,
    /// Colour-bar label with unit, e.g. `"damage [-]"`.
    pub value_label: String,
    /// Colour range; `None` = min/max of the finite values.
    pub range: Option<(f64, f64)>,
    /// Side of each square (mm), e.g. the particle spacing.
    pub point_size: f64,
}

fn draw_err<E: std::fmt::Debug>(path: &Path) -> impl Fn(E) -> PlotError + '_ {
    move |e| PlotError::Draw {
        path: path.display().to_string(),
        message: format!("{e:?}"),
    }
}

/// Min/max of finite values, padded by `pad` of the span (or by 1 for a degenerate span).
fn padded_range(values: impl Iterator<Item = f64>, pad: f64) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if lo > hi {
        return None;
    }
    let span = hi - lo;
    if span <= 1e-12 * lo.abs().max(hi.abs()) || span == 0.0 {
        let d = if lo == 0.0 { 1.0 } else { 0.05 * lo.abs() };
        Some((lo - d, hi + d))
    } else {
        Some((lo - pad * span, hi + pad * span))
    }
}

/// Draws with `draw` into a temporary PNG next to `path`, then renames it into place.
fn write_png_atomically(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> Result<(), PlotError>,
) -> Result<(), PlotError> {
    let io_err = |e: std::io::Error| PlotError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(io_err)?;
    }
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "plot".into());
    let tmp: PathBuf = path.with_file_name(format!(".{stem}.tmp-{}.png", std::process::id()));
    let result = (|| {
        let root = BitMapBackend::new(&tmp, size).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(path))?;
        draw(&root)?;
        root.present().map_err(draw_err(path))
    })();
    match result {
        Ok(()) => std::fs::rename(&tmp, path).map_err(io_err),
        Err(e) => {
            // Best effort: do not leave a partial temporary behind; the drawing error is what matters.
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}

const LINE_COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

impl LinePlot {
    /// An empty plot with title and axis labels.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
        }
    }

    /// Adds a curve.
    pub fn with_series(mut self, name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        self.series.push(Series {
            name: name.into(),
            points,
        });
        self
    }

    /// Renders a 1000 x 700 PNG.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), PlotError> {
        let path = path.as_ref();
        let invalid = |reason: &str| PlotError::InvalidData {
            title: self.title.clone(),
            reason: reason.into(),
        };
        let pts = || {
            self.series
                .iter()
                .flat_map(|s| s.points.iter())
                .filter(|p| p.0.is_finite() && p.1.is_finite())
        };
        let (x0, x1) =
            padded_range(pts().map(|p| p.0), 0.02).ok_or_else(|| invalid("no finite points"))?;
        let (y0, y1) =
            padded_range(pts().map(|p| p.1), 0.05).ok_or_else(|| invalid("no finite points"))?;
        write_png_atomically(path, (1000, 700), |root| {
            let e = draw_err(path);
            let mut chart = ChartBuilder::on(root)
                .caption(&self.title, (FONT, 26))
                .margin(15)
                .x_label_area_size(55)
                .y_label_area_size(85)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(&e)?;
            chart
                .configure_mesh()
                .x_desc(&self.x_label)
                .y_desc(&self.y_label)
                .label_style((FONT, 16))
                .axis_desc_style((FONT, 20))
                .light_line_style(RGBColor(235, 235, 235))
                .draw()
                .map_err(&e)?;
            for (k, s) in self.series.iter().enumerate() {
                let colour = LINE_COLOURS[k % LINE_COLOURS.len()];
                let data = s
                    .points
                    .iter()
                    .copied()
                    .filter(|p| p.0.is_finite() && p.1.is_finite());
                chart
                    .draw_series(LineSeries::new(data, colour.stroke_width(2)))
                    .map_err(&e)?
                    .label(s.name.clone())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                    });
            }
            if self.series.iter().any(|s| !s.name.is_empty()) {
                chart
                    .configure_series_labels()
                    .label_font((FONT, 16))
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK)
                    .position(SeriesLabelPosition::UpperRight)
                    .draw()
                    .map_err(&e)?;
            }
            Ok(())
        })
    }
}

/// Viridis colour map at `t` in [0, 1] (piecewise linear through 9 samples of the matplotlib map).
pub fn viridis(t: f64) -> RGBColor {
    const C: [(f64, f64, f64); 9] = [
        (68.0, 1.0, 84.0),
        (71.0, 44.0, 122.0),
        (59.0, 81.0, 139.0),
        (44.0, 113.0, 142.0),
        (33.0, 144.0, 141.0),
        (39.0, 173.0, 129.0),
        (92.0, 200.0, 99.0),
        (170.0, 220.0, 50.0),
        (253.0, 231.0, 37.0),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = t * (C.len() - 1) as f64;
    let i = (s.floor() as usize).min(C.len() - 2);
    let f = s - i as f64;
    let lerp = |a: f64, b: f64| (a + f * (b - a)).round() as u8;
    RGBColor(
        lerp(C[i].0, C[i + 1].0),
        lerp(C[i].1, C[i + 1].1),
        lerp(C[i].2, C[i + 1].2),
    )
}

impl ScatterField {
    /// Checks the data and returns the plotted extent `[x0, x1, y0, y1]` (mm, padded by half a point) and
    /// the colour range `(v0, v1)`.
    fn extent(&self) -> Result<([f64; 4], (f64, f64)), PlotError> {
        let invalid = |reason: String| PlotError::InvalidData {
            title: self.title.clone(),
            reason,
        };
        let n = self.value.len();
        if self.x.len() != n || self.y.len() != n {
            return Err(invalid(format!(
                "x, y and value have different lengths ({}, {}, {n})",
                self.x.len(),
                self.y.len()
            )));
        }
        if !(self.point_size.is_finite() && self.point_size > 0.0) {
            return Err(invalid(format!(
                "point_size = {} must be > 0",
                self.point_size
            )));
        }
        let half = 0.5 * self.point_size;
        let (x0, x1) = padded_range(self.x.iter().copied(), 0.0)
            .ok_or_else(|| invalid("no finite x".into()))?;
        let (y0, y1) = padded_range(self.y.iter().copied(), 0.0)
            .ok_or_else(|| invalid("no finite y".into()))?;
        let (v0, v1) = match self.range {
            Some((a, b)) if a.is_finite() && b.is_finite() && b > a => (a, b),
            Some((a, b)) => {
                return Err(invalid(format!(
                    "colour range ({a}, {b}) must be finite and increasing"
                )));
            }
            None => padded_range(self.value.iter().copied(), 0.0)
                .ok_or_else(|| invalid("no finite values".into()))?,
        };
        Ok(([x0 - half, x1 + half, y0 - half, y1 + half], (v0, v1)))
    }

    /// Renders the field with an equal aspect ratio (image height follows the data extent) and a colour bar.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), PlotError> {
        let path = path.as_ref();
        let n = self.value.len();
        let half = 0.5 * self.point_size;
        let ([x0, x1, y0, y1], (v0, v1)) = self.extent()?;

        // Layout (pixels): title band, plot with label areas, colour bar strip on the right.
        const TITLE: u32 = 45;
        const MARGIN: u32 = 15;
        const XLAB: u32 = 50;
        const YLAB: u32 = 70;
        const BAR: u32 = 150;
        let plot_w: u32 = 800;
        let aspect = (y1 - y0) / (x1 - x0);
        let plot_h = ((plot_w as f64 * aspect).round() as u32).clamp(150, 1400);
        // If clamped, widen the data range of the other axis so that 1 mm is the same in x and y.
        let scale = (plot_w as f64 / (x1 - x0)).min(plot_h as f64 / (y1 - y0)); // px per mm
        let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
        let (hx, hy) = (0.5 * plot_w as f64 / scale, 0.5 * plot_h as f64 / scale);
        let (x0, x1, y0, y1) = (cx - hx, cx + hx, cy - hy, cy + hy);
        let width = plot_w + YLAB + 2 * MARGIN + BAR;
        let height = plot_h + XLAB + 2 * MARGIN + TITLE;

        write_png_atomically(path, (width, height), |root| {
            let e = draw_err(path);
            let body = root.titled(&self.title, (FONT, 26)).map_err(&e)?;
            let (left, right) = body.split_horizontally(plot_w + YLAB + 2 * MARGIN);
            let mut chart = ChartBuilder::on(&left)
                .margin(MARGIN)
                .x_label_area_size(XLAB)
                .y_label_area_size(YLAB)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(&e)?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc("x [mm]")
                .y_desc("y [mm]")
                .label_style((FONT, 15))
                .axis_desc_style((FONT, 18))
                .draw()
                .map_err(&e)?;
            let squares = (0..n)
                .filter(|&i| self.x[i].is_finite() && self.y[i].is_finite())
                .map(|i| {
                    let (x, y, v) = (self.x[i], self.y[i], self.value[i]);
                    let colour = if v.is_finite() {
                        viridis((v - v0) / (v1 - v0))
                    } else {
                        RGBColor(200, 200, 200)
                    };
                    Rectangle::new(
                        [(x - half, y - half), (x + half, y + half)],
                        colour.filled(),
                    )
                });
            chart.draw_series(squares).map_err(&e)?;

            let mut bar = ChartBuilder::on(&right)
                .margin_top(MARGIN)
                .margin_bottom(MARGIN + XLAB)
                .margin_left(10)
                .margin_right(45)
                .y_label_area_size(90)
                .build_cartesian_2d(0.0..1.0, v0..v1)
                .map_err(&e)?;
            bar.configure_mesh()
                .disable_mesh()
                .disable_x_axis()
                .y_desc(&self.value_label)
                .label_style((FONT, 14))
                .axis_desc_style((FONT, 16))
                .draw()
                .map_err(&e)?;
            const SLICES: usize = 128;
            let dv = (v1 - v0) / SLICES as f64;
            bar.draw_series((0..SLICES).map(|k| {
                let lo = v0 + k as f64 * dv;
                Rectangle::new(
                    [(0.0, lo), (1.0, lo + dv)],
                    viridis((k as f64 + 0.5) / SLICES as f64).filled(),
                )
            }))
            .map_err(&e)?;
            Ok(())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp_dir(name: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("mpm_concrete_plot_{name}_{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn png_size(path: &Path) -> (u32, u32) {
        let bytes = std::fs::read(path).unwrap();
        assert_eq!(&bytes[1..4], b"PNG", "not a PNG");
        let be =
            |o: usize| u32::from_be_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
        (be(16), be(20))
    }

    #[test]
    fn line_plot_writes_png_and_no_temporary() {
        let d = tmp_dir("line");
        let p = d.join("curve.png");
        let pts: Vec<(f64, f64)> = (0..50)
            .map(|i| (i as f64 * 0.1, (i as f64 * 0.1).sin()))
            .collect();
        LinePlot::new("sine", "x [-]", "y [-]")
            .with_series("sin", pts)
            .with_series("flat", vec![(0.0, 0.5), (5.0, 0.5)])
            .save_png(&p)
            .unwrap();
        assert_eq!(png_size(&p), (1000, 700));
        let names: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn invalid_data_is_an_error_not_a_panic() {
        let d = tmp_dir("invalid");
        let p = d.join("x.png");
        assert!(matches!(
            LinePlot::new("t", "x", "y").save_png(&p),
            Err(PlotError::InvalidData { .. })
        ));
        let s = ScatterField {
            title: "t".into(),
            x: vec![0.0],
            y: vec![],
            value: vec![1.0],
            point_size: 1.0,
            ..Default::default()
        };
        assert!(matches!(s.save_png(&p), Err(PlotError::InvalidData { .. })));
        let s = ScatterField {
            x: vec![0.0],
            y: vec![0.0],
            value: vec![1.0],
            point_size: 0.0,
            ..Default::default()
        };
        assert!(matches!(s.save_png(&p), Err(PlotError::InvalidData { .. })));
        assert!(!p.exists());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn scatter_field_has_equal_aspect() {
        let d = tmp_dir("scatter");
        let p = d.join("field.png");
        // 40 mm x 20 mm block, 1 mm squares
        let (mut x, mut y, mut v) = (vec![], vec![], vec![]);
        for i in 0..40 {
            for j in 0..20 {
                x.push(i as f64 + 0.5);
                y.push(j as f64 + 0.5);
                v.push((-(((i as f64 - 20.0).powi(2) + (j as f64 - 10.0).powi(2)) / 30.0)).exp());
            }
        }
        let s = ScatterField {
            title: "damage".into(),
            x,
            y,
            value: v,
            value_label: "damage [-]".into(),
            range: Some((0.0, 1.0)),
            point_size: 1.0,
        };
        s.save_png(&p).unwrap();
        let (w, h) = png_size(&p);
        // plot area 800 x 400 px plus fixed decorations
        assert_eq!((w, h), (800 + 70 + 30 + 150, 400 + 50 + 30 + 45));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn viridis_endpoints() {
        assert_eq!(viridis(0.0), RGBColor(68, 1, 84));
        assert_eq!(viridis(1.0), RGBColor(253, 231, 37));
        assert_eq!(viridis(f64::NAN), RGBColor(68, 1, 84));
    }
}
