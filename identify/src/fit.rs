//! The fit itself: [`identify`] takes a model, measured observations and the decision
//! variables and returns the maximum-likelihood estimate with its Cramér-Rao errors.

use nalgebra::{DMatrix, DVector};

use crate::{optimize, starts, uncertainty};
use crate::{
    Criterion, DataError, EvalError, Evaluations, FitKind, JacobianMode, NoiseChoice, NoiseSource,
    Observations, Optimizer, Progress, Settings, StopReason, Uncertainty, Variables, VarsError,
};
use rfe::frf;
use rfe::model::Model;

/// Why an identification could not run.
#[derive(Debug, thiserror::Error)]
pub enum IdentifyError {
    /// Bad measured data.
    #[error(transparent)]
    Data(#[from] DataError),
    /// Bad variables file.
    #[error(transparent)]
    Variables(#[from] VarsError),
    /// More variables than observations.
    #[error(
        "{variables} variables but only {observations} observations: the problem is underdetermined; \
         group parameters (one variable for several SDEs) or add measured points"
    )]
    TooManyVariables {
        /// Number of variables.
        variables: usize,
        /// Number of scalar observations (residuals).
        observations: usize,
    },
    /// The noise model cannot be built from the data.
    #[error("{item}: {message}")]
    Noise {
        /// Where.
        item: String,
        /// What is wrong and how to fix it.
        message: String,
    },
    /// The model cannot be evaluated at the initial values.
    #[error("the model cannot be evaluated at the initial values: {0}")]
    Initial(EvalError),
    /// The model cannot be evaluated at the estimate the minimizer returned.
    #[error("the model cannot be evaluated at the estimate: {0}")]
    Estimate(EvalError),
    /// A gain variable names a characteristic the data do not have.
    #[error(
        "{origin}: variable \"{variable}\" sets the gain of {characteristic}, which the data do not \
         have; measure it or remove the variable"
    )]
    GainWithoutData {
        /// The variables file.
        origin: String,
        /// The variable.
        variable: String,
        /// The characteristic (`table u1`).
        characteristic: String,
    },
    /// No start point was given (`starts` = 0).
    #[error("no start point: give at least one start (--starts 1)")]
    NoStart,
}

/// How to identify.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Amplitude-only (default, as the paper) or complex.
    pub fit: FitKind,
    /// Where R comes from.
    pub noise: NoiseChoice,
    /// The minimizer.
    pub optimizer: Optimizer,
    /// Stopping tolerances and iteration limit.
    pub settings: Settings,
    /// Analytic (default) or finite-difference Jacobian.
    pub jacobian: JacobianMode,
    /// FRF solution path.
    pub frf_method: frf::Method,
    /// Number of starts: 1 = from the initial values only; more adds the points of a Latin
    /// hypercube over the bounds (in log over [x0/10, 10 x0] ∩ bounds where there is no upper
    /// bound; [`starts::latin_hypercube`]).
    pub starts: usize,
    /// Seed of the extra starts.
    pub seed: u64,
    /// Relative σ above which a direction of the information matrix is reported as poorly
    /// identifiable (0.5 = 50 %).
    pub weak_threshold: f64,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            fit: FitKind::Amplitude,
            noise: NoiseChoice::Auto,
            optimizer: Optimizer::LevenbergMarquardt,
            settings: Settings::default(),
            jacobian: JacobianMode::Analytic,
            frf_method: frf::Method::Auto,
            starts: 1,
            seed: 1,
            weak_threshold: 0.5,
        }
    }
}

/// Summary of one start of a multi-start run.
#[derive(Debug, Clone, PartialEq)]
pub struct StartSummary {
    /// Starting values (SI).
    pub x0: Vec<f64>,
    /// Where it ended (SI; the start itself when it could not be evaluated).
    pub estimate: Vec<f64>,
    /// Final criterion (`INFINITY` if the start could not be evaluated).
    pub criterion: f64,
    /// Iterations.
    pub iterations: usize,
    /// Why it stopped.
    pub stop: StopReason,
}

