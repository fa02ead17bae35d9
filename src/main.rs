//! `ident`: measure a machine tool on a test stand and identify the stiffness and damping of its
//! rigid-finite-element model (the IDENT method). Each subcommand lives in `commands/`.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod commands;

#[derive(Parser)]
#[command(name = "ident", version, about = "Identify stiffness and damping of machine tool RFE models from measured frequency responses")]
struct Cli {
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
    /// Band sensitivity MI of each characteristic to each SDE parameter (paper eq. 4.16).
    Sensitivity(commands::sensitivity::SensitivityArgs),
    /// Identify SDE parameters from measured characteristics (maximum likelihood).
    Identify(commands::identify::IdentifyArgs),
    /// The whole method on the built-in simulated FWD-32J stand, end to end.
    Demo(commands::demo::DemoArgs),
    /// Session files: recover a truncated recording.
    Mcap(commands::mcap::McapArgs),
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("IDENT_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Model(a) => commands::model::run(a),
        Command::Frf(a) => commands::frf::run(a),
        Command::Modes(a) => commands::modes::run(a),
        Command::Sensitivity(a) => commands::sensitivity::run(a),
        Command::Identify(a) => commands::identify::run(a),
        Command::Demo(a) => commands::demo::run(a),
        Command::Mcap(a) => commands::mcap::run(a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
