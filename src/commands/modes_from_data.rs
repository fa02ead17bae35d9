//! `ident modes-from-data FILE`: natural frequencies, damping and mode shapes extracted from
//! measured FRFs (poly-reference LSCF, stabilization diagram, LSFD), before any model is written.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context};
use process::modal::{
    self, FrfKind, LscfSettings, ModalData, SelectionSettings, StabilityTolerances,
};
use process::uff::{function_type, Abscissa, Ordinate};
use process::C64;

/// Arguments of `ident modes-from-data`.
#[derive(clap::Args)]
pub struct ModesFromDataArgs {
    /// Measured FRFs: a UFF file (datasets 58/58b, ASCII or binary), one FRF per
    /// response node/direction × reference node/direction, on common lines.
    pub file: PathBuf,
    /// Frequency band, `LO:HI` in Hz (either side may be empty: `20:`, `:400`).
    #[arg(long, value_parser = super::identify::parse_band)]
    pub band: Option<(Option<f64>, Option<f64>)>,
    /// Highest model order of the estimator (each order gives order × references poles).
    #[arg(long, default_value_t = 40)]
    pub max_order: usize,
    /// What the FRFs are when the file does not say (ordinate type 8/11/12): receptance,
    /// mobility or accelerance.
    #[arg(long, value_parser = parse_kind)]
    pub kind: Option<FrfKind>,
    /// Pick the poles nearest these approximate frequencies (Hz, comma-separated) instead of the
    /// automatic selection.
    #[arg(long, value_delimiter = ',')]
    pub freqs: Vec<f64>,
    /// Automatic selection: a pole must be stable at this many orders (default: max(3, order/4)).
    #[arg(long)]
    pub min_orders: Option<usize>,
    /// Stability tolerance on frequency between orders (relative).
    #[arg(long, default_value_t = 0.01)]
    pub tol_freq: f64,
    /// Stability tolerance on damping between orders (relative).
    #[arg(long, default_value_t = 0.05)]
    pub tol_damping: f64,
    /// Stability tolerance on the participation vectors, 1 − MAC.
    #[arg(long, default_value_t = 0.02)]
    pub tol_participation: f64,
    /// Poles with a damping ratio above this are not selected.
    #[arg(long, default_value_t = 0.2)]
    pub max_damping: f64,
    /// Write the stabilization diagram here (SVG).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Write the poles, shapes and the whole diagram here (JSON).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

fn parse_kind(text: &str) -> Result<FrfKind, String> {
    match text {
        "receptance" => Ok(FrfKind::Receptance),
        "mobility" => Ok(FrfKind::Mobility),
        "accelerance" => Ok(FrfKind::Accelerance),
        _ => Err(format!(
            "{text:?}: give receptance, mobility or accelerance"
        )),
    }
}

fn kind_name(k: FrfKind) -> &'static str {
    match k {
        FrfKind::Receptance => "receptance",
        FrfKind::Mobility => "mobility",
        FrfKind::Accelerance => "accelerance",
    }
}

/// A channel: UFF node and direction.
type Channel = (i64, i64);

