//! Closing the loop after a fit: find the residual, trace it to an effect the model lacks, add
//! it, and report the error before and after.
//!
//! 1. [`residuals`]: standardized residuals, χ² goodness of fit against R, runs test along
//!    frequency, the mode bands where the misfit concentrates, and a verdict.
//! 2. [`generate`]: a library of nested candidate [`effects`] built from the model's geometry
//!    (springs to bodies or ground, point masses, resonators, flexible bodies, sensor gains, a
//!    joint's own damping) — hundreds for a machine-tool model.
//! 3. [`score`]: every candidate ranked by a score (Lagrange-multiplier) test at the current fit,
//!    from one set of solves — about the cost of one Jacobian, not one fit per candidate.
//! 4. The best few are refitted fully with their parameters free ([`problem`]) and the most
//!    significant is accepted if its likelihood-ratio test passes at `α / (number of candidates
//!    ranked)` (Bonferroni: the family-wise false-alarm rate stays at α although hundreds are
//!    looked at). Repeat until nothing significant is left.
//!
//! ```no_run
//! use identify::diagnose::{diagnose, Options};
//! # fn run(model: &identify::Model, obs: &identify::identification::Observations,
//! #        vars: &identify::identification::Variables,
//! #        id: &identify::identification::Identification) {
//! let d = diagnose(model, obs, vars, id, &Options::default(), &mut |line| eprintln!("{line}")).unwrap();
//! println!("{}", identify::diagnose::text(&d));
//! # }
//! ```

pub mod effects;
pub mod generate;
pub mod problem;
pub mod residuals;
pub mod score;

use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};

pub use effects::Effect;
pub use residuals::ResidualAnalysis;

use crate::identification::optimize::{self, Residuals as _};
use crate::identification::{self, EvalError, Identification, Observations, Variables};
use crate::model::Model;
use problem::Problem;

/// How to diagnose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Family-wise significance level: the accepted false-alarm rate per diagnosis.
    pub alpha: f64,
    /// At most this many effects are added.
    pub max_effects: usize,
    /// Refit the best this many candidates of each round by the score ranking.
    pub refit: usize,
    /// How the identification was run (fit kind, noise model, optimizer settings).
    pub identification: identification::Options,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            alpha: 0.01,
            max_effects: 3,
            refit: 5,
            identification: identification::Options::default(),
        }
    }
}

/// An estimated effect parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParamEstimate {
    /// `k`, `psi`, `m`, `f`, `c`, `g`.
    pub name: String,
    /// SI unit.
    pub unit: String,
    /// Estimate (SI).
    pub value: f64,
    /// Cramér-Rao standard error (SI).
    pub std_error: f64,
}

impl ParamEstimate {
    /// Value, standard error and unit in the units of reports (the paper's N/µm for stiffness,
    /// µm/N for compliance; others as SI).
    pub fn display(&self) -> (f64, f64, &str) {
        match self.unit.as_str() {
            "N/m" => (self.value * 1e-6, self.std_error * 1e-6, "N/µm"),
            "m/N" => (self.value * 1e6, self.std_error * 1e6, "µm/N"),
            "m" => (self.value * 1e3, self.std_error * 1e3, "mm"),
            u => (self.value, self.std_error, u),
        }
    }

    /// `k = 0.5635 ± 0.0005 N/µm`, in report units.
    pub fn describe(&self) -> String {
        let (v, s, u) = self.display();
        let u = if u == "-" {
            String::new()
        } else {
            format!(" {u}")
        };
        let v = if (0.01..1e5).contains(&v.abs()) {
            format!("{v:.4}")
        } else {
            format!("{v:.4e}")
        };
        format!("{} = {v} ± {s:.2e}{u}", self.name)
    }
}

/// One candidate's full refit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Refit {
    /// What and where.
    pub effect: String,
    /// Kind (spring, mass, ...).
    pub kind: String,
    /// Criterion before (the current model) and after the refit.
    pub criterion_before: f64,
    /// After.
    pub criterion_after: f64,
    /// Likelihood-ratio statistic `2ΔJ/σ̂²`.
    pub lr: f64,
    /// Its degrees of freedom (the effect's parameters).
    pub dof: usize,
    /// p-value of the LR test.
    pub p_value: f64,
    /// Change of Akaike's criterion (negative = better).
    pub aic_change: f64,
    /// Change of the Bayesian information criterion.
    pub bic_change: f64,
    /// The effect's parameters.
    pub params: Vec<ParamEstimate>,
    /// Why the refit stopped.
    pub stop: String,
    /// Whether the refit converged (`stop` says why not); a refit that did not is also listed in
    /// [`Diagnosis::not_tried`].
    #[serde(skip)]
    pub converged: bool,
    /// Placements the data cannot tell from this one (see [`Ranked::equivalent`]).
    pub equivalent: Vec<String>,
}

/// One ranked candidate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ranked {
    /// 1-based rank.
    pub rank: usize,
    /// Kind.
    pub kind: String,
    /// What and where.
    pub effect: String,
    /// LM statistic.
    pub statistic: f64,
    /// p-value.
    pub p_value: f64,
    /// Other placements the data cannot tell from this one (their directions agree to
    /// |cos| ≥ 0.99 after the fit's own directions are projected out), best first.
    pub equivalent: Vec<String>,
}

