//! Runs from reports: a `report.json` (the [`report::Report`] type, schema `ident.report/1`,
//! `docs/report-json.md`) becomes one run record, and a folder of dated report folders (each
//! `*/report.json`) becomes the history; a run already stored is skipped, so an import can be
//! repeated.
//!
//! The model identity of an imported run does not depend on where the import runs: the model
//! file the report names is looked for as written when absolute, else beside the report and in
//! each folder above it (the report folder, the reports folder, the job's folder); its bytes'
//! hash is the identity. A model file that cannot be found gives the identity `file:NAME` (its
//! file name, never its path), and the import warns with both identities when runs of one
//! import disagree.

use std::path::{Path, PathBuf};

use report::Report;

use crate::error::HistoryError;
use crate::record::{
    model_hash, unit_factor, CharacteristicFit, Correlation, ParameterRecord, RunRecord,
};
use crate::store::Store;

/// What an import did.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct ImportSummary {
    /// Runs appended.
    pub imported: usize,
    /// Runs already in the history.
    pub already_stored: usize,
    /// Reports left out, one sentence each (unreadable, not a report).
    pub skipped: Vec<String>,
    /// Warnings (runs whose model identity differs from the rest).
    pub warnings: Vec<String>,
}

/// The run a `report.json` describes, named `run_id`.
pub fn run_from_report(path: &Path, run_id: &str) -> Result<RunRecord, HistoryError> {
    let text = std::fs::read_to_string(path).map_err(|e| HistoryError::Import {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })?;
    run_from_report_text(&text, path, run_id)
}

/// [`run_from_report`] of a report's JSON text (`path` names it in errors and anchors a
/// relative model path): a nightly records the report it is about to write.
pub fn run_from_report_text(
    text: &str,
    path: &Path,
    run_id: &str,
) -> Result<RunRecord, HistoryError> {
    let r: Report = serde_json::from_str(text).map_err(|e| HistoryError::Import {
        path: path.to_path_buf(),
        detail: explain_parse_error(text, &e),
    })?;
    run_from_document(&r, path, run_id)
}

/// Why a report did not parse, naming the parameter and field where the parser stopped and
/// the fix.
fn explain_parse_error(text: &str, e: &serde_json::Error) -> String {
    let mut offset = offset_of(text, e.line(), e.column()).min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let field = last_key(before);
    let variable = last_string_value(before, "\"variable\"");
    let at = format!("line {} column {}", e.line(), e.column());
    match (variable, field) {
        (Some(v), Some(f)) if is_number_field(&f) => format!(
            "parameter {v}, field \"{f}\" ({at}): {e}; the value is not a JSON number (NaN or infinite: the run did not determine this parameter): re-run that night's identification, or move its folder out of the reports folder so the import leaves it out"
        ),
        (_, Some(f)) => format!(
            "field \"{f}\" ({at}): {e}; not an {} report this ident reads: re-write it with this ident, or move its folder out of the reports folder",
            report::SCHEMA
        ),
        _ => format!(
            "{at}: {e}; not an {} report: move its folder out of the reports folder",
            report::SCHEMA
        ),
    }
}

fn is_number_field(f: &str) -> bool {
    matches!(
        f,
        "identified" | "initial" | "std_error" | "variability" | "estimate" | "reduced_chi2"
    )
}

/// Byte offset of 1-based `line`, `column`.
fn offset_of(text: &str, line: usize, column: usize) -> usize {
    let mut off = 0;
    for (i, l) in text.split_inclusive('\n').enumerate() {
        if i + 1 == line {
            return off + column.min(l.len());
        }
        off += l.len();
    }
    text.len()
}

/// The last `"key":` before the end of `before`.
fn last_key(before: &str) -> Option<String> {
    let colon = before.rfind("\":")?;
    let start = before[..colon].rfind('"')?;
    Some(before[start + 1..colon].to_string())
}

/// The string value of the last `key` before the end of `before`.
fn last_string_value(before: &str, key: &str) -> Option<String> {
    let k = before.rfind(key)?;
    let rest = before[k + key.len()..].trim_start().strip_prefix(':')?;
    let rest = rest.trim_start().strip_prefix('"')?;
    Some(rest[..rest.find('"')?].to_string())
}

/// The model file a report names, found independently of the current directory: as written
/// when absolute, else relative to the report's folder and each folder above it.
pub fn find_model(report_path: &Path, model: &str) -> Option<PathBuf> {
    let m = Path::new(model);
    if m.is_absolute() {
        return m.is_file().then(|| m.to_path_buf());
    }
    report_path
        .ancestors()
        .skip(1)
        .map(|dir| dir.join(m))
        .find(|p| p.is_file())
}

/// The model identity of a report: the hash of its model file's bytes ([`find_model`]), else
/// `file:` and the model's file name.
pub fn model_identity(report_path: &Path, model: &str) -> String {
    find_model(report_path, model)
        .and_then(|p| std::fs::read(p).ok())
        .map(|b| model_hash(&b))
        .unwrap_or_else(|| {
            let name = Path::new(model)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| model.to_string());
            format!("file:{name}")
        })
}

