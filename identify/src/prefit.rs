//! Modal pre-fit: a start for the FRF fit from the measured modes. Each measured mode is paired
//! with a model mode visible at the characteristics (by MAC there when the measured shapes are
//! given, else by order), then the stiffness variables are updated to match the measured natural
//! frequencies by damped Gauss-Newton in log-parameters with analytic eigen-sensitivities
//! `∂λ/∂p = φᵀ (∂K/∂p) φ` (mass-normalized φ; M does not depend on the variables), the pairs
//! tracked from one step to the next by MAC. Each pair's log-frequency residual is weighted by
//! the inverse of its variance: the measurement's `(σf/f)²` plus the model form's
//! [`MODEL_FORM_LOG_FREQ_STD`]², so a poorly estimated mode pulls the start less than a sharp one.
//! ψ variables start at 2π times the measured loss factors' inverse-variance weighted mean (a
//! random-effects mean: each loss factor's variance plus the spread between the modes that one ψ
//! cannot follow) when the measured modes carry them.

use rfe::model::Model;
use rfe::system::System;
use rfe::C64;

use super::variables::Variables;

/// One measured mode.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredMode {
    /// Natural frequency (Hz), > 0.
    pub freq_hz: f64,
    /// Standard deviation of the natural frequency (Hz), when known (e.g. from the modal
    /// estimator's covariance); `None` counts the frequency as exact (only the model-form error
    /// remains in its weight).
    pub freq_std_hz: Option<f64>,
    /// Loss factor η (= 2ζ), when known.
    pub loss_factor: Option<f64>,
    /// Standard deviation of the loss factor, when known; `None` counts it as exact.
    pub loss_factor_std: Option<f64>,
    /// Mode shape at the model's output characteristics (in `model.outputs` order), when known.
    pub shape: Option<Vec<C64>>,
}

/// One measured mode and the model mode paired with it.
#[derive(Debug, Clone, PartialEq)]
pub struct Pair {
    /// Index into the measured modes.
    pub measured: usize,
    /// Measured frequency (Hz).
    pub measured_hz: f64,
    /// The paired model mode's frequency at the initial values (Hz).
    pub model_hz_before: f64,
    /// Its frequency after the pre-fit (Hz).
    pub model_hz_after: f64,
    /// MAC between the measured and the model shape at the characteristics (after), when the
    /// measured shape is known.
    pub mac: Option<f64>,
    /// Standard deviation of ln f the pair was weighted with: the measurement's σf/f and the
    /// model form's [`MODEL_FORM_LOG_FREQ_STD`] combined in quadrature.
    pub sigma_log_freq: f64,
    /// Weight of the pair in the frequency match, `1/σ²` relative to the largest (1 for the
    /// sharpest pair; all 1 when the σ are equal).
    pub weight: f64,
    /// Weight of the measured loss factor in the ψ start, relative to the largest; `None` when
    /// ψ was not started from the loss factors.
    pub loss_factor_weight: Option<f64>,
}

/// The outcome of a modal pre-fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Prefit {
    /// The new start (SI), one value per variable.
    pub start: Vec<f64>,
    /// The pairs, in measured order (a measured mode the model has no place for is left out).
    pub pairs: Vec<Pair>,
    /// Gauss-Newton iterations done.
    pub iterations: usize,
    /// RMS of ln(f_model / f_measured) over the pairs (unweighted), before and after.
    pub rms_log_freq: (f64, f64),
    /// The loss factor ψ was started from (`ψ = 2π η`) with its standard error, when every
    /// paired mode has a loss factor.
    pub loss_factor: Option<LossFactorMean>,
}

/// The measured loss factors combined into the one a shared ψ gives every mode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LossFactorMean {
    /// The weighted mean η.
    pub value: f64,
    /// Its standard error (from the weights: `1/sqrt(Σ w)`, with the between-mode spread).
    pub std_error: f64,
    /// The spread of the modes' loss factors beyond their own standard deviations
    /// (DerSimonian-Laird moment estimate; 0 when they agree within them; their whole sample
    /// spread when their standard deviations are not all known).
    pub between_modes_std: f64,
}

