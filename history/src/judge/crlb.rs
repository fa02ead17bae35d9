//! The judgement of a history too short to learn run-to-run scatter from: every parameter of
//! this run against one baseline run, in Cramér-Rao standard errors of the difference,
//! `(x − x_b) / √(σ² + σ_b²)`, an alarm beyond `k`. It is what a nightly without a `[history]`
//! database uses, from its second night on. It knows only the measurement noise of each fit, so
//! on a real machine (run-to-run scatter several times the Cramér-Rao errors) it raises far more
//! alarms than the charts of [`super`]; those take over as soon as a baseline window exists.
//!
//! The result is the report's drift section ([`report::Drift`]): the series of every parameter
//! over the runs, drawn by the report.

use report::document::{Drift, DriftSeries};

use crate::error::HistoryError;
use crate::record::RunRecord;

/// Which earlier run is the reference.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum Baseline {
    /// The oldest successful run in the history.
    #[default]
    First,
    /// The run named so (its report folder, e.g. `2025-03-01T020000Z`).
    Run(String),
}

/// Compares `current` with `history` (earlier runs, oldest first; failed runs are left out).
/// `None` when there is no earlier run; an error when the named baseline is not in the history.
pub fn compare(
    history: &[RunRecord],
    current: &RunRecord,
    baseline: &Baseline,
    k_sigma: f64,
) -> Result<Option<Drift>, HistoryError> {
    let history: Vec<&RunRecord> = history.iter().filter(|r| r.outcome != "failure").collect();
    if history.is_empty() {
        return Ok(None);
    }
    let b = match baseline {
        Baseline::First => 0,
        Baseline::Run(name) => history
            .iter()
            .position(|r| r.run_id == *name)
            .ok_or_else(|| HistoryError::NoSuchBaseline {
                name: name.clone(),
                runs: history.len(),
            })?,
    };
    let mut runs: Vec<String> = history.iter().map(|r| r.time_utc.clone()).collect();
    runs.push(current.time_utc.clone());
    let parameters = current
        .parameters
        .iter()
        .map(|p| {
            let f = p.unit_factor;
            let find = |r: &RunRecord| {
                r.parameter(&p.variable)
                    .filter(|q| q.unit == p.unit)
                    .cloned()
            };
            let display = |v: f64| Some(v / f).filter(|x| x.is_finite());
            let mut values: Vec<Option<f64>> = history
                .iter()
                .map(|r| find(r).and_then(|q| display(q.estimate)))
                .collect();
            let mut std_errors: Vec<Option<f64>> = history
                .iter()
                .map(|r| find(r).and_then(|q| q.std_error).and_then(display))
                .collect();
            values.push(display(p.estimate));
            std_errors.push(p.std_error.and_then(display));
            let n = values.len() - 1;
            let deviation_sigma = match (values[b], std_errors[b], values[n], std_errors[n]) {
                (Some(xb), Some(sb), Some(x), Some(s)) if (sb * sb + s * s) > 0.0 => {
                    Some((x - xb) / (sb * sb + s * s).sqrt())
                }
                _ => None,
            };
            DriftSeries {
                variable: p.variable.clone(),
                unit: p.unit.clone(),
                alarm: deviation_sigma.is_some_and(|d| d.abs() > k_sigma),
                values,
                std_errors,
                deviation_sigma,
            }
        })
        .collect();
    Ok(Some(Drift {
        k_sigma,
        runs,
        baseline: b,
        parameters,
    }))
}
