//! `ident process SESSION.mcap [--out DIR]`: the measured characteristics of a recorded session
//! (`acquire::analysis::characteristics`: every step re-fitted from the raw blocks, FRFs, the
//! bodies' principal axes, scaled to the model's excitation), written as
//!
//! - `DIR/<session>.measured.json` and `.measured.csv` — the data for `ident identify --data`,
//! - `DIR/<session>.steps.csv` — the per-step FRF table (every channel, noise, variance, faults),
//! - `DIR/<session>.analysis.json` — everything, including dropped steps and faults,
//! - with `--uff FILE`: the sensors' accelerances and the characteristics as UFF dataset 58.
//!
//! Exit status: 0 all recorded steps used; 1 some steps were dropped or the file was truncated
//! (what was usable is written, and why the rest was not is printed); 2 failure.

use std::path::PathBuf;
use std::process::ExitCode;

use acquire::analysis::{characteristics, AnalysisOptions, SessionAnalysis};
use anyhow::Context;
use rfe::csv_text::CsvText;

/// Arguments of `ident process`.
#[derive(clap::Args)]
pub struct ProcessArgs {
    /// The session file (from `ident sweep`).
    pub session: PathBuf,
    /// Folder for the output files (default: next to the session).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Model file giving the bodies' geometry, instead of the geometry recorded in the session.
    #[arg(long)]
    pub geometry: Option<PathBuf>,
    /// Quantity of the characteristics (default: the geometry model's outputs', else displacement).
    #[arg(long, value_parser = ["displacement", "velocity", "acceleration"])]
    pub quantity: Option<String>,
    /// Also write the measured FRFs and characteristics as UFF dataset 58 (ASCII) for modal
    /// analysis tools (pyuff, Simcenter Testlab, ME'scope ...). The format writes uneven
    /// frequencies with 6 significant digits, values with 13.
    #[arg(long)]
    pub uff: Option<PathBuf>,
}

const DOF: [&str; 6] = ["u1", "u2", "u3", "r1", "r2", "r3"];

/// The identification CSV (docs/identification.md) of the measured characteristics.
pub fn measured_csv(a: &SessionAnalysis) -> String {
    let mut s = CsvText::new();
    s.comment(&a.measured.source);
    s.row([
        "body",
        "dof",
        "quantity",
        "freq_hz",
        "amplitude",
        "phase_rad",
        "variance",
    ]);
    for m in &a.measured.characteristics {
        let q = serde_json::to_value(m.quantity)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_default();
        for (k, f) in m.freqs_hz.iter().enumerate() {
            let ph = m.phase_rad.as_ref().map(|p| p[k]).unwrap_or(f64::NAN);
            let var = m.variance.as_ref().map(|v| v[k]).unwrap_or(f64::NAN);
            s.row([
                m.body.clone(),
                DOF[m.dof.min(5) as usize].to_string(),
                q.clone(),
                f.to_string(),
                format!("{:e}", m.amplitude[k]),
                ph.to_string(),
                format!("{var:e}"),
            ]);
        }
    }
    s.finish()
}

/// The per-step FRF table: one row per step and channel.
pub fn steps_csv(a: &SessionAnalysis) -> String {
    let mut s = CsvText::new();
    s.row([
        "step",
        "frequency_hz",
        "force_amplitude_n",
        "channel",
        "amplitude",
        "phase_rad",
        "frf_re",
        "frf_im",
        "noise_rms",
        "frf_variance",
        "fit_quality",
        "faults",
        "retries",
        "matches_live",
    ]);
    for st in &a.steps {
        for c in &st.channels {
            s.row([
                st.step.to_string(),
                st.frequency_hz.to_string(),
                st.force_amplitude_n.to_string(),
                c.name.clone(),
                format!("{:e}", c.amplitude),
                c.phase_rad.to_string(),
                format!("{:e}", c.frf_re),
                format!("{:e}", c.frf_im),
                format!("{:e}", c.noise_rms),
                format!("{:e}", c.frf_variance),
                c.fit_quality.to_string(),
                st.faults.to_string(),
                st.retries.to_string(),
                st.matches_live.to_string(),
            ]);
        }
    }
    s.finish()
}

/// Runs `ident process`.
pub fn run(a: ProcessArgs) -> anyhow::Result<ExitCode> {
    let opts = AnalysisOptions {
        geometry_model: a.geometry.clone(),
        quantity: a.quantity.as_deref().and_then(::rfe::Quantity::parse),
        ..AnalysisOptions::default()
    };
    let an = characteristics(&a.session, &opts)?;
    let dir = a
        .out
        .clone()
        .unwrap_or_else(|| a.session.parent().map(PathBuf::from).unwrap_or_default());
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let stem = a
        .session
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "session".into());
    let write = |suffix: &str, text: String| -> anyhow::Result<PathBuf> {
        let p = dir.join(format!("{stem}.{suffix}"));
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?;
        Ok(p)
    };
    let measured = write("measured.json", serde_json::to_string_pretty(&an.measured)?)?;
    write("measured.csv", measured_csv(&an))?;
    let steps = write("steps.csv", steps_csv(&an))?;
    write("analysis.json", serde_json::to_string_pretty(&an)?)?;
    if let Some(path) = &a.uff {
        let functions = an.to_uff();
        process::uff::write(path, &functions, process::uff::Encoding::Ascii)?;
        println!(
            "UFF 58: {} functions (accelerances per sensor, characteristics per N) in {}",
            functions.len(),
            path.display()
        );
    }
    let live = an.steps.iter().filter(|s| s.matches_live).count();
    println!(
        "{}: stand {:?}, {} steps used, {} dropped, {} stream faults recorded",
        an.session,
        an.stand,
        an.steps.len(),
        an.dropped.len(),
        an.faults.len()
    );
    println!(
        "recomputed from the raw blocks: {live} of {} steps equal the live estimate bit for bit",
        an.steps.len()
    );
    for m in &an.measured.characteristics {
        println!(
            "  {} {} {:?}: {} points, {:.1}-{:.1} Hz",
            m.body,
            DOF[m.dof.min(5) as usize],
            m.quantity,
            m.freqs_hz.len(),
            m.freqs_hz[0],
            m.freqs_hz[m.freqs_hz.len() - 1]
        );
    }
    let worst = an
        .steps
        .iter()
        .flat_map(|s| {
            s.rigidity
                .iter()
                .map(move |r| (r.residual, s.frequency_hz, &r.body))
        })
        .fold(None, |m: Option<(f64, f64, &String)>, x| match m {
            Some(y) if y.0 >= x.0 => Some(y),
            _ => Some(x),
        });
    if let Some((r, f, b)) = worst {
        println!("  largest rigidity residual: {r:.3} ({b}, {f:.1} Hz)");
    }
    for d in &an.dropped {
        println!(
            "  dropped step {} ({:.2} Hz): {}",
            d.step, d.frequency_hz, d.reason
        );
    }
    for n in &an.notes {
        println!("  note: {n}");
    }
    if let Some(t) = &an.truncated {
        println!("  the session file is truncated ({t}); `ident mcap recover` rewrites it into a valid file");
    }
    println!(
        "data for `ident identify --data`: {}\nper-step FRF table: {}",
        measured.display(),
        steps.display()
    );
    Ok(if an.dropped.is_empty() && an.truncated.is_none() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
