//! `ident`: measure a machine tool on a test stand and identify the stiffness and damping of its
//! rigid-finite-element model (the IDENT method). Each subcommand lives in `commands/`.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod commands;

#[derive(Parser)]
#[command(
    name = "ident",
    version,
    about = "Identify stiffness and damping of machine tool RFE models from measured frequency responses"
)]
struct Cli {
    /// Log progress (level info; `IDENT_LOG` overrides, e.g. `IDENT_LOG=debug`).
    #[arg(short, long, global = true)]
    verbose: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Model files: check, convert, export the resolved JSON.
    Model(commands::model::ModelArgs),
    /// Frequency response of a model's output characteristics.
    Frf(commands::frf::FrfArgs),
    /// Natural frequencies and mode shapes (undamped and complex).
    Modes(commands::modes::ModesArgs),
    /// Natural frequencies, damping and mode shapes extracted from measured FRFs (pLSCF).
    ModesFromData(commands::modes_from_data::ModesFromDataArgs),
    /// Band sensitivity MI of each characteristic to each SDE parameter (paper eq. 4.16).
    Sensitivity(commands::sensitivity::SensitivityArgs),
    /// Identify SDE parameters from measured characteristics (maximum likelihood).
    Identify(commands::identify::IdentifyArgs),
    /// Identify, then trace the residual to effects the model lacks and add them (closing the loop).
    Diagnose(commands::diagnose::DiagnoseArgs),
    /// The whole method on the built-in simulated FWD-32J stand, end to end.
    Demo(commands::demo::DemoArgs),
    /// Re-run processing, identification and diagnosis from a session recording.
    Replay(commands::replay::ReplayArgs),
    /// Unattended identification of a stand (cron/systemd): exit 0 ok, 1 drift alarm, 2 failure.
    Nightly(commands::nightly::NightlyArgs),
    /// The nightly run history: list, one parameter's series, CSV, import, HTML trend page.
    History(commands::history::HistoryArgs),
    /// Session files: recover a truncated recording.
    Mcap(commands::mcap::McapArgs),
    /// Serve a stand's simulated shaker controller and DAQ (pseudo-terminals or CAN) until Ctrl-C.
    Sim(commands::sim::SimArgs),
    /// Stepped-sine sweep of a stand into a new session file.
    Sweep(commands::sweep::SweepArgs),
    /// Measured characteristics of a session file (for `ident identify --data`).
    Process(commands::process::ProcessArgs),
    /// Chatter stability lobes of a model for a cut, with confidence bands.
    Stability(commands::stability::StabilityArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let level = if cli.verbose { "info" } else { "warn" };
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("IDENT_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level)),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let result = match cli.command {
        Command::Model(a) => commands::model::run(a),
        Command::Frf(a) => commands::frf::run(a),
        Command::Modes(a) => commands::modes::run(a),
        Command::ModesFromData(a) => commands::modes_from_data::run(a),
        Command::Sensitivity(a) => commands::sensitivity::run(a),
        Command::Identify(a) => commands::identify::run(a),
        Command::Diagnose(a) => commands::diagnose::run(a),
        Command::Demo(a) => commands::demo::run(a),
        Command::Mcap(a) => commands::mcap::run(a),
        Command::Stability(a) => commands::stability::run(a),
        Command::Replay(a) => commands::replay::run(a),
        Command::Nightly(a) => commands::nightly::run(a),
        Command::History(a) => commands::history::run(a),
        Command::Sim(a) => commands::sim::run(a),
        Command::Sweep(a) => commands::sweep::run(a),
        Command::Process(a) => commands::process::run(a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
