//! Closing the loop after a fit: does the model explain the data to the noise level, and if
//! not, which effect does it lack? Each round adds at most one effect, chosen by a
//! likelihood-ratio test at a Bonferroni level over every candidate looked at, so the
//! family-wise false-alarm rate per diagnosis stays at `alpha`. The loop, as [`diagnose`] runs it:
//!
//! 1. **Base fit** (`base.rs`): the identification's estimate continued with the same optimizer
//!    until it converges (up to `BASE_CONTINUATIONS` runs); when it does not, or the converged
//!    fit does not explain the data, a multi-start fit (`BASE_STARTS` starts) as well, the better
//!    kept. Every refit below starts from this fit with the same settings, so a likelihood ratio
//!    measures the effect and not further optimisation. [`residuals`] then gives the verdict
//!    "before": χ² against R, runs test along frequency, the mode bands holding the misfit.
//! 2. **Candidates** ([`generate`], [`effects`]): a library of nested effects built from the
//!    model's geometry and laws — springs, point masses, resonators, flexible bodies, sensor
//!    gains, a joint's own damping, an SDE's left-out or held-stiff directions, a body's mass:
//!    about a thousand on FWD-32J, each equal to the current model at its nested value.
//! 3. **Ranking** (`round.rs`, [`score`]): every candidate's score (Lagrange-multiplier) test at
//!    the current fit, from one set of solves; near-identical first-order actions
//!    (|cos| ≥ 0.99) form one family. The round's threshold is `alpha / candidates ranked`.
//! 4. **Screen** (`screen.rs`): the score is a slope at the nested value and understates large
//!    effects, so the 30 leading plausible candidates and each kind's two best are screened by a
//!    finite step: their own parameters fitted with the variables re-adjusted to first order.
//! 5. **Refit of the leading families** (`round.rs`, `refit_leading`): the `--refit` families the
//!    screen puts first and the score's two leading families are refitted with every variable
//!    and the effect's parameters free (each kind and site in a family gets its own refit).
//!    When the misfit is large (reduced χ² > 2) and the best refit still leaves it above the
//!    noise level, it escalates (both judged against R's level, or, with R known only up to
//!    scale, against the noise level the data imply times a real model's floor, `noise.rs`):
//!    (a) **kind jobs**, the best screened family of each kind the leading families leave out,
//!    where its screen alone is significant, refitted in full where its leader's short refit
//!    goes below the best refit so far; (b) if still above,
//!    **short refits** (40 iterations, also from the variables' initial values) of each kind's
//!    plausible candidates, the strongest pulls the one-sided score rules out, and every
//!    candidate of the kinds without a point, the families whose short refit ends below the best
//!    refit then refitted in full. When the misfit is small but above the noise level, the
//!    **damping splits** get the short refits instead.
//!    **Pair judgement** (`pairs.rs`): where the best refit still leaves the misfit above the
//!    noise level, it and the next leading refits are each judged with their best next effect
//!    (a ranking at their fit and a few refits); another refit whose pair explains the data and
//!    stands above the best one's by an LR of 3.84 takes its place: a look-alike of two effects
//!    at once explains more than either alone but less with any partner.
//! 6. **Acceptance** (`round.rs`): the most significant refit is accepted when its LR beats the
//!    round's Bonferroni threshold, its estimates are physical (none at a bound, a resonator
//!    tuned within the band), its size stands from its nested value at the round's own level
//!    (identifiability), and it removes at least 10 % of the misfit above the noise level (else
//!    a partial fix). The refits the data cannot tell from it (LR within 3.84) are its "≡".
//! 7. **After acceptance** (`placement.rs`): a point mass or resonator is moved to the body's
//!    point where it fits best; a point mass's position or a spring's line of action is refined
//!    with its place free; the **backward check** drops earlier effects the new one made
//!    unnecessary; earlier masses, resonators and springs are relocated now the new one is in.
//! 8. **Swap** (`swap.rs`): in a round that accepts nothing, each accepted effect is tried once
//!    against the effects of other kinds on the same bodies and replaced by one the data prefer;
//!    a swap gives the round back and the loop goes on. Otherwise the loop ends (or after
//!    `max_effects` acceptances).
//! 9. **Final fit and verdict** (`final_fit`): the residual analysis "after", the accepted
//!    effects' estimates and standard errors at the final fit, and, when the data are still not
//!    explained, the verdict OUTSIDE THE LIBRARY with the band and characteristics holding the
//!    remaining misfit. [`final_model`] writes the diagnosed model.
//!
//! This file holds the records (options, refits, rounds, the diagnosis) and the loop itself;
//! `tuning.rs` the numbers every stage uses (candidates looked at, iterations, levels), each with
//! its reason;
//! `text.rs` writes the report in the paper's units. `docs/diagnosis.md` gives the statistics,
//! the options, the JSON and the measured performance.
//!
//! ```no_run
//! use diagnose::{diagnose, Options};
//! # fn run(model: &rfe::Model, obs: &identify::Observations,
//! #        vars: &identify::Variables,
//! #        id: &identify::Identification) {
//! let d = diagnose(model, obs, vars, id, &Options::default(), &mut |line| eprintln!("{line}")).unwrap();
//! println!("{}", diagnose::text(&d));
//! # }
//! ```

