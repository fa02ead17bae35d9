//! One run as the history stores it: the row shapes, one Rust type per table, from which the
//! SQL of [`crate::store`] is written. Values in SI; each parameter also carries its display unit
//! (the paper's `MPa/um`, `N/um`, `-`) and the factor to it.

use serde::{Deserialize, Serialize};

/// One identification run (a nightly, or an `identify`/`diagnose` asked to record).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// Unique name of the run (the report folder name, e.g. `2026-03-01T020000Z`).
    pub run_id: String,
    /// When it ran (UTC, `YYYY-MM-DDTHH:MM:SSZ`).
    pub time_utc: String,
    /// Stand name, when a stand was measured.
    pub stand: Option<String>,
    /// Hash of the identification model ([`model_hash`]); runs of different models are never
    /// compared.
    pub model_hash: String,
    /// Session recording the run identified.
    pub session: Option<String>,
    /// `ok`, `alarm` or `failure`.
    pub outcome: String,
    /// 2J / (m − n) of the final fit (≈ 1 at the noise level).
    pub reduced_chi2: Option<f64>,
    /// Every identified parameter.
    pub parameters: Vec<ParameterRecord>,
    /// RMS relative amplitude error per characteristic (final fit).
    pub characteristics: Vec<CharacteristicFit>,
    /// Effects diagnosis accepted (`"spring spindle head–table"`).
    pub effects: Vec<String>,
    /// Covariates measured with the session (temperatures, ...).
    pub covariates: Vec<Covariate>,
    /// Cramér-Rao correlations between the parameters (each pair once; empty when the report
    /// had none): the multivariate chart's correlation structure.
    #[serde(default)]
    pub correlations: Vec<Correlation>,
    /// Quantities derived from the final model and judged like the parameters, but kept out of
    /// the multivariate chart (they are functions of the parameters): the minimum critical depth
    /// of a cut over its speed range (`stable depth 200–2000 rpm (cut)`, unit `mm`). Empty when
    /// the run had no cut.
    #[serde(default)]
    pub quantities: Vec<ParameterRecord>,
}

/// The Cramér-Rao correlation of two parameters of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Correlation {
    /// First variable.
    pub a: String,
    /// Second variable.
    pub b: String,
    /// Correlation coefficient (−1..1).
    pub value: f64,
}

/// One identified parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterRecord {
    /// Variable name (the key of a series).
    pub variable: String,
    /// Display unit (`MPa/um`, `N/um`, `-`).
    pub unit: String,
    /// SI per display unit (1e12 for MPa/µm, 1e6 for N/µm).
    pub unit_factor: f64,
    /// Estimate (SI).
    pub estimate: f64,
    /// Cramér-Rao standard error (SI); `None` when undetermined.
    pub std_error: Option<f64>,
}

impl ParameterRecord {
    /// The estimate in the display unit.
    pub fn in_unit(&self) -> f64 {
        self.estimate / self.unit_factor
    }
}

/// How well the final model fits one characteristic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CharacteristicFit {
    /// `"table u1 displacement"`.
    pub label: String,
    /// RMS of (model − measured) / measured (dimensionless).
    pub rms_relative_error: f64,
}

/// A quantity measured with the session that may explain normal variation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Covariate {
    /// Channel name (`"temperature"`, `"spindle housing temperature"`).
    pub name: String,
    /// Its unit (`"degC"`).
    pub unit: String,
    /// Value.
    pub value: f64,
}

impl RunRecord {
    /// The parameter or derived quantity named `variable`, if this run has it.
    pub fn parameter(&self, variable: &str) -> Option<&ParameterRecord> {
        self.parameters
            .iter()
            .chain(&self.quantities)
            .find(|p| p.variable == variable)
    }

    /// The Cramér-Rao correlation of variables `a` and `b` (1 when `a == b`), if recorded.
    pub fn correlation(&self, a: &str, b: &str) -> Option<f64> {
        if a == b {
            return Some(1.0);
        }
        self.correlations
            .iter()
            .find(|c| (c.a == a && c.b == b) || (c.a == b && c.b == a))
            .map(|c| c.value)
            .filter(|v| v.is_finite())
    }

    /// The covariate named `name`, if recorded.
    pub fn covariate(&self, name: &str) -> Option<f64> {
        self.covariates
            .iter()
            .find(|c| c.name == name)
            .map(|c| c.value)
    }
}

/// The model hash of a model file's bytes: CRC-64/ECMA-182 as 16 hex digits. Two runs compare
/// only when their models hash alike (any edit of the file makes a new series).
pub fn model_hash(bytes: &[u8]) -> String {
    const CRC: crc::Crc<u64> = crc::Crc::<u64>::new(&crc::CRC_64_ECMA_182);
    format!("{:016x}", CRC.checksum(bytes))
}

/// SI per display unit for a unit symbol of the identification tables (`MPa/um` → 1e12); `None`
/// when the symbol is not a unit of a stiffness, a contact stiffness, a rotational stiffness or a
/// pure number.
pub fn unit_factor(symbol: &str) -> Option<f64> {
    use rfe::units::{parse_quantity, Dim};
    let s = symbol.trim();
    if s == "-" || s.is_empty() {
        return Some(1.0);
    }
    [
        Dim::CONTACT_STIFFNESS,
        Dim::STIFFNESS,
        Dim::ROTATIONAL_STIFFNESS,
        Dim::NONE,
    ]
    .into_iter()
    .find_map(|d| parse_quantity(&format!("1 {s}"), d).ok())
}
