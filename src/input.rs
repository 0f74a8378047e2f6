//! Bad input as the layers below the application report it: the configuration key, the value given and
//! what is allowed. The configuration's own checks, the scenario and the model all report a refused
//! value this way; the application adds the file (`ConfigError::Invalid`, `crate::config`) and exits
//! with code 2 (`docs/bad-input.md`). Every file read as input passes one check first
//! ([`check_input_file`]): a regular file below the limit of its kind.

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

/// The most characters of a value given by the user (a `--set key=value`, a study set) that an error
/// line repeats.
pub const ECHO_MAX: usize = 80;

/// `text` as an error line repeats it: whole up to [`ECHO_MAX`] characters, else its first
/// [`ECHO_MAX`] characters and its length (`grid.cell_size=11111... (100016 bytes)`), so that a huge
/// value does not flood the terminal.
pub fn echoed(text: &str) -> String {
    match text.char_indices().nth(ECHO_MAX) {
        None => text.to_owned(),
        Some((end, _)) => format!("{}... ({} bytes)", &text[..end], text.len()),
    }
}

/// The largest text input the program reads: 64 MiB (67,108,864 bytes). Configurations, run records
/// (`run.json`), crack records (`crack.json`), study set files and PETSc options files are a few KB; a
/// run's `history.csv` and reference CSV files about half a KB per step (some 100,000 steps fit).
/// Anything larger (or endless, such as `/dev/zero`) is refused before it is read, so that a wrong file
/// cannot exhaust the memory.
pub const TEXT_INPUT_MAX: u64 = 64 << 20;

/// The largest HDF5 input the program opens (snapshots `fields_*.h5`, `checkpoint.h5`): 64 GiB
/// (68,719,476,736 bytes), far above what a run that fits in memory writes; HDF5 reads such a file by
/// dataset, never whole.
pub const DATA_INPUT_MAX: u64 = 64 << 30;

/// Why an input file was refused ([`check_input_file`]).
#[derive(Debug, Clone, PartialEq)]
pub enum InputProblem {
    /// The file does not exist.
    Missing,
    /// The file cannot be inspected or read (the system's reason).
    Unreadable(String),
    /// The path is not a regular file: a directory, FIFO, socket or device (what it is).
    NotRegular(&'static str),
    /// The file holds more bytes (given) than the limit.
    TooLarge(u64),
}

/// An input file refused before (or while) it was read: the path, why, and the limit of its kind.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {}", self.reason())]
pub struct InputError {
    /// The path as given.
    pub path: String,
    /// Why it was refused.
    pub problem: InputProblem,
    /// The largest size allowed for the file's kind (bytes).
    pub limit: u64,
}

impl InputError {
    /// The message without the path: `cannot read: ...`, `is a FIFO (named pipe), not a regular file: ...`.
    pub fn reason(&self) -> String {
        let allowed = format!(
            "an input must be a regular file of at most {} ({} bytes)",
            size_shown(self.limit),
            self.limit
        );
        match &self.problem {
            InputProblem::Missing => "cannot read: no such file".to_owned(),
            InputProblem::Unreadable(e) => format!("cannot read: {e}"),
            InputProblem::NotRegular(what) => format!("is {what}, not a regular file: {allowed}"),
            InputProblem::TooLarge(n) => format!("is {} ({n} bytes): {allowed}", size_shown(*n)),
        }
    }

