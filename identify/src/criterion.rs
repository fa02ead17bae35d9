//! The identification criterion `J(x) = ½ rᵀR⁻¹r` (paper eq. 4.4) as whitened residuals
//! `e = L⁻¹ r` with `R = L Lᵀ` diagonal, and their Jacobian from the model's analytic
//! sensitivities (eq. 4.7: `∇J = −HᵀR⁻¹(z − q)`).
//!
//! - amplitude fit (the paper's): `r_k = |z_k| − |q_k|`, `∂|q|/∂p = Re(q̄ ∂q/∂p) / |q|`;
//! - complex fit: `r = [Re(z − q), Im(z − q)]` per point.
//!
//! `R` is diagonal; its per-component variances `σ²` come from one [`NoiseSource`].
//!
//! The model's output `q_o` of a characteristic with a sensor-gain variable is `g·q_o`, so its
//! derivatives are `g ∂q_o/∂p` for the model's parameters and `q_o` (the output / g) for `g`.

use nalgebra::{DMatrix, DVector};

use super::data::Observations;
use super::variables::Variables;
use super::IdentifyError;
use rfe::frf::{self, Method, Response};
use rfe::model::{Model, Param, DOF_NAMES};
use rfe::system::System;
use rfe::C64;

/// What is fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FitKind {
    /// Amplitudes only (the paper's A-F characteristics), residual `|z| − |q|`.
    #[default]
    Amplitude,
    /// Log-amplitudes, residual `ln|z| − ln|q|` with σ_ln = σ/|z|: a resonance placed too low
    /// and a model low everywhere cost alike, so a misplaced peak is not "fixed" by lowering the
    /// whole curve (the bias of the amplitude criterion with σ = ε|z|). Needs |z| > 0.
    LogAmplitude,
    /// Real and imaginary parts (needs measured phase).
    Complex,
}

impl FitKind {
    /// The fit for data and a noise choice when the user did not choose: log-amplitude where σ
    /// is only known relative to the level (no variances, no coherence: the relative-error model
    /// σ = ε|z|), amplitude otherwise.
    pub fn for_data(data: &Observations, noise: NoiseChoice) -> FitKind {
        match noise_source(data, noise) {
            Ok(NoiseSource::Relative(_)) => FitKind::LogAmplitude,
            _ => FitKind::Amplitude,
        }
    }

    /// Its name in reports and on the command line.
    pub fn as_str(&self) -> &'static str {
        match self {
            FitKind::Amplitude => "amplitude",
            FitKind::LogAmplitude => "log-amplitude",
            FitKind::Complex => "complex",
        }
    }
}

/// Where the observation covariance `R` comes from.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum NoiseChoice {
    /// `variance` if every point has one; else coherence and averages if every point has them;
    /// else the relative model with ε = 0.01.
    #[default]
    Auto,
    /// The data's `variance` (E|z − z_true|²): σ² = variance / 2 per real component.
    Variance,
    /// The variance of an H1 estimate from coherence γ² and n averages:
    /// σ² = (1 − γ²) / (2 n γ²) · |z|².
    Coherence,
    /// σ = ε·|z| (R known only up to scale).
    Relative(f64),
}

/// The noise model actually used, for reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NoiseSource {
    /// From given variances.
    Variance,
    /// From coherence and averages (H1 estimate).
    Coherence,
    /// σ = ε·|z|.
    Relative(f64),
}

impl NoiseSource {
    /// True when `R` is known only up to a factor (the covariance is then scaled by the
    /// residual variance).
    pub fn scale_unknown(&self) -> bool {
        matches!(self, NoiseSource::Relative(_))
    }

    /// A sentence for reports.
    pub fn describe(&self) -> String {
        match self {
            NoiseSource::Variance => "R from the data's variances (σ² = variance/2 per component)".into(),
            NoiseSource::Coherence => {
                "R from coherence and averages, var|H1| = (1−γ²)/(2nγ²)·|H|²".into()
            }
            NoiseSource::Relative(e) => format!(
                "R from a relative-error model σ = {e}·|z| (known only up to scale: covariances are scaled by the residual variance)"
            ),
        }
    }
}

