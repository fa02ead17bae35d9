//! Bounded minimizers of `J(u) = ½‖e(u)‖²` over a box, in scaled variables `u = x / x_scale`:
//!
//! - [`Optimizer::LevenbergMarquardt`] (default): a damped Gauss-Newton (trust-region) step on the
//!   free variables, projected onto the bounds, accepted when the actual decrease is a fair share
//!   of the predicted one (Nielsen's damping update, Marquardt's diagonal scaling);
//! - [`Optimizer::GaussNewton`]: the paper's eq. 4.12-4.13, `d = (HᵀR⁻¹H)⁻¹HᵀR⁻¹(z − q)` (solved
//!   by SVD, so a rank-deficient `H` still gives a step) with a backtracking (Armijo) line search
//!   along the projected path;
//! - [`Optimizer::Bfgs`]: variable metric (BFGS update of the inverse Hessian, the paper's
//!   Wolfe-Broyden-Davidon family) with a strong-Wolfe line search, bounded by an active set.
//!
//! A variable at a bound whose gradient pushes it outward is held there (it is "active"); the
//! others are free. Every method stops on the gradient test (the largest cosine between the
//! residual and a free Jacobian column, as MINPACK), a small step, a small relative decrease, or
//! the iteration limit, and says which.

use nalgebra::{DMatrix, DVector};

/// The minimizer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Optimizer {
    /// Bounded Levenberg-Marquardt (robust default).
    #[default]
    LevenbergMarquardt,
    /// Gauss-Newton with line search (paper eq. 4.12-4.13).
    GaussNewton,
    /// BFGS variable metric with a Wolfe line search.
    Bfgs,
}

impl Optimizer {
    /// Name for reports.
    pub fn as_str(&self) -> &'static str {
        match self {
            Optimizer::LevenbergMarquardt => "levenberg-marquardt",
            Optimizer::GaussNewton => "gauss-newton",
            Optimizer::Bfgs => "bfgs",
        }
    }
}

/// Stopping tolerances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Maximum number of iterations.
    pub max_iterations: usize,
    /// Step test: `‖Δu‖ ≤ step_tol (‖u‖ + step_tol)`.
    pub step_tol: f64,
    /// Gradient test: `max_i |J_iᵀe| / (‖J_i‖ ‖e‖) ≤ gradient_tol` over free variables.
    pub gradient_tol: f64,
    /// Criterion test: `J_old − J_new ≤ criterion_tol · J_old` on an accepted step.
    pub criterion_tol: f64,
}

impl Default for Settings {
    fn default() -> Settings {
        Settings {
            max_iterations: 100,
            step_tol: 1e-9,
            gradient_tol: 1e-8,
            criterion_tol: 1e-12,
        }
    }
}

/// Why the minimizer stopped.
#[derive(Debug, Clone, PartialEq)]
pub enum StopReason {
    /// The gradient test passed: converged.
    GradientTolerance,
    /// The step became negligible: converged.
    StepTolerance,
    /// The relative decrease of J became negligible: converged.
    CriterionTolerance,
    /// No step along the search direction decreases J any more (at the limit of precision):
    /// the best point is kept, treated as converged.
    NoFurtherDecrease,
    /// The iteration limit was reached before convergence.
    IterationLimit,
    /// The model could not be evaluated (e.g. it became singular) or J is not finite.
    Diverged(String),
    /// The caller stopped the run (a multi-start's start heading for an optimum far above the
    /// best one found; see `identify::fit`): the point reached is kept, not converged.
    Abandoned(String),
}

impl StopReason {
    /// True for the converged outcomes.
    pub fn converged(&self) -> bool {
        matches!(
            self,
            StopReason::GradientTolerance
                | StopReason::StepTolerance
                | StopReason::CriterionTolerance
                | StopReason::NoFurtherDecrease
        )
    }

    /// A sentence for reports.
    pub fn describe(&self) -> String {
        match self {
            StopReason::GradientTolerance => "converged: gradient tolerance".into(),
            StopReason::StepTolerance => "converged: step tolerance".into(),
            StopReason::CriterionTolerance => "converged: criterion change tolerance".into(),
            StopReason::NoFurtherDecrease => {
                "converged: no further decrease possible along the search direction".into()
            }
            StopReason::IterationLimit => {
                "NOT converged: iteration limit reached (the best point is kept; raise --max-iterations or start closer)".into()
            }
            StopReason::Diverged(m) => format!("NOT converged: diverged ({m}); the best point is kept"),
            StopReason::Abandoned(m) => format!("NOT converged: stopped early ({m})"),
        }
    }
}

