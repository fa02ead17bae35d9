//! Where a new effect's refit starts, and a cheap finite-step screen of the leading candidates.
//!
//! The score test ranks candidates by their slope at the nested value: a small-effect statistic.
//! A large missing effect (a misfit of reduced χ² in the tens to hundreds) bends the criterion
//! far from that slope, and the candidate that explains it can rank low. The screen judges the
//! leading candidates by what a finite effect does instead: each candidate's own parameters are
//! fitted with the model's variables held at the current fit but re-adjusted to first order —
//! the residuals are projected off the span of the fit's Jacobian, `r(γ) = (I − P) e(x̂, γ)` —
//! so `½‖r‖²` approximates the refitted criterion at the cost of a few model evaluations per
//! candidate, not a fit. The refits then go to the candidates the screen puts first.

use nalgebra::{DMatrix, DVector};

use super::effects::EffectParam;
use super::lowrank::Shared;
use super::problem::Problem;
use super::tuning::{
    REFIT_SIZE_DECADES, REFIT_SIZE_FACTORS, REFIT_START_FRACTIONS, RESONATOR_GRID,
    SCREEN_ITERATIONS,
};
use identify::optimize::{self, Residuals};
use identify::EvalError;

/// Starting values (SI) of a new effect's parameters: `start`, and with `explore` also the way
/// there from the nested values ([`REFIT_START_FRACTIONS`]), the size over decades of its scale
/// on either side of the nested value ([`REFIT_SIZE_DECADES`]; for a large effect the score step
/// is no guide) and, for a positive nested size, multiples of it ([`REFIT_SIZE_FACTORS`]).
/// `start` comes first; sizes outside the bounds are left out.
pub(super) fn effect_starts(params: &[EffectParam], start: &[f64], explore: bool) -> Vec<Vec<f64>> {
    let fractions: &[f64] = if explore {
        &REFIT_START_FRACTIONS
    } else {
        &REFIT_START_FRACTIONS[..1]
    };
    let mut out: Vec<Vec<f64>> = fractions
        .iter()
        .map(|t| {
            params
                .iter()
                .zip(start)
                .map(|(np, v)| np.nested + t * (v - np.nested))
                .collect()
        })
        .collect();
    if let Some(np) = params.first().filter(|_| explore) {
        let steps = REFIT_SIZE_DECADES
            .iter()
            .flat_map(|&d| [1.0, -1.0].map(|sign| np.nested + sign * np.scale * 10f64.powi(d)));
        let multiples = REFIT_SIZE_FACTORS
            .iter()
            .filter(|_| np.nested > 0.0)
            .map(|f| f * np.nested);
        for x0 in steps.chain(multiples) {
            if x0 > np.lower && x0 < np.upper {
                let mut v = start.to_vec();
                v[0] = x0;
                out.push(v);
            }
        }
    }
    out
}

/// The screen's starting values (SI) of a new effect's parameters: `start` (the score step) and
/// the size over decades of its scale on either side of the nested value.
pub(super) fn size_starts(params: &[EffectParam], start: &[f64]) -> Vec<Vec<f64>> {
    let mut out = effect_starts(params, start, true);
    out.drain(1..REFIT_START_FRACTIONS.len());
    out
}