/// How the Jacobian is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum JacobianMode {
    /// The model's analytic sensitivities (one solve gives values and derivatives).
    #[default]
    Analytic,
    /// Forward differences, one extra model evaluation per variable (for comparison only).
    ForwardDifference,
}

/// One observation component.
#[derive(Debug, Clone, Copy)]
struct Obs {
    /// Output index in the working model.
    output: usize,
    /// Line index in the frequency grid.
    line: usize,
    /// Measured value: amplitude, or the complex value.
    z: C64,
    /// Standard deviation of each real component of the residual (for a log-amplitude fit, of
    /// ln|z|: σ/|z|).
    sigma: f64,
}

/// Counters of model evaluations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Evaluations {
    /// Frequency-response solves (each over all lines), with or without derivatives.
    pub model: usize,
    /// Of those, solves that also produced the analytic Jacobian.
    pub with_jacobian: usize,
}

/// The criterion for one model, data set and variable set.
pub struct Criterion {
    model: Model,
    /// The working model's assembled system, kept between evaluations.
    system: System,
    /// True when every variable sets an SDE law's value: the kept system then only needs its
    /// laws re-read ([`System::update_laws`]); otherwise (masses, inertias) it is assembled again
    /// at each evaluation.
    laws_only: bool,
    /// The last solve's response, its buffers reused by the next.
    response: Response,
    freqs: Vec<f64>,
    obs: Vec<Obs>,
    fit: FitKind,
    params: Vec<Param>,
    /// Per variable: (index into `params`, ratio).
    terms: Vec<Vec<(usize, f64)>>,
    /// Per characteristic (data order): the gain variable and its ratio, if any.
    gains: Vec<Option<(usize, f64)>>,
    vars: Variables,
    method: Method,
    /// Model evaluations so far.
    pub evaluations: Evaluations,
    /// The noise model used.
    pub noise: NoiseSource,
    /// Per characteristic: (label, range of point indices into `obs` / residual rows).
    pub groups: Vec<(String, std::ops::Range<usize>)>,
}

/// Where R comes from: the choice, or with `Auto` variances, else coherence and averages, else
/// 1 % of the amplitude.
fn noise_source(data: &Observations, noise: NoiseChoice) -> Result<NoiseSource, IdentifyError> {
    Ok(match noise {
        NoiseChoice::Auto => {
            if data.characteristics.iter().all(|c| c.variance.is_some()) {
                NoiseSource::Variance
            } else if data
                .characteristics
                .iter()
                .all(|c| c.coherence.is_some() && c.averages.is_some())
            {
                NoiseSource::Coherence
            } else {
                NoiseSource::Relative(0.01)
            }
        }
        NoiseChoice::Variance => NoiseSource::Variance,
        NoiseChoice::Coherence => NoiseSource::Coherence,
        NoiseChoice::Relative(e) => {
            if !(e.is_finite() && e > 0.0) {
                return Err(IdentifyError::Noise {
                    item: "relative error".into(),
                    message: format!("ε = {e} must be a finite number > 0"),
                });
            }
            NoiseSource::Relative(e)
        }
    })
}

/// Every measured point as an observation (characteristic, line, value, σ), and each
/// characteristic's range of observations with its label.
#[allow(clippy::type_complexity)]
fn observations(
    data: &Observations,
    freqs: &[f64],
    fit: FitKind,
    source: NoiseSource,
) -> Result<(Vec<Obs>, Vec<(String, std::ops::Range<usize>)>), IdentifyError> {
    let mut obs = Vec::new();
    let mut groups = Vec::new();
    for (o, c) in data.characteristics.iter().enumerate() {
        let item = format!("{}: {}", data.origin, c.label);
        let start = obs.len();
        if fit == FitKind::Complex && c.phase_rad.is_none() {
            return Err(IdentifyError::Noise {
                item,
                message: "a complex fit needs phase_rad for every characteristic; add the phases or fit amplitudes only".into(),
            });
        }
        for k in 0..c.freqs_hz.len() {
            let a = c.amplitude[k];
            let var = point_variance(c, k, source, &item)?;
            let line = freqs.partition_point(|f| *f < c.freqs_hz[k]);
            let z = match (fit, &c.phase_rad) {
                (FitKind::Complex, Some(p)) => C64::from_polar(a, p[k]),
                _ => C64::new(a, 0.0),
            };
            let sigma = match fit {
                FitKind::LogAmplitude if !(a > 0.0 && a.is_finite()) => {
                    return Err(IdentifyError::Noise {
                        item: format!("{item}, point {k} ({} Hz)", c.freqs_hz[k]),
                        message: format!(
                            "amplitude {a}: a log-amplitude fit needs amplitudes > 0; drop the point or choose --fit amplitude"
                        ),
                    });
                }
                FitKind::LogAmplitude => var.sqrt() / a,
                _ => var.sqrt(),
            };
            obs.push(Obs {
                output: o,
                line,
                z,
                sigma,
            });
        }
        groups.push((c.label.clone(), start..obs.len()));
    }
    Ok((obs, groups))
}

