//! Channel calibration (sensitivity, offset, units) and conversion between receptance
//! (displacement/force), mobility (velocity/force) and accelerance (acceleration/force).

use num_complex::Complex;
use rfe::Quantity;

use crate::error::{check_count, invalid, ProcessError, Result};

type C64 = Complex<f64>;

/// Standard gravity (m/s²), for sensitivities given per g.
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// Linear calibration of one channel: `si = (raw − offset) / sensitivity`.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// Channel name.
    pub name: String,
    /// Raw units (usually V) per SI unit (N, m/s², m/s, m).
    pub sensitivity: f64,
    /// Raw value at zero physical input (raw units).
    pub offset: f64,
    /// Physical quantity measured (SI unit implied: N for forces is reported by `force`).
    pub quantity: Option<Quantity>,
}

impl Calibration {
    /// Accelerometer given in mV/g (data-sheet unit).
    pub fn accelerometer_mv_per_g(name: &str, mv_per_g: f64) -> Calibration {
        Calibration {
            name: name.into(),
            sensitivity: mv_per_g * 1e-3 / STANDARD_GRAVITY,
            offset: 0.0,
            quantity: Some(Quantity::Acceleration),
        }
    }

    /// Force sensor or hammer given in mV/N.
    pub fn force_mv_per_n(name: &str, mv_per_n: f64) -> Calibration {
        Calibration {
            name: name.into(),
            sensitivity: mv_per_n * 1e-3,
            offset: 0.0,
            quantity: None,
        }
    }

    /// Converts raw samples to SI in place.
    pub fn apply(&self, raw: &mut [f64]) -> Result<()> {
        if !(self.sensitivity.is_finite() && self.sensitivity != 0.0 && self.offset.is_finite()) {
            return Err(invalid(
                "sensitivity",
                format!("{} (channel '{}')", self.sensitivity, self.name),
                "must be finite and nonzero: take it from the sensor's calibration sheet",
            ));
        }
        let inv = 1.0 / self.sensitivity;
        raw.iter_mut().for_each(|v| *v = (*v - self.offset) * inv);
        Ok(())
    }
}

fn order(q: Quantity) -> i32 {
    match q {
        Quantity::Displacement => 0,
        Quantity::Velocity => 1,
        Quantity::Acceleration => 2,
    }
}

/// Converts FRF values `h` at `freqs_hz` from one quantity to another in place, multiplying by
/// `(jω)^(n_to − n_from)` (accelerance = jω·mobility = −ω²·receptance). Integrating (to a lower
/// order) at 0 Hz is an error.
pub fn convert(freqs_hz: &[f64], h: &mut [C64], from: Quantity, to: Quantity) -> Result<()> {
    check_count("FRF values (one per frequency)", freqs_hz.len(), h.len())?;
    let p = order(to) - order(from);
    if p == 0 {
        return Ok(());
    }
    if p < 0 {
        if let Some(f) = freqs_hz.iter().find(|f| **f == 0.0) {
            return Err(ProcessError::ZeroFrequency {
                from: from.as_str(),
                to: to.as_str(),
                freq_hz: *f,
            });
        }
    }
    for (f, v) in freqs_hz.iter().zip(h.iter_mut()) {
        let jw = C64::new(0.0, 2.0 * std::f64::consts::PI * f);
        *v *= jw.powi(p);
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn receptance_to_accelerance_is_minus_omega_squared_and_back() {
        let f = [0.0, 10.0, 100.0];
        let h0 = vec![C64::new(1e-6, 2e-6); 3];
        let mut h = h0.clone();
        convert(&f, &mut h, Quantity::Displacement, Quantity::Acceleration).unwrap();
        let w = 2.0 * std::f64::consts::PI * 100.0;
        assert!((h[2] + h0[2] * w * w).norm() < 1e-12 * (w * w));
        assert!(convert(&f, &mut h, Quantity::Acceleration, Quantity::Velocity).is_err());
        let mut g = h[1..].to_vec();
        convert(
            &f[1..],
            &mut g,
            Quantity::Acceleration,
            Quantity::Displacement,
        )
        .unwrap();
        assert!((g[1] - h0[2]).norm() < 1e-18);
    }

    #[test]
    fn calibration_scales_and_rejects_zero_sensitivity() {
        let c = Calibration::accelerometer_mv_per_g("a", 100.0);
        let mut x = vec![0.1];
        c.apply(&mut x).unwrap();
        assert!((x[0] - STANDARD_GRAVITY).abs() < 1e-12);
        let bad = Calibration {
            sensitivity: 0.0,
            ..c
        };
        assert!(bad.apply(&mut x).unwrap_err().to_string().contains("'a'"));
    }
}