/// One progress line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Iteration number (1-based).
    pub iteration: usize,
    /// Criterion J after the iteration.
    pub criterion: f64,
    /// Norm of the step in scaled variables.
    pub step_norm: f64,
    /// Norm of the projected gradient of J in scaled variables.
    pub gradient_norm: f64,
}

/// Why the residuals cannot be evaluated at a point.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// The frequency response cannot be computed there (a singular model, for instance).
    #[error(transparent)]
    Solve(#[from] rfe::frf::SolveError),
    /// A residual, the criterion or a Jacobian entry is NaN or infinite; names which.
    #[error("the {0} is not finite")]
    NotFinite(&'static str),
    /// The residuals returned no Jacobian although one was asked for.
    #[error("the Jacobian was not computed")]
    NoJacobian,
    /// A changed model (a candidate effect added by a diagnosis) cannot be built at that point;
    /// the caller's own error, boxed so that the fit need not know the kinds of change.
    #[error(transparent)]
    Changed(Box<dyn std::error::Error + Send + Sync>),
    /// The criterion of a changed model cannot be set up.
    #[error(transparent)]
    Setup(Box<super::IdentifyError>),
}

/// What a minimizer needs: whitened residuals and, on request, their Jacobian in scaled
/// variables. An `Err` means the model cannot be evaluated at that point.
pub trait Residuals {
    /// `e(u)` and `∂e/∂u` if `jacobian`.
    fn eval(
        &mut self,
        u: &DVector<f64>,
        jacobian: bool,
    ) -> Result<(DVector<f64>, Option<DMatrix<f64>>), EvalError>;
    /// True when the Jacobian costs little more than the residuals (analytic): trial points are
    /// then evaluated with it.
    fn cheap_jacobian(&self) -> bool;
}

/// The result of one minimization.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// Best point (scaled).
    pub u: DVector<f64>,
    /// J at `u`.
    pub criterion: f64,
    /// Iterations done.
    pub iterations: usize,
    /// Why it stopped.
    pub stop: StopReason,
}

struct State {
    u: DVector<f64>,
    e: DVector<f64>,
    jac: DMatrix<f64>,
    cost: f64,
    g: DVector<f64>,
}

fn state(obj: &mut dyn Residuals, u: DVector<f64>) -> Result<State, EvalError> {
    let (e, jac) = obj.eval(&u, true)?;
    let jac = jac.ok_or(EvalError::NoJacobian)?;
    let cost = 0.5 * e.norm_squared();
    if !cost.is_finite() || jac.iter().any(|v| !v.is_finite()) {
        return Err(EvalError::NotFinite("criterion or its Jacobian"));
    }
    let g = jac.tr_mul(&e);
    Ok(State { u, e, jac, cost, g })
}

fn clamp(u: &DVector<f64>, lo: &DVector<f64>, hi: &DVector<f64>) -> DVector<f64> {
    DVector::from_fn(u.len(), |i, _| u[i].max(lo[i]).min(hi[i]))
}

/// Free variables: not at a bound that the gradient pushes against.
fn free_set(u: &DVector<f64>, g: &DVector<f64>, lo: &DVector<f64>, hi: &DVector<f64>) -> Vec<bool> {
    (0..u.len())
        .map(|i| !((u[i] <= lo[i] && g[i] > 0.0) || (u[i] >= hi[i] && g[i] < 0.0)))
        .collect()
}

fn projected_norm(g: &DVector<f64>, free: &[bool]) -> f64 {
    g.iter()
        .zip(free)
        .filter(|(_, f)| **f)
        .map(|(x, _)| x * x)
        .sum::<f64>()
        .sqrt()
}

fn gradient_converged(s: &State, free: &[bool], tol: f64) -> bool {
    let en = s.e.norm();
    if en == 0.0 {
        return true;
    }
    (0..s.u.len()).filter(|&i| free[i]).all(|i| {
        let cn = s.jac.column(i).norm();
        cn == 0.0 || s.g[i].abs() / (cn * en) <= tol
    })
}

