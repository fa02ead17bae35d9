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
        let d = C64::new(
            self.stiffness - w * w * self.mass,
            self.stiffness * self.loss_factor,
        );
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
        TruthModel::Sdof {
            mass,
            stiffness,
            loss_factor,
            direction,
            ..
        } => {
            let gains = channels
                .iter()
                .filter(|c| c.kind == ChannelKind::Acceleration)
                .map(|c| c.direction.iter().zip(direction).map(|(a, b)| a * b).sum())
                .collect();
            Ok(Box::new(SdofPlant {
                mass: *mass,
                stiffness: *stiffness,
                loss_factor: *loss_factor,
                gains,
            }))
        }
        TruthModel::ModelFile(p) => {
            let loaded = rfe::modelfile::load(p).map_err(|e| PlantError(e.to_string()))?;
            Ok(Box::new(ModelPlant::new(
                loaded.model,
                channels,
                &p.display().to_string(),
            )?))
        }
    }
}

/// An RFE model (from `identify`) as truth. An accelerometer at `x` on body `b` with global unit
/// direction `d` measures `−ω² dᵀ R_b (u + θ × R_bᵀ(x − c_b))`, where `u`, `θ` are the body's
/// translation and rotation in its principal axes (from [`rfe::frf::dof_response`]) and
/// `R_b` is `global_from_body`. Responses are divided by the magnitude of the model's first
/// declared excitation force (for a force pair: the exciter's force), so they are per newton.
pub struct ModelPlant {
    model: rfe::Model,
    /// (body index, offset from the centre of mass in body axes, direction in body axes).
    sensors: Vec<(usize, [f64; 3], [f64; 3])>,
    force_n: f64,
}

impl ModelPlant {
    /// Resolves the acceleration channels against the model's bodies.
    pub fn new(
        model: rfe::Model,
        channels: &[Channel],
        origin: &str,
    ) -> Result<ModelPlant, PlantError> {
        // A force pair declares the same magnitude twice: the exciter's force is one of them.
        let force_n = model.forces.first().map(|f| f.force.norm()).unwrap_or(0.0);
        if !(force_n > 0.0) {
            return Err(PlantError(format!("{origin}: the model declares no excitation force; the simulated stand drives its exciter")));
        }
        let mut sensors = Vec::new();
        for c in channels
            .iter()
            .filter(|c| c.kind == ChannelKind::Acceleration)
        {
            let name = c.body.as_deref().unwrap_or("");
            let b = model.body_index(name).ok_or_else(|| {
                let names: Vec<&str> = model.bodies.iter().map(|b| b.name.as_str()).collect();
                PlantError(format!(
                    "channel `{}`: body `{name}` is not in {origin} (bodies: {})",
                    c.name,
                    names.join(", ")
                ))
            })?;
            let body = &model.bodies[b];
            let x = nalgebra::Vector3::from(c.position_m) - body.position;
            let r_loc = body.rotation.transpose() * x;
            let d_loc = body.rotation.transpose() * nalgebra::Vector3::from(c.direction);
            sensors.push((b, [r_loc.x, r_loc.y, r_loc.z], [d_loc.x, d_loc.y, d_loc.z]));
        }
        Ok(ModelPlant {
            model,
            sensors,
            force_n,
        })
    }
}

