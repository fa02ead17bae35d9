//! The report's drift section as the page shows it: the deviation of a run from the baseline
//! run in standard errors of the difference, `(x − x_b) / √(σ² + σ_b²)` (both values are
//! estimates with Cramér-Rao errors), and attaching a judged section to a report.
//!
//! The rule that decides the alarms is not here: drift is judged by the run history
//! (`history::judge`, which imports this crate's [`Report`] type; this crate never imports the
//! history), and the section arrives here already judged.

use crate::document::{Drift, DriftSeries, Report};

/// The deviation of run `j` of a series from the baseline, in standard errors of the difference.
pub fn deviation(series: &DriftSeries, baseline: usize, j: usize) -> Option<f64> {
    let (xb, sb) = (
        series.values.get(baseline).copied().flatten()?,
        series.std_errors.get(baseline).copied().flatten()?,
    );
    let (x, s) = (
        series.values.get(j).copied().flatten()?,
        series.std_errors.get(j).copied().flatten()?,
    );
    let d = (sb * sb + s * s).sqrt();
    (d > 0.0).then(|| (x - xb) / d)
}

/// Attaches `drift` to `report`: each alarm becomes a status message and an `ok` outcome becomes
/// `alarm` (a `failure` stays a failure).
pub fn attach(report: &mut Report, drift: Drift) {
    for p in drift.parameters.iter().filter(|p| p.alarm) {
        report.status.messages.push(format!(
            "drift alarm: {} moved {:+.1} standard errors from the baseline run {} (threshold {} σ): {} → {} {}",
            p.variable,
            p.deviation_sigma.unwrap_or(0.0),
            drift.runs.get(drift.baseline).map(String::as_str).unwrap_or("?"),
            drift.k_sigma,
            p.values.get(drift.baseline).copied().flatten().map(|v| format!("{v:.4}")).unwrap_or_default(),
            p.values.last().copied().flatten().map(|v| format!("{v:.4}")).unwrap_or_default(),
            p.unit
        ));
    }
    if drift.parameters.iter().any(|p| p.alarm) && report.status.outcome == crate::Outcome::Ok {
        report.status.outcome = crate::Outcome::Alarm;
    }
    report.drift = Some(drift);
}
