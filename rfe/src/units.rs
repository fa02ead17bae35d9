//! Quantities with units as people write them in this field: `"0.05 MPa/um"`, `"10 N/um"`,
//! `"320 mm"`, `"1.2 t"`, `"45 kg m^2"`, `"60 deg"`, `"10.2 mV/g"`, `"100 mV/(m/s^2)"`.
//! Everything is converted to SI on reading; a unit of the wrong dimension, or an unknown one, is
//! an error that says what was expected. This is the project's one unit parser: model, variables,
//! stand and measured-data files all read through it.
//!
//! Grammar: a number, then unit terms separated by spaces, `*` or `·`, each term optionally
//! raised to an integer power (`m^4`, `m4`, `m²`); `/` divides by the next term only
//! (`N*m/rad`, `MPa/um`), and a parenthesized group is one term (`V/(m/s2)`). Angles are
//! dimensionless (rad = 1, deg = π/180), `%` is 0.01. `g` is the gram, except where the field
//! needs an acceleration (`"2 g"`, `"10 mV/g"`): there it is the standard gravity 9.80665 m/s².
//!
//! ```
//! use rfe::units::{parse_quantity, Dim};
//! assert_eq!(parse_quantity("0.05 MPa/um", Dim::CONTACT_STIFFNESS).unwrap(), 0.05e12);
//! assert_eq!(parse_quantity("1.2 t", Dim::MASS).unwrap(), 1200.0);
//! assert_eq!(parse_quantity("2 g", Dim::ACCELERATION).unwrap(), 2.0 * 9.80665);
//! assert!(parse_quantity("3 furlongs", Dim::LENGTH).is_err());
//! ```

use std::fmt;

/// Standard gravity (m/s²), the `g` of accelerometer units.
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// A physical dimension as exponents of kg, m, s and A.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dim {
    kg: i8,
    m: i8,
    s: i8,
    a: i8,
}

const fn dim(kg: i8, m: i8, s: i8, a: i8) -> Dim {
    Dim { kg, m, s, a }
}

impl Dim {
    /// Pure number (also angles, ψ, ratios).
    pub const NONE: Dim = dim(0, 0, 0, 0);
    /// m.
    pub const LENGTH: Dim = dim(0, 1, 0, 0);
    /// m².
    pub const AREA: Dim = dim(0, 2, 0, 0);
    /// m⁴ (second moment of area).
    pub const SECOND_MOMENT: Dim = dim(0, 4, 0, 0);
    /// kg.
    pub const MASS: Dim = dim(1, 0, 0, 0);
    /// kg·m².
    pub const INERTIA: Dim = dim(1, 2, 0, 0);
    /// N.
    pub const FORCE: Dim = dim(1, 1, -2, 0);
    /// N·m.
    pub const MOMENT: Dim = dim(1, 2, -2, 0);
    /// N/m.
    pub const STIFFNESS: Dim = dim(1, 0, -2, 0);
    /// N·m/rad.
    pub const ROTATIONAL_STIFFNESS: Dim = dim(1, 2, -2, 0);
    /// Pa/m: contact stiffness per unit area.
    pub const CONTACT_STIFFNESS: Dim = dim(1, -2, -2, 0);
    /// Hz.
    pub const FREQUENCY: Dim = dim(0, 0, -1, 0);
    /// s.
    pub const TIME: Dim = dim(0, 0, 1, 0);
    /// m/s.
    pub const VELOCITY: Dim = dim(0, 1, -1, 0);
    /// m/s².
    pub const ACCELERATION: Dim = dim(0, 1, -2, 0);
    /// V.
    pub const VOLTAGE: Dim = dim(1, 2, -3, -1);
    /// V/N: a force sensor's sensitivity.
    pub const FORCE_SENSITIVITY: Dim = dim(0, 1, -1, -1);
    /// V/(m/s²): an accelerometer's sensitivity.
    pub const ACCELERATION_SENSITIVITY: Dim = dim(1, 1, -1, -1);
    /// m/N: receptance (dynamic compliance), displacement per force.
    pub const RECEPTANCE: Dim = dim(-1, 0, 2, 0);
    /// (m/s)/N: mobility, velocity per force.
    pub const MOBILITY: Dim = dim(-1, 0, 1, 0);
    /// (m/s²)/N: accelerance (inertance), acceleration per force.
    pub const ACCELERANCE: Dim = dim(-1, 0, 0, 0);

    fn pow(self, e: i8) -> Dim {
        dim(self.kg * e, self.m * e, self.s * e, self.a * e)
    }

