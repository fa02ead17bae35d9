//! The report as data: what the JSON file holds (schema `ident.report/1`, documented in
//! `docs/report-json.md` and `docs/report.schema.json`) and what the HTML page draws.
//!
//! Units: frequencies in Hz; amplitudes in SI (m, m/s, m/s², rad, ...) for the model's declared
//! excitation; parameter values in each variable's display unit (`unit` field, e.g. `MPa/um`).
//! Every number is finite; values that do not exist are `null`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Schema identifier written into every report.
pub const SCHEMA: &str = "ident.report/1";

/// A whole report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Report {
    /// Always [`SCHEMA`].
    #[schemars(extend("const" = "ident.report/1"))]
    pub schema: String,
    /// Headline, e.g. `"FWD-32J nightly identification"`.
    pub title: String,
    /// When the report was made (UTC, ISO 8601 `YYYY-MM-DDTHH:MM:SSZ`).
    #[schemars(regex(pattern = r"^[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9]{2}:[0-9]{2}:[0-9]{2}Z$"))]
    pub created_utc: String,
    /// Where the data and models came from.
    pub source: Source,
    /// Overall outcome and the messages behind it.
    pub status: Status,
    /// Per measured characteristic: measured points and model curves per stage.
    pub characteristics: Vec<CharacteristicReport>,
    /// The identification (Table-1-like table and fit summary).
    pub identification: IdentificationSummary,
    /// Closed-loop diagnosis (docs/diagnosis.md), when it ran.
    pub diagnosis: Option<Diagnosis>,
    /// Band sensitivity (relative MI, paper eq. 4.16) of the identified model.
    pub sensitivity: Option<SensitivityMap>,
    /// The final model as a drawing: body boxes, SDEs, exciter, measured points and the mode
    /// shapes in the band ([`crate::picture`]); `null` in reports written before it existed.
    #[serde(default)]
    pub picture: Option<crate::picture::ModelPicture>,
    /// Parameter history across runs (nightly).
    pub drift: Option<Drift>,
    /// Chatter stability of the final model for a cut (`--cut`, or the nightly's
    /// `[stability]`): the lobes with their 5–95 % band from the final fit's covariance, the
    /// minimum critical depth over the speed range, the limiting modes with their bodies and
    /// joints (`docs/stability.md`); `null` when no cut was given.
    #[serde(default)]
    pub stability: Option<stability::section::Stability>,
    /// Natural frequencies of the identified and the diagnosed model inside the measured band
    /// (marked on the amplitude charts).
    #[serde(default)]
    pub natural_frequencies: Vec<StageModes>,
}

/// Provenance.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Source {
    /// `demo`, `replay`, `nightly`, `identify` or `diagnose`.
    #[schemars(extend("enum" = ["demo", "replay", "nightly", "identify", "diagnose"]))]
    pub workflow: String,
    /// Session recording (MCAP) the measurement came from, if any.
    pub session: Option<String>,
    /// Stand file or name.
    pub stand: Option<String>,
    /// Identification model file.
    pub model: String,
    /// Decision-variables file.
    pub variables: String,
    /// `MeasuredData.source`: free text about the measurement.
    pub measurement: String,
    /// `ident` version that wrote the report.
    pub software: String,
}

/// Outcome of the run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Status {
    /// `ok`, `alarm` (a drift alarm) or `failure`.
    pub outcome: Outcome,
    /// What happened, one sentence each (alarms, warnings, lost data).
    pub messages: Vec<String>,
}

/// Outcome of a run; nightly exits 0, 1, 2 for these.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Outcome {
    /// Nothing to report.
    Ok,
    /// A parameter drifted beyond the threshold.
    Alarm,
    /// The run could not complete.
    Failure,
}

impl Outcome {
    /// `ok` / `alarm` / `failure`.
    pub fn as_str(self) -> &'static str {
        match self {
            Outcome::Ok => "ok",
            Outcome::Alarm => "alarm",
            Outcome::Failure => "failure",
        }
    }
}

/// One characteristic: measured points and model curves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CharacteristicReport {
    /// `"table u1 displacement"`.
    pub label: String,
    /// Body name.
    pub body: String,
    /// 0-2 translations u1..u3, 3-5 rotations r1..r3 (principal central axes).
    pub dof: u8,
    /// `displacement`, `velocity` or `acceleration`.
    pub quantity: String,
    /// SI unit of the amplitudes (`m`, `rad/s2`, ...).
    pub unit: String,
    /// Frequencies (Hz).
    pub freqs_hz: Vec<f64>,
    /// Measured amplitudes.
    pub measured: Vec<f64>,
    /// Standard deviation of each measured amplitude (same unit), from the data's variance,
    /// coherence or (`sigma_kind = relative`) 1 % of the amplitude.
    pub sigma: Vec<f64>,
    /// `variance`, `coherence` or `relative`.
    pub sigma_kind: String,
    /// Measured phase (rad) at `freqs_hz`, when the data have phase.
    #[serde(default)]
    pub measured_phase_rad: Option<Vec<f64>>,
    /// Model amplitude per stage (`initial`, `identified`, `diagnosed`).
    pub stages: Vec<StageCurve>,
}

