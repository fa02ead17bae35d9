//! The report of a run and its folder: [`build_report`] (the `report` document of an
//! identification and its diagnosis, with the run's provenance), [`write_report`] (the dated
//! folder's files: HTML, JSON, the identification's table and models, the final model and the
//! next variables file), [`dated_folder`] (a new folder per run).

use std::path::{Path, PathBuf};

use identify::{report as table, Identification, Observations};
use rfe::Model;

use crate::analysis::Analysis;
use crate::error::PipelineError;
use crate::setup::Setup;

/// Provenance and context of a report.
pub struct ReportContext<'a> {
    /// Headline.
    pub title: &'a str,
    /// `demo`, `replay`, `nightly`.
    pub workflow: &'a str,
    /// Stand name or file.
    pub stand: Option<String>,
    /// Drift history, when there is one.
    pub drift: Option<report::Drift>,
    /// Extra status messages.
    pub messages: Vec<String>,
    /// Time stamp (UTC, ISO 8601); empty = now.
    pub created_utc: String,
}

/// Builds the report (`report::build`) of an identification and, when it ran, its diagnosis
/// (the section and the final model): `ctx` gives the headline, workflow, stand, drift, messages
/// and time stamp, `source` the files (its `workflow`, `stand` and `software` are filled here).
/// Shared by the workflows' report folders and `ident identify|diagnose --out`.
pub fn build_report(
    ctx: ReportContext<'_>,
    source: report::document::Source,
    observations: &Observations,
    id: &Identification,
    diagnosis: Option<(report::Diagnosis, &Model)>,
) -> Result<report::Report, PipelineError> {
    let mut inputs = report::build::Inputs::new(ctx.title, observations, id);
    inputs.source = report::document::Source {
        workflow: ctx.workflow.into(),
        stand: ctx.stand,
        software: inputs.source.software,
        ..source
    };
    inputs.diagnosis = diagnosis;
    inputs.drift = ctx.drift;
    inputs.created_utc = ctx.created_utc;
    inputs.messages = ctx.messages;
    let started = std::time::Instant::now();
    let r = report::build::build(inputs)?;
    tracing::info!(seconds = started.elapsed().as_secs_f64(), "report built");
    Ok(r)
}

/// Builds the report and writes the report folder: `report.html`, `report.json`,
/// `measured.json`, `identification.json`, `identification.csv`, `identified-model.json`, for TOML
/// models `identified-model.toml` (the first fit), when diagnosis ran `diagnosis.json`
/// (docs/diagnosis.md) and `diagnosed-model.json` (the identified model with the accepted
/// effects), and `final-model.toml` (the final model in the model format) with
/// `final-variables.toml` (the variables for the next run against it).
pub fn write_report(
    dir: &Path,
    ctx: ReportContext<'_>,
    setup: &Setup,
    a: &Analysis,
) -> Result<(report::Report, report::Written), PipelineError> {
    let id = &a.identification;
    let ctx = ReportContext {
        stand: ctx.stand.or_else(|| Some(a.session.stand.clone())),
        messages: a.messages.iter().cloned().chain(ctx.messages).collect(),
        ..ctx
    };
    let source = report::document::Source {
        session: Some(a.session.session.clone()),
        model: setup.model_file.clone(),
        variables: setup.vars_file.clone(),
        measurement: a.session.measured.source.clone(),
        ..report::document::Source::default()
    };
    let diagnosis = a
        .diagnosis
        .as_ref()
        .map(|(d, full)| (d.clone(), &full.model));
    let r = build_report(ctx, source, &a.problem.observations, id, diagnosis)?;
    let w = |name: &str, text: &str| report::write_atomic(&dir.join(name), text.as_bytes());
    w(
        "measured.json",
        &serde_json::to_string_pretty(&a.session.measured)?,
    )?;
    w(
        "identification.json",
        &serde_json::to_string_pretty(&table::json(id))?,
    )?;
    w("identification.csv", &table::csv(id))?;
    w(
        "identified-model.json",
        &serde_json::to_string_pretty(&rfe::contract::to_json(&id.model))?,
    )?;
    if let Some((_, d)) = &a.diagnosis {
        w("diagnosis.json", &serde_json::to_string_pretty(d)?)?;
        w(
            "diagnosed-model.json",
            &serde_json::to_string_pretty(&rfe::contract::to_json(&d.model))?,
        )?;
    }
    if let Some(text) = &setup.model_text {
        match table::update_toml(text, &setup.model_file, id) {
            Ok(updated) => w(
                "identified-model.toml",
                &format!("# The FIRST fit (before diagnosis) written back into the model's text. When the\n# diagnosis added an effect this fit is superseded: the final model is final-model.toml.\n\n{updated}"),
            )?,
            Err(e) => tracing::warn!("identified-model.toml not written: {e}"),
        }
    }
    let final_files = final_files(setup, a).and_then(|(model, vars)| {
        Ok((
            w("final-model.toml", &model)?,
            w("final-variables.toml", &vars)?,
        ))
    });
    if let Err(e) = final_files {
        tracing::warn!("final-model.toml not written: {}", chain(&e));
    }
    let written = report::write(&r, dir)?;
    Ok((r, written))
}

/// `e` and its sources, `: `-separated (as a log line reads best).
fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut source = e.source();
    while let Some(cause) = source {
        s.push_str(": ");
        s.push_str(&cause.to_string());
        source = cause.source();
    }
    s
}

/// The final model as TOML and the variables file for the next run (`diagnose::final_model`):
/// the diagnosis's final fit when it ran, else the identification's.
pub fn final_files(setup: &Setup, a: &Analysis) -> Result<(String, String), PipelineError> {
    let id = &a.identification;
    let d = a.diagnosis.as_ref().map(|(_, d)| d);
    let source = diagnose::final_model::Source {
        origin: &setup.model_file,
        text: setup.model_text.as_deref(),
    };
    let model = diagnose::final_model::model_toml(source, id, d)?;
    let vars = diagnose::final_model::variables_toml("final-model.toml", id, d)?;
    Ok((model, vars))
}

/// A folder name for a run: `PREFIX-YYYY-mm-ddTHHMMSSZ` (UTC), made unique with `-2`, `-3`...
pub fn dated_folder(parent: &Path, prefix: &str) -> Result<PathBuf, PipelineError> {
    let stamp = report::build::now_utc().replace(':', "");
    let base = if prefix.is_empty() {
        stamp
    } else {
        format!("{prefix}-{stamp}")
    };
    std::fs::create_dir_all(parent).map_err(|source| PipelineError::Folder {
        path: parent.to_path_buf(),
        source,
    })?;
    let mut k = 1;
    loop {
        let p = if k == 1 {
            parent.join(&base)
        } else {
            parent.join(format!("{base}-{k}"))
        };
        match std::fs::create_dir(&p) {
            Ok(()) => return Ok(p),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => k += 1,
            Err(source) => return Err(PipelineError::ReportFolder { path: p, source }),
        }
    }
}
