//! Drift of identified parameters across runs (nightly): every parameter of this run is compared
//! with a baseline run; a change beyond `k` standard errors of the difference is an alarm (a
//! loosening joint shows as a falling stiffness).
//!
//! The deviation is `(x − x_b) / √(σ² + σ_b²)`: both values are estimates with Cramér-Rao errors.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::document::{Drift, DriftSeries, Parameter, Report};

/// The parameters of one earlier run, as read from its report.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// The run's `created_utc`.
    pub created_utc: String,
    /// Where it was read from (report folder).
    pub folder: PathBuf,
    /// Its table.
    pub parameters: Vec<Parameter>,
}

/// Which earlier run is the reference.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum Baseline {
    /// The oldest successful run in the history.
    #[default]
    First,
    /// The run whose report folder has this name (e.g. `2025-03-01T020000Z`).
    Folder(String),
}

/// Only what drift needs from an older report; tolerant of other fields so that history survives
/// additions to the schema.
#[derive(Deserialize)]
struct Minimal {
    created_utc: String,
    status: MinimalStatus,
    identification: Option<MinimalId>,
}
#[derive(Deserialize)]
struct MinimalStatus {
    outcome: String,
}
#[derive(Deserialize)]
struct MinimalId {
    parameters: Vec<Parameter>,
}

/// Reads `*/report.json` under `dir` (one sub-folder per run), oldest first (by `created_utc`),
/// skipping failed runs. Unreadable reports are returned as messages, never fatal.
pub fn read_history(dir: &Path) -> (Vec<Run>, Vec<String>) {
    let mut runs = Vec::new();
    let mut messages = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return (runs, messages);
    };
    for e in entries.flatten() {
        let path = e.path().join("report.json");
        if !path.is_file() {
            continue;
        }
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(err) => {
                messages.push(format!(
                    "history: cannot read {}: {err}; that run is left out",
                    path.display()
                ));
                continue;
            }
        };
        match serde_json::from_str::<Minimal>(&text) {
            Ok(m) if m.status.outcome != "failure" => {
                if let Some(id) = m.identification {
                    runs.push(Run {
                        created_utc: m.created_utc,
                        folder: e.path(),
                        parameters: id.parameters,
                    });
                }
            }
            Ok(_) => {}
            Err(err) => messages.push(format!(
                "history: {} line {}: {err}; that run is left out of the drift comparison",
                path.display(),
                err.line()
            )),
        }
    }
    runs.sort_by(|a, b| {
        a.created_utc
            .cmp(&b.created_utc)
            .then(a.folder.cmp(&b.folder))
    });
    (runs, messages)
}

/// Compares `current` (this run's report, before drift is attached) with `history` (earlier runs,
/// oldest first). Returns `None` when there is no earlier run to compare with; an error message
/// when the named baseline is not in the history.
pub fn compare(
    history: &[Run],
    current: &Report,
    baseline: &Baseline,
    k_sigma: f64,
) -> Result<Option<Drift>, String> {
    if history.is_empty() {
        return Ok(None);
    }
    let b = match baseline {
        Baseline::First => 0,
        Baseline::Folder(name) => history
            .iter()
            .position(|r| r.folder.file_name().is_some_and(|f| f.to_string_lossy() == *name))
            .ok_or_else(|| {
                format!("baseline run \"{name}\" is not among the {} earlier reports; set `baseline` to one of their folder names or \"first\"", history.len())
            })?,
    };
    let mut runs: Vec<String> = history.iter().map(|r| r.created_utc.clone()).collect();
    runs.push(current.created_utc.clone());
    let parameters = current
        .identification
        .parameters
        .iter()
        .map(|p| {
            let find = |r: &Run| {
                r.parameters
                    .iter()
                    .find(|q| q.variable == p.variable && q.unit == p.unit)
                    .cloned()
            };
            let mut values: Vec<Option<f64>> = history
                .iter()
                .map(|r| find(r).map(|q| q.identified))
                .collect();
            let mut std_errors: Vec<Option<f64>> = history
                .iter()
                .map(|r| find(r).and_then(|q| q.std_error))
                .collect();
            values.push(Some(p.identified));
            std_errors.push(p.std_error);
            let deviation_sigma = match (values[b], std_errors[b], p.std_error) {
                (Some(xb), Some(sb), Some(s)) if (sb * sb + s * s) > 0.0 => {
                    Some((p.identified - xb) / (sb * sb + s * s).sqrt())
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