// No panic on anything from a file, a device or a user (tests may: allow-expect-in-tests).
#![warn(clippy::expect_used)]

mod base;
pub mod effects;
pub mod final_model;
pub mod generate;
pub mod lowrank;
mod noise;
mod pairs;
mod placement;
pub mod problem;
pub mod request;
pub mod residuals;
mod round;
pub mod score;
mod screen;
mod swap;
mod text;
mod tuning;

use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};

pub use effects::Effect;
use effects::{EffectParam, Z95};
pub use residuals::ResidualAnalysis;
pub use text::{final_text, gain_text, text};

use base::base_fit;
pub use base::BaseFit;
use placement::{after_acceptance, Chosen};
use round::{rank, refit_leading, screen_leading, Leading, Ranking, Refitted, Screened};
use swap::swap_accepted;

use identify::optimize::{self, Residuals as _};
use identify::{self, EvalError, Identification, Observations, Variables};
use problem::Problem;
use rfe::model::Model;

/// How to diagnose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Family-wise significance level: the accepted false-alarm rate per diagnosis.
    pub alpha: f64,
    /// At most this many effects are added.
    pub max_effects: usize,
    /// Refit this many candidate families of each round, the best screened first (and the
    /// score's two leading families when the screen left them out; when the misfit is large and
    /// their refits leave it above the noise level, also the family of each kind's best-scored
    /// candidate none of them holds, where its screen is significant, and then up to this many
    /// more whose short refits went below the best refit).
    pub refit: usize,
    /// How the identification was run (fit kind, noise model, optimizer settings).
    pub identification: identify::Options,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            alpha: 0.01,
            max_effects: 3,
            refit: 5,
            identification: identify::Options::default(),
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
    /// RMS amplitude error (dB) over every fitted point before the refit: the gain in the
    /// curves' terms, beside the criterion's.
    pub rms_db_before: f64,
    /// After it.
    pub rms_db_after: f64,
    /// The effect's parameters.
    pub params: Vec<ParamEstimate>,
    /// Why the refit stopped.
    pub stop: String,
    /// Whether the refit converged (`stop` says why not); a refit that did not is also listed in
    /// [`Diagnosis::not_tried`].
    #[serde(skip)]
    pub converged: bool,
    /// The effects the data cannot tell from this one: the family members and, for an accepted
    /// effect, the other refits of its round that the round could have accepted, whose refits end
    /// within a likelihood ratio of 3.84 of it (see [`Ranked::equivalent`] for the score's
    /// look-alikes). Described in the JSON.
    #[serde(serialize_with = "described")]
    pub equivalent: Vec<Effect>,
    /// The score family this refit stands for (every member, refitted or not): a ranked
    /// candidate whose family this is was accepted through this refit.
    #[serde(skip)]
    pub family: Vec<String>,
    /// For an accepted effect whose place was fitted: where, with its 95 % confidence region
    /// (mm, set at the final fit).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub place: Option<String>,
}

