//! Run configuration (TOML), one section per concept of the method; unknown fields are rejected.
//! Units: mm, s, N, MPa, t (tonne); density in t/mm^3, velocity in mm/s.
//!
//! ```toml
//! [run]                 # name, steps, output cadence, PETSc options (the command line wins)
//! [time]                # dt, Newmark beta/gamma, quasi-static, dt_min, initial acceleration
//! [grid]                # cell size, margin cells
//! [shape]               # interpolator, points per cell
//! [ct]                  # optional: the compact tension specimen generator (ct.rs; built by scenario.rs)
//! [[body]]              # deformable bodies: geometry, density, material, initial velocity
//! [[constraint]]        # grid nodes in a box, per component: "free", "fixed" or { velocity = v }
//! [[rigid_body]]        # rigid bodies of particles moving with a prescribed velocity
//! ```
//!
//! Every error names the file, the field and what is allowed. Each section checks itself (`validate`
//! beside its type: control.rs for run, time, grid, shape and extrusion, bodies.rs for bodies,
//! constraints, rigid bodies and loads, ct.rs for the CT specimen); [`RunConfig`] checks what spans
//! sections (the names of history.csv columns, a run without bodies).

#[macro_use]
mod choice;
mod bodies;
mod control;
mod ct;
#[cfg(test)]
mod tests;

pub use bodies::{
    BodyGeometry, BodySection, ConstraintSection, ContactSection, Keyword, LoadSection, MotionSpec,
    RigidBodySection,
};
pub use choice::Choice;
pub use control::{
    ExtrusionSection, GridSection, PathSection, RunSection, ShapeSection, TimeSection,
};
pub use ct::{CtSection, LoadIntroduction, NotchTip};

use crate::input::{BadValue, echoed};
use crate::material::{Material, MaterialError};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A configuration error: file, field and what is allowed.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file is no regular file below the limit of inputs, or could not be read
    /// ([`crate::input::read_text_input`]).
    #[error("{0}")]
    Read(#[from] crate::input::InputError),
    /// TOML syntax or schema error (serde names the field and the expected type).
    #[error("{file}: {message}")]
    Parse {
        /// File name.
        file: String,
        /// Parser message with line and column.
        message: String,
    },
    /// A value out of its range.
    #[error("{file}: field `{field}` = {}: {allowed}", echoed(value))]
    Invalid {
        /// File name.
        file: String,
        /// Dotted field name.
        field: String,
        /// Offending value (an error line shows its first [`crate::input::ECHO_MAX`] characters).
        value: String,
        /// What is allowed.
        allowed: String,
    },
    /// The checked configuration could not be built (seeding, the grid, a model the scenario made).
    #[error("{file}: {message}")]
    Build {
        /// File name.
        file: String,
        /// What failed.
        message: String,
    },
}

impl ConfigError {
    /// The error of a value the scenario or the model refused ([`BadValue`]), in the configuration
    /// `file` (with its overrides, as [`source_label`] names it).
    pub fn in_file(file: &str, bad: BadValue) -> Self {
        ConfigError::Invalid {
            file: file.to_owned(),
            field: bad.key,
            value: bad.value,
            allowed: bad.allowed,
        }
    }
}

/// Builds the errors of one file's checks.
#[derive(Clone, Copy)]
struct Check<'a> {
    /// The file (with its overrides) as errors name it.
    file: &'a str,
}

impl Check<'_> {
    /// The error: `field` = `value` is not allowed; `allowed` says what is.
    fn bad(self, field: &str, value: String, allowed: &str) -> ConfigError {
        ConfigError::Invalid {
            file: self.file.to_owned(),
            field: field.to_owned(),
            value,
            allowed: allowed.to_owned(),
        }
    }

    /// `Ok` where `ok` holds, else the error of `field` = `value` ([`Check::bad`]).
    fn ensure(
        self,
        ok: bool,
        field: &str,
        value: String,
        allowed: &str,
    ) -> Result<(), ConfigError> {
        match ok {
            true => Ok(()),
            false => Err(self.bad(field, value, allowed)),
        }
    }

    /// The error of the material of the table `section` (e.g. `ct.material`): a parameter out of its
    /// range is named by its full key and value, other errors by the table.
    fn material(self, section: &str, e: &MaterialError) -> ConfigError {
        match e {
            MaterialError::InvalidParameter {
                field,
                value,
                allowed,
            } => self.bad(&format!("{section}.{field}"), shown(*value), allowed),
            other => self.bad(section, String::new(), &other.to_string()),
        }
    }
}