/// σ² of point `k` of `c` under the noise model `source` (per real component: half the complex
/// variance E|ẑ−z|²); `item` names the characteristic in errors.
fn point_variance(
    c: &super::data::Observed,
    k: usize,
    source: NoiseSource,
    item: &str,
) -> Result<f64, IdentifyError> {
    let a = c.amplitude[k];
    let item = item.to_string();
    let var = match source {
        NoiseSource::Variance => match &c.variance {
            Some(v) => v[k] / 2.0,
            None => {
                return Err(IdentifyError::Noise { item, message: "no variances in the data; choose another noise model (coherence or relative)".into() })
            }
        },
        NoiseSource::Coherence => match (&c.coherence, c.averages) {
            (Some(g), Some(n)) => (1.0 - g[k]) / (2.0 * n as f64 * g[k]) * a * a,
            _ => {
                return Err(IdentifyError::Noise { item, message: "no coherence or no averages in the data; choose another noise model (variance or relative)".into() })
            }
        },
        NoiseSource::Relative(e) => (e * a).powi(2),
    };
    if !(var.is_finite() && var > 0.0) {
        return Err(IdentifyError::Noise {
            item: format!("{item}, point {k} ({} Hz)", c.freqs_hz[k]),
            message: format!(
                "the noise model gives σ² = {var} here (zero amplitude or coherence 1); such a point would have infinite weight: drop it or give variances"
            ),
        });
    }
    Ok(var)
}

/// Whitened log-amplitude residual `(ln|z| − ln|q|)/σ_ln`; a model response of exactly zero
/// counts as the smallest positive amplitude (a huge but finite residual).
fn log_residual(o: &Obs, q: C64) -> f64 {
    (o.z.re.ln() - q.norm().max(f64::MIN_POSITIVE).ln()) / o.sigma
}

/// `∂/∂x` of [`log_residual`] for a change `dq` of the response: `−Re(q̄ dq)/|q|² / σ_ln`
/// (0 where q = 0, the subgradient).
fn log_derivative(o: &Obs, q: C64, dq: C64) -> f64 {
    let q2 = q.norm_sqr();
    if q2 > 0.0 {
        -(q.conj() * dq).re / q2 / o.sigma
    } else {
        0.0
    }
}