    fn mul(self, o: Dim) -> Dim {
        dim(self.kg + o.kg, self.m + o.m, self.s + o.s, self.a + o.a)
    }

    /// A usual unit and an example for this dimension, for error messages.
    pub fn describe(&self) -> &'static str {
        match *self {
            Dim::NONE => "a plain number (or an angle in deg/rad, or %)",
            Dim::LENGTH => "a length, e.g. \"320 mm\" or 0.32 (m)",
            Dim::AREA => "an area, e.g. \"0.02 m^2\" or \"200 cm^2\"",
            Dim::SECOND_MOMENT => "a second moment of area, e.g. \"1.5e-4 m^4\"",
            Dim::MASS => "a mass, e.g. \"1.2 t\" or \"310 kg\"",
            Dim::INERTIA => "a moment of inertia, e.g. \"45 kg m^2\"",
            Dim::FORCE => "a force, e.g. \"4 kN\"",
            Dim::MOMENT => "a moment, e.g. \"20 N*m\"",
            Dim::STIFFNESS => "a stiffness, e.g. \"10 N/um\"",
            Dim::CONTACT_STIFFNESS => "a contact stiffness per unit area, e.g. \"0.05 MPa/um\"",
            Dim::FREQUENCY => "a frequency, e.g. \"120 Hz\"",
            Dim::TIME => "a time, e.g. \"2 s\" or \"500 ms\"",
            Dim::VELOCITY => "a velocity, e.g. \"3 mm/s\"",
            Dim::ACCELERATION => "an acceleration, e.g. \"2 m/s^2\" or \"0.1 g\"",
            Dim::VOLTAGE => "a voltage, e.g. \"2 V\" or \"500 mV\"",
            Dim::FORCE_SENSITIVITY => "a force sensitivity, e.g. \"2.25 mV/N\"",
            Dim::ACCELERATION_SENSITIVITY => {
                "an accelerometer sensitivity, e.g. \"100 mV/g\" or \"10.2 mV/(m/s^2)\""
            }
            Dim::RECEPTANCE => "a receptance, e.g. \"1e-6 mm/N\"",
            Dim::MOBILITY => "a mobility, e.g. \"0.2 (mm/s)/N\"",
            Dim::ACCELERANCE => "an accelerance, e.g. \"0.01 g/N\" or \"0.1 (m/s^2)/N\"",
            _ => "a quantity",
        }
    }
}

impl fmt::Display for Dim {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut parts = Vec::new();
        for (sym, e) in [("kg", self.kg), ("m", self.m), ("s", self.s), ("A", self.a)] {
            match e {
                0 => {}
                1 => parts.push(sym.to_string()),
                _ => parts.push(format!("{sym}^{e}")),
            }
        }
        if parts.is_empty() {
            write!(f, "dimensionless")
        } else {
            write!(f, "{}", parts.join(" "))
        }
    }
}

/// Why a quantity could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UnitError {
    /// No number at the start.
    #[error("\"{0}\" does not start with a number; write e.g. \"0.05 MPa/um\"")]
    NoNumber(String),
    /// An unknown unit symbol.
    #[error(
        "unknown unit \"{unit}\" in \"{text}\"; known units: m, mm, cm, um, µm, nm, km, in, kg, g, \
         t, s, ms, N, kN, MN, lbf, Pa, kPa, MPa, GPa, Hz, kHz, V, mV, rad, mrad, deg, %, g (gravity, \
         in accelerations), with powers (m^2, m2, m²) and groups (V/(m/s^2))"
    )]
    Unknown {
        /// The symbol.
        unit: String,
        /// The whole text.
        text: String,
    },
    /// The unit has the wrong dimension.
    #[error("\"{text}\" is {found}, but {expected} is needed here")]
    WrongDimension {
        /// The whole text.
        text: String,
        /// Dimension found.
        found: Dim,
        /// What the field needs.
        expected: &'static str,
    },
    /// NaN or infinite.
    #[error("\"{0}\" is not a finite number")]
    NotFinite(String),
}

/// A conversion factor to SI kept as `extra · 10^pow10`, so that decimal prefixes convert exactly
/// (950 mm is 0.95 m, not 0.9500000000000001 m).
#[derive(Debug, Clone, Copy)]
struct Factor {
    extra: f64,
    pow10: i32,
}

impl Factor {
    const ONE: Factor = Factor {
        extra: 1.0,
        pow10: 0,
    };

    fn times(self, extra: f64) -> Factor {
        Factor {
            extra: self.extra * extra,
            pow10: self.pow10,
        }
    }

