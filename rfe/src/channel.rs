//! A vendor file's measured channels as read, before a measurement map puts them on the model:
//! how the file names each (a UFF node and direction, or a sensor), its reference, its unit as the
//! file gives it, and its values.

use crate::frf_units::FrfUnit;

/// How a measured channel is named in its file.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub enum ChannelName {
    /// A UFF response node and direction (±1..±6 = ±X, Y, Z, RX, RY, RZ).
    Node {
        /// Node number.
        node: i64,
        /// Direction code.
        dir: i64,
    },
    /// A named sensor.
    Sensor(String),
}

impl std::fmt::Display for ChannelName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ChannelName::Node { node, dir } => write!(f, "node {node} {}", dir_text(*dir)),
            ChannelName::Sensor(s) => write!(f, "sensor \"{s}\""),
        }
    }
}

/// `+X`, `-Z`, `+RY`, or the number.
pub fn dir_text(dir: i64) -> String {
    let axes = ["X", "Y", "Z", "RX", "RY", "RZ"];
    match axes.get((dir.unsigned_abs() as usize).wrapping_sub(1)) {
        Some(a) => format!("{}{a}", if dir < 0 { '-' } else { '+' }),
        None => dir.to_string(),
    }
}

/// Why a file gives a channel no usable unit, in the file's own terms (records, fields): the
/// measurement map then has to give one, and its message starts with this.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct NoUsableUnit(pub String);

/// One measured response of a file, before it is mapped onto the model.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredChannel {
    /// How the file names it.
    pub name: ChannelName,
    /// Where it is in the file, for messages: `dataset 3 (line 120)`.
    pub item: String,
    /// The reference (excitation) node and direction, if the file says.
    pub reference: Option<(i64, i64)>,
    /// The unit of its values as the file gives it, or why the file gives none usable.
    pub unit: Result<FrfUnit, NoUsableUnit>,
    /// Where the unit came from, for notes: `records 9-10: "m/s^2" per "N"`.
    pub unit_source: String,
    /// Frequencies (Hz).
    pub freqs_hz: Vec<f64>,
    /// Amplitudes in `unit`.
    pub amplitude: Vec<f64>,
    /// Phases (rad), when the file has complex values.
    pub phase_rad: Option<Vec<f64>>,
    /// Coherence γ² per line, when the file has it.
    pub coherence: Option<Vec<f64>>,
}