/// The table under the key `k` of `t` for a `--set` override: `name` (created if absent) or `name[i]`,
/// entry `i` of an array of tables such as `[[body]]`.
fn descend<'t>(t: &'t mut toml::Table, k: &str) -> Result<&'t mut toml::Table, String> {
    let indexed = k
        .strip_suffix(']')
        .and_then(|r| r.split_once('['))
        .map(|(name, i)| (name, i.parse::<usize>()));
    match indexed {
        None => t
            .entry(k.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            .as_table_mut()
            .ok_or_else(|| format!("`{k}` is not a table")),
        Some((name, Err(_))) => Err(format!(
            "`{k}`: an index is a number, e.g. {name}[0] for the first [[{name}]]"
        )),
        Some((name, Ok(i))) => {
            let entries = t
                .get_mut(name)
                .and_then(toml::Value::as_array_mut)
                .ok_or_else(|| {
                    format!("`{name}` is no array of tables ([[{name}]]) in the file")
                })?;
            let n = entries.len();
            entries
                .get_mut(i)
                .and_then(toml::Value::as_table_mut)
                .ok_or_else(|| {
                    format!(
                        "`{k}`: the file has {n} [[{name}]] (indices 0 to {})",
                        n.max(1) - 1
                    )
                })
        }
    }
}

pub use crate::input::shown;

/// Refuses an array of numbers at `path` (a dotted key, `""` at the top) or below it whose length is not 2:
/// every vector, point and range of a configuration (`body_force`, `initial_velocity`, corners, vertices,
/// normals, pins, forces, `load_zone`) has an x and a y component, the set-up being plane (`[extrusion]`
/// extrudes it along z).
/// A `[[body]]`'s geometry other than the `include`/`exclude` lists is skipped: it may be of space, and
/// its reader checks its vectors ([`crate::csg`]).
fn check_vector_lengths(v: &toml::Value, path: &str, c: Check) -> Result<(), ConfigError> {
    let body_geometry = path
        .strip_prefix("body[")
        .and_then(|r| r.strip_suffix("].geometry"))
        .is_some_and(|i| i.parse::<usize>().is_ok());
    if body_geometry
        && v.as_table()
            .is_some_and(|t| !t.contains_key("include") && !t.contains_key("exclude"))
    {
        return Ok(());
    }
    let join = |k: &str| match path {
        "" => k.to_owned(),
        _ => format!("{path}.{k}"),
    };
    match v {
        toml::Value::Table(t) => t
            .iter()
            .try_for_each(|(k, v)| check_vector_lengths(v, &join(k), c)),
        toml::Value::Array(items) => {
            let numeric =
                |x: &toml::Value| matches!(x, toml::Value::Integer(_) | toml::Value::Float(_));
            if !items.is_empty() && items.iter().all(numeric) {
                if items.len() == 2 {
                    return Ok(());
                }
                return Err(c.bad(
                    path,
                    v.to_string(),
                    &format!(
                        "2 components (x, y), not {}: the configuration describes a plane set-up, a \
                         2D run ([extrusion] extrudes it along z)",
                        items.len()
                    ),
                ));
            }
            items
                .iter()
                .enumerate()
                .try_for_each(|(i, x)| check_vector_lengths(x, &format!("{path}[{i}]"), c))
        }
        _ => Ok(()),
    }
}

/// The sections of a configuration that are tables (`[ct]`), each with a key to show as an example.
const TABLE_SECTIONS: [(&str, &str); 6] = [
    ("run", "steps"),
    ("time", "dt"),
    ("grid", "cell_size"),
    ("shape", "kind"),
    ("ct", "loading_rate"),
    ("extrusion", "thickness"),
];

