//! From a session file to measured characteristics: what `ident process`, `ident replay`,
//! `ident nightly` and `ident demo` call after a sweep.
//!
//! [`characteristics`] reads a session MCAP (complete or truncated) and uses nothing but what is
//! recorded in it — the stand's channel map and calibration and the geometry of the bodies the
//! sensors are on (`/stand`), the raw sample blocks (`/daq/block`), the steps' measurement windows
//! (`/sweep/step`), faults and retries. For every completed stepped-sine step it
//!
//! 1. re-fits each channel's amplitude and phase from the raw blocks of the step's window with the
//!    same [`StepEstimator`] the live sweep used (so a replay is bit-identical to the live run, and
//!    each step says whether it matched the live record),
//! 2. forms each accelerometer's FRF (m/s² per N) and converts it to the wanted quantity
//!    (receptance by default: `H / (−ω²)`),
//! 3. fits each body's rigid-body motion at its centre of mass in its principal central axes
//!    ([`process::principal::RigidFit`]; translations when the layout cannot observe rotations),
//!    with the rigidity residual, and
//! 4. scales to the model's nominal excitation into [`rfe::MeasuredData`]
//!    ([`process::selection::to_measurement`]), with each point's variance.
//!
//! A broadband session is replayed through the live sweep's
//! [`crate::sweep::periodic::PeriodAverager`] instead, each line of its band taking the place of a
//! step (H1 per N, with its coherence and variance); steps 2-4 are the same.
//!
//! Steps that cannot be used are listed in [`SessionAnalysis::dropped`] with the reason; nothing
//! is dropped silently. The output is deterministic: the same file gives bit-identical results.
//!
//! ```no_run
//! use acquire::analysis::{characteristics, AnalysisOptions};
//!
//! let a = characteristics(std::path::Path::new("session.mcap"), &AnalysisOptions::default())?;
//! for m in &a.measured.characteristics {
//!     println!("{} dof {}: {} points", m.body, m.dof, m.freqs_hz.len());
//! }
//! for d in &a.dropped {
//!     eprintln!("step {} ({:.1} Hz) not used: {}", d.step, d.frequency_hz, d.reason);
//! }
//! # Ok::<(), acquire::analysis::AnalysisError>(())
//! ```

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use num_complex::Complex;
use process::principal::{Dofs, RigidFit, Sensor};
use process::selection::{to_measurement, CharacteristicSpec};
use rfe::{MeasuredData, Quantity};
use serde::Serialize;

use crate::record::TopicRecord;
use crate::record::{
    BlockRecord, BroadbandRecord, DaqStreamRecord, FaultRecord, SessionStart, StandRecord,
    SweepEvent,
};
use crate::session::{self, ReadReport, SessionError};
use crate::stand::{BodyGeometry, Channel, ChannelKind, Geometry, Stand};
use crate::sweep::estimate::StepEstimator;
use crate::sweep::{Broadband, ChannelResult, StepResult};

type C64 = Complex<f64>;

/// Why a session could not be analysed. Each names the file and says what to do.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AnalysisError {
    /// The file could not be read.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// Something the analysis needs is not in the file.
    #[error("{path}: {what}; {fix}")]
    Missing {
        /// Session file.
        path: String,
        /// What is missing.
        what: String,
        /// What to do.
        fix: String,
    },
    /// The recorded data contradict each other (e.g. the channel map).
    #[error("{path}: {detail}")]
    Inconsistent {
        /// Session file.
        path: String,
        /// What does not fit.
        detail: String,
    },
    /// The geometry given in the options could not be used.
    #[error("{path}: geometry: {detail}")]
    Geometry {
        /// Session file.
        path: String,
        /// Why.
        detail: String,
    },
    /// Processing failed (degenerate sensor layout, bad values).
    #[error("{path}: {context}: {source}")]
    Process {
        /// Session file.
        path: String,
        /// Which body or characteristic.
        context: String,
        /// Why.
        source: process::ProcessError,
    },
}

/// How to analyse a session.
#[derive(Debug, Clone)]
pub struct AnalysisOptions {
    /// A model file whose bodies replace the geometry recorded in the session (sessions recorded
    /// before geometry was recorded, or a corrected geometry). Never the truth model.
    pub geometry_model: Option<PathBuf>,
    /// Quantity of the characteristics; `None` (default): the geometry model's declared outputs'
    /// quantity, displacement (receptance) where it declares none.
    pub quantity: Option<Quantity>,
    /// Which DOFs to fit per body (default: six if the layout observes them, else translations).
    pub dofs: Dofs,
}

