//! Sweeps: stepped sine with closed-loop force control and a live per-step amplitude/phase
//! estimate, broadband (random / burst random / chirp) with averages, a progress display, a clean
//! stop on Ctrl-C and resuming from the last completed step. Every block, fault and decision is
//! recorded in the session; the sweep drives `dyn Shaker` and `dyn Daq` and does not know which.

pub mod estimate;
pub mod force_loop;
pub mod period_force;
pub mod periodic;
mod progress;

pub use progress::{IndicatifProgress, NoProgress, SweepProgress};

pub use crate::record::{ChannelResult, StepResult};
pub use crate::stand::Broadband;

use std::collections::BTreeSet;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use num_complex::Complex;
use serde::{Deserialize, Serialize};

use crate::daq::{DaqError, DaqEvent, SampleBlock};
use crate::record::{
    self, BlockRecord, BroadbandChannel, BroadbandRecord, FaultRecord, SessionStart, SweepEvent,
};
use crate::rig::Rig;
use crate::session::{self, SessionError, SessionHandle};
use crate::shaker::{ForceReading, PeriodForce, ShakerError, Waveform};
use estimate::StepEstimator;
use force_loop::ForceLoop;

/// Sweep errors. Device errors keep their port and advice.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SweepError {
    /// Shaker controller.
    #[error(transparent)]
    Shaker(#[from] ShakerError),
    /// DAQ.
    #[error(transparent)]
    Daq(#[from] DaqError),
    /// Session file.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// The plan is unusable.
    #[error("sweep plan: {0}")]
    Plan(String),
    /// A step's window could not be fitted.
    #[error("step {step} ({frequency_hz:.2} Hz): {source}")]
    Estimate {
        /// Step index.
        step: usize,
        /// Frequency (Hz).
        frequency_hz: f64,
        /// Why.
        source: process::ProcessError,
    },
    /// The force channel reached the DAQ input's range: the force read from a clipped signal is
    /// too low (the loop would drive harder) and an over-force could go unseen.
    #[error("step {step} ({frequency_hz:.2} Hz): force channel `{channel}` clipped: {peak_v:.3} V peak at the DAQ's ±{range_v} V input range (daq.input_range); output switched off. Lower the target force, or give the force channel more headroom (a load cell or conditioning of lower sensitivity, a larger input range)")]
    ForceClipped {
        /// Step index.
        step: usize,
        /// Frequency (Hz).
        frequency_hz: f64,
        /// Force channel name.
        channel: String,
        /// Largest force sample of the window (V).
        peak_v: f64,
        /// The DAQ's input range (V, ±).
        range_v: f64,
    },
    /// The previous session cannot be resumed.
    #[error("cannot resume from {path}: {detail}")]
    Resume {
        /// Previous session file.
        path: String,
        /// Why.
        detail: String,
    },
}

/// How the frequencies of a stepped sine are chosen (Hz).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FrequencyList {
    /// `n` equally spaced frequencies from `start` to `stop`.
    Linear {
        /// First (Hz).
        start: f64,
        /// Last (Hz).
        stop: f64,
        /// Count.
        n: usize,
    },
    /// `n` logarithmically spaced frequencies.
    Log {
        /// First (Hz).
        start: f64,
        /// Last (Hz).
        stop: f64,
        /// Count.
        n: usize,
    },
    /// `per_resonance` frequencies within ±`relative_span` around each expected resonance.
    AroundResonances {
        /// Expected resonances (Hz).
        resonances: Vec<f64>,
        /// Half-width relative to the resonance (e.g. 0.2 = ±20 %).
        relative_span: f64,
        /// Frequencies per resonance.
        per_resonance: usize,
    },
    /// Explicit list.
    Explicit {
        /// Frequencies (Hz).
        freqs: Vec<f64>,
    },
}

