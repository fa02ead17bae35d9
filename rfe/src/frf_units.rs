//! Units of measured frequency responses: receptance (m/N), mobility ((m/s)/N) and accelerance
//! ((m/s²)/N) as files write them (`mm/N`, `(mm/s)/kN`, `g/lbf`, `m/s^2/N`), a response to the
//! model's own excitation (`mm`, `mm/s`, `g`), or a transmissibility — the response per the same
//! quantity of a base motion (`m/m`, `g/g`, `(m/s²)/(m/s²)`, `(mm/s)/(m/s)`, `dimensionless`);
//! read through the one unit parser
//! [`crate::units`], converted exactly (g = 9.80665 m/s², lbf = 4.4482216152605 N), and brought
//! to the model's convention: SI, the response to the model's declared excitation, in the
//! quantity of the model's output for that body and DOF (by (jω)^k). Every conversion is noted so
//! a report can state what was assumed.
//!
//! ```
//! use rfe::frf_units::FrfUnit;
//! use rfe::model::Quantity;
//! let u = FrfUnit::parse("g/N").unwrap();
//! assert_eq!((u.quantity, u.per_force, u.to_si), (Quantity::Acceleration, true, 9.80665));
//! let u = FrfUnit::parse("(mm/s)/kN").unwrap();
//! assert_eq!((u.quantity, u.to_si), (Quantity::Velocity, 1e-6));
//! let u = FrfUnit::parse("(mm/s^2)/g").unwrap();
//! assert!(u.per_base_motion && (u.to_si - 1e-3 / 9.80665).abs() < 1e-18);
//! assert!(FrfUnit::parse("N/mm").is_err());
//! ```

use std::f64::consts::{FRAC_PI_2, PI};

use crate::measured::Measurement;
use crate::model::{Characteristic, Model, PointForce, Quantity};
use crate::units::{parse_quantity, Dim};

/// Why a text is not the unit of a measured response.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrfUnitError {
    /// The unit field is empty.
    #[error("no unit given")]
    Empty,
    /// The text is none of the accepted kinds (the message lists them).
    #[error(
        "\"{text}\" is not a receptance (m/N, mm/N, um/N), mobility (m/s/N, (mm/s)/N), \
         accelerance ((m/s^2)/N, g/N) per N, kN or lbf, a displacement, velocity or \
         acceleration, nor a transmissibility (m/m, g/g, (m/s^2)/(m/s^2), dimensionless){}",
        unknown.as_ref().map(|u| format!(" (unknown unit \"{u}\")")).unwrap_or_default()
    )]
    NotAResponse {
        /// The unit as written.
        text: String,
        /// The unit symbol the parser did not know, when that was the reason.
        unknown: Option<String>,
    },
}

/// Why a measurement cannot be brought to the model's convention; each names the measurement
/// (`label`, e.g. `head u1`) and the fix.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConventionError {
    /// A unit declared for a rotational DOF.
    #[error(
        "{label}: a unit ({unit}) is declared for a rotation; declared units are for \
         translations u1-u3 (give rotations in SI: rad, rad/s, rad/s² to the model's excitation)"
    )]
    Rotation {
        /// The measurement.
        label: String,
        /// The unit as written.
        unit: String,
    },
    /// Per-force data against a base-motion reference.
    #[error("{label}: the data are per unit force ({unit}), but reference \"{reference}\" is a base motion: give transmissibilities with a transmissibility unit (unit = \"g/g\", \"m/m\", \"(m/s^2)/(m/s^2)\")")]
    ForceAgainstBaseMotion {
        /// The measurement.
        label: String,
        /// The unit as written.
        unit: String,
        /// The reference named.
        reference: String,
    },
    /// Per-force data, but no force to scale them to.
    #[error(
        "{label}: the data are per unit force ({unit}), but the model declares no excitation \
         force to scale them to; add an [[excitation]] to the model"
    )]
    NoExcitationForce {
        /// The measurement.
        label: String,
        /// The unit as written.
        unit: String,
    },
    /// A transmissibility whose reference is not a base motion.
    #[error("{label}: a transmissibility ({unit}) is the response per the base's motion, but its reference is {now}: name the model's base-motion [[reference]] for it ({fix})")]
    TransmissibilityReference {
        /// The measurement.
        label: String,
        /// The unit as written.
        unit: String,
        /// The reference it has now, for the message.
        now: String,
        /// The base-motion references to name, or how to add one.
        fix: String,
    },
    /// A line at 0 Hz that would be divided by ω to reach the model's output quantity.
    #[error(
        "{label}: point {index} is at 0 Hz, where {have} cannot be converted to the model's {want} \
         output; drop that line"
    )]
    ZeroFrequency {
        /// The measurement.
        label: String,
        /// The line's index.
        index: usize,
        /// The measured quantity.
        have: &'static str,
        /// The model's output quantity.
        want: &'static str,
    },
}

