//! Ranking candidate effects by a score (Lagrange-multiplier) test at the current fit.
//!
//! With whitened residuals `e` and Jacobian `J` of the free variables at the fit, and `g = ∂e/∂γ`
//! for an effect's parameter at its nested value, the score is `s = gᵀe` (= ∂J/∂γ) and
//!
//! ```text
//! LM = s² / (σ̂² · gᵀ(I − P)g),   P = J(JᵀJ)⁻¹Jᵀ,
//! ```
//!
//! χ²(1) under "no effect" (σ̂² = 1 when R is known). Effects bounded at their nested value
//! (a stiffness, a mass, a compliance cannot be negative) are tested one-sided: only a score that
//! lowers J for γ above the nested value counts, p = ½·P(χ²₁ > LM).
//!
//! Every `g` but the flexible body's comes from one set of solves ([`frf::states`]): the effect's
//! first-order action `∂q_o = −w_oᵀ ΔA q` costs O(its support) per line.

use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};

use super::effects::{split_body, Effect};
use crate::frf::{self, States};
use crate::identification::Criterion;
use crate::model::{Model, ParamRef};
use crate::C64;

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// One candidate's score test.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Scored {
    /// Index into the candidate list.
    pub candidate: usize,
    /// LM statistic.
    pub statistic: f64,
    /// p-value (one-sided where the effect is bounded at its nested value).
    pub p_value: f64,
    /// One Gauss-Newton step for γ from the nested value, with the variables re-adjusted (SI).
    pub step: f64,
    /// The candidate's whitened column with the fit's columns projected out, unit length: two
    /// candidates whose directions nearly coincide cannot be told apart by the data.
    #[serde(skip)]
    pub direction: DVector<f64>,
}

/// The fit the scores are taken at.
pub struct FitPoint<'a> {
    /// The criterion of the current (realized) model.
    pub crit: &'a Criterion,
    /// Variables (SI).
    pub x: &'a [f64],
    /// Sensor gains `1 + g` per characteristic.
    pub gains: &'a [f64],
    /// Whitened residuals.
    pub e: &'a DVector<f64>,
    /// Whitened Jacobian of the free parameters (any column scaling).
    pub jac: &'a DMatrix<f64>,
    /// σ̂² (1 when R is known).
    pub sigma2: f64,
}

/// Scores every candidate; `Err` entries say why a candidate could not be scored.
pub fn score_all(fit: &FitPoint, candidates: &[Effect]) -> Result<Vec<Result<Scored, String>>, String> {
    let crit = fit.crit;
    let model = crit.model_at(fit.x);
    let lines = crit.lines().to_vec();
    let states = frf::states(&model, &lines, frf::Method::Auto).map_err(|e| e.to_string())?;
    let outputs: Vec<usize> = model.outputs.iter().map(|c| 6 * c.body + c.dof as usize).collect();
    let q = |o: usize, k: usize| states.load_at(k)[outputs[o]] * states.factor[k * states.outputs + o] * fit.gains[o];
    // Orthonormal basis of the fit Jacobian's columns, for the projection.
    let basis = orthonormal_columns(fit.jac);
    let damping = damping_jacobian(&model, &lines, candidates)?;
    let mut out = Vec::with_capacity(candidates.len());
    let mut dq = vec![C64::new(0.0, 0.0); outputs.len() * lines.len()];
    for (ci, cand) in candidates.iter().enumerate() {
        let filled = fill_derivative(cand, &model, &states, &outputs, fit.gains, &lines, &damping, &mut dq);
        let col = match filled {
            Ok(()) => crit.whitened_derivative(q, |o, k| dq[o * lines.len() + k]),
            Err(e) => {
                out.push(Err(e));
                continue;
            }
        };
        out.push(statistic(ci, cand, &col, fit, &basis));
    }
    Ok(out)
}

fn statistic(ci: usize, cand: &Effect, g: &DVector<f64>, fit: &FitPoint, basis: &DMatrix<f64>) -> Result<Scored, String> {
    let s = g.dot(fit.e);
    let resid = g - basis * (basis.transpose() * g);
    let info = resid.norm_squared();
    if !(info.is_finite() && info > 1e-12 * g.norm_squared().max(1e-300)) {
        return Err("its effect on the characteristics is indistinguishable from the fitted variables' (or nil)".into());
    }
    let lm = s * s / (info * fit.sigma2);
    let step = -s / info;
    let one_sided = cand.params(1.0)[0].lower >= cand.params(1.0)[0].nested;
    let chi = ChiSquared::new(1.0).map_err(|e| e.to_string())?;
    let tail = 1.0 - chi.cdf(lm);
    let p_value = if one_sided {
        if step > 0.0 { 0.5 * tail } else { 1.0 }
    } else {
        tail
    };
    let direction = resid / info.sqrt();
    Ok(Scored { candidate: ci, statistic: if one_sided && step <= 0.0 { 0.0 } else { lm }, p_value, step, direction })
}