impl FrequencyList {
    /// The frequencies, sorted ascending, duplicates removed.
    pub fn frequencies(&self) -> Result<Vec<f64>, SweepError> {
        let bad = |m: &str| Err(SweepError::Plan(m.to_string()));
        let mut v: Vec<f64> = match self {
            FrequencyList::Linear { start, stop, n } | FrequencyList::Log { start, stop, n } => {
                if *n == 0 || !(*start > 0.0) || !(stop >= start) {
                    return bad("need n ≥ 1 and 0 < start ≤ stop");
                }
                let n = *n;
                let log = matches!(self, FrequencyList::Log { .. });
                (0..n)
                    .map(|i| {
                        let u = if n == 1 {
                            0.0
                        } else {
                            i as f64 / (n - 1) as f64
                        };
                        if log {
                            start * (stop / start).powf(u)
                        } else {
                            start + (stop - start) * u
                        }
                    })
                    .collect()
            }
            FrequencyList::AroundResonances {
                resonances,
                relative_span,
                per_resonance,
            } => {
                if resonances.is_empty()
                    || *per_resonance == 0
                    || !(*relative_span > 0.0 && *relative_span < 1.0)
                {
                    return bad("need resonances, per_resonance ≥ 1 and 0 < relative_span < 1");
                }
                let mut v = Vec::new();
                for &r in resonances {
                    if !(r > 0.0) {
                        return bad("resonances must be > 0 Hz");
                    }
                    let (a, b) = (r * (1.0 - relative_span), r * (1.0 + relative_span));
                    // Denser near the resonance: a sine-spaced grid.
                    for i in 0..*per_resonance {
                        let u = if *per_resonance == 1 {
                            0.5
                        } else {
                            i as f64 / (*per_resonance - 1) as f64
                        };
                        let w = 0.5 - 0.5 * (std::f64::consts::PI * u).cos();
                        v.push(a + (b - a) * w);
                    }
                }
                v
            }
            FrequencyList::Explicit { freqs } => {
                if freqs.iter().any(|f| !(*f > 0.0) || !f.is_finite()) || freqs.is_empty() {
                    return bad("explicit frequencies must be finite and > 0");
                }
                freqs.clone()
            }
        };
        v.sort_by(|a, b| a.total_cmp(b));
        v.dedup_by(|a, b| (*a - *b).abs() <= 1e-9 * b.abs());
        Ok(v)
    }
}

/// A stepped-sine sweep.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SteppedSine {
    /// Frequencies.
    pub frequencies: FrequencyList,
    /// Wait after each change before measuring (s).
    pub settle_s: f64,
    /// Cycles of the excitation in each measurement window (at least `min_window_s` long).
    pub cycles: f64,
    /// Shortest measurement window (s).
    pub min_window_s: f64,
    /// Force amplitude to hold (N, peak).
    pub target_force_n: f64,
    /// Accepted relative deviation from the target (e.g. 0.03).
    pub force_tolerance: f64,
    /// Closed-loop corrections per step before measuring anyway (recorded as a warning).
    pub max_iterations: u32,
    /// Re-measurements of a step whose window was hit by a stream fault, before giving up.
    pub max_retries: u32,
}

impl SteppedSine {
    /// The operator workflows' plan (`ident sweep`, `ident demo`, `ident nightly`): `n`
    /// log-spaced lines from `start` to `stop` Hz at `force_n` N peak, settling 0.25 s and
    /// measuring 20 cycles (at least 0.25 s) per line, force held within 3 % in up to 6 corrections,
    /// up to 3 re-measurements of a faulted window.
    pub fn log(start: f64, stop: f64, n: usize, force_n: f64) -> SteppedSine {
        SteppedSine {
            frequencies: FrequencyList::Log { start, stop, n },
            settle_s: 0.25,
            cycles: 20.0,
            min_window_s: 0.25,
            target_force_n: force_n,
            force_tolerance: 0.03,
            max_iterations: 6,
            max_retries: 3,
        }
    }
}

impl Default for SteppedSine {
    fn default() -> Self {
        SteppedSine {
            frequencies: FrequencyList::Log {
                start: 20.0,
                stop: 400.0,
                n: 30,
            },
            settle_s: 0.2,
            cycles: 20.0,
            min_window_s: 0.25,
            target_force_n: 4000.0,
            force_tolerance: 0.03,
            max_iterations: 6,
            max_retries: 3,
        }
    }
}

/// A request to stop a sweep, shared with a Ctrl-C handler.
#[derive(Debug, Clone, Default)]
pub struct StopSignal(Arc<AtomicBool>);

impl StopSignal {
    /// A signal that is not set.
    pub fn new() -> Self {
        Self::default()
    }
    /// A signal set when the process receives Ctrl-C (SIGINT) or a polite stop (SIGTERM, as
    /// systemd sends). Call inside a tokio runtime. The handlers are installed before this
    /// returns, so a signal that arrives right after it is never lost to the default action
    /// (which would kill the process with the drive on).
    pub fn on_ctrl_c() -> Self {
        use tokio::signal::unix::{signal, SignalKind};
        let s = Self::new();
        for kind in [SignalKind::interrupt(), SignalKind::terminate()] {
            match signal(kind) {
                Ok(mut stream) => {
                    let t = s.clone();
                    tokio::spawn(async move {
                        if stream.recv().await.is_some() {
                            t.set();
                        }
                    });
                }
                Err(e) => tracing::warn!("cannot listen for signal {kind:?}: {e}"),
            }
        }
        s
    }
    /// Requests a stop.
    pub fn set(&self) {
        self.0.store(true, Ordering::SeqCst);
    }
    /// True once a stop was requested.
    pub fn is_set(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// How a sweep ended.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepOutcome {
    /// Steps measured in this run.
    pub steps: Vec<StepResult>,
    /// Steps skipped because a previous session completed them.
    pub skipped: Vec<usize>,
    /// True if stopped by the operator before the end.
    pub stopped: bool,
    /// Stream faults seen (all recorded).
    pub faults: u64,
}

fn event(
    s: &SessionHandle,
    kind: &str,
    step: Option<usize>,
    f: Option<f64>,
    detail: impl Into<String>,
) -> Result<(), SessionError> {
    s.record(&SweepEvent {
        kind: kind.to_string(),
        step,
        frequency_hz: f,
        detail: detail.into(),
    })
}

/// Pulls blocks from the DAQ, records every block and fault.
struct Pump<'a> {
    rig: &'a mut Rig,
    session: &'a SessionHandle,
    faults: u64,
    last_fault_sample: Option<u64>,
    next_sample: u64,
    /// When the stream started, and how many samples the DAQ produces per wall-clock second.
    started: std::time::Instant,
    samples_per_wall_s: f64,
}

