//! `ident identify MODEL --data DATA --vars VARS`: maximum-likelihood identification of SDE
//! parameters, body masses and inertias, and sensor gains with Cramér-Rao errors
//! (docs/identification.md).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use identify::request::{self, DataRequest, Request, Start};
use identify::{
    self as idn, report, FitKind, JacobianMode, NoiseChoice, Optimizer, Options, Settings,
};

use super::{emit, MethodArg};
use pipeline::{build_report, ReportContext};

/// `--method`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default)]
pub enum OptimizerArg {
    /// Bounded Levenberg-Marquardt (default).
    #[default]
    Lm,
    /// Gauss-Newton with line search (paper eq. 4.12-4.13).
    Gn,
    /// BFGS variable metric with a Wolfe line search.
    Bfgs,
}

/// `--start`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StartArg {
    /// For data without variances or coherence (vendor files: the log-amplitude fit), the
    /// variables file's start and the modal pre-fit's both, the better fit kept; otherwise the
    /// variables file's start.
    #[default]
    Auto,
    /// The variables file's initial values (else the model's).
    Model,
    /// Moved from there by a modal pre-fit to the modes extracted from the data (frequencies
    /// matched, ψ from the loss factors; `identify::modal_start`).
    Modal,
}

/// `--fit`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default)]
pub enum FitArg {
    /// Log-amplitude where the data have no variances or coherence (σ known only relative to
    /// the level), amplitude otherwise.
    #[default]
    Auto,
    /// Amplitudes only (the paper's A-F characteristics).
    Amplitude,
    /// Log-amplitudes, residual ln|z| − ln|q| (a misplaced resonance costs as much as a model
    /// too low everywhere).
    LogAmplitude,
    /// Real and imaginary parts (needs phases).
    Complex,
}

/// `--noise`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default)]
pub enum NoiseArg {
    /// Variances if given, else coherence + averages, else relative.
    #[default]
    Auto,
    /// The data's variances.
    Variance,
    /// H1 variance from coherence and averages.
    Coherence,
    /// σ = ε·|z| (--relative-error).
    Relative,
}

/// `--format`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default)]
pub enum FormatArg {
    /// Human-readable report.
    #[default]
    Text,
    /// JSON report.
    Json,
    /// The table as CSV.
    Csv,
}