/// The unit of measured values of a translational response.
#[derive(Debug, Clone, PartialEq)]
pub struct FrfUnit {
    /// The unit as written.
    pub text: String,
    /// What the values are: displacement (receptance), velocity (mobility), acceleration
    /// (accelerance).
    pub quantity: Quantity,
    /// True for a response per unit force (an FRF); false for a response to the model's
    /// declared excitation.
    pub per_force: bool,
    /// True for a transmissibility: the response per the same quantity of the base's motion
    /// (dimensionless; a ratio of accelerations is the ratio of displacements), read as the
    /// displacement per metre of base displacement (`quantity` is then displacement).
    pub per_base_motion: bool,
    /// Factor from the written unit to SI (m/N, (m/s)/N, (m/s²)/N, or m, m/s, m/s², or m/m).
    pub to_si: f64,
}

impl FrfUnit {
    /// Reads a unit: an FRF (response per force) or a plain response; `Err` says what is
    /// accepted.
    pub fn parse(text: &str) -> Result<FrfUnit, FrfUnitError> {
        let t = text.trim();
        if t.is_empty() {
            return Err(FrfUnitError::Empty);
        }
        let kinds = [
            (Dim::RECEPTANCE, Quantity::Displacement, true),
            (Dim::MOBILITY, Quantity::Velocity, true),
            (Dim::ACCELERANCE, Quantity::Acceleration, true),
            (Dim::LENGTH, Quantity::Displacement, false),
            (Dim::VELOCITY, Quantity::Velocity, false),
            (Dim::ACCELERATION, Quantity::Acceleration, false),
        ];
        let mut last = None;
        for (dim, quantity, per_force) in kinds {
            match parse_quantity(&format!("1 {t}"), dim) {
                Ok(to_si) => {
                    return Ok(FrfUnit {
                        text: t.to_string(),
                        quantity,
                        per_force,
                        per_base_motion: false,
                        to_si,
                    })
                }
                Err(e) => last = Some(e),
            }
        }
        if let Some(to_si) = transmissibility(t) {
            return Ok(FrfUnit {
                text: t.to_string(),
                quantity: Quantity::Displacement,
                per_force: false,
                per_base_motion: true,
                to_si,
            });
        }
        let unknown = match last {
            Some(crate::units::UnitError::Unknown { unit, .. }) => Some(unit),
            _ => None,
        };
        Err(FrfUnitError::NotAResponse {
            text: t.to_string(),
            unknown,
        })
    }

    /// The SI unit of this kind of value, for notes: `(m/s²)/N`.
    pub fn si_text(&self) -> &'static str {
        self.kind_and_si_text().1
    }

    /// `receptance`, `mobility`, `accelerance` (per force), `transmissibility`, or the
    /// quantity's name.
    pub fn kind(&self) -> &'static str {
        self.kind_and_si_text().0
    }

    /// [`Self::kind`] and [`Self::si_text`] from one table, so that a kind's name and its unit
    /// stand on one row.
    fn kind_and_si_text(&self) -> (&'static str, &'static str) {
        if self.per_base_motion {
            return ("transmissibility", "m/m");
        }
        let q = self.quantity;
        match (q, self.per_force) {
            (Quantity::Displacement, true) => ("receptance", "m/N"),
            (Quantity::Velocity, true) => ("mobility", "(m/s)/N"),
            (Quantity::Acceleration, true) => ("accelerance", "(m/s²)/N"),
            (Quantity::Displacement, false) => (q.as_str(), "m"),
            (Quantity::Velocity, false) => (q.as_str(), "m/s"),
            (Quantity::Acceleration, false) => (q.as_str(), "m/s²"),
        }
    }
}

