//! The operator workflows' steps, shared by `ident demo`, `ident replay` and `ident nightly`:
//!
//! ```text
//! sweep (stand → session.mcap) → process (session → characteristics) → identify → diagnose → report
//! ```
//!
//! Everything after the sweep reads only the session file ([`analyse`]), so a replay of a
//! recording recomputes the live run's results bit for bit.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use acquire::analysis::{characteristics, AnalysisOptions, SessionAnalysis};
use acquire::rig::Rig;
use acquire::session::{Session, SessionHandle, SessionOptions};
use acquire::sim::SimStand;
use acquire::stand::{PortSpec, Stand};
use acquire::sweep::{
    self, Broadband, BroadbandResult, SteppedSine, StopSignal, SweepError, SweepOutcome,
    SweepProgress,
};
use anyhow::Context;
use identify::{self, data, report as table, variables, Identification, Observations, Variables};
use rfe::Model;

/// The identification set-up: the model to identify (never the truth) and its decision variables.
#[derive(Debug, Clone)]
pub struct Setup {
    /// Model file (for messages and the report).
    pub model_file: String,
    /// Its text, for writing the identified values back (TOML models only).
    pub model_text: Option<String>,
    /// The model.
    pub model: Model,
    /// Variables file.
    pub vars_file: String,
    /// The decision variables.
    pub vars: Variables,
}

impl Setup {
    /// Loads a model (TOML or resolved JSON) and a variables file.
    pub fn load(model: &Path, vars: &Path) -> anyhow::Result<Setup> {
        let m = crate::commands::load_model(model)?;
        let v = variables::load(vars, &m)?;
        let text = std::fs::read_to_string(model)
            .ok()
            .filter(|_| model.extension().is_some_and(|e| e == "toml"));
        Ok(Setup {
            model_file: model.display().to_string(),
            model_text: text,
            model: m,
            vars_file: vars.display().to_string(),
            vars: v,
        })
    }

    /// The model's name for reports: its file name without extension.
    pub fn model_name(&self) -> String {
        Path::new(&self.model_file)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| self.model_file.clone())
    }
}

/// A sweep that ended, completely or not.
#[derive(Debug)]
pub struct Swept {
    /// The session file (complete and readable even when the sweep failed).
    pub session: PathBuf,
    /// Steps planned.
    pub planned: usize,
    /// The sweep's outcome, or why it failed (device, plan, disk).
    pub outcome: Result<SweepOutcome, String>,
    /// Messages in the completed session file.
    pub messages: u64,
    /// Why the session file could not be completed (its flushed chunks are still readable:
    /// `ident mcap recover`).
    pub finish_error: Option<String>,
}

/// Where a sweep goes beyond its plan.
#[derive(Debug, Default)]
pub struct SweepOptions<'a> {
    /// Serve the simulated DAQ on this CAN interface instead of a pseudo-terminal.
    pub can: Option<&'a str>,
    /// The earlier session this one continues (recorded in the session start).
    pub resume: Option<&'a Path>,
    /// Steps the earlier session completed (skipped here).
    pub done: BTreeSet<usize>,
    /// Ctrl-C stops the sweep after the current step (the file is still completed).
    pub ctrl_c: bool,
}

/// The async runtime the device drivers run on (two worker threads: the sweep and the simulated
/// stand's devices).
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

/// What stops a sweep: Ctrl-C when the options ask for it, else only the sweep's own end.
fn stop_signal(opts: &SweepOptions<'_>) -> StopSignal {
    if opts.ctrl_c {
        StopSignal::on_ctrl_c()
    } else {
        StopSignal::new()
    }
}

/// Creates the session file every signal of the sweep goes into, and says where.
fn record(session: &Path) -> anyhow::Result<Session> {
    let file = Session::create(session, SessionOptions::default())
        .with_context(|| format!("cannot create the session file {}", session.display()))?;
    eprintln!("recording {}", session.display());
    Ok(file)
}

/// Runs a stepped-sine sweep of `stand` into a new session file at `session`. Ports given as
/// `"sim"` are served by the simulated stand (announced on stderr). The session file is kept
/// whatever happens; only failures before it exists are `Err`.
pub fn sweep(
    stand: &Stand,
    plan: &SteppedSine,
    session: &Path,
    opts: &SweepOptions<'_>,
    progress: &dyn SweepProgress,
) -> anyhow::Result<Swept> {
    let planned = plan.frequencies.frequencies()?.len();
    let r = recorded(stand, plan, session, opts, async |rig, h, stop| {
        sweep::stepped_sine(rig, plan, h, progress, stop, &opts.done).await
    })?;
    Ok(Swept {
        session: session.to_path_buf(),
        planned,
        outcome: r.outcome,
        messages: r.messages,
        finish_error: r.finish_error,
    })
}