/// Why a pre-fit could not be done.
#[derive(Debug, thiserror::Error)]
pub enum PrefitError {
    /// Nothing to match.
    #[error("modal pre-fit: no measured mode to match")]
    NoModes,
    /// A measured frequency that is not a positive number.
    #[error("modal pre-fit: measured mode {0} has frequency {1} Hz (must be > 0)")]
    BadFrequency(usize, f64),
    /// A standard deviation that is not a finite number ≥ 0.
    #[error("modal pre-fit: measured mode {mode} has {what} standard deviation {value} (must be finite and ≥ 0)")]
    BadStd {
        /// The measured mode.
        mode: usize,
        /// Which: "frequency" or "loss factor".
        what: &'static str,
        /// The value given.
        value: f64,
    },
    /// No stiffness variable to move.
    #[error("modal pre-fit: no stiffness variable to update (only ψ variables)")]
    NoStiffness,
    /// More measured modes than model modes visible at the characteristics.
    #[error("modal pre-fit: {measured} measured modes but the model has {model} modes visible at its output characteristics")]
    TooManyModes {
        /// Measured modes.
        measured: usize,
        /// Elastic model modes.
        model: usize,
    },
    /// The model's eigenproblem failed.
    #[error("modal pre-fit: {0}")]
    Eigen(String),
}

/// Largest step in ln x per iteration (a factor 3).
const MAX_LOG_STEP: f64 = 1.0986;

/// Standard deviation of ln f by which the model form misplaces a mode at its best (the
/// model-form error of the frequency match), combined with each measured mode's `σf/f` in
/// quadrature: the residual `ln(f_model/f_measured)` at the values that explain the structure is
/// the estimator's error plus the model's own, independent of it. An RFE model lumps bodies and
/// joints; on the real three-storey structure (`docs/real-structure.md`) the FRF fit's optimum,
/// the best this model form does on the data, leaves the three sway modes −4.0 %, +0.8 % and
/// +0.1 % from the measured ones: RMS 2.3 %, the value taken. The estimator's σf/f there is
/// 1e-5-2e-4: on real structures the model form dominates and a measured σ counts only where it
/// comes near the model's own error. A larger value would make all modes pull alike whatever
/// their σ; a smaller one would let σf that differ by less than the model can follow decide the
/// start.
pub const MODEL_FORM_LOG_FREQ_STD: f64 = 0.023;

/// Undamped modes of `model`: (λ = ω², mass-normalized φ over all DOFs), elastic ones only
/// (ω above 1e-6 of the largest), ascending.
fn elastic_modes(model: &Model, sys: &System) -> Result<Vec<(f64, Vec<f64>)>, PrefitError> {
    let modes = rfe::modes::undamped(model).map_err(|e| PrefitError::Eigen(e.to_string()))?;
    let top = modes.iter().map(|m| m.freq_hz).fold(0.0, f64::max);
    Ok(modes
        .into_iter()
        .filter(|m| m.freq_hz > 1e-6 * top)
        .map(|m| {
            let phi: Vec<f64> = m.shape.iter().map(|v| v.re).collect();
            let norm = sys.mass_inner(&phi, &phi).sqrt();
            let w = 2.0 * std::f64::consts::PI * m.freq_hz;
            (w * w, phi.iter().map(|p| p / norm).collect())
        })
        .collect())
}

/// MAC of two real-or-complex vectors.
fn mac(a: &[C64], b: &[C64]) -> f64 {
    let ab: C64 = a.iter().zip(b).map(|(x, y)| x.conj() * y).sum();
    let aa: f64 = a.iter().map(|x| x.norm_sqr()).sum();
    let bb: f64 = b.iter().map(|x| x.norm_sqr()).sum();
    if aa > 0.0 && bb > 0.0 {
        ab.norm_sqr() / (aa * bb)
    } else {
        0.0
    }
}

/// Mass-weighted MAC of two model shapes (mode tracking).
fn mac_mass(a: &[f64], b: &[f64], sys: &System) -> f64 {
    let ab = sys.mass_inner(a, b);
    ab * ab / (sys.mass_inner(a, a) * sys.mass_inner(b, b))
}

fn shape_at_outputs(sys: &System, phi: &[f64]) -> Vec<C64> {
    sys.output_rows
        .iter()
        .map(|row| C64::new(row.taps.iter().map(|&(d, c)| c * phi[d]).sum(), 0.0))
        .collect()
}

/// Share of a mass-normalized mode's kinetic energy at the output characteristics' DOFs: the
/// modes the measurement can see.
fn visibility(sys: &System, phi: &[f64]) -> f64 {
    let mut dofs: Vec<usize> = sys
        .output_rows
        .iter()
        .flat_map(|row| row.taps.iter().map(|&(d, _)| d))
        .collect();
    dofs.sort_unstable();
    dofs.dedup();
    dofs.iter().map(|&d| sys.mass[d] * phi[d] * phi[d]).sum()
}

