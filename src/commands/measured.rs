//! The measured data of `ident identify` / `ident diagnose`: ident's JSON or CSV (a CSV may
//! declare its unit), or a vendor UFF58/58b file (detected by content) mapped onto the model by
//! a measurement map (`--map`); then checked against the initial model (band: an error when
//! they do not overlap; level: a warning when it looks 9.81× or 1000× off). What was assumed and
//! converted is printed to stderr and kept in the data's `source`.

use std::path::Path;

use anyhow::Context;
use identify::line_choice::LineChoice;
use identify::{data, measurement_map, plausibility, Observations};
use rfe::{MeasuredData, Model};

/// Loads `path` (UFF with `map`, else JSON/CSV) in the model's convention.
pub fn load(path: &Path, map: Option<&Path>, model: &Model) -> anyhow::Result<MeasuredData> {
    let bytes = std::fs::read(path)
        .with_context(|| format!("{}: cannot read the data file", path.display()))?;
    let origin = path.display().to_string();
    let measured = if process::uff::looks_like_uff(&bytes) {
        let file = process::uff::parse_file(&bytes, &origin)?;
        let (channels, notes) = process::uff::measured_channels(&file, &origin)?;
        let Some(map) = map else {
            anyhow::bail!(
                "{origin} is a UFF file of {} FRF(s): give --map FILE saying which node and direction is which body of the model (docs/identification.md, measurement map)",
                channels.len()
            );
        };
        let map = measurement_map::load(map, model)?;
        let mut m = map.apply(&channels, &origin, model)?;
        for n in notes {
            m.source.push_str("; ");
            m.source.push_str(&n);
        }
        m
    } else {
        anyhow::ensure!(
            map.is_none(),
            "--map applies to UFF files (node and direction → body); {origin} is ident's JSON/CSV, which names bodies and DOFs itself"
        );
        data::load_for_model(path, model)?
    };
    // What was taken from the file, assumed or converted; the plain statement that ident's own
    // JSON/CSV is SI (its documented convention) stays in `source` only.
    for note in measured.source.split("; ").skip(1) {
        if !note.starts_with("units: ") {
            eprintln!("data: {note}");
        }
    }
    Ok(measured)
}

/// Keeps the lines `choice` keeps and, with `points`, decimates each characteristic to at most
/// that many (log-uniform plus resonance peaks, `process::selection`); what was dropped is said on
/// stderr, one line per characteristic.
pub fn choose_lines(
    measured: &MeasuredData,
    choice: &LineChoice,
    points: Option<usize>,
    path: &Path,
) -> anyhow::Result<MeasuredData> {
    let origin = path.display().to_string();
    let mut out = measured.clone();
    if !choice.is_all() {
        let (chosen, accounts) = choice.apply(measured, &origin)?;
        for a in accounts {
            eprintln!("lines: {} ({})", a.describe(), choice.describe());
        }
        out = chosen;
    }
    if let Some(n) = points {
        anyhow::ensure!(
            n >= 2,
            "--points {n}: give at least 2 lines per characteristic"
        );
        for m in &mut out.characteristics {
            decimate(m, n, &origin)?;
        }
    }
    Ok(out)
}

/// Decimates one characteristic to at most `n` lines (`process::selection::select_points`).
fn decimate(m: &mut rfe::Measurement, n: usize, origin: &str) -> anyhow::Result<()> {
    let before = m.freqs_hz.len();
    if before <= n {
        return Ok(());
    }
    let config = process::selection::SelectionConfig {
        count: n,
        min_coherence: 0.0,
        ..Default::default()
    };
    let label = format!("{origin}: {}", m.label());
    let chosen =
        process::selection::select_points(&label, &m.freqs_hz, &m.amplitude, None, &config)?;
    let mut keep = vec![false; before];
    for k in chosen {
        keep[k] = true;
    }
    identify::line_choice::retain(m, &keep);
    eprintln!(
        "lines: {}: decimated from {before} to {} lines (log-uniform, denser at the resonance peaks)",
        m.label(),
        m.freqs_hz.len()
    );
    Ok(())
}

/// The band check (an error) and the level check (warnings on stderr).
pub fn check(model: &Model, obs: &Observations) -> anyhow::Result<()> {
    plausibility::check_band(model, obs)?;
    for level in plausibility::check_level(model, obs) {
        if let Some(w) = level.warning {
            eprintln!("warning: {w}");
        }
    }
    Ok(())
}