/// The run a report document describes (`path`: where the report is or will be written).
pub fn run_from_document(r: &Report, path: &Path, run_id: &str) -> Result<RunRecord, HistoryError> {
    let bad = |detail: String| HistoryError::Import {
        path: path.to_path_buf(),
        detail,
    };
    let diag = r.diagnosis.as_ref();
    let from_diagnosis = diag.is_some_and(|d| !d.final_parameters.is_empty());
    let table = match diag {
        Some(d) if from_diagnosis => &d.final_parameters,
        _ => &r.identification.parameters,
    };
    let parameters = table
        .iter()
        .map(|p| {
            let f = unit_factor(&p.unit).ok_or_else(|| {
                bad(format!(
                    "parameter {}: unit \"{}\" is not a stiffness, contact stiffness or pure number unit; fix the unit in the decision-variables file and re-run",
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
    // The Cramér-Rao correlations belong to the identification's table; after diagnosis added
    // an effect the final table is another fit's.
    let correlations = if from_diagnosis {
        Vec::new()
    } else {
        correlations(&r.identification)
    };
    let quantities = r.stability.iter().map(stable_depth).collect();
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
        time_utc: r.created_utc.clone(),
        stand: r.source.stand.clone(),
        model_hash: model_identity(path, &r.source.model),
        session: r.source.session.clone(),
        outcome: r.status.outcome.as_str().to_string(),
        reduced_chi2: diag
            .map(|d| d.after.reduced_chi2)
            .or(Some(r.identification.reduced_chi2))
            .filter(|c| c.is_finite()),
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
        correlations,
        quantities,
    })
}

/// The judged quantity of a report's stability section: the minimum critical depth over the
/// cut's speed range (mm), its σ from the linear band (`null` without one).
pub fn stable_depth(s: &stability::section::Stability) -> ParameterRecord {
    ParameterRecord {
        variable: s.quantity_name(),
        unit: "mm".into(),
        unit_factor: 1e-3,
        estimate: s.minimum.depth_mm * 1e-3,
        std_error: s.minimum.sigma_mm.map(|v| v * 1e-3),
    }
}

/// Each pair of the identification's correlation matrix once (finite values only).
fn correlations(id: &report::document::IdentificationSummary) -> Vec<Correlation> {
    let names: Vec<&str> = id.parameters.iter().map(|p| p.variable.as_str()).collect();
    let mut out = Vec::new();
    for (a, row) in id.correlation.iter().enumerate() {
        for (b, v) in row.iter().enumerate().skip(a + 1) {
            if let (Some(v), Some(na), Some(nb)) = (v, names.get(a), names.get(b)) {
                if v.is_finite() {
                    out.push(Correlation {
                        a: (*na).into(),
                        b: (*nb).into(),
                        value: *v,
                    });
                }
            }
        }
    }
    out
}

/// The runs of every `*/report.json` under `reports` (one sub-folder per run, named after it),
/// oldest folder name first, without a database; reports that cannot be read are listed in the
/// summary's `skipped`.
pub fn runs_from_reports(reports: &Path) -> Result<(Vec<RunRecord>, ImportSummary), HistoryError> {
    let mut summary = ImportSummary::default();
    let mut runs = Vec::new();
    for f in report_folders(reports)? {
        let run_id = folder_name(&f);
        match run_from_report(&f.join("report.json"), &run_id) {
            Ok(run) => runs.push(run),
            Err(e) => summary.skipped.push(format!("{e}; left out")),
        }
    }
    runs.sort_by(|a, b| a.time_utc.cmp(&b.time_utc).then(a.run_id.cmp(&b.run_id)));
    summary.warnings = identity_warnings(&runs);
    Ok((runs, summary))
}

fn report_folders(reports: &Path) -> Result<Vec<PathBuf>, HistoryError> {
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
    Ok(folders)
}

fn folder_name(f: &Path) -> String {
    f.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// A warning for each run whose model identity differs from the run before it, naming both.
fn identity_warnings(runs: &[RunRecord]) -> Vec<String> {
    runs.windows(2)
        .filter(|w| w[0].model_hash != w[1].model_hash)
        .map(|w| {
            format!(
                "run {} has model identity {} but run {} before it has {}: runs of different identities are never compared (a changed model file, or a model file not found from here: identities starting with file: are file names)",
                w[1].run_id, w[1].model_hash, w[0].run_id, w[0].model_hash
            )
        })
        .collect()
}

/// Imports every `*/report.json` under `reports` (one sub-folder per run), oldest folder name
/// first. Reports that cannot be read are listed in the summary, never fatal; a database error is.
pub fn import_reports(store: &mut Store, reports: &Path) -> Result<ImportSummary, HistoryError> {
    let mut summary = ImportSummary::default();
    let mut imported = Vec::new();
    for f in report_folders(reports)? {
        let run_id = folder_name(&f);
        if store.contains(&run_id)? {
            summary.already_stored += 1;
            continue;
        }
        match run_from_report(&f.join("report.json"), &run_id) {
            Ok(run) => {
                store.append(&run)?;
                summary.imported += 1;
                imported.push(run);
            }
            Err(e) => summary.skipped.push(format!("{e}; left out")),
        }
    }
    summary.warnings = identity_warnings(&imported);
    Ok(summary)
}
