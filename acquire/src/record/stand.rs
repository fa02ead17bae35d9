//! `/stand`: the stand file verbatim and what it resolved to: the channel map (what each DAQ
//! channel measures, where, with which sensitivity) and the mass properties of the bodies the
//! sensors are on. `stand` resolves them from the stand file; `analysis` and replay read them back.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::topic::{Topic, TopicRecord};

/// `/stand`: the stand file verbatim and what it resolved to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.Stand")]
pub struct StandRecord {
    /// Stand name.
    pub name: String,
    /// The stand file's path as given.
    #[serde(default)]
    pub file: String,
    /// The stand file's text.
    pub text: String,
    /// The resolved channel map (sensitivity V/N or V/(m/s²), positions m, directions unit).
    pub channels: Vec<Channel>,
    /// Bodies the sensors are on, from the stand's `[geometry]` model (absent without one).
    #[serde(default)]
    pub geometry: Option<Geometry>,
}

impl TopicRecord for StandRecord {
    const TOPIC: Topic = Topic::Stand;
}

/// What a channel measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ChannelKind {
    /// The excitation force (N) at the exciter.
    Force,
    /// Acceleration (m/s²) along `direction` at `position` on `body`.
    Acceleration,
}

/// One DAQ channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Channel {
    /// Unique name.
    pub name: String,
    /// Channel number on the DAQ.
    pub device_channel: u16,
    /// What it measures.
    pub kind: ChannelKind,
    /// Sensitivity (V/N or V/(m/s²)): physical value = volts / sensitivity.
    pub sensitivity: f64,
    /// Body the sensor is on (acceleration channels).
    pub body: Option<String>,
    /// Sensor position, global frame (m).
    pub position_m: [f64; 3],
    /// Measuring direction, global frame, unit length.
    pub direction: [f64; 3],
    /// Line in the stand file, for later messages.
    #[serde(default)]
    pub line: usize,
}

/// Mass properties of the bodies the accelerometers are on, and the nominal excitation: what
/// processing needs to turn sensor FRFs into principal-axis characteristics. Truth independent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Geometry {
    /// The model file it was read from.
    pub source: String,
    /// Bodies that carry accelerometers, in first-use order.
    pub bodies: Vec<BodyGeometry>,
    /// Amplitude of the model's declared excitation force (N): characteristics are the response
    /// to it (`rfe::MeasuredData` convention).
    pub nominal_force_n: f64,
    /// The model's declared output characteristics on these bodies (what identification uses).
    #[serde(default)]
    pub outputs: Vec<GeometryOutput>,
}

/// A characteristic the geometry model declares as an output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct GeometryOutput {
    /// Body name.
    pub body: String,
    /// 0-2 translations, 3-5 rotations along the principal axes.
    pub dof: u8,
    /// `displacement`, `velocity` or `acceleration`.
    pub quantity: String,
}

/// One body's mass properties (the `identify` model's body, SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct BodyGeometry {
    /// Body name.
    pub name: String,
    /// Mass (kg).
    pub mass: f64,
    /// Principal central moments of inertia (kg·m²).
    pub inertia: [f64; 3],
    /// Centre of mass, global frame (m).
    pub position: [f64; 3],
    /// `global_from_body`, row-major: its columns are the principal axes in the global frame.
    pub rotation: [[f64; 3]; 3],
}

impl BodyGeometry {
    /// From an `identify` body.
    pub fn from_body(b: &rfe::Body) -> BodyGeometry {
        let r = &b.rotation;
        BodyGeometry {
            name: b.name.clone(),
            mass: b.mass,
            inertia: b.inertia,
            position: [b.position.x, b.position.y, b.position.z],
            rotation: [
                [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
                [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
                [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
            ],
        }
    }

    /// As an `identify` body.
    pub fn to_body(&self) -> rfe::Body {
        let r = &self.rotation;
        rfe::Body {
            name: self.name.clone(),
            mass: self.mass,
            inertia: self.inertia,
            position: nalgebra::Vector3::from(self.position),
            rotation: nalgebra::Matrix3::new(
                r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2],
            ),
        }
    }

    /// Half extents (m) along the principal axes of the homogeneous box with this mass and these
    /// principal moments (`J1 = m(b² + c²)/12`, ...): where a sensor on the body can sit.
    pub fn equivalent_box_half_extents(&self) -> [f64; 3] {
        let [j1, j2, j3] = self.inertia;
        let m = self.mass;
        let half = |x: f64| 0.5 * (6.0 * x / m).max(0.0).sqrt();
        [half(j2 + j3 - j1), half(j1 + j3 - j2), half(j1 + j2 - j3)]
    }

    /// Where a global point lies in body axes, relative to the centre of mass (m).
    pub fn body_from_global(&self, x: [f64; 3]) -> [f64; 3] {
        let d = [
            x[0] - self.position[0],
            x[1] - self.position[1],
            x[2] - self.position[2],
        ];
        let r = &self.rotation;
        // Rᵀ d: column k of R is principal axis k.
        [0, 1, 2].map(|k| r[0][k] * d[0] + r[1][k] * d[1] + r[2][k] * d[2])
    }
}
