//! The small CSV reader of reference files and of the run's `history.csv`.

use super::{Result, bad};
use std::path::Path;

/// A small CSV table: header and rows, each with its 1-based line number in the file.
pub(super) struct Csv {
    /// File name (messages).
    pub(super) name: String,
    /// Line of the header.
    pub(super) header_line: usize,
    /// Column names.
    pub(super) header: Vec<String>,
    /// Rows: line, fields.
    pub(super) rows: Vec<(usize, Vec<String>)>,
}

impl Csv {
    /// Parses `text`; `name` (the file) prefixes every message.
    pub(super) fn parse(text: &str, name: &str) -> Result<Self> {
        let mut header: Option<(usize, Vec<String>)> = None;
        let mut rows = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let trimmed = line.trim();
            if trimmed.is_empty() || trimmed.starts_with('#') {
                continue;
            }
            let fields: Vec<String> = trimmed.split(',').map(|f| f.trim().to_owned()).collect();
            match &header {
                None => header = Some((i + 1, fields)),
                Some((_, h)) => {
                    if fields.len() != h.len() {
                        return Err(bad(format!(
                            "{name}:{}: {} fields, the header has {} ({})",
                            i + 1,
                            fields.len(),
                            h.len(),
                            h.join(",")
                        )));
                    }
                    rows.push((i + 1, fields));
                }
            }
        }
        let (header_line, header) =
            header.ok_or_else(|| bad(format!("{name}: no header line (the file is empty)")))?;
        if let Some(empty) = header.iter().position(|h| h.is_empty()) {
            return Err(bad(format!(
                "{name}:{header_line}: header field {} is empty",
                empty + 1
            )));
        }
        Ok(Self {
            name: name.to_owned(),
            header_line,
            header,
            rows,
        })
    }

    /// Reads and parses the file at `path`.
    pub(super) fn read(path: &Path) -> Result<Self> {
        let text = crate::input::read_text_input(path).map_err(|e| bad(e.to_string()))?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Position of the column `name`.
    pub(super) fn column_index(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    /// `text` (at `line`, in `column`) as a finite number.
    pub(super) fn number(&self, line: usize, column: &str, text: &str) -> Result<f64> {
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(bad(format!(
                "{}:{line}: `{column}` = `{text}` is not a finite number",
                self.name
            ))),
        }
    }
}
