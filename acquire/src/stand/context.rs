//! How the stand file's text is read: errors located at file:line:column and quantities with units
//! converted to SI, shared by every section's parser.

use std::ops::Range;

use serde_spanned::Spanned;

use rfe::source::{Located, Quantity as Value, SourceText};
use rfe::units::Dim;

/// A stand-file error: where and what (file:line:column: message).
pub type StandError = Located;

/// Reads the stand file's text: locates errors and converts quantities.
pub(super) struct Ctx<'a> {
    pub(super) src: SourceText<'a>,
}

impl<'a> Ctx<'a> {
    pub(super) fn new(file: &'a str, text: &'a str) -> Ctx<'a> {
        Ctx {
            src: SourceText::new(file, text),
        }
    }

    pub(super) fn at(&self, span: Range<usize>, message: impl Into<String>) -> StandError {
        self.src.at(span, message)
    }

    pub(super) fn line_of(&self, span: Range<usize>) -> usize {
        rfe::source::line_col(self.src.text, span.start).0
    }

    pub(super) fn value(
        &self,
        v: &Spanned<Value>,
        dim: Dim,
        what: &str,
    ) -> Result<f64, StandError> {
        self.src.quantity(v, dim, what)
    }

    pub(super) fn positive(
        &self,
        v: &Spanned<Value>,
        dim: Dim,
        what: &str,
    ) -> Result<f64, StandError> {
        self.src.positive(v, dim, what)
    }

    pub(super) fn unit_vector(
        &self,
        v: &Spanned<Vec<f64>>,
        what: &str,
    ) -> Result<[f64; 3], StandError> {
        let d = v.get_ref();
        if d.len() != 3 || d.iter().any(|x| !x.is_finite()) {
            return Err(self.at(v.span(), format!("{what} must be three numbers [x, y, z]")));
        }
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if n < 1e-9 {
            return Err(self.at(
                v.span(),
                format!("{what} has zero length; give the sensor's measuring axis, e.g. [1, 0, 0]"),
            ));
        }
        Ok([d[0] / n, d[1] / n, d[2] / n])
    }

    pub(super) fn probability(
        &self,
        v: &Option<Spanned<f64>>,
        what: &str,
    ) -> Result<f64, StandError> {
        match v {
            None => Ok(0.0),
            Some(p) if (0.0..=1.0).contains(p.get_ref()) => Ok(*p.get_ref()),
            Some(p) => Err(self.at(
                p.span(),
                format!("faults.{what} is a probability per frame and must be within 0..1"),
            )),
        }
    }
}

/// A serial line's bit rate, `default` when absent; 0 is an error.
pub(super) fn baud(
    cx: &Ctx<'_>,
    v: &Option<Spanned<u32>>,
    field: &str,
    default: u32,
) -> Result<u32, StandError> {
    match v {
        None => Ok(default),
        Some(b) if *b.get_ref() == 0 => Err(cx.at(
            b.span(),
            format!("{field} = 0: give the serial line's bit rate, e.g. {default}"),
        )),
        Some(b) => Ok(*b.get_ref()),
    }
}