fn step_small(step: f64, u: &DVector<f64>, tol: f64) -> bool {
    step <= tol * (u.norm() + tol)
}

/// Minimizes from `u0` (clamped into the box) with the chosen method. `Err` only when the model
/// cannot be evaluated at the starting point.
pub fn minimize(
    method: Optimizer,
    obj: &mut dyn Residuals,
    u0: &DVector<f64>,
    lo: &DVector<f64>,
    hi: &DVector<f64>,
    settings: &Settings,
    progress: &mut dyn FnMut(&Progress),
) -> Result<Outcome, EvalError> {
    minimize_watched(method, obj, (u0, lo, hi), settings, progress, &mut |_| None)
}

/// [`minimize`] with a watch: after every accepted step `watch` sees the progress and may stop
/// the run with a reason ([`StopReason::Abandoned`], the point reached kept).
pub fn minimize_watched(
    method: Optimizer,
    obj: &mut dyn Residuals,
    (u0, lo, hi): (&DVector<f64>, &DVector<f64>, &DVector<f64>),
    settings: &Settings,
    progress: &mut dyn FnMut(&Progress),
    watch: &mut dyn FnMut(&Progress) -> Option<String>,
) -> Result<Outcome, EvalError> {
    let s0 = state(obj, clamp(u0, lo, hi))?;
    let mut run = Run {
        obj,
        lo,
        hi,
        set: settings,
        progress,
        watch,
    };
    Ok(match method {
        Optimizer::LevenbergMarquardt => levenberg_marquardt(&mut run, s0),
        Optimizer::GaussNewton => gauss_newton(&mut run, s0),
        Optimizer::Bfgs => bfgs(&mut run, s0),
    })
}

/// One minimization's residuals, box, tolerances and progress report.
struct Run<'a> {
    obj: &'a mut dyn Residuals,
    lo: &'a DVector<f64>,
    hi: &'a DVector<f64>,
    set: &'a Settings,
    progress: &'a mut dyn FnMut(&Progress),
    watch: &'a mut dyn FnMut(&Progress) -> Option<String>,
}

fn outcome(s: &State, iterations: usize, stop: StopReason) -> Outcome {
    Outcome {
        u: s.u.clone(),
        criterion: s.cost,
        iterations,
        stop,
    }
}

/// After an accepted step of iteration `it` (criterion `old` before it, step norm `sn`): reports
/// progress, then stops on the criterion or step tolerance when `test_tolerances`.
fn after_step(
    run: &mut Run,
    s: &State,
    (old, sn, it): (f64, f64, usize),
    test_tolerances: bool,
) -> Option<Outcome> {
    let free = free_set(&s.u, &s.g, run.lo, run.hi);
    let progress = Progress {
        iteration: it,
        criterion: s.cost,
        step_norm: sn,
        gradient_norm: projected_norm(&s.g, &free),
    };
    (run.progress)(&progress);
    if let Some(why) = (run.watch)(&progress) {
        return Some(outcome(s, it, StopReason::Abandoned(why)));
    }
    if !test_tolerances {
        return None;
    }
    if old - s.cost <= run.set.criterion_tol * old {
        return Some(outcome(s, it, StopReason::CriterionTolerance));
    }
    if step_small(sn, &s.u, run.set.step_tol) {
        return Some(outcome(s, it, StopReason::StepTolerance));
    }
    None
}

/// The outcome at the iteration limit: converged after all if the projected gradient is small.
fn at_limit(run: &Run, s: &State) -> Outcome {
    let free = free_set(&s.u, &s.g, run.lo, run.hi);
    let n = run.set.max_iterations;
    if gradient_converged(s, &free, run.set.gradient_tol) {
        return outcome(s, n, StopReason::GradientTolerance);
    }
    outcome(s, n, StopReason::IterationLimit)
}

/// A trial point: its criterion, its full state when evaluated with the Jacobian, and the point.
type Trial = (f64, Option<State>, DVector<f64>);