/// Serializes effects as their descriptions, the JSON's form of an effect.
fn described<S: serde::Serializer>(effects: &[Effect], s: S) -> Result<S::Ok, S::Error> {
    s.collect_seq(effects.iter().map(Effect::describe))
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
    /// The family's effects, this one first, then the equivalent ones.
    #[serde(skip)]
    pub family: Vec<Effect>,
}

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
    /// Point masses and resonators moved to another body's attachment point, and earlier
    /// springs to another pair of bodies, where they fit better: the round's accepted one
    /// (replacing the candidate the round accepted), then earlier ones, refitted there with the
    /// later effects in.
    pub relocated: Vec<Refit>,
    /// Accepted effects replaced, once no candidate was significant any more, by an effect of
    /// another kind on the same bodies that the data prefer (a round that accepted nothing).
    pub replaced: Vec<Replaced>,
    /// The accepted point mass or spring refitted with its place free, when the data prefer the
    /// fitted place (it then replaces the candidate placement).
    pub placed: Option<Refit>,
    /// Refits significant by their LR test but not added: an estimate at a bound of its
    /// parameter or a confidence interval that includes the nested value ("indicated but not
    /// identifiable").
    pub not_identifiable: Vec<NotTried>,
    /// Where the best refit left the misfit above the noise level, each leading refit with its
    /// best next effect, as a refit (`effect` "first + next", `dof` and `params` both effects';
    /// the likelihood ratio against the fit the round started from). A first effect whose pair
    /// explains the data and that the data prefer to the best refit's own pair was accepted in
    /// its place (see `pairs.rs`).
    pub pairs: Vec<Refit>,
}

/// An accepted effect replaced by one of another kind on the same bodies.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Replaced {
    /// The effect replaced: what and where.
    pub effect: String,
    /// The refit of the effect that replaced it (in the fit without the replaced one).
    pub by: Refit,
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
    /// The Cramér-Rao correlation of those variables at that fit (row-major, variables-file
    /// order; NaN where undetermined); empty when no effect was accepted.
    pub correlation: Vec<Vec<f64>>,
    /// The final model (effects added, estimates written in).
    #[serde(skip)]
    pub model: Model,
    /// The effects added, in order (with `accepted[i].params` their values).
    #[serde(skip)]
    pub effects: Vec<Effect>,
    /// Where the diagnosis's wall time went.
    pub timing: Timing,
    /// The base fit the diagnosis started from.
    pub base: BaseFit,
    /// The units of the JSON form: [`JSON_UNITS`].
    pub units: &'static str,
    /// When the final model still does not explain the data: the plain verdict that an effect
    /// the candidate library lacks remains, where in frequency and on which characteristics.
    pub outside_library: Option<String>,
}

/// The verdict when the diagnosis ends with the data unexplained: no candidate of the library
/// (or none that is significant and physical) brings the fit to the noise level, so an effect the
/// library lacks remains. Names the band with the largest excess of misfit and the
/// characteristics carrying most of it, so an engineer knows where to look.
fn outside_library(after: &ResidualAnalysis, added: usize) -> Option<String> {
    if after.explained {
        return None;
    }
    let total: f64 = after.characteristics.iter().map(|c| c.chi2).sum();
    let mut chars: Vec<(&str, f64)> = after
        .characteristics
        .iter()
        .map(|c| (c.label.as_str(), c.chi2 / total.max(f64::MIN_POSITIVE)))
        .collect();
    chars.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut on: Vec<String> = Vec::new();
    let mut covered = 0.0;
    for (label, share) in chars {
        on.push(format!("{label} ({:.0} %)", 100.0 * share));
        covered += share;
        if covered >= 0.6 || on.len() == 3 {
            break;
        }
    }
    let band = after
        .bands
        .iter()
        .find(|b| b.share > b.points_share)
        .map(|b| {
            format!(
                " at {:.0}-{:.0} Hz (the {:.0} Hz mode, mostly {}: {:.0} % of the misfit on {:.0} % of the lines)",
                b.from_hz,
                b.to_hz,
                b.mode_hz,
                b.body,
                100.0 * b.share,
                100.0 * b.points_share
            )
        })
        .unwrap_or_default();
    let partial = if added > 0 {
        format!(" The {added} effect(s) added are partial fixes; judge them with this in mind.")
    } else {
        String::new()
    };
    Some(format!(
        "OUTSIDE THE LIBRARY: no candidate effect brings the model to the noise level (reduced χ² {:.3} after); an effect the library lacks remains{band}, on {}.{partial} Check the model form there (a joint's held-stiff direction, a flexible body, a missing element) and the data (units, band, sensor placement).",
        after.reduced_chi2,
        on.join(", ")
    ))
}

/// What the numbers of a diagnosis's JSON form are in (the text report uses the paper's units:
/// N/µm, µm/N, mm).
pub const JSON_UNITS: &str = "SI throughout: each effect parameter's unit is its params[].unit (N/m, N·m/rad, m/N, rad/(N·m), m, kg, Hz, - ); estimate[] and std_error[] in each variable's SI unit, in variables-file order; frequencies in Hz (freqs_hz, mode_hz, from_hz, to_hz); RMS amplitude errors in dB (rms_db, rms_db_before, rms_db_after); criteria, statistics, p-values, shares and residuals dimensionless; timing in s";

