//! The simulated stand's truth: the complex response of each sensor to the exciter's force.

use crate::stand::{Channel, ChannelKind, Truth, TruthModel};

/// Complex double.
pub type C64 = num_complex::Complex<f64>;

/// A structure seen through the stand's sensors.
pub trait Plant: Send + Sync {
    /// Number of sensors (acceleration channels, in stand order).
    fn sensor_count(&self) -> usize;
    /// For each frequency (Hz), the response of every sensor per newton of *delivered* force at
    /// the exciter, in the sensor's physical unit (m/s² per N for accelerometers).
    fn response(&self, freqs_hz: &[f64]) -> Result<Vec<Vec<C64>>, PlantError>;
}

/// Why the truth cannot be evaluated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("truth model: {0}")]
pub struct PlantError(pub String);

/// A rigid mass on a spring with hysteretic damping, moving along one direction. A sensor with
/// measuring direction `d` sees `(d·e) · a` where `e` is the direction of motion and
/// `a = −ω² / (k(1 + jη) − ω² m)` per newton.
#[derive(Debug, Clone, PartialEq)]
pub struct SdofPlant {
    /// Mass (kg).
    pub mass: f64,
    /// Stiffness (N/m).
    pub stiffness: f64,
    /// Loss factor η.
    pub loss_factor: f64,
    /// Each sensor's projection `d·e` onto the direction of motion.
    pub gains: Vec<f64>,
}

impl SdofPlant {
    /// Acceleration per newton along the direction of motion at `f` (Hz).
    pub fn accelerance(&self, f: f64) -> C64 {
        let w = 2.0 * std::f64::consts::PI * f;
        let d = C64::new(self.stiffness - w * w * self.mass, self.stiffness * self.loss_factor);
        C64::new(-w * w, 0.0) / d
    }
}

impl Plant for SdofPlant {
    fn sensor_count(&self) -> usize {
        self.gains.len()
    }
    fn response(&self, freqs_hz: &[f64]) -> Result<Vec<Vec<C64>>, PlantError> {
        Ok(freqs_hz
            .iter()
            .map(|&f| {
                let a = self.accelerance(f);
                self.gains.iter().map(|g| a * g).collect()
            })
            .collect())
    }
}

/// The shaker-structure interaction: delivered force = commanded · `gain / (1 + j f / cutoff)`.
/// The closed loop of a sweep has to compensate it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interaction {
    /// Low-frequency gain.
    pub gain: f64,
    /// Roll-off frequency (Hz); infinite for none.
    pub cutoff_hz: f64,
}

impl Interaction {
    /// Delivered force per commanded newton at `f` (Hz).
    pub fn at(&self, f: f64) -> C64 {
        if self.cutoff_hz.is_finite() {
            C64::new(self.gain, 0.0) / C64::new(1.0, f / self.cutoff_hz)
        } else {
            C64::new(self.gain, 0.0)
        }
    }
}

/// Builds the truth plant of a stand: one sensor per acceleration channel, in stand order.
pub fn plant_for(truth: &Truth, channels: &[Channel]) -> Result<Box<dyn Plant>, PlantError> {
    match &truth.model {
        TruthModel::Sdof { mass, stiffness, loss_factor, direction, .. } => {
            let gains = channels
                .iter()
                .filter(|c| c.kind == ChannelKind::Acceleration)
                .map(|c| c.direction.iter().zip(direction).map(|(a, b)| a * b).sum())
                .collect();
            Ok(Box::new(SdofPlant { mass: *mass, stiffness: *stiffness, loss_factor: *loss_factor, gains }))
        }
        TruthModel::ModelFile(p) => Err(PlantError(format!(
            "{}: RFE truth models need identify::frf::dof_response, which is not available yet; use `sdof = {{...}}` in [truth]",
            p.display()
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sdof_resonance_matches_analytic_values() {
        let p = SdofPlant { mass: 400.0, stiffness: 1.6e8, loss_factor: 0.05, gains: vec![1.0, 0.5] };
        let fn_ = (1.6e8f64 / 400.0).sqrt() / (2.0 * std::f64::consts::PI);
        let r = p.response(&[fn_, 1.0]).unwrap();
        // At ω_n: a = −ω²/(jηk) → |a| = m⁻¹/η, phase +90°.
        let a = r[0][0];
        assert!((a.norm() - 1.0 / (400.0 * 0.05)).abs() < 1e-9);
        assert!((a.arg() - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        assert!((r[0][1] - a * 0.5).norm() < 1e-15);
        // Far below resonance: a ≈ −ω²/k.
        let w = 2.0 * std::f64::consts::PI;
        assert!((r[1][0].re + w * w / 1.6e8).abs() < 1e-3 * w * w / 1.6e8);
    }

    #[test]
    fn interaction_rolls_off() {
        let i = Interaction { gain: 0.8, cutoff_hz: 100.0 };
        assert!((i.at(0.0).norm() - 0.8).abs() < 1e-12);
        assert!((i.at(100.0).norm() - 0.8 / 2f64.sqrt()).abs() < 1e-12);
    }
}
