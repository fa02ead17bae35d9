//! `--start modal`: a start for the fit from the measured modes. The fitted characteristics'
//! modes are extracted as `ident modes-from-data` does (pLSCF, stabilization, automatic selection,
//! LSFD shapes), then `identification::prefit` pairs them with the model's modes and moves the
//! stiffness variables to match their frequencies (and ψ to their loss factors). A mode whose
//! frequency standard deviation (from the LSCF covariance) exceeds 1 % of it is not matched.

use anyhow::{bail, Context};
use identify::{self as idn, prefit};
use process::modal::{self, FrfKind, LscfSettings, ModalData, SelectionSettings};
use process::C64;
use rfe::model::Quantity;

/// Highest LSCF order (as `ident modes-from-data`'s default).
const MAX_ORDER: usize = 40;

/// Measured modes whose frequency standard deviation exceeds this fraction of the frequency are
/// not matched: the pre-fit moves stiffnesses to the measured frequencies, and a frequency known
/// to a few percent only would move them by as much on no evidence.
const MAX_REL_FREQ_STD: f64 = 0.01;

/// The measured modes of `obs` from the characteristics of one reference (the model's
/// excitation if measured, else the first reference the data hold), as outputs: a mode's shape
/// over the outputs is the same under every reference up to a factor, while a mix of references
/// would multiply each row by that reference's own participation. They must share their lines
/// and carry phases.
pub fn measured_modes(
    model: &rfe::Model,
    obs: &idn::Observations,
) -> anyhow::Result<Vec<prefit::MeasuredMode>> {
    let reference = obs
        .characteristics
        .iter()
        .map(|c| c.characteristic.reference)
        .min()
        .unwrap_or(0);
    let chosen: Vec<&idn::data::Observed> = obs
        .characteristics
        .iter()
        .filter(|c| c.characteristic.reference == reference)
        .collect();
    let Some(first) = chosen.first() else {
        bail!("{}: no characteristic", obs.origin);
    };
    let freqs = first.freqs_hz.clone();
    let quantity = first.characteristic.quantity;
    let mut h = Vec::with_capacity(chosen.len() * freqs.len());
    for c in &chosen {
        if c.freqs_hz != freqs {
            bail!(
                "--start modal: {} and {} have different lines; a modal extraction needs the characteristics on common lines",
                first.label,
                c.label
            );
        }
        if c.characteristic.quantity != quantity {
            bail!(
                "--start modal: {} is {} but {} is {}; one quantity for all characteristics",
                first.label,
                quantity.as_str(),
                c.label,
                c.characteristic.quantity.as_str()
            );
        }
        let Some(phase) = &c.phase_rad else {
            bail!(
                "--start modal: {} has no phase; a modal extraction needs complex FRFs",
                c.label
            );
        };
        h.extend(
            c.amplitude
                .iter()
                .zip(phase)
                .map(|(a, p)| C64::from_polar(*a, *p)),
        );
    }
    let kind = match quantity {
        Quantity::Displacement => FrfKind::Receptance,
        Quantity::Velocity => FrfKind::Mobility,
        Quantity::Acceleration => FrfKind::Accelerance,
    };
    let band = (freqs[0], freqs[freqs.len() - 1]);
    let data =
        ModalData::new(freqs, chosen.len(), 1, h, kind).with_context(|| obs.origin.clone())?;
    let orders = modal::lscf(
        &data,
        &LscfSettings {
            max_order: MAX_ORDER,
            band_hz: Some(band),
        },
    )?;
    let diagram = modal::stabilize(orders, modal::StabilityTolerances::default());
    let poles = modal::select_auto(
        &diagram,
        &SelectionSettings {
            band_hz: band,
            min_orders: MAX_ORDER / 4,
            max_damping: 0.2,
        },
    );
    if poles.is_empty() {
        bail!(
            "--start modal: no pole is stable at enough orders in {}..{} Hz; start from the model's values",
            band.0,
            band.1
        );
    }
    let fitted = modal::lsfd(&data, &poles, Some(band))?;
    // Shapes in the model's output order: each model output reads the chosen characteristic at
    // the same place (body, DOF or point, quantity) whatever its reference; None unless every
    // output has one.
    let rows: Option<Vec<usize>> = model
        .outputs
        .iter()
        .map(|o| {
            chosen.iter().position(|c| {
                let k = &c.characteristic;
                (k.body, k.dof, k.quantity, k.at, k.relative)
                    == (o.body, o.dof, o.quantity, o.at, o.relative)
            })
        })
        .collect();
    // A mode whose frequency the data fix poorly (a wide band of plausible values, from the
    // estimator's covariance) would pull the stiffnesses as hard as a sharp one: leave it out.
    let sharp: Vec<&modal::Mode> = fitted
        .modes
        .iter()
        .filter(|m| match m.pole.std {
            Some(s) if s.freq_hz > MAX_REL_FREQ_STD * m.pole.freq_hz => {
                eprintln!(
                    "start: measured mode at {:.4} Hz ± {:.4} Hz left out of the modal pre-fit (σf/f above {} %)",
                    m.pole.freq_hz,
                    s.freq_hz,
                    100.0 * MAX_REL_FREQ_STD
                );
                false
            }
            _ => true,
        })
        .collect();
    Ok(sharp
        .into_iter()
        .map(|m| prefit::MeasuredMode {
            freq_hz: m.pole.freq_hz,
            loss_factor: Some(2.0 * m.pole.damping_ratio),
            shape: rows
                .as_ref()
                .map(|rows| rows.iter().map(|&r| m.shape[r]).collect()),
        })
        .collect())
}

/// The variables with their start moved by the modal pre-fit; what was done goes to stderr.
pub fn modal_start(
    model: &rfe::Model,
    obs: &idn::Observations,
    vars: &idn::Variables,
) -> anyhow::Result<idn::Variables> {
    let modes = measured_modes(model, obs)?;
    let pre = prefit::modal_prefit(model, vars, &modes)?;
    eprintln!(
        "start: modal pre-fit on {} measured mode(s) ({} paired), {} iteration(s), RMS frequency error {:.1} % -> {:.2e} %",
        modes.len(),
        pre.pairs.len(),
        pre.iterations,
        100.0 * (pre.rms_log_freq.0.exp() - 1.0),
        100.0 * (pre.rms_log_freq.1.exp() - 1.0)
    );
    for p in &pre.pairs {
        eprintln!(
            "start: measured {:.4} Hz (η {:.4}) <- model {:.4} Hz -> {:.4} Hz{}",
            p.measured_hz,
            modes[p.measured].loss_factor.unwrap_or(f64::NAN),
            p.model_hz_before,
            p.model_hz_after,
            p.mac.map(|m| format!(", MAC {m:.3}")).unwrap_or_default()
        );
    }
    for (v, x) in vars.vars.iter().zip(&pre.start) {
        eprintln!(
            "start: {} = {} {}",
            v.name,
            rfe::display::num(x / v.unit.factor),
            v.unit.symbol
        );
    }
    Ok(prefit::with_start(vars, &pre.start))
}