impl Default for AnalysisOptions {
    fn default() -> Self {
        AnalysisOptions {
            geometry_model: None,
            quantity: None,
            dofs: Dofs::Auto,
        }
    }
}

/// One step as recomputed from the raw blocks.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepAnalysis {
    /// Step index in the plan.
    pub step: usize,
    /// Frequency (Hz).
    pub frequency_hz: f64,
    /// First sample of the measurement window (since START).
    pub first_sample: u64,
    /// Samples in the window.
    pub samples: u64,
    /// Measured force amplitude (N).
    pub force_amplitude_n: f64,
    /// Per channel (stream order): amplitude, phase, FRF (per N), noise, FRF variance.
    pub channels: Vec<ChannelResult>,
    /// Per body: rigidity residual `‖y − A q‖/‖y‖` of the principal-axis fit (0 = rigid).
    pub rigidity: Vec<BodyResidual>,
    /// Stream faults recorded since the previous step (while this step was being measured).
    pub faults: u32,
    /// Measurement windows of this step re-measured after a fault.
    pub retries: u32,
    /// True if the recomputation equals the live estimate recorded in `/sweep/step`, bit for bit.
    pub matches_live: bool,
}

/// A body's rigidity residual at a step.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BodyResidual {
    /// Body name.
    pub body: String,
    /// `‖y − A q‖/‖y‖`.
    pub residual: f64,
}

/// A recorded step that is not in the characteristics, and why.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DroppedStep {
    /// Step index.
    pub step: usize,
    /// Frequency (Hz).
    pub frequency_hz: f64,
    /// Why it was not used.
    pub reason: String,
}

/// A stream fault recorded in the session.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecordedFault {
    /// `gap`, `crc`, `duplicate`, ...
    pub kind: String,
    /// Sequence number, if known.
    pub seq: Option<u64>,
    /// Detail.
    pub detail: String,
}

/// Everything [`characteristics`] found in a session.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SessionAnalysis {
    /// Session file.
    pub session: String,
    /// Stand name.
    pub stand: String,
    /// Sample rate (Hz).
    pub sample_rate_hz: f64,
    /// The recorded channel map (stream order).
    pub channels: Vec<Channel>,
    /// Geometry used (recorded, or from [`AnalysisOptions::geometry_model`]).
    pub geometry: Geometry,
    /// The measured characteristics (identification input).
    pub measured: MeasuredData,
    /// Every usable step, in frequency order.
    pub steps: Vec<StepAnalysis>,
    /// Steps not used, with reasons.
    pub dropped: Vec<DroppedStep>,
    /// All stream faults recorded.
    pub faults: Vec<RecordedFault>,
    /// Why the file ended early (`None` if complete).
    pub truncated: Option<String>,
    /// Things the operator should know (e.g. a declared output the sensor layout cannot observe).
    pub notes: Vec<String>,
}

/// Reads a session and computes its measured characteristics (see the module docs).
pub fn characteristics(
    session_path: &Path,
    opts: &AnalysisOptions,
) -> Result<SessionAnalysis, AnalysisError> {
    let cx = Cx {
        path: session_path.display().to_string(),
    };
    let rep = session::read(session_path)?;
    let stand: StandRecord = rep.first()?.ok_or_else(|| {
        cx.missing(
            "no /stand record",
            "the session was not written by a sweep (or was cut before the stand was recorded)",
        )
    })?;
    let force_channel = check_channels(&stand, &cx)?;
    let geometry = geometry(&stand, opts, &cx)?;
    let fs = sample_rate(&rep, &stand, &cx)?;
    let broadband: Option<BroadbandRecord> = rep.first()?;
    let mut replayed = match &broadband {
        Some(live) => replay_broadband(&rep, &stand, fs, live, &cx)?,
        None => replay_steps(&rep, &stand, force_channel, fs, &cx)?,
    };
    let steps = first_per_frequency(replayed.steps, &mut replayed.dropped);
    if steps.is_empty() {
        return Err(cx.missing(
            "no usable stepped-sine step in the session",
            if replayed.dropped.is_empty() {
                "run a sweep (`ident sweep`) first"
            } else {
                "see why each step was dropped (ident process prints them)"
            },
        ));
    }
    let mut steps = steps;
    let mut notes = Vec::new();
    let mut measured = Vec::new();
    for g in &geometry.bodies {
        measured.extend(body_characteristics(
            g,
            &stand.channels,
            &geometry,
            opts,
            &mut steps,
            &mut notes,
            &cx,
        )?);
    }
    if measured.is_empty() {
        return Err(cx.inconsistent(format!(
            "no accelerometer is on a body of the geometry ({}); check the channels' `body` against [geometry] model",
            geometry.bodies.iter().map(|b| b.name.as_str()).collect::<Vec<_>>().join(", ")
        )));
    }
    let source = format!(
        "session {} (stand {:?}): {} {}, {} dropped; response to the model's excitation ({} N), principal axes from {}",
        cx.path,
        stand.name,
        steps.len(),
        if broadband.is_some() {
            "broadband lines (H1)"
        } else {
            "stepped-sine steps"
        },
        replayed.dropped.len(),
        rfe::display::sig(geometry.nominal_force_n, 6),
        geometry.source
    );
    Ok(SessionAnalysis {
        session: cx.path.clone(),
        stand: stand.name,
        sample_rate_hz: fs,
        channels: stand.channels,
        geometry,
        measured: MeasuredData {
            source,
            characteristics: measured,
        },
        steps,
        dropped: replayed.dropped,
        faults: replayed.faults,
        truncated: rep.truncated,
        notes,
    })
}

