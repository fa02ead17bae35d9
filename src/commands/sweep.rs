//! `ident sweep --stand FILE [--out DIR] [--resume SESSION]`: a stepped-sine sweep of a stand into
//! a new session file `DIR/<stand>-<UTC time>.mcap`, with a live progress line (step, frequency,
//! force, fit quality). Ctrl-C stops after the current step and still leaves a complete file that
//! `--resume` continues. Ports given as `"sim"` are served by the simulated stand (`--can IFACE`
//! puts its DAQ on CAN).
//!
//! Exit status: 0 every step measured; 1 the sweep is incomplete (stopped; resume it);
//! 2 failure (device, file or plan; the session file is still complete and says what happened).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use acquire::rig::Rig;
use acquire::session::{Session, SessionOptions};
use acquire::sim::SimStand;
use acquire::stand::{PortSpec, Stand};
use acquire::sweep::{self, FrequencyList, IndicatifProgress, SteppedSine, StopSignal};
use anyhow::Context;

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
}

/// The plan `ident sweep` runs (also what `--resume` checks against).
pub fn plan(a: &SweepArgs) -> SteppedSine {
    SteppedSine {
        frequencies: FrequencyList::Log { start: a.from, stop: a.to, n: a.points },
        settle_s: 0.25,
        cycles: 20.0,
        min_window_s: 0.25,
        target_force_n: a.force,
        force_tolerance: 0.03,
        max_iterations: 6,
        max_retries: 3,
    }
}

/// `YYYYmmddTHHMMSSZ` for a Unix time (s), UTC.
fn utc_stamp(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}{m:02}{d:02}T{:02}{:02}{:02}Z", rem / 3600, rem % 3600 / 60, rem % 60)
}

fn session_path(dir: &Path, stand_file: &Path) -> PathBuf {
    let stem = stand_file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "stand".into());
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    let base = format!("{stem}-{}", utc_stamp(secs));
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
        anyhow::ensure!(s.is_finite() && s > 0.0, "--speed {s}: give a factor > 0 (1 = real time)");
        let t = stand.truth.as_mut().with_context(|| format!("--speed: {} has no [truth] section (only the simulated stand runs faster than real time)", a.stand.display()))?;
        t.speed = s;
    }
    let plan = plan(&a);
    let freqs = plan.frequencies.frequencies()?;
    let done: BTreeSet<usize> = match &a.resume {
        Some(prev) => sweep::completed_steps(prev, &plan)?,
        None => BTreeSet::new(),
    };
    std::fs::create_dir_all(&a.out).with_context(|| format!("cannot create the session folder {}", a.out.display()))?;
    let path = session_path(&a.out, &a.stand);
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().context("cannot start the async runtime")?;
    rt.block_on(async move {
        let uses_sim = stand.shaker.port == PortSpec::Sim || stand.daq.port == PortSpec::Sim;
        let sim = match (uses_sim, &a.can) {
            (true, Some(iface)) => Some(SimStand::start_can(&stand, iface)?),
            (true, None) => Some(SimStand::start(&stand)?),
            (false, Some(_)) => anyhow::bail!("--can serves the simulated DAQ; {} has no port = \"sim\" (give daq.port = \"can:IFACE\" for a real CAN DAQ)", a.stand.display()),
            (false, None) => None,
        };
        let bound = match &sim {
            Some(s) => {
                eprintln!("ident sweep: simulated stand at {}× real time: shaker {}, daq {}", stand.truth.as_ref().map(|t| t.speed).unwrap_or(1.0), s.shaker_port, s.daq_port);
                s.bind(&stand)
            }
            None => stand.clone(),
        };
        let session = Session::create(&path, SessionOptions::default())?;
        let h = session.handle();
        eprintln!("ident sweep: recording {}", path.display());
        let stop = StopSignal::on_ctrl_c();
        let progress = IndicatifProgress::new();
        let started = Instant::now();
        let result = async {
            sweep::log_session_start(&h, &stand.file, &plan, a.resume.as_deref(), &done)?;
            let mut rig = Rig::connect(&bound, Some(&h)).await?;
            Ok::<_, anyhow::Error>(sweep::stepped_sine(&mut rig, &plan, &h, &progress, &stop, &done).await?)
        }
        .await;
        let finished = session.finish();
        let elapsed = started.elapsed().as_secs_f64();
        if let Some(s) = sim {
            s.shutdown();
        }
        let summary = finished.with_context(|| format!("the session file {} could not be completed", path.display()))?;
        match result {
            Ok(o) => {
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
                    summary.total()
                );
                if o.stopped || measured < freqs.len() {
                    println!("the sweep is incomplete; continue it with: ident sweep --stand {} --resume {}", a.stand.display(), path.display());
                    Ok(ExitCode::from(1))
                } else {
                    Ok(ExitCode::SUCCESS)
                }
            }
            Err(e) => {
                eprintln!("session (complete, records the failure): {}", path.display());
                Err(e)
            }
        }
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn utc_stamps_are_civil_dates() {
        assert_eq!(super::utc_stamp(0), "19700101T000000Z");
        assert_eq!(super::utc_stamp(951_782_400), "20000229T000000Z");
        assert_eq!(super::utc_stamp(1_700_000_000), "20231114T221320Z");
    }
}