    /// Whether the file does not exist (an optional input may be absent).
    pub fn is_missing(&self) -> bool {
        self.problem == InputProblem::Missing
    }
}

/// A size in bytes as the errors show it: `16 MiB`, `64 GiB`, `20.5 MiB`.
fn size_shown(bytes: u64) -> String {
    let (value, unit) = match bytes {
        b if b >= 1 << 30 => (b as f64 / (1u64 << 30) as f64, "GiB"),
        b if b >= 1 << 20 => (b as f64 / (1u64 << 20) as f64, "MiB"),
        b if b >= 1 << 10 => (b as f64 / (1u64 << 10) as f64, "KiB"),
        b => return format!("{b} B"),
    };
    if value.fract() == 0.0 {
        format!("{value:.0} {unit}")
    } else {
        format!("{value:.1} {unit}")
    }
}

/// The check of every file the program reads as input, before it is opened: `path` (symbolic links
/// followed) must be a regular file of at most `limit` bytes ([`TEXT_INPUT_MAX`], [`DATA_INPUT_MAX`]).
/// A FIFO or a device would block the program or be read as an endless stream, a directory is no
/// input, and a huge file would exhaust the memory. Returns the file's size.
pub fn check_input_file(path: &std::path::Path, limit: u64) -> Result<u64, InputError> {
    use std::os::unix::fs::FileTypeExt;
    let refused = |problem| InputError {
        path: path.display().to_string(),
        problem,
        limit,
    };
    let meta = std::fs::metadata(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => refused(InputProblem::Missing),
        _ => refused(InputProblem::Unreadable(e.to_string())),
    })?;
    let kind = meta.file_type();
    let what = if kind.is_file() {
        None
    } else if kind.is_dir() {
        Some("a directory")
    } else if kind.is_fifo() {
        Some("a FIFO (named pipe)")
    } else if kind.is_char_device() {
        Some("a character device")
    } else if kind.is_block_device() {
        Some("a block device")
    } else if kind.is_socket() {
        Some("a socket")
    } else {
        Some("no file")
    };
    if let Some(what) = what {
        return Err(refused(InputProblem::NotRegular(what)));
    }
    if meta.len() > limit {
        return Err(refused(InputProblem::TooLarge(meta.len())));
    }
    Ok(meta.len())
}

/// The text of the input file `path`, checked by [`check_input_file`] with the limit
/// [`TEXT_INPUT_MAX`] and read no further than the limit (a file that grows meanwhile is refused too).
pub fn read_text_input(path: &std::path::Path) -> Result<String, InputError> {
    use std::io::Read as _;
    check_input_file(path, TEXT_INPUT_MAX)?;
    let unreadable = |e: std::io::Error| InputError {
        path: path.display().to_string(),
        problem: InputProblem::Unreadable(e.to_string()),
        limit: TEXT_INPUT_MAX,
    };
    let mut text = String::new();
    std::fs::File::open(path)
        .map_err(unreadable)?
        .take(TEXT_INPUT_MAX + 1)
        .read_to_string(&mut text)
        .map_err(unreadable)?;
    if text.len() as u64 > TEXT_INPUT_MAX {
        let size = std::fs::metadata(path).map_or(text.len() as u64, |m| m.len());
        return Err(InputError {
            path: path.display().to_string(),
            problem: InputProblem::TooLarge(size),
            limit: TEXT_INPUT_MAX,
        });
    }
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn input_files_must_be_regular_files_below_the_limit() {
        let dir = std::env::temp_dir().join(format!("mpmc-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let small = dir.join("small.toml");
        std::fs::write(&small, "a = 1\n").expect("write");
        assert_eq!(read_text_input(&small).expect("a small file"), "a = 1\n");
        let big = dir.join("big.csv");
        std::fs::File::create(&big)
            .and_then(|f| f.set_len(TEXT_INPUT_MAX + 1))
            .expect("a sparse file");
        let e = read_text_input(&big).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "{}: is 64.0 MiB (67108865 bytes): an input must be a regular file of at most 64 MiB \
                 (67108864 bytes)",
                big.display()
            )
        );
        assert!(check_input_file(&big, DATA_INPUT_MAX).is_ok());
        let e = read_text_input(Path::new("/dev/zero")).unwrap_err();
        assert!(e.to_string().starts_with("/dev/zero: is a character device, not a regular file: an input must be a regular file of at most 64 MiB"), "{e}");
        let e = read_text_input(&dir).unwrap_err();
        assert_eq!(e.problem, InputProblem::NotRegular("a directory"));
        let e = read_text_input(&dir.join("absent")).unwrap_err();
        assert!(e.is_missing(), "{e}");
        assert_eq!(size_shown(DATA_INPUT_MAX), "64 GiB");
        std::fs::remove_dir_all(&dir).ok();
    }
}
