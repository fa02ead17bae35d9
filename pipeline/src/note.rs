//! What a workflow step did that the operator should know, handed to the caller as it happens
//! (the command line prints each on stderr before a later, long step starts).

use std::fmt;
use std::path::PathBuf;

/// One thing a step did or found that the operator should know.
#[derive(Debug, Clone, PartialEq)]
pub enum Note {
    /// A warning of the model file (an unknown key, a default taken).
    Model(String),
    /// The session file a measurement records into.
    Recording(PathBuf),
    /// The simulated stand started for the stand's `"sim"` ports.
    SimulatedStand {
        /// Simulated time per wall-clock time.
        speed: f64,
        /// `shaker` or `generator`.
        exciter: &'static str,
        /// The exciter's port.
        exciter_port: String,
        /// The DAQ's port.
        daq_port: String,
    },
    /// A session file left out of the newest-session search.
    SkippedSession {
        /// The session file.
        path: PathBuf,
        /// Why it could not be read; `None`: its writer did not finish it.
        unreadable: Option<String>,
    },
}

impl fmt::Display for Note {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Note::Model(s) => write!(f, "{s}"),
            Note::Recording(p) => write!(f, "recording {}", p.display()),
            Note::SimulatedStand {
                speed,
                exciter,
                exciter_port,
                daq_port,
            } => write!(
                f,
                "simulated stand at {speed}× real time: {exciter} {exciter_port}, daq {daq_port}"
            ),
            Note::SkippedSession {
                path,
                unreadable: None,
            } => write!(
                f,
                "skipped the unfinished session {} (its writer did not finish it: a sweep killed mid-way, or one still running); `ident mcap recover` makes a readable copy, which `ident process` reports as truncated",
                path.display()
            ),
            Note::SkippedSession {
                path,
                unreadable: Some(e),
            } => write!(f, "skipped the session {}: cannot read it: {e}", path.display()),
        }
    }
}