/// Evaluates a trial point: the full state if the Jacobian is cheap, residuals only otherwise.
fn trial(obj: &mut dyn Residuals, u: DVector<f64>) -> Result<Trial, EvalError> {
    if obj.cheap_jacobian() {
        let s = state(obj, u.clone())?;
        Ok((s.cost, Some(s), u))
    } else {
        let (e, _) = obj.eval(&u, false)?;
        let cost = 0.5 * e.norm_squared();
        if !cost.is_finite() {
            return Err(EvalError::NotFinite("criterion"));
        }
        Ok((cost, None, u))
    }
}

fn complete(obj: &mut dyn Residuals, t: Trial) -> Result<State, EvalError> {
    match t.1 {
        Some(s) => Ok(s),
        None => state(obj, t.2),
    }
}

/// Levenberg-Marquardt's first damping, relative to the diagonal of JᵀJ (Marquardt's scaling): the
/// first step is about 1/100 of the Gauss-Newton step in each variable's own metric, and grows up
/// to 3× per accepted step. Being relative, the steps are the same whatever the size of the
/// residuals or the scale of a variable. (An absolute start, `1e-3 · max_i (JᵀJ)_ii` as for an
/// unscaled `λI`, multiplied by the diagonal made the first steps `max (JᵀJ)_ii` times shorter
/// than intended: with large whitened residuals, or a start far from the variables' scale, the
/// first step fell under the step tolerance and the fit "converged" after 0 iterations where it
/// began. A cautious first step is kept: a near Gauss-Newton first step (1e-3) lands in other
/// basins of these multimodal fits — on FWD-32J without the actuator, seed 11, J 9028 instead of
/// 126.7.)
const INITIAL_DAMPING: f64 = 1e2;

/// The state at the trial point `accepted` in iteration `it` after `s` (with the step's norm);
/// the outcome instead when none was, when it cannot be evaluated in full, or when a tolerance
/// stops the run.
fn advance(
    run: &mut Run,
    s: &State,
    accepted: Option<(Trial, f64)>,
    it: usize,
) -> Result<State, Outcome> {
    let Some((t, sn)) = accepted else {
        return Err(outcome(s, it - 1, StopReason::NoFurtherDecrease));
    };
    let new =
        complete(run.obj, t).map_err(|m| outcome(s, it, StopReason::Diverged(m.to_string())))?;
    match after_step(run, &new, (s.cost, sn, it), true) {
        Some(o) => Err(o),
        None => Ok(new),
    }
}

fn levenberg_marquardt(run: &mut Run, mut s: State) -> Outcome {
    let n = s.u.len();
    let mut diag = vec![0.0f64; n];
    let mut lambda: Option<f64> = None;
    let mut nu = 2.0;
    for it in 1..=run.set.max_iterations {
        let a = s.jac.tr_mul(&s.jac);
        let free = free_set(&s.u, &s.g, run.lo, run.hi);
        if gradient_converged(&s, &free, run.set.gradient_tol) {
            return outcome(&s, it - 1, StopReason::GradientTolerance);
        }
        let idx: Vec<usize> = (0..n).filter(|&i| free[i]).collect();
        for i in 0..n {
            diag[i] = diag[i].max(a[(i, i)]);
        }
        let dmax = idx
            .iter()
            .map(|&i| diag[i])
            .fold(0.0, f64::max)
            .max(f64::MIN_POSITIVE);
        // The damping multiplies D = diag(JᵀJ) (Marquardt's scaling), so λ is a pure number:
        // the step is the same whatever the size of the residuals or the scale of a variable.
        let mut lam = lambda.unwrap_or(INITIAL_DAMPING);
        let mut tries = 0;
        let accepted = loop {
            tries += 1;
            if tries > 60 || lam > 1e30 {
                break None;
            }
            let k = idx.len();
            let mut m = DMatrix::zeros(k, k);
            let mut rhs = DVector::zeros(k);
            for (p, &i) in idx.iter().enumerate() {
                rhs[p] = -s.g[i];
                for (q, &j) in idx.iter().enumerate() {
                    m[(p, q)] = a[(i, j)];
                }
                m[(p, p)] += lam * diag[i].max(1e-12 * dmax);
            }
            let Some(ch) = m.cholesky() else {
                lam *= nu;
                nu *= 2.0;
                continue;
            };
            let d = ch.solve(&rhs);
            let mut un = s.u.clone();
            for (p, &i) in idx.iter().enumerate() {
                un[i] += d[p];
            }
            let un = clamp(&un, run.lo, run.hi);
            let step = &un - &s.u;
            let sn = step.norm();
            if step_small(sn, &s.u, run.set.step_tol) {
                return outcome(&s, it - 1, StopReason::StepTolerance);
            }
            let pred = -(s.g.dot(&step) + 0.5 * step.dot(&(&a * &step)));
            match trial(run.obj, un) {
                Ok(t) if t.0 < s.cost && pred > 0.0 => {
                    let rho = (s.cost - t.0) / pred;
                    if rho > 1e-4 {
                        lam *= (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3));
                        nu = 2.0;
                        break Some((t, sn));
                    }
                    lam *= nu;
                    nu *= 2.0;
                }
                _ => {
                    lam *= nu;
                    nu *= 2.0;
                }
            }
        };
        lambda = Some(lam);
        match advance(run, &s, accepted, it) {
            Ok(next) => s = next,
            Err(o) => return o,
        }
    }
    at_limit(run, &s)
}

