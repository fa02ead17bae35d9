//! `ident demo`: the whole pipeline on the built-in simulated FWD-32J stand, end to end.
//!
//! The simulated shaker controller and DAQ serve their real protocols over pseudo-terminals; their
//! truth is `configs/models/fwd32j.toml` (the paper's identified values, with the hydraulic
//! actuator SDE 34). A stepped-sine sweep (38 log-spaced lines, 20-400 Hz, 4 kN held by the closed
//! loop) is recorded into a session file; processing turns it into the table's principal-axis
//! characteristics; identification fits the paper's decision variables from Table 1's initial
//! values on `configs/models/fwd32j-no-actuator.toml` — a model that lacks the actuator, the
//! undeclared effect that diagnosis finds and adds. The Table-1-like summary, the diagnosis (ranked
//! candidate effects, the accepted one, the error before and after) are printed and
//! the report folder (HTML, JSON, the session and the configs that ran) is written.
//!
//! With `--generator` the exciter is the simulated SCPI signal generator + power amplifier of
//! `configs/stands/fwd32j-generator-sim.toml` (same structure, sensors and truth), the force loop
//! closed by ident on the DAQ's force channel (docs/scpi-generator.md).
//!
//! The configs are built in and written into the report folder, so the demo runs from anywhere
//! and the folder says exactly what ran.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use acquire::stand::Stand;
use acquire::sweep::{IndicatifProgress, NoProgress, SteppedSine, SweepProgress};
use anyhow::Context;

use pipeline::{ReportContext, Setup};

use super::note;

/// The built-in configs, at their paths relative to `configs/` (the stand file refers to the
/// models by relative path).
const CONFIGS: [(&str, &str); 5] = [
    (
        "stands/fwd32j-model-sim.toml",
        include_str!("../../configs/stands/fwd32j-model-sim.toml"),
    ),
    (
        GENERATOR_STAND,
        include_str!("../../configs/stands/fwd32j-generator-sim.toml"),
    ),
    (
        "models/fwd32j.toml",
        include_str!("../../configs/models/fwd32j.toml"),
    ),
    (
        "models/fwd32j-no-actuator.toml",
        include_str!("../../configs/models/fwd32j-no-actuator.toml"),
    ),
    (
        "identification/fwd32j-no-actuator.toml",
        include_str!("../../configs/identification/fwd32j-no-actuator.toml"),
    ),
];

/// The generator stand's file under `configs/` (`ident demo --generator`).
const GENERATOR_STAND: &str = "stands/fwd32j-generator-sim.toml";

/// Arguments of `ident demo`.
#[derive(clap::Args)]
pub struct DemoArgs {
    /// Folder for the report (a dated sub-folder is made in it).
    #[arg(long, default_value = "reports")]
    pub out: PathBuf,
    /// Simulated time per wall-clock time of the simulated stand (1 = real time; default: the
    /// stand file's `truth.speed`).
    #[arg(long)]
    pub speed: Option<f64>,
    /// Number of log-spaced lines of the sweep, 20-400 Hz (the paper measured 38).
    #[arg(long, default_value_t = 38)]
    pub points: usize,
    /// Seed of the simulated sensor noise.
    #[arg(long)]
    pub seed: Option<u64>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Drive the simulated stand the way real stands are: a SCPI signal generator and power
    /// amplifier, the force loop closed by ident (configs/stands/fwd32j-generator-sim.toml,
    /// docs/scpi-generator.md) instead of the shaker controller.
    #[arg(long)]
    pub generator: bool,
}

/// The demo's sweep plan.
pub fn plan(points: usize) -> SteppedSine {
    SteppedSine::log(20.0, 400.0, points, 4000.0)
}

/// Writes the built-in configs under `dir` and returns it.
fn materialize(dir: &Path) -> anyhow::Result<PathBuf> {
    let root = dir.join("configs");
    for (rel, text) in CONFIGS {
        let p = root.join(rel);
        if let Some(parent) = p.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create {}", parent.display()))?;
        }
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(root)
}