/// Candidates whose projected directions agree to this |cos| form one family in the ranking.
const EQUIVALENT_COS: f64 = 0.99;

/// One round: rank, refit the best, accept one or stop.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Round {
    /// Candidates scored.
    pub candidates: usize,
    /// The best-ranked candidates (up to 20).
    pub ranked: Vec<Ranked>,
    /// Full refits of the best.
    pub refits: Vec<Refit>,
    /// The p-value an LR test must beat (α / candidates).
    pub threshold: f64,
    /// Index into `refits` of the accepted effect.
    pub accepted: Option<usize>,
    /// Earlier effects dropped after this round's was added: the data no longer need them.
    pub removed: Vec<Removed>,
    /// The accepted point mass or spring refitted with its place free, when the data prefer the
    /// fitted place (it then replaces the candidate placement).
    pub placed: Option<Refit>,
}

/// An effect accepted in an earlier round and dropped by the backward check.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Removed {
    /// What and where.
    pub effect: String,
    /// Likelihood-ratio statistic for keeping it, given the later effects.
    pub lr: f64,
    /// Its p-value (not below the round's threshold: not needed).
    pub p_value: f64,
}

/// A candidate or refit that could not be evaluated.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NotTried {
    /// What.
    pub effect: String,
    /// Why.
    pub reason: String,
}

/// The result of a diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// Residuals of the identification as given.
    pub before: ResidualAnalysis,
    /// Residuals after the accepted effects.
    pub after: ResidualAnalysis,
    /// The rounds.
    pub rounds: Vec<Round>,
    /// Accepted effects with their estimates, in order.
    pub accepted: Vec<Refit>,
    /// What could not be tried, and why.
    pub not_tried: Vec<NotTried>,
    /// Variable estimates after the last accepted effect (SI).
    pub estimate: Vec<f64>,
    /// Their Cramér-Rao standard errors at that fit (SI; NaN where undetermined); empty when no
    /// effect was accepted (the identification's errors stand).
    pub std_error: Vec<f64>,
    /// The final model (effects added, estimates written in).
    #[serde(skip)]
    pub model: Model,
    /// The effects added, in order (with `accepted[i].params` their values).
    #[serde(skip)]
    pub effects: Vec<Effect>,
}

/// Why a diagnosis could not run.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    /// The identification's model cannot be evaluated.
    #[error("cannot evaluate the identified model for diagnosis: {0}")]
    Model(#[from] EvalError),
    /// The significance level is not in (0, 1).
    #[error("significance level {0}: give 0 < α < 1")]
    Alpha(f64),
}

