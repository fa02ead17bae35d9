//! `ident nightly CONFIG`: unattended identification of one stand (cron / systemd timer).
//!
//! Takes a lock (a second run exits 2; the kernel releases it when a run dies, even by `kill -9`), runs the sweep
//! (or takes the newest session), processes, identifies, diagnoses, compares every parameter with
//! its history and writes a dated report folder (HTML, JSON, identification files,
//! `status.json`). Drift: with `[history]` every run is appended to the run history database and
//! judged against the normal run-to-run scatter of a baseline window (`history::judge`,
//! `docs/nightly.md`); without it, beyond k standard errors from the baseline run is an alarm.
//! `newest-session` skips sessions their writer did not finish (a sweep killed with `kill -9`).
//! `prometheus` writes the status as a node_exporter textfile. Logs to a file and to stderr; never
//! prompts. Exit status: 0 ok, 1 alarm, 2 failure. On failure the partial session is kept and
//! `status.json` says what happened.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use acquire::stand::Stand;
use acquire::sweep::{NoProgress, SteppedSine};
use anyhow::Context;
use serde::Deserialize;
use serde_json::json;

use pipeline::{ReportContext, Setup};

use super::note;

/// Arguments of `ident nightly`.
#[derive(clap::Args)]
pub struct NightlyArgs {
    /// The job file (configs/nightly.toml; keys: configs/README.md).
    pub config: PathBuf,
}

/// The job file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Headline of the reports.
    pub name: String,
    /// `sweep` or `newest-session`.
    pub measure: Measure,
    /// Stand file (needed for `sweep`).
    pub stand: Option<PathBuf>,
    /// Identification model.
    pub model: PathBuf,
    /// Decision variables.
    pub variables: PathBuf,
    /// Session folder.
    pub sessions: PathBuf,
    /// Report folder (one dated sub-folder per run).
    pub reports: PathBuf,
    /// Log file.
    pub log: PathBuf,
    /// Lock file.
    pub lock: PathBuf,
    /// Sweep plan.
    #[serde(default)]
    pub sweep: SweepConfig,
    /// Drift rule.
    #[serde(default)]
    pub drift: DriftConfig,
    /// Run history and drift judged from it; without it, the `[drift]` k_sigma rule alone.
    pub history: Option<HistoryConfig>,
    /// Prometheus textfile (node_exporter's textfile collector) with the last run's status.
    pub prometheus: Option<PathBuf>,
    /// Chatter stability of each night's final model for a cut: a section in the report, and
    /// the minimum critical depth over the speed range judged in the history.
    pub stability: Option<StabilityConfig>,
}

/// `[stability]`: the cut whose minimum critical depth the nightly judges (`docs/stability.md`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StabilityConfig {
    /// The cutting file (relative to the job file's folder).
    pub cut: PathBuf,
    /// The spindle-speed range of interest (rpm), `[from, to]`; default: the cut file's
    /// `speed_rpm`.
    pub speed_rpm: Option<[f64; 2]>,
}

/// `[history]`: every run is appended to `database` and judged against a baseline window of
/// earlier runs of the same model (`history::judge`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HistoryConfig {
    /// The SQLite history database (created when missing).
    pub database: PathBuf,
    /// Runs in the baseline window.
    #[serde(default = "default_baseline_runs")]
    pub baseline_runs: usize,
    /// `first` (the first `baseline_runs` runs) or `rolling` (the runs just before).
    #[serde(default)]
    pub window: Window,
    /// Covariate to compensate (a channel recorded with the session, e.g. `temperature`).
    pub covariate: Option<String>,
}

fn default_baseline_runs() -> usize {
    20
}

/// The baseline window's kind.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Window {
    /// The first runs.
    #[default]
    First,
    /// The runs just before the judged one.
    Rolling,
}

impl HistoryConfig {
    /// The judgement's settings.
    pub fn judge(&self) -> history::judge::JudgeConfig {
        use history::judge::BaselineWindow;
        history::judge::JudgeConfig {
            baseline: match self.window {
                Window::First => BaselineWindow::First(self.baseline_runs),
                Window::Rolling => BaselineWindow::Rolling(self.baseline_runs),
            },
            covariate: self.covariate.clone(),
            ..Default::default()
        }
    }
}

/// What a run measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Measure {
    /// Sweep the stand now.
    Sweep,
    /// Take the newest session in `sessions`.
    NewestSession,
}