/// The session file being analysed, for errors.
struct Cx {
    path: String,
}

impl Cx {
    fn missing(&self, what: &str, fix: &str) -> AnalysisError {
        AnalysisError::Missing {
            path: self.path.clone(),
            what: what.into(),
            fix: fix.into(),
        }
    }

    fn inconsistent(&self, detail: String) -> AnalysisError {
        AnalysisError::Inconsistent {
            path: self.path.clone(),
            detail,
        }
    }

    fn geometry(&self, detail: String) -> AnalysisError {
        AnalysisError::Geometry {
            path: self.path.clone(),
            detail,
        }
    }
}

/// Checks the recorded channel map; returns the index of its one force channel.
fn check_channels(stand: &StandRecord, cx: &Cx) -> Result<usize, AnalysisError> {
    if let Some(i) = stand
        .channels
        .iter()
        .position(|c| !(c.sensitivity.is_finite() && c.sensitivity > 0.0))
    {
        return Err(cx.inconsistent(format!(
            "/stand channel {i}: field `sensitivity` missing or malformed"
        )));
    }
    let forces: Vec<usize> = (0..stand.channels.len())
        .filter(|&i| stand.channels[i].kind == ChannelKind::Force)
        .collect();
    match forces[..] {
        [f] => Ok(f),
        _ => Err(cx.inconsistent(format!(
            "/stand has {} force channels; exactly one is needed as the FRFs' reference",
            forces.len()
        ))),
    }
}

/// The bodies' geometry: from `opts.geometry_model` if given, else as recorded.
fn geometry(
    stand: &StandRecord,
    opts: &AnalysisOptions,
    cx: &Cx,
) -> Result<Geometry, AnalysisError> {
    if let Some(model) = &opts.geometry_model {
        if stand.text.is_empty() {
            return Err(cx.missing(
                "the /stand record has no stand-file text",
                "re-record the session",
            ));
        }
        let file = if stand.file.is_empty() {
            "recorded stand"
        } else {
            &stand.file
        };
        let mut st = Stand::parse(&stand.text, file).map_err(|e| cx.geometry(e.to_string()))?;
        st.geometry_model = Some(model.clone());
        st.resolve_geometry(crate::stand::SENSOR_MOUNT_TOLERANCE_M)
            .map_err(|e| cx.geometry(e.to_string()))?;
        return st
            .geometry
            .ok_or_else(|| cx.geometry("no geometry resolved".into()));
    }
    stand.geometry.clone().ok_or_else(|| {
        cx.missing(
            "the session records no body geometry (its stand file has no [geometry] model)",
            "add `[geometry] model = \"../models/<identification model>.toml\"` to the stand file for future sessions, or pass the model (`ident process --geometry MODEL`)",
        )
    })
}

/// The stream's sample rate (Hz), checking that its channels are the stand's.
fn sample_rate(rep: &ReadReport, stand: &StandRecord, cx: &Cx) -> Result<f64, AnalysisError> {
    let stream: DaqStreamRecord = rep.first()?.ok_or_else(|| {
        cx.missing(
            "no /daq/stream record",
            "the DAQ was never configured in this session; nothing was measured",
        )
    })?;
    if !(stream.sample_rate_hz > 0.0) {
        return Err(cx.inconsistent("/daq/stream has no sample rate".into()));
    }
    if let Some(got) = &stream.names {
        let want: Vec<&str> = stand.channels.iter().map(|c| c.name.as_str()).collect();
        if *got != want {
            return Err(cx.inconsistent(format!(
                "the DAQ stream's channels {got:?} are not the stand's channel map {want:?}"
            )));
        }
    }
    Ok(stream.sample_rate_hz)
}