/// Gauss-Newton direction on the free variables by SVD (singular values below 1e-12 of the
/// largest are dropped).
fn gauss_newton_direction(s: &State, free: &[bool]) -> DVector<f64> {
    let n = s.u.len();
    let idx: Vec<usize> = (0..n).filter(|&i| free[i]).collect();
    let mut d = DVector::zeros(n);
    if idx.is_empty() {
        return d;
    }
    let jf = DMatrix::from_fn(s.jac.nrows(), idx.len(), |r, c| s.jac[(r, idx[c])]);
    let svd = jf.svd(true, true);
    let smax = svd.singular_values.max();
    let Ok(x) = svd.solve(&(-&s.e), 1e-12 * smax) else {
        return d;
    };
    for (p, &i) in idx.iter().enumerate() {
        d[i] = x[p];
    }
    d
}

fn gauss_newton(run: &mut Run, mut s: State) -> Outcome {
    for it in 1..=run.set.max_iterations {
        let free = free_set(&s.u, &s.g, run.lo, run.hi);
        if gradient_converged(&s, &free, run.set.gradient_tol) {
            return outcome(&s, it - 1, StopReason::GradientTolerance);
        }
        let mut d = gauss_newton_direction(&s, &free);
        if s.g.dot(&d) >= 0.0 {
            d = DVector::from_fn(s.u.len(), |i, _| if free[i] { -s.g[i] } else { 0.0 });
        }
        // Backtracking along the projected path u(α) = P(u + α d).
        let mut alpha = 1.0;
        let mut accepted = None;
        for _ in 0..40 {
            let un = clamp(&(&s.u + &d * alpha), run.lo, run.hi);
            let step = &un - &s.u;
            let sn = step.norm();
            if step_small(sn, &s.u, run.set.step_tol) {
                return outcome(&s, it - 1, StopReason::StepTolerance);
            }
            let slope = s.g.dot(&step);
            match trial(run.obj, un) {
                Ok(t) if t.0 <= s.cost + 1e-4 * slope && t.0 < s.cost => {
                    accepted = Some((t, sn));
                    break;
                }
                Ok(t) => {
                    // Minimum of the quadratic through J(0), its slope and J(α), safeguarded.
                    let den = 2.0 * (t.0 - s.cost - slope);
                    let q = if den > 0.0 { -slope / den } else { 0.5 };
                    alpha *= q.clamp(0.1, 0.5);
                }
                Err(_) => alpha *= 0.25,
            }
        }
        match advance(run, &s, accepted, it) {
            Ok(next) => s = next,
            Err(o) => return o,
        }
    }
    at_limit(run, &s)
}

/// A point on the search line: the state and φ'(α) = ∇J·d there.
struct LinePoint {
    alpha: f64,
    s: State,
    slope: f64,
}

fn line_point(
    obj: &mut dyn Residuals,
    s: &State,
    d: &DVector<f64>,
    alpha: f64,
    lo: &DVector<f64>,
    hi: &DVector<f64>,
) -> Option<LinePoint> {
    let u = clamp(&(&s.u + d * alpha), lo, hi);
    let st = state(obj, u).ok()?;
    let slope = st.g.dot(d);
    Some(LinePoint {
        alpha,
        s: st,
        slope,
    })
}