/// Runs the demo.
pub fn run(a: DemoArgs) -> anyhow::Result<ExitCode> {
    if let Some(s) = a.speed {
        anyhow::ensure!(
            s.is_finite() && s > 0.0 && s <= 50.0,
            "--speed {s}: give a factor in (0, 50] (1 = real time)"
        );
    }
    anyhow::ensure!(
        (4..=400).contains(&a.points),
        "--points {}: give 4 to 400 lines",
        a.points
    );
    let dir = pipeline::dated_folder(&a.out, "demo")?;
    let configs = materialize(&dir)?;
    let (stand, speed) = demo_stand(&configs, &a)?;
    let setup = Setup::load(
        &configs.join("models/fwd32j-no-actuator.toml"),
        &configs.join("identification/fwd32j-no-actuator.toml"),
        &mut note,
    )?;
    let plan = plan(a.points);
    introduce(&setup, a.points, speed, a.generator);
    let started = Instant::now();
    let progress: Box<dyn SweepProgress> = if a.quiet {
        Box::new(NoProgress)
    } else {
        Box::new(IndicatifProgress::new())
    };
    let swept = pipeline::sweep(
        &stand,
        &plan,
        &dir.join("session.mcap"),
        &Default::default(),
        progress.as_ref(),
        &mut note,
    )?;
    let outcome = swept.outcome.map_err(|e| {
        anyhow::anyhow!(
            "the sweep failed: {:#} (session kept: {})",
            anyhow::Error::from(e),
            swept.session.display()
        )
    })?;
    if let Some(e) = &swept.finish_error {
        anyhow::bail!(
            "the session file {} could not be completed: {e}",
            swept.session.display()
        );
    }
    let t_sweep = started.elapsed().as_secs_f64();
    println!(
        "  session: {} ({} steps, {} stream faults) in {t_sweep:.1} s",
        swept.session.display(),
        outcome.steps.len(),
        outcome.faults
    );

    let analysis = pipeline::analyse(&swept.session, &setup, &pipeline::identification_options())?;
    let t_all = started.elapsed().as_secs_f64();
    println!();
    print!("{}", pipeline::summary_text(&analysis));
    for m in &analysis.messages {
        println!("note: {m}");
    }
    let ctx = ReportContext {
        title: "ident demo: simulated FWD-32J stand",
        workflow: "demo",
        stand: Some(stand.name.clone()),
        drift: None,
        messages: Vec::new(),
        created_utc: String::new(),
    };
    let (_, written) = pipeline::write_report(&dir, ctx, &setup, &analysis)?;
    println!(
        "\nsweep {t_sweep:.1} s, processing, identification and diagnosis {:.1} s",
        t_all - t_sweep
    );
    println!("report: {}", dir.display());
    println!("open: {}", written.html.display());
    Ok(ExitCode::SUCCESS)
}

/// The simulated stand with the demo's speed and seed; and its speed.
fn demo_stand(configs: &Path, a: &DemoArgs) -> anyhow::Result<(Stand, f64)> {
    let file = if a.generator {
        GENERATOR_STAND
    } else {
        "stands/fwd32j-model-sim.toml"
    };
    let mut stand = Stand::load(&configs.join(file))?;
    let mut speed = 1.0;
    if let Some(t) = stand.truth.as_mut() {
        if let Some(s) = a.speed {
            t.speed = s;
        }
        speed = t.speed;
        if let Some(s) = a.seed {
            t.seed = s;
        }
    }
    Ok((stand, speed))
}

/// What the demo is about to do.
fn introduce(setup: &Setup, points: usize, speed: f64, generator: bool) {
    if generator {
        println!("ident demo: simulated FWD-32J stand driven by a SCPI signal generator + power amplifier (force loop closed by ident; pseudo-terminals)");
    } else {
        println!(
            "ident demo: simulated FWD-32J stand over simulated serial devices (pseudo-terminals)"
        );
    }
    println!("  truth: configs/models/fwd32j.toml (the paper's identified values, with the hydraulic actuator SDE 34)");
    println!(
        "  identification model: configs/models/fwd32j-no-actuator.toml ({} bodies, {} SDEs, actuator missing), {} decision variables",
        setup.model.bodies.len(),
        setup.model.sdes.len(),
        setup.vars.len()
    );
    println!(
        "  sweep: {} log-spaced lines 20-400 Hz at 4 kN, simulated stand at {speed}x real time",
        points
    );
}
