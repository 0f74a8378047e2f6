//! The run-control sections: `[run]`, `[time]`, `[grid]`, `[shape]` and `[extrusion]`, with their checks.

use super::{Check, ConfigError, shown};
use crate::input::serde_defaults;
use crate::model::{DEFAULT_MASS_TOLERANCE, InitialAcceleration, Method, TimeIntegration};
use crate::shape::ShapeKind;
use crate::space::Frame;
use serde::Deserialize;
use std::path::PathBuf;

/// `[extrusion]`: the set-up of the file, read as a plane (x, y) one, extruded along z to a plate of
/// finite thickness with free faces and run in three dimensions (docs/theory.md, "Three dimensions").
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExtrusionSection {
    /// Plate thickness (mm), `0 <= z <= thickness`; a multiple of `grid.cell_size`.
    pub thickness: f64,
    /// The z (mm) of the section on which the crack is measured and the damage maps are drawn (the layer
    /// of points seeded nearest it); default: the mid-plane.
    pub section_z: Option<f64>,
}

/// `[run]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunSection {
    /// Name of the run (titles, file names).
    pub name: String,
    /// Number of time steps.
    pub steps: usize,
    /// Output directory (relative to the working directory); default `runs/<name>`.
    pub output_dir: Option<PathBuf>,
    /// Write point fields (HDF5), damage maps (PNG) and the checkpoint every this many steps; 0: only at
    /// the end of the run (and when it is interrupted or a step fails), so a run killed outright cannot
    /// be resumed.
    #[serde(default = "default_output_every")]
    pub output_every: usize,
    /// PETSc options applied as defaults; options given on the command line win.
    #[serde(default)]
    pub petsc_options: String,
}

serde_defaults! {
    default_output_every: usize = 100;
}

/// `[time]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeSection {
    /// Time step (s), > 0.
    #[serde(default = "default_dt")]
    pub dt: f64,
    /// Smallest time step of the retry halving (s); default dt/64.
    pub dt_min: Option<f64>,
    /// Newmark beta, in (0, 0.5].
    #[serde(default = "default_beta")]
    pub beta: f64,
    /// Newmark gamma, in [0.5, 1].
    #[serde(default = "default_gamma")]
    pub gamma: f64,
    /// Static equilibrium each step (no inertia).
    #[serde(default)]
    pub quasi_static: bool,
    /// Acceleration of a dynamic run at t = 0: "consistent" (default, `M a_0 = f_ext - f_int`) or "zero".
    #[serde(default)]
    pub initial_acceleration: InitialAcceleration,
}

serde_defaults! {
    default_dt: f64 = TimeIntegration::DEFAULT_DT;
    default_beta: f64 = TimeIntegration::DEFAULT_BETA;
    default_gamma: f64 = TimeIntegration::DEFAULT_GAMMA;
}

impl Default for TimeSection {
    fn default() -> Self {
        Self {
            dt: default_dt(),
            dt_min: None,
            beta: default_beta(),
            gamma: default_gamma(),
            quasi_static: false,
            initial_acceleration: InitialAcceleration::default(),
        }
    }
}

/// `[grid]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridSection {
    /// Cell size h (mm), > 0.
    pub cell_size: f64,
    /// Empty cells around the bodies' bounding box.
    #[serde(default = "default_margin")]
    pub margin_cells: usize,
    /// Nodes whose mass is at most this fraction of the largest nodal mass carry no unknowns (they
    /// only touch the fringe of a particle domain and would make the system nearly singular).
    #[serde(default = "default_mass_tolerance")]
    pub mass_tolerance: f64,
    /// The whole set-up turned by this angle (degrees, counter-clockwise, about the out-of-plane axis
    /// through the origin) inside the axis-aligned grid, to measure the grid's bias; results are
    /// reported back in the specimen's frame. Default 0 (plane runs only).
    #[serde(default)]
    pub rotation: f64,
}

impl GridSection {
    /// The specimen's frame on the grid (`rotation`): the one place where the angle becomes a frame.
    pub fn frame(&self) -> Frame {
        Frame::from_degrees(self.rotation)
    }
}

serde_defaults! {
    default_mass_tolerance: f64 = DEFAULT_MASS_TOLERANCE;
    default_margin: usize = 3;
}

/// `[shape]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShapeSection {
    /// Interpolator: "linear", "gimp", "cpdi1" (default), "cpdi2", "bspline2".
    #[serde(default = "default_kind")]
    pub kind: ShapeKind,
    /// Material points per cell and direction.
    #[serde(default = "default_ppc")]
    pub points_per_cell: usize,
    /// The CPDI corners' hold on their cell, in cell widths (default 0: plain CPDI; within `[0, 0.25]`):
    /// a domain corner that crossed a grid line away from its domain's centre by up to this much keeps its
    /// cell's functions, blending into the next cell's hats up to twice this (docs/shape-functions.md).
    #[serde(default = "default_corner_hold")]
    pub corner_hold: f64,
    /// Discretisation: "mpm" (default; grid reset each step) or "fem" (points fixed at the Gauss points of
    /// the grid cells, bilinear elements, no grid reset; requires `kind = "linear"`).
    #[serde(default)]
    pub method: Method,
}