const WOLFE_C1: f64 = 1e-4;
const WOLFE_C2: f64 = 0.9;

/// The zoom phase of the strong-Wolfe search between `lo_p` (a point satisfying sufficient
/// decrease, or α = 0 when `None`) and `hi_a`, by safeguarded bisection.
#[allow(clippy::too_many_arguments)]
fn zoom(
    obj: &mut dyn Residuals,
    s: &State,
    d: &DVector<f64>,
    lo: &DVector<f64>,
    hi: &DVector<f64>,
    dphi0: f64,
    mut lo_p: Option<LinePoint>,
    mut hi_a: f64,
) -> Option<LinePoint> {
    let phi0 = s.cost;
    for _ in 0..30 {
        let (la, lphi) = lo_p
            .as_ref()
            .map(|p| (p.alpha, p.s.cost))
            .unwrap_or((0.0, phi0));
        let a = la + 0.5 * (hi_a - la);
        let Some(p) = line_point(obj, s, d, a, lo, hi) else {
            hi_a = a;
            continue;
        };
        if p.s.cost > phi0 + WOLFE_C1 * a * dphi0 || p.s.cost >= lphi {
            hi_a = a;
        } else {
            if p.slope.abs() <= -WOLFE_C2 * dphi0 {
                return Some(p);
            }
            if p.slope * (hi_a - la) >= 0.0 {
                hi_a = la;
            }
            lo_p = Some(p);
        }
        let la = lo_p.as_ref().map(|p| p.alpha).unwrap_or(0.0);
        if (hi_a - la).abs() <= 1e-14 * la.abs().max(hi_a.abs()) {
            break;
        }
    }
    lo_p
}

/// Strong-Wolfe line search (Nocedal & Wright, algorithms 3.5 and 3.6) on `α ∈ (0, α_max]`;
/// at `α_max` (a bound) the sufficient-decrease condition alone is accepted.
fn wolfe_search(
    obj: &mut dyn Residuals,
    s: &State,
    d: &DVector<f64>,
    alpha0: f64,
    alpha_max: f64,
    lo: &DVector<f64>,
    hi: &DVector<f64>,
) -> Option<LinePoint> {
    let phi0 = s.cost;
    let dphi0 = s.g.dot(d);
    let mut prev: Option<LinePoint> = None;
    let mut alpha = alpha0.min(alpha_max);
    for i in 0..30 {
        let Some(p) = line_point(obj, s, d, alpha, lo, hi) else {
            // Could not evaluate: treat as too far.
            return zoom(obj, s, d, lo, hi, dphi0, prev, alpha);
        };
        let pphi = prev.as_ref().map(|q| q.s.cost).unwrap_or(phi0);
        if p.s.cost > phi0 + WOLFE_C1 * alpha * dphi0 || (i > 0 && p.s.cost >= pphi) {
            return zoom(obj, s, d, lo, hi, dphi0, prev, alpha);
        }
        if p.slope.abs() <= -WOLFE_C2 * dphi0 {
            return Some(p);
        }
        if p.slope >= 0.0 {
            let pa = prev.as_ref().map(|q| q.alpha).unwrap_or(0.0);
            return zoom(obj, s, d, lo, hi, dphi0, Some(p), pa);
        }
        if alpha >= alpha_max {
            return Some(p);
        }
        prev = Some(p);
        alpha = (2.0 * alpha).min(alpha_max);
    }
    prev
}