impl<'a> Pump<'a> {
    fn new(rig: &'a mut Rig, session: &'a SessionHandle) -> Self {
        // The simulated stand runs `speed` times faster than real time; real devices at 1.
        let speed = rig.stand.truth.as_ref().map(|t| t.speed).unwrap_or(1.0);
        let samples_per_wall_s = rig.stream.sample_rate_hz * speed;
        Pump {
            rig,
            session,
            faults: 0,
            last_fault_sample: None,
            next_sample: 0,
            started: std::time::Instant::now(),
            samples_per_wall_s,
        }
    }

    /// The first sample the DAQ takes after now: the samples before it were taken before the
    /// last command reached the exciter, so settling counts from there. It comes from the DAQ's
    /// sample clock — the host's own where it paces the sampling
    /// ([`crate::daq::Daq::sample_clock`]), else wall-clock time since START × sample rate × the
    /// simulated stand's speed — and not from what the host has read so far: blocks that arrive
    /// late (a busy or emulated host, a buffering link) are stale however long the host took to
    /// read them. At most two seconds of stream ahead of what was read (a simulated DAQ slowed
    /// down by its host runs behind the wall clock, and its stream must not be waited for in
    /// vain).
    fn fresh_from(&self) -> u64 {
        let clock = self.rig.daq.sample_clock().unwrap_or_else(|| {
            (self.started.elapsed().as_secs_f64() * self.samples_per_wall_s) as u64
        });
        let ahead = (2.0 * self.samples_per_wall_s) as u64;
        clock.clamp(self.next_sample, self.next_sample + ahead)
    }
}

impl Pump<'_> {
    /// The next good block; faults are recorded and flagged in `fault_seen`.
    async fn next(&mut self, fault_seen: &mut bool) -> Result<SampleBlock, SweepError> {
        loop {
            match self.rig.daq.next_event().await? {
                DaqEvent::Block(b) => {
                    if b.channel_count as usize != self.rig.stand.channels.len()
                        || b.volts.len() % b.channel_count.max(1) as usize != 0
                    {
                        return Err(SweepError::Daq(DaqError::Protocol {
                            port: self.rig.daq.port().to_string(),
                            command: "stream".into(),
                            detail: format!(
                                "block of {} values in {} channels; the stand file ({}) has {} channels",
                                b.volts.len(),
                                b.channel_count,
                                self.rig.stand.file,
                                self.rig.stand.channels.len()
                            ),
                        }));
                    }
                    let n = b.len() as u64;
                    let volts: Vec<Vec<f32>> = (0..b.channel_count as usize)
                        .map(|c| b.channel(c).collect())
                        .collect();
                    self.session.record(&BlockRecord {
                        seq: b.seq,
                        first_sample: b.first_sample,
                        sample_rate_hz: Some(self.rig.stream.sample_rate_hz),
                        volts,
                    })?;
                    if b.first_sample != self.next_sample {
                        *fault_seen = true;
                    }
                    self.next_sample = b.first_sample + n;
                    return Ok(b);
                }
                DaqEvent::Fault(f) => {
                    self.faults += 1;
                    *fault_seen = true;
                    self.last_fault_sample = Some(self.next_sample);
                    self.session
                        .record(&FaultRecord::of(self.rig.daq.port(), &f))?;
                }
            }
        }
    }
}