/// `[sweep]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SweepConfig {
    /// First line (Hz).
    pub from_hz: f64,
    /// Last line (Hz).
    pub to_hz: f64,
    /// Log-spaced lines.
    pub points: usize,
    /// Force amplitude (N, peak).
    pub force_n: f64,
    /// Simulated stands: simulated time per wall-clock time.
    pub speed: Option<f64>,
}

impl Default for SweepConfig {
    fn default() -> Self {
        SweepConfig {
            from_hz: 20.0,
            to_hz: 400.0,
            points: 38,
            force_n: 4000.0,
            speed: None,
        }
    }
}

/// `[drift]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriftConfig {
    /// Alarm threshold in standard errors.
    pub k_sigma: f64,
    /// `first` or a run folder name.
    pub baseline: String,
}

impl Default for DriftConfig {
    fn default() -> Self {
        DriftConfig {
            k_sigma: 3.0,
            baseline: "first".into(),
        }
    }
}

impl Config {
    /// Loads a job file; relative paths become relative to its folder. Errors name file:line:column.
    pub fn load(path: &Path) -> anyhow::Result<Config> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read the nightly job file {}", path.display()))?;
        let mut c: Config = toml::from_str(&text).map_err(|e| {
            let (l, col) = rfe::source::line_col(&text, e.span().map(|s| s.start).unwrap_or(0));
            anyhow::anyhow!(
                "{}:{l}:{col}: {} (keys: configs/README.md#nightly)",
                path.display(),
                e.message().trim()
            )
        })?;
        let at = |key: &str| {
            let (l, _) = text
                .lines()
                .enumerate()
                .find(|(_, s)| s.trim_start().starts_with(key))
                .map(|(i, _)| (i + 1, 0))
                .unwrap_or((0, 0));
            format!("{}:{l}", path.display())
        };
        let dir = path.parent().unwrap_or(Path::new("."));
        for p in [
            &mut c.model,
            &mut c.variables,
            &mut c.sessions,
            &mut c.reports,
            &mut c.log,
            &mut c.lock,
        ] {
            if p.is_relative() {
                *p = dir.join(&*p);
            }
        }
        for p in [
            c.stand.as_mut(),
            c.prometheus.as_mut(),
            c.history.as_mut().map(|h| &mut h.database),
            c.stability.as_mut().map(|s| &mut s.cut),
        ]
        .into_iter()
        .flatten()
        {
            if p.is_relative() {
                *p = dir.join(&*p);
            }
        }
        anyhow::ensure!(
            c.stability
                .as_ref()
                .and_then(|s| s.speed_rpm)
                .is_none_or(|[a, b]| a > 0.0 && b > a && b.is_finite()),
            "{}: [stability] speed_rpm must be [from, to] with 0 < from < to (rpm)",
            at("speed_rpm")
        );
        anyhow::ensure!(
            c.history.as_ref().is_none_or(|h| h.baseline_runs >= 3),
            "{}: [history] baseline_runs must be at least 3 (20 or more learns normal scatter well)",
            at("baseline_runs")
        );
        anyhow::ensure!(
            c.measure != Measure::Sweep || c.stand.is_some(),
            "{}: measure = \"sweep\" needs `stand = \"stands/NAME.toml\"`",
            at("measure")
        );
        let s = &c.sweep;
        anyhow::ensure!(
            s.from_hz > 0.0 && s.to_hz > s.from_hz && s.to_hz.is_finite(),
            "{}: [sweep] needs 0 < from_hz < to_hz (Hz)",
            at("from_hz")
        );
        anyhow::ensure!(
            (2..=1000).contains(&s.points),
            "{}: [sweep] points = {}: give 2 to 1000 lines",
            at("points"),
            s.points
        );
        anyhow::ensure!(
            s.force_n > 0.0 && s.force_n.is_finite(),
            "{}: [sweep] force_n must be > 0 N",
            at("force_n")
        );
        anyhow::ensure!(
            s.speed.is_none_or(|v| v > 0.0 && v.is_finite()),
            "{}: [sweep] speed must be > 0",
            at("speed")
        );
        anyhow::ensure!(
            c.drift.k_sigma > 0.0 && c.drift.k_sigma.is_finite(),
            "{}: [drift] k_sigma must be > 0",
            at("k_sigma")
        );
        Ok(c)
    }

    fn plan(&self) -> SteppedSine {
        let s = &self.sweep;
        SteppedSine::log(s.from_hz, s.to_hz, s.points, s.force_n)
    }

    fn baseline(&self) -> history::judge::crlb::Baseline {
        if self.drift.baseline == "first" {
            history::judge::crlb::Baseline::First
        } else {
            history::judge::crlb::Baseline::Run(self.drift.baseline.clone())
        }
    }
}