/// Why the refit of one candidate failed (the candidate is then reported as not tried).
#[derive(Debug, thiserror::Error)]
pub enum RefitError {
    /// Fewer observations than parameters plus one.
    #[error("too few observations ({observations}) for {parameters} parameters")]
    TooFewObservations {
        /// Scalar residuals.
        observations: usize,
        /// Variables plus effect parameters.
        parameters: usize,
    },
    /// The extended model cannot be evaluated.
    #[error(transparent)]
    Eval(#[from] EvalError),
}

/// The state of the extended fit after a round.
struct Current {
    effects: Vec<Effect>,
    u: DVector<f64>,
    e: DVector<f64>,
    jac: DMatrix<f64>,
}

/// Diagnoses the identification `id` of `vars` on `model` from `obs`. `progress` gets one line
/// per step (ranking, each refit, each decision).
pub fn diagnose(
    model: &Model,
    obs: &Observations,
    vars: &Variables,
    id: &Identification,
    opts: &Options,
    progress: &mut dyn FnMut(&str),
) -> Result<Diagnosis, DiagnoseError> {
    if !(opts.alpha > 0.0 && opts.alpha < 1.0) {
        return Err(DiagnoseError::Alpha(opts.alpha));
    }
    let (f_lo, f_hi) = band(obs);
    let iopts = &opts.identification;
    let labels: Vec<String> = obs
        .characteristics
        .iter()
        .map(|c| c.label.clone())
        .collect();
    let mut p0 = Problem::new(model, vars, obs, iopts, Vec::new(), f_hi);
    let mut cur = base_fit(&mut p0, &id.estimate)?;
    let before = analysis(&p0, &cur, opts)?;
    progress(&format!("before: {}", before.verdict));

    let mut rounds = Vec::new();
    let mut accepted = Vec::new();
    let mut not_tried = untestable();
    for _ in 0..opts.max_effects {
        let pc = Problem::new(model, vars, obs, iopts, cur.effects.clone(), f_hi);
        let ranking = rank(&pc, &cur, &labels, (f_lo, f_hi), opts.alpha, &mut not_tried)?;
        progress(&format!(
            "ranked {} candidates; best: {}",
            ranking.scored.len(),
            ranking
                .scored
                .first()
                .map(|s| ranking.candidates[s.candidate].describe())
                .unwrap_or_default()
        ));
        let (refits, best) = refit_leading(
            (model, vars, obs),
            opts,
            &cur,
            &ranking,
            f_hi,
            &mut not_tried,
            progress,
        );
        let mut round = Round {
            candidates: ranking.scored.len(),
            ranked: ranking.ranked.clone(),
            refits: refits.clone(),
            threshold: ranking.threshold,
            accepted: best.as_ref().map(|(i, _)| *i),
            removed: Vec::new(),
            placed: None,
        };
        let Some((i, next)) = best else {
            rounds.push(round);
            progress("nothing significant left");
            break;
        };
        progress(&format!("accepted: {}", refits[i].effect));
        let chosen = refits[i].clone();
        let (chosen, next) = placed(
            (model, vars, obs),
            opts,
            &cur,
            (chosen, next),
            (f_hi, ranking.sigma2, ranking.threshold),
            &mut round,
            progress,
        );
        accepted.push(chosen);
        cur = next;
        remove_unneeded(
            (model, vars, obs),
            opts,
            (&mut cur, &mut accepted),
            (f_hi, ranking.sigma2, ranking.threshold),
            &mut round,
            progress,
        );
        rounds.push(round);
    }
    final_fit(
        (model, vars, obs),
        opts,
        cur,
        f_hi,
        (before, rounds, accepted, not_tried),
        progress,
    )
}

/// The diagnosis at the final fit `cur`: the residual analysis after, the accepted effects'
/// values and errors there (a later effect or a removal moved them), the final model.
fn final_fit(
    (model, vars, obs): (&Model, &Variables, &Observations),
    opts: &Options,
    cur: Current,
    f_hi: f64,
    (before, rounds, mut accepted, not_tried): (
        ResidualAnalysis,
        Vec<Round>,
        Vec<Refit>,
        Vec<NotTried>,
    ),
    progress: &mut dyn FnMut(&str),
) -> Result<Diagnosis, DiagnoseError> {
    let iopts = &opts.identification;
    let pf = Problem::new(model, vars, obs, iopts, cur.effects.clone(), f_hi);
    let after = analysis(&pf, &cur, opts)?;
    progress(&format!("after: {}", after.verdict));
    // Effects refitted after their own round (a later effect, a removal) moved: report their
    // values and errors at the final fit, and the variables' errors there.
    let mut std_error = Vec::new();
    if !cur.effects.is_empty() {
        let crit_scale = residual_scale(
            &cur,
            free_columns(&pf, &cur.u).len(),
            after.chi2_p.is_none(),
        );
        let finals = estimates(&pf, &cur, f_hi, crit_scale);
        for (a, params) in accepted.iter_mut().zip(finals) {
            a.params = params;
        }
        std_error = variable_errors(&pf, &cur, crit_scale);
    }
    let (x, gamma) = pf.split(&cur.u);
    let realized = pf.realize(&gamma)?;
    let mut final_model = realized.model;
    realized.vars.apply(&mut final_model, &x);
    Ok(Diagnosis {
        before,
        after,
        rounds,
        accepted,
        not_tried,
        estimate: x,
        std_error,
        model: final_model,
        effects: cur.effects,
    })
}

/// The identification's fit `estimate` as the starting state: no effect, its residuals and
/// Jacobian.
fn base_fit(p0: &mut Problem, estimate: &[f64]) -> Result<Current, DiagnoseError> {
    let u0 = DVector::from_iterator(
        estimate.len(),
        estimate.iter().zip(&p0.scale).map(|(x, s)| x / s),
    );
    let (e, jac) = p0.eval(&u0, true)?;
    let jac = jac.unwrap_or_else(|| DMatrix::zeros(e.len(), 0));
    Ok(Current {
        effects: Vec::new(),
        u: u0,
        e,
        jac,
    })
}

/// Backward elimination after an acceptance: drops, one at a time, every earlier effect the
/// later ones made unnecessary (recorded in `round.removed`).
fn remove_unneeded(
    (model, vars, obs): (&Model, &Variables, &Observations),
    opts: &Options,
    (cur, accepted): (&mut Current, &mut Vec<Refit>),
    (f_hi, sigma2, threshold): (f64, f64, f64),
    round: &mut Round,
    progress: &mut dyn FnMut(&str),
) {
    while let Some((k, r, next)) = backward(model, vars, obs, opts, cur, f_hi, sigma2, threshold) {
        progress(&format!(
            "removed: {} (no longer needed: LR = {:.1}, p = {:.2e})",
            r.effect, r.lr, r.p_value
        ));
        accepted.remove(k);
        round.removed.push(r);
        *cur = next;
    }
}

/// The measured band (Hz): lowest and highest line (at least 1 mHz, the top above the bottom).
fn band(obs: &Observations) -> (f64, f64) {
    let freqs: Vec<f64> = obs
        .characteristics
        .iter()
        .flat_map(|c| c.freqs_hz.iter().copied())
        .collect();
    let f_lo = freqs
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
        .max(1e-3);
    let f_hi = freqs.iter().copied().fold(0.0, f64::max).max(f_lo * 1.01);
    (f_lo, f_hi)
}

/// Effects this data cannot test, and why (reported with every diagnosis).
fn untestable() -> Vec<NotTried> {
    vec![
        NotTried {
            effect: "amplitude-dependent stiffness".into(),
            reason: "needs characteristics measured at two excitation levels; the data has one".into(),
        },
        NotTried {
            effect: "ψ varying with frequency".into(),
            reason: "the model's hysteretic damping is frequency independent by construction; a frequency-dependent ψ is not a nested change of this model".into(),
        },
        NotTried {
            effect: "sensor misalignment".into(),
            reason: "the characteristics are principal-axis motions fitted from several sensors; a per-sensor misalignment is checked by the processing's rigidity indicator, not here".into(),
        },
    ]
}

/// One round's candidates ranked by the score test at the current fit.
struct Ranking {
    candidates: Vec<Effect>,
    /// The scorable candidates, most significant first.
    scored: Vec<score::Scored>,
    /// Families of near-identical candidates (indices into `scored`), representative first.
    families: Vec<Vec<usize>>,
    /// The families as reported.
    ranked: Vec<Ranked>,
    /// Bonferroni threshold of the round: α / candidates.
    threshold: f64,
    /// σ̂² of the current fit.
    sigma2: f64,
}

/// Generates the candidates on the current fit of `pc` and ranks them at family-wise level
/// `alpha`; those that cannot be scored go to `not_tried`.
fn rank(
    pc: &Problem,
    cur: &Current,
    labels: &[String],
    (f_lo, f_hi): (f64, f64),
    alpha: f64,
    not_tried: &mut Vec<NotTried>,
) -> Result<Ranking, DiagnoseError> {
    let (x, gamma) = pc.split(&cur.u);
    let realized = pc.realize(&gamma)?;
    let crit = pc.criterion(&realized)?;
    let free = free_columns(pc, &cur.u);
    let jfree = DMatrix::from_fn(cur.jac.nrows(), free.len(), |r, c| cur.jac[(r, free[c])]);
    let sigma2 = residual_scale(cur, free.len(), crit.noise.scale_unknown());
    // A characteristic whose gain is already a variable gets no gain candidate.
    let candidates: Vec<_> = generate::candidates(
        &crit.model_at(&x),
        &realized.vars,
        &x,
        labels,
        f_lo,
        f_hi,
    )
    .into_iter()
    .filter(|e| !matches!(e, Effect::Gain { output, .. } if crit.gain_variable(*output).is_some()))
    .collect();
    // The effects' gains times the gain variables' (the model output the criterion fits).
    let gains: Vec<f64> = realized
        .gains
        .iter()
        .enumerate()
        .map(|(o, g)| g * crit.gain(o, &x))
        .collect();
    let fit = score::FitPoint {
        crit: &crit,
        x: &x,
        gains: &gains,
        e: &cur.e,
        jac: &jfree,
        sigma2,
    };
    let scores = score::score_all(&fit, &candidates).map_err(EvalError::from)?;
    let mut scored: Vec<score::Scored> = Vec::new();
    for (c, s) in candidates.iter().zip(scores) {
        match s {
            Ok(s) => scored.push(s),
            Err(reason) => not_tried.push(NotTried {
                effect: c.describe(),
                reason: reason.to_string(),
            }),
        }
    }
    scored.sort_by(|a, b| {
        a.p_value
            .total_cmp(&b.p_value)
            .then(b.statistic.total_cmp(&a.statistic))
    });
    let threshold = alpha / scored.len().max(1) as f64;
    let families = families(&scored, 20);
    let ranked: Vec<Ranked> = families
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let s = &scored[f[0]];
            Ranked {
                rank: i + 1,
                kind: candidates[s.candidate].kind().into(),
                effect: candidates[s.candidate].describe(),
                statistic: s.statistic,
                p_value: s.p_value,
                equivalent: f[1..]
                    .iter()
                    .map(|&j| candidates[scored[j].candidate].describe())
                    .collect(),
            }
        })
        .collect();
    Ok(Ranking {
        candidates,
        scored,
        families,
        ranked,
        threshold,
        sigma2,
    })
}