/// A mode is visible when at least this share of its kinetic energy is at the outputs' DOFs.
const VISIBLE: f64 = 0.01;

/// Pairs measured modes with distinct visible model modes (see [`VISIBLE`]), as
/// `(measured, model)` index pairs. With every measured shape known: greedily by the highest MAC
/// at the characteristics over all pairs (ties to the nearer frequency), as many pairs as there
/// are visible modes or measured modes (a measured mode the model has no place for stays
/// unpaired). Without shapes: by order (the measured modes ascending onto the lowest visible model
/// modes ascending: a first model may be far off in frequency but rarely in the order of its
/// modes); then every measured mode needs a visible model mode.
fn pair_initial(
    sys: &System,
    model_modes: &[(f64, Vec<f64>)],
    measured: &[MeasuredMode],
) -> Result<Vec<(usize, usize)>, PrefitError> {
    let visible: Vec<usize> = (0..model_modes.len())
        .filter(|&j| visibility(sys, &model_modes[j].1) >= VISIBLE)
        .collect();
    let shapes: Option<Vec<&Vec<C64>>> = measured.iter().map(|m| m.shape.as_ref()).collect();
    let Some(shapes) = shapes else {
        if visible.len() < measured.len() {
            return Err(PrefitError::TooManyModes {
                measured: measured.len(),
                model: visible.len(),
            });
        }
        let mut order: Vec<usize> = (0..measured.len()).collect();
        order.sort_by(|&a, &b| measured[a].freq_hz.total_cmp(&measured[b].freq_hz));
        return Ok(order
            .into_iter()
            .enumerate()
            .map(|(k, r)| (r, visible[k]))
            .collect());
    };
    let mut scored: Vec<(f64, usize, usize)> = Vec::new();
    for (r, s) in shapes.iter().enumerate() {
        let lam_m = (2.0 * std::f64::consts::PI * measured[r].freq_hz).powi(2);
        for &j in &visible {
            let near = (model_modes[j].0 / lam_m).ln().abs();
            scored.push((
                mac(s, &shape_at_outputs(sys, &model_modes[j].1)) - 1e-3 * near,
                r,
                j,
            ));
        }
    }
    scored.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (mut used_r, mut used_j) = (vec![false; measured.len()], vec![false; model_modes.len()]);
    let mut out = Vec::new();
    for (_, r, j) in scored {
        if !used_r[r] && !used_j[j] {
            used_r[r] = true;
            used_j[j] = true;
            out.push((r, j));
        }
    }
    out.sort_unstable();
    Ok(out)
}