fn bfgs(run: &mut Run, mut s: State) -> Outcome {
    let n = s.u.len();
    let mut hinv = DMatrix::<f64>::identity(n, n);
    let mut fresh = true;
    let mut prev_free: Option<Vec<bool>> = None;
    for it in 1..=run.set.max_iterations {
        let free = free_set(&s.u, &s.g, run.lo, run.hi);
        if gradient_converged(&s, &free, run.set.gradient_tol) {
            return outcome(&s, it - 1, StopReason::GradientTolerance);
        }
        if prev_free.as_ref() != Some(&free) {
            hinv = DMatrix::identity(n, n);
            fresh = true;
        }
        prev_free = Some(free.clone());
        let gf = DVector::from_fn(n, |i, _| if free[i] { s.g[i] } else { 0.0 });
        // Components that would leave the box at once are dropped (the quasi-Newton direction
        // can point outward where the gradient points inward).
        let blocked = |i: usize, di: f64| {
            !free[i] || (s.u[i] >= run.hi[i] && di > 0.0) || (s.u[i] <= run.lo[i] && di < 0.0)
        };
        let mut d = -(&hinv * &gf);
        for i in 0..n {
            if blocked(i, d[i]) {
                d[i] = 0.0;
            }
        }
        if s.g.dot(&d) >= 0.0 || d.amax() == 0.0 {
            hinv = DMatrix::identity(n, n);
            fresh = true;
            d = -gf.clone();
            for i in 0..n {
                if blocked(i, d[i]) {
                    d[i] = 0.0;
                }
            }
        }
        let mut alpha_max = f64::INFINITY;
        for i in 0..n {
            if d[i] < 0.0 && run.lo[i].is_finite() {
                alpha_max = alpha_max.min((run.lo[i] - s.u[i]) / d[i]);
            } else if d[i] > 0.0 && run.hi[i].is_finite() {
                alpha_max = alpha_max.min((run.hi[i] - s.u[i]) / d[i]);
            }
        }
        let alpha_max = alpha_max.max(0.0);
        let dinf = d.amax();
        let alpha0 = if fresh {
            (0.1 / dinf.max(f64::MIN_POSITIVE)).min(1.0)
        } else {
            1.0
        };
        let Some(p) = wolfe_search(run.obj, &s, &d, alpha0, alpha_max, run.lo, run.hi) else {
            return outcome(&s, it - 1, StopReason::NoFurtherDecrease);
        };
        if p.s.cost >= s.cost {
            return outcome(&s, it - 1, StopReason::NoFurtherDecrease);
        }
        let step = &p.s.u - &s.u;
        let was_fresh = fresh;
        let y = DVector::from_fn(n, |i, _| if free[i] { p.s.g[i] - s.g[i] } else { 0.0 });
        let sy = step.dot(&y);
        if sy > 1e-12 * step.norm() * y.norm() {
            if fresh {
                hinv = DMatrix::identity(n, n) * (sy / y.norm_squared());
            }
            let rho = 1.0 / sy;
            let i_n = DMatrix::<f64>::identity(n, n);
            let left = &i_n - (&step * y.transpose()) * rho;
            let right = &i_n - (&y * step.transpose()) * rho;
            hinv = &left * &hinv * &right + (&step * step.transpose()) * rho;
            fresh = false;
        }
        let old = s.cost;
        let sn = step.norm();
        s = p.s;
        // A (short) steepest-descent step after a restart says little about convergence.
        if let Some(o) = after_step(run, &s, (old, sn, it), !was_fresh) {
            return o;
        }
    }
    at_limit(run, &s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock as residuals: e = [10 (u1 − u0²), 1 − u0].
    struct Rosen;
    impl Residuals for Rosen {
        fn eval(
            &mut self,
            u: &DVector<f64>,
            jacobian: bool,
        ) -> Result<(DVector<f64>, Option<DMatrix<f64>>), EvalError> {
            let e = DVector::from_vec(vec![10.0 * (u[1] - u[0] * u[0]), 1.0 - u[0]]);
            let j =
                jacobian.then(|| DMatrix::from_row_slice(2, 2, &[-20.0 * u[0], 10.0, -1.0, 0.0]));
            Ok((e, j))
        }
        fn cheap_jacobian(&self) -> bool {
            true
        }
    }

    const METHODS: [Optimizer; 3] = [
        Optimizer::LevenbergMarquardt,
        Optimizer::GaussNewton,
        Optimizer::Bfgs,
    ];

    /// Minimizes Rosenbrock's function from (-1.2, 1) within `lo`..`hi`.
    fn rosenbrock(m: Optimizer, lo: [f64; 2], hi: [f64; 2], max_iterations: usize) -> Outcome {
        let set = Settings {
            max_iterations,
            ..Settings::default()
        };
        minimize(
            m,
            &mut Rosen,
            &DVector::from_vec(vec![-1.2, 1.0]),
            &DVector::from_row_slice(&lo),
            &DVector::from_row_slice(&hi),
            &set,
            &mut |_| {},
        )
        .unwrap()
    }

    #[test]
    fn every_method_solves_rosenbrock() {
        for m in METHODS {
            let o = rosenbrock(m, [-10.0; 2], [10.0; 2], 500);
            assert!(o.stop.converged(), "{m:?}: {:?}", o.stop);
            assert!(
                (o.u[0] - 1.0).abs() < 1e-5 && (o.u[1] - 1.0).abs() < 1e-5,
                "{m:?}: {:?}",
                o.u
            );
        }
    }

    #[test]
    fn a_bound_is_respected_and_reported_by_position() {
        // Minimum at (1, 1) lies outside u0 ≤ 0.5: the solution is on the bound.
        for m in METHODS {
            let o = rosenbrock(m, [-10.0; 2], [0.5, 10.0], 500);
            assert_eq!(o.u[0], 0.5, "{m:?}");
            assert!((o.u[1] - 0.25).abs() < 1e-5, "{m:?}: {:?}", o.u);
        }
    }

    /// Rosenbrock with its residuals multiplied by `c` and its variables by `s`
    /// (`x = s ∘ u`): the same problem in other units.
    struct ScaledRosen {
        c: f64,
        s: [f64; 2],
    }
    impl Residuals for ScaledRosen {
        fn eval(
            &mut self,
            u: &DVector<f64>,
            jacobian: bool,
        ) -> Result<(DVector<f64>, Option<DMatrix<f64>>), EvalError> {
            let (c, [s0, s1]) = (self.c, self.s);
            let x = [s0 * u[0], s1 * u[1]];
            let e = DVector::from_vec(vec![10.0 * c * (x[1] - x[0] * x[0]), c * (1.0 - x[0])]);
            let j = jacobian.then(|| {
                DMatrix::from_row_slice(2, 2, &[-20.0 * c * x[0] * s0, 10.0 * c * s1, -c * s0, 0.0])
            });
            Ok((e, j))
        }
        fn cheap_jacobian(&self) -> bool {
            true
        }
    }

    #[test]
    fn levenberg_marquardt_takes_the_same_steps_in_any_units() {
        // Large whitened residuals (small σ, many lines) and a start far from the variables'
        // scale: the damping used to start at 1e-3 max (JᵀJ)_ii on top of Marquardt's diagonal,
        // so with c = 1e8 the first step was 1e13 times too short, fell under the step
        // tolerance, and the fit "converged" after 0 iterations at its start.
        let run = |c: f64, s: [f64; 2]| {
            let u0 = DVector::from_vec(vec![-1.2 / s[0], 1.0 / s[1]]);
            minimize(
                Optimizer::LevenbergMarquardt,
                &mut ScaledRosen { c, s },
                &u0,
                &DVector::from_element(2, -1e9),
                &DVector::from_element(2, 1e9),
                &Settings {
                    max_iterations: 500,
                    ..Settings::default()
                },
                &mut |_| {},
            )
            .unwrap()
        };
        let plain = run(1.0, [1.0, 1.0]);
        assert!(plain.stop.converged() && plain.iterations > 5, "{plain:?}");
        for c in [1e8, 1e3, 1e-4] {
            for s in [[1.0, 1.0], [10.0, 0.1], [1e-3, 1e2]] {
                let o = run(c, s);
                let x = [o.u[0] * s[0], o.u[1] * s[1]];
                assert!(
                    o.stop.converged() && (x[0] - 1.0).abs() < 1e-5 && (x[1] - 1.0).abs() < 1e-5,
                    "c {c}, s {s:?}: {o:?}"
                );
                assert!(
                    o.iterations.abs_diff(plain.iterations) <= 2,
                    "c {c}, s {s:?}: {} iterations against {}",
                    o.iterations,
                    plain.iterations
                );
            }
        }
    }

    #[test]
    fn the_iteration_limit_is_reported() {
        let o = rosenbrock(Optimizer::Bfgs, [-10.0; 2], [10.0; 2], 2);
        assert_eq!(o.stop, StopReason::IterationLimit);
        assert!(!o.stop.converged());
    }
}
