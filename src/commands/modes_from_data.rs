//! `ident modes-from-data FILE`: natural frequencies, damping and mode shapes extracted from
//! measured FRFs (poly-reference LSCF, stabilization diagram, LSFD), before any model is written.
//! The test layout is recognised from the file's channels (`process::modal::layout`): the side
//! with fewer channels carries the polynomial, the shapes are given over the points.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context};
use process::modal::{
    self, indicators, Channel, FrfKind, Layout, LscfSettings, MeasuredFrf, ModalData,
    SelectionSettings, StabilityTolerances,
};
use process::uff::{function_type, Abscissa, Ordinate};
use process::C64;

/// Arguments of `ident modes-from-data`.
#[derive(clap::Args)]
pub struct ModesFromDataArgs {
    /// Measured FRFs: a UFF file (datasets 58/58b, ASCII or binary), one FRF per
    /// response node/direction × reference node/direction, on common lines. Roving hammer,
    /// roving accelerometer, multi-reference and mixed sets are recognised from the channels.
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
    /// Selected poles whose shape has a modal phase collinearity below this (0..1) are left out
    /// (spurious poles have scattered, complex shapes).
    #[arg(long)]
    pub min_mpc: Option<f64>,
    /// Also give the shapes scaled to unit modal mass (needs a driving-point FRF at a fixed
    /// channel).
    #[arg(long)]
    pub mass_normalize: bool,
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

/// The FRFs of a UFF file arranged as points × fixed channels (see `process::modal::layout`).
fn load_uff(path: &Path, kind: Option<FrfKind>) -> anyhow::Result<(ModalData, Layout)> {
    let file = process::uff::read_file(path)?;
    let origin = path.display().to_string();
    for s in &file.skipped {
        eprintln!("note: {origin}: {s}");
    }
    let mut frfs: Vec<MeasuredFrf> = Vec::new();
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
        frfs.push(MeasuredFrf {
            response: Channel {
                node: f.response_node,
                dir: f.response_dir,
            },
            reference: Channel {
                node: f.reference_node,
                dir: f.reference_dir,
            },
            h: h.clone(),
            source: format!("dataset {n}"),
        });
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
    modal::arrange(frfs, freqs, kind).with_context(|| origin.clone())
}

/// Runs `ident modes-from-data`.
pub fn run(a: ModesFromDataArgs) -> anyhow::Result<ExitCode> {
    let (data, layout) = load_uff(&a.file, a.kind)?;
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
    if let Some(m) = a.min_mpc {
        if !(0.0..=1.0).contains(&m) {
            bail!("--min-mpc {m}: give a modal phase collinearity between 0 and 1");
        }
    }
    // Unit-modal-mass shapes need a driving point at a fixed channel; refuse before the work.
    let driving = if a.mass_normalize {
        let Some(q) = layout.driving_points.first() else {
            return Err(modal::ModalError::NoDrivingPoint {
                fixed: layout
                    .fixed
                    .iter()
                    .map(|c| c.to_string())
                    .collect::<Vec<_>>()
                    .join(", "),
            })
            .with_context(|| a.file.display().to_string());
        };
        Some(*q)
    } else {
        None
    };
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
    let mut poles = if a.freqs.is_empty() {
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
    let mut model = modal::lsfd(&data, &poles, Some(band))?;
    if let Some(min_mpc) = a.min_mpc {
        // Poles whose shape is not collinear enough are left out, and the rest refitted.
        let keep: Vec<bool> = model
            .modes
            .iter()
            .map(|m| indicators::mpc(&m.shape) >= min_mpc)
            .collect();
        if keep.iter().any(|k| !k) {
            for (m, _) in model.modes.iter().zip(&keep).filter(|(_, k)| !**k) {
                eprintln!(
                    "note: pole at {:.4} Hz left out: MPC {:.3} < --min-mpc {min_mpc}",
                    m.pole.freq_hz,
                    indicators::mpc(&m.shape)
                );
            }
            poles = poles
                .into_iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(p, _)| p)
                .collect();
            model = modal::lsfd(&data, &poles, Some(band))?;
        }
    }
    let scaled: Vec<Option<Vec<C64>>> = model
        .modes
        .iter()
        .map(|m| {
            driving.and_then(|q| {
                let fixed = layout.fixed.iter().position(|c| *c == q)?;
                let point = layout.points.iter().position(|c| *c == q)?;
                Some(modal::layout::mass_normalized(
                    &m.residues,
                    data.references,
                    fixed,
                    point,
                    m.pole.lambda,
                ))
            })
        })
        .collect();

    print_table(&data, &layout, band, a.max_order, &model);
    if let Some(path) = &a.svg {
        write_svg(path, &data, &diagram, band, &poles)?;
    }
    if let Some(path) = &a.json {
        let doc = json_doc(&a, &data, &layout, band, &diagram, &model, &scaled);
        std::fs::write(path, serde_json::to_string_pretty(&doc)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("poles and shapes: {}", path.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// A standard deviation for the table, `-` when unknown.
fn std_text(s: Option<f64>, decimals: usize) -> String {
    s.map(|v| format!("{v:.decimals$}"))
        .unwrap_or_else(|| "-".into())
}

/// The layout line, the summary line and one row per mode.
fn print_table(
    data: &ModalData,
    layout: &Layout,
    band: (f64, f64),
    max_order: usize,
    model: &modal::ModalModel,
) {
    println!("{}", layout.describe());
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
        max_order
    );
    println!(
        "{:>4} {:>12} {:>9} {:>10} {:>9} {:>10} {:>6} {:>7} {:>6} {:>7}",
        "mode",
        "f [Hz]",
        "σf [Hz]",
        "ζ [-]",
        "σζ [-]",
        "η=2ζ [-]",
        "MPC",
        "MPD [°]",
        "MCF",
        "rank-1"
    );
    for (i, m) in model.modes.iter().enumerate() {
        let q = indicators::shape_quality(&m.shape);
        println!(
            "{:>4} {:>12.4} {:>9} {:>10.5} {:>9} {:>10.5} {:>6.3} {:>7.2} {:>6.3} {:>7.4}",
            i + 1,
            m.pole.freq_hz,
            std_text(m.pole.std.map(|s| s.freq_hz), 4),
            m.pole.damping_ratio,
            std_text(m.pole.std.map(|s| s.damping_ratio), 5),
            2.0 * m.pole.damping_ratio,
            q.mpc,
            q.mpd_deg,
            q.mcf,
            m.rank_one
        );
    }
}

/// The stabilization diagram over the first singular value of the complex mode indicator
/// function (dB).
fn write_svg(
    path: &Path,
    data: &ModalData,
    diagram: &modal::StabilizationDiagram,
    band: (f64, f64),
    poles: &[modal::Pole],
) -> anyhow::Result<()> {
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
    let indicator: Vec<(f64, f64)> = indicators::cmif(data, 1)
        .iter()
        .zip(&data.freqs_hz)
        .map(|(sv, f)| (*f, 20.0 * sv.first().copied().unwrap_or(0.0).log10()))
        .collect();
    let selected: Vec<f64> = poles.iter().map(|p| p.freq_hz).collect();
    let svg = report::stabilization::stabilization_svg(&points, band, &indicator, &selected)?;
    std::fs::write(path, svg).with_context(|| format!("cannot write {}", path.display()))?;
    eprintln!("stabilization diagram: {}", path.display());
    Ok(())
}

/// The JSON document: layout, settings, modes with uncertainty and quality, the whole diagram.
fn json_doc(
    a: &ModesFromDataArgs,
    data: &ModalData,
    layout: &Layout,
    band: (f64, f64),
    diagram: &modal::StabilizationDiagram,
    model: &modal::ModalModel,
    scaled: &[Option<Vec<C64>>],
) -> serde_json::Value {
    let c = |v: &C64| serde_json::json!([v.re, v.im]);
    let names = |v: &[Channel]| v.iter().map(|r| r.to_string()).collect::<Vec<_>>();
    let modes: Vec<serde_json::Value> = model
        .modes
        .iter()
        .zip(scaled)
        .map(|(m, sc)| {
            let q = indicators::shape_quality(&m.shape);
            serde_json::json!({
                "freq_hz": m.pole.freq_hz,
                "freq_std_hz": m.pole.std.map(|s| s.freq_hz),
                "damping_ratio": m.pole.damping_ratio,
                "damping_std": m.pole.std.map(|s| s.damping_ratio),
                "loss_factor": 2.0 * m.pole.damping_ratio,
                "pole_rad_s": c(&m.pole.lambda),
                "complexity": m.complexity,
                "mpc": q.mpc,
                "mpd_deg": q.mpd_deg,
                "mcf": q.mcf,
                "rank_one": m.rank_one,
                "shape": m.shape.iter().map(c).collect::<Vec<_>>(),
                "shape_unit_modal_mass": sc.as_ref().map(|v| v.iter().map(c).collect::<Vec<_>>()),
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
                    "freq_std_hz": p.std.map(|s| s.freq_hz),
                    "damping_ratio": p.damping_ratio,
                    "damping_std": p.std.map(|s| s.damping_ratio),
                    "stability": s.symbol().to_string(),
                })).collect::<Vec<_>>(),
            })
        })
        .collect();
    let (responses, references) = if layout.transposed {
        (&layout.fixed, &layout.points)
    } else {
        (&layout.points, &layout.fixed)
    };
    let t = diagram.tolerances;
    serde_json::json!({
        "file": a.file.display().to_string(),
        "kind": kind_name(data.kind),
        "band_hz": [band.0, band.1],
        "max_order": a.max_order,
        "layout": {
            "kind": layout.kind.name(),
            "points": names(&layout.points),
            "fixed": names(&layout.fixed),
            "polynomial_side": if layout.transposed { "responses" } else { "references" },
            "transposed_by_reciprocity": layout.transposed,
            "reciprocal_frfs": layout.reciprocal,
            "driving_points": names(&layout.driving_points),
            "summary": layout.describe(),
        },
        "responses": names(responses),
        "references": names(references),
        "shapes_over": names(&layout.points),
        "criteria": {
            "tol_freq": t.freq,
            "tol_damping": t.damping,
            "tol_participation": t.participation,
            "min_orders": a.min_orders.unwrap_or((a.max_order / 4).max(3)),
            "max_damping": a.max_damping,
            "min_mpc": a.min_mpc,
        },
        "selection": if a.freqs.is_empty() { "automatic" } else { "user frequencies" },
        "modes": modes,
        "stabilization": diag,
    })
}