/// A measurement that ended, completely or not, with its session file.
struct Recorded<T> {
    outcome: Result<T, String>,
    messages: u64,
    finish_error: Option<String>,
}

/// Runs `measure` (of `plan`, recorded in the session start) on `stand`'s rig, its `"sim"` ports
/// served by the simulated stand, into a new session file at `session`, completed whatever
/// happens; only failures before it exists are `Err`.
fn recorded<T>(
    stand: &Stand,
    plan: &impl serde::Serialize,
    session: &Path,
    opts: &SweepOptions<'_>,
    measure: impl AsyncFnOnce(&mut Rig, &SessionHandle, &StopSignal) -> Result<T, SweepError>,
) -> anyhow::Result<Recorded<T>> {
    let rt = runtime()?;
    rt.block_on(async {
        // The Ctrl-C handler needs the runtime.
        let stop = stop_signal(opts);
        let (sim, bound) = start_sim(stand, opts.can)?;
        let file = record(session)?;
        let h = file.handle();
        let outcome = async {
            sweep::log_session_start(&h, &stand.file, plan, opts.resume, &opts.done)?;
            let mut rig = Rig::connect(&bound, Some(&h)).await?;
            if let Some(s) = &sim {
                // Settling counts from the stream the simulator has produced.
                rig = s.clock_rig(rig);
            }
            Ok::<_, anyhow::Error>(measure(&mut rig, &h, &stop).await?)
        }
        .await
        .map_err(|e| format!("{e:#}"));
        let (messages, finish_error) = match file.finish() {
            Ok(summary) => (summary.total(), None),
            Err(e) => (0, Some(e.to_string())),
        };
        if let Some(s) = sim {
            s.shutdown();
        }
        Ok(Recorded {
            outcome,
            messages,
            finish_error,
        })
    })
}

/// The simulated stand serving `stand`'s `"sim"` ports (announced on stderr; its DAQ on CAN with
/// `can`), and the stand bound to them. Call inside the runtime.
fn start_sim(stand: &Stand, can: Option<&str>) -> anyhow::Result<(Option<SimStand>, Stand)> {
    let uses_sim = stand.shaker.port == PortSpec::Sim || stand.daq.port == PortSpec::Sim;
    let sim = match (uses_sim, can) {
        (true, Some(iface)) => Some(SimStand::start_can(stand, iface)?),
        (true, None) => Some(SimStand::start(stand)?),
        (false, Some(_)) => anyhow::bail!(
            "the CAN interface serves the simulated DAQ; {} has no port = \"sim\" (give daq.port = \"can:IFACE\" for a real CAN DAQ)",
            stand.file
        ),
        (false, None) => None,
    };
    let bound = match &sim {
        Some(s) => {
            let speed = stand.truth.as_ref().map(|t| t.speed).unwrap_or(1.0);
            let exciter = if stand.generator.is_some() {
                "generator"
            } else {
                "shaker"
            };
            eprintln!(
                "simulated stand at {speed}× real time: {exciter} {}, daq {}",
                s.shaker_port, s.daq_port
            );
            s.bind(stand)
        }
        None => stand.clone(),
    };
    Ok((sim, bound))
}

/// A broadband measurement that ended, completely or not.
#[derive(Debug)]
pub struct BroadbandSwept {
    /// The estimate, or why the measurement failed.
    pub outcome: Result<BroadbandResult, String>,
    /// Messages in the completed session file.
    pub messages: u64,
    /// Why the session file could not be completed.
    pub finish_error: Option<String>,
}

/// Runs a broadband measurement (`stand`'s `[broadband]` plan) into a new session file, like
/// [`sweep()`] does a stepped sine (`opts.resume` and `opts.done` are for stepped sines: leave them
/// empty).
pub fn broadband_sweep(
    stand: &Stand,
    plan: &Broadband,
    session: &Path,
    opts: &SweepOptions<'_>,
    progress: &dyn SweepProgress,
) -> anyhow::Result<BroadbandSwept> {
    let r = recorded(stand, plan, session, opts, async |rig, h, stop| {
        sweep::broadband(rig, plan, h, progress, stop).await
    })?;
    Ok(BroadbandSwept {
        outcome: r.outcome,
        messages: r.messages,
        finish_error: r.finish_error,
    })
}