/// A resonator's starting point (its mass and tuning frequency, the last two of `u0`, scaled):
/// the tuning frequency on a log grid across its range (`lo`, `hi`) at the current mass, then the
/// mass over decades of its scale at the best frequency, then the frequency refined around the
/// best by halving steps. `objective` is the criterion to lower (`j_best` at `u0`).
pub(super) fn tune_resonator(
    objective: &mut dyn FnMut(&DVector<f64>) -> f64,
    u0: &mut DVector<f64>,
    mut j_best: f64,
    (lo, hi): (&DVector<f64>, &DVector<f64>),
) {
    let n = u0.len();
    if n < 2 {
        return;
    }
    let (im, i_f) = (n - 2, n - 1);
    let mut try_at = |u0: &mut DVector<f64>, i: usize, v: f64, j_best: &mut f64| {
        let mut u = u0.clone();
        u[i] = v.clamp(lo[i], hi[i]);
        let j = objective(&u);
        if j < *j_best {
            *j_best = j;
            *u0 = u;
        }
    };
    let (f_lo, f_hi) = (lo[i_f].max(1e-9), hi[i_f]);
    let ratio = (f_hi / f_lo).powf(1.0 / (RESONATOR_GRID - 1) as f64);
    for k in 0..RESONATOR_GRID {
        try_at(u0, i_f, f_lo * ratio.powi(k as i32), &mut j_best);
    }
    for d in REFIT_SIZE_DECADES {
        try_at(u0, im, 10f64.powi(d), &mut j_best);
    }
    let mut step = ratio.sqrt();
    for _ in 0..4 {
        let f = u0[i_f];
        try_at(u0, i_f, f * step, &mut j_best);
        try_at(u0, i_f, f / step, &mut j_best);
        step = step.sqrt();
    }
}

/// The extended problem seen through its new effect's parameters only: the variables and earlier
/// effects held at the current fit `fixed`, the residuals projected off `basis` (orthonormal
/// columns spanning the current fit's Jacobian), the Jacobian by forward differences. With
/// `shared`, the current fit's solves, each evaluation is a low-rank update of them (its cost
/// per line does not grow with the model); a candidate that is no such update is solved in full.
struct Screened<'p, 'a> {
    problem: &'p mut Problem<'a>,
    shared: Option<&'p Shared>,
    fixed: &'p DVector<f64>,
    basis: &'p DMatrix<f64>,
    scale: Vec<f64>,
    upper: Vec<f64>,
}

impl Screened<'_, '_> {
    fn residuals(&mut self, g: &DVector<f64>) -> Result<DVector<f64>, EvalError> {
        let n = self.fixed.len();
        let u = DVector::from_fn(
            n + g.len(),
            |i, _| {
                if i < n {
                    self.fixed[i]
                } else {
                    g[i - n]
                }
            },
        );
        let fast = self.shared.and_then(|s| s.residuals(self.problem, &u));
        let e = match fast {
            Some(e) => e?,
            None => self.problem.eval(&u, false)?.0,
        };
        let proj = self.basis * (self.basis.transpose() * &e);
        Ok(e - proj)
    }
}

impl Residuals for Screened<'_, '_> {
    fn eval(
        &mut self,
        g: &DVector<f64>,
        jacobian: bool,
    ) -> Result<(DVector<f64>, Option<DMatrix<f64>>), EvalError> {
        let r = self.residuals(g)?;
        if !jacobian {
            return Ok((r, None));
        }
        let mut jac = DMatrix::zeros(r.len(), g.len());
        for j in 0..g.len() {
            let h = 1e-5 * g[j].abs().max(1.0);
            let h = if (g[j] + h) * self.scale[j] > self.upper[j] {
                -h
            } else {
                h
            };
            let mut gh = g.clone();
            gh[j] += h;
            let rh = self.residuals(&gh)?;
            jac.set_column(j, &((rh - &r) / h));
        }
        Ok((r, Some(jac)))
    }

    fn cheap_jacobian(&self) -> bool {
        false
    }
}