    fn apply(self, x: f64) -> f64 {
        let x = x * self.extra;
        if self.pow10 >= 0 {
            x * 10f64.powi(self.pow10)
        } else {
            x / 10f64.powi(-self.pow10)
        }
    }
}

/// What `g` means in a unit: the gram, or (where an acceleration is needed) standard gravity.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum G {
    Gram,
    Gravity,
}

fn symbol(sym: &str, g: G) -> Option<(Factor, Dim)> {
    let p = |pow10| Factor { extra: 1.0, pow10 };
    let exact = |extra| Factor { extra, pow10: 0 };
    // Symbols that take no prefix.
    match sym {
        "%" => return Some((p(-2), Dim::NONE)),
        "lbf" => return Some((exact(4.448_221_615_260_5), Dim::FORCE)),
        "in" => return Some((p(-4).times(254.0), Dim::LENGTH)),
        "deg" | "°" => return Some((exact(std::f64::consts::PI / 180.0), Dim::NONE)),
        "t" => return Some((p(3), Dim::MASS)),
        _ => {}
    }
    let base = |s: &str| -> Option<(Factor, Dim)> {
        Some(match s {
            "m" => (p(0), Dim::LENGTH),
            "g" if g == G::Gravity => (exact(STANDARD_GRAVITY), Dim::ACCELERATION),
            "g" => (p(-3), Dim::MASS),
            "s" => (p(0), Dim::TIME),
            "N" => (p(0), Dim::FORCE),
            "Pa" => (p(0), dim(1, -1, -2, 0)),
            "Hz" => (p(0), Dim::FREQUENCY),
            "V" => (p(0), Dim::VOLTAGE),
            "rad" => (p(0), Dim::NONE),
            _ => return None,
        })
    };
    if let Some(b) = base(sym) {
        return Some(b);
    }
    let mut chars = sym.chars();
    let first = chars.next()?;
    let rest = chars.as_str();
    let prefix = match first {
        'G' => 9,
        'M' => 6,
        'k' => 3,
        'c' if rest == "m" => -2,
        'd' if rest == "m" => -1,
        'm' => -3,
        'u' | 'µ' | 'μ' => -6,
        'n' => -9,
        _ => return None,
    };
    base(rest).map(|(f, d)| {
        (
            Factor {
                extra: f.extra,
                pow10: f.pow10 + prefix,
            },
            d,
        )
    })
}

fn superscript_power(term: &str) -> (&str, Option<i8>) {
    const SUP: [(char, i8); 4] = [('²', 2), ('³', 3), ('⁴', 4), ('¹', 1)];
    for (c, p) in SUP {
        if let Some(base) = term.strip_suffix(c) {
            return (base, Some(p));
        }
    }
    (term, None)
}

/// A term's symbol and its power: `m^4`, `m²`, `mm4`, `m-1`, `N`.
fn split_power(term: &str) -> Result<(&str, i8), ()> {
    if let Some((b, p)) = term.split_once('^') {
        return p.parse::<i8>().map(|p| (b, p)).map_err(|_| ());
    }
    if let (b, Some(p)) = superscript_power(term) {
        return Ok((b, p));
    }
    let split = term
        .find(|c: char| c.is_ascii_digit() || c == '-')
        .unwrap_or(term.len());
    if split < term.len() && split > 0 {
        let p = term[split..].parse::<i8>().map_err(|_| ())?;
        return Ok((&term[..split], p));
    }
    Ok((term, 1))
}

/// Parses a unit expression (without number) into a factor to SI and a dimension.
fn parse_unit(unit: &str, text: &str, g: G) -> Result<(Factor, Dim), UnitError> {
    let spaced = unit
        .replace('/', " / ")
        .replace('(', " ( ")
        .replace(')', " ) ")
        .replace(['*', '·'], " ");
    let tokens: Vec<&str> = spaced.split_whitespace().collect();
    let mut at = 0;
    let unknown = |u: &str| UnitError::Unknown {
        unit: u.to_string(),
        text: text.to_string(),
    };
    let parsed = product(&tokens, &mut at, g).map_err(|u| unknown(&u))?;
    if at < tokens.len() {
        return Err(unknown(tokens[at]));
    }
    Ok(parsed)
}