/// Refits the leading families (up to `opts.refit`) whose score makes them plausible; returns
/// every refit and the most significant one that passes the round's threshold, with its fit.
fn refit_leading(
    (model, vars, obs): (&Model, &Variables, &Observations),
    opts: &Options,
    cur: &Current,
    ranking: &Ranking,
    f_hi: f64,
    not_tried: &mut Vec<NotTried>,
    progress: &mut dyn FnMut(&str),
) -> (Vec<Refit>, Option<(usize, Current)>) {
    let Ranking {
        candidates,
        scored,
        families,
        ranked,
        threshold,
        sigma2,
    } = ranking;
    let mut refits: Vec<Refit> = Vec::new();
    let mut best: Option<(usize, Current)> = None;
    // Refit only what the score makes plausible: the score and LR statistics agree for small
    // effects and the score understates large ones, so a loose gate (1000× the LR's
    // threshold) loses nothing and saves the refits when there is nothing to find.
    for (f, family) in families
        .iter()
        .enumerate()
        .take(opts.refit)
        .filter(|(_, f)| scored[f[0]].p_value < (1000.0 * threshold).min(1.0))
    {
        let s = &scored[family[0]];
        let cand = &candidates[s.candidate];
        // The first parameter starts at the score's Gauss-Newton step, the others at their
        // initial values.
        let start: Vec<f64> = cand
            .params(f_hi)
            .iter()
            .enumerate()
            .map(|(j, np)| {
                if j == 0 {
                    np.nested + s.step
                } else {
                    np.initial
                }
            })
            .collect();
        match refit(model, vars, obs, opts, cur, cand, &start, f_hi, *sigma2) {
            Ok((mut r, next)) => {
                r.equivalent = ranked[f].equivalent.clone();
                progress(&format!(
                    "refit {}: ΔJ = {:.1}, LR = {:.1}, p = {:.2e}",
                    r.effect,
                    r.criterion_before - r.criterion_after,
                    r.lr,
                    r.p_value
                ));
                // Most significant first; p-values of large effects underflow to 0, so
                // compare the LR's margin over its critical value at the threshold.
                let better = best
                    .as_ref()
                    .is_none_or(|(b, _)| margin(&r, *threshold) > margin(&refits[*b], *threshold));
                if r.p_value < *threshold && better {
                    best = Some((refits.len(), next));
                }
                if !r.converged {
                    not_tried.push(NotTried {
                        effect: format!("refit of {}", r.effect),
                        reason: format!(
                            "{}; its likelihood-ratio test used the best point reached",
                            r.stop
                        ),
                    });
                }
                refits.push(r);
            }
            Err(reason) => not_tried.push(NotTried {
                effect: format!("refit of {}", cand.describe()),
                reason: reason.to_string(),
            }),
        }
    }
    (refits, best)
}