impl Criterion {
    /// Builds the criterion: the model's outputs become the measured characteristics, the
    /// frequency grid the union of the measured frequencies.
    pub fn new(
        model: &Model,
        data: &Observations,
        vars: &Variables,
        fit: FitKind,
        noise: NoiseChoice,
        method: Method,
    ) -> Result<Criterion, IdentifyError> {
        let freqs = data.lines_hz();
        let source = noise_source(data, noise)?;
        let mut work = model.clone();
        work.outputs = data
            .characteristics
            .iter()
            .map(|c| c.characteristic)
            .collect();
        let (obs, groups) = observations(data, &freqs, fit, source)?;
        let params = vars.model_params();
        let gains: Vec<Option<(usize, f64)>> = data
            .characteristics
            .iter()
            .map(|c| vars.gain(c.characteristic.body, c.characteristic.dof))
            .collect();
        for (i, v) in vars.vars.iter().enumerate() {
            for t in &v.targets {
                if let Param::Gain { body, dof } = t.param {
                    let measured = data
                        .characteristics
                        .iter()
                        .any(|c| c.characteristic.body == body && c.characteristic.dof == dof);
                    if !measured {
                        return Err(IdentifyError::GainWithoutData {
                            origin: vars.origin.clone(),
                            variable: vars.vars[i].name.clone(),
                            characteristic: format!(
                                "{} {}",
                                model
                                    .bodies
                                    .get(body)
                                    .map(|b| b.name.as_str())
                                    .unwrap_or("?"),
                                DOF_NAMES.get(dof as usize).copied().unwrap_or("?")
                            ),
                        });
                    }
                }
            }
        }
        let terms = vars
            .vars
            .iter()
            .map(|v| {
                v.targets
                    .iter()
                    .filter_map(|t| {
                        let p = params.iter().position(|p| *p == t.param)?;
                        Some((p, t.ratio))
                    })
                    .collect()
            })
            .collect();
        let laws_only = params.iter().all(|p| matches!(p, Param::Sde(_)));
        let c = Criterion {
            system: System::assemble(&work),
            laws_only,
            response: Response {
                freqs_hz: Vec::new(),
                outputs: 0,
                params: Vec::new(),
                values: Vec::new(),
                jacobian: Vec::new(),
            },
            model: work,
            freqs,
            obs,
            fit,
            params,
            terms,
            gains,
            vars: vars.clone(),
            method,
            evaluations: Evaluations::default(),
            noise: source,
            groups,
        };
        if vars.len() > c.residual_count() {
            return Err(IdentifyError::TooManyVariables {
                variables: vars.len(),
                observations: c.residual_count(),
            });
        }
        Ok(c)
    }

    /// Number of whitened residuals (points, ×2 for a complex fit).
    pub fn residual_count(&self) -> usize {
        match self.fit {
            FitKind::Amplitude | FitKind::LogAmplitude => self.obs.len(),
            FitKind::Complex => 2 * self.obs.len(),
        }
    }

    /// Number of variables.
    pub fn variable_count(&self) -> usize {
        self.vars.len()
    }

    /// The working model with values `x` (SI) applied.
    pub fn model_at(&self, x: &[f64]) -> Model {
        let mut m = self.model.clone();
        self.vars.apply(&mut m, x);
        m
    }

    /// The sensor gain of characteristic `o` (data order) at values `x`: 1 unless a gain
    /// variable sets it.
    pub fn gain(&self, o: usize, x: &[f64]) -> f64 {
        match self.gains.get(o).copied().flatten() {
            Some((v, ratio)) => ratio * x[v],
            None => 1.0,
        }
    }

    /// The variable that sets the sensor gain of characteristic `o` (data order), if any.
    pub fn gain_variable(&self, o: usize) -> Option<usize> {
        self.gains.get(o).copied().flatten().map(|(v, _)| v)
    }

    /// Model responses `q` at every observation for values `x` (with the sensor gains).
    pub fn predicted(&mut self, x: &[f64]) -> Result<Vec<C64>, frf::SolveError> {
        self.solve(x, None)?;
        Ok(self.predicted_of_response(x))
    }

    /// Model responses `q` at every observation (with the sensor gains at `x`) from the last
    /// solve.
    fn predicted_of_response(&self, x: &[f64]) -> Vec<C64> {
        let r = &self.response;
        self.obs
            .iter()
            .map(|o| r.output(o.output)[o.line] * self.gain(o.output, x))
            .collect()
    }

    /// Applies `x` (SI) to the working model and solves it into `self.response`, with the
    /// Jacobian of `params` when given (none: a plain response, for which [`Method::Auto`] may
    /// choose another path). The kept system is updated, or assembled again when variables
    /// move masses.
    fn solve(&mut self, x: &[f64], params: Option<&[Param]>) -> Result<(), frf::SolveError> {
        self.vars.apply(&mut self.model, x);
        if self.laws_only {
            self.system.update_laws(&self.model);
        } else {
            self.system = System::assemble(&self.model);
        }
        frf::response_params_into(
            &self.system,
            &self.model,
            &self.freqs,
            params.unwrap_or(&[]),
            self.method,
            &mut self.response,
        )?;
        self.evaluations.model += 1;
        if params.is_some() {
            self.evaluations.with_jacobian += 1;
        }
        Ok(())
    }

