//! Band sensitivity of the amplitude-frequency characteristics to SDE parameters: the paper's
//! mean coefficient of band sensitivity (eq. 4.16)
//!
//! ```text
//! MI(α, i) = Σ_k |∂|q_i(ω_k)|/∂p_α| / Σ_k |q_i(ω_k)|        (1 / unit of p_α)
//! ```
//!
//! and its relative, dimensionless variant `MIr(α, i) = p_α · MI(α, i)`, which ranks parameters of
//! different units against each other: the table an engineer uses to pick decision variables.

use crate::frf::{response_params, Method, SolveError};
use crate::model::{Model, Param, ParamRef};

/// MI of every parameter for every output characteristic over one band.
#[derive(Debug, Clone, PartialEq)]
pub struct Sensitivity {
    /// The parameters (rows).
    pub params: Vec<ParamRef>,
    /// Number of output characteristics (columns).
    pub outputs: usize,
    /// `mi[p * outputs + o]`, eq. 4.16 (per SI unit of the parameter).
    pub mi: Vec<f64>,
    /// `relative[p * outputs + o] = p · mi` (dimensionless).
    pub relative: Vec<f64>,
}

impl Sensitivity {
    /// Parameters ranked by relative MI for output `o`, most sensitive first.
    pub fn ranking(&self, o: usize) -> Vec<(ParamRef, f64, f64)> {
        let mut rows: Vec<(ParamRef, f64, f64)> = self
            .params
            .iter()
            .enumerate()
            .map(|(p, r)| {
                (
                    *r,
                    self.mi[p * self.outputs + o],
                    self.relative[p * self.outputs + o],
                )
            })
            .collect();
        rows.sort_by(|a, b| b.2.total_cmp(&a.2));
        rows
    }
}

/// Computes MI over the lines `freqs_hz` for `params` (all parameters of enabled SDEs if empty).
pub fn band_sensitivity(
    model: &Model,
    freqs_hz: &[f64],
    params: &[ParamRef],
    method: Method,
) -> Result<Sensitivity, SolveError> {
    let params = if params.is_empty() {
        model.all_params()
    } else {
        params.to_vec()
    };
    let all: Vec<Param> = params.iter().map(|&p| p.into()).collect();
    let (mi, relative) = band_mi(model, freqs_hz, &all, method)?;
    Ok(Sensitivity {
        params,
        outputs: model.outputs.len(),
        mi,
        relative,
    })
}

/// [`band_sensitivity`] of any physical parameters (SDE parameters, masses, inertias):
/// `(mi, relative)`, each `[p * outputs + o]`.
pub fn band_mi(
    model: &Model,
    freqs_hz: &[f64],
    params: &[Param],
    method: Method,
) -> Result<(Vec<f64>, Vec<f64>), SolveError> {
    let r = response_params(model, freqs_hz, params, method)?;
    let outputs = model.outputs.len();
    let mut mi = vec![0.0; params.len() * outputs];
    let mut relative = vec![0.0; params.len() * outputs];
    for o in 0..outputs {
        let q = r.output(o);
        let total: f64 = q.iter().map(|v| v.norm()).sum();
        for (p, pr) in params.iter().enumerate() {
            let dq = r.derivative(p, o);
            // ∂|q|/∂p = Re(conj(q) ∂q/∂p) / |q|
            let sum: f64 = q
                .iter()
                .zip(dq)
                .map(|(q, d)| {
                    if q.norm() > 0.0 {
                        ((q.conj() * d).re / q.norm()).abs()
                    } else {
                        0.0
                    }
                })
                .sum();
            let v = if total > 0.0 { sum / total } else { 0.0 };
            mi[p * outputs + o] = v;
            relative[p * outputs + o] = v * model.value(*pr).unwrap_or(0.0).abs();
        }
    }
    Ok((mi, relative))
}
