//! Why a workflow step failed. Each variant names the file and, where there is one, the fix; the
//! steps' own errors pass through unchanged (their messages already do).

use std::path::PathBuf;

/// Why a workflow step failed.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The model file.
    #[error(transparent)]
    Model(#[from] rfe::modelfile::LoadError),
    /// The variables file.
    #[error(transparent)]
    Variables(#[from] identify::VarsError),
    /// The async runtime the devices run on could not be started.
    #[error("cannot start the async runtime")]
    Runtime(#[source] std::io::Error),
    /// The sweep plan (its frequencies) or a sweep step before the session exists.
    #[error(transparent)]
    Plan(#[from] acquire::sweep::SweepError),
    /// The simulated stand could not be started.
    #[error(transparent)]
    Sim(#[from] acquire::sim::SimError),
    /// A CAN interface given for a stand that has no simulated port.
    #[error("the CAN interface serves the simulated DAQ; {stand} has no port = \"sim\" (give daq.port = \"can:IFACE\" for a real CAN DAQ)")]
    CanWithoutSim {
        /// The stand file.
        stand: String,
    },
    /// The session file could not be created.
    #[error("cannot create the session file {}", path.display())]
    CreateSession {
        /// The session file.
        path: PathBuf,
        /// Why.
        source: acquire::session::SessionError,
    },
    /// The session folder cannot be read.
    #[error("cannot read the session folder {}", path.display())]
    SessionFolder {
        /// The folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// No finished session in the session folder.
    #[error("no {}*.mcap session in {}; record one with `ident sweep` or set measure = \"sweep\"", if *unfinished { "finished " } else { "" }, dir.display())]
    NoSession {
        /// The session folder.
        dir: PathBuf,
        /// Whether it holds `*.mcap` files (none of them finished and readable).
        unfinished: bool,
    },
    /// The session file could not be processed into characteristics.
    #[error(transparent)]
    Analysis(#[from] acquire::analysis::AnalysisError),
    /// The characteristics do not fit the identification model.
    #[error(transparent)]
    Data(#[from] identify::DataError),
    /// The identification could not run.
    #[error(transparent)]
    Identify(#[from] identify::IdentifyError),
    /// The report could not be built or written.
    #[error(transparent)]
    Report(#[from] report::ReportError),
    /// A result could not be written as JSON.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// The final model or the next variables file cannot be written.
    #[error(transparent)]
    FinalModel(#[from] diagnose::final_model::FinalModelError),
    /// A folder for the run's reports could not be created.
    #[error("cannot create {}", path.display())]
    Folder {
        /// The folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The run's report folder could not be created.
    #[error("cannot create the report folder {}", path.display())]
    ReportFolder {
        /// The folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}