/// `∂ output / ∂γ` of one candidate at every (characteristic, line), into `dq[o * lines + k]`.
#[allow(clippy::too_many_arguments)]
fn fill_derivative(
    cand: &Effect,
    model: &Model,
    states: &States,
    outputs: &[usize],
    gains: &[f64],
    lines: &[f64],
    damping: &Option<(Vec<ParamRef>, frf::Response)>,
    dq: &mut [C64],
) -> Result<(), String> {
    let nl = lines.len();
    if let Some(rows) = cand.rows(model) {
        for (k, f) in lines.iter().enumerate() {
            let c = cand.coefficient(TWO_PI * f);
            for (o, g) in gains.iter().enumerate() {
                dq[o * nl + k] = states.first_order(k, o, rows.iter().map(|r| (r.as_slice(), c))) * g;
            }
        }
        return Ok(());
    }
    match cand {
        Effect::Gain { output, .. } => {
            for o in 0..gains.len() {
                for k in 0..nl {
                    dq[o * nl + k] = if o == *output {
                        states.load_at(k)[outputs[o]] * states.factor[k * states.outputs + o] * gains[o]
                    } else {
                        C64::new(0.0, 0.0)
                    };
                }
            }
            Ok(())
        }
        Effect::Damping { sdes, parameter, .. } => {
            let (params, r) = damping.as_ref().ok_or("no damping Jacobian")?;
            dq.iter_mut().for_each(|v| *v = C64::new(0.0, 0.0));
            for (p, pr) in params.iter().enumerate() {
                if pr.name == *parameter && sdes.contains(&model.sdes[pr.sde].name) {
                    for (o, g) in gains.iter().enumerate() {
                        for (k, d) in r.derivative(p, o).iter().enumerate() {
                            dq[o * nl + k] += d * g;
                        }
                    }
                }
            }
            Ok(())
        }
        Effect::Flexible { body, axis, scale } => {
            // The split model at a small compliance against the rigid one: one extra solve.
            let h = 1e-4 * scale;
            let mut split = model.clone();
            split_body(&mut split, body, *axis, h)?;
            let rh = frf::response(&split, lines, &[], frf::Method::Auto).map_err(|e| e.to_string())?;
            for (o, g) in gains.iter().enumerate() {
                for k in 0..nl {
                    let q0 = states.load_at(k)[outputs[o]] * states.factor[k * states.outputs + o];
                    dq[o * nl + k] = (rh.output(o)[k] - q0) / h * g;
                }
            }
            Ok(())
        }
        _ => Err("this effect has no first-order form".into()),
    }
}

/// One Jacobian of every ψ parameter the damping candidates split off.
fn damping_jacobian(model: &Model, lines: &[f64], candidates: &[Effect]) -> Result<Option<(Vec<ParamRef>, frf::Response)>, String> {
    let mut params: Vec<ParamRef> = Vec::new();
    for c in candidates {
        if let Effect::Damping { sdes, parameter, .. } = c {
            for s in sdes {
                if let Some(i) = model.sde_index(s) {
                    let p = ParamRef { sde: i, name: *parameter };
                    if !params.contains(&p) {
                        params.push(p);
                    }
                }
            }
        }
    }
    if params.is_empty() {
        return Ok(None);
    }
    let r = frf::response(model, lines, &params, frf::Method::Auto).map_err(|e| e.to_string())?;
    Ok(Some((params, r)))
}

/// An orthonormal basis of the column space of `j` (thin QR; near-dependent columns dropped).
fn orthonormal_columns(j: &DMatrix<f64>) -> DMatrix<f64> {
    if j.ncols() == 0 {
        return DMatrix::zeros(j.nrows(), 0);
    }
    let qr = j.clone().qr();
    let (q, r) = (qr.q(), qr.r());
    let big = (0..r.nrows().min(r.ncols())).map(|i| r[(i, i)].abs()).fold(0.0, f64::max);
    let keep: Vec<usize> = (0..r.nrows().min(r.ncols())).filter(|&i| r[(i, i)].abs() > 1e-10 * big).collect();
    DMatrix::from_fn(q.nrows(), keep.len(), |a, b| q[(a, keep[b])])
}