/// Arguments of `ident identify`.
#[derive(clap::Args)]
pub struct IdentifyArgs {
    /// Model file (TOML or resolved JSON).
    pub model: PathBuf,
    /// Measured data: JSON `MeasuredData`, CSV (optionally declaring its unit), or UFF58/58b
    /// with --map (docs/identification.md).
    #[arg(long)]
    pub data: PathBuf,
    /// Measurement map (TOML): which UFF node and direction is which body and DOF of the model.
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Decision variables (TOML; docs/identification.md).
    #[arg(long)]
    pub vars: PathBuf,
    /// Fit only the lines in this band, `LO:HI` in Hz (either side may be empty: `20:`, `:400`).
    #[arg(long, value_parser = parse_band)]
    pub band: Option<(Option<f64>, Option<f64>)>,
    /// Drop the lines near these frequencies (Hz, comma-separated), ± --exclude-width.
    #[arg(long, value_delimiter = ',')]
    pub exclude: Vec<f64>,
    /// Drop the lines near every harmonic of the mains frequency (Hz, e.g. 50 or 60).
    #[arg(long)]
    pub mains: Option<f64>,
    /// Half-width (Hz) of the neighbourhood --exclude and --mains drop.
    #[arg(long, default_value_t = 0.5)]
    pub exclude_width: f64,
    /// Drop the lines whose coherence is below this (0..1), where the data have coherence.
    #[arg(long)]
    pub min_coherence: Option<f64>,
    /// Decimate each characteristic to at most this many lines, spread log-uniformly with extra
    /// density at the resonance peaks (the paper's characteristic points; dense spectra of
    /// thousands of lines fit as well and much faster).
    #[arg(long)]
    pub points: Option<usize>,
    /// Minimizer.
    #[arg(long, value_enum, default_value_t = OptimizerArg::Lm)]
    pub method: OptimizerArg,
    /// What is fitted: amplitudes, log-amplitudes or complex values (auto: log-amplitude for
    /// data without variances or coherence, amplitude otherwise).
    #[arg(long, value_enum, default_value_t = FitArg::Auto)]
    pub fit: FitArg,
    /// Where the observation covariance R comes from.
    #[arg(long, value_enum, default_value_t = NoiseArg::Auto)]
    pub noise: NoiseArg,
    /// ε of the relative-error model σ = ε·|z|.
    #[arg(long, default_value_t = 0.01)]
    pub relative_error: f64,
    /// Iteration limit (per start).
    #[arg(long, default_value_t = 100)]
    pub max_iterations: usize,
    /// Number of starts (extra ones: a Latin hypercube in log-parameter space over the bounds).
    #[arg(long, default_value_t = 1)]
    pub starts: usize,
    /// Where the fit starts: `auto` (default) also starts from the modal pre-fit for data
    /// without variances (vendor files), keeping the better fit; `model` the variables file's
    /// values only; `modal` the modal pre-fit's only.
    #[arg(long, value_enum, default_value_t = StartArg::Auto)]
    pub start: StartArg,
    /// Seed of the extra starts.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Use forward-difference Jacobians (for comparison; slower).
    #[arg(long)]
    pub finite_difference: bool,
    /// FRF solution path.
    #[arg(long = "frf-method", value_enum, default_value_t = MethodArg::Auto)]
    pub frf_method: MethodArg,
    /// Output format on stdout.
    #[arg(long, value_enum, default_value_t = FormatArg::Text)]
    pub format: FormatArg,
    /// Also write report.txt, table.json, table.csv, model.json (and model.toml for a TOML model)
    /// into this directory, and the report (report.html, report.json: docs/report-json.md) with
    /// the model curves (`ident diagnose --out` writes only the report, with its diagnosis).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Append this run to a run history database (SQLite, `docs/nightly.md`; created when
    /// missing) for `ident history` and the nightly's drift judgement.
    #[arg(long, value_name = "DB")]
    pub record_history: Option<PathBuf>,
    /// Relative standard error above which a direction of the information matrix is reported as
    /// poorly identifiable (0.5 = 50 %).
    #[arg(long, default_value_t = 0.5)]
    pub weak_threshold: f64,
    /// A plain progress line per iteration on stderr (iteration, criterion J, step norm,
    /// projected gradient norm). The same lines are always logged at level info (`-v` or
    /// `IDENT_LOG=info`).
    #[arg(long)]
    pub progress: bool,
    /// Print on stderr the wall time of each step: set-up (reading and preparing the files),
    /// the fit alone (the minimisation from every start, what an optimizer's own timing covers),
    /// the identification around it (the solves at the start and the estimate, Cramér-Rao) and
    /// the output.
    #[arg(long)]
    pub timing: bool,
    /// Write the fit problem (resolved model at the initial values, observations with σ,
    /// variables as linear maps onto SDE stiffness and ψ) as JSON to this file and exit without
    /// fitting: for external tools such as bench/python/ident_baseline.py.
    #[arg(long)]
    pub export_problem: Option<PathBuf>,
    /// Write the final model to this file as TOML in the model format (docs/model-format.md):
    /// the model's own text with the final estimates written back (after `ident diagnose`, the
    /// accepted effects appended as elements, each with where it came from). A resolved JSON
    /// model is written whole.
    #[arg(long)]
    pub write_model: Option<PathBuf>,
    /// Write the identification variables file for the next run to this file: the same
    /// variables with `initial` = the final estimates (after `ident diagnose`, plus the added
    /// springs' k and ψ), to be used with the `--write-model` file.
    #[arg(long)]
    pub write_vars: Option<PathBuf>,
    /// A cutting file (docs/stability.md): the report (`--out`, `--record-history`) gets a
    /// chatter-stability section for it — the final model's lobes with their 5–95 % band from the
    /// final fit's covariance, the minimum critical depth and the modes and joints that set it.
    #[arg(long)]
    pub cut: Option<PathBuf>,
}