/// The result of an identification.
#[derive(Debug, Clone)]
pub struct Identification {
    /// The decision variables.
    pub variables: Variables,
    /// Initial values (SI).
    pub initial: Vec<f64>,
    /// Estimates (SI), the best point found.
    pub estimate: Vec<f64>,
    /// Criterion J at the initial values.
    pub criterion_initial: f64,
    /// Criterion J at the estimate.
    pub criterion: f64,
    /// Minimizer used.
    pub optimizer: Optimizer,
    /// Why the (best) run stopped.
    pub stop: StopReason,
    /// Iterations of the best run.
    pub iterations: usize,
    /// Model evaluations over all starts (and the final Jacobian).
    pub evaluations: Evaluations,
    /// Noise model used.
    pub noise: NoiseSource,
    /// What was fitted.
    pub fit: FitKind,
    /// Number of scalar observations (residuals).
    pub observations: usize,
    /// Cramér-Rao errors, correlations, identifiability.
    pub uncertainty: Uncertainty,
    /// RMS relative amplitude error per characteristic at the initial values.
    pub rms_initial: Vec<(String, f64)>,
    /// RMS relative amplitude error per characteristic at the estimate.
    pub rms: Vec<(String, f64)>,
    /// RMS amplitude error in dB per characteristic: (initial, estimate).
    pub rms_db: Vec<(String, f64, f64)>,
    /// Every start (the first from the initial values).
    pub starts: Vec<StartSummary>,
    /// The model with the estimates written in.
    pub model: Model,
    /// Wall time of the minimisation from every start (s): the fit alone, without the
    /// criterion's set-up, the solves at the start and at the estimate and the Cramér-Rao bound.
    pub fit_seconds: f64,
}

/// The residuals in scaled variables `u = x / scale` for the minimizers.
struct Scaled<'a> {
    crit: &'a mut Criterion,
    scale: Vec<f64>,
    mode: JacobianMode,
}

impl optimize::Residuals for Scaled<'_> {
    fn eval(
        &mut self,
        u: &DVector<f64>,
        jacobian: bool,
    ) -> Result<(DVector<f64>, Option<DMatrix<f64>>), optimize::EvalError> {
        let x: Vec<f64> = u.iter().zip(&self.scale).map(|(u, s)| u * s).collect();
        let (e, j) = self.crit.evaluate(&x, jacobian.then_some(self.mode))?;
        if e.iter().any(|v| !v.is_finite()) {
            return Err(optimize::EvalError::NotFinite("model response"));
        }
        let j = j.map(|mut j| {
            for (c, s) in self.scale.iter().enumerate() {
                j.column_mut(c).scale_mut(*s);
            }
            j
        });
        Ok((e, j))
    }

    fn cheap_jacobian(&self) -> bool {
        self.mode == JacobianMode::Analytic
    }
}

