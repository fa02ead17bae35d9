//! Quantities with units as people write them in this field: `"0.05 MPa/um"`, `"10 N/um"`,
//! `"320 mm"`, `"1.2 t"`, `"45 kg m^2"`, `"60 deg"`. Everything is converted to SI on reading;
//! a unit of the wrong dimension, or an unknown one, is an error that says what was expected.
//!
//! Grammar: a number, then unit terms separated by spaces, `*` or `·`, each term optionally
//! raised to an integer power (`m^4`, `m4`, `m²`); `/` divides by the next term only
//! (`N*m/rad`, `MPa/um`). Angles are dimensionless (rad = 1, deg = π/180).
//!
//! ```
//! use identify::units::{parse_quantity, Dim};
//! assert_eq!(parse_quantity("0.05 MPa/um", Dim::CONTACT_STIFFNESS).unwrap(), 0.05e12);
//! assert_eq!(parse_quantity("1.2 t", Dim::MASS).unwrap(), 1200.0);
//! assert!(parse_quantity("3 furlongs", Dim::LENGTH).is_err());
//! ```

use std::fmt;

/// A physical dimension as exponents of kg, m and s.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dim {
    kg: i8,
    m: i8,
    s: i8,
}

impl Dim {
    /// Pure number (also angles, ψ, ratios).
    pub const NONE: Dim = Dim { kg: 0, m: 0, s: 0 };
    /// m.
    pub const LENGTH: Dim = Dim { kg: 0, m: 1, s: 0 };
    /// m².
    pub const AREA: Dim = Dim { kg: 0, m: 2, s: 0 };
    /// m⁴ (second moment of area).
    pub const SECOND_MOMENT: Dim = Dim { kg: 0, m: 4, s: 0 };
    /// kg.
    pub const MASS: Dim = Dim { kg: 1, m: 0, s: 0 };
    /// kg·m².
    pub const INERTIA: Dim = Dim { kg: 1, m: 2, s: 0 };
    /// N.
    pub const FORCE: Dim = Dim { kg: 1, m: 1, s: -2 };
    /// N·m.
    pub const MOMENT: Dim = Dim { kg: 1, m: 2, s: -2 };
    /// N/m.
    pub const STIFFNESS: Dim = Dim { kg: 1, m: 0, s: -2 };
    /// N·m/rad.
    pub const ROTATIONAL_STIFFNESS: Dim = Dim { kg: 1, m: 2, s: -2 };
    /// Pa/m: contact stiffness per unit area.
    pub const CONTACT_STIFFNESS: Dim = Dim {
        kg: 1,
        m: -2,
        s: -2,
    };
    /// Hz.
    pub const FREQUENCY: Dim = Dim { kg: 0, m: 0, s: -1 };

    fn pow(self, e: i8) -> Dim {
        Dim {
            kg: self.kg * e,
            m: self.m * e,
            s: self.s * e,
        }
    }

    fn mul(self, o: Dim) -> Dim {
        Dim {
            kg: self.kg + o.kg,
            m: self.m + o.m,
            s: self.s + o.s,
        }
    }

    /// A usual unit and an example for this dimension, for error messages.
    pub fn describe(&self) -> &'static str {
        match *self {
            Dim::NONE => "a plain number (or an angle in deg/rad)",
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
            _ => "a quantity",
        }
    }
}

impl fmt::Display for Dim {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut parts = Vec::new();
        for (sym, e) in [("kg", self.kg), ("m", self.m), ("s", self.s)] {
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
        "unknown unit \"{unit}\" in \"{text}\"; known units: m, mm, cm, um, µm, nm, km, kg, g, t, \
         s, ms, N, kN, MN, Pa, kPa, MPa, GPa, Hz, kHz, rad, mrad, deg"
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

    fn apply(self, x: f64) -> f64 {
        let x = x * self.extra;
        if self.pow10 >= 0 {
            x * 10f64.powi(self.pow10)
        } else {
            x / 10f64.powi(-self.pow10)
        }
    }
}

fn symbol(sym: &str) -> Option<(Factor, Dim)> {
    let p = |pow10| Factor { extra: 1.0, pow10 };
    let base = |s: &str| -> Option<(Factor, Dim)> {
        Some(match s {
            "m" => (p(0), Dim::LENGTH),
            "g" => (p(-3), Dim::MASS),
            "t" => (p(3), Dim::MASS),
            "s" => (p(0), Dim { kg: 0, m: 0, s: 1 }),
            "N" => (p(0), Dim::FORCE),
            "Pa" => (
                p(0),
                Dim {
                    kg: 1,
                    m: -1,
                    s: -2,
                },
            ),
            "Hz" => (p(0), Dim::FREQUENCY),
            "rad" => (p(0), Dim::NONE),
            "deg" | "°" => (
                Factor {
                    extra: std::f64::consts::PI / 180.0,
                    pow10: 0,
                },
                Dim::NONE,
            ),
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
    if rest == "deg" || rest == "°" || rest == "t" {
        return None;
    }
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

/// Parses a unit expression (without number) into a factor to SI and a dimension.
fn parse_unit(unit: &str, text: &str) -> Result<(Factor, Dim), UnitError> {
    let mut factor = Factor::ONE;
    let mut dim = Dim::NONE;
    let unknown = |u: &str| UnitError::Unknown {
        unit: u.to_string(),
        text: text.to_string(),
    };
    let spaced = unit.replace('/', " / ").replace(['*', '·'], " ");
    let mut divide = false;
    for term in spaced.split_whitespace() {
        if term == "/" {
            if divide {
                return Err(unknown("//"));
            }
            divide = true;
            continue;
        }
        let (body, power) = match term.split_once('^') {
            Some((b, p)) => (b, Some(p.parse::<i8>().map_err(|_| unknown(term))?)),
            None => match superscript_power(term) {
                (b, Some(p)) => (b, Some(p)),
                (b, None) => {
                    // trailing digits: m2, mm4, m-1
                    let split = b
                        .find(|c: char| c.is_ascii_digit() || c == '-')
                        .unwrap_or(b.len());
                    if split < b.len() && split > 0 {
                        (
                            &b[..split],
                            Some(b[split..].parse::<i8>().map_err(|_| unknown(term))?),
                        )
                    } else {
                        (b, None)
                    }
                }
            },
        };
        let (f, d) = symbol(body).ok_or_else(|| unknown(body))?;
        let mut p = power.unwrap_or(1);
        if divide {
            p = -p;
            divide = false;
        }
        factor.extra *= f.extra.powi(p as i32);
        factor.pow10 += f.pow10 * p as i32;
        dim = dim.mul(d.pow(p));
    }
    if divide {
        return Err(unknown("/"));
    }
    Ok((factor, dim))
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
    let (factor, dim) = parse_unit(unit, text)?;
    if !unit.is_empty() && dim != expected {
        return Err(UnitError::WrongDimension {
            text: text.to_string(),
            found: dim,
            expected: expected.describe(),
        });
    }
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
    let (factor, dim) = parse_unit(rest, text)?;
    if !rest.is_empty() && dim != expected {
        return Err(UnitError::WrongDimension {
            text: text.to_string(),
            found: dim,
            expected: expected.describe(),
        });
    }
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