/// Wall time of a diagnosis's parts (seconds).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Timing {
    /// Unit of every figure: `"s"`.
    pub unit: &'static str,
    /// The base fit the diagnosis starts from (its convergence check and extra starts).
    pub base_fit: f64,
    /// Candidate generation and ranking, every round.
    pub ranking: f64,
    /// The candidates' refits, every round.
    pub refits: f64,
    /// The swaps of accepted effects for effects of other kinds (see `swap.rs`).
    pub swaps: f64,
    /// The pair judgement of rounds whose best refit left the misfit above the noise level
    /// (see `pairs.rs`).
    pub pairs: f64,
    /// Placement refinement, backward checks and the final analysis.
    pub other: f64,
}

/// The time split of a diagnosis, one line.
pub fn timing_text(d: &Diagnosis) -> String {
    let t = &d.timing;
    format!(
        "time: base fit {:.2} s, ranking {:.2} s, refits {:.2} s, pairs {:.2} s, swaps {:.2} s, placement and checks {:.2} s",
        t.base_fit, t.ranking, t.refits, t.pairs, t.swaps, t.other
    )
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

/// What every step of a diagnosis works on: the model, its variables, the data, the options,
/// and the top of the measured band (Hz: it bounds a resonator's tuning).
#[derive(Clone, Copy)]
struct Setting<'a> {
    model: &'a Model,
    vars: &'a Variables,
    obs: &'a Observations,
    opts: &'a Options,
    f_hi: f64,
    /// The noise level the data imply (`noise.rs`) when R is known only up to scale: what a
    /// misfit is judged "large" and "above the noise" against.
    data_noise: Option<f64>,
    /// The round's held solves (see [`lowrank::Solves`]).
    solves: &'a lowrank::Solves,
}

impl<'a> Setting<'a> {
    /// The identification problem with `effects` added to the model.
    fn problem(&self, effects: Vec<Effect>) -> Problem<'a> {
        Problem::new(
            self.model,
            self.vars,
            self.obs,
            &self.opts.identification,
            effects,
            self.f_hi,
        )
    }
}

/// A round's noise level and significance: σ̂² of the fit the round starts from and the
/// round's Bonferroni threshold (a p-value).
#[derive(Clone, Copy)]
struct Level {
    sigma2: f64,
    threshold: f64,
}

/// The state of the extended fit after a round.
struct Current {
    effects: Vec<Effect>,
    u: DVector<f64>,
    e: DVector<f64>,
    jac: DMatrix<f64>,
}

/// The diagnosis so far: the current fit and the refits of the effects accepted into it, in the
/// order of `cur.effects`.
struct Diagnosed {
    cur: Current,
    accepted: Vec<Refit>,
}

/// What the rounds leave besides the fit: the residual analysis before them, each round, and
/// what could not be tried.
struct Record {
    before: ResidualAnalysis,
    rounds: Vec<Round>,
    not_tried: Vec<NotTried>,
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
    let (f_lo, f_hi) = obs.band_hz();
    let labels: Vec<String> = obs
        .characteristics
        .iter()
        .map(|c| c.label.clone())
        .collect();
    let clock = std::time::Instant::now();
    let mut timing = Timing {
        unit: "s",
        ..Timing::default()
    };
    let solves = lowrank::Solves::default();
    let mut setting = Setting {
        model,
        vars,
        obs,
        opts,
        f_hi,
        data_noise: None,
        solves: &solves,
    };
    let mut p0 = setting.problem(Vec::new());
    setting.data_noise = noise::data_level(&p0.criterion(&p0.realize(&[])?)?);
    let (cur, base) = base_fit(model, vars, obs, &mut p0, id, opts, progress)?;
    timing.base_fit = clock.elapsed().as_secs_f64();
    let before = analysis(&p0, &cur, opts)?;
    progress(&format!("before: {}", before.verdict));
    if let Some(s2) = setting.data_noise {
        progress(&format!("noise level the data imply (R known up to scale): {:.2}× the assumed relative error in RMS", s2.sqrt()));
    }