/// Identifies `vars` from `data` on `model`. `progress(start, line)` is called once per
/// iteration. A run that stops on the iteration limit or diverges still returns the best point
/// (check [`StopReason::converged`]); `Err` means it could not start.
pub fn identify(
    model: &Model,
    data: &Observations,
    vars: &Variables,
    opts: &Options,
    progress: &mut dyn FnMut(usize, &Progress),
) -> Result<Identification, IdentifyError> {
    let mut crit = Criterion::new(model, data, vars, opts.fit, opts.noise, opts.frf_method)?;
    let x0 = vars.initial();
    let scale: Vec<f64> = vars.vars.iter().map(|v| v.scale).collect();
    // One solve at the start gives its criterion and both error measures; one at the estimate
    // its criterion, the Jacobian of the Cramér-Rao bound and the error measures.
    let q0 = crit
        .predicted(&x0)
        .map_err(|e| IdentifyError::Initial(e.into()))?;
    let criterion_initial = 0.5 * crit.residuals_of_predicted(&q0).norm_squared();
    let rms_initial = crit.rms_relative_error_of(&q0);
    let db_initial = crit.rms_db_error_of(&q0);
    let started = std::time::Instant::now();
    let (out, starts) = best_of_starts(&mut crit, vars, opts, progress)?;
    let fit_seconds = started.elapsed().as_secs_f64();
    let estimate: Vec<f64> = out.u.iter().zip(&scale).map(|(u, s)| u * s).collect();
    let (e, jac, q) = crit
        .evaluate_predicted(&estimate)
        .map_err(|e| IdentifyError::Estimate(e.into()))?;
    let criterion = 0.5 * e.norm_squared();
    let unc = uncertainty::uncertainty(
        vars,
        &estimate,
        &jac,
        criterion,
        crit.noise.scale_unknown(),
        opts.weak_threshold,
    );
    let rms = crit.rms_relative_error_of(&q);
    let rms_db = crit
        .rms_db_error_of(&q)
        .into_iter()
        .zip(db_initial)
        .map(|((label, b), (_, a))| (label, a, b))
        .collect();
    let mut updated = model.clone();
    vars.apply(&mut updated, &estimate);
    Ok(Identification {
        variables: vars.clone(),
        initial: x0,
        estimate,
        criterion_initial,
        criterion,
        optimizer: opts.optimizer,
        stop: out.stop,
        iterations: out.iterations,
        evaluations: crit.evaluations,
        noise: crit.noise,
        fit: opts.fit,
        observations: crit.residual_count(),
        uncertainty: unc,
        rms_initial,
        rms,
        rms_db,
        starts,
        model: updated,
        fit_seconds,
    })
}

/// Iterations a hypercube start always gets before it may be stopped as hopeless.
const HOPELESS_AFTER: usize = 5;
/// A start whose criterion is this many times the best start's is far from the best optimum:
/// were the best one at the noise level, it would miss the data by ten times the noise in
/// every residual.
const HOPELESS_RATIO: f64 = 100.0;
/// A start still lowering its criterion by this fraction an iteration is still descending into
/// its valley, wherever that leads, and goes on.
const STILL_DESCENDING: f64 = 0.1;

/// Why a multi-start's start is stopped at `p` (criterion `previous` one iteration before),
/// with `best` the best criterion of the starts finished so far: after [`HOPELESS_AFTER`]
/// iterations, its criterion is [`HOPELESS_RATIO`] times the best and falls by less than
/// [`STILL_DESCENDING`] an iteration — a start settling in a valley far above the best optimum
/// (multi-level single linkage stops such starts; a start of a resonant structure's fit from
/// far away mostly ends in one).
fn hopeless(p: &Progress, previous: f64, best: f64) -> Option<String> {
    let slow = previous - p.criterion < STILL_DESCENDING * previous;
    (p.iteration >= HOPELESS_AFTER && p.criterion > HOPELESS_RATIO * best && slow).then(|| {
        format!(
            "after {} iterations its criterion {:.4e} was {:.0}× the best start's and falling by less than {:.0} % an iteration",
            p.iteration,
            p.criterion,
            p.criterion / best,
            100.0 * STILL_DESCENDING
        )
    })
}

