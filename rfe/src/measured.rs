//! Measured characteristics: what processing produces and identification consumes.
//!
//! A [`Measurement`] holds the points of one [`Characteristic`] (body, DOF in the body's principal
//! central axes, quantity). Values are the complex response, in SI units, **to the model's declared
//! excitation** (e.g. the paper's 4 kN force pair): processing turns a per-newton FRF `H` into that
//! by multiplying with the nominal excitation amplitude. Amplitude-only data (as in the paper) leave
//! `phase_rad` empty.

use serde::{Deserialize, Serialize};

use crate::model::{Characteristic, PointOutput, Quantity};

/// The measured points of one characteristic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Measurement {
    /// Name of the measured body (resolved to an index against a model by [`Measurement::resolve`]).
    pub body: String,
    /// 0-2 translations u1..u3, 3-5 rotations r1..r3, in the body's principal central axes.
    pub dof: u8,
    /// Displacement, velocity or acceleration.
    pub quantity: QuantityName,
    /// Frequencies (Hz), strictly increasing.
    pub freqs_hz: Vec<f64>,
    /// Amplitude |z| at each frequency (SI: m, m/s, m/s², rad, ...), ≥ 0.
    pub amplitude: Vec<f64>,
    /// Phase (rad) at each frequency, when measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phase_rad: Option<Vec<f64>>,
    /// Variance of the complex estimate at each point (E|z − z_true|², SI units squared), when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variance: Option<Vec<f64>>,
    /// Ordinary coherence γ² (0..1) at each point, when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coherence: Option<Vec<f64>>,
    /// Number of averages behind each point's estimate, when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub averages: Option<u32>,
    /// A point output: the sensor's location and axis (global); absent for a principal-axis DOF
    /// (then `dof` is the output; with `at`, `dof` is the principal translation nearest the axis).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at: Option<PointOutput>,
    /// The excitation this FRF responds to: a name among the model's `[[reference]]`s; absent
    /// for the model's own excitation (`forces`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<String>,
    /// Under base motion: the response relative to the base; `false` (absent): absolute, the
    /// transmissibility.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub relative: bool,
}

/// Serialized name of a [`Quantity`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum QuantityName {
    /// m or rad.
    Displacement,
    /// m/s or rad/s.
    Velocity,
    /// m/s² or rad/s².
    Acceleration,
}

impl From<QuantityName> for Quantity {
    fn from(q: QuantityName) -> Quantity {
        match q {
            QuantityName::Displacement => Quantity::Displacement,
            QuantityName::Velocity => Quantity::Velocity,
            QuantityName::Acceleration => Quantity::Acceleration,
        }
    }
}

impl From<Quantity> for QuantityName {
    fn from(q: Quantity) -> QuantityName {
        match q {
            Quantity::Displacement => QuantityName::Displacement,
            Quantity::Velocity => QuantityName::Velocity,
            Quantity::Acceleration => QuantityName::Acceleration,
        }
    }
}

impl Measurement {
    /// Its name in messages: the body and the DOF, e.g. `table u3`.
    pub fn label(&self) -> String {
        let mut s = match &self.at {
            Some(at) => format!("{} {}", self.body, at.label()),
            None => {
                let dof = crate::model::DOF_NAMES
                    .get(self.dof as usize)
                    .copied()
                    .unwrap_or("?");
                format!("{} {dof}", self.body)
            }
        };
        if self.relative {
            s.push_str(" relative");
        }
        if let Some(r) = &self.reference {
            s.push_str(&format!(" / {r}"));
        }
        s
    }

    /// [`Characteristic::reference`] of this measurement in `model`: 0 for none, `u8::MAX` for a
    /// name the model does not have (which no output carries; `identify::data::validate`
    /// says so).
    pub fn reference_index(&self, model: &crate::Model) -> u8 {
        match &self.reference {
            None => 0,
            Some(name) => model.reference_index(name).unwrap_or(u8::MAX),
        }
    }

    /// The characteristic this measurement is of, with the body resolved in `model`;
    /// `None` if the model has no body of that name or the DOF is out of range.
    pub fn resolve(&self, model: &crate::Model) -> Option<Characteristic> {
        let body = model.body_index(&self.body)?;
        (self.dof < 6).then_some(Characteristic {
            body,
            dof: self.dof,
            quantity: self.quantity.into(),
            at: self.at,
            reference: self.reference_index(model),
            relative: self.relative,
        })
    }
}

/// A set of measured characteristics, e.g. one identification data file.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct MeasuredData {
    /// Free-text description of where the data came from (session, stand, date).
    #[serde(default)]
    pub source: String,
    /// The characteristics.
    pub characteristics: Vec<Measurement>,
}