/// Reads the steps a previous session completed (complete or truncated file), checking that it
/// ran the same plan.
pub fn completed_steps(previous: &Path, plan: &SteppedSine) -> Result<BTreeSet<usize>, SweepError> {
    let p = previous.display().to_string();
    let rep = session::read(previous).map_err(|e| SweepError::Resume {
        path: p.clone(),
        detail: e.to_string(),
    })?;
    let resume = |detail: String| SweepError::Resume {
        path: p.clone(),
        detail,
    };
    let want = serde_json::to_value(plan).map_err(|e| SweepError::Plan(e.to_string()))?;
    let starts: Vec<SessionStart> = rep.all().map_err(|e| resume(e.to_string()))?;
    match starts.first() {
        None => return Err(resume("no /session record (not a sweep session?)".into())),
        Some(s) if s.plan.as_ref() != Some(&want) => {
            return Err(resume(
                "it ran a different plan; resume with the same plan or start afresh".into(),
            ))
        }
        _ => {}
    }
    let steps: Vec<StepResult> = rep.all().map_err(|e| resume(e.to_string()))?;
    let mut done: BTreeSet<usize> = steps.iter().map(|s| s.step).collect();
    // Steps completed before that session (chained resumes).
    for s in &starts {
        done.extend(s.completed_steps_before.iter().copied());
    }
    Ok(done)
}

/// Writes the `/session` record that starts a sweep session.
pub fn log_session_start(
    s: &SessionHandle,
    stand_file: &str,
    plan: &impl Serialize,
    resumed_from: Option<&Path>,
    done: &BTreeSet<usize>,
) -> Result<(), SessionError> {
    let plan = serde_json::to_value(plan).map_err(|e| SessionError::Write {
        path: s.path().to_string(),
        detail: format!("the sweep plan cannot be recorded: {e}"),
    })?;
    s.record(&SessionStart {
        version: record::VERSION,
        software: concat!("ident-acquire ", env!("CARGO_PKG_VERSION")).into(),
        started_unix_ns: session::now_ns(),
        stand_file: stand_file.into(),
        plan: Some(plan),
        resumed_from: resumed_from.map(|p| p.display().to_string()),
        completed_steps_before: done.iter().copied().collect(),
    })
}

/// Runs a stepped-sine sweep on a connected rig, skipping `skip` (from [`completed_steps`]).
/// On a device error the output is switched off (best effort), the error is recorded and
/// returned; the caller still finishes the session so the file stays complete.
pub async fn stepped_sine(
    rig: &mut Rig,
    plan: &SteppedSine,
    session: &SessionHandle,
    progress: &dyn SweepProgress,
    stop: &StopSignal,
    skip: &BTreeSet<usize>,
) -> Result<SweepOutcome, SweepError> {
    let freqs = plan.frequencies.frequencies()?;
    if !(plan.target_force_n > 0.0) || plan.target_force_n > rig.stand.shaker.max_force_n {
        return Err(SweepError::Plan(format!(
            "target force {} N must be within 0..{} N (shaker.max_force in {})",
            plan.target_force_n, rig.stand.shaker.max_force_n, rig.stand.file
        )));
    }
    event(
        session,
        "started",
        None,
        None,
        format!(
            "stepped sine, {} steps, {} already done",
            freqs.len(),
            skip.len()
        ),
    )?;
    progress.start(freqs.len() as u64, skip.len() as u64);
    let r = stepped_inner(rig, plan, &freqs, session, progress, stop, skip).await;
    // Always try to leave the stand safe and the stream stopped.
    let off = rig.shaker.set_output(false).await;
    let stopped_daq = rig.daq.stop().await;
    drain_faults(rig, session).await?;
    match &r {
        Ok(o) if o.stopped => event(
            session,
            "stopped",
            None,
            None,
            "operator stop; output off; the sweep can be resumed",
        )?,
        Ok(_) => event(session, "completed", None, None, "all steps measured")?,
        Err(e) => event(session, "error", None, None, e.to_string())?,
    }
    if let Err(e) = &off {
        event(
            session,
            "error",
            None,
            None,
            format!("could not switch the shaker output off: {e}"),
        )?;
    }
    if let Err(e) = &stopped_daq {
        event(
            session,
            "warning",
            None,
            None,
            format!("could not stop the DAQ stream: {e}"),
        )?;
    }
    progress.finish(match &r {
        Ok(o) if o.stopped => "stopped",
        Ok(_) => "done",
        Err(_) => "failed",
    });
    let o = r?;
    off?;
    Ok(o)
}

