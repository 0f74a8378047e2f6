//! Run configuration (TOML), one section per concept of the method; unknown fields are rejected.
//! Units: mm, s, N, MPa, t (tonne); density in t/mm^3, velocity in mm/s.
//!
//! ```toml
//! [run]                 # name, steps, output cadence, PETSc options (the command line wins)
//! [time]                # dt, Newmark beta/gamma, quasi-static, dt_min, initial acceleration
//! [grid]                # cell size, margin cells
//! [shape]               # interpolator, points per cell
//! [ct]                  # optional: the compact tension specimen generator (scenario::ct)
//! [[body]]              # deformable bodies: geometry, density, material, initial velocity
//! [[constraint]]        # grid nodes in a box, per component: "free", "fixed" or { velocity = v }
//! [[rigid_body]]        # rigid bodies of particles moving with a prescribed velocity
//! ```
//!
//! Every error names the file, the field and what is allowed.

use crate::material::{ElasticConfig, MaterialConfig};
use crate::model::{InitialAcceleration, Method};
use crate::particles::Geometry;
use crate::shape::ShapeKind;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A configuration error: file, field and what is allowed.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Read {
        /// File name.
        file: String,
        /// I/O error.
        source: std::io::Error,
    },
    /// TOML syntax or schema error (serde names the field and the expected type).
    #[error("{file}: {message}")]
    Parse {
        /// File name.
        file: String,
        /// Parser message with line and column.
        message: String,
    },
    /// A value out of its range.
    #[error("{file}: field `{field}` = {value}: {allowed}")]
    Invalid {
        /// File name.
        file: String,
        /// Dotted field name.
        field: String,
        /// Offending value.
        value: String,
        /// What is allowed.
        allowed: String,
    },
}

/// The whole run configuration.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunConfig {
    /// Run control and output.
    pub run: RunSection,
    /// Time integration.
    #[serde(default)]
    pub time: TimeSection,
    /// Background grid.
    pub grid: GridSection,
    /// Interpolation.
    #[serde(default)]
    pub shape: ShapeSection,
    /// Body force per unit mass (mm/s^2), e.g. [0, -9810] for gravity.
    #[serde(default)]
    pub body_force: [f64; 2],
    /// Quasi-static runs ramp the body force over this time (s).
    #[serde(default)]
    pub body_force_ramp: f64,
    /// Compact tension specimen generator.
    pub ct: Option<CtSection>,
    /// Deformable bodies.
    #[serde(default)]
    pub body: Vec<BodySection>,
    /// Node-box constraints.
    #[serde(default)]
    pub constraint: Vec<ConstraintSection>,
    /// Rigid bodies.
    #[serde(default)]
    pub rigid_body: Vec<RigidBodySection>,
    /// Loads (`[[load]]`).
    #[serde(default)]
    pub load: Vec<LoadSection>,
    /// The plane set-up extruded to a plate and run in 3D (`[extrusion]`); absent: plane strain.
    pub extrusion: Option<ExtrusionSection>,
}

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
    /// Write point fields (HDF5) and damage maps (PNG) every this many steps (0: only at the end).
    #[serde(default = "default_output_every")]
    pub output_every: usize,
    /// PETSc options applied as defaults; options given on the command line win.
    #[serde(default)]
    pub petsc_options: String,
}

fn default_output_every() -> usize {
    100
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

fn default_dt() -> f64 {
    1e-6
}
fn default_beta() -> f64 {
    0.25
}
fn default_gamma() -> f64 {
    0.5
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
}

fn default_mass_tolerance() -> f64 {
    1e-6
}

fn default_margin() -> usize {
    3
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
    /// Discretisation: "mpm" (default; grid reset each step) or "fem" (points fixed at the Gauss points of
    /// the grid cells, bilinear elements, no grid reset; requires `kind = "linear"`).
    #[serde(default)]
    pub method: Method,
}

fn default_kind() -> ShapeKind {
    ShapeKind::Cpdi1
}
fn default_ppc() -> usize {
    2
}

impl Default for ShapeSection {
    fn default() -> Self {
        Self {
            kind: default_kind(),
            points_per_cell: default_ppc(),
            method: Method::default(),
        }
    }
}

/// `[[body]]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySection {
    /// Name.
    pub name: String,
    /// Density (t/mm^3), e.g. 2.4e-9 for concrete.
    pub density: f64,
    /// Geometry: union of include regions minus exclude regions.
    pub geometry: Geometry,
    /// Constitutive law.
    pub material: MaterialConfig,
    /// Initial velocity (mm/s).
    #[serde(default)]
    pub initial_velocity: [f64; 2],
    /// The body has its own velocity field on the grid and meets the specimen (the first body) only
    /// through frictionless unilateral contact; default false: it shares the specimen's grid nodes
    /// (bonded where they touch).
    #[serde(default)]
    pub own_field: bool,
}

/// Motion of one component: "free", "fixed" or `{ velocity = v }` (mm/s).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum MotionSpec {
    /// "free" or "fixed".
    Keyword(Keyword),
    /// Prescribed velocity.
    Velocity {
        /// mm/s.
        velocity: f64,
    },
}

/// Keywords of [`MotionSpec`].
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Keyword {
    /// Not constrained.
    Free,
    /// Zero velocity.
    Fixed,
}

impl From<Keyword> for MotionSpec {
    fn from(k: Keyword) -> Self {
        MotionSpec::Keyword(k)
    }
}

impl Default for MotionSpec {
    fn default() -> Self {
        MotionSpec::Keyword(Keyword::Free)
    }
}

impl MotionSpec {
    /// As the solver's motion.
    pub fn motion(self) -> crate::boundary::Motion {
        use crate::boundary::Motion;
        match self {
            MotionSpec::Keyword(Keyword::Free) => Motion::Free,
            MotionSpec::Keyword(Keyword::Fixed) => Motion::Velocity(0.0),
            MotionSpec::Velocity { velocity } => Motion::Velocity(velocity),
        }
    }
}