    /// Measured values at every observation (amplitude fit: the amplitude as a real number).
    pub fn measured(&self) -> Vec<C64> {
        self.obs.iter().map(|o| o.z).collect()
    }

    /// Whitened residuals `e = (z − q)/σ` at `x` (SI) and, if asked, their Jacobian `∂e/∂x`
    /// (rows: residuals, columns: variables, per SI unit of each variable).
    pub fn evaluate(
        &mut self,
        x: &[f64],
        jacobian: Option<JacobianMode>,
    ) -> Result<(DVector<f64>, Option<DMatrix<f64>>), frf::SolveError> {
        match jacobian {
            None => Ok((self.residuals_only(x)?, None)),
            Some(JacobianMode::Analytic) => {
                let (e, j) = self.residuals_analytic(x)?;
                Ok((e, Some(j)))
            }
            Some(JacobianMode::ForwardDifference) => {
                let e = self.residuals_only(x)?;
                let n = x.len();
                let mut j = DMatrix::zeros(e.len(), n);
                let mut xp = x.to_vec();
                for i in 0..n {
                    let h = 1e-7 * self.vars.vars[i].scale.max(x[i].abs());
                    xp[i] = x[i] + h;
                    let ep = self.residuals_only(&xp)?;
                    xp[i] = x[i];
                    j.set_column(i, &((ep - &e) / h));
                }
                Ok((e, Some(j)))
            }
        }
    }

    fn residuals_only(&mut self, x: &[f64]) -> Result<DVector<f64>, frf::SolveError> {
        self.solve(x, None)?;
        let r = &self.response;
        Ok(self.residuals_of(x, |o, line| r.output(o)[line]))
    }

    /// Whitened residuals at `x` (SI) with their analytic Jacobian and the model responses `q`
    /// at every observation ([`Criterion::predicted`]), all from one solve.
    #[allow(clippy::type_complexity)]
    pub fn evaluate_predicted(
        &mut self,
        x: &[f64],
    ) -> Result<(DVector<f64>, DMatrix<f64>, Vec<C64>), frf::SolveError> {
        let (e, j) = self.evaluate_with(x, &[])?;
        Ok((e, j, self.predicted_of_response(x)))
    }

    /// Whitened residuals of model responses `q` at every observation ([`Criterion::predicted`],
    /// gains included): those [`Criterion::evaluate`] gives at the `x` they were predicted at.
    pub fn residuals_of_predicted(&self, q: &[C64]) -> DVector<f64> {
        let mut e = DVector::zeros(self.residual_count());
        for (i, (o, &q)) in self.obs.iter().zip(q).enumerate() {
            self.write_residual(&mut e, i, o, q);
        }
        e
    }

    /// Writes observation `i`'s whitened residual of the model output `q` (gains applied) into
    /// `e`: its one entry, or its real part at `i` and its imaginary part `obs.len()` further.
    fn write_residual(&self, e: &mut DVector<f64>, i: usize, o: &Obs, q: C64) {
        match self.fit {
            FitKind::Amplitude => e[i] = (o.z.re - q.norm()) / o.sigma,
            FitKind::LogAmplitude => e[i] = log_residual(o, q),
            FitKind::Complex => {
                let d = (o.z - q) / o.sigma;
                e[i] = d.re;
                e[self.obs.len() + i] = d.im;
            }
        }
    }

    /// Whitened residuals `e = (z − g q)/σ` of given model outputs `q(characteristic, line)`
    /// (the working model's outputs, data order, at [`Criterion::lines`]) at values `x` (the
    /// gains `g` are read from `x`): the residuals of a model solved elsewhere, e.g. by
    /// [`rfe::lowrank`].
    pub fn residuals_of(&self, x: &[f64], q: impl Fn(usize, usize) -> C64) -> DVector<f64> {
        let mut e = DVector::zeros(self.residual_count());
        for (i, o) in self.obs.iter().enumerate() {
            let q = q(o.output, o.line) * self.gain(o.output, x);
            self.write_residual(&mut e, i, o, q);
        }
        e
    }