async fn stepped_inner(
    rig: &mut Rig,
    plan: &SteppedSine,
    freqs: &[f64],
    session: &SessionHandle,
    progress: &dyn SweepProgress,
    stop: &StopSignal,
    skip: &BTreeSet<usize>,
) -> Result<SweepOutcome, SweepError> {
    let fs = rig.stream.sample_rate_hz;
    let force_ch = rig.stand.force_channel();
    let sens: Vec<f64> = rig.stand.channels.iter().map(|c| c.sensitivity).collect();
    let names: Vec<String> = rig.stand.channels.iter().map(|c| c.name.clone()).collect();
    let mut estimator = StepEstimator::new(fs, &sens, force_ch);
    let max_drive = drive_limit(&rig.stand);
    let tolerance = force_tolerance(&rig.stand, plan);
    let mut force = ForceLoop::new(&rig.stand, plan.target_force_n, tolerance, max_drive);
    let first = freqs
        .iter()
        .enumerate()
        .find(|(i, _)| !skip.contains(i))
        .map(|(_, f)| *f);
    let mut outcome = SweepOutcome {
        steps: Vec::new(),
        skipped: skip.iter().copied().collect(),
        stopped: false,
        faults: 0,
    };
    let Some(first) = first else {
        return Ok(outcome);
    };
    rig.shaker.set_waveform(&Waveform::Sine).await?;
    rig.shaker.set_frequency(first).await?;
    // Start gently: half the target until the loop has measured the path gain.
    rig.shaker
        .set_force((0.5 * plan.target_force_n).min(max_drive))
        .await?;
    rig.shaker.set_output(true).await?;
    rig.daq.start().await?;
    let mut pump = Pump::new(rig, session);

    for (step, &f) in freqs.iter().enumerate() {
        if skip.contains(&step) {
            continue;
        }
        if stop.is_set() {
            outcome.stopped = true;
            break;
        }
        let measured =
            measure_step(&mut pump, &mut estimator, plan, (step, f), &mut force, stop).await?;
        let Some(m) = measured else {
            outcome.stopped = true;
            break;
        };
        let channels = estimator.channel_results(&m.estimate, &names);
        let quality = channels.iter().map(|c| c.fit_quality).fold(1.0, f64::min);
        let res = StepResult {
            step,
            frequency_hz: f,
            drive_n: m.drive_n,
            force_amplitude_n: m.force_n,
            first_sample: m.first_sample,
            samples: m.samples,
            iterations: m.iterations,
            generator_settings: pump.rig.shaker.settings_this_line(),
            channels,
        };
        session.record(&res)?;
        event(
            session,
            "step_completed",
            Some(step),
            Some(f),
            match res.generator_settings {
                Some(n) => format!(
                    "force {:.1} N, {} corrections, {n} generator settings",
                    m.force_n, m.iterations
                ),
                None => format!("force {:.1} N, {} corrections", m.force_n, m.iterations),
            },
        )?;
        session.check()?;
        progress.step(step, f, m.force_n, quality);
        outcome.steps.push(res);
    }
    outcome.faults = pump.faults;
    Ok(outcome)
}

/// The largest drive (N) the loop commands: a shaker controller's `max_force`. A generator
/// stand's drive is volts times the amplifier's gain estimate, not a force: the exciter itself
/// refuses a drive above its voltage limit (an over-voltage stops the sweep) and stops on a
/// measured over-force, so the loop does not clip it.
fn drive_limit(stand: &crate::stand::Stand) -> f64 {
    match &stand.generator {
        Some(_) => f64::INFINITY,
        None => stand.shaker.max_force_n,
    }
}

/// The accepted relative deviation of the force from the target: the plan's, or a generator
/// stand's amplifier tolerance (2 % by default), tighter or not.
fn force_tolerance(stand: &crate::stand::Stand, plan: &SteppedSine) -> f64 {
    match &stand.generator {
        Some(g) => g.amplifier.tolerance,
        None => plan.force_tolerance,
    }
}

/// One step measured with the force held at the plan's target.
struct Measured {
    estimate: process::sine::Step,
    force_n: f64,
    drive_n: f64,
    first_sample: u64,
    samples: u64,
    iterations: u32,
}