/// What replaying the records gave: the recomputed steps, the dropped ones and the faults.
struct Replayed {
    steps: Vec<StepAnalysis>,
    dropped: Vec<DroppedStep>,
    faults: Vec<RecordedFault>,
}

/// The blocks of the current stream run (since the last START), samples interleaved by channel.
struct StreamRun {
    channels: usize,
    blocks: Vec<(u64, Vec<f32>)>,
}

impl StreamRun {
    /// Adds a block; a block that does not start after the last one starts a new run.
    fn push(&mut self, block: &BlockRecord, cx: &Cx) -> Result<(), AnalysisError> {
        let nch = self.channels;
        if block.volts.len() != nch {
            return Err(cx.inconsistent(format!(
                "/daq/block seq {} does not have the stand's {nch} channels",
                block.seq
            )));
        }
        let len = block.volts[0].len();
        if block.volts.iter().any(|v| v.len() != len) {
            return Err(cx.inconsistent(format!(
                "/daq/block seq {}: channels differ in length",
                block.seq
            )));
        }
        let mut data = vec![0f32; len * nch];
        for (c, v) in block.volts.iter().enumerate() {
            for (i, x) in v.iter().enumerate() {
                data[i * nch + c] = *x;
            }
        }
        if self
            .blocks
            .last()
            .is_some_and(|(f, _)| block.first_sample <= *f)
        {
            self.blocks.clear(); // the stream restarted (a new START)
        }
        self.blocks.push((block.first_sample, data));
        Ok(())
    }

    /// Feeds samples `first .. first + n` to `estimator`; `Err(s)` names the first sample that
    /// is not in the run.
    fn feed(&self, first: u64, n: u64, estimator: &mut StepEstimator) -> Result<(), u64> {
        let nch = self.channels;
        let mut k = self
            .blocks
            .partition_point(|(b0, d)| b0 + (d.len() / nch.max(1)) as u64 <= first);
        let mut s = first;
        while s < first + n {
            let Some((b0, d)) = self.blocks.get(k) else {
                return Err(s);
            };
            let len = (d.len() / nch) as u64;
            if s < *b0 || s >= b0 + len {
                return Err(s);
            }
            let i = (s - b0) as usize;
            estimator.push_row(&d[i * nch..(i + 1) * nch]);
            s += 1;
            if s >= b0 + len {
                k += 1;
            }
        }
        Ok(())
    }
}

/// Walks the records in file order and re-fits every `/sweep/step` from the raw blocks of its
/// window with the live sweep's estimator.
fn replay_steps(
    rep: &ReadReport,
    stand: &StandRecord,
    force_channel: usize,
    fs: f64,
    cx: &Cx,
) -> Result<Replayed, AnalysisError> {
    let sens: Vec<f64> = stand.channels.iter().map(|c| c.sensitivity).collect();
    let names: Vec<String> = stand.channels.iter().map(|c| c.name.clone()).collect();
    let mut estimator = StepEstimator::new(fs, &sens, force_channel);
    let mut run = StreamRun {
        channels: names.len(),
        blocks: Vec::new(),
    };
    let mut out = Replayed {
        steps: Vec::new(),
        dropped: Vec::new(),
        faults: Vec::new(),
    };
    let mut faults_since_step = 0u32;
    let mut retries: std::collections::BTreeMap<usize, u32> = Default::default();
    let mut index = [0usize; 4];
    for r in &rep.records {
        if r.is::<BlockRecord>() {
            let block = decode::<BlockRecord>(rep, r, &mut index[0])?;
            run.push(&block, cx)?;
        } else if r.is::<FaultRecord>() {
            let f = decode::<FaultRecord>(rep, r, &mut index[1])?;
            faults_since_step += 1;
            out.faults.push(RecordedFault {
                kind: f.kind,
                seq: f.seq,
                detail: f.detail,
            });
        } else if r.is::<SweepEvent>() {
            let e = decode::<SweepEvent>(rep, r, &mut index[2])?;
            if let ("retry", Some(s)) = (e.kind.as_str(), e.step) {
                *retries.entry(s).or_default() += 1;
            }
        } else if r.is::<StepResult>() {
            let live = decode::<StepResult>(rep, r, &mut index[3])?;
            let step_faults = std::mem::take(&mut faults_since_step);
            let step = live.step;
            estimator.clear();
            if let Err(s) = run.feed(live.first_sample, live.samples, &mut estimator) {
                out.dropped.push(DroppedStep {
                    step,
                    frequency_hz: live.frequency_hz,
                    reason: format!("samples {s}.. of its window {}..{} are not in the file (blocks lost or file truncated)", live.first_sample, live.first_sample + live.samples),
                });
                continue;
            }
            match recompute_step(&mut estimator, &live, &names) {
                Ok(mut s) => {
                    s.faults = step_faults;
                    s.retries = retries.get(&step).copied().unwrap_or(0);
                    out.steps.push(s);
                }
                Err(e) => out.dropped.push(DroppedStep {
                    step,
                    frequency_hz: live.frequency_hz,
                    reason: format!("sine fit failed: {e}"),
                }),
            }
        }
    }
    Ok(out)
}