/// The job lock: an advisory lock (`flock`, through std's `File::try_lock`) on the lock file,
/// held while the job runs. The kernel releases it when the process ends, however it ends
/// (`kill -9` and power loss included), so a lock can never be left stale. The file holds the
/// owner's PID for people to read; a clean exit empties it. It is never deleted: deleting a lock
/// file races with a process that has just opened it.
pub struct Lock {
    file: File,
    path: PathBuf,
}

impl Lock {
    /// Takes the lock. `Ok(Err(message))` when another run holds it. A PID left in the file by
    /// a run that did not end cleanly is reported in `notes`.
    pub fn take(path: &Path, notes: &mut Vec<String>) -> anyhow::Result<Result<Lock, String>> {
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create the lock folder {}", parent.display()))?;
        }
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .with_context(|| format!("cannot open the lock file {}", path.display()))?;
        let mut previous = String::new();
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                let _ = file.read_to_string(&mut previous);
                let owner = match previous.trim() {
                    "" => String::new(),
                    pid => format!("pid {pid}, "),
                };
                return Ok(Err(format!(
                    "another ident nightly is running ({owner}lock {}); this run exits without \
                     doing anything",
                    path.display()
                )));
            }
            Err(std::fs::TryLockError::Error(e)) => {
                return Err(e).with_context(|| format!("cannot lock {}", path.display()))
            }
        }
        let _ = file.read_to_string(&mut previous);
        if !previous.trim().is_empty() {
            notes.push(format!(
                "stale lock {} from pid {}, a run that did not end cleanly: taken over",
                path.display(),
                previous.trim()
            ));
        }
        file.set_len(0)
            .and_then(|_| file.seek(SeekFrom::Start(0)))
            .and_then(|_| writeln!(file, "{}", std::process::id()))
            .and_then(|_| file.sync_data())
            .with_context(|| format!("cannot write the lock file {}", path.display()))?;
        Ok(Ok(Lock {
            file,
            path: path.to_path_buf(),
        }))
    }
}

impl Drop for Lock {
    fn drop(&mut self) {
        // Empty the PID (a clean exit); the lock itself goes with the file handle.
        if let Err(e) = self.file.set_len(0) {
            eprintln!(
                "warning: cannot clear the lock file {}: {e}",
                self.path.display()
            );
        }
    }
}

/// Log lines to a file (appended) and stderr; a log that cannot be written (disk full) does not
/// stop the job — stderr still has everything.
struct Log {
    file: Option<File>,
}

impl Log {
    fn open(path: &Path) -> (Log, Option<String>) {
        let r = path
            .parent()
            .map(std::fs::create_dir_all)
            .unwrap_or(Ok(()))
            .and_then(|_| OpenOptions::new().create(true).append(true).open(path));
        match r {
            Ok(f) => (Log { file: Some(f) }, None),
            Err(e) => (
                Log { file: None },
                Some(format!(
                    "cannot open the log file {}: {e}; logging to stderr only",
                    path.display()
                )),
            ),
        }
    }

    fn line(&mut self, msg: &str) {
        let l = format!("{} ident nightly: {msg}", report::build::now_utc());
        eprintln!("{l}");
        if let Some(f) = &mut self.file {
            if writeln!(f, "{l}").and_then(|_| f.flush()).is_err() {
                eprintln!("warning: the log file can no longer be written (disk full?); logging to stderr only");
                self.file = None;
            }
        }
    }
}