/// Measures step `step` at `f` (Hz): sets the drive the force loop predicts, measures a window,
/// and corrects the drive until the force is within the tolerance (or the iterations run out,
/// with a warning). A window hit by a stream fault is re-measured; so is one whose force changed
/// within it (not settled: it holds no gain to learn). A clipped window is never kept: the loop
/// drives less when the target lies within the force channel's range, otherwise the sweep stops.
/// `None` when the operator stopped.
async fn measure_step(
    pump: &mut Pump<'_>,
    estimator: &mut StepEstimator,
    plan: &SteppedSine,
    (step, f): (usize, f64),
    force: &mut ForceLoop,
    stop: &StopSignal,
) -> Result<Option<Measured>, SweepError> {
    let session = pump.session;
    let fs = pump.rig.stream.sample_rate_hz;
    let tolerance = force.tolerance();
    pump.rig.shaker.set_frequency(f).await?;
    let mut drive = force.drive_n();
    pump.rig.shaker.set_force(drive).await?;
    event(
        session,
        "step_started",
        Some(step),
        Some(f),
        format!("drive {drive:.1} N"),
    )?;
    let settle = (plan.settle_s * fs).ceil() as u64;
    let window = ((plan.cycles / f).max(plan.min_window_s) * fs).ceil() as u64;
    let mut iterations = 0u32;
    let mut retries = 0u32;
    loop {
        let start = match measure_window(pump, estimator, settle, window, stop).await? {
            Window::Stopped => return Ok(None),
            Window::Fault => {
                retries += 1;
                event(session, "retry", Some(step), Some(f), format!("stream fault during the measurement window; re-measuring (attempt {retries})"))?;
                if retries > plan.max_retries {
                    return Err(SweepError::Daq(DaqError::Protocol {
                        port: pump.rig.daq.port().to_string(),
                        command: "stream".into(),
                        detail: format!("step {step} ({f:.2} Hz): {retries} measurement windows in a row hit stream faults; check the cable and the DAQ"),
                    }));
                }
                continue;
            }
            Window::Measured { first_sample } => first_sample,
        };
        let estimate = |e| SweepError::Estimate {
            step,
            frequency_hz: f,
            source: e,
        };
        let est = estimator.estimate(f).map_err(estimate)?;
        let famp = est.force.amplitude();
        pump.rig
            .shaker
            .force_measured(&ForceReading {
                step,
                frequency_hz: f,
                target_n: plan.target_force_n,
                commanded_n: drive,
                measured_n: famp,
            })
            .await?;
        let more = iterations < plan.max_iterations;
        // After the exciter's own checks (an over-force reads as such even when clipped): a
        // clipped force reads low, and the loop would take it for too small and drive harder.
        if is_clipped(pump, estimator) {
            let amplitude = estimator.clipped_force_amplitude(force.full_scale_n());
            if !(more && force.may_drive_less(amplitude)) {
                return Err(clipping_error(pump, estimator, step, f));
            }
            force.learn(amplitude, drive);
            iterations += 1;
            let why = format!("force clipped at the input range (≈ {amplitude:.0} N from the share of clipped samples)");
            drive = correct_drive(pump, force, (step, f), drive, &why).await?;
            continue;
        }
        if more && !estimator.force_settled(f, tolerance).map_err(estimate)? {
            iterations += 1;
            event(session, "retry", Some(step), Some(f), format!("force {famp:.1} N changed within the measurement window (not settled); re-measuring at drive {drive:.1} N"))?;
            continue;
        }
        force.learn(famp, drive);
        let err = (famp - plan.target_force_n).abs() / plan.target_force_n;
        if err <= tolerance || !more || famp <= 0.0 {
            if err > tolerance {
                event(session, "warning", Some(step), Some(f), format!("force {famp:.1} N not within {:.1} % of {} N after {iterations} corrections", tolerance * 100.0, plan.target_force_n))?;
            }
            return Ok(Some(Measured {
                estimate: est,
                force_n: famp,
                drive_n: drive,
                first_sample: start,
                samples: estimator.len() as u64,
                iterations,
            }));
        }
        iterations += 1;
        let why = format!("force {famp:.1} N");
        drive = correct_drive(pump, force, (step, f), drive, &why).await?;
    }
}

/// Sets the drive the force loop now predicts, recording why (`force_control`); returns it.
async fn correct_drive(
    pump: &mut Pump<'_>,
    force: &ForceLoop,
    (step, f): (usize, f64),
    drive: f64,
    why: &str,
) -> Result<f64, SweepError> {
    let new_drive = force.drive_n();
    event(
        pump.session,
        "force_control",
        Some(step),
        Some(f),
        format!("{why} → drive {drive:.1} N becomes {new_drive:.1} N"),
    )?;
    pump.rig.shaker.set_force(new_drive).await?;
    Ok(new_drive)
}

/// True when the window's force samples reached the DAQ's input range
/// ([`crate::stand::CLIP_FRACTION`] of `daq.input_range`).
fn is_clipped(pump: &Pump<'_>, estimator: &StepEstimator) -> bool {
    let range_v = pump.rig.stand.daq.input_range_v;
    estimator.force_peak_volts() >= crate::stand::CLIP_FRACTION * range_v
}

/// The error that stops a step whose force clipped.
fn clipping_error(pump: &Pump<'_>, estimator: &StepEstimator, step: usize, f: f64) -> SweepError {
    let stand = &pump.rig.stand;
    let channel = stand
        .channels
        .get(stand.force_channel())
        .map(|c| c.name.clone())
        .unwrap_or_default();
    SweepError::ForceClipped {
        step,
        frequency_hz: f,
        channel,
        peak_v: estimator.force_peak_volts(),
        range_v: stand.daq.input_range_v,
    }
}