    let mut rounds = Vec::new();
    let mut so_far = Diagnosed {
        cur,
        accepted: Vec::new(),
    };
    let mut not_tried = untestable();
    // Rounds left: each may accept one effect; a round that replaces one instead gives its
    // round back (an effect is tried for a swap once, so this ends).
    let mut rounds_left = opts.max_effects;
    let mut swap_tried = Vec::new();
    // The partner of a pair that chose the last round's first effect (`pairs.rs`).
    let mut carried: Option<pairs::Carried> = None;
    while rounds_left > 0 {
        rounds_left -= 1;
        let t = std::time::Instant::now();
        let (ranking, screened) = rank_and_screen(
            setting,
            &so_far.cur,
            &labels,
            f_lo,
            &mut not_tried,
            progress,
        )?;
        timing.ranking += t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let refitted = refit_leading(
            setting,
            &so_far.cur,
            Leading {
                ranking: &ranking,
                screened: &screened,
                carried: carried.as_ref(),
            },
            &mut not_tried,
            progress,
        );
        timing.refits += t.elapsed().as_secs_f64();
        // A leading refit whose pair with its best next effect explains the data better than
        // the best single's own pair takes its place (`pairs.rs`).
        let t = std::time::Instant::now();
        let judged = pairs::judge_pairs(setting, &so_far.cur, ranking.level(), &refitted, progress);
        let Refitted {
            refits,
            best,
            not_identifiable,
            contenders,
            mut fits,
        } = refitted;
        let best = judged.first.or(best).map(|i| (i, fits.swap_remove(i)));
        carried = judged.partner;
        timing.pairs += t.elapsed().as_secs_f64();
        let mut round = Round {
            candidates: ranking.scored.len(),
            ranked: ranking.ranked.clone(),
            refits: refits.clone(),
            threshold: ranking.threshold,
            accepted: best.as_ref().map(|(i, _)| *i),
            removed: Vec::new(),
            relocated: Vec::new(),
            replaced: Vec::new(),
            placed: None,
            not_identifiable,
            pairs: judged.pairs,
        };
        let Some((i, next)) = best else {
            let t = std::time::Instant::now();
            let swapped = swap_accepted(
                setting,
                ranking.level(),
                &mut so_far,
                &mut round,
                &mut swap_tried,
                progress,
            );
            timing.swaps += t.elapsed().as_secs_f64();
            rounds.push(round);
            if swapped {
                rounds_left += 1;
                continue;
            }
            progress("nothing significant left");
            break;
        };
        progress(&format!("accepted: {}", refits[i].effect));
        let level = ranking.level();
        after_acceptance(
            setting,
            level,
            Chosen {
                refit: refits[i].clone(),
                next,
                contenders: &contenders,
            },
            &mut so_far,
            &mut round,
            progress,
        );
        rounds.push(round);
    }
    let mut d = final_fit(
        setting,
        so_far,
        Record {
            before,
            rounds,
            not_tried,
        },
        progress,
    )?;
    timing.other = clock.elapsed().as_secs_f64()
        - timing.base_fit
        - timing.ranking
        - timing.refits
        - timing.pairs
        - timing.swaps;
    d.timing = timing;
    d.base = base;
    Ok(d)
}

/// A round's ranking of every candidate at the current fit `cur` and its screen of the leading
/// ones; `labels` name the characteristics, the band starts at `f_lo`.
fn rank_and_screen(
    setting: Setting,
    cur: &Current,
    labels: &[String],
    f_lo: f64,
    not_tried: &mut Vec<NotTried>,
    progress: &mut dyn FnMut(&str),
) -> Result<(Ranking, Vec<Screened>), DiagnoseError> {
    let pc = setting.problem(cur.effects.clone());
    let band = (f_lo, setting.f_hi);
    let ranking = rank(&pc, cur, labels, band, setting.opts.alpha, not_tried)?;
    progress(&format!(
        "ranked {} candidates; best: {}",
        ranking.scored.len(),
        ranking
            .scored
            .first()
            .map(|s| ranking.candidates[s.candidate].describe())
            .unwrap_or_default()
    ));
    // The round's evaluations that change one candidate start from the current fit or, for a
    // fresh start, from the same with the variables at their initial values.
    let fresh = round::from_initial(&cur.u, setting.vars, &pc.scale);
    setting.solves.hold(&pc, &[cur.u.clone(), fresh]);
    let screened = screen_leading(setting, cur, &ranking);
    Ok((ranking, screened))
}