/// The model's curve at one stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct StageCurve {
    /// `initial`, `identified` or `diagnosed`.
    pub stage: String,
    /// Model amplitudes at `freqs_hz`.
    pub amplitude: Vec<f64>,
    /// (measured − model) / sigma per point.
    pub standardized_residual: Vec<f64>,
    /// RMS of (model − measured) / measured over the points.
    pub rms_relative_error: f64,
    /// RMS of 20·log10(model / measured) over the points (dB): not dominated by the
    /// anti-resonance lines as the relative error is. 0 in reports written before it existed.
    #[serde(default)]
    pub rms_db_error: f64,
    /// The model on a dense log grid across the measured band (the identified and diagnosed
    /// stages; `null` for `initial`), drawn as the smooth model curve.
    #[serde(default)]
    pub dense: Option<DenseCurve>,
}

/// A model curve on a dense frequency grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DenseCurve {
    /// Frequencies (Hz), strictly increasing: [`crate::build::DENSE_LINES`] log-spaced lines
    /// from the lowest to the highest measured line, the measured lines themselves, and each
    /// natural frequency of the stage's model in the band with its half-power points, so
    /// resonance peaks are not clipped between grid lines.
    pub freqs_hz: Vec<f64>,
    /// Model amplitudes at `freqs_hz` (the characteristic's `unit`).
    pub amplitude: Vec<f64>,
    /// Model phase (rad, in (−π, π]) at `freqs_hz`, when the measurement has phase.
    pub phase_rad: Option<Vec<f64>>,
}

/// The natural frequencies of one stage's model inside the measured band.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct StageModes {
    /// `identified` or `diagnosed`.
    pub stage: String,
    /// The band (Hz): lowest and highest measured line.
    pub band_hz: [f64; 2],
    /// The modes in the band, ascending.
    pub modes: Vec<NaturalMode>,
}

/// One mode of a model (`rfe::modes::complex`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NaturalMode {
    /// 1-based number among all the model's modes, ascending in frequency (rigid-body modes
    /// included), as `ident modes` numbers them.
    pub number: usize,
    /// Natural frequency (Hz).
    pub freq_hz: f64,
    /// Loss factor η (dimensionless; ψ = 2πη for a single SDE).
    pub loss_factor: f64,
}

/// One row of the Table-1-like table, in the variable's display unit: the record `ident identify`
/// writes as its table, so the two cannot drift apart.
pub use identify::report::Row as Parameter;

/// The JSON Schema of the report, generated from [`Report`] (docs/report.schema.json is this,
/// pretty-printed; `IDENT_BLESS=1 cargo test -p report --test schema` rewrites it).
pub fn json_schema() -> serde_json::Value {
    let mut s = serde_json::Value::from(schemars::schema_for!(Report));
    if let Some(o) = s.as_object_mut() {
        o.insert("$id".into(), SCHEMA.into());
        o.insert("title".into(), SCHEMA.into());
        o.insert(
            "description".into(),
            "An ident identification report (docs/report-json.md), generated from report::document::Report. Frequencies in Hz, amplitudes in SI for the model's declared excitation, parameter values in each row's display unit.".into(),
        );
    }
    s
}

/// The identification's outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct IdentificationSummary {
    /// Minimizer.
    pub optimizer: String,
    /// Whether it converged.
    pub converged: bool,
    /// Why it stopped.
    pub stop: String,
    /// Iterations.
    pub iterations: usize,
    /// Scalar observations (residuals).
    pub observations: usize,
    /// Noise model sentence.
    pub noise: String,
    /// Criterion J at the initial values.
    pub criterion_initial: f64,
    /// Criterion J at the estimate.
    pub criterion: f64,
    /// 2J / (m − n).
    pub reduced_chi2: f64,
    /// The table.
    pub parameters: Vec<Parameter>,
    /// Correlation matrix in table order (`null` where undetermined).
    pub correlation: Vec<Vec<Option<f64>>>,
    /// Poorly identifiable combinations with their relative σ (`null`: no information).
    pub weak_directions: Vec<WeakDirection>,
}

/// A poorly identifiable direction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WeakDirection {
    /// `"0.71 kn_2 − 0.70 kn_3"`.
    pub combination: String,
    /// Relative σ along it.
    pub relative_std: Option<f64>,
}