/// The factor to SI of a transmissibility unit: a quantity over a quantity of the same kind
/// (length, velocity or acceleration: `m/m`, `g/g`, `(mm/s^2)/(m/s^2)`, `m/s²/g`), or a plain
/// ratio (`1`, `-`, `dimensionless`, `ratio`). `None` for anything else (an angle, a percentage,
/// a force ratio).
fn transmissibility(t: &str) -> Option<f64> {
    if ["1", "-", "dimensionless", "ratio"]
        .iter()
        .any(|w| t.eq_ignore_ascii_case(w))
    {
        return Some(1.0);
    }
    let like = [Dim::LENGTH, Dim::VELOCITY, Dim::ACCELERATION];
    // Every '/' is a candidate split between numerator and denominator.
    t.char_indices()
        .filter(|&(_, c)| c == '/')
        .find_map(|(i, _)| {
            let (num, den) = (t[..i].trim(), t[i + 1..].trim());
            like.iter().find_map(|&dim| {
                let n = parse_quantity(&format!("1 {num}"), dim).ok()?;
                let d = parse_quantity(&format!("1 {den}"), dim).ok()?;
                (n.is_finite() && d.is_finite() && d != 0.0).then(|| n / d)
            })
        })
}

/// Amplitude of the model's declared excitation (N): the first force's magnitude, the
/// convention of [`crate::MeasuredData`] (characteristics are the response to it).
pub fn excitation_amplitude(model: &Model) -> Option<f64> {
    first_force_amplitude(&model.forces)
}

/// The first of `forces`' magnitude (N), when it is a finite positive one: the amplitude the
/// characteristics of an excitation are the response to.
fn first_force_amplitude(forces: &[PointForce]) -> Option<f64> {
    forces
        .first()
        .map(|f| f.force.norm())
        .filter(|f| f.is_finite() && *f > 0.0)
}

fn order(q: Quantity) -> i32 {
    match q {
        Quantity::Displacement => 0,
        Quantity::Velocity => 1,
        Quantity::Acceleration => 2,
    }
}

/// Brings one measurement, whose values are in `unit` (with `m.quantity` = `unit.quantity`), to
/// the model's convention: SI; per force → times the model's excitation amplitude; and, when
/// the model's output for this body and DOF is another quantity, multiplied by (jω)^k (phase
/// shifted by k·90°). Appends what it did to `notes`; `Err` says why it cannot.
pub fn to_model_convention(
    m: &mut Measurement,
    unit: &FrfUnit,
    model: &Model,
    notes: &mut Vec<String>,
) -> Result<(), ConventionError> {
    let label = m.label();
    if m.dof >= 3 {
        return Err(ConventionError::Rotation {
            label,
            unit: unit.text.clone(),
        });
    }
    if unit.per_base_motion {
        return transmissibility_to_model(m, unit, model, notes);
    }
    let mut factor = unit.to_si;
    let mut how = if unit.to_si == 1.0 {
        format!("{} in {}", unit.kind(), unit.text)
    } else {
        format!(
            "{} in {} converted to {} (× {})",
            unit.kind(),
            unit.text,
            unit.si_text(),
            unit.to_si
        )
    };
    if unit.per_force {
        let of_reference = match m.reference.as_deref() {
            None => excitation_amplitude(model),
            Some(name) => match model.references.iter().find(|r| r.name == name) {
                Some(crate::model::Reference {
                    excitation: crate::model::Excitation::Forces(f),
                    ..
                }) => first_force_amplitude(f),
                Some(_) => {
                    return Err(ConventionError::ForceAgainstBaseMotion {
                        label,
                        unit: unit.text.clone(),
                        reference: name.to_string(),
                    })
                }
                None => None,
            },
        };
        let Some(f) = of_reference else {
            return Err(ConventionError::NoExcitationForce {
                label,
                unit: unit.text.clone(),
            });
        };
        factor *= f;
        how.push_str(&format!(
            ", scaled to the model's {} ({f} N, the first force's amplitude)",
            m.reference
                .as_deref()
                .map(|r| format!("reference \"{r}\""))
                .unwrap_or_else(|| "excitation".into())
        ));
    }
    scale(m, factor);
    m.quantity = unit.quantity.into();
    notes.push(format!("{label}: {how}"));
    convert_quantity(m, model, notes)
}

