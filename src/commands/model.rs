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
            let mass: f64 = (0..m.bodies.len()).map(|b| m.carried_mass(b)).sum();
            println!("{}: \"{}\"", model.display(), m.name);
            println!(
                "  {} bodies, total mass {:.1} kg, {} DOFs",
                m.bodies.len(),
                mass,
                m.dof_count()
            );
            if !m.point_masses.is_empty() {
                let added: f64 = m.point_masses.iter().map(|p| p.mass).sum();
                println!(
                    "  {} point masses, {} kg in all (in the total)",
                    m.point_masses.len(),
                    rfe::display::sig(added, 4)
                );
            }
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
            let text = serde_json::to_string_pretty(&rfe::contract::to_json(&m))? + "\n";
            emit(output.as_deref(), &text)?;
            Ok(ExitCode::SUCCESS)
        }
    }
}