/// The modal pre-fit of `vars` on `model` to the `measured` modes: the new start and what was
/// matched. The model's other values are left as they are.
pub fn modal_prefit(
    model: &Model,
    vars: &Variables,
    measured: &[MeasuredMode],
) -> Result<Prefit, PrefitError> {
    let fit = FrequencyMatch {
        model,
        vars,
        stiff: stiffness_variables(vars, measured)?,
    };
    let mut x = vars.initial();
    let m0 = fit.at(&x);
    let sys0 = System::assemble(&m0);
    let modes0 = elastic_modes(&m0, &sys0)?;
    let paired = pair_initial(&sys0, &modes0, measured)?;
    let lam_meas: Vec<f64> = paired
        .iter()
        .map(|&(r, _)| (2.0 * std::f64::consts::PI * measured[r].freq_hz).powi(2))
        .collect();
    let sigma: Vec<f64> = paired
        .iter()
        .map(|&(r, _)| log_freq_std(&measured[r]))
        .collect();
    let weight = relative_weights(&sigma);
    let before: Vec<f64> = paired.iter().map(|&(_, j)| modes0[j].0).collect();
    let mut shapes: Vec<Vec<f64>> = paired.iter().map(|&(_, j)| modes0[j].1.clone()).collect();
    let mut lam: Vec<f64> = before.clone();
    // RMS of ln(f_model/f_measured) with the pairs' weights (the match's criterion) and plain
    // (the report's).
    let rms_with = |lam: &[f64], w: &dyn Fn(usize) -> f64| -> f64 {
        (lam.iter()
            .zip(&lam_meas)
            .enumerate()
            .map(|(k, (a, b))| w(k) * (0.5 * (a / b).ln()).powi(2))
            .sum::<f64>()
            / lam.len() as f64)
            .sqrt()
    };
    let weighted = |lam: &[f64]| rms_with(lam, &|k| weight[k]);
    let rms = |lam: &[f64]| rms_with(lam, &|_| 1.0);
    let rms_before = rms(&lam);
    let mut mu = 1e-3;
    let mut iterations = 0;
    for _ in 0..50 {
        let cur = weighted(&lam);
        if cur < 1e-8 {
            break;
        }
        iterations += 1;
        let mut jac = fit.log_sensitivities(&x, &shapes, &lam);
        for (k, w) in weight.iter().enumerate() {
            jac.row_mut(k).scale_mut(w.sqrt());
        }
        let res = nalgebra::DVector::from_iterator(
            paired.len(),
            lam_meas
                .iter()
                .zip(&lam)
                .zip(&weight)
                .map(|((m, l), w)| w.sqrt() * (m / l).ln()),
        );
        match fit.step(&x, &jac, &res, &shapes, &mut mu, &|l| weighted(l) < cur)? {
            Some(next) => (x, lam, shapes) = next,
            None => break,
        }
    }
    let loss = psi_from_loss_factors(vars, measured, &paired, &mut x);
    let sys = System::assemble(&fit.at(&x));
    let pairs = paired
        .iter()
        .enumerate()
        .map(|(k, &(r, _))| Pair {
            measured: r,
            measured_hz: measured[r].freq_hz,
            model_hz_before: before[k].sqrt() / (2.0 * std::f64::consts::PI),
            model_hz_after: lam[k].sqrt() / (2.0 * std::f64::consts::PI),
            mac: measured[r]
                .shape
                .as_ref()
                .map(|s| mac(s, &shape_at_outputs(&sys, &shapes[k]))),
            sigma_log_freq: sigma[k],
            weight: weight[k],
            loss_factor_weight: loss.as_ref().map(|l| l.1[k]),
        })
        .collect();
    Ok(Prefit {
        start: x,
        pairs,
        iterations,
        rms_log_freq: (rms_before, rms(&lam)),
        loss_factor: loss.map(|l| l.0),
    })
}

/// Standard deviation of ln f for a measured mode in the frequency match: its `σf/f` (first
/// order: `δ ln f = δf / f`) and the model form's [`MODEL_FORM_LOG_FREQ_STD`], independent, in
/// quadrature.
fn log_freq_std(m: &MeasuredMode) -> f64 {
    let measured = m.freq_std_hz.map_or(0.0, |s| s / m.freq_hz);
    measured.hypot(MODEL_FORM_LOG_FREQ_STD)
}

/// Inverse-variance weights `1/σ²` relative to the largest (so equal σ give all 1, the
/// unweighted match, and the damping of the Gauss-Newton steps keeps its scale).
fn relative_weights(sigma: &[f64]) -> Vec<f64> {
    let smallest = sigma.iter().copied().fold(f64::INFINITY, f64::min);
    sigma.iter().map(|s| (smallest / s).powi(2)).collect()
}

/// The stiffness variables the pre-fit moves, after checking the measured modes.
fn stiffness_variables(
    vars: &Variables,
    measured: &[MeasuredMode],
) -> Result<Vec<usize>, PrefitError> {
    if measured.is_empty() {
        return Err(PrefitError::NoModes);
    }
    for (i, m) in measured.iter().enumerate() {
        if !(m.freq_hz.is_finite() && m.freq_hz > 0.0) {
            return Err(PrefitError::BadFrequency(i, m.freq_hz));
        }
        for (what, std) in [
            ("frequency", m.freq_std_hz),
            ("loss factor", m.loss_factor_std),
        ] {
            if let Some(value) = std.filter(|s| !(s.is_finite() && *s >= 0.0)) {
                return Err(PrefitError::BadStd {
                    mode: i,
                    what,
                    value,
                });
            }
        }
    }
    let stiff: Vec<usize> = (0..vars.len())
        .filter(|&i| !vars.vars[i].dissipation && vars.vars[i].initial > 0.0)
        .collect();
    if stiff.is_empty() {
        return Err(PrefitError::NoStiffness);
    }
    Ok(stiff)
}

/// The frequency match of the pre-fit: the model's paired eigenvalues moved to the measured ones
/// by the stiffness variables `stiff`, in ln x.
struct FrequencyMatch<'a> {
    model: &'a Model,
    vars: &'a Variables,
    stiff: Vec<usize>,
}