/// The accepted refit with its location refined where that is significantly better (recorded
/// in `round.placed`), and the fit that goes with it.
fn placed(
    (model, vars, obs): (&Model, &Variables, &Observations),
    opts: &Options,
    cur: &Current,
    (chosen, next): (Refit, Current),
    (f_hi, sigma2, threshold): (f64, f64, f64),
    round: &mut Round,
    progress: &mut dyn FnMut(&str),
) -> (Refit, Current) {
    let Some((placed, better)) = place(
        model, vars, obs, opts, cur, &next, &chosen, f_hi, sigma2, threshold,
    ) else {
        return (chosen, next);
    };
    progress(&format!(
        "placed: {}",
        placed
            .params
            .iter()
            .map(ParamEstimate::describe)
            .collect::<Vec<_>>()
            .join(", ")
    ));
    round.placed = Some(placed.clone());
    (placed, better)
}

/// The backward check after an effect was added: an earlier effect may only have compensated for
/// what the new one explains (a first identification in a poor local minimum, a placement next to
/// the true one). Refits without each earlier effect and returns the first one the data no longer
/// need (LR p-value not below `threshold`), with the fit without it.
#[allow(clippy::too_many_arguments)]
fn backward(
    model: &Model,
    vars: &Variables,
    obs: &Observations,
    opts: &Options,
    cur: &Current,
    f_hi: f64,
    sigma2: f64,
    threshold: f64,
) -> Option<(usize, Removed, Current)> {
    let n = cur.effects.len();
    let nx = cur.u.len()
        - cur
            .effects
            .iter()
            .map(|e| e.params(f_hi).len())
            .sum::<usize>();
    let mut offset = nx;
    for k in 0..n.saturating_sub(1) {
        let q = cur.effects[k].params(f_hi).len();
        let effects: Vec<Effect> = cur
            .effects
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != k)
            .map(|(_, e)| e.clone())
            .collect();
        let u0 = DVector::from_iterator(
            cur.u.len() - q,
            cur.u
                .iter()
                .enumerate()
                .filter(|(i, _)| *i < offset || *i >= offset + q)
                .map(|(_, v)| *v),
        );
        offset += q;
        let mut p = Problem::new(
            model,
            vars,
            obs,
            &opts.identification,
            effects.clone(),
            f_hi,
        );
        let (lo, hi) = p.bounds();
        let Ok(out) = optimize::minimize(
            opts.identification.optimizer,
            &mut p,
            &u0,
            &lo,
            &hi,
            &opts.identification.settings,
            &mut |_| {},
        ) else {
            continue;
        };
        let Ok((e, Some(jac))) = p.eval(&out.u, true) else {
            continue;
        };
        let lr = ((e.norm_squared() - cur.e.norm_squared()) / sigma2).max(0.0);
        let p_value = residuals::chi2_tail(q as f64, lr);
        if p_value >= threshold {
            let r = Removed {
                effect: cur.effects[k].describe(),
                lr,
                p_value,
            };
            return Some((
                k,
                r,
                Current {
                    effects,
                    u: out.u,
                    e,
                    jac,
                },
            ));
        }
    }
    None
}

