//! `ident demo`: the whole method on the built-in simulated FWD-32J stand, end to end.
//!
//! The stand's truth is `configs/models/fwd32j.toml` (the paper's identified values). It is
//! "measured" at 38 log-spaced lines per table characteristic (20-400 Hz, the band of the joint
//! modes) with seeded relative noise whose variance is stated with the data, then identified from the paper's initial values (`fwd32j-initial.toml`) with its 20
//! decision variables (`configs/identification/fwd32j.toml`), and the Table-1-like summary is
//! printed. The measurement is simulated from the model directly; acquisition over the simulated
//! serial devices (issue 5) and processing into principal axes (issue 4) join this path under
//! issue 7.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use identify::identification::{self, data, report, variables};
use identify::modelfile::parse_toml;
use identify::{MeasuredData, Measurement};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

const TRUTH: &str = include_str!("../../configs/models/fwd32j.toml");
const INITIAL: &str = include_str!("../../configs/models/fwd32j-initial.toml");
const VARIABLES: &str = include_str!("../../configs/identification/fwd32j.toml");

/// Arguments of `ident demo`.
#[derive(clap::Args)]
pub struct DemoArgs {
    /// Folder for the report (a dated sub-folder is made in it).
    #[arg(long, default_value = "reports")]
    pub out: PathBuf,
    /// Relative measurement noise (standard deviation of |z| / |z|).
    #[arg(long, default_value_t = 0.01)]
    pub noise: f64,
    /// Seed of the simulated measurement noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Runs the demo.
pub fn run(a: DemoArgs) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(a.noise.is_finite() && (0.0..0.5).contains(&a.noise), "--noise {}: give a relative noise level in [0, 0.5)", a.noise);
    let truth = parse_toml(TRUTH, "configs/models/fwd32j.toml")?.model;
    let initial_text = INITIAL;
    let initial = parse_toml(initial_text, "configs/models/fwd32j-initial.toml")?.model;
    let vars = variables::parse(VARIABLES, "configs/identification/fwd32j.toml", &initial)?;
    println!("ident demo: simulated FWD-32J stand (truth: the IDENT paper's identified values)");
    println!("  model: {} bodies, {} SDEs, {} DOFs; excitation 4 kN between spindle head and table (α 60°, β 81°)",
        truth.bodies.len(), truth.sdes.len(), truth.dof_count());

    // The simulated measurement: 38 points per characteristic, log-spaced over 20-400 Hz.
    let freqs: Vec<f64> = (0..38).map(|i| 20.0 * (400.0f64 / 20.0).powf(i as f64 / 37.0)).collect();
    let r = identify::frf::response(&truth, &freqs, &[], identify::frf::Method::Auto)?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(a.seed);
    let normal = Normal::new(0.0, 1.0).context("noise distribution")?;
    let measured = MeasuredData {
        source: format!("ident demo: simulated from configs/models/fwd32j.toml, relative noise {}, seed {}", a.noise, a.seed),
        characteristics: truth
            .outputs
            .iter()
            .enumerate()
            .map(|(o, c)| Measurement {
                body: truth.bodies[c.body].name.clone(),
                dof: c.dof,
                quantity: c.quantity.into(),
                freqs_hz: freqs.clone(),
                amplitude: r.output(o).iter().map(|v| v.norm() * (1.0 + a.noise * normal.sample(&mut rng)).abs()).collect(),
                phase_rad: None,
                // complex variance E|z − z_true|² = 2 σ², σ = noise · |z| (amplitude σ = noise · |z|)
                variance: Some(r.output(o).iter().map(|v| 2.0 * (a.noise * v.norm()).powi(2)).collect()),
                coherence: None,
                averages: None,
            })
            .collect(),
    };
    println!("  measured: {} characteristics × {} points = {} observations (amplitude only, as in the paper)",
        measured.characteristics.len(), freqs.len(), measured.characteristics.len() * freqs.len());

    let obs = data::validate(&measured, &initial, "simulated stand")?;
    let opts = identification::Options::default();
    let started = std::time::Instant::now();
    let id = identification::identify(&initial, &obs, &vars, &opts, &mut |_, p| {
        tracing::info!(?p, "iteration");
    })?;
    let elapsed = started.elapsed();
    println!();
    print!("{}", report::text(&id));
    println!("\nidentified in {:.2} s", elapsed.as_secs_f64());

    let stamp = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    let dir = a.out.join(format!("demo-{stamp}"));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create the report folder {}", dir.display()))?;
    std::fs::write(dir.join("measured.json"), serde_json::to_string_pretty(&measured)?)?;
    std::fs::write(dir.join("identification.json"), serde_json::to_string_pretty(&report::json(&id))?)?;
    std::fs::write(dir.join("identification.csv"), report::csv(&id))?;
    std::fs::write(dir.join("identified-model.json"), serde_json::to_string_pretty(&identify::contract::to_json(&id.model))?)?;
    if let Ok(updated) = report::update_toml(initial_text, "configs/models/fwd32j-initial.toml", &id) {
        std::fs::write(dir.join("identified-model.toml"), updated)?;
    }
    println!("report: {}", dir.display());
    Ok(ExitCode::SUCCESS)
}