/// Writes `--write-model` and `--write-vars` for the final fit: the identification's, or the
/// diagnosis's when `diagnosis` is given.
pub fn write_final(
    a: &IdentifyArgs,
    id: &idn::Identification,
    diagnosis: Option<&::diagnose::Diagnosis>,
) -> anyhow::Result<()> {
    use ::diagnose::final_model;
    if a.write_model.is_none() && a.write_vars.is_none() {
        return Ok(());
    }
    let original = std::fs::read_to_string(&a.model)
        .with_context(|| format!("cannot re-read {}", a.model.display()))?;
    let origin = a.model.display().to_string();
    let source = final_model::Source {
        origin: &origin,
        text: (!original.trim_start().starts_with('{')).then_some(original.as_str()),
    };
    if let Some(p) = &a.write_model {
        let text = final_model::model_toml(source, id, diagnosis)
            .context("--write-model: the final model")?;
        emit(Some(p), &text)?;
    }
    if let Some(p) = &a.write_vars {
        let model_file = a.write_model.as_ref().unwrap_or(&a.model);
        let text = final_model::variables_toml(&model_file.display().to_string(), id, diagnosis)
            .context("--write-vars: the next variables file")?;
        emit(Some(p), &text)?;
    }
    Ok(())
}

/// `--band LO:HI` in Hz, either side may be empty.
pub fn parse_band(text: &str) -> Result<(Option<f64>, Option<f64>), String> {
    let (lo, hi) = text
        .split_once(':')
        .ok_or_else(|| format!("{text:?}: give LO:HI in Hz, e.g. 20:400 (or 20: / :400)"))?;
    let edge = |s: &str| -> Result<Option<f64>, String> {
        let s = s.trim();
        if s.is_empty() {
            return Ok(None);
        }
        s.parse::<f64>()
            .map(Some)
            .map_err(|_| format!("{s:?} is not a frequency in Hz (LO:HI, e.g. 20:400)"))
    };
    Ok((edge(lo)?, edge(hi)?))
}

/// The line choice of `--band`, `--exclude`, `--mains`, `--exclude-width`, `--min-coherence`.
fn line_choice(a: &IdentifyArgs) -> idn::line_choice::LineChoice {
    idn::line_choice::LineChoice {
        band_hz: a.band.unwrap_or((None, None)),
        exclude_hz: a.exclude.clone(),
        mains_hz: a.mains,
        exclude_width_hz: a.exclude_width,
        min_coherence: a.min_coherence,
    }
}

/// Prepares the identification of `a` (`identify::request`: model, data, map, line choice,
/// decimation, variables, start) with its options, saying on stderr what was assumed, converted,
/// dropped or warned about (shared by `ident identify` and `ident diagnose`).
pub fn setup(a: &IdentifyArgs) -> anyhow::Result<request::Problem> {
    anyhow::ensure!(
        a.relative_error.is_finite() && a.relative_error > 0.0,
        "--relative-error {} must be a number > 0 (e.g. 0.02 for 2 %)",
        a.relative_error
    );
    anyhow::ensure!(a.max_iterations > 0, "--max-iterations must be at least 1");
    anyhow::ensure!(a.starts > 0, "--starts must be at least 1");
    anyhow::ensure!(
        a.weak_threshold.is_finite() && a.weak_threshold > 0.0,
        "--weak-threshold {} must be a relative standard error > 0 (e.g. 0.5 for 50 %)",
        a.weak_threshold
    );
    let lines = line_choice(a);
    let req = Request {
        model: &a.model,
        data: DataRequest {
            data: &a.data,
            map: a.map.as_deref(),
            lines: &lines,
            points: a.points,
        },
        vars: &a.vars,
        start: match a.start {
            StartArg::Auto => Start::Auto,
            StartArg::Model => Start::Variables,
            StartArg::Modal => Start::Modal,
        },
        fit: match a.fit {
            FitArg::Auto => None,
            FitArg::Amplitude => Some(FitKind::Amplitude),
            FitArg::LogAmplitude => Some(FitKind::LogAmplitude),
            FitArg::Complex => Some(FitKind::Complex),
        },
        options: options(a),
    };
    Ok(request::prepare(&req, &mut |note| eprintln!("{note}"))?)
}

