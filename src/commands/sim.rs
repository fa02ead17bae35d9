//! `ident sim --stand FILE [--can IFACE]`: serve a stand's simulated shaker controller (or signal
//! generator + amplifier, on a pty or a local TCP port) and DAQ (SCPI and the COBS/CRC stream over
//! pseudo-terminals; the DAQ on a CAN interface with `--can`) until Ctrl-C, printing where they are. Their signals come from the stand's `[truth]`.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use acquire::sim::SimStand;
use acquire::stand::Stand;
use anyhow::Context;

/// Arguments of `ident sim`.
#[derive(clap::Args)]
pub struct SimArgs {
    /// Stand file with a `[truth]` section (e.g. configs/stands/fwd32j-model-sim.toml).
    #[arg(long)]
    pub stand: PathBuf,
    /// Serve the DAQ on this CAN interface (e.g. vcan0) instead of a pseudo-terminal.
    #[arg(long)]
    pub can: Option<String>,
    /// Simulated time per wall-clock time (overrides the stand's `truth.speed`).
    #[arg(long)]
    pub speed: Option<f64>,
}

/// Runs `ident sim`.
pub fn run(a: SimArgs) -> anyhow::Result<ExitCode> {
    let mut stand = Stand::load(&a.stand)?;
    let truth = stand.truth.as_mut().with_context(|| {
        format!(
            "{}: `ident sim` needs a [truth] section (the simulated structure)",
            a.stand.display()
        )
    })?;
    if let Some(s) = a.speed {
        anyhow::ensure!(
            s.is_finite() && s > 0.0,
            "--speed {s}: give a factor > 0 (1 = real time)"
        );
        truth.speed = s;
    }
    let speed = truth.speed;
    let rt = pipeline::runtime()?;
    rt.block_on(async {
        let sim = match &a.can {
            Some(iface) => SimStand::start_can(&stand, iface)?,
            None => SimStand::start(&stand)?,
        };
        let exciter = if stand.generator.is_some() { "generator.port" } else { "shaker.port" };
        let hint = format!(
            "{} at {speed}× real time; set the stand file's ports to these ({exciter}, daq.port = \"{}\") and run `ident sweep`; Ctrl-C stops",
            stand.name, sim.daq_port
        );
        serve_until_ctrl_c(sim, "ident sim", &hint).await
    })
}

/// Prints the served ports on stdout (`shaker PATH`, `daq PATH`: scripts read them), `hint` on
/// stderr, and serves until Ctrl-C (or SIGTERM).
pub async fn serve_until_ctrl_c(sim: SimStand, who: &str, hint: &str) -> anyhow::Result<ExitCode> {
    use tokio::signal::unix::{signal, SignalKind};
    // Listen before printing the ports: a script that reads them may signal at once.
    let mut interrupt = signal(SignalKind::interrupt()).context("cannot listen for Ctrl-C")?;
    let mut terminate = signal(SignalKind::terminate()).context("cannot listen for SIGTERM")?;
    let mut out = std::io::stdout().lock();
    // A generator stand's exciter is its signal generator (a pty path or tcp:127.0.0.1:PORT).
    let exciter = if sim.generator_state().is_some() {
        "generator"
    } else {
        "shaker"
    };
    writeln!(out, "{exciter} {}", sim.shaker_port)?;
    writeln!(out, "daq {}", sim.daq_port)?;
    out.flush()?;
    drop(out);
    eprintln!("{who}: {hint}");
    tokio::select! {
        _ = interrupt.recv() => {}
        _ = terminate.recv() => {}
    }
    sim.shutdown();
    eprintln!("{who}: stopped");
    Ok(ExitCode::SUCCESS)
}