/// The variables, eigenvalues and shapes after an accepted step.
type Accepted = (Vec<f64>, Vec<f64>, Vec<Vec<f64>>);

impl FrequencyMatch<'_> {
    /// The model at `x`.
    fn at(&self, x: &[f64]) -> Model {
        let mut m = self.model.clone();
        self.vars.apply(&mut m, x);
        m
    }

    /// `∂ ln λ_r / ∂ ln x_i` at `x` for the paired modes' `shapes` and eigenvalues `lam`.
    fn log_sensitivities(
        &self,
        x: &[f64],
        shapes: &[Vec<f64>],
        lam: &[f64],
    ) -> nalgebra::DMatrix<f64> {
        // Sensitivities at x: ∂λ_r/∂x_i = φ_rᵀ (∂K/∂x_i) φ_r; K is linear in every stiffness
        // parameter, so ∂K/∂x_i = (K(x + h e_i) − K(x)) / h exactly (up to round-off).
        let sys = System::assemble(&self.at(x));
        let n = sys.n;
        let quad = |k: &[f64], phi: &[f64]| -> f64 {
            (0..n)
                .map(|a| phi[a] * (0..n).map(|b| k[a * n + b] * phi[b]).sum::<f64>())
                .sum()
        };
        let mut jac = nalgebra::DMatrix::<f64>::zeros(shapes.len(), self.stiff.len());
        for (c, &i) in self.stiff.iter().enumerate() {
            let h = x[i].abs().max(self.vars.vars[i].scale.abs()) * 1e-3;
            let mut xh = x.to_vec();
            xh[i] += h;
            let kh = System::assemble(&self.at(&xh)).k;
            let dk: Vec<f64> = kh.iter().zip(&sys.k).map(|(a, b)| (a - b) / h).collect();
            for (r, phi) in shapes.iter().enumerate() {
                // ∂ ln λ / ∂ ln x
                jac[(r, c)] = quad(&dk, phi) * x[i] / lam[r];
            }
        }
        jac
    }

    /// One damped Gauss-Newton (Levenberg) step in ln x from `x`, trying larger damping `mu`
    /// until the match `improves`: the new point with its eigenvalues and shapes (each pair
    /// tracked to the model mode most like its previous shape), or `None` when no damping helps.
    fn step(
        &self,
        x: &[f64],
        jac: &nalgebra::DMatrix<f64>,
        res: &nalgebra::DVector<f64>,
        shapes: &[Vec<f64>],
        mu: &mut f64,
        improves: &dyn Fn(&[f64]) -> bool,
    ) -> Result<Option<Accepted>, PrefitError> {
        let ns = self.stiff.len();
        for _ in 0..20 {
            let a = jac.transpose() * jac + nalgebra::DMatrix::<f64>::identity(ns, ns) * *mu;
            let Some(step) = a.cholesky().map(|c| c.solve(&(jac.transpose() * res))) else {
                *mu *= 10.0;
                continue;
            };
            let big = step.amax();
            let step = if big > MAX_LOG_STEP {
                step * (MAX_LOG_STEP / big)
            } else {
                step
            };
            let mut xn = x.to_vec();
            for (c, &i) in self.stiff.iter().enumerate() {
                let v = &self.vars.vars[i];
                xn[i] = (x[i] * step[c].exp()).clamp(v.lower.max(f64::MIN_POSITIVE), v.upper);
            }
            let mn = self.at(&xn);
            let sn = System::assemble(&mn);
            let modes = elastic_modes(&mn, &sn)?;
            // Track each pair to the model mode most like its previous shape.
            let mut taken = vec![false; modes.len()];
            let mut next = Vec::with_capacity(shapes.len());
            for s in shapes {
                let j = (0..modes.len())
                    .filter(|&j| !taken[j])
                    .max_by(|&a, &b| {
                        mac_mass(s, &modes[a].1, &sn).total_cmp(&mac_mass(s, &modes[b].1, &sn))
                    })
                    .unwrap_or(0);
                taken[j] = true;
                next.push(j);
            }
            let lam_n: Vec<f64> = next.iter().map(|&j| modes[j].0).collect();
            if improves(&lam_n) {
                *mu = (*mu / 10.0).max(1e-9);
                let shapes_n = next.iter().map(|&j| modes[j].1.clone()).collect();
                return Ok(Some((xn, lam_n, shapes_n)));
            }
            *mu *= 10.0;
        }
        Ok(None)
    }
}