/// Runs the job.
pub fn run(a: NightlyArgs) -> anyhow::Result<ExitCode> {
    let cfg = Config::load(&a.config)?;
    let mut notes = Vec::new();
    let lock = match Lock::take(&cfg.lock, &mut notes)? {
        Ok(l) => l,
        Err(busy) => {
            eprintln!("ident nightly: {busy}");
            return Ok(ExitCode::from(2));
        }
    };
    let (mut log, log_err) = Log::open(&cfg.log);
    if let Some(e) = log_err {
        eprintln!("warning: {e}");
    }
    log.line(&format!("start: {} ({})", cfg.name, a.config.display()));
    for n in &notes {
        log.line(n);
    }
    let dir = match pipeline::dated_folder(&cfg.reports, "") {
        Ok(d) => d,
        Err(e) => {
            log.line(&format!("FAILURE: {e:#}"));
            drop(lock);
            return Ok(ExitCode::from(2));
        }
    };
    log.line(&format!("report folder {}", dir.display()));
    let mut session: Option<PathBuf> = None;
    let result = job(&cfg, &dir, &mut log, &mut session, notes);
    let code = match result {
        Ok(code) => code,
        Err(e) => {
            let msg = format!("{e:#}");
            log.line(&format!("FAILURE: {msg}"));
            if let Some(s) = &session {
                log.line(&format!("the session is kept: {}", s.display()));
            }
            let now = report::build::now_utc();
            let status = json!({"outcome": "failure", "error": msg, "session": session.as_ref().map(|s| s.display().to_string()), "created_utc": now});
            if let Err(e) =
                report::write_atomic(&dir.join("status.json"), status.to_string().as_bytes())
            {
                log.line(&format!("cannot write status.json: {e}"));
            }
            let mut lines = Vec::new();
            if let Some(s) = &session {
                lines.push(format!("the session is kept: {}", s.display()));
            }
            lines.push(format!("log: {}", cfg.log.display()));
            lines.push(format!("configuration: {}", a.config.display()));
            let page = report::html::failure_page(&cfg.name, &now, &msg, &lines);
            if let Err(e) = report::write_atomic(&dir.join("report.html"), page.as_bytes()) {
                log.line(&format!("cannot write report.html: {e}"));
            }
            if let Some(p) = &cfg.prometheus {
                let status = super::prometheus::RunStatus {
                    job: &cfg.name,
                    outcome: "failure",
                    exit_code: 2,
                    end_unix: now_unix(),
                    judgement: None,
                    record: None,
                };
                if let Err(e) = super::prometheus::write(p, &status) {
                    log.line(&format!("cannot write the Prometheus textfile: {e}"));
                }
            }
            2
        }
    };
    log.line(&format!("end: exit {code}"));
    drop(lock);
    Ok(ExitCode::from(code))
}