/// Minimizes from every start point (the initial values first); the best outcome and a summary
/// of each start. The model must evaluate at the initial values; a later start that cannot is
/// recorded as diverged.
fn best_of_starts(
    crit: &mut Criterion,
    vars: &Variables,
    opts: &Options,
    progress: &mut dyn FnMut(usize, &Progress),
) -> Result<(optimize::Outcome, Vec<StartSummary>), IdentifyError> {
    let scale: Vec<f64> = vars.vars.iter().map(|v| v.scale).collect();
    let n = scale.len();
    let lo = DVector::from_iterator(n, vars.vars.iter().map(|v| v.lower / v.scale));
    let hi = DVector::from_iterator(n, vars.vars.iter().map(|v| v.upper / v.scale));
    let mut best: Option<(optimize::Outcome, usize)> = None;
    let mut starts = Vec::new();
    // The initial values, the variables' extra starts (a pre-fit's), then the hypercube.
    let mut points = starts::latin_hypercube(vars, opts.starts, opts.seed);
    let extra = vars.extra_starts.iter().filter(|x| x.len() == n).cloned();
    points.splice(1..1, extra);
    for (k, xs) in points.into_iter().enumerate() {
        let u0 = DVector::from_iterator(xs.len(), xs.iter().zip(&scale).map(|(x, s)| x / s));
        let mut obj = Scaled {
            crit: &mut *crit,
            scale: scale.clone(),
            mode: opts.jacobian,
        };
        // The written start and the extra (informed) starts run to their end; a hypercube
        // start is stopped once it is heading for an optimum far above the best one found.
        let informed = k < 1 + vars.extra_starts.len();
        let best_j = best.as_ref().map(|(b, _)| b.criterion);
        let mut previous = f64::INFINITY;
        let mut watch = |p: &Progress| {
            let why = best_j
                .filter(|_| !informed)
                .and_then(|j| hopeless(p, previous, j));
            previous = p.criterion;
            why
        };
        let res = optimize::minimize_watched(
            opts.optimizer,
            &mut obj,
            (&u0, &lo, &hi),
            &opts.settings,
            &mut |p| progress(k, p),
            &mut watch,
        );
        match res {
            Ok(o) => {
                starts.push(StartSummary {
                    estimate: o.u.iter().zip(&scale).map(|(u, s)| u * s).collect(),
                    x0: xs,
                    criterion: o.criterion,
                    iterations: o.iterations,
                    stop: o.stop.clone(),
                });
                if best.as_ref().is_none_or(|(b, _)| o.criterion < b.criterion) {
                    best = Some((o, k));
                }
            }
            Err(m) => {
                if k == 0 {
                    return Err(IdentifyError::Initial(m));
                }
                starts.push(StartSummary {
                    estimate: xs.clone(),
                    x0: xs,
                    criterion: f64::INFINITY,
                    iterations: 0,
                    stop: StopReason::Diverged(m.to_string()),
                });
            }
        }
    }
    let Some((out, _)) = best else {
        return Err(IdentifyError::NoStart);
    };
    Ok((out, starts))
}

/// The Cramér-Rao uncertainty of `vars` at their initial values (no fit): what the data would
/// determine if the model at those values were the truth. For experiment design and for
/// checking identifiability before fitting. R is taken at face value (also the relative model:
/// σ = ε|z| with the given ε), since there are no residuals to scale it by.
pub fn uncertainty_at(
    model: &Model,
    data: &Observations,
    vars: &Variables,
    opts: &Options,
) -> Result<Uncertainty, IdentifyError> {
    let mut crit = Criterion::new(model, data, vars, opts.fit, opts.noise, opts.frf_method)?;
    let x0 = vars.initial();
    let (e, jac) = crit
        .evaluate(&x0, Some(JacobianMode::Analytic))
        .map_err(|e| IdentifyError::Initial(e.into()))?;
    let jac = jac.unwrap_or_else(|| DMatrix::zeros(e.len(), x0.len()));
    let j = 0.5 * e.norm_squared();
    Ok(uncertainty::uncertainty(
        vars,
        &x0,
        &jac,
        j,
        false,
        opts.weak_threshold,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(iteration: usize, criterion: f64) -> Progress {
        Progress {
            iteration,
            criterion,
            step_norm: 0.0,
            gradient_norm: 0.0,
        }
    }

    /// A hypercube start is stopped only when it has had its first iterations, sits far above
    /// the best start's criterion, and has stopped falling fast.
    #[test]
    fn a_start_is_hopeless_only_far_above_the_best_and_settling() {
        let best = 1.0e3;
        assert!(hopeless(&at(6, 1.0e7), 1.01e7, best).is_some());
        // Too early.
        assert!(hopeless(&at(HOPELESS_AFTER - 1, 1.0e7), 1.01e7, best).is_none());
        // Still falling by half an iteration.
        assert!(hopeless(&at(6, 1.0e7), 2.0e7, best).is_none());
        // Within the ratio of the best.
        assert!(hopeless(&at(6, 0.5 * HOPELESS_RATIO * best), 1.01e5, best).is_none());
    }
}