/// A transmissibility to the model's convention: the response per metre of the base's
/// displacement (a ratio of like quantities is that ratio), in the quantity of the model's output
/// by (jω)^k. Its reference must be a base motion.
fn transmissibility_to_model(
    m: &mut Measurement,
    unit: &FrfUnit,
    model: &Model,
    notes: &mut Vec<String>,
) -> Result<(), ConventionError> {
    let label = m.label();
    let is_base = |r: &&crate::model::Reference| {
        matches!(r.excitation, crate::model::Excitation::BaseMotion { .. })
    };
    let base = m.reference.as_deref().and_then(|name| {
        model
            .references
            .iter()
            .filter(is_base)
            .find(|r| r.name == name)
    });
    let Some(base) = base else {
        let bases: Vec<&str> = model
            .references
            .iter()
            .filter(is_base)
            .map(|r| r.name.as_str())
            .collect();
        let now = match m.reference.as_deref() {
            Some(r) => format!("\"{r}\""),
            None => "the model's force excitation".into(),
        };
        let fix = if bases.is_empty() {
            "the model has none: add a [[reference]] with base_motion = [x, y, z]".to_string()
        } else {
            format!("reference = \"{}\"", bases.join("\" or \""))
        };
        return Err(ConventionError::TransmissibilityReference {
            label,
            unit: unit.text.clone(),
            now,
            fix,
        });
    };
    scale(m, unit.to_si);
    m.quantity = Quantity::Displacement.into();
    let how = if unit.to_si == 1.0 {
        String::new()
    } else {
        format!(" (× {})", unit.to_si)
    };
    notes.push(format!(
        "{label}: transmissibility in {}{how}, read as the response per metre of the base motion \"{}\" (a ratio of accelerations or velocities is the ratio of displacements)",
        unit.text, base.name
    ));
    convert_quantity(m, model, notes)
}

fn scale(m: &mut Measurement, factor: f64) {
    for a in &mut m.amplitude {
        *a *= factor;
    }
    if let Some(v) = &mut m.variance {
        for x in v {
            *x *= factor * factor;
        }
    }
}

