//! The judgement's vocabulary, below the charts and the judgement that use it: the control-chart
//! rules and the change an alarm opens, followed night after night.

use serde::{Deserialize, Serialize};

/// A control-chart rule.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Rule {
    /// Individuals chart: one run beyond `k` scatters.
    Shewhart,
    /// Cumulative sum beyond its limit: a step.
    Cusum,
    /// Exponentially weighted moving average beyond its limit: a trend.
    Ewma,
    /// Hotelling T² of the parameter vector beyond its limit.
    HotellingT2,
    /// An effect no baseline run needed.
    NewEffect,
}

impl Rule {
    /// Name for readers.
    pub fn as_str(self) -> &'static str {
        match self {
            Rule::Shewhart => "Shewhart",
            Rule::Cusum => "CUSUM",
            Rule::Ewma => "EWMA",
            Rule::HotellingT2 => "Hotelling T²",
            Rule::NewEffect => "new effect",
        }
    }
}

/// The subject of the multivariate chart's alarms and changes.
pub const VECTOR: &str = "parameter vector";

/// A change followed after its alarm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Change {
    /// The rule that raised it.
    pub rule: Rule,
    /// The parameter, or [`VECTOR`].
    pub subject: String,
    /// The run of the alarm.
    pub alarm_run: String,
    /// The change-point estimate: the first run of the new level.
    pub change_point_run: String,
    /// The level since the change point in multiples of normal scatter (T²: mean T² / limit).
    pub level: f64,
    /// Nights judged after the alarm night.
    pub nights_after: usize,
    /// Whether the nights after the alarm confirm the change (`None` before the first).
    pub persists: Option<bool>,
    /// One sentence for the report.
    pub message: String,
    /// Sum of the residuals after the alarm (signed, scatters), for `persists`.
    #[serde(skip)]
    pub(super) sum_after: f64,
}
