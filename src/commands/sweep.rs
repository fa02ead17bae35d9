//! `ident sweep --stand FILE [--out DIR] [--resume SESSION]`: a stepped-sine sweep of a stand into
//! a new session file `DIR/<stand>-<UTC time>.mcap`, with a live progress line (step, frequency,
//! force, fit quality). Ctrl-C stops after the current step and still leaves a complete file that
//! `--resume` continues. Ports given as `"sim"` are served by the simulated stand (`--can IFACE`
//! puts its DAQ on CAN).
//!
//! `--broadband` runs the stand file's `[broadband]` measurement instead (periodic random, burst
//! random or chirp, averaged period by period; on a generator stand uploaded as an arbitrary
//! waveform, docs/scpi-generator.md) and prints the averages, the band and the mean coherence.
//!
//! Exit status: 0 every step measured; 1 the sweep is incomplete (stopped; resume it);
//! 2 failure (device, file or plan; the session file is still complete and says what happened).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use acquire::stand::Stand;
use acquire::sweep::{self, IndicatifProgress, SteppedSine};
use anyhow::Context;

use super::note;

/// Arguments of `ident sweep`.
#[derive(clap::Args)]
pub struct SweepArgs {
    /// Stand file (configs/stands/NAME.toml).
    #[arg(long)]
    pub stand: PathBuf,
    /// Folder for the session file.
    #[arg(long, default_value = "sessions")]
    pub out: PathBuf,
    /// Continue the sweep of this earlier session (same stand and plan): measure only the steps
    /// it did not complete.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// First frequency (Hz).
    #[arg(long, default_value_t = 20.0)]
    pub from: f64,
    /// Last frequency (Hz).
    #[arg(long, default_value_t = 400.0)]
    pub to: f64,
    /// Number of log-spaced lines (the paper measured 38).
    #[arg(long, default_value_t = 38)]
    pub points: usize,
    /// Force amplitude held by the closed loop (N, peak; the paper held 4 kN).
    #[arg(long, default_value_t = 4000.0)]
    pub force: f64,
    /// Simulated stand only: simulated time per wall-clock time (overrides `truth.speed`).
    #[arg(long)]
    pub speed: Option<f64>,
    /// Simulated stand only: serve its DAQ on this CAN interface.
    #[arg(long)]
    pub can: Option<String>,
    /// Run the stand file's `[broadband]` measurement instead of the stepped sine.
    #[arg(long, conflicts_with_all = ["resume", "from", "to", "points", "force"])]
    pub broadband: bool,
}

/// The plan `ident sweep` runs (also what `--resume` checks against).
pub fn plan(a: &SweepArgs) -> SteppedSine {
    SteppedSine::log(a.from, a.to, a.points, a.force)
}

fn session_path(dir: &Path, stand_file: &Path) -> PathBuf {
    let stem = stand_file
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "stand".into());
    // `YYYYmmddTHHMMSSZ`: sortable, and valid in file names everywhere.
    let base = format!(
        "{stem}-{}",
        report::build::now_utc().replace(['-', ':'], "")
    );
    let mut p = dir.join(format!("{base}.mcap"));
    let mut k = 1;
    while p.exists() {
        k += 1;
        p = dir.join(format!("{base}-{k}.mcap"));
    }
    p
}