    fn residuals_analytic(
        &mut self,
        x: &[f64],
    ) -> Result<(DVector<f64>, DMatrix<f64>), frf::SolveError> {
        self.evaluate_with(x, &[])
    }

    /// Whitened residuals at `x` (SI) with the analytic Jacobian of the variables and, after
    /// their columns, one column per combination `further[j]` of the working model's physical
    /// parameters: `Σ c · ∂e/∂p` over its `(p, c)` terms (per SI unit of each `p`). A change of
    /// the model that moves only physical parameters (an added SDE's stiffness, a body's mass)
    /// has its derivative here from the same solves as the variables' (the adjoint states each
    /// line already has), instead of a further evaluation per parameter.
    pub fn evaluate_with(
        &mut self,
        x: &[f64],
        further: &[Vec<(Param, f64)>],
    ) -> Result<(DVector<f64>, DMatrix<f64>), frf::SolveError> {
        // The variables' parameters, extended by the further columns' (taken out of `self` for
        // the solve and put back), and the further columns' terms.
        let mut params = std::mem::take(&mut self.params);
        let own = params.len();
        let mut further_terms = Vec::with_capacity(further.len());
        for combination in further {
            let mut t = Vec::with_capacity(combination.len());
            for &(p, c) in combination {
                let at = match params.iter().position(|q| *q == p) {
                    Some(at) => at,
                    None => {
                        params.push(p);
                        params.len() - 1
                    }
                };
                t.push((at, c));
            }
            further_terms.push(t);
        }
        let solved = self.solve(x, Some(&params));
        params.truncate(own);
        self.params = params;
        solved?;
        let columns = self.terms.len() + further_terms.len();
        let r = &self.response;
        let m = self.residual_count();
        let n = self.vars.len();
        let np = self.obs.len();
        let mut e = DVector::zeros(m);
        let mut jac = DMatrix::zeros(m, columns);
        // ∂q/∂p of output `o` at line `k` is `r.jacobian[p * stride + o * lines + k]`.
        let lines = r.freqs_hz.len();
        let stride = r.outputs * lines;
        // Per point: where its response is, its gain, the response, with the gain and |q|.
        let mut points = Vec::with_capacity(np);
        for (i, o) in self.obs.iter().enumerate() {
            let g = self.gain(o.output, x);
            let at = o.output * lines + o.line;
            let q0 = r.values[at];
            let q = q0 * g;
            self.write_residual(&mut e, i, o, q);
            points.push((at, g, q0, q, q.norm()));
        }
        // A column at a time: ∂q/∂x of every point, summed over the column's terms in order
        // (a parameter's derivatives are read along its row of the response's Jacobian).
        let mut dqs = vec![C64::new(0.0, 0.0); np];
        for (v, terms) in self.terms.iter().chain(&further_terms).enumerate() {
            dqs.fill(C64::new(0.0, 0.0));
            for &(p, ratio) in terms {
                let row = &r.jacobian[p * stride..(p + 1) * stride];
                for (dq, point) in dqs.iter_mut().zip(&points) {
                    *dq += row[point.0] * ratio;
                }
            }
            for (i, (o, (&(_, g, q0, q, qa), &dq))) in
                self.obs.iter().zip(points.iter().zip(&dqs)).enumerate()
            {
                let mut dq = dq * g;
                if let Some((gv, ratio)) = self.gains[o.output] {
                    if gv == v && v < n {
                        dq += q0 * ratio;
                    }
                }
                match self.fit {
                    FitKind::Amplitude => {
                        // ∂|q|/∂x = Re(q̄ ∂q/∂x)/|q|; at |q| = 0 the modulus is not differentiable:
                        // use the subgradient 0.
                        let da = if qa > 0.0 {
                            (q.conj() * dq).re / qa
                        } else {
                            0.0
                        };
                        jac[(i, v)] = -da / o.sigma;
                    }
                    FitKind::LogAmplitude => jac[(i, v)] = log_derivative(o, q, dq),
                    FitKind::Complex => {
                        jac[(i, v)] = -dq.re / o.sigma;
                        jac[(np + i, v)] = -dq.im / o.sigma;
                    }
                }
            }
        }
        Ok((e, jac))
    }