impl Plant for ModelPlant {
    fn sensor_count(&self) -> usize {
        self.sensors.len()
    }
    fn response(&self, freqs_hz: &[f64]) -> Result<Vec<Vec<C64>>, PlantError> {
        let q =
            rfe::frf::dof_response(&self.model, freqs_hz).map_err(|e| PlantError(e.to_string()))?;
        Ok(q.iter()
            .zip(freqs_hz)
            .map(|(q, &f)| {
                let w = 2.0 * std::f64::consts::PI * f;
                self.sensors
                    .iter()
                    .map(|(b, r, d)| {
                        let u = &q[6 * b..6 * b + 3];
                        let t = &q[6 * b + 3..6 * b + 6];
                        // θ × r
                        let tr = [
                            t[1] * r[2] - t[2] * r[1],
                            t[2] * r[0] - t[0] * r[2],
                            t[0] * r[1] - t[1] * r[0],
                        ];
                        let disp: C64 = (0..3).map(|k| (u[k] + tr[k]) * d[k]).sum();
                        disp * (-w * w) / self.force_n
                    })
                    .collect()
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sdof_resonance_matches_analytic_values() {
        let p = SdofPlant {
            mass: 400.0,
            stiffness: 1.6e8,
            loss_factor: 0.05,
            gains: vec![1.0, 0.5],
        };
        let fn_ = (1.6e8f64 / 400.0).sqrt() / (2.0 * std::f64::consts::PI);
        let r = p.response(&[fn_, 1.0]).unwrap();
        // At ω_n: a = −ω²/(jηk) → |a| = m⁻¹/η, phase +90°.
        let a = r[0][0];
        assert!((a.norm() - 1.0 / (400.0 * 0.05)).abs() < 1e-9);
        assert!((a.arg() - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        assert!((r[0][1] - a * 0.5).norm() < 1e-15);
        // Far below resonance: a ≈ −ω²/(k(1 + jη)).
        let w = 2.0 * std::f64::consts::PI;
        let quasi_static = C64::new(-w * w, 0.0) / C64::new(1.6e8, 1.6e8 * 0.05);
        // (relative deviation ω²m/k ≈ 1e-4 at 1 Hz)
        assert!((r[1][0] - quasi_static).norm() < 2e-4 * quasi_static.norm());
    }

    #[test]
    fn model_plant_sensors_follow_rigid_body_kinematics() {
        use nalgebra::Vector3;
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/models/fwd32j.toml");
        let model = rfe::modelfile::load(&path).unwrap().model;
        let b = 0;
        let body = model.bodies[b].clone();
        let offset = Vector3::new(0.21, -0.13, 0.08);
        let dir = Vector3::new(0.3, 0.5, 0.812).normalize();
        let ch = |name: &str, pos: Vector3<f64>, d: Vector3<f64>| Channel {
            name: name.into(),
            device_channel: 1,
            kind: ChannelKind::Acceleration,
            sensitivity: 1.0,
            body: Some(body.name.clone()),
            position_m: [pos.x, pos.y, pos.z],
            direction: [d.x, d.y, d.z],
            line: 1,
        };
        let axis1 = body.rotation.column(0).into_owned();
        let channels = vec![
            ch("com", body.position, axis1),
            ch("off", body.position + offset, dir),
        ];
        let plant = ModelPlant::new(model.clone(), &channels, "fwd32j").unwrap();
        let freqs = [15.0, 80.0];
        let r = plant.response(&freqs).unwrap();
        let q = rfe::frf::dof_response(&model, &freqs).unwrap();
        let fnorm = model.forces[0].force.norm();
        for (k, f) in freqs.iter().enumerate() {
            let w2 = (2.0 * std::f64::consts::PI * f).powi(2);
            // At the centre of mass along principal axis 1: −ω² u1.
            let want = q[k][6 * b] * (-w2) / fnorm;
            assert!(
                (r[k][0] - want).norm() <= 1e-9 * want.norm(),
                "{} vs {}",
                r[k][0],
                want
            );
            // Independent, global-frame computation: R u + (R θ) × (x − c).
            let rot = body.rotation.map(|x| C64::new(x, 0.0));
            let u = rot * nalgebra::Vector3::new(q[k][6 * b], q[k][6 * b + 1], q[k][6 * b + 2]);
            let t = rot * nalgebra::Vector3::new(q[k][6 * b + 3], q[k][6 * b + 4], q[k][6 * b + 5]);
            let off = offset.map(|x| C64::new(x, 0.0));
            let disp = u + t.cross(&off);
            let want = disp.dot(&dir.map(|x| C64::new(x, 0.0))) * (-w2) / fnorm;
            assert!(
                (r[k][1] - want).norm() <= 1e-9 * want.norm(),
                "{} vs {}",
                r[k][1],
                want
            );
        }
    }

    #[test]
    fn interaction_rolls_off() {
        let i = Interaction {
            gain: 0.8,
            cutoff_hz: 100.0,
        };
        assert!((i.at(0.0).norm() - 0.8).abs() < 1e-12);
        assert!((i.at(100.0).norm() - 0.8 / 2f64.sqrt()).abs() < 1e-12);
    }
}
