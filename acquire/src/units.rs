//! Physical values in files: a bare number (SI) or a string with a unit (`"320 mm"`, `"4 kN"`,
//! `"10.2 mV/g"`), converted to SI on reading.

use serde::Deserialize;

/// The dimension a value must have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dimension {
    /// m
    Length,
    /// kg
    Mass,
    /// N
    Force,
    /// Hz
    Frequency,
    /// s
    Time,
    /// N/m
    Stiffness,
    /// m/s²
    Acceleration,
    /// V per physical unit (V/N for force, V/(m/s²) for acceleration)
    Sensitivity,
    /// dimensionless
    Ratio,
}

impl Dimension {
    /// The SI unit, for messages.
    pub fn si(&self) -> &'static str {
        match self {
            Dimension::Length => "m",
            Dimension::Mass => "kg",
            Dimension::Force => "N",
            Dimension::Frequency => "Hz",
            Dimension::Time => "s",
            Dimension::Stiffness => "N/m",
            Dimension::Acceleration => "m/s2",
            Dimension::Sensitivity => "V/N or V/(m/s2)",
            Dimension::Ratio => "(no unit)",
        }
    }
}

const G0: f64 = 9.80665;

const UNITS: &[(&str, Dimension, f64)] = &[
    ("m", Dimension::Length, 1.0),
    ("cm", Dimension::Length, 1e-2),
    ("mm", Dimension::Length, 1e-3),
    ("um", Dimension::Length, 1e-6),
    ("µm", Dimension::Length, 1e-6),
    ("kg", Dimension::Mass, 1.0),
    ("g", Dimension::Mass, 1e-3),
    ("t", Dimension::Mass, 1e3),
    ("N", Dimension::Force, 1.0),
    ("kN", Dimension::Force, 1e3),
    ("Hz", Dimension::Frequency, 1.0),
    ("kHz", Dimension::Frequency, 1e3),
    ("s", Dimension::Time, 1.0),
    ("ms", Dimension::Time, 1e-3),
    ("N/m", Dimension::Stiffness, 1.0),
    ("N/mm", Dimension::Stiffness, 1e3),
    ("N/um", Dimension::Stiffness, 1e6),
    ("N/µm", Dimension::Stiffness, 1e6),
    ("kN/mm", Dimension::Stiffness, 1e6),
    ("m/s2", Dimension::Acceleration, 1.0),
    ("m/s^2", Dimension::Acceleration, 1.0),
    ("m/s²", Dimension::Acceleration, 1.0),
    ("mm/s2", Dimension::Acceleration, 1e-3),
    ("g", Dimension::Acceleration, G0),
    ("mg", Dimension::Acceleration, G0 * 1e-3),
    ("V/N", Dimension::Sensitivity, 1.0),
    ("mV/N", Dimension::Sensitivity, 1e-3),
    ("V/kN", Dimension::Sensitivity, 1e-3),
    ("mV/g", Dimension::Sensitivity, 1e-3 / G0),
    ("V/g", Dimension::Sensitivity, 1.0 / G0),
    ("V/(m/s2)", Dimension::Sensitivity, 1.0),
    ("mV/(m/s2)", Dimension::Sensitivity, 1e-3),
    ("V/(m/s^2)", Dimension::Sensitivity, 1.0),
    ("mV/(m/s^2)", Dimension::Sensitivity, 1e-3),
    ("%", Dimension::Ratio, 1e-2),
];

/// A value as written in a file: a number (already SI) or a string with a unit.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum Value {
    /// SI number.
    Number(f64),
    /// Number and unit.
    Text(String),
}

impl Value {
    /// Converts to SI, checking the unit has the wanted dimension. The error says what was
    /// expected (without location; the caller adds file:line).
    pub fn si(&self, dim: Dimension) -> Result<f64, String> {
        match self {
            Value::Number(x) if x.is_finite() => Ok(*x),
            Value::Number(x) => Err(format!("{x} is not a finite number")),
            Value::Text(s) => parse_with_unit(s, dim),
        }
    }
}

/// Parses `"<number> <unit>"` into SI.
pub fn parse_with_unit(s: &str, dim: Dimension) -> Result<f64, String> {
    let t = s.trim();
    let split = t
        .char_indices()
        .find(|&(i, c)| {
            !(c.is_ascii_digit()
                || c == '.'
                || c == '-'
                || c == '+'
                || ((c == 'e' || c == 'E')
                    && i > 0
                    && t[i + 1..]
                        .starts_with(|d: char| d.is_ascii_digit() || d == '-' || d == '+')))
        })
        .map(|(i, _)| i)
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let x: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} does not start with a number (write e.g. \"320 mm\")"))?;
    let unit = unit.trim();
    if unit.is_empty() {
        return Ok(x);
    }
    match UNITS.iter().find(|(u, d, _)| *u == unit && *d == dim) {
        Some((_, _, f)) => Ok(x * f),
        None => {
            let known: Vec<&str> = UNITS
                .iter()
                .filter(|(_, d, _)| *d == dim)
                .map(|(u, _, _)| *u)
                .collect();
            Err(format!(
                "unit {unit:?} in {s:?} is not a {dim:?} unit; use one of {}",
                known.join(", ")
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_units_and_rejects_wrong_dimensions() {
        assert_eq!(parse_with_unit("320 mm", Dimension::Length), Ok(0.32));
        assert_eq!(parse_with_unit("4 kN", Dimension::Force), Ok(4000.0));
        assert_eq!(parse_with_unit("2e8 N/m", Dimension::Stiffness), Ok(2e8));
        assert_eq!(parse_with_unit("1.5e-3", Dimension::Length), Ok(1.5e-3));
        assert!(
            (parse_with_unit("100 mV/g", Dimension::Sensitivity).unwrap() - 0.1 / G0).abs() < 1e-15
        );
        assert!(parse_with_unit("4 kN", Dimension::Length)
            .unwrap_err()
            .contains("not a Length unit"));
        assert!(parse_with_unit("abc", Dimension::Length).is_err());
        assert_eq!(Value::Number(3.0).si(Dimension::Mass), Ok(3.0));
    }
}