/// One nightly run, top to bottom: the session (the newest, or a new sweep), process → identify →
/// diagnose, drift against the earlier reports, the run history's judgement, the report and
/// status.json, the Prometheus textfile. Longer than a screen because every step adds to the same
/// log and report messages; split, each step would take and return both.
fn job(
    cfg: &Config,
    dir: &Path,
    log: &mut Log,
    session: &mut Option<PathBuf>,
    mut notes: Vec<String>,
) -> anyhow::Result<u8> {
    let setup = Setup::load(&cfg.model, &cfg.variables, &mut note)?;
    let mut stand_name = None;
    let path = match cfg.measure {
        Measure::NewestSession => {
            let mut skipped = Vec::new();
            let found = pipeline::sessions::newest_finished(&cfg.sessions, &mut |n| {
                skipped.push(n.to_string())
            });
            for m in &skipped {
                log.line(m);
            }
            notes.extend(skipped);
            let p = found?;
            log.line(&format!("newest session: {}", p.display()));
            p
        }
        Measure::Sweep => {
            let (p, name) = sweep_session(cfg, dir, log, session)?;
            stand_name = Some(name);
            p
        }
    };
    *session = Some(path.clone());
    let analysis = pipeline::analyse(&path, &setup, &pipeline::identification_options())?;
    for m in &analysis.messages {
        log.line(m);
    }
    log.line(&format!(
        "identified {} variables: J {:.4e} -> {:.4e}, {}",
        analysis.identification.variables.len(),
        analysis.identification.criterion_initial,
        analysis.identification.criterion,
        analysis.identification.stop.describe()
    ));
    // The drift needs this run's table and time: build once without, compare, then write with it.
    // With its diagnosis, so that this run is read at the same stage as the earlier reports (the
    // final model's parameters when the diagnosis added an effect).
    let mut probe = report::build::build({
        let mut i = report::build::Inputs::new(
            &cfg.name,
            &analysis.problem.observations,
            &analysis.identification,
        );
        i.sensitivity = false;
        i.diagnosis = analysis
            .diagnosis
            .as_ref()
            .map(|(section, d)| (section.clone(), &d.model));
        i
    })?;
    // The stable depth: in the probe, so that the history records and judges it.
    if let Some(s) = &cfg.stability {
        let full = analysis.diagnosis.as_ref().map(|(_, d)| d);
        match super::stability::report_section(
            &s.cut,
            &analysis.identification,
            full,
            &probe,
            s.speed_rpm.map(|[a, b]| (a, b)),
        ) {
            Ok(section) => {
                log.line(&format!(
                    "stability: {} {:.4} mm at {:.0} rpm",
                    section.quantity_name(),
                    section.minimum.depth_mm,
                    section.minimum.speed_rpm
                ));
                probe.stability = Some(section);
            }
            Err(e) => {
                let m = format!("stability not computed: {e:#}");
                log.line(&m);
                notes.push(m);
            }
        }
    }
    // History: earlier runs' reports (this run's folder has none yet), read as run records.
    let (mut drift, hist_msgs) = crlb_drift(cfg, dir, &probe)?;
    for m in &hist_msgs {
        log.line(m);
    }
    let mut messages: Vec<String> = notes.into_iter().chain(hist_msgs).collect();
    // The run history: this run as a record, judged against the baseline window.
    let mut recorded = None;
    if let Some(h) = &cfg.history {
        match judge_from_history(cfg, h, dir, &probe, &path, stand_name.clone()) {
            Ok((judgement, record, store)) => {
                if let Some(d) = drift.as_mut() {
                    for p in &mut d.parameters {
                        p.alarm = false;
                    }
                    messages.push(format!(
                    "the deviations from the baseline run in Cramér-Rao errors (k_sigma {}) are shown for reference; alarms are judged from the run history {}",
                    cfg.drift.k_sigma,
                    h.database.display()
                ));
                }
                log.line(&judgement.summary());
                messages.push(judgement.summary());
                messages.extend(judgement.alarms.iter().map(|a| a.message.clone()));
                messages.extend(
                    judgement
                        .changes
                        .iter()
                        .filter(|c| c.alarm_run != judgement.run_id)
                        .map(|c| format!("drift: {}", c.message)),
                );
                messages.extend(
                    judgement
                        .not_judged
                        .iter()
                        .map(|n| format!("drift: {} not judged: {}", n.variable, n.why)),
                );
                messages.extend(judgement.notes.iter().map(|n| format!("drift: {n}")));
                recorded = Some((judgement, record, store));
            }
            Err(e) => {
                let m = format!("the run history is not used tonight: {e:#}; this run is not recorded and drift is not judged from the history (the k_sigma comparison still is)");
                log.line(&m);
                messages.push(m);
            }
        }
    }
    let ctx = ReportContext {
        title: &cfg.name,
        workflow: "nightly",
        stand: stand_name,
        drift,
        messages,
        created_utc: probe.created_utc.clone(),
    };
    let (mut r, mut written) = pipeline::write_report(dir, ctx, &setup, &analysis)?;
    if probe.stability.is_some() {
        r.stability = probe.stability.clone();
        written = report::write(&r, dir)?;
    }
    if let Some((judgement, record, store)) = &mut recorded {
        if judgement.alarm() && r.status.outcome == report::Outcome::Ok {
            r.status.outcome = report::Outcome::Alarm;
            written = report::write(&r, dir)?;
        }
        record.outcome = r.status.outcome.as_str().into();
        match store.append(record) {
            Ok(()) => log.line(&format!(
                "recorded in the history {}",
                store.path().display()
            )),
            Err(e) => {
                let m = format!("this run could not be recorded in the history: {e}");
                log.line(&m);
                r.status.messages.push(m);
            }
        }
    }
    for m in r
        .status
        .messages
        .iter()
        .filter(|m| m.starts_with("drift alarm"))
    {
        log.line(&format!("ALARM: {m}"));
    }
    let status = json!({"outcome": r.status.outcome.as_str(), "created_utc": r.created_utc, "session": path.display().to_string(), "report": written.html.display().to_string(), "messages": r.status.messages});
    report::write_atomic(&dir.join("status.json"), status.to_string().as_bytes())?;
    log.line(&format!("report: {}", written.html.display()));
    println!("{}", pipeline::summary_text(&analysis));
    println!("outcome: {}", r.status.outcome.as_str());
    println!("report: {}", dir.display());
    let code = match r.status.outcome {
        report::Outcome::Ok => 0,
        report::Outcome::Alarm => 1,
        report::Outcome::Failure => 2,
    };
    if let Some(p) = &cfg.prometheus {
        let status = super::prometheus::RunStatus {
            job: &cfg.name,
            outcome: r.status.outcome.as_str(),
            exit_code: code,
            end_unix: now_unix(),
            judgement: recorded.as_ref().map(|(j, _, _)| j),
            record: recorded.as_ref().map(|(_, r, _)| r),
        };
        if let Err(e) = super::prometheus::write(p, &status) {
            log.line(&format!("cannot write the Prometheus textfile: {e}"));
        }
    }
    Ok(code)
}