/// Parses terms from `tokens[*at..]` up to a `)` or the end; `Err` holds the offending token.
fn product(tokens: &[&str], at: &mut usize, g: G) -> Result<(Factor, Dim), String> {
    let mut factor = Factor::ONE;
    let mut dim = Dim::NONE;
    let mut divide = false;
    while let Some(&tok) = tokens.get(*at) {
        if tok == ")" {
            break;
        }
        *at += 1;
        if tok == "/" {
            if divide {
                return Err("//".into());
            }
            divide = true;
            continue;
        }
        let (f, d, p) = if tok == "(" {
            let (f, d) = product(tokens, at, g)?;
            if tokens.get(*at) != Some(&")") {
                return Err("(".into());
            }
            *at += 1;
            (f, d, 1)
        } else {
            let (sym, p) = split_power(tok).map_err(|_| tok.to_string())?;
            let (f, d) = symbol(sym, g).ok_or_else(|| sym.to_string())?;
            (f, d, p)
        };
        let p = if divide { -p } else { p };
        divide = false;
        factor.extra *= f.extra.powi(p as i32);
        factor.pow10 += f.pow10 * p as i32;
        dim = dim.mul(d.pow(p));
    }
    if divide {
        return Err("/".into());
    }
    Ok((factor, dim))
}

/// The unit of `text` (its number removed: `unit`), which must have dimension `expected`. `g`
/// is read as the gram first and, if that does not give `expected`, as standard gravity.
fn unit_for(unit: &str, text: &str, expected: Dim) -> Result<Factor, UnitError> {
    let (factor, dim) = parse_unit(unit, text, G::Gram)?;
    if unit.is_empty() || dim == expected {
        return Ok(factor);
    }
    if let Ok((f, d)) = parse_unit(unit, text, G::Gravity) {
        if d == expected {
            return Ok(f);
        }
    }
    Err(UnitError::WrongDimension {
        text: text.to_string(),
        found: dim,
        expected: expected.describe(),
    })
}

/// Splits `"0.05 MPa/um"` into the number and the unit text.
fn split_number(text: &str) -> Result<(f64, &str), UnitError> {
    let t = text.trim();
    let end = t
        .char_indices()
        .find(|&(i, c)| {
            !(c.is_ascii_digit()
                || c == '.'
                || c == '+'
                || c == '-'
                || ((c == 'e' || c == 'E')
                    && t[i + 1..]
                        .starts_with(|n: char| n.is_ascii_digit() || n == '-' || n == '+')))
        })
        .map(|(i, _)| i)
        .unwrap_or(t.len());
    let number: f64 = t[..end]
        .parse()
        .map_err(|_| UnitError::NoNumber(text.to_string()))?;
    Ok((number, t[end..].trim()))
}

/// Parses one quantity with an optional unit, checking its dimension; a bare number is SI.
pub fn parse_quantity(text: &str, expected: Dim) -> Result<f64, UnitError> {
    let (number, unit) = split_number(text)?;
    let factor = unit_for(unit, text, expected)?;
    let v = factor.apply(number);
    if !v.is_finite() {
        return Err(UnitError::NotFinite(text.to_string()));
    }
    Ok(v)
}

