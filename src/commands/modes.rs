//! `ident modes MODEL`: natural frequencies, loss factors and where each mode's energy is.

use std::path::PathBuf;
use std::process::ExitCode;

use super::load_model;

/// Arguments of `ident modes`.
#[derive(clap::Args)]
pub struct ModesArgs {
    /// Model file (TOML or resolved JSON).
    pub model: PathBuf,
    /// Complex modes of the damped system (with loss factors) instead of undamped modes.
    #[arg(long)]
    pub complex: bool,
    /// Only modes up to this frequency (Hz).
    #[arg(long, default_value_t = 1000.0)]
    pub max_hz: f64,
    /// Print JSON (frequency, loss factor, energy share per body, mode shape) instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Runs `ident modes`.
pub fn run(a: ModesArgs) -> anyhow::Result<ExitCode> {
    let model = load_model(&a.model)?;
    let modes = if a.complex {
        rfe::modes::complex(&model)?
    } else {
        rfe::modes::undamped(&model)?
    };
    let modes: Vec<_> = modes
        .into_iter()
        .filter(|m| m.freq_hz <= a.max_hz)
        .collect();
    if a.json {
        let v: Vec<serde_json::Value> = modes
            .iter()
            .map(|m| {
                serde_json::json!({
                    "freq_hz": m.freq_hz,
                    "loss_factor": m.loss_factor,
                    "energy": model.bodies.iter().zip(&m.energy).map(|(b, e)| (b.name.clone(), serde_json::json!(e))).collect::<serde_json::Map<_, _>>(),
                    "shape_re": m.shape.iter().map(|v| v.re).collect::<Vec<_>>(),
                    "shape_im": m.shape.iter().map(|v| v.im).collect::<Vec<_>>(),
                })
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(ExitCode::SUCCESS);
    }
    println!(
        "{:>4} {:>10} {:>8}  energy by body (largest first)",
        "mode", "f [Hz]", "η [-]"
    );
    for (i, m) in modes.iter().enumerate() {
        let mut shares: Vec<(usize, f64)> = m.energy.iter().copied().enumerate().collect();
        shares.sort_by(|a, b| b.1.total_cmp(&a.1));
        let top: Vec<String> = shares
            .iter()
            .take(3)
            .filter(|(_, e)| *e >= 0.05)
            .map(|(b, e)| format!("{} {:.0}%", model.bodies[*b].name, 100.0 * e))
            .collect();
        println!(
            "{:>4} {:>10.3} {:>8.4}  {}",
            i + 1,
            m.freq_hz,
            m.loss_factor,
            top.join(", ")
        );
    }
    Ok(ExitCode::SUCCESS)
}
