//! `ident model check|export`: validate a model file, print its resolved JSON.

use std::path::PathBuf;
use std::process::ExitCode;

use super::{emit, load_model};

/// Arguments of `ident model`.
#[derive(clap::Args)]
pub struct ModelArgs {
    #[command(subcommand)]
    action: Action,
}

#[derive(clap::Subcommand)]
enum Action {
    /// Load and validate a model; print a summary (bodies, SDEs, parameters, excitation).
    Check {
        /// Model file (TOML or resolved JSON).
        model: PathBuf,
    },
    /// Print the resolved model (SI units, six springs per SDE, forces at points).
    Export {
        /// Model file (TOML or resolved JSON).
        model: PathBuf,
        /// Print the resolved JSON of docs/model-json.md (the only form for now).
        #[arg(long, default_value_t = true)]
        json: bool,
        /// Write to this file instead of stdout.
        #[arg(long, short)]
        output: Option<PathBuf>,
    },
}

/// Runs `ident model`.
pub fn run(args: ModelArgs) -> anyhow::Result<ExitCode> {
    match args.action {
        Action::Check { model } => {
            let m = load_model(&model)?;
            let mass: f64 = m.bodies.iter().map(|b| b.mass).sum();
            println!("{}: \"{}\"", model.display(), m.name);
            println!(
                "  {} bodies, total mass {:.1} kg, {} DOFs",
                m.bodies.len(),
                mass,
                m.dof_count()
            );
            let enabled = m.sdes.iter().filter(|s| s.enabled).count();
            println!(
                "  {} SDEs ({} enabled), {} parameters",
                m.sdes.len(),
                enabled,
                m.all_params().len()
            );
            println!(
                "  {} point forces, {} output characteristics",
                m.forces.len(),
                m.outputs.len()
            );
            for c in &m.outputs {
                println!("    {}", m.characteristic_label(*c));
            }
            Ok(ExitCode::SUCCESS)
        }
        Action::Export {
            model,
            json: _,
            output,
        } => {
            let m = load_model(&model)?;
            let text = serde_json::to_string_pretty(&identify::contract::to_json(&m))? + "\n";
            emit(output.as_deref(), &text)?;
            Ok(ExitCode::SUCCESS)
        }
    }
}