/// Why `--set KEY=value` may not put the non-table `value` where the file has the table `old` (or where
/// a top-level section, `top`, is a table): a table is changed key by key; `None` when it may.
fn replaces_table(
    old: Option<&toml::Value>,
    top: bool,
    key: &str,
    value: &toml::Value,
) -> Option<String> {
    if value.is_table() {
        return None;
    }
    let listed = |t: &toml::Table| t.keys().cloned().collect::<Vec<_>>().join(", ");
    match old {
        Some(toml::Value::Table(t)) => {
            let example = TABLE_SECTIONS
                .iter()
                .find(|(name, _)| top && *name == key)
                .map(|(_, k)| *k)
                .or_else(|| t.keys().next().map(String::as_str))
                .unwrap_or("KEY");
            Some(format!(
                "`{key}` is a table: --set names a key inside it, e.g. --set {key}.{example}=...; its \
                 keys in the file: {}",
                listed(t)
            ))
        }
        Some(toml::Value::Array(a)) if !value.is_array() && a.iter().all(toml::Value::is_table) => {
            Some(format!(
                "`{key}` is an array of tables ([[{key}]]): --set names a key of one entry, e.g. \
                 --set {key}[0].name=..."
            ))
        }
        _ if top => TABLE_SECTIONS
            .iter()
            .find(|(name, _)| *name == key)
            .map(|(name, example)| {
                format!("`{name}` is a table ([{name}]): --set names a key inside it, e.g. --set {name}.{example}=...")
            }),
        _ => None,
    }
}

/// All components finite.
fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// The longest rise or ramp time (s): 1000 s, the longest time step allowed ([`DT_RANGE`]).
pub const RISE_TIME_MAX: f64 = 1e3;

/// A rise or ramp time (s) in [0, [`RISE_TIME_MAX`]].
fn time_ok(t: f64) -> bool {
    (0.0..=RISE_TIME_MAX).contains(&t)
}

/// What a rise or ramp time may be, for the errors.
const TIME_ALLOWED: &str = "a time in [0, 1000] s";

/// The densities a real solid can have (t/mm^3): from aerogels (1e-12) with room to spare down to 1e-15, up
/// to 1e-6 (forty times osmium's 2.26e-8); outside, the points' masses overflow or vanish.
pub const DENSITY_RANGE: (f64, f64) = (1e-15, 1e-6);

/// What a density must be, as the errors say it.
const DENSITY_ALLOWED: &str = "a density in [1e-15, 1e-6] t/mm^3 (concrete 2.4e-9, steel 7.85e-9)";

/// A density (t/mm^3) within [`DENSITY_RANGE`].
fn density_ok(d: f64) -> bool {
    d.is_finite() && (DENSITY_RANGE.0..=DENSITY_RANGE.1).contains(&d)
}

/// The largest speed (mm/s) of a prescribed or initial velocity: 1e7 mm/s = 10 km/s, beyond any impact
/// test on concrete; faster, a step moves the bodies through many cells.
pub const SPEED_MAX: f64 = 1e7;

/// What a velocity must be, as the errors say it.
const SPEED_ALLOWED: &str = "finite components of at most 1e7 mm/s (10 km/s) in magnitude";

/// All components finite and at most [`SPEED_MAX`] in magnitude (mm/s).
fn speed_ok(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite() && x.abs() <= SPEED_MAX)
}

/// The range of the time step (s): 1 ps to 1000 s (a quasi-static load step); outside, 1 / (beta dt^2)
/// or the prescribed displacement of a step overflows and the first step gives NaN.
pub const DT_RANGE: (f64, f64) = (1e-12, 1e3);

/// The largest body force per unit mass (mm/s^2): 1e9, about 1e5 g (gravity is 9810).
pub const BODY_FORCE_MAX: f64 = 1e9;

/// The largest resultant of a `[[load]]` (N per mm thickness): 1e9, a gigatonne-force on a millimetre;
/// beyond it the nodal forces of a real body's stiffness cannot balance it in floating point.
pub const LOAD_FORCE_MAX: f64 = 1e9;

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
    /// Path following of a quasi-static run (`[path]`); absent: the motion follows time.
    pub path: Option<PathSection>,
    /// The materials, built by the checks (which so validate them) and kept for the scenario.
    #[serde(skip)]
    materials: Materials,
}