/// Replays a broadband session: the blocks go through the live sweep's
/// [`crate::sweep::periodic::PeriodAverager`] with the recorded plan, faults marking their period,
/// and each line of the band becomes a "step" (frequency, every channel's H1 per N, its
/// coherence as `fit_quality` and its variance); `matches_live` says whether the line equals the
/// recorded `/sweep/broadband` estimate bit for bit.
fn replay_broadband(
    rep: &ReadReport,
    stand: &StandRecord,
    fs: f64,
    live: &BroadbandRecord,
    cx: &Cx,
) -> Result<Replayed, AnalysisError> {
    let start: SessionStart = rep
        .first()?
        .ok_or_else(|| cx.missing("no /session record", "re-record the session"))?;
    let plan: Broadband = start
        .plan
        .clone()
        .and_then(|p| serde_json::from_value(p).ok())
        .ok_or_else(|| {
            cx.inconsistent("the /session plan is not a broadband plan, but the session has a /sweep/broadband record".into())
        })?;
    let (mut averager, lo, hi) = crate::sweep::period_averager(&plan, fs, &stand.channels)
        .map_err(|e| cx.inconsistent(e.to_string()))?;
    let nch = stand.channels.len();
    let mut out = Replayed {
        steps: Vec::new(),
        dropped: Vec::new(),
        faults: Vec::new(),
    };
    let mut index = [0usize; 2];
    let mut interleaved = Vec::new();
    for r in &rep.records {
        if r.is::<BlockRecord>() {
            let b = decode::<BlockRecord>(rep, r, &mut index[0])?;
            if b.volts.len() != nch || b.volts.iter().any(|v| v.len() != b.volts[0].len()) {
                return Err(cx.inconsistent(format!(
                    "/daq/block seq {} does not have the stand's {nch} channels of equal length",
                    b.seq
                )));
            }
            interleaved.clear();
            for i in 0..b.volts[0].len() {
                interleaved.extend(b.volts.iter().map(|v| v[i]));
            }
            averager
                .push_block(b.first_sample, &interleaved)
                .map_err(|e| cx.inconsistent(format!("broadband estimate: {e}")))?;
        } else if r.is::<FaultRecord>() {
            let f = decode::<FaultRecord>(rep, r, &mut index[1])?;
            averager.fault();
            out.faults.push(RecordedFault {
                kind: f.kind,
                seq: f.seq,
                detail: f.detail,
            });
        }
    }
    if averager.averages() == 0 {
        return Err(cx.missing(
            "no complete period of the broadband drive in the file",
            "record longer (more averages) or check the stream faults",
        ));
    }
    let e = averager
        .estimate(lo, hi)
        .map_err(|e| cx.inconsistent(format!("broadband estimate: {e}")))?;
    out.steps = broadband_lines(&e, live, &stand.channels);
    Ok(out)
}

/// Each line of the replayed broadband estimate `e` as a step (H1 per N, coherence as
/// `fit_quality`, variance), with whether it equals the `live` record bit for bit.
fn broadband_lines(
    e: &crate::sweep::periodic::PeriodicFrf,
    live: &BroadbandRecord,
    channels: &[Channel],
) -> Vec<StepAnalysis> {
    let nch = channels.len();
    let mut steps = Vec::with_capacity(e.freqs_hz.len());
    for (k, f) in e.freqs_hz.iter().enumerate() {
        let channels: Vec<ChannelResult> = (0..nch)
            .map(|c| {
                let h = e.h1[c][k];
                ChannelResult {
                    name: channels[c].name.clone(),
                    // A broadband line has no response amplitude of its own: per N only.
                    amplitude: f64::NAN,
                    phase_rad: h.arg(),
                    frf_re: h.re,
                    frf_im: h.im,
                    fit_quality: e.coherence[c][k],
                    noise_rms: f64::NAN,
                    frf_variance: e.variance[c][k],
                }
            })
            .collect();
        let matches_live = live.freqs_hz.get(k).map(|x| x.to_bits()) == Some(f.to_bits())
            && live.channels.len() == nch
            && live.channels.iter().zip(&channels).all(|(l, c)| {
                l.name == c.name
                    && l.h1_re.get(k).map(|x| x.to_bits()) == Some(c.frf_re.to_bits())
                    && l.h1_im.get(k).map(|x| x.to_bits()) == Some(c.frf_im.to_bits())
            });
        steps.push(StepAnalysis {
            step: k,
            frequency_hz: *f,
            first_sample: 0,
            samples: 0,
            force_amplitude_n: f64::NAN,
            channels,
            rigidity: Vec::new(),
            faults: 0,
            retries: 0,
            matches_live,
        });
    }
    steps
}