/// When the model has no output of `m`'s quantity for its body and DOF but has one of another
/// quantity, converts `m` to it by (jω)^k and notes it; otherwise leaves `m` as it is (the
/// validation then says what is missing).
pub fn convert_quantity(
    m: &mut Measurement,
    model: &Model,
    notes: &mut Vec<String>,
) -> Result<(), ConventionError> {
    let Some(body) = model.body_index(&m.body) else {
        return Ok(());
    };
    let have = Quantity::from(m.quantity);
    let is_output = |q: Quantity| {
        model.outputs.contains(&Characteristic {
            body,
            dof: m.dof,
            quantity: q,
            at: m.at,
            reference: m.reference_index(model),
            relative: m.relative,
        })
    };
    if is_output(have) {
        return Ok(());
    }
    let Some(want) = [
        Quantity::Displacement,
        Quantity::Velocity,
        Quantity::Acceleration,
    ]
    .into_iter()
    .find(|q| is_output(*q)) else {
        return Ok(());
    };
    let k = order(want) - order(have);
    let label = m.label();
    for (i, f) in m.freqs_hz.iter().enumerate() {
        let omega = 2.0 * PI * f;
        if k < 0 && omega == 0.0 {
            return Err(ConventionError::ZeroFrequency {
                label,
                index: i,
                have: have.as_str(),
                want: want.as_str(),
            });
        }
        let g = omega.powi(k);
        m.amplitude[i] *= g;
        if let Some(v) = &mut m.variance {
            v[i] *= g * g;
        }
        if let Some(p) = &mut m.phase_rad {
            p[i] = (p[i] + f64::from(k) * FRAC_PI_2 + PI).rem_euclid(2.0 * PI) - PI;
        }
    }
    m.quantity = want.into();
    notes.push(format!(
        "{label}: {} converted to the model's {} output by (jω)^{k}",
        have.as_str(),
        want.as_str()
    ));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_field_unit_reads_exactly() {
        let g = crate::units::STANDARD_GRAVITY;
        let lbf = 4.448_221_615_260_5;
        let cases: &[(&str, Quantity, bool, f64)] = &[
            ("m/N", Quantity::Displacement, true, 1.0),
            ("mm/N", Quantity::Displacement, true, 1e-3),
            ("µm/N", Quantity::Displacement, true, 1e-6),
            ("um/kN", Quantity::Displacement, true, 1e-9),
            ("m/lbf", Quantity::Displacement, true, 1.0 / lbf),
            ("(m/s)/N", Quantity::Velocity, true, 1.0),
            ("mm/s/N", Quantity::Velocity, true, 1e-3),
            ("(mm/s)/lbf", Quantity::Velocity, true, 1e-3 / lbf),
            ("(m/s^2)/N", Quantity::Acceleration, true, 1.0),
            ("m/s²/N", Quantity::Acceleration, true, 1.0),
            ("g/N", Quantity::Acceleration, true, g),
            ("g/lbf", Quantity::Acceleration, true, g / lbf),
            ("g/kN", Quantity::Acceleration, true, g * 1e-3),
            ("mm", Quantity::Displacement, false, 1e-3),
            ("mm/s", Quantity::Velocity, false, 1e-3),
            ("g", Quantity::Acceleration, false, g),
        ];
        for (text, q, per, si) in cases {
            let u = FrfUnit::parse(text).unwrap_or_else(|e| panic!("{text}: {e}"));
            assert_eq!((u.quantity, u.per_force), (*q, *per), "{text}");
            assert!(
                (u.to_si - si).abs() <= 1e-15 * si,
                "{text}: {} vs {si}",
                u.to_si
            );
        }
        assert_eq!(FrfUnit::parse("g/N").unwrap().to_si, 9.80665);
        for bad in [
            "",
            "N/mm",
            "Pa",
            "furlong/N",
            "V/N",
            "deg",
            "N/N",
            "%",
            "rad",
        ] {
            assert!(FrfUnit::parse(bad).is_err(), "{bad}");
        }
        let ratios: &[(&str, f64)] = &[
            ("m/m", 1.0),
            ("mm/m", 1e-3),
            ("g/g", 1.0),
            ("(m/s^2)/(m/s^2)", 1.0),
            ("m/s²/(m/s²)", 1.0),
            ("(mm/s^2)/g", 1e-3 / g),
            ("(m/s^2)/g", 1.0 / g),
            ("g/(m/s^2)", g),
            ("(mm/s)/(m/s)", 1e-3),
            ("um/mm", 1e-3),
            ("dimensionless", 1.0),
            ("-", 1.0),
        ];
        for (text, si) in ratios {
            let u = FrfUnit::parse(text).unwrap_or_else(|e| panic!("{text}: {e}"));
            assert!(
                u.per_base_motion && !u.per_force && u.quantity == Quantity::Displacement,
                "{text}: {u:?}"
            );
            assert!(
                (u.to_si - si).abs() <= 1e-15 * si,
                "{text}: {} vs {si}",
                u.to_si
            );
            assert_eq!(u.kind(), "transmissibility");
        }
        assert!(FrfUnit::parse("furlong/N")
            .unwrap_err()
            .to_string()
            .contains("furlong"));
    }
}
