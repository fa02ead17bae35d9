//! Reading configuration text the way people write it: a problem is reported at its file, line and
//! column ([`SourceText::at`] → [`Located`]), and a value is a bare number (SI) or a number with a
//! unit ([`Quantity`], converted by [`crate::units`]).
//!
//! Every TOML file of the project (model, variables, stand, nightly job) reads through these, so
//! an error looks the same wherever it comes from:
//!
//! ```
//! use rfe::source::SourceText;
//! let text = "[shaker]\nbaud = 0\n";
//! let e = SourceText::new("stand.toml", text).at(16..17, "baud must be > 0");
//! assert_eq!(e.to_string(), "stand.toml:2:8: baud must be > 0");
//! ```

use std::ops::Range;

use serde::Deserialize;
use serde_spanned::Spanned;

use crate::units::{parse_quantity, Dim, UnitError};

/// A problem at a place in a text file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}:{line}:{column}: {message}")]
pub struct Located {
    /// File name as the user gave it.
    pub file: String,
    /// 1-based line.
    pub line: usize,
    /// 1-based column, in characters.
    pub column: usize,
    /// What is wrong and how to fix it.
    pub message: String,
}

/// A text being read and the name of the file it came from.
#[derive(Debug, Clone, Copy)]
pub struct SourceText<'a> {
    /// File name as the user gave it.
    pub file: &'a str,
    /// Its whole text.
    pub text: &'a str,
}

impl<'a> SourceText<'a> {
    /// The text of `file`.
    pub fn new(file: &'a str, text: &'a str) -> SourceText<'a> {
        SourceText { file, text }
    }

    /// A problem at the start of the byte range `span`.
    pub fn at(&self, span: Range<usize>, message: impl Into<String>) -> Located {
        let (line, column) = line_col(self.text, span.start);
        Located {
            file: self.file.into(),
            line,
            column,
            message: message.into(),
        }
    }

    /// The SI value of `v`, which must have dimension `dim`; `field` names it in the error.
    pub fn quantity(&self, v: &Spanned<Quantity>, dim: Dim, field: &str) -> Result<f64, Located> {
        v.get_ref()
            .si(dim)
            .map_err(|e| self.at(v.span(), format!("{field}: {e}")))
    }

    /// As [`SourceText::quantity`], and it must be > 0.
    pub fn positive(&self, v: &Spanned<Quantity>, dim: Dim, field: &str) -> Result<f64, Located> {
        let x = self.quantity(v, dim, field)?;
        if x > 0.0 {
            Ok(x)
        } else {
            Err(self.at(
                v.span(),
                format!("{field} must be > 0 ({}), got {x}", dim.describe()),
            ))
        }
    }
}

/// A JSON text that does not deserialize: where and what.
#[derive(Debug, Clone, PartialEq)]
pub struct JsonProblem {
    /// Path of the bad item, e.g. `$.sdes[3].k`.
    pub path: String,
    /// What is wrong, with its line and column.
    pub message: String,
}

/// Deserializes a JSON text, naming the path of the item where it fails.
pub fn from_json<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, JsonProblem> {
    let de = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let inner = e.inner();
        JsonProblem {
            path: format!("$.{}", e.path())
                .replace("$.?", "$")
                .replace(".[", "["),
            message: format!("{inner} (line {}, column {})", inner.line(), inner.column()),
        }
    })
}

/// Reads a file that is JSON when its text starts with `{` and another format otherwise, and
/// parses it with `json` or `other` (each given the text and the file's name).
pub fn read_json_or<T, E>(
    path: &std::path::Path,
    io: impl FnOnce(std::io::Error) -> E,
    json: impl FnOnce(&str, &str) -> Result<T, E>,
    other: impl FnOnce(&str, &str) -> Result<T, E>,
) -> Result<T, E> {
    let text = std::fs::read_to_string(path).map_err(io)?;
    let origin = path.display().to_string();
    if text.trim_start().starts_with('{') {
        json(&text, &origin)
    } else {
        other(&text, &origin)
    }
}

/// `text` without a leading UTF-8 byte-order mark (spreadsheet programs and Windows editors write
/// one); every text reader of the project starts with this.
pub fn strip_bom(text: &str) -> &str {
    text.strip_prefix('\u{feff}').unwrap_or(text)
}

/// 1-based line and column (in characters) of a byte offset into `text`.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let column = before
        .rsplit('\n')
        .next()
        .map(|l| l.chars().count())
        .unwrap_or(0)
        + 1;
    (line, column)
}

/// A value as written in a file: a bare number (already SI) or a string with a unit
/// (`"320 mm"`, `"4 kN"`, `"10.2 mV/g"`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum Quantity {
    /// SI number.
    Number(f64),
    /// Number and unit.
    Text(String),
}

impl Quantity {
    /// The value in SI, checking that a unit has dimension `dim` and that it is finite.
    pub fn si(&self, dim: Dim) -> Result<f64, UnitError> {
        match self {
            Quantity::Number(x) if x.is_finite() => Ok(*x),
            Quantity::Number(x) => Err(UnitError::NotFinite(x.to_string())),
            Quantity::Text(s) => parse_quantity(s, dim),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_and_column_count_characters() {
        let text = "a = 1\nµ = \"x\"\n";
        assert_eq!(line_col(text, 0), (1, 1));
        // After the two-byte µ and " = ": the fifth character of line 2.
        assert_eq!(line_col(text, text.find('"').unwrap_or(0)), (2, 5));
        // Offsets past the end or inside a character are clamped.
        assert_eq!(line_col(text, 1000).0, 3);
        assert_eq!(line_col(text, 7), (2, 1));
    }

    #[test]
    fn quantities_read_numbers_and_units() {
        assert_eq!(Quantity::Number(3.0).si(Dim::MASS), Ok(3.0));
        assert_eq!(Quantity::Text("320 mm".into()).si(Dim::LENGTH), Ok(0.32));
        assert!(Quantity::Number(f64::NAN).si(Dim::MASS).is_err());
        assert!(Quantity::Text("4 kN".into()).si(Dim::LENGTH).is_err());
    }
}