    /// The frequency grid (Hz): the union of the measured frequencies.
    pub fn lines(&self) -> &[f64] {
        &self.freqs
    }

    /// Amplitude-only or complex.
    pub fn fit(&self) -> FitKind {
        self.fit
    }

    /// Per observation, in residual order: (characteristic index, line index, σ of one
    /// component).
    pub fn points(&self) -> Vec<(usize, usize, f64)> {
        self.obs
            .iter()
            .map(|o| (o.output, o.line, o.sigma))
            .collect()
    }

    /// `∂e/∂γ` for a direction γ in which the model's outputs change by `dq(characteristic,
    /// line)` from `q(characteristic, line)`: how an effect the model does not have would move
    /// the whitened residuals (used by diagnosis).
    pub fn whitened_derivative(
        &self,
        q: impl Fn(usize, usize) -> C64,
        dq: impl Fn(usize, usize) -> C64,
    ) -> DVector<f64> {
        let np = self.obs.len();
        let mut col = DVector::zeros(self.residual_count());
        for (i, o) in self.obs.iter().enumerate() {
            let (qv, d) = (q(o.output, o.line), dq(o.output, o.line));
            match self.fit {
                FitKind::Amplitude => {
                    let qa = qv.norm();
                    col[i] = if qa > 0.0 {
                        -(qv.conj() * d).re / qa / o.sigma
                    } else {
                        0.0
                    };
                }
                FitKind::LogAmplitude => col[i] = log_derivative(o, qv, d),
                FitKind::Complex => {
                    col[i] = -d.re / o.sigma;
                    col[np + i] = -d.im / o.sigma;
                }
            }
        }
        col
    }

    /// RMS amplitude error in dB, `sqrt(mean((20·log10(|q|/|z|))²))`, per characteristic at `x`
    /// (points with |z| = 0 or |q| = 0 are skipped). Unlike the relative error it is not
    /// dominated by the anti-resonance lines, where |z| is small.
    pub fn rms_db_error(&mut self, x: &[f64]) -> Result<Vec<(String, f64)>, frf::SolveError> {
        let q = self.predicted(x)?;
        Ok(self.rms_db_error_of(&q))
    }

    /// [`Criterion::rms_db_error`] of model responses `q` at every observation
    /// ([`Criterion::predicted`]).
    pub fn rms_db_error_of(&self, q: &[C64]) -> Vec<(String, f64)> {
        self.groups
            .iter()
            .map(|(label, range)| {
                let db: Vec<f64> = range
                    .clone()
                    .filter_map(|i| {
                        let (z, qa) = (self.obs[i].z.norm(), q[i].norm());
                        (z > 0.0 && qa > 0.0).then(|| 20.0 * (qa / z).log10())
                    })
                    .collect();
                let ms = db.iter().map(|d| d * d).sum::<f64>() / db.len() as f64;
                (
                    label.clone(),
                    if db.is_empty() { f64::NAN } else { ms.sqrt() },
                )
            })
            .collect()
    }

    /// RMS relative amplitude error `sqrt(mean(((|q| − |z|)/|z|)²))` per characteristic at `x`
    /// (points with |z| = 0 are skipped).
    pub fn rms_relative_error(&mut self, x: &[f64]) -> Result<Vec<(String, f64)>, frf::SolveError> {
        let q = self.predicted(x)?;
        Ok(self.rms_relative_error_of(&q))
    }

    /// [`Criterion::rms_relative_error`] of model responses `q` at every observation
    /// ([`Criterion::predicted`]).
    pub fn rms_relative_error_of(&self, q: &[C64]) -> Vec<(String, f64)> {
        self.groups
            .iter()
            .map(|(label, range)| {
                let mut s = 0.0;
                let mut n = 0usize;
                for i in range.clone() {
                    let z = self.obs[i].z.norm();
                    if z > 0.0 {
                        s += ((q[i].norm() - z) / z).powi(2);
                        n += 1;
                    }
                }
                (
                    label.clone(),
                    if n > 0 {
                        (s / n as f64).sqrt()
                    } else {
                        f64::NAN
                    },
                )
            })
            .collect()
    }
}