/// Runs `ident sweep`.
pub fn run(a: SweepArgs) -> anyhow::Result<ExitCode> {
    let mut stand = Stand::load(&a.stand)?;
    if let Some(s) = a.speed {
        anyhow::ensure!(
            s.is_finite() && s > 0.0,
            "--speed {s}: give a factor > 0 (1 = real time)"
        );
        let t = stand.truth.as_mut().with_context(|| format!("--speed: {} has no [truth] section (only the simulated stand runs faster than real time)", a.stand.display()))?;
        t.speed = s;
    }
    if a.broadband {
        return broadband(&a, &stand);
    }
    let plan = plan(&a);
    let freqs = plan.frequencies.frequencies()?;
    let done: BTreeSet<usize> = match &a.resume {
        Some(prev) => sweep::completed_steps(prev, &plan)?,
        None => BTreeSet::new(),
    };
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create the session folder {}", a.out.display()))?;
    let path = session_path(&a.out, &a.stand);
    let opts = pipeline::SweepOptions {
        can: a.can.as_deref(),
        resume: a.resume.as_deref(),
        done,
        ctrl_c: true,
    };
    let started = Instant::now();
    let swept = pipeline::sweep(
        &stand,
        &plan,
        &path,
        &opts,
        &IndicatifProgress::new(),
        &mut note,
    )?;
    let elapsed = started.elapsed().as_secs_f64();
    let o = completed(&path, swept.finish_error, swept.outcome)?;
    let measured = o.steps.len() + o.skipped.len();
    println!("session: {}", path.display());
    println!(
        "{} of {} steps measured in {elapsed:.1} s ({} in this run, {} from {}), {} stream faults recorded, {} messages",
        measured,
        freqs.len(),
        o.steps.len(),
        o.skipped.len(),
        a.resume.as_ref().map(|p| p.display().to_string()).unwrap_or_else(|| "earlier sessions".into()),
        o.faults,
        swept.messages
    );
    let settings: Vec<u32> = o
        .steps
        .iter()
        .filter_map(|s| s.generator_settings)
        .collect();
    if let (Some(lo), Some(hi)) = (settings.iter().min(), settings.iter().max()) {
        let first = settings.first().copied().unwrap_or(0);
        let later: Vec<u32> = settings.iter().skip(1).copied().collect();
        let mean = later.iter().map(|&n| f64::from(n)).sum::<f64>() / later.len().max(1) as f64;
        println!(
            "generator settings per line (frequency, ramp, corrections): {lo} to {hi}; first line {first}, later lines {mean:.1} on average"
        );
    }
    if o.stopped || measured < freqs.len() {
        println!(
            "the sweep is incomplete; continue it with: ident sweep --stand {} --resume {}",
            a.stand.display(),
            path.display()
        );
        Ok(ExitCode::from(1))
    } else {
        Ok(ExitCode::SUCCESS)
    }
}

/// A measurement's result once its session file at `path` is complete: `Err` when the file could
/// not be completed, or when the measurement failed (the file records the failure, and stderr
/// says where it is).
fn completed<T>(
    path: &Path,
    finish_error: Option<acquire::session::SessionError>,
    outcome: Result<T, pipeline::MeasureError>,
) -> anyhow::Result<T> {
    if let Some(e) = finish_error {
        anyhow::bail!(
            "the session file {} could not be completed: {e}",
            path.display()
        );
    }
    outcome.map_err(|e| {
        eprintln!(
            "session (complete, records the failure): {}",
            path.display()
        );
        anyhow::Error::from(e)
    })
}

/// `ident sweep --broadband`: the stand's `[broadband]` plan into a new session.
fn broadband(a: &SweepArgs, stand: &Stand) -> anyhow::Result<ExitCode> {
    let plan = stand.broadband.clone().with_context(|| {
        format!(
            "--broadband: {} has no [broadband] section; add one, e.g.\n[broadband]\nwaveform = \"random\"\nfrom = \"20 Hz\"\nto = \"400 Hz\"\nforce = \"500 N\"\naverages = 8\nsettle_periods = 4",
            a.stand.display()
        )
    })?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create the session folder {}", a.out.display()))?;
    let path = session_path(&a.out, &a.stand);
    let opts = pipeline::SweepOptions {
        can: a.can.as_deref(),
        ctrl_c: true,
        ..Default::default()
    };
    let started = Instant::now();
    let swept = pipeline::broadband_sweep(
        stand,
        &plan,
        &path,
        &opts,
        &IndicatifProgress::new(),
        &mut note,
    )?;
    let elapsed = started.elapsed().as_secs_f64();
    let r = completed(&path, swept.finish_error, swept.outcome)?;
    let force = stand
        .channels
        .iter()
        .position(|c| c.kind == acquire::stand::ChannelKind::Force);
    let coherence: Vec<f64> = r
        .coherence
        .iter()
        .enumerate()
        .filter(|(c, _)| Some(*c) != force)
        .flat_map(|(_, v)| v.iter().copied())
        .collect();
    let mean = coherence.iter().sum::<f64>() / coherence.len().max(1) as f64;
    println!("session: {}", path.display());
    println!(
        "broadband {:?}: {} averages of {} lines ({:.1} to {:.1} Hz) in {elapsed:.1} s, mean coherence {mean:.3}, {} messages",
        plan.waveform,
        r.averages,
        r.freqs_hz.len(),
        r.freqs_hz.first().copied().unwrap_or(0.0),
        r.freqs_hz.last().copied().unwrap_or(0.0),
        swept.messages
    );
    if r.stopped {
        println!("stopped before all {} averages", plan.averages);
        Ok(ExitCode::from(1))
    } else {
        Ok(ExitCode::SUCCESS)
    }
}
