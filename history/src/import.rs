//! Import of the dated report folders that nightly runs wrote before the history existed: each
//! `*/report.json` (schema `ident.report/1`, `docs/report-json.md`) becomes one run named after its
//! folder. Only the fields the history needs are read, so reports of older and newer schemas
//! import alike; a run already stored is skipped, so an import can be repeated.

use std::path::Path;

use serde::Deserialize;

use crate::error::HistoryError;
use crate::record::{model_hash, unit_factor, CharacteristicFit, ParameterRecord, RunRecord};
use crate::store::Store;

#[derive(Deserialize)]
struct Report {
    created_utc: String,
    source: Source,
    status: Status,
    identification: Option<Identification>,
    #[serde(default)]
    characteristics: Vec<Characteristic>,
    diagnosis: Option<Diagnosis>,
}
#[derive(Deserialize)]
struct Source {
    session: Option<String>,
    stand: Option<String>,
    model: String,
}
#[derive(Deserialize)]
struct Status {
    outcome: String,
}
#[derive(Deserialize)]
struct Identification {
    reduced_chi2: Option<f64>,
    parameters: Vec<Parameter>,
}
#[derive(Deserialize)]
struct Parameter {
    variable: String,
    unit: String,
    identified: f64,
    std_error: Option<f64>,
}
#[derive(Deserialize)]
struct Characteristic {
    label: String,
    #[serde(default)]
    stages: Vec<Stage>,
}
#[derive(Deserialize)]
struct Stage {
    stage: String,
    rms_relative_error: f64,
}
#[derive(Deserialize)]
struct Diagnosis {
    #[serde(default)]
    candidates: Vec<Candidate>,
    #[serde(default)]
    final_parameters: Vec<Parameter>,
    after: Option<After>,
}
#[derive(Deserialize)]
struct Candidate {
    name: String,
    location: String,
    accepted: bool,
}
#[derive(Deserialize)]
struct After {
    reduced_chi2: Option<f64>,
}

/// What an import did.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct ImportSummary {
    /// Runs appended.
    pub imported: usize,
    /// Runs already in the history.
    pub already_stored: usize,
    /// Reports left out, one sentence each (unreadable, not a report).
    pub skipped: Vec<String>,
}

/// The run a `report.json` describes, named `run_id`. The model hash is that of the model file the
/// report names when it can still be read, else `path:` and its name (such runs compare only with
/// each other).
pub fn run_from_report(path: &Path, run_id: &str) -> Result<RunRecord, HistoryError> {
    let text = std::fs::read_to_string(path).map_err(|e| HistoryError::Import {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })?;
    run_from_report_text(&text, path, run_id)
}

/// [`run_from_report`] of a report's JSON text (`path` names it in errors): a nightly records
/// the report it is about to write.
pub fn run_from_report_text(
    text: &str,
    path: &Path,
    run_id: &str,
) -> Result<RunRecord, HistoryError> {
    let bad = |detail: String| HistoryError::Import {
        path: path.to_path_buf(),
        detail,
    };
    let r: Report = serde_json::from_str(text)
        .map_err(|e| bad(format!("line {}: {e}; not an ident report", e.line())))?;
    let hash = std::fs::read(&r.source.model)
        .map(|b| model_hash(&b))
        .unwrap_or_else(|_| format!("path:{}", r.source.model));
    let diag = r.diagnosis.as_ref();
    let table = match diag {
        Some(d) if !d.final_parameters.is_empty() => &d.final_parameters,
        _ => match &r.identification {
            Some(i) => &i.parameters,
            None => &Vec::new(),
        },
    };
    let parameters = table
        .iter()
        .map(|p| {
            let f = unit_factor(&p.unit).ok_or_else(|| {
                bad(format!(
                    "parameter {}: unit \"{}\" is not a stiffness, contact stiffness or pure number unit",
                    p.variable, p.unit
                ))
            })?;
            Ok(ParameterRecord {
                variable: p.variable.clone(),
                unit: p.unit.clone(),
                unit_factor: f,
                estimate: p.identified * f,
                std_error: p.std_error.map(|s| s * f),
            })
        })
        .collect::<Result<Vec<_>, HistoryError>>()?;
    let final_stage = if diag.is_some() {
        "diagnosed"
    } else {
        "identified"
    };
    let characteristics = r
        .characteristics
        .iter()
        .filter_map(|c| {
            let s = c
                .stages
                .iter()
                .find(|s| s.stage == final_stage)
                .or_else(|| c.stages.iter().find(|s| s.stage == "identified"))?;
            Some(CharacteristicFit {
                label: c.label.clone(),
                rms_relative_error: s.rms_relative_error,
            })
        })
        .collect();
    Ok(RunRecord {
        run_id: run_id.to_string(),
        time_utc: r.created_utc,
        stand: r.source.stand,
        model_hash: hash,
        session: r.source.session,
        outcome: r.status.outcome,
        reduced_chi2: diag
            .and_then(|d| d.after.as_ref())
            .and_then(|a| a.reduced_chi2)
            .or(r.identification.as_ref().and_then(|i| i.reduced_chi2)),
        parameters,
        characteristics,
        effects: diag
            .map(|d| {
                d.candidates
                    .iter()
                    .filter(|c| c.accepted)
                    .map(|c| format!("{} {}", c.name, c.location))
                    .collect()
            })
            .unwrap_or_default(),
        covariates: Vec::new(),
    })
}

/// Imports every `*/report.json` under `reports` (one sub-folder per run), oldest folder name
/// first. Reports that cannot be read are listed in the summary, never fatal; a database error is.
pub fn import_reports(store: &mut Store, reports: &Path) -> Result<ImportSummary, HistoryError> {
    let mut summary = ImportSummary::default();
    let entries = std::fs::read_dir(reports).map_err(|e| HistoryError::Import {
        path: reports.to_path_buf(),
        detail: format!("cannot read the report folder: {e}"),
    })?;
    let mut folders: Vec<_> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.join("report.json").is_file())
        .collect();
    folders.sort();
    for f in folders {
        let run_id = f
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if store.contains(&run_id)? {
            summary.already_stored += 1;
            continue;
        }
        match run_from_report(&f.join("report.json"), &run_id) {
            Ok(run) => {
                store.append(&run)?;
                summary.imported += 1;
            }
            Err(e) => summary.skipped.push(format!("{e}; left out")),
        }
    }
    Ok(summary)
}