/// ψ from the measured loss factors, when every paired mode has one: a ψ shared by all elements
/// gives every mode η = ψ/2π, so ψ starts at 2π × their weighted mean ([`loss_factor_mean`]).
/// Returns the mean and each pair's relative weight in it.
fn psi_from_loss_factors(
    vars: &Variables,
    measured: &[MeasuredMode],
    paired: &[(usize, usize)],
    x: &mut [f64],
) -> Option<(LossFactorMean, Vec<f64>)> {
    let etas: Vec<(f64, f64)> = paired
        .iter()
        .filter_map(|&(r, _)| {
            measured[r]
                .loss_factor
                .map(|e| (e, measured[r].loss_factor_std.unwrap_or(0.0)))
        })
        .collect();
    if etas.len() != paired.len() || etas.is_empty() {
        return None;
    }
    let (mean, weights) = loss_factor_mean(&etas);
    let eta = mean.value;
    if !(eta.is_finite() && eta > 0.0) {
        return None;
    }
    for (i, v) in vars.vars.iter().enumerate() {
        if v.dissipation {
            x[i] = (2.0 * std::f64::consts::PI * eta).clamp(v.lower, v.upper);
        }
    }
    Some((mean, weights))
}

/// The random-effects (inverse-variance) mean of loss factors `(η_k, σ_k)`: each η_k estimates
/// the one η a shared ψ gives with variance `σ_k² + τ²`, τ the spread of the modes' own damping
/// that one ψ cannot follow, estimated from the loss factors themselves by the DerSimonian-Laird
/// moment estimator (Q, the weighted scatter about the fixed-effect mean, against its
/// expectation k − 1 without spread). Loss factors that agree within their σ get τ = 0, the
/// inverse-variance mean; ones that disagree far beyond them tend to the plain mean, as modes
/// that really differ should; equal σ give the plain mean. Unless every σ is known and > 0 the
/// plain mean (a σ not known cannot rank the modes). Returns the mean and the relative weights
/// (largest 1).
pub fn loss_factor_mean(etas: &[(f64, f64)]) -> (LossFactorMean, Vec<f64>) {
    let k = etas.len() as f64;
    let var: Vec<f64> = etas.iter().map(|e| e.1 * e.1).collect();
    if etas.is_empty() || !var.iter().all(|&v| v > 0.0 && v.is_finite()) {
        let value = etas.iter().map(|e| e.0).sum::<f64>() / k;
        let spread = etas.iter().map(|e| (e.0 - value).powi(2)).sum::<f64>() / (k - 1.0).max(1.0);
        return (
            LossFactorMean {
                value,
                std_error: (spread / k).sqrt(),
                between_modes_std: spread.sqrt(),
            },
            vec![1.0; etas.len()],
        );
    }
    let weighted_mean = |w: &[f64]| -> f64 {
        etas.iter().zip(w).map(|(e, w)| w * e.0).sum::<f64>() / w.iter().sum::<f64>()
    };
    let w: Vec<f64> = var.iter().map(|v| 1.0 / v).collect();
    let sw: f64 = w.iter().sum();
    let fixed = weighted_mean(&w);
    let q: f64 = etas
        .iter()
        .zip(&w)
        .map(|(e, w)| w * (e.0 - fixed).powi(2))
        .sum();
    let c = sw - w.iter().map(|w| w * w).sum::<f64>() / sw;
    let tau2 = if c > 0.0 {
        ((q - (k - 1.0)) / c).max(0.0)
    } else {
        0.0
    };
    let w: Vec<f64> = var.iter().map(|v| 1.0 / (v + tau2)).collect();
    let top = w.iter().copied().fold(0.0, f64::max);
    (
        LossFactorMean {
            value: weighted_mean(&w),
            std_error: 1.0 / w.iter().sum::<f64>().sqrt(),
            between_modes_std: tau2.sqrt(),
        },
        w.iter().map(|w| w / top).collect(),
    )
}

/// `vars` with their initial values replaced by `start` (e.g. a pre-fit's). A scale that was the
/// default (`|initial|`) follows the new start, so the optimizer sees the variables near 1 as it
/// would had the file given that start; an explicit scale is kept.
pub fn with_start(vars: &Variables, start: &[f64]) -> Variables {
    let mut v = vars.clone();
    for (var, &x) in v.vars.iter_mut().zip(start) {
        if var.scale == var.initial.abs() && x != 0.0 {
            var.scale = x.abs();
        }
        var.initial = x;
    }
    v
}