/// The FRF matrix of a UFF file, with its response and reference channels.
fn load_uff(
    path: &Path,
    kind: Option<FrfKind>,
) -> anyhow::Result<(ModalData, Vec<Channel>, Vec<Channel>)> {
    let file = process::uff::read_file(path)?;
    let origin = path.display().to_string();
    for s in &file.skipped {
        eprintln!("note: {origin}: {s}");
    }
    let mut responses: Vec<Channel> = Vec::new();
    let mut references: Vec<Channel> = Vec::new();
    let mut frfs: BTreeMap<(Channel, Channel), (usize, Vec<C64>)> = BTreeMap::new();
    let mut freqs: Option<(usize, Vec<f64>)> = None;
    let mut file_kind: Option<(usize, FrfKind)> = None;
    for (i, f) in file.functions.iter().enumerate() {
        let (n, _) = file.positions.get(i).copied().unwrap_or((i + 1, 0));
        if f.func_type != function_type::FRF {
            eprintln!(
                "note: {origin}: dataset {n} is function type {} (not an FRF): skipped",
                f.func_type
            );
            continue;
        }
        let Ordinate::Complex(h) = &f.data else {
            bail!("{origin}: dataset {n}: an FRF with real values; complex values are needed");
        };
        let x = f.x();
        if let Abscissa::Even { increment, .. } = f.abscissa {
            if !(increment > 0.0) {
                bail!("{origin}: dataset {n}: abscissa increment {increment} is not positive");
            }
        }
        match &freqs {
            None => freqs = Some((n, x)),
            Some((m, x0)) => {
                if x0.len() != x.len()
                    || x0
                        .iter()
                        .zip(&x)
                        .any(|(a, b)| (a - b).abs() > 1e-9 * b.abs().max(1.0))
                {
                    bail!("{origin}: dataset {n} has other frequency lines than dataset {m}: all FRFs must share their lines");
                }
            }
        }
        let k = match f.axes[1].spec_data_type {
            8 => Some(FrfKind::Receptance),
            11 => Some(FrfKind::Mobility),
            12 => Some(FrfKind::Accelerance),
            _ => None,
        };
        if let Some(k) = k {
            match file_kind {
                None => file_kind = Some((n, k)),
                Some((m, k0)) if k0 != k => bail!(
                    "{origin}: dataset {n} is {} but dataset {m} is {}: one kind per file",
                    kind_name(k),
                    kind_name(k0)
                ),
                _ => {}
            }
        }
        let resp = (f.response_node, f.response_dir);
        let refc = (f.reference_node, f.reference_dir);
        if !responses.contains(&resp) {
            responses.push(resp);
        }
        if !references.contains(&refc) {
            references.push(refc);
        }
        if let Some((m, _)) = frfs.insert((resp, refc), (n, h.clone())) {
            bail!("{origin}: datasets {m} and {n} both hold the FRF of response {}:{} to reference {}:{}", resp.0, resp.1, refc.0, refc.1);
        }
    }
    let Some((_, freqs)) = freqs else {
        bail!("{origin}: no FRF (dataset 58, function type 4) in the file");
    };
    let kind = match (kind, file_kind) {
        (Some(k), _) => k,
        (None, Some((_, k))) => k,
        (None, None) => bail!(
            "{origin}: the FRFs do not say whether they are receptance, mobility or accelerance (ordinate data type not 8/11/12): give --kind"
        ),
    };
    let nl = freqs.len();
    let mut h = Vec::with_capacity(responses.len() * references.len() * nl);
    for r in &responses {
        for q in &references {
            let Some((_, v)) = frfs.get(&(*r, *q)) else {
                bail!("{origin}: no FRF of response {}:{} to reference {}:{}: every response needs an FRF to every reference", r.0, r.1, q.0, q.1);
            };
            h.extend_from_slice(v);
        }
    }
    let data = ModalData::new(freqs, responses.len(), references.len(), h, kind)
        .with_context(|| origin.clone())?;
    Ok((data, responses, references))
}