/// Decodes record `r` as `R`, counting `R`'s records in `index` for the error.
fn decode<R: TopicRecord>(
    rep: &ReadReport,
    r: &session::Record,
    index: &mut usize,
) -> Result<R, AnalysisError> {
    let i = *index;
    *index += 1;
    Ok(r.decode().map_err(|e| rep.malformed::<R>(i, e))?)
}

/// The step `live` recomputed from the samples fed to `estimator`; `Err` when the sine fit fails.
fn recompute_step(
    estimator: &mut StepEstimator,
    live: &StepResult,
    names: &[String],
) -> Result<StepAnalysis, process::ProcessError> {
    let est = estimator.estimate(live.frequency_hz)?;
    let results = estimator.channel_results(&est, names);
    let matches_live = live.channels.len() == results.len()
        && live.channels.iter().zip(&results).all(|(a, b)| {
            a.name == b.name
                && a.frf_re.to_bits() == b.frf_re.to_bits()
                && a.frf_im.to_bits() == b.frf_im.to_bits()
                && a.amplitude.to_bits() == b.amplitude.to_bits()
        });
    Ok(StepAnalysis {
        step: live.step,
        frequency_hz: live.frequency_hz,
        first_sample: live.first_sample,
        samples: live.samples,
        force_amplitude_n: est.force.amplitude(),
        channels: results,
        rigidity: Vec::new(),
        faults: 0,
        retries: 0,
        matches_live,
    })
}

/// Sorts `steps` by frequency; a frequency measured twice keeps its first measurement, the
/// others go to `dropped` (which ends sorted by step).
fn first_per_frequency(
    mut steps: Vec<StepAnalysis>,
    dropped: &mut Vec<DroppedStep>,
) -> Vec<StepAnalysis> {
    steps.sort_by(|a, b| {
        a.frequency_hz
            .total_cmp(&b.frequency_hz)
            .then(a.step.cmp(&b.step))
    });
    let mut kept: Vec<StepAnalysis> = Vec::with_capacity(steps.len());
    for s in steps {
        match kept.last() {
            Some(p) if s.frequency_hz <= p.frequency_hz => dropped.push(DroppedStep {
                step: s.step,
                frequency_hz: s.frequency_hz,
                reason: format!(
                    "frequency already measured by step {}; the first measurement is used",
                    p.step
                ),
            }),
            _ => kept.push(s),
        }
    }
    dropped.sort_by_key(|d| d.step);
    kept
}