/// The constitutive laws of a configuration, built once when it is checked.
#[derive(Debug, Clone, Default)]
pub struct Materials {
    /// `[ct]`: the concrete (`ct.material`).
    pub concrete: Option<Material>,
    /// `[ct]` with `load_introduction = "inserts"`: the inserts' steel (`ct.insert_material`).
    pub insert: Option<Material>,
    /// Each `[[body]]`'s material, in the order of the file.
    pub bodies: Vec<Material>,
}

/// How errors name a configuration file read with `overrides`: `configs/x.toml (with --set a=1)`.
pub fn source_label(file: &str, overrides: &[String]) -> String {
    if overrides.is_empty() {
        return file.to_owned();
    }
    let sets: Vec<String> = overrides
        .iter()
        .map(|o| format!("--set {}", echoed(o)))
        .collect();
    format!("{file} (with {})", sets.join(" "))
}

/// Whether the key `key` (dotted: `grid.rotation`, `body[0].density`) of the configuration text `config`
/// holds the value the configuration takes without it, i.e. a default spelled out: the text with and
/// without the key reads as the same settings. False when the key is not there or a text does not read.
pub fn holds_default(config: &str, key: &str) -> bool {
    let Ok(mut table) = toml::from_str::<toml::Table>(config) else {
        return false;
    };
    if !remove_key(&mut table, key) {
        return false;
    }
    let settings = |text: &str| {
        toml::from_str::<RunConfig>(text)
            .ok()
            .map(|c| format!("{c:?}"))
    };
    let without = toml::to_string(&table).ok();
    match (settings(config), without.as_deref().and_then(settings)) {
        (Some(with), Some(without)) => with == without,
        _ => false,
    }
}

/// Removes the dotted key `key` (`body[0].density`: entry 0 of the array of tables `body`) from
/// `table`; false when it is not there.
fn remove_key(table: &mut toml::Table, key: &str) -> bool {
    let (path, last) = key.rsplit_once('.').unwrap_or(("", key));
    let mut t = table;
    for part in path.split('.').filter(|p| !p.is_empty()) {
        let entry = match part.strip_suffix(']').and_then(|r| r.split_once('[')) {
            Some((name, i)) => i
                .parse::<usize>()
                .ok()
                .and_then(|i| t.get_mut(name)?.as_array_mut()?.get_mut(i)),
            None => t.get_mut(part),
        };
        match entry.and_then(|v| v.as_table_mut()) {
            Some(next) => t = next,
            None => return false,
        }
    }
    t.remove(last).is_some()
}

/// A TOML error on one line: the parser's message, the table it is in and, with `position`, the line and
/// column in `text`.
fn toml_message(e: &toml::de::Error, text: &str, position: bool) -> String {
    // The parser quotes the value it refused, which may be a huge --set value: cut it.
    let quoted: Vec<String> = e.message().trim().split('"').map(echoed).collect();
    let mut message = quoted.join("\"").replace('\n', " ");
    if let Some(start) = e.span().map(|span| span.start) {
        // The table is the last header up to the end of the error's line (a missing field's span is the
        // header of the table that misses it).
        let line_end = text[start.min(text.len())..]
            .find('\n')
            .map_or(text.len(), |i| start + i);
        if let Some(table) = table_named(text, line_end) {
            message += &format!(" (in {table})");
        }
        if position && let Some(before) = text.get(..start) {
            let line = before.matches('\n').count() + 1;
            let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
            message = format!("line {line}, column {column}: {message}");
        }
    }
    message
}

/// The last table header of `text` before the byte `upto` (the end of an error's line), an array's entry
/// with its index and its name if it has one: `[grid]`, `[[body]] 0`, `[[rigid_body]] 1 (name = "pin")`.
fn table_named(text: &str, upto: usize) -> Option<String> {
    let before = text.get(..upto)?.lines().count();
    let lines: Vec<&str> = text.lines().map(str::trim).collect();
    let at = lines[..before.min(lines.len())]
        .iter()
        .rposition(|l| l.starts_with('['))?;
    let header = lines[at];
    if !header.starts_with("[[") {
        return Some(header.to_owned());
    }
    let index = lines[..at].iter().filter(|l| **l == header).count();
    let name = lines[at + 1..]
        .iter()
        .take_while(|l| !l.starts_with('['))
        .find_map(|l| l.strip_prefix("name").map(str::trim_start))
        .and_then(|r| r.strip_prefix('='))
        .map(|v| format!(" (name = {})", v.trim()));
    Some(format!("{header} {index}{}", name.unwrap_or_default()))
}