/// How a measurement window ended.
enum Window {
    /// Complete and fault-free from this sample on.
    Measured { first_sample: u64 },
    /// A stream fault hit it.
    Fault,
    /// The operator stopped.
    Stopped,
}

/// Lets `settle` samples pass from the first sample taken after now ([`Pump::fresh_from`]; the
/// blocks before it are read and recorded), then collects `window` samples into `estimator`.
/// Faults while settling do not touch the window: it starts after them.
async fn measure_window(
    pump: &mut Pump<'_>,
    estimator: &mut StepEstimator,
    settle: u64,
    window: u64,
    stop: &StopSignal,
) -> Result<Window, SweepError> {
    if stop.is_set() {
        return Ok(Window::Stopped);
    }
    let mut fault = false;
    let start = pump.fresh_from() + settle;
    estimator.clear();
    let mut window_first = None;
    while (estimator.len() as u64) < window {
        let b = pump.next(&mut fault).await?;
        if stop.is_set() {
            break;
        }
        let nch = b.channel_count as usize;
        for i in 0..b.len() {
            let n = b.first_sample + i as u64;
            if n < start || estimator.len() as u64 >= window {
                continue;
            }
            if window_first.is_none() {
                window_first = Some(n);
                fault = false;
            }
            estimator.push_row(&b.volts[i * nch..(i + 1) * nch]);
        }
        if fault && window_first.is_some() {
            break;
        }
    }
    Ok(if stop.is_set() {
        Window::Stopped
    } else if fault {
        Window::Fault
    } else {
        Window::Measured {
            first_sample: window_first.unwrap_or(start),
        }
    })
}

/// Records the faults a DAQ still holds after STOP (decoded while waiting for its answer).
async fn drain_faults(rig: &mut Rig, session: &SessionHandle) -> Result<(), SweepError> {
    for _ in 0..10_000 {
        match tokio::time::timeout(std::time::Duration::from_millis(200), rig.daq.next_event())
            .await
        {
            Ok(Ok(DaqEvent::Fault(f))) => session.record(&FaultRecord::of(rig.daq.port(), &f))?,
            Ok(Ok(DaqEvent::Block(_))) => continue,
            _ => break,
        }
    }
    Ok(())
}

/// Result of a broadband run: H1 estimates over the band (per N) and their coherence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BroadbandResult {
    /// Frequencies (Hz).
    pub freqs_hz: Vec<f64>,
    /// Per channel (stand order), H1 = S_xF / S_FF per frequency.
    pub h1: Vec<Vec<Complex<f64>>>,
    /// Per channel, ordinary coherence per frequency.
    pub coherence: Vec<Vec<f64>>,
    /// Averages used.
    pub averages: u32,
    /// True if stopped early.
    pub stopped: bool,
}

/// Runs a broadband measurement: drives the waveform and averages whole periods (the simulated
/// and most real controllers repeat it with `period_s`). Every block is recorded.
pub async fn broadband(
    rig: &mut Rig,
    plan: &Broadband,
    session: &SessionHandle,
    progress: &dyn SweepProgress,
    stop: &StopSignal,
) -> Result<BroadbandResult, SweepError> {
    broadband_period(plan, rig.stream.sample_rate_hz)?;
    if plan.averages == 0 || !(plan.force_n > 0.0) || plan.force_n > rig.stand.shaker.max_force_n {
        return Err(SweepError::Plan(
            "broadband needs ≥ 1 average and 0 < force ≤ shaker.max_force".into(),
        ));
    }
    event(
        session,
        "started",
        None,
        None,
        format!("broadband {:?}, {} averages", plan.waveform, plan.averages),
    )?;
    progress.start(plan.averages as u64, 0);
    let r = broadband_inner(rig, plan, session, progress, stop).await;
    if let Ok(o) = &r {
        let channels = rig
            .stand
            .channels
            .iter()
            .enumerate()
            .map(|(c, ch)| BroadbandChannel {
                name: ch.name.clone(),
                h1_re: o.h1[c].iter().map(|h| h.re).collect(),
                h1_im: o.h1[c].iter().map(|h| h.im).collect(),
                coherence: o.coherence[c].clone(),
            })
            .collect();
        session.record(&BroadbandRecord {
            waveform: plan.waveform.clone(),
            force_n: plan.force_n,
            averages: o.averages,
            stopped: o.stopped,
            freqs_hz: o.freqs_hz.clone(),
            channels,
        })?;
    }
    let off = rig.shaker.set_output(false).await;
    let _ = rig.daq.stop().await;
    drain_faults(rig, session).await?;
    match &r {
        Ok(o) if o.stopped => event(session, "stopped", None, None, "operator stop")?,
        Ok(_) => event(session, "completed", None, None, "all averages measured")?,
        Err(e) => event(session, "error", None, None, e.to_string())?,
    }
    progress.finish(if r.is_ok() { "done" } else { "failed" });
    let o = r?;
    off?;
    Ok(o)
}