/// Runs `ident modes-from-data`.
pub fn run(a: ModesFromDataArgs) -> anyhow::Result<ExitCode> {
    let (data, responses, references) = load_uff(&a.file, a.kind)?;
    let first = data.freqs_hz[0];
    let last = data.freqs_hz[data.lines() - 1];
    let band = match a.band {
        Some((lo, hi)) => (lo.unwrap_or(first).max(first), hi.unwrap_or(last).min(last)),
        None => (first, last),
    };
    if !(band.1 > band.0) {
        bail!(
            "--band {}:{} Hz does not overlap the data's lines {first}..{last} Hz",
            band.0,
            band.1
        );
    }
    let orders = modal::lscf(
        &data,
        &LscfSettings {
            max_order: a.max_order,
            band_hz: Some(band),
        },
    )?;
    let diagram = modal::stabilize(
        orders,
        StabilityTolerances {
            freq: a.tol_freq,
            damping: a.tol_damping,
            participation: a.tol_participation,
        },
    );
    let poles = if a.freqs.is_empty() {
        modal::select_auto(
            &diagram,
            &SelectionSettings {
                band_hz: band,
                min_orders: a.min_orders.unwrap_or((a.max_order / 4).max(3)),
                max_damping: a.max_damping,
            },
        )
    } else {
        modal::select_near(&diagram, &a.freqs, 0.05)?
    };
    if poles.is_empty() {
        eprintln!(
            "warning: no pole is stable at enough orders in {}..{} Hz: raise --max-order, lower --min-orders or give --freqs",
            band.0, band.1
        );
    }
    let model = modal::lsfd(&data, &poles, Some(band))?;

    println!(
        "{} × {} {} FRFs, {} lines in {:.6}..{:.6} Hz, orders 1..{}",
        data.outputs,
        data.references,
        kind_name(data.kind),
        data.freqs_hz
            .iter()
            .filter(|&&f| f >= band.0 && f <= band.1)
            .count(),
        band.0,
        band.1,
        a.max_order
    );
    println!(
        "{:>4} {:>12} {:>10} {:>10} {:>11} {:>9}",
        "mode", "f [Hz]", "ζ [-]", "η=2ζ [-]", "complexity", "rank-1"
    );
    for (i, m) in model.modes.iter().enumerate() {
        println!(
            "{:>4} {:>12.4} {:>10.5} {:>10.5} {:>11.3} {:>9.4}",
            i + 1,
            m.pole.freq_hz,
            m.pole.damping_ratio,
            2.0 * m.pole.damping_ratio,
            m.complexity,
            m.rank_one
        );
    }

    if let Some(path) = &a.svg {
        let points: Vec<report::stabilization::DiagramPole> = diagram
            .orders
            .iter()
            .zip(&diagram.stability)
            .flat_map(|(op, st)| {
                op.poles
                    .iter()
                    .zip(st)
                    .map(|(p, s)| report::stabilization::DiagramPole {
                        order: op.order,
                        freq_hz: p.freq_hz,
                        symbol: s.symbol(),
                    })
            })
            .collect();
        let nfrf = (data.outputs * data.references) as f64;
        let indicator: Vec<(f64, f64)> = (0..data.lines())
            .map(|k| {
                let mean = (0..data.outputs)
                    .flat_map(|o| (0..data.references).map(move |r| (o, r)))
                    .map(|(o, r)| data.frf(o, r)[k].norm())
                    .sum::<f64>()
                    / nfrf;
                (data.freqs_hz[k], 20.0 * mean.log10())
            })
            .collect();
        let selected: Vec<f64> = poles.iter().map(|p| p.freq_hz).collect();
        let svg = report::stabilization::stabilization_svg(&points, band, &indicator, &selected)?;
        std::fs::write(path, svg).with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("stabilization diagram: {}", path.display());
    }
    if let Some(path) = &a.json {
        let c = |v: &C64| serde_json::json!([v.re, v.im]);
        let modes: Vec<serde_json::Value> = model
            .modes
            .iter()
            .map(|m| {
                serde_json::json!({
                    "freq_hz": m.pole.freq_hz,
                    "damping_ratio": m.pole.damping_ratio,
                    "loss_factor": 2.0 * m.pole.damping_ratio,
                    "pole_rad_s": c(&m.pole.lambda),
                    "complexity": m.complexity,
                    "rank_one": m.rank_one,
                    "shape": m.shape.iter().map(c).collect::<Vec<_>>(),
                    "participation": m.participation.iter().map(c).collect::<Vec<_>>(),
                })
            })
            .collect();
        let diag: Vec<serde_json::Value> = diagram
            .orders
            .iter()
            .zip(&diagram.stability)
            .map(|(op, st)| {
                serde_json::json!({
                    "order": op.order,
                    "poles": op.poles.iter().zip(st).map(|(p, s)| serde_json::json!({
                        "freq_hz": p.freq_hz,
                        "damping_ratio": p.damping_ratio,
                        "stability": s.symbol().to_string(),
                    })).collect::<Vec<_>>(),
                })
            })
            .collect();
        let doc = serde_json::json!({
            "file": a.file.display().to_string(),
            "kind": kind_name(data.kind),
            "band_hz": [band.0, band.1],
            "max_order": a.max_order,
            "responses": responses.iter().map(|r| format!("{}:{}", r.0, r.1)).collect::<Vec<_>>(),
            "references": references.iter().map(|r| format!("{}:{}", r.0, r.1)).collect::<Vec<_>>(),
            "selection": if a.freqs.is_empty() { "automatic" } else { "user frequencies" },
            "modes": modes,
            "stabilization": diag,
        });
        std::fs::write(path, serde_json::to_string_pretty(&doc)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("poles and shapes: {}", path.display());
    }
    Ok(ExitCode::SUCCESS)
}
