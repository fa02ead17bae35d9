//! Does the fitted model explain the data? A fit whose reduced χ² lies far above 1 — beyond what
//! noise explains (χ² tail probability below [`P_THRESHOLD`] and reduced χ² above
//! [`REDUCED_CHI2_THRESHOLD`]) — converged to residuals that are systematic, not noise; its
//! Cramér-Rao standard errors (which assume the model is right) are then not to be trusted.
//! This is the verdict the report puts in its headline, with the likely causes.

use super::Identification;
use rfe::display::{p_value, sig};

/// Tail probability of χ² below which the residuals are not noise.
pub const P_THRESHOLD: f64 = 1e-6;
/// Reduced χ² above which a misfit is reported (with many observations a tiny excess is already
/// significant; this keeps the verdict for misfits that matter).
pub const REDUCED_CHI2_THRESHOLD: f64 = 3.0;

/// The verdict on a fit whose model does not explain the data.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Misfit {
    /// Reduced χ² = 2J/(m − n_free).
    pub reduced_chi2: f64,
    /// Degrees of freedom m − n_free.
    pub dof: usize,
    /// `P(χ²(dof) ≥ 2J)`.
    pub p_value: f64,
    /// The headline: what it means, what not to trust, the likely causes.
    pub message: String,
}

/// The misfit verdict of `id`, or `None` when the residuals are compatible with the noise model.
pub fn misfit(id: &Identification) -> Option<Misfit> {
    let free = id
        .uncertainty
        .at_bound
        .iter()
        .filter(|b| b.is_none())
        .count();
    let dof = id.observations.saturating_sub(free).max(1);
    let reduced = id.uncertainty.reduced_chi2;
    if !(reduced.is_finite() && reduced > REDUCED_CHI2_THRESHOLD) {
        return None;
    }
    let p = crate::stats::chi2_tail(dof as f64, reduced * dof as f64);
    if !(p < P_THRESHOLD) {
        return None;
    }
    let noise = if id.noise.scale_unknown() {
        " (against the assumed relative error; if the data really are that noisy, say so with --relative-error)"
    } else {
        ""
    };
    let message = format!(
        "THE MODEL DOES NOT EXPLAIN THE DATA: reduced χ² = {} (p {} for {dof} degrees of freedom): the residuals are {}x the noise level{noise}, so they are systematic and the standard errors below are NOT to be trusted. Likely causes: units (g vs m/s², mm vs m, kHz vs Hz, per N vs per the model's excitation: see the data notes), the band (lines the model cannot represent), or the model form (a joint stiffness missing, masses off, a flexible body).",
        sig(reduced, 3),
        match p_value(p) {
            s if s.starts_with('<') => s,
            s => format!("= {s}"),
        },
        sig(reduced.sqrt(), 2)
    );
    Some(Misfit {
        reduced_chi2: reduced,
        dof,
        p_value: p,
        message,
    })
}