/// Body `g`'s characteristics: its accelerometers' FRFs fitted to its rigid-body motion in its
/// principal central axes, for the outputs the geometry declares on it (or every observed DOF),
/// in the wanted quantity. Adds each step's rigidity residual to `steps`.
fn body_characteristics(
    g: &BodyGeometry,
    channels: &[Channel],
    geometry: &Geometry,
    opts: &AnalysisOptions,
    steps: &mut [StepAnalysis],
    notes: &mut Vec<String>,
    cx: &Cx,
) -> Result<Vec<rfe::Measurement>, AnalysisError> {
    let idx: Vec<usize> = (0..channels.len())
        .filter(|&c| {
            channels[c].kind != ChannelKind::Force
                && channels[c].body.as_deref() == Some(g.name.as_str())
        })
        .collect();
    if idx.is_empty() {
        return Ok(Vec::new());
    }
    let sensors: Vec<Sensor> = idx
        .iter()
        .map(|&c| Sensor {
            name: channels[c].name.clone(),
            position: Vector3::from(channels[c].position_m),
            direction: Vector3::from(channels[c].direction),
        })
        .collect();
    let body = g.to_body();
    let process_err = |context: String| {
        move |source| AnalysisError::Process {
            path: cx.path.clone(),
            context: context.clone(),
            source,
        }
    };
    let body_err = process_err(format!("body `{}`", g.name));
    let fit = RigidFit::new(&body, &sensors, opts.dofs).map_err(&body_err)?;
    // Rigid-body fit of the accelerances (m/s² or rad/s² per N); linear, so quantities are
    // converted afterwards.
    let mut q_lines = Vec::with_capacity(steps.len());
    let mut var_lines = Vec::with_capacity(steps.len());
    let mut y = vec![C64::default(); idx.len()];
    let mut yv = vec![0.0; idx.len()];
    for s in steps.iter_mut() {
        for (k, &c) in idx.iter().enumerate() {
            let ch = &s.channels[c];
            y[k] = C64::new(ch.frf_re, ch.frf_im);
            yv[k] = ch.frf_variance;
        }
        let mut q = [C64::default(); 6];
        let residual = fit.fit_line(&y, &mut q).map_err(&body_err)?;
        s.rigidity.push(BodyResidual {
            body: g.name.clone(),
            residual,
        });
        q_lines.push(q);
        var_lines.push(fit.variance(&yv).map_err(&body_err)?);
    }
    let freqs: Vec<f64> = steps.iter().map(|s| s.frequency_hz).collect();
    let points: Vec<usize> = (0..freqs.len()).collect();
    let mut out = Vec::new();
    for (dof, quantity) in wanted_outputs(g, geometry, fit.dofs(), opts) {
        if dof as usize >= fit.dofs() {
            notes.push(format!(
                "{}: body `{}` dof {dof} is declared as an output but its {} accelerometer(s) only observe {} DOFs; add sensors",
                geometry.source,
                g.name,
                idx.len(),
                fit.dofs()
            ));
            continue;
        }
        let p = 2 - quantity_order(quantity);
        let mut h = Vec::with_capacity(freqs.len());
        let mut var = Vec::with_capacity(freqs.len());
        for (k, f) in freqs.iter().enumerate() {
            // Accelerance → quantity: divide by (jω)^(2 − order).
            let factor = C64::new(1.0, 0.0) / C64::new(0.0, 2.0 * std::f64::consts::PI * f).powi(p);
            h.push(q_lines[k][dof as usize] * factor);
            var.push(var_lines[k][dof as usize] * factor.norm_sqr());
        }
        let spec = CharacteristicSpec {
            body: g.name.clone(),
            dof,
            quantity,
            nominal_force: geometry.nominal_force_n,
        };
        let m = to_measurement(&spec, &freqs, &h, None, Some(&var), None, &points)
            .map_err(process_err(format!("body `{}` dof {dof}", g.name)))?;
        out.push(m);
    }
    Ok(out)
}

/// The (dof, quantity) pairs wanted on body `g`: the geometry's declared outputs on it, or every
/// DOF the layout observes; `opts.quantity` overrides the declared quantities.
fn wanted_outputs(
    g: &BodyGeometry,
    geometry: &Geometry,
    observed: usize,
    opts: &AnalysisOptions,
) -> Vec<(u8, Quantity)> {
    let declared: Vec<&crate::stand::GeometryOutput> = geometry
        .outputs
        .iter()
        .filter(|o| o.body == g.name)
        .collect();
    if declared.is_empty() {
        return (0..observed as u8)
            .map(|d| (d, opts.quantity.unwrap_or(Quantity::Displacement)))
            .collect();
    }
    declared
        .iter()
        .map(|o| {
            (
                o.dof,
                opts.quantity
                    .or_else(|| Quantity::parse(&o.quantity))
                    .unwrap_or(Quantity::Displacement),
            )
        })
        .collect()
}

impl SessionAnalysis {
    /// The measured FRFs as UFF dataset 58 functions: every accelerometer's accelerance
    /// ((m/s²)/N) against the force channel at the steps' frequencies (nodes 1.. in stream
    /// order, direction ±1..3 when the sensor is along a global axis, else 0 with the direction
    /// in record 5), then every characteristic per newton (node 101.. per body, direction 1..6 =
    /// the principal axes' u1..r3), each with its units in records 8-11.
    pub fn to_uff(&self) -> Vec<process::uff::Function> {
        let freqs: Vec<f64> = self.steps.iter().map(|s| s.frequency_hz).collect();
        let force = crate::stand::force_channel(&self.channels);
        let mut out = Vec::new();
        for (c, ch) in self.channels.iter().enumerate() {
            if c == force {
                continue;
            }
            let h: Vec<C64> = self
                .steps
                .iter()
                .map(|s| C64::new(s.channels[c].frf_re, s.channels[c].frf_im))
                .collect();
            let mut f = uff_frf(&ch.name, &freqs, h, self);
            f.response_node = c as i64 + 1;
            f.response_dir = axis_direction(&ch.direction);
            f.reference_node = force as i64 + 1;
            f.reference_dir = axis_direction(&self.channels[force].direction);
            f.ids[4] = format!("direction {:?}", ch.direction);
            f.axes[1] = uff_axis(12, "Acceleration", "m/s^2", 1);
            out.push(f);
        }
        let bodies: Vec<&str> = self
            .geometry
            .bodies
            .iter()
            .map(|b| b.name.as_str())
            .collect();
        let per_newton = 1.0 / self.geometry.nominal_force_n;
        for m in &self.measured.characteristics {
            let h: Vec<C64> = m
                .amplitude
                .iter()
                .enumerate()
                .map(|(k, a)| {
                    let ph = m.phase_rad.as_ref().map(|p| p[k]).unwrap_or(0.0);
                    C64::from_polar(a * per_newton, ph)
                })
                .collect();
            let name = format!(
                "{} {}",
                m.body,
                ["u1", "u2", "u3", "r1", "r2", "r3"][m.dof.min(5) as usize]
            );
            let mut f = uff_frf(&name, &m.freqs_hz, h, self);
            f.response_entity = m.body.chars().take(10).collect();
            f.response_node = 101 + bodies.iter().position(|b| *b == m.body).unwrap_or(0) as i64;
            f.response_dir = i64::from(m.dof) + 1;
            f.reference_node = force as i64 + 1;
            f.ids[4] = format!("{} principal axes, per N of the model's excitation", m.body);
            let base = if m.dof < 3 { "m" } else { "rad" };
            f.axes[1] = match Quantity::from(m.quantity) {
                Quantity::Displacement => uff_axis(8, "Displacement", base, 1),
                Quantity::Velocity => uff_axis(11, "Velocity", &format!("{base}/s"), 1),
                Quantity::Acceleration => uff_axis(12, "Acceleration", &format!("{base}/s^2"), 1),
            };
            out.push(f);
        }
        out
    }

