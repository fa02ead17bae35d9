//! `ident replay SESSION.mcap`: re-run processing, identification and diagnosis from a recording,
//! with the same code the live run used ([`crate::pipeline::analyse`]); the results are
//! bit-identical to the live run's (tests/cli_pipeline.rs checks it). A truncated recording is
//! read up to the cut and the report says which steps are lost.

use std::path::PathBuf;
use std::process::ExitCode;

use crate::pipeline::{self, ReportContext, Setup};

/// Arguments of `ident replay`.
#[derive(clap::Args)]
pub struct ReplayArgs {
    /// The session recording.
    pub session: PathBuf,
    /// Identification model (the one the live run used; never the truth).
    #[arg(long, default_value = "configs/models/fwd32j-no-actuator.toml")]
    pub model: PathBuf,
    /// Decision variables.
    #[arg(long, default_value = "configs/identification/fwd32j-no-actuator.toml")]
    pub vars: PathBuf,
    /// Folder for the report (a dated sub-folder is made in it).
    #[arg(long, default_value = "reports")]
    pub out: PathBuf,
}

/// Runs the replay.
pub fn run(a: ReplayArgs) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(a.session.is_file(), "{}: no such session file", a.session.display());
    let setup = Setup::load(&a.model, &a.vars)?;
    let analysis = pipeline::analyse(&a.session, &setup, &pipeline::identification_options())?;
    println!("ident replay: {} ({} steps used, {} dropped)", a.session.display(), analysis.session.steps.len(), analysis.session.dropped.len());
    print!("{}", pipeline::summary_text(&analysis));
    for m in &analysis.messages {
        println!("note: {m}");
    }
    let dir = pipeline::dated_folder(&a.out, "replay")?;
    let ctx = ReportContext { title: "ident replay", workflow: "replay", stand: None, drift: None, messages: Vec::new(), created_utc: String::new() };
    let (_, written) = pipeline::write_report(&dir, ctx, &setup, &analysis)?;
    println!("report: {}", dir.display());
    println!("open: {}", written.html.display());
    Ok(ExitCode::SUCCESS)
}
