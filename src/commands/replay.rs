//! `ident replay SESSION.mcap`: re-run processing, identification and diagnosis from a recording,
//! with the same code the live run used ([`pipeline::analyse`]); the results are
//! bit-identical to the live run's (tests/cli_pipeline.rs checks it). A truncated recording is
//! read up to the cut and the report says which steps are lost.
//!
//! `ident replay --serve SESSION.mcap`: serve the session through the simulated devices instead
//! ([`acquire::replay`]): its recorded stand, identities, measured response and noise level, on two
//! new pseudo-terminals, until Ctrl-C — so `ident sweep` exercises the live path on a real
//! session's structure.

use std::path::PathBuf;
use std::process::ExitCode;

use pipeline::{ReportContext, Setup};

use super::note;

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
    /// Serve the session's devices (recorded stand, identities and measured response) on
    /// pseudo-terminals until Ctrl-C, instead of re-running the analysis.
    #[arg(long)]
    pub serve: bool,
    /// With --serve: simulated time per wall-clock time (default: the recorded simulated stand's
    /// speed, or 1 = real time).
    #[arg(long, requires = "serve")]
    pub speed: Option<f64>,
}

/// Runs the replay.
pub fn run(a: ReplayArgs) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(
        a.session.is_file(),
        "{}: no such session file",
        a.session.display()
    );
    if a.serve {
        return serve(&a);
    }
    let setup = Setup::load(&a.model, &a.vars, &mut note)?;
    let analysis = pipeline::analyse(&a.session, &setup, &pipeline::identification_options())?;
    println!(
        "ident replay: {} ({} steps used, {} dropped)",
        a.session.display(),
        analysis.session.steps.len(),
        analysis.session.dropped.len()
    );
    print!("{}", pipeline::summary_text(&analysis));
    for m in &analysis.messages {
        println!("note: {m}");
    }
    let dir = pipeline::dated_folder(&a.out, "replay")?;
    let ctx = ReportContext {
        title: "ident replay",
        workflow: "replay",
        stand: None,
        drift: None,
        messages: Vec::new(),
        created_utc: String::new(),
    };
    let (_, written) = pipeline::write_report(&dir, ctx, &setup, &analysis)?;
    println!("report: {}", dir.display());
    println!("open: {}", written.html.display());
    Ok(ExitCode::SUCCESS)
}

/// `--serve`: the session's devices on pseudo-terminals until Ctrl-C.
fn serve(a: &ReplayArgs) -> anyhow::Result<ExitCode> {
    let served = acquire::replay::prepare(&a.session, a.speed)?;
    let (name, speed, lines) = (
        served.stand.name.clone(),
        served.setup.speed,
        served.plant.frequencies().len(),
    );
    let (lo, hi) = (
        served.plant.frequencies()[0],
        served.plant.frequencies()[lines - 1],
    );
    let rt = pipeline::runtime()?;
    rt.block_on(async {
        let sim = acquire::sim::SimStand::start_with(served.setup)?;
        let hint = format!(
            "{name} as recorded in {} ({lines} measured lines, {lo:.1}-{hi:.1} Hz) at {speed}× real time; \
             point the stand file's shaker.port and daq.port at these and run `ident sweep`; Ctrl-C stops",
            a.session.display()
        );
        super::sim::serve_until_ctrl_c(sim, "ident replay --serve", &hint).await
    })
}