/// The diagnosis at the final fit: the residual analysis after, the accepted effects' values
/// and errors there (a later effect or a removal moved them), the final model.
fn final_fit(
    setting: Setting,
    Diagnosed { cur, mut accepted }: Diagnosed,
    Record {
        before,
        rounds,
        not_tried,
    }: Record,
    progress: &mut dyn FnMut(&str),
) -> Result<Diagnosis, DiagnoseError> {
    let Setting { opts, f_hi, .. } = setting;
    // A refit that stopped short but was accepted all the same is not "not tried".
    let not_tried: Vec<NotTried> = not_tried
        .into_iter()
        .filter(|n| {
            !accepted
                .iter()
                .chain(rounds.iter().flat_map(|r| {
                    let by = r.replaced.iter().map(|x| &x.by);
                    r.placed.iter().chain(&r.relocated).chain(by)
                }))
                .any(|a| n.effect == format!("refit of {}", a.effect) || n.effect == a.effect)
        })
        .collect();
    let pf = setting.problem(cur.effects.clone());
    let after = analysis(&pf, &cur, opts)?;
    progress(&format!("after: {}", after.verdict));
    // Effects refitted after their own round (a later effect, a removal) moved: report their
    // values and errors at the final fit, and the variables' errors there.
    let mut std_error = Vec::new();
    let mut correlation = Vec::new();
    if !cur.effects.is_empty() {
        let crit_scale = residual_scale(
            &cur,
            free_columns(&pf, &cur.u).len(),
            after.chi2_p.is_none(),
        );
        let finals = estimates(&pf, &cur, f_hi, crit_scale);
        for ((a, params), effect) in accepted.iter_mut().zip(finals).zip(&cur.effects) {
            let values: Vec<f64> = params.iter().map(|p| p.value).collect();
            let errors: Vec<f64> = params.iter().map(|p| p.std_error).collect();
            a.place = effect.fitted_place(&values, &errors);
            a.params = params;
        }
        std_error = variable_errors(&pf, &cur, crit_scale);
        correlation = variable_correlation(&pf, &cur);
    }
    let (x, gamma) = pf.split(&cur.u);
    let realized = pf.realize(&gamma)?;
    let mut final_model = realized.model;
    realized.vars.apply(&mut final_model, &x);
    let outside_library = outside_library(&after, accepted.len());
    Ok(Diagnosis {
        before,
        after,
        outside_library,
        rounds,
        accepted,
        not_tried,
        estimate: x,
        std_error,
        correlation,
        model: final_model,
        effects: cur.effects,
        timing: Timing::default(),
        units: JSON_UNITS,
        base: BaseFit {
            unit: "-",
            criterion_identification: f64::NAN,
            criterion: f64::NAN,
            converged: false,
            stop: String::new(),
            continuations: 0,
            starts: 0,
            iterations: 0,
        },
    })
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

/// A family member's refit is equivalent to the family's best when its LR's margin over its
/// critical value is within this of the best's (`indistinguishable`; for the same number of
/// parameters, their likelihood ratio against each other: χ² with 1 degree of freedom at 95 %):
/// the data cannot tell them apart.
pub const EQUIVALENT_LR: f64 = 3.84;

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

/// The Cramér-Rao correlation of the variables at `cur` (free of the noise scale and the
/// variables' scaling), as [`Diagnosis::correlation`].
fn variable_correlation(p: &Problem, cur: &Current) -> Vec<Vec<f64>> {
    let info = cur.jac.tr_mul(&cur.jac);
    let cov = info
        .clone()
        .try_inverse()
        .or_else(|| info.pseudo_inverse(1e-12).ok());
    let n = p.split(&cur.u).0.len();
    (0..n)
        .map(|i| {
            (0..n)
                .map(|j| match &cov {
                    Some(c) => {
                        let r = c[(i, j)] / (c[(i, i)] * c[(j, j)]).sqrt();
                        if r.is_finite() {
                            r.clamp(-1.0, 1.0)
                        } else {
                            f64::NAN
                        }
                    }
                    None => f64::NAN,
                })
                .collect()
        })
        .collect()
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

/// Fixtures of the crate's unit tests.
#[cfg(test)]
mod test_support {
    use std::path::{Path, PathBuf};

    /// A file of the repository (`rel` from the repository's root).
    pub fn repo_file(rel: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
    }

    /// The FWD-32J model (`configs/models/fwd32j.toml`).
    pub fn fwd32j() -> rfe::Model {
        rfe::modelfile::load(&repo_file("configs/models/fwd32j.toml"))
            .expect("configs/models/fwd32j.toml loads")
            .model
    }
}