/// The diagnosis section: filled from `diagnose::diagnose` by [`crate::build::diagnosis`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Diagnosis {
    /// Candidate effects ranked by their score statistic, strongest first.
    pub candidates: Vec<Candidate>,
    /// Fit of the model before diagnosis (the identified model).
    pub before: FitQuality,
    /// Fit after the accepted effects were added and the model refitted.
    pub after: FitQuality,
    /// One line on the final model (e.g. `"fwd32j-no-actuator + spring spindle head–table"`).
    pub final_model: String,
    /// For each added effect the data cannot tell from others (their refits end within a
    /// likelihood ratio of 3.84 of it): `"<effect> ≡ <other>; <other>"`.
    #[serde(default)]
    pub look_alikes: Vec<String>,
    /// The final model's variables when an effect was added: `identified` is the value at the
    /// final (extended) fit with its Cramér-Rao error there, `initial` the superseded first fit's
    /// value. Empty when nothing was added: the identification's table is final.
    #[serde(default)]
    pub final_parameters: Vec<Parameter>,
    /// The Cramér-Rao correlation of `final_parameters` at the final fit, in their order (`null`
    /// where undetermined); empty when nothing was added (the identification's `correlation`
    /// is final) and in reports written before it existed.
    #[serde(default)]
    pub final_correlation: Vec<Vec<Option<f64>>>,
    /// Whether the final model explains the data to the noise level.
    pub explained: bool,
    /// The verdict on the final model in words.
    pub verdict: String,
    /// Effects and refits that could not be evaluated, and why.
    pub not_tried: Vec<NotTried>,
}

/// A candidate effect or refit diagnosis could not evaluate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NotTried {
    /// What.
    pub effect: String,
    /// Why.
    pub reason: String,
}

/// A candidate undeclared effect.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Candidate {
    /// Diagnosis round (1-based): each round ranks the candidates at the current fit and adds at
    /// most one.
    pub round: usize,
    /// What the effect is (`"spring"`, `"joint stiffness kn"`).
    pub name: String,
    /// Where (`"spindle head–table"`, `"SDE 12"`).
    pub location: String,
    /// Score-test statistic (χ², 1 degree of freedom per added parameter).
    pub statistic: f64,
    /// Its p-value.
    pub p_value: f64,
    /// Whether diagnosis added it to the model.
    pub accepted: bool,
    /// Estimated value after the refit, when accepted.
    pub estimate: Option<f64>,
    /// Its standard error.
    pub std_error: Option<f64>,
    /// Unit of estimate and std_error.
    pub unit: String,
    /// When accepted: the RMS amplitude error (dB, every fitted point) before and after it was
    /// added, its gain in the curves' terms beside the criterion's.
    #[serde(default)]
    pub rms_db_before: Option<f64>,
    /// After.
    #[serde(default)]
    pub rms_db_after: Option<f64>,
}

/// How well a model fits the data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FitQuality {
    /// Criterion J.
    pub criterion: f64,
    /// p-value of 2J under χ²(m − n) (small: the model does not explain the data); `null` when
    /// the noise level is known only up to scale.
    pub chi2_p_value: Option<f64>,
    /// 2J / (m − n): ≈ 1 at the noise level.
    pub reduced_chi2: f64,
    /// RMS relative amplitude error per characteristic label.
    pub rms_relative_error: Vec<LabelledValue>,
    /// RMS amplitude error (dB) per characteristic label.
    #[serde(default)]
    pub rms_db_error: Vec<LabelledValue>,
}

/// A label and a number.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LabelledValue {
    /// Label.
    pub label: String,
    /// Value.
    pub value: f64,
}

/// Relative band sensitivity MIr (dimensionless) of each characteristic to each identified
/// parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SensitivityMap {
    /// Band (Hz): the measured lines from `band_hz[0]` to `band_hz[1]`.
    pub band_hz: [f64; 2],
    /// Row labels: `"SDE 2 kn"`.
    pub parameters: Vec<String>,
    /// Column labels: characteristic labels.
    pub characteristics: Vec<String>,
    /// `relative[row][column]`.
    pub relative: Vec<Vec<f64>>,
}

/// Parameter history across runs, compared with a baseline run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Drift {
    /// Alarm threshold in baseline standard errors.
    pub k_sigma: f64,
    /// `created_utc` of each run, oldest first; the last is this run.
    pub runs: Vec<String>,
    /// Index into `runs` of the baseline.
    pub baseline: usize,
    /// One series per parameter of this run.
    pub parameters: Vec<DriftSeries>,
}

/// The history of one parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DriftSeries {
    /// Variable name.
    pub variable: String,
    /// Display unit.
    pub unit: String,
    /// Value per run (`null` where the run did not identify it).
    pub values: Vec<Option<f64>>,
    /// Standard error per run.
    pub std_errors: Vec<Option<f64>>,
    /// (this run − baseline) / baseline standard error; `null` without a baseline value or error.
    pub deviation_sigma: Option<f64>,
    /// |deviation_sigma| > k_sigma.
    pub alarm: bool,
}
