//! A measurement of a stand into a new session file: a stepped-sine sweep ([`sweep()`]) or a
//! broadband measurement ([`broadband_sweep`]). Ports given as `"sim"` are served by the
//! simulated stand for the measurement's duration. The session file is completed whatever
//! happens (a device fault, Ctrl-C, a full disk leaves a readable file); only failures before it
//! exists are errors, the measurement's own failure is in the result.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use acquire::rig::{Rig, RigError};
use acquire::session::{Session, SessionError, SessionHandle, SessionOptions};
use acquire::sim::SimStand;
use acquire::stand::{PortSpec, Stand};
use acquire::sweep::{
    self, Broadband, BroadbandResult, SteppedSine, StopSignal, SweepError, SweepOutcome,
    SweepProgress,
};

use crate::error::PipelineError;
use crate::note::Note;

/// Why a measurement failed once its session file existed (the file is still completed).
#[derive(Debug, thiserror::Error)]
pub enum MeasureError {
    /// The session start could not be recorded.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// The devices could not be connected.
    #[error(transparent)]
    Rig(#[from] RigError),
    /// The sweep itself (a device, the plan, a clipped force, the disk).
    #[error(transparent)]
    Sweep(#[from] SweepError),
}

/// A sweep that ended, completely or not.
#[derive(Debug)]
pub struct Swept {
    /// The session file (complete and readable even when the sweep failed).
    pub session: PathBuf,
    /// Steps planned.
    pub planned: usize,
    /// The sweep's outcome, or why it failed (device, plan, disk).
    pub outcome: Result<SweepOutcome, MeasureError>,
    /// Messages in the completed session file.
    pub messages: u64,
    /// Why the session file could not be completed (its flushed chunks are still readable:
    /// `ident mcap recover`).
    pub finish_error: Option<SessionError>,
}

/// A broadband measurement that ended, completely or not.
#[derive(Debug)]
pub struct BroadbandSwept {
    /// The estimate, or why the measurement failed.
    pub outcome: Result<BroadbandResult, MeasureError>,
    /// Messages in the completed session file.
    pub messages: u64,
    /// Why the session file could not be completed.
    pub finish_error: Option<SessionError>,
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
pub fn runtime() -> Result<tokio::runtime::Runtime, PipelineError> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(PipelineError::Runtime)
}

/// Runs a stepped-sine sweep of `stand` into a new session file at `session`. Ports given as
/// `"sim"` are served by the simulated stand; where the session goes and the simulated stand's
/// ports are [`Note`]s. The session file is kept whatever happens; only failures before it
/// exists are `Err`.
pub fn sweep(
    stand: &Stand,
    plan: &SteppedSine,
    session: &Path,
    opts: &SweepOptions<'_>,
    progress: &dyn SweepProgress,
    note: &mut dyn FnMut(Note),
) -> Result<Swept, PipelineError> {
    let planned = plan.frequencies.frequencies()?.len();
    let r = recorded(stand, plan, session, opts, note, async |rig, h, stop| {
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

/// Runs a broadband measurement (`stand`'s `[broadband]` plan) into a new session file, like
/// [`sweep()`] does a stepped sine (`opts.resume` and `opts.done` are for stepped sines: leave them
/// empty).
pub fn broadband_sweep(
    stand: &Stand,
    plan: &Broadband,
    session: &Path,
    opts: &SweepOptions<'_>,
    progress: &dyn SweepProgress,
    note: &mut dyn FnMut(Note),
) -> Result<BroadbandSwept, PipelineError> {
    let r = recorded(stand, plan, session, opts, note, async |rig, h, stop| {
        sweep::broadband(rig, plan, h, progress, stop).await
    })?;
    Ok(BroadbandSwept {
        outcome: r.outcome,
        messages: r.messages,
        finish_error: r.finish_error,
    })
}

/// A measurement that ended, completely or not, with its session file.
struct Recorded<T> {
    outcome: Result<T, MeasureError>,
    messages: u64,
    finish_error: Option<SessionError>,
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
fn record(session: &Path, note: &mut dyn FnMut(Note)) -> Result<Session, PipelineError> {
    let file = Session::create(session, SessionOptions::default()).map_err(|source| {
        PipelineError::CreateSession {
            path: session.to_path_buf(),
            source,
        }
    })?;
    note(Note::Recording(session.to_path_buf()));
    Ok(file)
}

/// Runs `measure` (of `plan`, recorded in the session start) on `stand`'s rig, its `"sim"` ports
/// served by the simulated stand, into a new session file at `session`, completed whatever
/// happens; only failures before it exists are `Err`.
fn recorded<T>(
    stand: &Stand,
    plan: &impl serde::Serialize,
    session: &Path,
    opts: &SweepOptions<'_>,
    note: &mut dyn FnMut(Note),
    measure: impl AsyncFnOnce(&mut Rig, &SessionHandle, &StopSignal) -> Result<T, SweepError>,
) -> Result<Recorded<T>, PipelineError> {
    let rt = runtime()?;
    rt.block_on(async {
        // The Ctrl-C handler needs the runtime.
        let stop = stop_signal(opts);
        let (sim, bound) = start_sim(stand, opts.can, note)?;
        let file = record(session, note)?;
        let h = file.handle();
        let outcome = async {
            sweep::log_session_start(&h, &stand.file, plan, opts.resume, &opts.done)?;
            let mut rig = Rig::connect(&bound, Some(&h)).await?;
            if let Some(s) = &sim {
                // Settling counts from the stream the simulator has produced.
                rig = s.clock_rig(rig);
            }
            Ok::<_, MeasureError>(measure(&mut rig, &h, &stop).await?)
        }
        .await;
        let (messages, finish_error) = match file.finish() {
            Ok(summary) => (summary.total(), None),
            Err(e) => (0, Some(e)),
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

/// The simulated stand serving `stand`'s `"sim"` ports (announced as a [`Note`]; its DAQ on CAN
/// with `can`), and the stand bound to them. Call inside the runtime.
fn start_sim(
    stand: &Stand,
    can: Option<&str>,
    note: &mut dyn FnMut(Note),
) -> Result<(Option<SimStand>, Stand), PipelineError> {
    let uses_sim = stand.shaker.port == PortSpec::Sim || stand.daq.port == PortSpec::Sim;
    let sim = match (uses_sim, can) {
        (true, Some(iface)) => Some(SimStand::start_can(stand, iface)?),
        (true, None) => Some(SimStand::start(stand)?),
        (false, Some(_)) => {
            return Err(PipelineError::CanWithoutSim {
                stand: stand.file.clone(),
            })
        }
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
            note(Note::SimulatedStand {
                speed,
                exciter,
                exciter_port: s.shaker_port.clone(),
                daq_port: s.daq_port.clone(),
            });
            s.bind(stand)
        }
        None => stand.clone(),
    };
    Ok((sim, bound))
}