impl RunConfig {
    /// Reads and validates a configuration file.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let text = crate::input::read_text_input(path)?;
        Self::from_str_named(&text, &path.display().to_string())
    }

    /// Reads a configuration file, applies `key=value` overrides (dotted keys into tables, values in TOML
    /// syntax, e.g. `shape.method="fem"` or `grid.cell_size=2.5`; a bare word is taken as a string) and
    /// validates the result. Returns the configuration and its effective text: the file with the
    /// overrides applied, in canonical TOML (sorted keys, no comments), the same for every spelling of
    /// the same configuration.
    pub fn load(path: &Path, overrides: &[String]) -> Result<(Self, String), ConfigError> {
        let file = path.display().to_string();
        let text = crate::input::read_text_input(path)?;
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
            let set = echoed(o);
            let (key, value) = o.split_once('=').ok_or_else(|| {
                parse_err(
                    &file,
                    format!("--set {set}: expected key=value (e.g. grid.cell_size=2.5)"),
                )
            })?;
            let value: toml::Value = match toml::from_str::<toml::Table>(&format!("v = {value}")) {
                Ok(mut t) => t.remove("v").unwrap_or(toml::Value::String(value.into())),
                Err(_) => toml::Value::String(value.trim().into()),
            };
            let keys: Vec<&str> = key.trim().split('.').collect();
            let mut t = &mut table;
            for k in &keys[..keys.len() - 1] {
                t = descend(t, k).map_err(|e| parse_err(&file, format!("--set {set}: {e}")))?;
            }
            let last = keys[keys.len() - 1];
            if let Some((name, _)) = last.strip_suffix(']').and_then(|r| r.split_once('[')) {
                return Err(parse_err(
                    &file,
                    format!(
                        "--set {set}: `{last}` is an entry of [[{name}]]: --set names a key inside it, \
                         e.g. --set {last}.name=..."
                    ),
                ));
            }
            if let Some(e) = replaces_table(t.get(last), keys.len() == 1, key.trim(), &value) {
                return Err(parse_err(&file, format!("--set {set}: {e}")));
            }
            t.insert(last.to_string(), value);
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
        // Lengths first: serde reads a fixed-size array from the first items and ignores the rest.
        if let Ok(table) = toml::from_str::<toml::Table>(text) {
            check_vector_lengths(&toml::Value::Table(table), "", Check { file })?;
        }
        let cfg: RunConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            file: file.to_owned(),
            message: toml_message(&e, text, position),
        })?;
        let mut cfg = cfg;
        cfg.materials = cfg.validate(file)?;
        Ok(cfg)
    }

    /// The materials as the checks built them (`[ct]`'s, then each `[[body]]`'s).
    pub fn materials(&self) -> &Materials {
        &self.materials
    }

    /// Checks every section, then what spans sections; returns the materials built on the way.
    fn validate(&self, file: &str) -> Result<Materials, ConfigError> {
        let c = Check { file };
        self.run.validate(c)?;
        self.time.validate(c)?;
        self.grid.validate(c)?;
        self.shape.validate(c)?;
        if self.shape.kind == crate::shape::ShapeKind::Bspline2 && self.grid.margin_cells < 2 {
            return Err(c.bad(
                "grid.margin_cells",
                self.grid.margin_cells.to_string(),
                "at least 2 with shape.kind = \"bspline2\" (the quadratic B-spline of a point reaches \
                 1.5 cells beyond its cell)",
            ));
        }
        if let Some(e) = &self.extrusion {
            e.validate(c, self.grid.cell_size, self.shape.method)?;
        }
        if let Some(p) = &self.path {
            p.validate(c, self.time.quasi_static)?;
        }
        if !self
            .body_force
            .iter()
            .all(|g| g.is_finite() && g.abs() <= BODY_FORCE_MAX)
        {
            return Err(c.bad(
                "body_force",
                format!("{:?}", self.body_force),
                "finite components of at most 1e9 mm/s^2 in magnitude (gravity is [0, -9810])",
            ));
        }
        if !time_ok(self.body_force_ramp) {
            return Err(c.bad("body_force_ramp", shown(self.body_force_ramp), TIME_ALLOWED));
        }
        let thickness = self.extrusion.as_ref().map(|e| e.thickness);
        let (bodies, shapes) =
            bodies::validate_bodies(&self.body, self.ct.is_some(), thickness, c)?;
        bodies::check_overlaps(&self.body, &shapes, self.grid.cell_size, thickness, c)?;
        for (i, s) in self.constraint.iter().enumerate() {
            s.validate(c, i)?;
        }
        for (i, rb) in self.rigid_body.iter().enumerate() {
            rb.validate(c, i, &self.body)?;
        }
        for (i, l) in self.load.iter().enumerate() {
            l.validate(c, i)?;
        }
        let (concrete, insert) = match &self.ct {
            Some(ct) => {
                let (concrete, insert) = ct.validate(c, self.grid.cell_size)?;
                (Some(concrete), insert)
            }
            None if self.body.is_empty() => {
                return Err(c.bad(
                    "body",
                    "[]".into(),
                    "at least one [[body]] (or a [ct] section)",
                ));
            }
            None => (None, None),
        };
        bodies::validate_names(c, &self.history_names())?;
        self.check_rotation(c)?;
        self.check_cell_size(c, &shapes)?;
        let materials = Materials {
            concrete,
            insert,
            bodies,
        };
        self.check_derived(c, &materials)?;
        Ok(materials)
    }

    /// Refuses a cell size so large that no point could be seeded: the bodies (the [ct] plate and the
    /// `[[body]]` regions together, `shapes`, in the plane) span less than half a point spacing `h / (2 n)`
    /// in a direction (`n` points per cell and direction, the first of them half a spacing inside its
    /// cell).
    fn check_cell_size(
        &self,
        c: Check,
        shapes: &[crate::csg::BodyShape],
    ) -> Result<(), ConfigError> {
        let plate = self.ct.as_ref().map(|ct| {
            (
                nalgebra::Vector2::zeros(),
                nalgebra::Vector2::new(ct.width, ct.height),
            )
        });
        let Some((lo, hi)) = plate
            .into_iter()
            .chain(
                shapes
                    .iter()
                    .filter_map(crate::csg::BodyShape::plane_bounds),
            )
            .reduce(|(lo, hi), (l, h)| (lo.inf(&l), hi.sup(&h)))
        else {
            return Ok(());
        };
        let (extent, h) = (hi - lo, self.grid.cell_size);
        let most = 2.0 * self.shape.points_per_cell as f64 * extent.min();
        if h <= most {
            return Ok(());
        }
        let cells = extent / h;
        Err(c.bad(
            "grid.cell_size",
            shown(h),
            &format!(
                "a cell size of at most {} mm: the bodies span {} x {} mm, {} x {} cells of this size, \
                 less than half a point spacing (no point would be seeded)",
                shown(most),
                shown(extent.x),
                shown(extent.y),
                shown(cells.x),
                shown(cells.y)
            ),
        ))
    }

    /// The quantities the first step derives from the inputs, each finite and > 0 for every material and
    /// its density: the P-wave modulus `M = K + 4G/3` (MPa), the wave speed `c = sqrt(M / rho)` (mm/s),
    /// the Courant number `c dt / h` and the ratio `r = rho h^2 / (beta dt^2 M)` of inertia to stiffness
    /// (`docs/theory.md`); a value that overflows or vanishes would give NaN in the first step.
    fn check_derived(&self, c: Check, materials: &Materials) -> Result<(), ConfigError> {
        let mut pairs: Vec<(String, f64, String, &Material)> = Vec::new();
        if let (Some(ct), Some(m)) = (&self.ct, &materials.concrete) {
            pairs.push(("ct.density".into(), ct.density, "ct.material".into(), m));
            if let Some(steel) = &materials.insert {
                let (d, k) = ("ct.insert_density".into(), "ct.insert_material".into());
                pairs.push((d, ct.insert_density, k, steel));
            }
        }
        for (i, (b, m)) in self.body.iter().zip(&materials.bodies).enumerate() {
            let (d, k) = (format!("body[{i}].density"), format!("body[{i}].material"));
            pairs.push((d, b.density, k, m));
        }
        let (h, dt, beta) = (self.grid.cell_size, self.time.dt, self.time.beta);
        for (density_key, rho, material_key, m) in pairs {
            let moduli = m.elastic_moduli();
            let p_wave = moduli.bulk + 4.0 * moduli.shear / 3.0;
            let speed = (p_wave / rho).sqrt();
            let courant = speed * dt / h;
            let ratio = rho * h * h / (beta * dt * dt * p_wave);
            let sane = |v: f64| v.is_finite() && v > 0.0;
            if ![p_wave, speed, courant, ratio].into_iter().all(sane) {
                return Err(c.bad(
                    "time.dt",
                    shown(dt),
                    &format!(
                        "with grid.cell_size = {h} mm, {density_key} = {rho} t/mm^3 and \
                         {material_key} (P-wave modulus {p_wave:e} MPa) the wave speed is {speed:e} \
                         mm/s, the Courant number c dt / h {courant:e} and the ratio of inertia to \
                         stiffness {ratio:e}: each must be finite and > 0 (choose dt, the cell size, \
                         the density and the moduli nearer the values of a real run)"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// What a set-up turned inside the grid (`grid.rotation` != 0) cannot have: finite elements (they
    /// are the grid's cells), a plate (the turn is about z, the extrusion is not turned), node boxes and nodal loads (they select grid nodes along
    /// the grid's axes), a rigid body with one component free and the other prescribed (a motion along
    /// one specimen axis is along no grid axis).
    fn check_rotation(&self, c: Check) -> Result<(), ConfigError> {
        if self.grid.rotation == 0.0 {
            return Ok(());
        }
        let value = self.grid.rotation.to_string();
        let refuse = |what: &str| {
            Err(c.bad(
                "grid.rotation",
                value.clone(),
                &format!("0 with {what} (a turned set-up is plane, with [ct] specimens, [[body]] and [[rigid_body]] sections whose x and y motions are both free or both prescribed)"),
            ))
        };
        if self.shape.method == crate::model::Method::Fem {
            return refuse(
                "shape.method = \"fem\" (the elements are the grid's cells, along its axes)",
            );
        }
        if self.extrusion.is_some() {
            return refuse("[extrusion]");
        }
        if !self.constraint.is_empty() {
            return refuse("[[constraint]] (node boxes along the grid's axes)");
        }
        if !self.load.is_empty() {
            return refuse("[[load]] (segments along grid lines)");
        }
        let free = |m: &MotionSpec| *m == MotionSpec::Keyword(Keyword::Free);
        if let Some(rb) = self.rigid_body.iter().find(|r| free(&r.x) != free(&r.y)) {
            return refuse(&format!(
                "[[rigid_body]] `{}`, x free and y not or y free and x not",
                rb.name
            ));
        }
        if let Some(ct) = &self.ct
            && ct.load_introduction == LoadIntroduction::Glued
        {
            return refuse(
                "ct.load_introduction = \"glued\" (the glued plates' x is free or held, their y driven)",
            );
        }
        Ok(())
    }

    /// The sets that name history.csv columns, (section, name) in the order of the file: [ct]'s two
    /// plates, the constraints, the rigid bodies, the loads.
    fn history_names(&self) -> Vec<(String, &str)> {
        let mut sets: Vec<(String, &str)> = Vec::new();
        if self.ct.is_some() {
            sets.push(("ct".into(), "loading_plate"));
            sets.push(("ct".into(), "support_plate"));
        }
        for (i, s) in self.constraint.iter().enumerate() {
            sets.push((format!("constraint[{i}]"), &s.name));
        }
        for (i, rb) in self.rigid_body.iter().enumerate() {
            sets.push((format!("rigid_body[{i}]"), &rb.name));
        }
        for (i, l) in self.load.iter().enumerate() {
            sets.push((format!("load[{i}]"), &l.name));
        }
        sets
    }

    /// Output directory of the run.
    pub fn output_dir(&self) -> PathBuf {
        self.run
            .output_dir
            .clone()
            .unwrap_or_else(|| PathBuf::from("runs").join(&self.run.name))
    }
}