/// How the workflows identify: the library's defaults with four starts. From Table 1's initial
/// values alone, the 19-variable fit of the demo's model (which lacks the actuator) lands in a poor
/// local minimum for about one sweep in five — data that differ by under 1 % send it there (a
/// criterion 38× the good minimum's); three more starts spread over the bounds find the good
/// minimum (0.24 s instead of 0.1 s in release).
pub fn identification_options() -> identify::Options {
    identify::Options {
        starts: 4,
        ..identify::Options::default()
    }
}

/// Results of processing, identification and diagnosis of one session.
#[derive(Debug)]
pub struct Analysis {
    /// The session's characteristics, steps, dropped steps and faults.
    pub session: SessionAnalysis,
    /// The characteristics validated against the identification model.
    pub observations: Observations,
    /// The identification.
    pub identification: Identification,
    /// The diagnosis (its report section, and the full result with the final model), when it ran.
    pub diagnosis: Option<(report::Diagnosis, diagnose::Diagnosis)>,
    /// What the operator should know: data not used, faults, truncation, non-convergence.
    pub messages: Vec<String>,
}

/// Process → identify → diagnose, from the session file alone (deterministic: a replay of the same
/// file gives bit-identical results). A diagnosis that cannot run is a message, not a failure: the
/// identification is still reported.
pub fn analyse(
    session: &Path,
    setup: &Setup,
    opts: &identify::Options,
) -> anyhow::Result<Analysis> {
    let a = characteristics(session, &AnalysisOptions::default())?;
    let mut messages = a.messages();
    let obs = data::validate(&a.measured, &setup.model, &session.display().to_string())?;
    let id = identify::identify(&setup.model, &obs, &setup.vars, opts, &mut |_, p| {
        tracing::info!(?p, "iteration")
    })?;
    // The score test projects the fit's own directions out of the residual, so it ranks candidates
    // from the best point of an identification that hit its iteration limit too; the refits then
    // free every variable again.
    if !id.stop.converged() {
        messages.push(
            "diagnosis started from the best point of the identification, which did not converge"
                .into(),
        );
    }
    let diagnosis = {
        let dopts = diagnose::Options {
            identification: *opts,
            ..diagnose::Options::default()
        };
        match diagnose::diagnose(&setup.model, &obs, &setup.vars, &id, &dopts, &mut |line| {
            tracing::info!("diagnose: {line}")
        }) {
            Ok(d) => Some((report::build::diagnosis(&d, &setup.model_name(), &id), d)),
            Err(e) => {
                messages.push(format!("diagnosis not run: {e}"));
                None
            }
        }
    };
    Ok(Analysis {
        session: a,
        observations: obs,
        identification: id,
        diagnosis,
        messages,
    })
}

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
) -> anyhow::Result<report::Report> {
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
) -> anyhow::Result<(report::Report, report::Written)> {
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
    let r = build_report(ctx, source, &a.observations, id, diagnosis)?;
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
        tracing::warn!("final-model.toml not written: {e:#}");
    }
    let written = report::write(&r, dir)?;
    Ok((r, written))
}

/// The final model as TOML and the variables file for the next run (`diagnose::final_model`):
/// the diagnosis's final fit when it ran, else the identification's.
pub fn final_files(setup: &Setup, a: &Analysis) -> anyhow::Result<(String, String)> {
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

/// The Table-1-like summary printed by the workflows.
pub fn summary_text(a: &Analysis) -> String {
    let mut s = table::text(&a.identification);
    match &a.diagnosis {
        Some((_, d)) => {
            s.push('\n');
            s.push_str(&diagnose::text(d));
            s.push('\n');
            s.push_str(&diagnose::final_text(&a.identification, d));
        }
        None => s.push_str("\ndiagnosis: not run (see the notes)\n"),
    }
    s
}

/// A folder name for a run: `PREFIX-YYYY-mm-ddTHHMMSSZ` (UTC), made unique with `-2`, `-3`...
pub fn dated_folder(parent: &Path, prefix: &str) -> anyhow::Result<PathBuf> {
    let stamp = report::build::now_utc().replace(':', "");
    let base = if prefix.is_empty() {
        stamp
    } else {
        format!("{prefix}-{stamp}")
    };
    std::fs::create_dir_all(parent)
        .with_context(|| format!("cannot create {}", parent.display()))?;
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
            Err(e) => {
                return Err(e)
                    .with_context(|| format!("cannot create the report folder {}", p.display()))
            }
        }
    }
}