    /// What the operator should know about the session, one sentence each: a truncated file and
    /// the steps it lost, every dropped step with its reason, the stream faults, steps whose
    /// recomputation differs from the live estimate, and the analysis's notes. The workflows put
    /// these in their reports.
    pub fn messages(&self) -> Vec<String> {
        let mut messages = Vec::new();
        if let Some(t) = &self.truncated {
            messages.push(format!(
                "the session file is truncated ({t}); every complete step before the cut is used, {} step(s) are lost",
                self.dropped.len()
            ));
        }
        for d in &self.dropped {
            messages.push(format!(
                "step {} ({:.2} Hz) not used: {}",
                d.step, d.frequency_hz, d.reason
            ));
        }
        if !self.faults.is_empty() {
            messages.push(format!(
                "{} stream fault(s) recorded; the steps they hit were re-measured",
                self.faults.len()
            ));
        }
        let differ: Vec<usize> = self
            .steps
            .iter()
            .filter(|s| !s.matches_live)
            .map(|s| s.step)
            .collect();
        if !differ.is_empty() {
            messages.push(format!("steps {differ:?}: the recomputation differs from the live estimate recorded in the session"));
        }
        messages.extend(self.notes.iter().cloned());
        messages
    }
}

/// An FRF dataset at the (uneven) frequencies `freqs`, per newton of force.
fn uff_frf(name: &str, freqs: &[f64], h: Vec<C64>, a: &SessionAnalysis) -> process::uff::Function {
    let mut f = process::uff::Function::frf(name, 0.0, 0.0, h);
    f.abscissa = process::uff::Abscissa::Uneven(freqs.to_vec());
    f.ids[1] = format!("ident process {}", file_name(&a.session));
    f.ids[2] = format!("stand {}", a.stand);
    f.ids[3] = "stepped-sine FRF".into();
    f.axes[2] = uff_axis(13, "Force", "N", 0);
    f.axes[2].force_exp = 1;
    f
}

fn file_name(path: &str) -> &str {
    Path::new(path)
        .file_name()
        .and_then(|s| s.to_str())
        .unwrap_or(path)
}

/// Records 8-11 of one axis: specific data type, label, units, length exponent.
fn uff_axis(spec_data_type: i64, label: &str, units: &str, length_exp: i64) -> process::uff::Axis {
    process::uff::Axis {
        spec_data_type,
        length_exp,
        force_exp: 0,
        temperature_exp: 0,
        label: label.into(),
        units: units.into(),
    }
}

/// The UFF direction code of a unit vector: ±1..3 along a global axis, 0 otherwise.
fn axis_direction(d: &[f64; 3]) -> i64 {
    for (i, x) in d.iter().enumerate() {
        if (x.abs() - 1.0).abs() < 1e-9 {
            return (i as i64 + 1) * x.signum() as i64;
        }
    }
    0
}

/// Time derivatives from displacement: 0, 1 (velocity) or 2 (acceleration).
fn quantity_order(q: Quantity) -> i32 {
    match q {
        Quantity::Displacement => 0,
        Quantity::Velocity => 1,
        Quantity::Acceleration => 2,
    }
}