/// An accepted point mass or spring sits at the nearest candidate point, not where the effect
/// is: refit it with its place free too — a mass's position (±half the host body's largest
/// side), a spring's line of action across its direction (±half the largest side of the bodies
/// it joins) — from `base` (the fit before it was added), from several starting places. Kept when the place parameters beat the
/// round's threshold against the candidate placement `fixed` (LR test).
#[allow(clippy::too_many_arguments)]
fn place(
    model: &Model,
    vars: &Variables,
    obs: &Observations,
    opts: &Options,
    base: &Current,
    fixed: &Current,
    accepted: &Refit,
    f_hi: f64,
    sigma2: f64,
    threshold: f64,
) -> Option<(Refit, Current)> {
    let half_side = |name: &str| {
        model
            .bodies
            .iter()
            .find(|b| b.name == name)
            .map(|b| 0.5 * effects::box_sides(b).into_iter().fold(0.0, f64::max))
    };
    let values: Vec<f64> = accepted.params.iter().map(|p| p.value).collect();
    // The place is a nonlinear parameter with local minima: start from the candidate's point and
    // from points half a reach away (a 3×3 grid across a spring's line of action; ± along each
    // axis for a mass), keep the best. `start` holds the accepted estimates; the place offsets
    // are appended per start.
    let (cand, start, offsets) = match fixed.effects.last()? {
        Effect::Mass { body, point, scale } => {
            let reach = half_side(body)?;
            let h = 0.5 * reach;
            let mut offsets = vec![vec![0.0; 3]];
            for i in 0..3 {
                for sign in [-h, h] {
                    let mut o = vec![0.0; 3];
                    o[i] = sign;
                    offsets.push(o);
                }
            }
            (
                Effect::PlacedMass {
                    body: body.clone(),
                    point: *point,
                    scale: *scale,
                    reach,
                },
                vec![values[0]],
                offsets,
            )
        }
        Effect::Spring {
            bodies,
            point,
            direction,
            ..
        } => {
            let reach = bodies
                .iter()
                .flatten()
                .filter_map(|b| half_side(b))
                .fold(0.0, f64::max);
            if !(reach > 0.0) {
                return None;
            }
            let h = 0.5 * reach;
            let offsets = [-h, 0.0, h]
                .iter()
                .flat_map(|&a| [-h, 0.0, h].map(|b| vec![a, b]))
                .collect();
            (
                Effect::PlacedSpring {
                    bodies: bodies.clone(),
                    point: *point,
                    direction: *direction,
                    reach,
                },
                vec![values[0], values[1]],
                offsets,
            )
        }
        _ => return None,
    };
    let dof = offsets[0].len() as f64;
    let (r, next) = offsets
        .iter()
        .filter_map(|o| {
            let st: Vec<f64> = start.iter().chain(o).copied().collect();
            refit(model, vars, obs, opts, base, &cand, &st, f_hi, sigma2).ok()
        })
        .min_by(|a, b| a.1.e.norm_squared().total_cmp(&b.1.e.norm_squared()))?;
    let lr = ((fixed.e.norm_squared() - next.e.norm_squared()) / sigma2).max(0.0);
    let p = residuals::chi2_tail(dof, lr);
    (p < threshold).then_some((r, next))
}

/// The effects' parameter estimates and Cramér-Rao errors at the fit `cur` of `p`.
fn estimates(p: &Problem, cur: &Current, f_hi: f64, sigma2: f64) -> Vec<Vec<ParamEstimate>> {
    let info = cur.jac.tr_mul(&cur.jac);
    let cov = info
        .clone()
        .try_inverse()
        .or_else(|| info.pseudo_inverse(1e-12).ok());
    let (_, gamma) = p.split(&cur.u);
    let nx = cur.u.len() - gamma.len();
    let mut idx = 0;
    cur.effects
        .iter()
        .map(|eff| {
            eff.params(f_hi)
                .iter()
                .map(|np| {
                    let i = nx + idx;
                    let se = cov
                        .as_ref()
                        .map(|c| (c[(i, i)] * sigma2).max(0.0).sqrt() * np.scale)
                        .unwrap_or(f64::NAN);
                    let v = ParamEstimate {
                        name: np.name.into(),
                        unit: np.unit.into(),
                        value: gamma[idx],
                        std_error: se,
                    };
                    idx += 1;
                    v
                })
                .collect()
        })
        .collect()
}

/// The variables' Cramér-Rao standard errors (SI) at the extended fit `cur` of `p`.
fn variable_errors(p: &Problem, cur: &Current, sigma2: f64) -> Vec<f64> {
    let info = cur.jac.tr_mul(&cur.jac);
    let cov = info
        .clone()
        .try_inverse()
        .or_else(|| info.pseudo_inverse(1e-12).ok());
    let (x, _) = p.split(&cur.u);
    (0..x.len())
        .map(|i| match &cov {
            Some(c) => (c[(i, i)] * sigma2).max(0.0).sqrt() * p.scale[i],
            None => f64::NAN,
        })
        .collect()
}

/// How far a refit's LR exceeds the critical value of its test at `threshold`.
fn margin(r: &Refit, threshold: f64) -> f64 {
    let crit = ChiSquared::new(r.dof as f64)
        .map(|c| c.inverse_cdf(1.0 - threshold))
        .unwrap_or(f64::INFINITY);
    r.lr - crit
}

/// Groups the ranked candidates (best first) into families of near-identical projected
/// directions; returns up to `n` families as indices into `ranked`, representative first.
fn families(ranked: &[score::Scored], n: usize) -> Vec<Vec<usize>> {
    let mut out: Vec<Vec<usize>> = Vec::new();
    // Only the head of the ranking matters; bound the quadratic grouping.
    for (i, s) in ranked.iter().enumerate().take(50 * n) {
        let len = out.len();
        match out
            .iter_mut()
            .find(|f| ranked[f[0]].direction.dot(&s.direction).abs() >= EQUIVALENT_COS)
        {
            Some(f) => f.push(i),
            None if len < n => out.push(vec![i]),
            None => {}
        }
    }
    out
}