fn now_unix() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0)
}

/// The report's drift section: this run against the earlier reports in `reports`, in
/// Cramér-Rao errors of the difference (`history::judge::crlb`), with the messages of reports
/// that could not be read.
fn crlb_drift(
    cfg: &Config,
    dir: &Path,
    probe: &report::Report,
) -> anyhow::Result<(Option<report::Drift>, Vec<String>)> {
    let (earlier, summary) = match history::import::runs_from_reports(&cfg.reports) {
        Ok(x) => x,
        Err(e) => return Ok((None, vec![format!("history: {e}")])),
    };
    let run_id = dir
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default();
    let current = history::import::run_from_document(probe, &dir.join("report.json"), &run_id)?;
    let earlier: Vec<_> = earlier.into_iter().filter(|r| r.run_id != run_id).collect();
    let drift =
        history::judge::crlb::compare(&earlier, &current, &cfg.baseline(), cfg.drift.k_sigma)
            .map_err(|e| anyhow::anyhow!("[drift] baseline: {e}"))?;
    let messages = summary
        .skipped
        .iter()
        .map(|m| format!("history: {m} of the drift comparison"))
        .collect();
    Ok((drift, messages))
}

/// Opens the history, makes this run's record (named after its report folder) and judges it
/// against the earlier runs. The record is appended by the caller once the report is written.
fn judge_from_history(
    cfg: &Config,
    h: &HistoryConfig,
    dir: &Path,
    probe: &report::Report,
    session: &Path,
    stand: Option<String>,
) -> anyhow::Result<(
    history::judge::Judgement,
    history::record::RunRecord,
    history::store::Store,
)> {
    if let Some(parent) = h.database.parent() {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("cannot create the folder of {}", h.database.display()))?;
    }
    let store = history::store::Store::open(&h.database)?;
    let run_id = dir
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut record = history::import::run_from_document(probe, &dir.join("report.json"), &run_id)?;
    let model = std::fs::read(&cfg.model)
        .with_context(|| format!("cannot read the model {}", cfg.model.display()))?;
    record.model_hash = history::record::model_hash(&model);
    record.session = Some(session.display().to_string());
    record.stand = stand;
    let earlier = store.runs()?;
    let judgement = history::judge::judge_latest(&earlier, &record, &h.judge());
    Ok((judgement, record, store))
}
/// Sweeps the job's stand into a new session named after the report folder `dir`; returns the
/// session and the stand's name. The session path is set in `session` as soon as it exists.
fn sweep_session(
    cfg: &Config,
    dir: &Path,
    log: &mut Log,
    session: &mut Option<PathBuf>,
) -> anyhow::Result<(PathBuf, String)> {
    let stand_file = cfg.stand.as_deref().context("no stand")?;
    let mut stand = Stand::load(stand_file)?;
    if let (Some(t), Some(s)) = (stand.truth.as_mut(), cfg.sweep.speed) {
        t.speed = s;
    }
    std::fs::create_dir_all(&cfg.sessions).with_context(|| {
        format!(
            "cannot create the session folder {}",
            cfg.sessions.display()
        )
    })?;
    let stem = stand_file
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "stand".into());
    let p = cfg.sessions.join(format!(
        "{stem}-{}.mcap",
        dir.file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default()
    ));
    log.line(&format!("sweep of {} into {}", stand.name, p.display()));
    let swept = pipeline::sweep(
        &stand,
        &cfg.plan(),
        &p,
        &Default::default(),
        &NoProgress,
        &mut note,
    )?;
    *session = Some(p.clone());
    if let Some(e) = &swept.finish_error {
        log.line(&format!("the session file could not be completed: {e}; its flushed part is readable (ident mcap recover)"));
    }
    let o = swept
        .outcome
        .map_err(|e| anyhow::anyhow!("the sweep failed: {:#}", anyhow::Error::from(e)))?;
    anyhow::ensure!(
        swept.finish_error.is_none(),
        "the session file {} could not be completed (disk full?)",
        p.display()
    );
    log.line(&format!(
        "sweep done: {} of {} steps, {} stream faults",
        o.steps.len(),
        swept.planned,
        o.faults
    ));
    Ok((p, stand.name))
}
