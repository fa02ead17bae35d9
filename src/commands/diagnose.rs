//! `ident diagnose MODEL --data DATA --vars VARS`: identify, then close the loop — residual
//! analysis, candidate effects ranked by a score test, refits accepted by a likelihood-ratio test,
//! and the error before and after (docs/diagnosis.md).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;

use identify::{self as idn};

use super::emit;
use super::identify::{setup, write_final, IdentifyArgs};

/// Arguments of `ident diagnose`: those of `ident identify`, plus the diagnosis' own.
#[derive(clap::Args)]
pub struct DiagnoseArgs {
    #[command(flatten)]
    pub identify: IdentifyArgs,
    /// Family-wise significance level: the accepted false-alarm rate of one diagnosis.
    #[arg(long, default_value_t = 0.01)]
    pub alpha: f64,
    /// Add at most this many effects.
    #[arg(long, default_value_t = 3)]
    pub max_effects: usize,
    /// Refit this many candidate families per round, the best screened first (and the score's
    /// two leading families when the screen left them out; when the misfit is large and their refits
    /// leave it above the noise level, also the family of each kind's best-scored candidate none
    /// of them holds, where its screen is significant, and then up to this many more whose short
    /// refits went below the best refit).
    #[arg(long, default_value_t = 5)]
    pub refit: usize,
    /// Write the diagnosis as JSON to this file (docs/diagnosis.md).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the final model (effects added, estimates written in) as resolved JSON to this file.
    #[arg(long)]
    pub out_model: Option<PathBuf>,
}

/// Runs identification and diagnosis. Exit 0: the final model explains the data to the noise
/// level; 1: it does not (or even the diagnosis's continued, multi-start base fit did not
/// converge); 2: bad input.
pub fn run(a: DiagnoseArgs) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(
        a.alpha > 0.0 && a.alpha < 1.0,
        "--alpha {}: give a significance level between 0 and 1 (e.g. 0.01)",
        a.alpha
    );
    anyhow::ensure!(a.refit > 0, "--refit must be at least 1");
    let problem = setup(&a.identify)?;
    let obs = &problem.observations;
    let id = problem.identify(&mut |_, p| {
        tracing::info!(iteration = p.iteration, criterion = p.criterion, "identify");
    })?;
    println!("{}", idn::report::text(&id));
    let request = diagnose::request::Request {
        alpha: a.alpha,
        max_effects: a.max_effects,
        refit: a.refit,
        ..diagnose::request::Request::new(&problem, &id)
    };
    let started = std::time::Instant::now();
    let d = request
        .diagnose(&mut |line| tracing::info!("diagnose: {line}"))
        .context("diagnosis")?;
    print!("{}", diagnose::text(&d));
    println!(
        "diagnosed in {:.2} s ({})",
        started.elapsed().as_secs_f64(),
        diagnose::timing_text(&d)
    );
    if let Some(p) = &a.json {
        emit(Some(p), &(serde_json::to_string_pretty(&d)? + "\n"))?;
    }
    let section = || ::report::build::diagnosis(&d, &super::identify::model_name(&a.identify), &id);
    if let Some(dir) = &a.identify.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the output directory {}", dir.display()))?;
        let diagnosis = Some((section(), &d));
        super::identify::write_report(dir, &a.identify, "diagnose", obs, &id, diagnosis)?;
    }
    if let Some(db) = &a.identify.record_history {
        let diagnosis = Some((section(), &d));
        super::identify::record_history(db, &a.identify, "diagnose", obs, &id, diagnosis)?;
    }
    if let Some(p) = &a.out_model {
        emit(
            Some(p),
            &(serde_json::to_string_pretty(&rfe::contract::to_json(&d.model))? + "\n"),
        )?;
    }
    write_final(&a.identify, &id, Some(&d))?;
    // The diagnosis's base fit is the identification continued until it converged: its verdict
    // after is the answer (docs/diagnosis.md).
    Ok(if d.after.explained && d.base.converged {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
