//! Bad input as the layers below the application report it: the configuration key, the value given and
//! what is allowed. The configuration's own checks, the scenario and the model all report a refused
//! value this way; the application adds the file (`ConfigError::Invalid`, `crate::config`) and exits
//! with code 2 (`docs/bad-input.md`).

/// Serde's field defaults, one line each: `#[serde(default = "name")]` needs a function, so each
/// `name: Type = value;` becomes `fn name() -> Type { value }`.
macro_rules! serde_defaults {
    ($($name:ident: $ty:ty = $value:expr;)*) => {
        $(fn $name() -> $ty {
            $value
        })*
    };
}
pub(crate) use serde_defaults;

/// A value that a check refused: the key path in the configuration (`body[1].geometry`,
/// `constraint[0]`, `rigid_body.loading_plate.contact`), the value given and what is allowed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("field `{key}` = {value}: {allowed}")]
pub struct BadValue {
    /// Dotted key path.
    pub key: String,
    /// The value given.
    pub value: String,
    /// What is allowed.
    pub allowed: String,
}

impl BadValue {
    /// `key` = `value` is refused; `allowed` says what is allowed.
    pub fn new(
        key: impl Into<String>,
        value: impl Into<String>,
        allowed: impl Into<String>,
    ) -> Self {
        Self {
            key: key.into(),
            value: value.into(),
            allowed: allowed.into(),
        }
    }
}

/// A number as the errors show it: plainly (`-0.000001`, `4300`), or in scientific notation when that
/// would take more than 16 digits (`1e300`, `5e-324`).
pub fn shown(v: f64) -> String {
    let a = v.abs();
    if a.is_finite() && a != 0.0 && !(1e-6..1e16).contains(&a) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}