/// The scale of the Cramér-Rao bounds and LR statistics at `cur`: 1 when the noise model is
/// known, else the residual variance `‖e‖² / (m − free)` (`unknown`: the noise is known only up
/// to scale).
fn residual_scale(cur: &Current, free: usize, unknown: bool) -> f64 {
    if unknown {
        cur.e.norm_squared() / (cur.e.len().saturating_sub(free).max(1)) as f64
    } else {
        1.0
    }
}

/// The parameters of `p` not at a bound at `u`: the fit's free columns.
fn free_columns(p: &Problem, u: &DVector<f64>) -> Vec<usize> {
    let (lo, hi) = p.bounds();
    (0..u.len())
        .filter(|&i| u[i] > lo[i] + 1e-12 && u[i] < hi[i] - 1e-12)
        .collect()
}

fn analysis(p: &Problem, cur: &Current, opts: &Options) -> Result<ResidualAnalysis, DiagnoseError> {
    let (x, gamma) = p.split(&cur.u);
    let r = p.realize(&gamma)?;
    let crit = p.criterion(&r)?;
    Ok(residuals::analyze(
        &crit,
        &cur.e,
        free_columns(p, &cur.u).len(),
        &crit.model_at(&x),
        opts.alpha,
    ))
}

/// Refits the current effects plus `cand` with every parameter free.
#[allow(clippy::too_many_arguments)]
fn refit(
    model: &Model,
    vars: &Variables,
    obs: &Observations,
    opts: &Options,
    cur: &Current,
    cand: &Effect,
    start: &[f64],
    f_hi: f64,
    sigma2: f64,
) -> Result<(Refit, Current), RefitError> {
    let mut effects = cur.effects.clone();
    effects.push(cand.clone());
    let mut p = Problem::new(
        model,
        vars,
        obs,
        &opts.identification,
        effects.clone(),
        f_hi,
    );
    let new_params = cand.params(f_hi);
    let q = new_params.len();
    let m = cur.e.len();
    if m <= p.scale.len() + 1 {
        return Err(RefitError::TooFewObservations {
            observations: m,
            parameters: p.scale.len(),
        });
    }
    // Start: the current point, the new parameters at `start`.
    let mut u0: Vec<f64> = cur.u.iter().copied().collect();
    for (np, v) in new_params.iter().zip(start) {
        u0.push(v.clamp(np.lower, np.upper) / np.scale);
    }
    let (lo, hi) = p.bounds();
    let u0 = DVector::from_vec(u0);
    let settings = opts.identification.settings;
    let out = optimize::minimize(
        opts.identification.optimizer,
        &mut p,
        &u0,
        &lo,
        &hi,
        &settings,
        &mut |_| {},
    )?;
    let (e, jac) = p.eval(&out.u, true)?;
    let jac = jac.ok_or(EvalError::NoJacobian)?;
    let j0 = 0.5 * cur.e.norm_squared();
    let j1 = 0.5 * e.norm_squared();
    let lr = (2.0 * (j0 - j1) / sigma2).max(0.0);
    let p_value = residuals::chi2_tail(q as f64, lr);
    let n = m as f64;
    let stop = out.stop.describe();
    let next = Current {
        effects,
        u: out.u,
        e,
        jac,
    };
    // Standard errors from the Fisher information at the refit (σ̂² scaled when R is unknown):
    // the new effect's are the last.
    let params = estimates(&p, &next, f_hi, sigma2).pop().unwrap_or_default();
    let r = Refit {
        effect: cand.describe(),
        kind: cand.kind().into(),
        criterion_before: j0,
        criterion_after: j1,
        lr,
        dof: q,
        p_value,
        aic_change: -lr + 2.0 * q as f64,
        bic_change: -lr + q as f64 * n.ln(),
        params,
        stop,
        converged: out.stop.converged(),
        equivalent: Vec::new(),
    };
    Ok((r, next))
}

/// The diagnosis as text: verdict before, ranking, refits, accepted effects, error before/after.
pub fn text(d: &Diagnosis) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "Diagnosis");
    let _ = writeln!(s, "  before: {}", d.before.verdict);
    for (i, r) in d.rounds.iter().enumerate() {
        round_text(&mut s, i, r);
    }
    let _ = writeln!(s);
    if d.accepted.is_empty() {
        let _ = writeln!(
            s,
            "  no effect added: nothing significant at the chosen level"
        );
    }
    for a in &d.accepted {
        let ps: Vec<String> = a.params.iter().map(ParamEstimate::describe).collect();
        let _ = writeln!(s, "  added: {} ({})", a.effect, ps.join(", "));
    }
    before_after_text(&mut s, d);
    let _ = writeln!(s, "  after: {}", d.after.verdict);
    let skipped: Vec<&NotTried> = d.not_tried.iter().collect();
    if !skipped.is_empty() {
        let _ = writeln!(s, "\n  not tried ({}):", skipped.len());
        for n in skipped.iter().take(12) {
            let _ = writeln!(s, "    - {}: {}", n.effect, n.reason);
        }
        if skipped.len() > 12 {
            let _ = writeln!(
                s,
                "    … and {} more (see the JSON report)",
                skipped.len() - 12
            );
        }
    }
    s
}