/// The repetition period of a broadband plan in samples at `fs`, and its band (Hz).
pub fn broadband_period(plan: &Broadband, fs: f64) -> Result<(usize, f64, f64), SweepError> {
    let (lo, hi, period) = match plan.waveform {
        Waveform::Random { f_lo_hz, f_hi_hz } => (f_lo_hz, f_hi_hz, 1.0),
        Waveform::BurstRandom {
            f_lo_hz,
            f_hi_hz,
            period_s,
            ..
        }
        | Waveform::Chirp {
            f_lo_hz,
            f_hi_hz,
            period_s,
        } => (f_lo_hz, f_hi_hz, period_s),
        Waveform::Sine => {
            return Err(SweepError::Plan(
                "broadband needs random, burst random or chirp".into(),
            ))
        }
    };
    let n = (period * fs).round() as usize;
    if n < 16 {
        return Err(SweepError::Plan(
            "period too short for the sample rate".into(),
        ));
    }
    Ok((n, lo, hi))
}

/// The averager of a broadband plan on a stream of these channels (stream order) at `fs` (Hz),
/// and the plan's band (Hz).
pub fn period_averager(
    plan: &Broadband,
    fs: f64,
    channels: &[crate::stand::Channel],
) -> Result<(periodic::PeriodAverager, f64, f64), SweepError> {
    let (n, lo, hi) = broadband_period(plan, fs)?;
    let names: Vec<&str> = channels.iter().map(|c| c.name.as_str()).collect();
    let sens: Vec<f64> = channels.iter().map(|c| c.sensitivity).collect();
    let force = crate::stand::force_channel(channels);
    let averager = periodic::PeriodAverager::new(
        fs,
        n,
        plan.settle_periods,
        plan.averages,
        &names,
        &sens,
        force,
    )
    .map_err(|e| SweepError::Plan(format!("broadband estimate: {e}")))?;
    Ok((averager, lo, hi))
}

async fn broadband_inner(
    rig: &mut Rig,
    plan: &Broadband,
    session: &SessionHandle,
    progress: &dyn SweepProgress,
    stop: &StopSignal,
) -> Result<BroadbandResult, SweepError> {
    let (mut averager, lo, hi) =
        period_averager(plan, rig.stream.sample_rate_hz, &rig.stand.channels)?;
    let (period_samples, _, _) = broadband_period(plan, rig.stream.sample_rate_hz)?;
    let force_channel = rig.stand.force_channel();
    let mut force = period_force::PeriodForceMonitor::new(
        period_samples,
        force_channel,
        rig.stand.channels.len(),
        rig.stand.channels[force_channel].sensitivity,
    );
    rig.shaker.set_waveform(&plan.waveform).await?;
    rig.shaker.set_force(plan.force_n).await?;
    rig.shaker.set_output(true).await?;
    rig.daq.start().await?;
    let mut pump = Pump::new(rig, session);
    let mut stopped = false;
    let mut fault = false;
    while !averager.done() {
        if stop.is_set() {
            stopped = true;
            break;
        }
        let b = pump.next(&mut fault).await?;
        if std::mem::take(&mut fault) {
            averager.fault();
        }
        let completed = averager
            .push_block(b.first_sample, &b.volts)
            .map_err(|e| SweepError::Plan(format!("broadband estimate: {e}")))?;
        // Every whole period's force to the exciter: limits, and the loop while settling.
        for p in force.push_block(b.first_sample, &b.volts) {
            let reading = PeriodForce {
                period: p.period,
                target_n: plan.force_n,
                rms_n: p.rms_n,
                peak_n: p.peak_n,
                may_adjust: p.period + 2 <= u64::from(plan.settle_periods),
            };
            if pump.rig.shaker.period_force_measured(&reading).await? {
                event(
                    session,
                    "force_control",
                    None,
                    None,
                    format!(
                        "period {}: force {:.1} N RMS, drive corrected",
                        p.period, p.rms_n
                    ),
                )?;
            }
        }
        if completed > 0 {
            let done = averager.averages();
            let coh = averager.mean_coherence(lo, hi);
            event(
                session,
                "average",
                Some(done as usize),
                None,
                format!("mean coherence {coh:.3}"),
            )?;
            progress.step(done as usize - 1, hi, plan.force_n, coh);
        }
    }
    let e = averager
        .estimate(lo, hi)
        .map_err(|e| SweepError::Plan(format!("broadband estimate: {e}")))?;
    Ok(BroadbandResult {
        freqs_hz: e.freqs_hz,
        h1: e.h1,
        coherence: e.coherence,
        averages: e.averages,
        stopped,
    })
}
