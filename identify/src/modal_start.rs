//! A start for the fit from the measured modes (`--start modal`): the fitted characteristics'
//! modes are extracted as `ident modes-from-data` does (`process::modal`: pLSCF, stabilization,
//! automatic selection, LSFD shapes), then [`crate::prefit`] pairs them with the model's modes and
//! moves the stiffness variables to match their frequencies (and ψ to their loss factors), each
//! weighted by its standard deviations from the LSCF covariance. A mode whose frequency standard
//! deviation exceeds 1 % of it is not matched at all.

use process::modal::{self, FrfKind, LscfSettings, ModalData, SelectionSettings};
use process::C64;
use rfe::model::Quantity;
use rfe::Model;

use crate::data::{Observations, Observed};
use crate::prefit::{self, MeasuredMode, PrefitError};
use crate::variables::Variables;

/// Highest LSCF order (as `ident modes-from-data`'s default).
const MAX_ORDER: usize = 40;

/// Measured modes whose frequency standard deviation exceeds this fraction of the frequency are
/// not matched. The pre-fit weights each mode by its σf, but weights only decide a compromise:
/// with as many stiffness variables as paired modes every paired frequency is matched exactly
/// whatever its weight, and a frequency known to a few percent only would move the stiffnesses by
/// as much on no evidence. Below 1 % a mode's σf is within the model-form error the weights
/// already allow for ([`prefit::MODEL_FORM_LOG_FREQ_STD`]).
const MAX_REL_FREQ_STD: f64 = 0.01;