/// Parses several numbers sharing one unit: `"0 450 950 mm"`.
pub fn parse_quantities(text: &str, expected: Dim) -> Result<Vec<f64>, UnitError> {
    let mut numbers = Vec::new();
    let mut rest = text.trim();
    loop {
        match split_number(rest) {
            Ok((n, r)) if !rest.is_empty() => {
                numbers.push(n);
                rest = r;
                if rest.is_empty()
                    || !rest.starts_with(|c: char| {
                        c.is_ascii_digit() || c == '-' || c == '+' || c == '.'
                    })
                {
                    break;
                }
            }
            _ => break,
        }
    }
    if numbers.is_empty() {
        return Err(UnitError::NoNumber(text.to_string()));
    }
    let factor = unit_for(rest, text, expected)?;
    numbers
        .into_iter()
        .map(|n| {
            let v = factor.apply(n);
            if v.is_finite() {
                Ok(v)
            } else {
                Err(UnitError::NotFinite(text.to_string()))
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_units_convert_to_si() {
        let cases: &[(&str, Dim, f64)] = &[
            ("0.05 MPa/um", Dim::CONTACT_STIFFNESS, 0.05e12),
            ("0.05 MPa/µm", Dim::CONTACT_STIFFNESS, 0.05e12),
            ("10 N/um", Dim::STIFFNESS, 1e7),
            ("320 mm", Dim::LENGTH, 0.32),
            ("1.2 t", Dim::MASS, 1200.0),
            ("45 kg m^2", Dim::INERTIA, 45.0),
            ("45 kg*m2", Dim::INERTIA, 45.0),
            ("2 kg·m²", Dim::INERTIA, 2.0),
            ("200 cm^2", Dim::AREA, 0.02),
            ("1e6 mm4", Dim::SECOND_MOMENT, 1e-6),
            ("3e5 N*m/rad", Dim::ROTATIONAL_STIFFNESS, 3e5),
            ("4 kN", Dim::FORCE, 4000.0),
            ("2.5", Dim::NONE, 2.5),
            ("1.5e3", Dim::STIFFNESS, 1.5e3),
            ("120 Hz", Dim::FREQUENCY, 120.0),
        ];
        for (text, dim, want) in cases {
            let got = parse_quantity(text, *dim).unwrap();
            assert!(
                (got - want).abs() <= 1e-12 * want.abs(),
                "{text}: {got} vs {want}"
            );
        }
        let deg = parse_quantity("60 deg", Dim::NONE).unwrap();
        assert!((deg - std::f64::consts::FRAC_PI_3).abs() < 1e-15);
    }

    #[test]
    fn bad_units_are_explained() {
        let e = parse_quantity("10 N/mm2", Dim::STIFFNESS).unwrap_err();
        assert!(e.to_string().contains("stiffness"), "{e}");
        assert!(matches!(
            parse_quantity("3 furlong", Dim::LENGTH),
            Err(UnitError::Unknown { .. })
        ));
        assert!(matches!(
            parse_quantity("mm", Dim::LENGTH),
            Err(UnitError::NoNumber(_))
        ));
        assert!(parse_quantity("1e400 m", Dim::LENGTH).is_err());
        assert!(parse_quantity("5 m/", Dim::LENGTH).is_err());
    }

    #[test]
    fn instrument_units_convert_to_si() {
        let g0 = STANDARD_GRAVITY;
        let cases: &[(&str, Dim, f64)] = &[
            ("2 g", Dim::ACCELERATION, 2.0 * g0),
            ("5 mg", Dim::ACCELERATION, 5e-3 * g0),
            ("5 mg", Dim::MASS, 5e-6),
            ("3 m/s2", Dim::ACCELERATION, 3.0),
            ("3 m/s²", Dim::ACCELERATION, 3.0),
            ("3 mm/s^2", Dim::ACCELERATION, 3e-3),
            ("3 mm/s", Dim::VELOCITY, 3e-3),
            ("100 mV/g", Dim::ACCELERATION_SENSITIVITY, 0.1 / g0),
            ("10.2 mV/(m/s^2)", Dim::ACCELERATION_SENSITIVITY, 10.2e-3),
            ("10.2 mV/(m/s2)", Dim::ACCELERATION_SENSITIVITY, 10.2e-3),
            ("2.25 mV/N", Dim::FORCE_SENSITIVITY, 2.25e-3),
            ("2 V/kN", Dim::FORCE_SENSITIVITY, 2e-3),
            ("500 mV", Dim::VOLTAGE, 0.5),
            ("250 ms", Dim::TIME, 0.25),
            ("5 %", Dim::NONE, 0.05),
            ("10 lbf", Dim::FORCE, 44.482216152605),
            ("2 in", Dim::LENGTH, 0.0508),
            ("1 (m/s)/N", dim(-1, 0, 1, 0), 1.0),
        ];
        for (text, d, want) in cases {
            let got = parse_quantity(text, *d).unwrap_or_else(|e| panic!("{text}: {e}"));
            assert!(
                (got - want).abs() <= 1e-14 * want.abs(),
                "{text}: {got} vs {want}"
            );
        }
        // Gravity is not a mass, a gram is not an acceleration, unbalanced groups are errors.
        assert!(parse_quantity("2 g", Dim::FORCE).is_err());
        assert!(parse_quantity("1 V/(m/s2", Dim::ACCELERATION_SENSITIVITY).is_err());
        assert!(parse_quantity("1 V/m/s2)", Dim::ACCELERATION_SENSITIVITY).is_err());
        let e = parse_quantity("4 kN", Dim::ACCELERATION_SENSITIVITY).unwrap_err();
        assert!(e.to_string().contains("accelerometer sensitivity"), "{e}");
    }

    #[test]
    fn vectors_share_a_unit() {
        assert_eq!(
            parse_quantities("0 450 950 mm", Dim::LENGTH).unwrap(),
            vec![0.0, 0.45, 0.95]
        );
        assert_eq!(
            parse_quantities("1 -2 3", Dim::LENGTH).unwrap(),
            vec![1.0, -2.0, 3.0]
        );
    }
}