/// The fit options of `a` (the fit kind is chosen with the data, `identify::request`).
fn options(a: &IdentifyArgs) -> Options {
    Options {
        noise: match a.noise {
            NoiseArg::Auto => NoiseChoice::Auto,
            NoiseArg::Variance => NoiseChoice::Variance,
            NoiseArg::Coherence => NoiseChoice::Coherence,
            NoiseArg::Relative => NoiseChoice::Relative(a.relative_error),
        },
        optimizer: match a.method {
            OptimizerArg::Lm => Optimizer::LevenbergMarquardt,
            OptimizerArg::Gn => Optimizer::GaussNewton,
            OptimizerArg::Bfgs => Optimizer::Bfgs,
        },
        settings: Settings {
            max_iterations: a.max_iterations,
            ..Settings::default()
        },
        jacobian: if a.finite_difference {
            JacobianMode::ForwardDifference
        } else {
            JacobianMode::Analytic
        },
        frf_method: a.frf_method.into(),
        starts: a.starts,
        seed: a.seed,
        weak_threshold: a.weak_threshold,
        ..Options::default()
    }
}

/// The report of an identification, and of its diagnosis when given, built as the workflows
/// build theirs (`pipeline::build_report`), with the stability section for `--cut`.
fn build(
    a: &IdentifyArgs,
    workflow: &str,
    obs: &idn::Observations,
    id: &idn::Identification,
    diagnosis: Option<(::report::Diagnosis, &::diagnose::Diagnosis)>,
) -> anyhow::Result<::report::Report> {
    let title = format!("ident {workflow}: {}", model_name(a));
    let ctx = ReportContext {
        title: &title,
        workflow,
        stand: None,
        drift: None,
        messages: Vec::new(),
        created_utc: String::new(),
    };
    let source = ::report::document::Source {
        model: a.model.display().to_string(),
        variables: a.vars.display().to_string(),
        measurement: format!("data file {}", a.data.display()),
        ..::report::document::Source::default()
    };
    let full = diagnosis.as_ref().map(|(_, d)| *d);
    let mut r = build_report(ctx, source, obs, id, diagnosis.map(|(s, d)| (s, &d.model)))?;
    if let Some(cut) = &a.cut {
        r.stability = Some(super::stability::report_section(cut, id, full, &r, None)?);
    }
    Ok(r)
}

/// The model file's name without its extension (the whole path if it has none).
pub fn model_name(a: &IdentifyArgs) -> String {
    a.model
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| a.model.display().to_string())
}

/// Writes report.html and report.json (docs/report-json.md) of an identification, and of its
/// diagnosis when given, into `dir` (which exists).
pub fn write_report(
    dir: &Path,
    a: &IdentifyArgs,
    workflow: &str,
    obs: &idn::Observations,
    id: &idn::Identification,
    diagnosis: Option<(::report::Diagnosis, &::diagnose::Diagnosis)>,
) -> anyhow::Result<::report::Written> {
    let r = build(a, workflow, obs, id, diagnosis)?;
    let written = ::report::write(&r, dir)?;
    tracing::info!("report: {}", written.html.display());
    Ok(written)
}

/// Appends this run to the history database `db` (`--record-history`): the run as its report
/// describes it, named `WORKFLOW-<UTC>`, the model hash of the model file's bytes.
pub fn record_history(
    db: &Path,
    a: &IdentifyArgs,
    workflow: &str,
    obs: &idn::Observations,
    id: &idn::Identification,
    diagnosis: Option<(::report::Diagnosis, &::diagnose::Diagnosis)>,
) -> anyhow::Result<()> {
    let r = build(a, workflow, obs, id, diagnosis)?;
    let run_id = format!("{workflow}-{}", r.created_utc.replace(':', ""));
    let mut run =
        history::import::run_from_report_text(&serde_json::to_string(&r)?, &a.data, &run_id)?;
    let model =
        std::fs::read(&a.model).with_context(|| format!("cannot re-read {}", a.model.display()))?;
    run.model_hash = history::record::model_hash(&model);
    run.session = Some(a.data.display().to_string());
    if !id.stop.converged() {
        run.outcome = "failure".into();
    }
    let mut store = history::store::Store::open(db)?;
    // Two runs in the same second: the later gets a suffix rather than overwriting.
    let base = run.run_id.clone();
    let mut n = 1;
    while store.contains(&run.run_id)? {
        n += 1;
        run.run_id = format!("{base}-{n}");
    }
    store.append(&run)?;
    eprintln!("recorded as run {} in {}", run.run_id, db.display());
    Ok(())
}