/// The final model in one block, to be read first: after an accepted effect, every variable's
/// value at the final fit in its report unit with its Cramér-Rao error (bounds hit flagged) and
/// each added effect's parameters; when nothing was accepted, that the first fit stands.
pub fn final_text(id: &Identification, d: &Diagnosis) -> String {
    use crate::display::{relative, sig};
    use std::fmt::Write;
    let mut s = String::new();
    let converged = if id.stop.converged() {
        String::new()
    } else {
        format!(" — the fit did NOT converge ({})", id.stop.describe())
    };
    if d.accepted.is_empty() {
        let _ = writeln!(
            s,
            "FINAL MODEL = the first fit above: the diagnosis added nothing{converged}"
        );
        return s;
    }
    let _ = writeln!(
        s,
        "FINAL MODEL: the first fit above is superseded; {} effect(s) added{converged}",
        d.accepted.len()
    );
    let _ = writeln!(
        s,
        "  {:<20} {:<8} {:>12} {:>12} {:>9}",
        "variable", "unit", "value", "std error", "σ/x"
    );
    for (i, v) in id.variables.vars.iter().enumerate() {
        let x = d.estimate[i];
        let se = d.std_error.get(i).copied().unwrap_or(f64::NAN);
        let f = v.unit.factor;
        let tol = 1e-9 * v.scale;
        let bound = if x <= v.lower + tol {
            "  at lower bound"
        } else if x >= v.upper - tol {
            "  at upper bound"
        } else {
            ""
        };
        let _ = writeln!(
            s,
            "  {:<20} {:<8} {:>12} {:>12} {:>9}{bound}",
            v.name,
            v.unit.symbol,
            sig(x / f, 5),
            sig(se / f, 3),
            if x != 0.0 {
                relative(se / x)
            } else {
                "-".into()
            }
        );
    }
    for a in &d.accepted {
        let ps: Vec<String> = a.params.iter().map(ParamEstimate::describe).collect();
        let _ = writeln!(s, "  + {} ({})", a.effect, ps.join(", "));
    }
    s
}

/// Round `i` of a diagnosis: the ranking, the refits, the placement and the removals.
fn round_text(s: &mut String, i: usize, r: &Round) {
    use std::fmt::Write;
    let _ = writeln!(s, "\n  round {}: {} candidates scored (score test at the current fit); LR threshold p < {:.1e}", i + 1, r.candidates, r.threshold);
    let _ = writeln!(
        s,
        "    {:>4}  {:<14} {:>10} {:>9}  effect",
        "rank", "kind", "LM", "p"
    );
    for c in r.ranked.iter().take(10) {
        let _ = writeln!(
            s,
            "    {:>4}  {:<14} {:>10.1} {:>9.1e}  {}",
            c.rank, c.kind, c.statistic, c.p_value, c.effect
        );
        if !c.equivalent.is_empty() {
            let shown: Vec<&str> = c.equivalent.iter().take(3).map(String::as_str).collect();
            let more = c.equivalent.len().saturating_sub(3);
            let tail = if more > 0 {
                format!(" and {more} more")
            } else {
                String::new()
            };
            let _ = writeln!(s, "          ≡ {}{tail}", shown.join("; "));
        }
    }
    for (k, f) in r.refits.iter().enumerate() {
        let mark = if r.accepted == Some(k) {
            "ACCEPTED"
        } else {
            ""
        };
        let _ = writeln!(
            s,
            "    refit: {}: J {:.1} → {:.1}, LR {:.1} ({} dof), p {:.1e}, ΔBIC {:.1} {mark}",
            f.effect, f.criterion_before, f.criterion_after, f.lr, f.dof, f.p_value, f.bic_change
        );
    }
    if let Some(p) = &r.placed {
        let ps: Vec<String> = p.params.iter().map(ParamEstimate::describe).collect();
        let _ = writeln!(
            s,
            "    placed: {} ({}): its place fitted, LR {:.1} against the model without it",
            p.effect,
            ps.join(", "),
            p.lr
        );
    }
    for x in &r.removed {
        let _ = writeln!(
            s,
            "    removed: {} (not needed once this round's effect is in: LR {:.1}, p {:.2e})",
            x.effect, x.lr, x.p_value
        );
    }
}

/// The error before and after the diagnosis, one line per figure.
fn before_after_text(s: &mut String, d: &Diagnosis) {
    use std::fmt::Write;
    let _ = writeln!(s, "\n  error before → after:");
    let _ = writeln!(
        s,
        "    criterion J     {:.1} → {:.1}",
        d.before.criterion, d.after.criterion
    );
    let _ = writeln!(
        s,
        "    reduced χ²      {:.2} → {:.2}",
        d.before.reduced_chi2, d.after.reduced_chi2
    );
    if let (Some(a), Some(b)) = (d.before.chi2_p, d.after.chi2_p) {
        let _ = writeln!(
            s,
            "    χ² p-value      {} → {}",
            crate::display::p_value(a),
            crate::display::p_value(b)
        );
    }
    for (a, b) in d
        .before
        .characteristics
        .iter()
        .zip(&d.after.characteristics)
    {
        let _ = writeln!(
            s,
            "    RMS rel. error  {:<28} {} → {}",
            a.label,
            crate::display::relative(a.rms_relative),
            crate::display::relative(b.rms_relative)
        );
    }
}