/// `[[constraint]]`: grid nodes in a box.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstraintSection {
    /// Name (reaction-force columns).
    pub name: String,
    /// Box lower-left corner (mm).
    pub min: [f64; 2],
    /// Box upper-right corner (mm).
    pub max: [f64; 2],
    /// x component.
    #[serde(default)]
    pub x: MotionSpec,
    /// y component.
    #[serde(default)]
    pub y: MotionSpec,
    /// Prescribed velocities rise linearly from zero over this time (s); default 0 (a step).
    #[serde(default)]
    pub rise_time: f64,
}

/// `[[load]]`: a force distributed over the grid nodes on a segment as a uniform traction.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadSection {
    /// Name (history columns `NAME_ux, NAME_uy, NAME_fx, NAME_fy`).
    pub name: String,
    /// Start of the segment (mm); the segment lies on a grid line (horizontal or vertical).
    pub from: [f64; 2],
    /// End of the segment (mm).
    pub to: [f64; 2],
    /// Resultant force (N per mm thickness).
    pub force: [f64; 2],
    /// The force rises linearly from zero over this time (s); default 0 (applied at once).
    #[serde(default)]
    pub rise_time: f64,
}

/// `[[rigid_body]]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigidBodySection {
    /// Name (reaction-force columns).
    pub name: String,
    /// Geometry of the body.
    pub geometry: Geometry,
    /// x component.
    #[serde(default)]
    pub x: MotionSpec,
    /// y component.
    #[serde(default)]
    pub y: MotionSpec,
    /// Prescribed velocities rise linearly from zero over this time (s); default 0 (a step).
    #[serde(default)]
    pub rise_time: f64,
    /// Unilateral contact with the specimen instead of gluing (default: glued).
    #[serde(default)]
    pub contact: Option<ContactSection>,
    /// The `[[body]]` with `own_field = true` it holds or pushes (by name); default: the specimen and
    /// the bodies that share its nodes.
    #[serde(default)]
    pub acts_on: Option<String>,
}

/// `contact = { normal = [nx, ny], friction = mu, pin = [x, y] }` of a `[[rigid_body]]`: the device pushes
/// on the specimen through its flat face with the outward normal `normal` (from the device into the
/// specimen; normalised), never pulls, with Coulomb friction `friction` (-, default 0), and, with `pin`
/// (mm), is driven at the pin and turns freely about it.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactSection {
    /// Outward normal of the contact face (from the device into the specimen).
    pub normal: [f64; 2],
    /// Coulomb friction coefficient (-), default 0 (frictionless).
    #[serde(default)]
    pub friction: f64,
    /// Pin position at t = 0 (mm); none: the device only translates.
    #[serde(default)]
    pub pin: Option<[f64; 2]>,
}

/// How the CT specimen is loaded (`[ct] load_introduction`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(try_from = "String")]
pub enum LoadIntroduction {
    /// Rigid plates glued to the notch faces: every grid node under a plate follows it (pulls as well as
    /// pushes; the plates do not turn).
    #[default]
    Glued,
    /// Rigid plates in unilateral contact with the notch faces (push only, Coulomb friction), translating
    /// without rotation.
    Contact,
    /// Rigid plates in unilateral contact, each driven at a pin and free to turn about it (a testing
    /// machine's clevis and pin; the support is a pinned seat).
    Pin,
    /// Deformable steel inserts on the notch faces, each a body with its own velocity field in
    /// frictionless contact with the concrete, pushed by a pin-driven plate (a testing machine's
    /// loading device).
    Inserts,
}

impl TryFrom<String> for LoadIntroduction {
    type Error = String;

    fn try_from(name: String) -> Result<Self, String> {
        match name.as_str() {
            "glued" => Ok(Self::Glued),
            "contact" => Ok(Self::Contact),
            "pin" => Ok(Self::Pin),
            "inserts" => Ok(Self::Inserts),
            _ => Err(format!(
                "field `ct.load_introduction` = \"{name}\": \"glued\" (plates glued to the notch faces), \
                 \"contact\" (plates pushing through unilateral contact), \"pin\" (contact plates \
                 turning freely about a pin) or \"inserts\" (steel inserts in contact with the concrete, \
                 pushed by pinned plates)"
            )),
        }
    }
}

/// The end of the CT notch (`[ct] notch_tip`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(try_from = "String")]
pub enum NotchTip {
    /// A square end at `x = notch_length` with two corners (the source paper's rectangular notch).
    #[default]
    Flat,
    /// A semicircular end of radius `notch_width / 2` whose apex lies at `x = notch_length` (a sawn notch).
    Round,
}

impl TryFrom<String> for NotchTip {
    type Error = String;

    fn try_from(name: String) -> Result<Self, String> {
        match name.as_str() {
            "flat" => Ok(Self::Flat),
            "round" => Ok(Self::Round),
            _ => Err(format!(
                "field `ct.notch_tip` = \"{name}\": \"flat\" (square end with two corners) or \"round\" \
                 (semicircular end of radius notch_width / 2, apex at notch_length)"
            )),
        }
    }
}