/// Why no modal start could be made; each names the characteristic or band and what to do.
#[derive(Debug, thiserror::Error)]
pub enum ModalStartError {
    /// The observations hold no characteristic.
    #[error("{0}: no characteristic")]
    NoCharacteristic(String),
    /// Two characteristics of the chosen reference on different lines.
    #[error("--start modal: {first} and {other} have different lines; a modal extraction needs the characteristics on common lines")]
    DifferentLines {
        /// The first characteristic.
        first: String,
        /// The one whose lines differ.
        other: String,
    },
    /// Two characteristics of different quantities.
    #[error("--start modal: {first} is {first_quantity} but {other} is {other_quantity}; one quantity for all characteristics")]
    MixedQuantities {
        /// The first characteristic.
        first: String,
        /// Its quantity.
        first_quantity: &'static str,
        /// The one of another quantity.
        other: String,
        /// That quantity.
        other_quantity: &'static str,
    },
    /// A characteristic without phases.
    #[error("--start modal: {0} has no phase; a modal extraction needs complex FRFs")]
    NoPhase(String),
    /// The FRFs cannot be put together for the modal extraction.
    #[error("{origin}: {why}")]
    Data {
        /// The data file.
        origin: String,
        /// Why.
        why: modal::ModalError,
    },
    /// The extraction failed.
    #[error(transparent)]
    Extraction(#[from] modal::ModalError),
    /// No pole is stable.
    #[error("--start modal: no pole is stable at enough orders in {0}..{1} Hz; start from the model's values")]
    NoStablePole(f64, f64),
    /// The pre-fit failed.
    #[error(transparent)]
    Prefit(#[from] PrefitError),
}

/// The measured modes of `obs` from the characteristics of one reference (the model's
/// excitation if measured, else the first reference the data hold), as outputs: a mode's shape
/// over the outputs is the same under every reference up to a factor, while a mix of references
/// would multiply each row by that reference's own participation. They must share their lines
/// and carry phases. A mode left out for its frequency's uncertainty is said through `note`.
pub fn measured_modes(
    model: &Model,
    obs: &Observations,
    note: &mut dyn FnMut(String),
) -> Result<Vec<MeasuredMode>, ModalStartError> {
    let chosen = one_reference(obs);
    let Some(first) = chosen.first() else {
        return Err(ModalStartError::NoCharacteristic(obs.origin.clone()));
    };
    let freqs = first.freqs_hz.clone();
    let data = modal_data(&chosen, obs)?;
    let band = (freqs[0], freqs[freqs.len() - 1]);
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
        return Err(ModalStartError::NoStablePole(band.0, band.1));
    }
    let fitted = modal::lsfd(&data, &poles, Some(band))?;
    let rows = output_rows(model, &chosen);
    // A mode whose frequency the data fix poorly (a wide band of plausible values, from the
    // estimator's covariance) would pull the stiffnesses as hard as a sharp one: leave it out.
    let sharp = fitted.modes.iter().filter(|m| match m.pole.std {
        Some(s) if s.freq_hz > MAX_REL_FREQ_STD * m.pole.freq_hz => {
            note(format!(
                "measured mode at {:.4} Hz ± {:.4} Hz left out of the modal pre-fit (σf/f above {} %)",
                m.pole.freq_hz,
                s.freq_hz,
                100.0 * MAX_REL_FREQ_STD
            ));
            false
        }
        _ => true,
    });
    Ok(sharp
        .map(|m| MeasuredMode {
            freq_hz: m.pole.freq_hz,
            freq_std_hz: m.pole.std.map(|s| s.freq_hz),
            loss_factor: Some(2.0 * m.pole.damping_ratio),
            // η = 2ζ, so σ_η = 2σ_ζ.
            loss_factor_std: m.pole.std.map(|s| 2.0 * s.damping_ratio),
            shape: rows
                .as_ref()
                .map(|rows| rows.iter().map(|&r| m.shape[r]).collect()),
        })
        .collect())
}

/// The characteristics of one reference: the model's excitation's if measured, else the first
/// reference's the data hold.
fn one_reference(obs: &Observations) -> Vec<&Observed> {
    let reference = obs
        .characteristics
        .iter()
        .map(|c| c.characteristic.reference)
        .min()
        .unwrap_or(0);
    obs.characteristics
        .iter()
        .filter(|c| c.characteristic.reference == reference)
        .collect()
}

/// The chosen characteristics as one FRF matrix (outputs × one input) on their common lines.
fn modal_data(chosen: &[&Observed], obs: &Observations) -> Result<ModalData, ModalStartError> {
    let first = chosen[0];
    let freqs = first.freqs_hz.clone();
    let quantity = first.characteristic.quantity;
    let mut h = Vec::with_capacity(chosen.len() * freqs.len());
    for c in chosen {
        if c.freqs_hz != freqs {
            return Err(ModalStartError::DifferentLines {
                first: first.label.clone(),
                other: c.label.clone(),
            });
        }
        if c.characteristic.quantity != quantity {
            return Err(ModalStartError::MixedQuantities {
                first: first.label.clone(),
                first_quantity: quantity.as_str(),
                other: c.label.clone(),
                other_quantity: c.characteristic.quantity.as_str(),
            });
        }
        let Some(phase) = &c.phase_rad else {
            return Err(ModalStartError::NoPhase(c.label.clone()));
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
    ModalData::new(freqs, chosen.len(), 1, h, kind).map_err(|why| ModalStartError::Data {
        origin: obs.origin.clone(),
        why,
    })
}

/// Shapes in the model's output order: each model output reads the chosen characteristic at the
/// same place (body, DOF or point, quantity) whatever its reference; `None` unless every output
/// has one.
fn output_rows(model: &Model, chosen: &[&Observed]) -> Option<Vec<usize>> {
    model
        .outputs
        .iter()
        .map(|o| {
            chosen.iter().position(|c| {
                let k = &c.characteristic;
                (k.body, k.dof, k.quantity, k.at, k.relative)
                    == (o.body, o.dof, o.quantity, o.at, o.relative)
            })
        })
        .collect()
}

/// The variables with their start moved by the modal pre-fit; what was done is said through
/// `note`, one line each.
pub fn modal_start(
    model: &Model,
    obs: &Observations,
    vars: &Variables,
    note: &mut dyn FnMut(String),
) -> Result<Variables, ModalStartError> {
    let modes = measured_modes(model, obs, note)?;
    let pre = prefit::modal_prefit(model, vars, &modes)?;
    note(format!(
        "modal pre-fit on {} measured mode(s) ({} paired), {} iteration(s), RMS frequency error {:.1} % -> {:.2e} %",
        modes.len(),
        pre.pairs.len(),
        pre.iterations,
        100.0 * (pre.rms_log_freq.0.exp() - 1.0),
        100.0 * (pre.rms_log_freq.1.exp() - 1.0)
    ));
    for p in &pre.pairs {
        let m = &modes[p.measured];
        note(format!(
            "measured {:.4} Hz (η {:.4}) <- model {:.4} Hz -> {:.4} Hz{}; σ(ln f) {:.4} (measured {}), weight {:.3}{}",
            p.measured_hz,
            m.loss_factor.unwrap_or(f64::NAN),
            p.model_hz_before,
            p.model_hz_after,
            p.mac.map(|m| format!(", MAC {m:.3}")).unwrap_or_default(),
            p.sigma_log_freq,
            m.freq_std_hz
                .map(|s| format!("{:.6}", s / m.freq_hz))
                .unwrap_or_else(|| "not known".into()),
            p.weight,
            match (m.loss_factor_std, p.loss_factor_weight) {
                (Some(s), Some(w)) => format!("; σ(η) {s:.5}, η weight {w:.3}"),
                (None, Some(w)) => format!("; η weight {w:.3}"),
                _ => String::new(),
            }
        ));
    }
    if let Some(eta) = pre.loss_factor {
        note(format!(
            "ψ from the loss factors' weighted mean η {:.5} ± {:.5} (spread between modes {:.5})",
            eta.value, eta.std_error, eta.between_modes_std
        ));
    }
    for (v, x) in vars.vars.iter().zip(&pre.start) {
        note(format!(
            "{} = {} {}",
            v.name,
            rfe::display::num(x / v.unit.factor),
            v.unit.symbol
        ));
    }
    Ok(prefit::with_start(vars, &pre.start))
}