serde_defaults! {
    default_kind: ShapeKind = ShapeKind::Cpdi1;
    default_ppc: usize = 2;
    default_corner_hold: f64 = crate::shape::DEFAULT_CORNER_HOLD;
}

impl Default for ShapeSection {
    fn default() -> Self {
        Self {
            kind: default_kind(),
            points_per_cell: default_ppc(),
            corner_hold: default_corner_hold(),
            method: Method::default(),
        }
    }
}

/// The longest run name (bytes): a file name's limit on common file systems.
const NAME_MAX: usize = 255;

/// Invisible format characters (Unicode category Cf: soft hyphen, zero-width and joiner characters,
/// bidirectional marks, embeddings, overrides and isolates, the byte-order mark) that make a directory
/// name display as something else.
fn invisible(ch: char) -> bool {
    matches!(ch, '\u{ad}' | '\u{61c}' | '\u{180e}' | '\u{200b}'..='\u{200f}' | '\u{202a}'..='\u{202e}'
        | '\u{2060}'..='\u{206f}' | '\u{feff}' | '\u{fff9}'..='\u{fffb}')
}

/// A run name for an error message: quoted with escapes, cut after 60 characters.
fn shown_name(name: &str) -> String {
    if name.chars().count() <= 60 {
        format!("{name:?}")
    } else {
        let head: String = name.chars().take(60).collect();
        format!("{head:?}... ({} bytes)", name.len())
    }
}

impl RunSection {
    /// Checks `[run]`.
    pub(super) fn validate(&self, c: Check) -> Result<(), ConfigError> {
        let name = &self.name;
        if name.trim().is_empty()
            || name.contains(['/', '\\'])
            || name == "."
            || name == ".."
            || name.len() > NAME_MAX
            || name.chars().any(|ch| ch.is_control() || invisible(ch))
        {
            return Err(c.bad(
                "run.name",
                shown_name(name),
                "a non-empty name of at most 255 bytes without / or \\, control or invisible format \
                 characters (it names the output directory runs/<name>)",
            ));
        }
        if self.steps == 0 {
            return Err(c.bad("run.steps", "0".into(), "at least one step"));
        }
        Ok(())
    }
}

impl TimeSection {
    /// The model's time integration of this section: unset keys take the defaults of
    /// [`TimeIntegration::with_dt`] (`dt_min = dt / 64`).
    pub fn integration(&self) -> TimeIntegration {
        TimeIntegration {
            dt: self.dt,
            dt_min: self
                .dt_min
                .unwrap_or(TimeIntegration::with_dt(self.dt).dt_min),
            beta: self.beta,
            gamma: self.gamma,
            quasi_static: self.quasi_static,
            initial_acceleration: self.initial_acceleration,
        }
    }

    /// Checks `[time]`.
    pub(super) fn validate(&self, c: Check) -> Result<(), ConfigError> {
        let (lo, hi) = super::DT_RANGE;
        c.ensure(
            self.dt.is_finite() && self.dt >= lo && self.dt <= hi,
            "time.dt",
            shown(self.dt),
            "a time step in [1e-12, 1000] s (the CT demo takes 1e-6)",
        )?;
        if let Some(m) = self.dt_min {
            c.ensure(
                m >= lo && m <= self.dt,
                "time.dt_min",
                shown(m),
                "1e-12 <= dt_min <= dt (s): the smallest step of the retry halving",
            )?;
        }
        c.ensure(
            self.beta > 0.0 && self.beta <= 0.5,
            "time.beta",
            shown(self.beta),
            "Newmark beta in (0, 0.5]; 0 (explicit) is not supported",
        )?;
        c.ensure(
            (0.5..=1.0).contains(&self.gamma),
            "time.gamma",
            shown(self.gamma),
            "Newmark gamma in [0.5, 1]",
        )
    }
}

impl GridSection {
    /// Checks `[grid]`.
    pub(super) fn validate(&self, c: Check) -> Result<(), ConfigError> {
        c.ensure(
            self.cell_size.is_finite() && self.cell_size > 0.0,
            "grid.cell_size",
            shown(self.cell_size),
            "a cell size > 0 (mm)",
        )?;
        c.ensure(
            (0.0..1e-2).contains(&self.mass_tolerance),
            "grid.mass_tolerance",
            shown(self.mass_tolerance),
            "a fraction in [0, 0.01)",
        )?;
        c.ensure(
            self.rotation.is_finite() && self.rotation.abs() <= 360.0,
            "grid.rotation",
            self.rotation.to_string(),
            "an angle from -360 to 360 (degrees)",
        )
    }
}