/// `[ct]`: the compact tension specimen of the source paper (spec 03-ct-test.md; the defaults are the
/// project's reconstruction). A plate with a straight notch from the left edge along mid-height; a rigid
/// loading plate on the lower notch face near the mouth moves down at `loading_rate`; a rigid support plate
/// holds the upper face (or moves up at the same rate with `symmetric = true`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CtSection {
    /// Plate width (mm).
    #[serde(default = "ct_width")]
    pub width: f64,
    /// Plate height (mm).
    #[serde(default = "ct_height")]
    pub height: f64,
    /// Notch length from the left edge (mm).
    #[serde(default = "ct_notch_length")]
    pub notch_length: f64,
    /// Notch width (mm), centred on mid-height.
    #[serde(default = "ct_notch_width")]
    pub notch_width: f64,
    /// End of the notch: "flat" (default, square with two corners) or "round" (semicircle of radius
    /// `notch_width / 2`, apex at `notch_length`).
    #[serde(default)]
    pub notch_tip: NotchTip,
    /// x range of the loading and support plates on the notch faces (mm).
    #[serde(default = "ct_load_zone")]
    pub load_zone: [f64; 2],
    /// Thickness of the rigid plates inside the notch (mm).
    #[serde(default = "ct_plate_thickness")]
    pub plate_thickness: f64,
    /// Opening rate of the loading plate (mm/s), e.g. 4300 for 4.3 m/s.
    pub loading_rate: f64,
    /// The loading velocity rises linearly from zero over this time (s); default 0 (a velocity step).
    #[serde(default)]
    pub rise_time: f64,
    /// Load both faces symmetrically (each at half the rate, mirror-identical devices) instead of holding
    /// the upper one.
    #[serde(default)]
    pub symmetric: bool,
    /// How the plates act on the notch faces: "glued" (default), "contact", "pin" or "inserts".
    #[serde(default)]
    pub load_introduction: LoadIntroduction,
    /// Coulomb friction coefficient between the plates and what they push (-): the concrete for
    /// "contact" and "pin", the inserts for "inserts" (whose contact with the concrete is frictionless);
    /// default 0 (frictionless).
    #[serde(default)]
    pub friction: f64,
    /// x range of the support plate on the upper notch face (mm); default: `load_zone`.
    #[serde(default)]
    pub support_zone: Option<[f64; 2]>,
    /// x of the pins of both plates (mm), for "pin" and "inserts"; default: the middle of each plate.
    #[serde(default)]
    pub pin_x: Option<f64>,
    /// Distance of the pins from the plates' contact faces into the plates (mm), for "pin" and
    /// "inserts"; default:
    /// half the plate thickness.
    #[serde(default)]
    pub pin_offset: Option<f64>,
    /// Thickness of the steel inserts on the notch faces (mm), for "inserts"; at least one cell, and
    /// the two inserts and plates leave a cell free in the notch.
    #[serde(default)]
    pub insert_thickness: Option<f64>,
    /// Constitutive law of the inserts; default: steel as neo-Hooke, E = 210,000 MPa, nu = 0.3.
    #[serde(default = "ct_insert_material")]
    pub insert_material: MaterialConfig,
    /// Density of the inserts (t/mm^3); default 7.85e-9 (steel).
    #[serde(default = "ct_insert_density")]
    pub insert_density: f64,
    /// Density of the concrete (t/mm^3).
    #[serde(default = "ct_density")]
    pub density: f64,
    /// Constitutive law of the concrete.
    pub material: MaterialConfig,
}

impl CtSection {
    /// Where the straight notch faces end (mm): `notch_length`, less the radius of a round tip.
    pub fn straight_faces_end(&self) -> f64 {
        match self.notch_tip {
            NotchTip::Flat => self.notch_length,
            NotchTip::Round => self.notch_length - 0.5 * self.notch_width,
        }
    }
}

fn ct_width() -> f64 {
    200.0
}
fn ct_height() -> f64 {
    200.0
}
fn ct_notch_length() -> f64 {
    110.0
}
fn ct_notch_width() -> f64 {
    10.0
}
fn ct_load_zone() -> [f64; 2] {
    [0.0, 30.0]
}
fn ct_plate_thickness() -> f64 {
    2.0
}
fn ct_density() -> f64 {
    2.4e-9
}
fn ct_insert_density() -> f64 {
    7.85e-9
}
fn ct_insert_material() -> MaterialConfig {
    MaterialConfig::NeoHookean(ElasticConfig {
        youngs_modulus: Some(210_000.0),
        poisson_ratio: Some(0.3),
        ..ElasticConfig::default()
    })
}

/// How errors name a configuration file read with `overrides`: `configs/x.toml (with --set a=1)`.
pub fn source_label(file: &str, overrides: &[String]) -> String {
    if overrides.is_empty() {
        return file.to_owned();
    }
    let sets: Vec<String> = overrides.iter().map(|o| format!("--set {o}")).collect();
    format!("{file} (with {})", sets.join(" "))
}

/// A TOML error on one line: the parser's message, the table it is in and, with `position`, the line and
/// column in `text`.
fn toml_message(e: &toml::de::Error, text: &str, position: bool) -> String {
    let mut message = e.message().trim().replace('\n', " ");
    if let Some(before) = e.span().and_then(|span| text.get(..span.start)) {
        if let Some(table) = before
            .lines()
            .rev()
            .map(str::trim)
            .find(|l| l.starts_with('['))
        {
            message += &format!(" (in {table})");
        }
        if position {
            let line = before.matches('\n').count() + 1;
            let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
            message = format!("line {line}, column {column}: {message}");
        }
    }
    message
}