/// The screen of one candidate, the last effect of `problem`: its parameters (scaled) fitted to
/// the residuals of the current fit `fixed` projected off `basis`, from the best of the starts
/// `starts` (SI; a resonator also tuned, see [`tune_resonator`]). Returns the screened criterion
/// `½‖(I − P) e‖²` and the parameters (SI) where it is least; `None` when no start can be
/// evaluated. `shared`: the current fit's solves for low-rank evaluations ([`Shared`]).
pub(super) fn screen(
    problem: &mut Problem,
    shared: Option<&Shared>,
    fixed: &DVector<f64>,
    basis: &DMatrix<f64>,
    starts: &[Vec<f64>],
    resonator: bool,
) -> Option<(f64, Vec<f64>)> {
    let n = fixed.len();
    let (lo, hi) = problem.bounds();
    let q = lo.len() - n;
    let params: Vec<EffectParam> = problem.params[problem.params.len() - q..].to_vec();
    let scale: Vec<f64> = params.iter().map(|p| p.scale).collect();
    let upper: Vec<f64> = params.iter().map(|p| p.upper).collect();
    let (glo, ghi) = (lo.rows(n, q).into_owned(), hi.rows(n, q).into_owned());
    let mut screened = Screened {
        problem,
        shared,
        fixed,
        basis,
        scale,
        upper,
    };
    let mut objective = |g: &DVector<f64>| {
        screened
            .residuals(g)
            .map_or(f64::INFINITY, |r| r.norm_squared())
    };
    let mut best: Option<(f64, DVector<f64>)> = None;
    for st in starts {
        let g = DVector::from_iterator(
            q,
            params
                .iter()
                .zip(st)
                .map(|(p, x)| x.clamp(p.lower, p.upper) / p.scale),
        );
        let j = objective(&g);
        if best.as_ref().is_none_or(|(b, _)| j < *b) {
            best = Some((j, g));
        }
    }
    let (mut j0, mut g0) = best.filter(|(j, _)| j.is_finite())?;
    if resonator {
        tune_resonator(&mut objective, &mut g0, j0, (&glo, &ghi));
        j0 = objective(&g0);
    }
    let settings = optimize::Settings {
        max_iterations: SCREEN_ITERATIONS,
        ..optimize::Settings::default()
    };
    let out = optimize::minimize(
        optimize::Optimizer::LevenbergMarquardt,
        &mut screened,
        &g0,
        &glo,
        &ghi,
        &settings,
        &mut |_| {},
    )
    .ok()
    .filter(|o| o.criterion.is_finite() && 2.0 * o.criterion < j0);
    let (j, g) = match out {
        Some(o) => (o.criterion, o.u),
        None => (0.5 * j0, g0),
    };
    let values = g.iter().zip(&params).map(|(u, p)| u * p.scale).collect();
    Some((j, values))
}

#[cfg(test)]
mod tests {
    use super::*;

    const PSI_MAX: f64 = 4.0 * std::f64::consts::PI;

    fn param(nested: f64, scale: f64, upper: f64) -> EffectParam {
        EffectParam {
            name: "x",
            unit: "-",
            nested,
            initial: nested,
            lower: 0.0,
            upper,
            scale,
        }
    }

    /// A split ψ starts at fractions and multiples of its group's value, where the additive
    /// steps of its scale do not reach; a size nested at 0 (a spring's
    /// stiffness) has no multiples, and no start leaves the bounds.
    #[test]
    fn a_positive_nested_size_is_also_started_at_multiples_of_it() {
        let sizes = |p: &EffectParam| -> Vec<f64> {
            effect_starts(std::slice::from_ref(p), &[p.nested], true)
                .iter()
                .map(|v| v[0])
                .collect()
        };
        let near = |xs: &[f64], x: f64| xs.iter().any(|y| (y / x).ln().abs() < 0.35);
        let psi = sizes(&param(1.45, 1.45, PSI_MAX));
        assert!(near(&psi, 0.39) && near(&psi, 4.3), "{psi:?}");
        assert!(psi.iter().all(|&x| x > 0.0 && x < PSI_MAX));
        // A stiffness: the start on the way from 0, then one step up per decade.
        let stiffness = sizes(&param(0.0, 1e6, f64::INFINITY));
        let steps = REFIT_START_FRACTIONS.len() + REFIT_SIZE_DECADES.len();
        assert_eq!(stiffness.len(), steps, "{stiffness:?}");
        // Without `explore`, only the given start.
        assert_eq!(
            effect_starts(&[param(1.45, 1.45, PSI_MAX)], &[2.0], false),
            [vec![2.0]]
        );
    }
}