impl ShapeSection {
    /// Checks `[shape]`.
    pub(super) fn validate(&self, c: Check) -> Result<(), ConfigError> {
        let ppc = self.points_per_cell;
        c.ensure(
            (1..=8).contains(&ppc),
            "shape.points_per_cell",
            ppc.to_string(),
            "1 to 8 points per direction",
        )?;
        c.ensure(
            (0.0..=0.25).contains(&self.corner_hold),
            "shape.corner_hold",
            shown(self.corner_hold),
            "0 (plain CPDI) to 0.25 cell widths",
        )?;
        c.ensure(
            self.corner_hold == 0.0 || matches!(self.kind, ShapeKind::Cpdi1 | ShapeKind::Cpdi2),
            "shape.corner_hold",
            shown(self.corner_hold),
            "0 unless kind is \"cpdi1\" or \"cpdi2\" (the hold is a CPDI corner's)",
        )?;
        if self.method == Method::Fem {
            c.ensure(
                self.kind == ShapeKind::Linear,
                "shape.kind",
                self.kind.name().into(),
                "\"linear\" with method = \"fem\" (bilinear elements)",
            )?;
            c.ensure(
                (1..=3).contains(&ppc),
                "shape.points_per_cell",
                ppc.to_string(),
                "1, 2 or 3 Gauss points per direction with method = \"fem\"",
            )?;
        }
        Ok(())
    }
}

impl ExtrusionSection {
    /// Checks `[extrusion]` of a run on a grid of cell size `h` (mm) with the discretisation `method`.
    pub(super) fn validate(&self, c: Check, h: f64, method: Method) -> Result<(), ConfigError> {
        let layers = self.thickness / h;
        if !(self.thickness.is_finite() && self.thickness > 0.0)
            || (layers - layers.round()).abs() > 1e-9 * layers.max(1.0)
        {
            return Err(c.bad(
                "extrusion.thickness",
                shown(self.thickness),
                &format!("a plate thickness > 0 (mm), a multiple of grid.cell_size = {h}"),
            ));
        }
        if method == Method::Fem {
            return Err(c.bad(
                "shape.method",
                "\"fem\"".into(),
                "\"mpm\" with [extrusion] (the FEM mode is plane only)",
            ));
        }
        if let Some(z) = self.section_z
            && !(0.0..=self.thickness).contains(&z)
        {
            return Err(c.bad(
                "extrusion.section_z",
                shown(z),
                &format!("a z within the plate, 0 to {} (mm)", self.thickness),
            ));
        }
        Ok(())
    }
}

/// `[path]`: path following of a quasi-static run by indirect displacement control (docs/theory.md,
/// "Path following"): every step opens the distance between two material points by `increment`, and the
/// motion of the moving constraints becomes the load factor, so that a snap-back is followed.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PathSection {
    /// Where the first measured point is at t = 0 (mm): the material point nearest it.
    pub from: [f64; 2],
    /// Where the second measured point is at t = 0 (mm).
    pub to: [f64; 2],
    /// Direction of the measured opening; default: from `from` to `to`.
    pub direction: Option<[f64; 2]>,
    /// Opening per step (mm), > 0.
    pub increment: f64,
}

impl PathSection {
    /// The direction of the opening (not normalised): `direction`, or from `from` to `to`.
    pub fn direction(&self) -> [f64; 2] {
        self.direction
            .unwrap_or([self.to[0] - self.from[0], self.to[1] - self.from[1]])
    }

    /// Checks `[path]` of a run that is `quasi_static` or not.
    pub(super) fn validate(&self, c: Check, quasi_static: bool) -> Result<(), ConfigError> {
        if !quasi_static {
            return Err(c.bad(
                "time.quasi_static",
                "false".into(),
                "true with [path] (path following replaces time as the load parameter of a static run)",
            ));
        }
        for (key, p) in [("path.from", self.from), ("path.to", self.to)] {
            if !p.iter().all(|v| v.is_finite() && v.abs() < 1e9) {
                return Err(c.bad(
                    key,
                    format!("{p:?}"),
                    "a point with finite coordinates (mm)",
                ));
            }
        }
        let d = self.direction();
        if !(d.iter().all(|v| v.is_finite()) && d[0].hypot(d[1]) > 0.0) {
            return Err(c.bad(
                "path.direction",
                format!("{d:?}"),
                "a nonzero direction of the opening (default: from `from` to `to`, which then must differ)",
            ));
        }
        if !(self.increment.is_finite() && self.increment > 0.0 && self.increment < 1e3) {
            return Err(c.bad(
                "path.increment",
                shown(self.increment),
                "an opening per step > 0 and below 1000 (mm)",
            ));
        }
        Ok(())
    }
}