impl RunConfig {
    /// Reads and validates a configuration file.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            file: file.clone(),
            source,
        })?;
        Self::from_str_named(&text, &file)
    }

    /// Reads a configuration file, applies `key=value` overrides (dotted keys into tables, values in TOML
    /// syntax, e.g. `shape.method="fem"` or `grid.cell_size=2.5`; a bare word is taken as a string) and
    /// validates the result. Returns the configuration and its effective text: the file with the
    /// overrides applied, in canonical TOML (sorted keys, no comments), the same for every spelling of
    /// the same configuration.
    pub fn load(path: &Path, overrides: &[String]) -> Result<(Self, String), ConfigError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            file: file.clone(),
            source,
        })?;
        let parse_err = |file: &str, message: String| ConfigError::Parse {
            file: file.to_owned(),
            message,
        };
        if overrides.is_empty() {
            // Parse the file itself first, so that errors point at its lines.
            let cfg = Self::from_str_named(&text, &file)?;
            let table: toml::Table = toml::from_str(&text)
                .map_err(|e| parse_err(&file, toml_message(&e, &text, true)))?;
            let canonical = toml::to_string(&table).map_err(|e| parse_err(&file, e.to_string()))?;
            return Ok((cfg, canonical));
        }
        let mut table: toml::Table =
            toml::from_str(&text).map_err(|e| parse_err(&file, toml_message(&e, &text, true)))?;
        for o in overrides {
            let (key, value) = o.split_once('=').ok_or_else(|| {
                parse_err(
                    &file,
                    format!("--set {o}: expected key=value (e.g. grid.cell_size=2.5)"),
                )
            })?;
            let value: toml::Value = match toml::from_str::<toml::Table>(&format!("v = {value}")) {
                Ok(mut t) => t.remove("v").unwrap_or(toml::Value::String(value.into())),
                Err(_) => toml::Value::String(value.trim().into()),
            };
            let keys: Vec<&str> = key.trim().split('.').collect();
            let mut t = &mut table;
            for k in &keys[..keys.len() - 1] {
                t = t
                    .entry(k.to_string())
                    .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                    .as_table_mut()
                    .ok_or_else(|| parse_err(&file, format!("--set {o}: `{k}` is not a table")))?;
            }
            t.insert(keys[keys.len() - 1].to_string(), value);
        }
        let named = source_label(&file, overrides);
        let canonical = toml::to_string(&table).map_err(|e| parse_err(&named, e.to_string()))?;
        // Lines of the canonical text mean nothing to the user: name the table instead.
        let cfg = Self::parse(&canonical, &named, false)?;
        Ok((cfg, canonical))
    }

    /// Parses and validates configuration text; `file` names it in errors.
    pub fn from_str_named(text: &str, file: &str) -> Result<Self, ConfigError> {
        Self::parse(text, file, true)
    }

    /// As [`RunConfig::from_str_named`]; `position`: errors give the line and column in `text`.
    fn parse(text: &str, file: &str, position: bool) -> Result<Self, ConfigError> {
        let cfg: RunConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            file: file.to_owned(),
            message: toml_message(&e, text, position),
        })?;
        cfg.validate(file)?;
        Ok(cfg)
    }

    fn validate(&self, file: &str) -> Result<(), ConfigError> {
        let bad = |field: &str, value: String, allowed: &str| ConfigError::Invalid {
            file: file.to_owned(),
            field: field.to_owned(),
            value,
            allowed: allowed.to_owned(),
        };
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        let time_ok = |t: f64| t.is_finite() && t >= 0.0;
        let density_ok = |d: f64| d.is_finite() && d > 0.0;
        let r = &self.run;
        if r.name.trim().is_empty()
            || r.name.contains(['/', '\\'])
            || r.name == "."
            || r.name == ".."
            || r.name.chars().any(char::is_control)
        {
            return Err(bad(
                "run.name",
                format!("{:?}", r.name),
                "a non-empty name without / or \\ (it names the output directory runs/<name>)",
            ));
        }
        if r.steps == 0 {
            return Err(bad("run.steps", "0".into(), "at least one step"));
        }
        let t = &self.time;
        if !(t.dt.is_finite() && t.dt > 0.0) {
            return Err(bad("time.dt", t.dt.to_string(), "a time step > 0 (s)"));
        }
        if let Some(m) = t.dt_min
            && !(m > 0.0 && m <= t.dt)
        {
            return Err(bad("time.dt_min", m.to_string(), "0 < dt_min <= dt (s)"));
        }
        if !(t.beta > 0.0 && t.beta <= 0.5) {
            return Err(bad(
                "time.beta",
                t.beta.to_string(),
                "Newmark beta in (0, 0.5]; 0 (explicit) is not supported",
            ));
        }
        if !(0.5..=1.0).contains(&t.gamma) {
            return Err(bad(
                "time.gamma",
                t.gamma.to_string(),
                "Newmark gamma in [0.5, 1]",
            ));
        }
        if !(self.grid.cell_size.is_finite() && self.grid.cell_size > 0.0) {
            return Err(bad(
                "grid.cell_size",
                self.grid.cell_size.to_string(),
                "a cell size > 0 (mm)",
            ));
        }
        if !(0.0..1e-2).contains(&self.grid.mass_tolerance) {
            return Err(bad(
                "grid.mass_tolerance",
                self.grid.mass_tolerance.to_string(),
                "a fraction in [0, 0.01)",
            ));
        }
        if self.shape.points_per_cell == 0 || self.shape.points_per_cell > 8 {
            return Err(bad(
                "shape.points_per_cell",
                self.shape.points_per_cell.to_string(),
                "1 to 8 points per direction",
            ));
        }
        if self.shape.method == Method::Fem {
            if self.shape.kind != ShapeKind::Linear {
                return Err(bad(
                    "shape.kind",
                    self.shape.kind.name().into(),
                    "\"linear\" with method = \"fem\" (bilinear elements)",
                ));
            }
            if !(1..=3).contains(&self.shape.points_per_cell) {
                return Err(bad(
                    "shape.points_per_cell",
                    self.shape.points_per_cell.to_string(),
                    "1, 2 or 3 Gauss points per direction with method = \"fem\"",
                ));
            }
        }
        if let Some(e) = &self.extrusion {
            let h = self.grid.cell_size;
            let layers = e.thickness / h;
            if !(e.thickness.is_finite() && e.thickness > 0.0)
                || (layers - layers.round()).abs() > 1e-9 * layers.max(1.0)
            {
                return Err(bad(
                    "extrusion.thickness",
                    e.thickness.to_string(),
                    &format!("a plate thickness > 0 (mm), a multiple of grid.cell_size = {h}"),
                ));
            }
            if self.shape.method == Method::Fem {
                return Err(bad(
                    "shape.method",
                    "\"fem\"".into(),
                    "\"mpm\" with [extrusion] (the FEM mode is plane only)",
                ));
            }
            if let Some(z) = e.section_z
                && !(0.0..=e.thickness).contains(&z)
            {
                return Err(bad(
                    "extrusion.section_z",
                    z.to_string(),
                    &format!("a z within the plate, 0 to {} (mm)", e.thickness),
                ));
            }
        }
        if !finite(&self.body_force) {
            return Err(bad(
                "body_force",
                format!("{:?}", self.body_force),
                "finite components (mm/s^2)",
            ));
        }
        if !time_ok(self.body_force_ramp) {
            return Err(bad(
                "body_force_ramp",
                self.body_force_ramp.to_string(),
                "a time >= 0 (s)",
            ));
        }
        for (i, b) in self.body.iter().enumerate() {
            if b.name.trim().is_empty() {
                return Err(bad(&format!("body[{i}].name"), "\"\"".into(), "a name"));
            }
            // Names are unique (`acts_on` refers to them), and [ct] names its own bodies.
            let reserved: &[&str] = match &self.ct {
                Some(_) => &["concrete", "loading_insert", "support_insert"],
                None => &[],
            };
            if reserved.contains(&b.name.as_str())
                || self.body[..i].iter().any(|other| other.name == b.name)
            {
                return Err(bad(
                    &format!("body[{i}].name"),
                    format!("{:?}", b.name),
                    &format!("a name no other body has (with [ct] also not one of {reserved:?})"),
                ));
            }
            if !density_ok(b.density) {
                return Err(bad(
                    &format!("body[{i}].density"),
                    b.density.to_string(),
                    "a density > 0 (t/mm^3)",
                ));
            }
            if !finite(&b.initial_velocity) {
                return Err(bad(
                    &format!("body[{i}].initial_velocity"),
                    format!("{:?}", b.initial_velocity),
                    "finite components (mm/s)",
                ));
            }
            b.geometry.validate().map_err(|e| {
                bad(
                    &format!("body[{i}].geometry"),
                    String::new(),
                    &e.to_string(),
                )
            })?;
            b.material.build().map_err(|e| {
                bad(
                    &format!("body[{i}].material"),
                    String::new(),
                    &e.to_string(),
                )
            })?;
            if b.own_field && i == 0 && self.ct.is_none() {
                return Err(bad(
                    "body[0].own_field",
                    "true".into(),
                    "false: the first body is the specimen, which the bodies with their own field meet \
                     in contact",
                ));
            }
        }
        // Constraint sets, rigid bodies and loads name the columns of history.csv.
        let mut sets: Vec<(String, &str)> = Vec::new();
        if self.ct.is_some() {
            sets.push(("ct".into(), "loading_plate"));
            sets.push(("ct".into(), "support_plate"));
        }
        let motion_ok = |m: &MotionSpec| match m {
            MotionSpec::Velocity { velocity } => velocity.is_finite(),
            MotionSpec::Keyword(_) => true,
        };
        for (i, c) in self.constraint.iter().enumerate() {
            let field = format!("constraint[{i}]");
            sets.push((field.clone(), &c.name));
            if !finite(&c.min) || !finite(&c.max) || (0..2).any(|k| c.min[k] > c.max[k]) {
                return Err(bad(
                    &format!("{field}.min/max"),
                    format!("{:?}/{:?}", c.min, c.max),
                    "finite corners with min <= max in both directions (mm)",
                ));
            }
            for (axis, m) in [("x", &c.x), ("y", &c.y)] {
                if !motion_ok(m) {
                    return Err(bad(
                        &format!("{field}.{axis}"),
                        format!("{m:?}"),
                        "\"free\", \"fixed\" or { velocity = v } with a finite v (mm/s)",
                    ));
                }
            }
            if !time_ok(c.rise_time) {
                return Err(bad(
                    &format!("{field}.rise_time"),
                    c.rise_time.to_string(),
                    "a time >= 0 (s)",
                ));
            }
        }
        for (i, rb) in self.rigid_body.iter().enumerate() {
            let field = format!("rigid_body[{i}]");
            sets.push((field.clone(), &rb.name));
            if let Some(name) = &rb.acts_on
                && !self.body.iter().any(|b| b.own_field && &b.name == name)
            {
                let own: Vec<&str> = self
                    .body
                    .iter()
                    .filter(|b| b.own_field)
                    .map(|b| b.name.as_str())
                    .collect();
                return Err(bad(
                    &format!("{field}.acts_on"),
                    format!("{name:?}"),
                    &format!("the name of a [[body]] with own_field = true: {own:?}"),
                ));
            }
            rb.geometry
                .validate()
                .map_err(|e| bad(&format!("{field}.geometry"), String::new(), &e.to_string()))?;
            for (axis, m) in [("x", &rb.x), ("y", &rb.y)] {
                if !motion_ok(m) {
                    return Err(bad(
                        &format!("{field}.{axis}"),
                        format!("{m:?}"),
                        "\"free\", \"fixed\" or { velocity = v } with a finite v (mm/s)",
                    ));
                }
            }
            if !time_ok(rb.rise_time) {
                return Err(bad(
                    &format!("{field}.rise_time"),
                    rb.rise_time.to_string(),
                    "a time >= 0 (s)",
                ));
            }
            if let Some(c) = &rb.contact {
                let norm = (c.normal[0] * c.normal[0] + c.normal[1] * c.normal[1]).sqrt();
                if !(finite(&c.normal) && norm > 0.0) {
                    return Err(bad(
                        &format!("{field}.contact.normal"),
                        format!("{:?}", c.normal),
                        "a finite non-zero vector, the outward normal of the contact face (from the \
                         device into the specimen)",
                    ));
                }
                if !(c.friction.is_finite() && c.friction >= 0.0) {
                    return Err(bad(
                        &format!("{field}.contact.friction"),
                        c.friction.to_string(),
                        "a Coulomb coefficient >= 0 (0 = frictionless)",
                    ));
                }
                if c.pin.is_some_and(|p| !finite(&p)) {
                    return Err(bad(
                        &format!("{field}.contact.pin"),
                        format!("{:?}", c.pin),
                        "a finite point (mm)",
                    ));
                }
                for (axis, m) in [("x", &rb.x), ("y", &rb.y)] {
                    if !matches!(
                        m,
                        MotionSpec::Velocity { .. } | MotionSpec::Keyword(Keyword::Fixed)
                    ) {
                        return Err(bad(
                            &format!("{field}.{axis}"),
                            format!("{m:?}"),
                            "\"fixed\" or { velocity = v }: a device in contact is driven in both \
                             directions (a free component would need the device's mass)",
                        ));
                    }
                }
            }
        }
        for (i, l) in self.load.iter().enumerate() {
            sets.push((format!("load[{i}]"), &l.name));
            let axis_aligned = l.from[0] == l.to[0] || l.from[1] == l.to[1];
            if !finite(&l.from)
                || !finite(&l.to)
                || !finite(&l.force)
                || !axis_aligned
                || l.from == l.to
            {
                return Err(bad(
                    &format!("load[{i}] ({}).from/to/force", l.name),
                    format!("{:?}/{:?}/{:?}", l.from, l.to, l.force),
                    "finite values and a horizontal or vertical segment of non-zero length (mm)",
                ));
            }
            if !time_ok(l.rise_time) {
                return Err(bad(
                    &format!("load[{i}] ({}).rise_time", l.name),
                    l.rise_time.to_string(),
                    "a time >= 0 (s)",
                ));
            }
        }
        if let Some(ct) = &self.ct {
            for (field, v) in [("ct.width", ct.width), ("ct.height", ct.height)] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(bad(field, v.to_string(), "a length > 0 (mm)"));
                }
            }
            if !(ct.notch_length > 0.0 && ct.notch_length < ct.width) {
                return Err(bad(
                    "ct.notch_length",
                    ct.notch_length.to_string(),
                    "0 < notch_length < width (mm)",
                ));
            }
            if !(ct.notch_width > 0.0 && ct.notch_width < ct.height) {
                return Err(bad(
                    "ct.notch_width",
                    ct.notch_width.to_string(),
                    "0 < notch_width < height (mm)",
                ));
            }
            if ct.notch_tip == NotchTip::Round && ct.notch_length <= 0.5 * ct.notch_width {
                return Err(bad(
                    "ct.notch_length",
                    ct.notch_length.to_string(),
                    "notch_length > notch_width / 2 with notch_tip = \"round\" (mm)",
                ));
            }
            // The plates bear on the straight faces, which end where a round tip begins.
            let end = ct.straight_faces_end();
            let [a, b] = ct.load_zone;
            if !(a >= 0.0 && a < b && b <= end) {
                return Err(bad(
                    "ct.load_zone",
                    format!("{:?}", ct.load_zone),
                    &format!(
                        "an x range [a, b] on the straight notch faces: 0 <= a < b <= notch_length \
                         (less notch_width / 2 with a round tip), here {end} (mm)"
                    ),
                ));
            }
            if let Some(z) = ct.support_zone {
                let [a, b] = z;
                if !(a >= 0.0 && a < b && b <= end) {
                    return Err(bad(
                        "ct.support_zone",
                        format!("{z:?}"),
                        &format!(
                            "an x range [a, b] on the straight upper notch face: 0 <= a < b <= \
                             notch_length (less notch_width / 2 with a round tip), here {end} (mm)"
                        ),
                    ));
                }
            }
            if !(ct.friction.is_finite() && ct.friction >= 0.0) {
                return Err(bad(
                    "ct.friction",
                    ct.friction.to_string(),
                    "a Coulomb coefficient >= 0 (0 = frictionless)",
                ));
            }
            let pinned = matches!(
                ct.load_introduction,
                LoadIntroduction::Pin | LoadIntroduction::Inserts
            );
            if !pinned && (ct.pin_x.is_some() || ct.pin_offset.is_some()) {
                return Err(bad(
                    "ct.pin_x/pin_offset",
                    format!("{:?}/{:?}", ct.pin_x, ct.pin_offset),
                    "only with load_introduction = \"pin\" or \"inserts\"",
                ));
            }
            if ct.load_introduction == LoadIntroduction::Glued && ct.friction != 0.0 {
                return Err(bad(
                    "ct.friction",
                    ct.friction.to_string(),
                    "only with load_introduction = \"contact\", \"pin\" or \"inserts\" (glued plates do \
                     not slide)",
                ));
            }
            if let Some(px) = ct.pin_x {
                let s = ct.support_zone.unwrap_or(ct.load_zone);
                if !(px > a.max(s[0]) && px < b.min(s[1])) {
                    return Err(bad(
                        "ct.pin_x",
                        px.to_string(),
                        "an x strictly inside both plates (load_zone and support_zone, mm): a massless \
                         plate pinned outside its contact face cannot balance its moment and overturns",
                    ));
                }
            }
            if let Some(o) = ct.pin_offset
                && !(o.is_finite() && o >= 0.0)
            {
                return Err(bad(
                    "ct.pin_offset",
                    o.to_string(),
                    "a distance >= 0 from the contact face into the plate (mm)",
                ));
            }
            if !(ct.plate_thickness > 0.0 && 2.0 * ct.plate_thickness < ct.notch_width) {
                return Err(bad(
                    "ct.plate_thickness",
                    ct.plate_thickness.to_string(),
                    "0 < plate_thickness < notch_width / 2 (mm)",
                ));
            }
            let inserts = ct.load_introduction == LoadIntroduction::Inserts;
            match (inserts, ct.insert_thickness) {
                (false, Some(ti)) => {
                    return Err(bad(
                        "ct.insert_thickness",
                        ti.to_string(),
                        "only with load_introduction = \"inserts\"",
                    ));
                }
                (true, None) => {
                    return Err(bad(
                        "ct.insert_thickness",
                        "(missing)".into(),
                        "the thickness of the steel inserts (mm), required with load_introduction = \
                         \"inserts\"",
                    ));
                }
                (true, Some(ti)) => {
                    let h = self.grid.cell_size;
                    let room = ct.notch_width - 2.0 * (ti + ct.plate_thickness);
                    if !(ti >= h - 1e-9 && room >= h - 1e-9) {
                        return Err(bad(
                            "ct.insert_thickness",
                            ti.to_string(),
                            &format!(
                                "at least one cell ({h} mm), with a cell left free between the two \
                                 inserts and their plates: notch_width - 2 (insert_thickness + \
                                 plate_thickness) >= cell_size (mm); here {room} mm"
                            ),
                        ));
                    }
                }
                (false, None) => {}
            }
            if inserts {
                if !density_ok(ct.insert_density) {
                    return Err(bad(
                        "ct.insert_density",
                        ct.insert_density.to_string(),
                        "a density > 0 (t/mm^3)",
                    ));
                }
                ct.insert_material.build().map_err(|e| {
                    bad(
                        "ct.insert_material",
                        format!("{:?}", ct.insert_material),
                        &e.to_string(),
                    )
                })?;
            }
            if !density_ok(ct.density) {
                return Err(bad(
                    "ct.density",
                    ct.density.to_string(),
                    "a density > 0 (t/mm^3)",
                ));
            }
            if !ct.loading_rate.is_finite() {
                return Err(bad(
                    "ct.loading_rate",
                    ct.loading_rate.to_string(),
                    "a finite velocity (mm/s)",
                ));
            }
            if !time_ok(ct.rise_time) {
                return Err(bad(
                    "ct.rise_time",
                    ct.rise_time.to_string(),
                    "a time >= 0 (s)",
                ));
            }
            ct.material
                .build()
                .map_err(|e| bad("ct.material", String::new(), &e.to_string()))?;
        } else if self.body.is_empty() {
            return Err(bad(
                "body",
                "[]".into(),
                "at least one [[body]] (or a [ct] section)",
            ));
        }
        for (k, (field, name)) in sets.iter().enumerate() {
            let column_safe = |c: char| c.is_ascii_alphanumeric() || "_-.".contains(c);
            if name.is_empty() || !name.chars().all(column_safe) {
                return Err(bad(
                    &format!("{field}.name"),
                    format!("{name:?}"),
                    "letters, digits, _, - or . (it names columns of history.csv)",
                ));
            }
            if let Some((other, _)) = sets[..k].iter().find(|(_, n)| n == name) {
                return Err(bad(
                    &format!("{field}.name"),
                    format!("{name:?}"),
                    &format!(
                        "a name not used by {other} (the names of constraints, rigid bodies and loads are history.csv columns{})",
                        if other == "ct" {
                            "; [ct] uses loading_plate and support_plate"
                        } else {
                            ""
                        }
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Output directory of the run.
    pub fn output_dir(&self) -> PathBuf {
        self.run
            .output_dir
            .clone()
            .unwrap_or_else(|| PathBuf::from("runs").join(&self.run.name))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every configuration the repository ships parses and validates (a renamed field breaks no run
    /// unnoticed), and the 3D demo is the plane demo extruded.
    #[test]
    fn the_shipped_configurations_are_valid() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
        let mut checked = 0;
        for entry in std::fs::read_dir(&dir).expect("configs/") {
            let path = entry.expect("entry").path();
            if path.extension().is_some_and(|e| e == "toml") {
                RunConfig::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
                checked += 1;
            }
        }
        assert!(checked >= 10, "{checked} configurations");
        let plane = RunConfig::from_file(&dir.join("ct-demo.toml")).expect("ct-demo");
        let plate = RunConfig::from_file(&dir.join("ct-3d-demo.toml")).expect("ct-3d-demo");
        assert!(plane.extrusion.is_none());
        assert_eq!(plate.extrusion.map(|e| e.thickness), Some(8.0));
        assert_eq!(format!("{:?}", plane.ct), format!("{:?}", plate.ct));
    }

    const MINIMAL: &str = r#"
[run]
name = "t"
steps = 2
[grid]
cell_size = 1.0
[[body]]
name = "b"
density = 1e-9
geometry = { include = [{ type = "rect", min = [0.0, 0.0], max = [2.0, 2.0] }] }
material = { model = "svk", youngs_modulus = 100.0, poisson_ratio = 0.2 }
[[constraint]]
name = "base"
min = [-1.0, -0.1]
max = [3.0, 0.1]
y = "fixed"
x = { velocity = 5.0 }
"#;

    #[test]
    fn minimal_config_parses_with_defaults() {
        let c = RunConfig::from_str_named(MINIMAL, "t.toml").expect("valid");
        assert_eq!(c.time.beta, 0.25);
        assert_eq!(c.time.initial_acceleration, InitialAcceleration::Consistent);
        assert_eq!(c.shape.kind, ShapeKind::Cpdi1);
        assert_eq!(c.constraint[0].x, MotionSpec::Velocity { velocity: 5.0 });
        assert_eq!(c.constraint[0].y, MotionSpec::Keyword(Keyword::Fixed));
    }

    #[test]
    fn errors_name_file_field_and_allowed_range() {
        let neg = MINIMAL.replace("[grid]", "[time]\ndt = -1e-6\n[grid]");
        let e = RunConfig::from_str_named(&neg, "t.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.toml") && e.contains("time.dt") && e.contains("> 0"),
            "{e}"
        );
        let typo = MINIMAL.replace("cell_size", "cell_sise");
        let e = RunConfig::from_str_named(&typo, "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("t.toml") && e.contains("cell_sise"), "{e}");
        assert!(
            !e.contains('\n') && e.contains("line 6, column 1") && e.contains("(in [grid])"),
            "one line with the position and the table: {e}"
        );
        let start = MINIMAL.replace("[grid]", "[time]\ninitial_acceleration = \"rest\"\n[grid]");
        let e = RunConfig::from_str_named(&start, "t.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.toml")
                && e.contains("time.initial_acceleration")
                && e.contains("\"rest\"")
                && e.contains("\"consistent\"")
                && e.contains("\"zero\""),
            "{e}"
        );
        let beta0 = MINIMAL.replace("[grid]", "[time]\nbeta = 0.0\n[grid]");
        let e = RunConfig::from_str_named(&beta0, "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("time.beta"), "{e}");
    }

    #[test]
    fn overrides_and_fem_mode_are_validated() {
        let path = std::env::temp_dir().join(format!("mpmc-cfg-{}.toml", std::process::id()));
        std::fs::write(&path, MINIMAL).unwrap();
        let set = |o: &[&str]| {
            RunConfig::load(&path, &o.iter().map(|s| s.to_string()).collect::<Vec<_>>())
                .map(|(c, _)| c)
        };
        let c = set(&[
            "shape.method=fem",
            "shape.kind=linear",
            "grid.cell_size=2.5",
        ])
        .unwrap();
        assert_eq!(c.shape.method, Method::Fem);
        assert_eq!(c.grid.cell_size, 2.5);
        // FEM needs the bilinear interpolator and 1-3 Gauss points.
        let e = set(&["shape.method=fem"]).unwrap_err().to_string();
        assert!(e.contains("shape.kind") && e.contains("linear"), "{e}");
        let e = set(&["shape.method=\"fe\""]).unwrap_err().to_string();
        assert!(e.contains("--set") && e.contains("method"), "{e}");
        let e = set(&["grid.cell_size"]).unwrap_err().to_string();
        assert!(e.contains("key=value"), "{e}");
        std::fs::remove_file(&path).ok();
    }

    #[test]
    fn effective_text_includes_the_overrides_and_ignores_formatting() {
        let dir = std::env::temp_dir().join(format!("mpmc-cfg-eff-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (a, b) = (dir.join("a.toml"), dir.join("b.toml"));
        std::fs::write(&a, MINIMAL).unwrap();
        let reformatted = format!(
            "# a comment\n{}",
            MINIMAL.replace("steps = 2", "steps   =   2 # two")
        );
        std::fs::write(&b, reformatted).unwrap();
        let (_, ta) = RunConfig::load(&a, &[]).unwrap();
        let (_, tb) = RunConfig::load(&b, &[]).unwrap();
        assert_eq!(
            ta, tb,
            "comments and spacing do not change the effective text"
        );
        let (c, tc) = RunConfig::load(&a, &["grid.cell_size=0.5".to_string()]).unwrap();
        assert_eq!(c.grid.cell_size, 0.5);
        assert!(tc.contains("cell_size = 0.5"), "{tc}");
        let again = RunConfig::from_str_named(&tc, "effective").unwrap();
        assert_eq!(again.grid.cell_size, 0.5);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn non_finite_negative_and_inconsistent_values_are_rejected() {
        let ct = |extra: &str| {
            format!(
                "[run]\nname = \"c\"\nsteps = 1\n[grid]\ncell_size = 4.0\n[ct]\nloading_rate = 4300.0\n\
                 material = {{ model = \"svk\", youngs_modulus = 100.0, poisson_ratio = 0.2 }}\n{extra}"
            )
        };
        let cases: Vec<(String, &str)> = vec![
            (ct("rise_time = -1e-6"), "ct.rise_time"),
            (ct("rise_time = nan"), "ct.rise_time"),
            (ct("load_zone = [-100.0, -50.0]"), "ct.load_zone"),
            (ct("density = inf"), "ct.density"),
            (ct("width = nan"), "ct.width"),
            (
                MINIMAL.replace("y = \"fixed\"", "y = { velocity = nan }"),
                "constraint[0].y",
            ),
            (
                MINIMAL.replace("max = [3.0, 0.1]", "max = [inf, 0.1]"),
                "constraint[0].min/max",
            ),
            (
                MINIMAL.replace(
                    "material = {",
                    "initial_velocity = [nan, 0.0]\nmaterial = {",
                ),
                "body[0].initial_velocity",
            ),
            (
                MINIMAL.replace("y = \"fixed\"", "y = \"fixed\"\nrise_time = -1.0"),
                "constraint[0].rise_time",
            ),
            (
                MINIMAL.replace("max = [2.0, 2.0]", "max = [-2.0, 2.0]"),
                "body[0].geometry",
            ),
            (MINIMAL.replace("name = \"t\"", "name = \"\""), "run.name"),
            (
                MINIMAL.replace("name = \"base\"", "name = \"a,b\""),
                "constraint[0].name",
            ),
            (
                format!(
                    "{MINIMAL}\n[[constraint]]\nname = \"base\"\nmin = [0.0, 0.0]\nmax = [1.0, 1.0]\n"
                ),
                "constraint[1].name",
            ),
            (format!("body_force = [0.0, nan]\n{MINIMAL}"), "body_force"),
        ];
        for (text, field) in cases {
            let e = RunConfig::from_str_named(&text, "t.toml")
                .expect_err(field)
                .to_string();
            assert!(
                e.starts_with("t.toml: field `") && e.contains(field),
                "{field}: {e}"
            );
        }
    }
}