/// Runs the identification. Exit 0: converged; 1: iteration limit or divergence (the best point
/// is still reported and written).
pub fn run(a: IdentifyArgs) -> anyhow::Result<ExitCode> {
    let begun = std::time::Instant::now();
    let problem = setup(&a)?;
    let obs = &problem.observations;
    if let Some(path) = &a.export_problem {
        let p = &problem;
        let exported = idn::problem::to_json(&p.model, obs, &p.variables, &p.options)?;
        emit(Some(path), &(serde_json::to_string(&exported)? + "\n"))?;
        return Ok(ExitCode::SUCCESS);
    }
    let plain = a.progress;
    let multi = a.starts > 1;
    let started = std::time::Instant::now();
    let id = problem.identify(&mut |start, p| {
        tracing::info!(
            start,
            iteration = p.iteration,
            criterion = p.criterion,
            step = p.step_norm,
            gradient = p.gradient_norm,
            "identify"
        );
        if plain {
            let prefix = if multi {
                format!("start {start} ")
            } else {
                String::new()
            };
            eprintln!(
                "{prefix}iteration {:>3}  J = {:.6e}  step = {:.3e}  gradient = {:.3e}",
                p.iteration, p.criterion, p.step_norm, p.gradient_norm
            );
        }
    })?;
    let identified = started.elapsed().as_secs_f64();
    tracing::info!(
        seconds = identified,
        iterations = id.iterations,
        model_evaluations = id.evaluations.model,
        "identify: {}",
        id.stop.describe()
    );
    let output = std::time::Instant::now();
    // Each form is made when it is written: on stdout in the chosen format, all three with --out.
    let text = || report::text(&id);
    let json = || -> anyhow::Result<String> {
        Ok(serde_json::to_string_pretty(&report::json(&id))? + "\n")
    };
    let csv = || report::csv(&id);
    match a.format {
        FormatArg::Text => emit(None, &text())?,
        FormatArg::Json => emit(None, &json()?)?,
        FormatArg::Csv => emit(None, &csv())?,
    }
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the output directory {}", dir.display()))?;
        emit(Some(&dir.join("report.txt")), &text())?;
        emit(Some(&dir.join("table.json")), &json()?)?;
        emit(Some(&dir.join("table.csv")), &csv())?;
        let resolved = serde_json::to_string_pretty(&rfe::contract::to_json(&id.model))? + "\n";
        emit(Some(&dir.join("model.json")), &resolved)?;
        let original = std::fs::read_to_string(&a.model)
            .with_context(|| format!("cannot re-read {}", a.model.display()))?;
        if !original.trim_start().starts_with('{') {
            let updated = report::update_toml(&original, &a.model.display().to_string(), &id)?;
            emit(Some(&dir.join("model.toml")), &updated)?;
        }
        write_report(dir, &a, "identify", obs, &id, None)?;
    }
    if let Some(db) = &a.record_history {
        record_history(db, &a, "identify", obs, &id, None)?;
    }
    write_final(&a, &id, None)?;
    if a.timing {
        let ms = |s: f64| 1e3 * s;
        eprintln!(
            "timing: set-up {:.2} ms, fit {:.2} ms ({} iterations, {} model evaluations in all), identification around it {:.2} ms, output {:.2} ms, run {:.2} ms",
            ms(started.duration_since(begun).as_secs_f64()),
            ms(id.fit_seconds),
            id.iterations,
            id.evaluations.model,
            ms(identified - id.fit_seconds),
            ms(output.elapsed().as_secs_f64()),
            ms(begun.elapsed().as_secs_f64()),
        );
    }
    if id.stop.converged() {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!("{}", id.stop.describe());
        Ok(ExitCode::from(1))
    }
}
