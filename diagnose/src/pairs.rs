//! Two effects judged together: the pair judgement of a round whose best single refit leaves the
//! misfit above the noise level.
//!
//! A round adds one effect, the most significant single refit. With two effects A and B in the
//! data, a look-alike C of neither can explain more than A or B alone (it mimics part of both),
//! so C is accepted first and the next rounds, and the swaps, must undo it. Judging the round's
//! leading refits in pairs tells the two apart: A with B explains the data, C with any partner
//! less.
//!
//! What it does, only where the best single refit C leaves the misfit above the noise level (χ²
//! at the diagnosis's level, the test the escalation uses):
//!
//! 1. the round's significant refits with the largest margins ([`PAIR_CONTENDERS`] of them, one
//!    per family: different places or kinds) are taken as the pair's possible members;
//! 2. every pair of them is refitted jointly — both effects' parameters and every variable free
//!    — from the two single refits' ends, each with the other effect's parameters at its own
//!    single refit's values or at its nested value, whichever fits better (the nested value is
//!    the single's end itself: a single refit's size can be far off where the effect only mimics
//!    the other one), the lower end kept;
//! 3. the pair with the largest margin of its likelihood ratio over its critical value (against
//!    the fit the round starts from, `dof` = both effects' parameters, at the round's Bonferroni
//!    threshold) wins. When it does not hold C, it replaces C as the round's choice only if
//!    - it stands above the best pair holding C by more than [`PAIR_LEVEL`] in that margin (the
//!      data tell the two answers apart; C with its best partner is where the one-at-a-time
//!      loop would go), or above C alone where no pair holding C could be refitted;
//!    - each member is needed beside the other: dropping either (the other's single refit
//!      against the pair) raises the criterion by more than the critical value of the dropped
//!      member's parameters at the round's threshold;
//!    - both members' estimates in the pair fit are physical and identified (the acceptance's
//!      own rule, [`unidentifiable`]);
//! 4. the winning pair's stronger member (larger margin alone) is accepted in C's place, if its
//!    single refit is acceptable on its own (physical, identified, more than a partial fix),
//!    else the other member. The next round then finds the other member with the first in the
//!    model, where the look-alike no longer explains more than it does.
//!
//! The pairs' refits are reported in the round's `pairs` (JSON and progress lines) as refits
//! whose `effect` names both effects and whose `dof` counts both effects' parameters.
//!
//! Cost: at most `PAIR_CONTENDERS·(PAIR_CONTENDERS−1)/2` pair refits of two starts each, in
//! parallel, in a round whose best refit is above the noise level — none on a round that reaches
//! it (the FWD-32J demo's).

use super::round::{
    in_parallel, margin, partial_fix, rank, refit, score_start, unidentifiable, Refitted,
};
use super::tuning::{PAIR_FIRSTS, PAIR_LEVEL, PAIR_PARTNERS};
use super::*;
use identify::stats::chi2_tail;

/// What the pair judgement decided in a round.
pub(super) struct Judged {
    /// Each first effect's best pair, as refits (both effects named, both effects' parameters,
    /// the likelihood ratio against the fit the round started from).
    pub(super) pairs: Vec<Refit>,
    /// The round's refit to accept instead of its best single (index into its refits), when
    /// another first effect's pair explains the data better.
    pub(super) first: Option<usize>,
}

/// One first effect's best pair: the round's refit `first` (index), the pair as a refit, and
/// the partner's own refit from the first's fit.
struct Pair {
    first: usize,
    refit: Refit,
    partner: Refit,
}

/// Judges the round's leading refits (`refitted`, from the fit `cur` at the round's `level`)
/// in pairs where its best single refit leaves the misfit above the noise level; see the module
/// doc.
pub(super) fn judge_pairs(
    setting: Setting,
    cur: &Current,
    level: Level,
    refitted: &Refitted,
    progress: &mut dyn FnMut(&str),
) -> Judged {
    let mut judged = Judged {
        pairs: Vec::new(),
        first: None,
    };
    let Refitted {
        refits, fits, best, ..
    } = refitted;
    let Some((best, best_fit)) = best.as_ref().map(|(b, f)| (*b, f)) else {
        return judged;
    };
    if !above_noise(setting, level, best_fit) {
        return judged;
    }
    let firsts = leading(refits, best, level.threshold);
    if firsts.len() < 2 {
        return judged;
    }
    progress(&format!(
        "the best refit leaves J {:.1}, above the noise level: judging the {} leading refits by their best next effect",
        refits[best].criterion_after,
        firsts.len()
    ));
    let mut pairs: Vec<Pair> = Vec::new();
    for &first in &firsts {
        match best_partner(setting, cur, &fits[first], level.sigma2) {
            Ok(Some((refit, partner))) => {
                progress(&format!(
                    "pair {}: J {:.1} → {:.1}, LR = {:.1} ({} dof)",
                    refit.effect, refit.criterion_before, refit.criterion_after, refit.lr, refit.dof
                ));
                pairs.push(Pair {
                    first,
                    refit,
                    partner,
                });
            }
            Ok(None) => {}
            Err(e) => progress(&format!(
                "pairs of {}: not refitted ({e})",
                refits[first].effect
            )),
        }
    }
    judged.first = choose(setting, cur, level, refitted, &pairs, best);
    if let Some(first) = judged.first {
        progress(&format!(
            "pair judgement: adding {} first in place of {} (with its best next effect it explains the data better)",
            refits[first].effect, refits[best].effect
        ));
    }
    judged.pairs = pairs.into_iter().map(|p| p.refit).collect();
    judged
}

/// Whether the fit `fit` leaves the misfit above the noise level: χ² for the observations less
/// its parameters at the diagnosis's level, judged against the gates' level (`noise.rs`), as
/// the escalation judges it.
fn above_noise(setting: Setting, level: Level, fit: &Current) -> bool {
    let m = fit.e.len();
    let gate = noise::gate_level(setting.data_noise, level.sigma2);
    let dof = m.saturating_sub(fit.u.len()).max(1) as f64;
    chi2_tail(dof, fit.e.norm_squared() / gate) < setting.opts.alpha
}

/// The round's best refit `best`, then its other significant refits with the largest margins
/// over their critical values at `threshold`: at most [`PAIR_FIRSTS`] (indices into `refits`),
/// each effect once.
fn leading(refits: &[Refit], best: usize, threshold: f64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..refits.len())
        .filter(|&i| i != best && refits[i].p_value < threshold)
        .collect();
    order.sort_by(|&a, &b| margin(&refits[b], threshold).total_cmp(&margin(&refits[a], threshold)));
    let mut out: Vec<usize> = vec![best];
    for i in order {
        if out.len() < PAIR_FIRSTS && !out.iter().any(|&j| refits[j].effect == refits[i].effect)
        {
            out.push(i);
        }
    }
    out
}

/// The best next effect with the single refit's fit `fit` in: every candidate ranked by its
/// score there (as a round does), the [`PAIR_PARTNERS`] leading families' first members refitted
/// from `fit` with every parameter free; the lowest end as the pair (a refit against `cur`, the
/// fit the round started from, on both effects' parameters) and the partner's own refit.
/// `None` when no partner could be refitted.
fn best_partner(
    setting: Setting,
    cur: &Current,
    fit: &Current,
    sigma2: f64,
) -> Result<Option<(Refit, Refit)>, DiagnoseError> {
    let Setting {
        obs, opts, f_hi, ..
    } = setting;
    let labels: Vec<String> = obs
        .characteristics
        .iter()
        .map(|c| c.label.clone())
        .collect();
    let band = (obs.band_hz().0, f_hi);
    let pc = setting.problem(fit.effects.clone());
    let ranking = rank(&pc, fit, &labels, band, opts.alpha, &mut Vec::new())?;
    let partners: Vec<&Effect> = ranking
        .families
        .iter()
        .take(PAIR_PARTNERS)
        .map(|f| &ranking.candidates[ranking.scored[f[0]].candidate])
        .collect();
    let steps: Vec<Vec<f64>> = ranking
        .families
        .iter()
        .take(PAIR_PARTNERS)
        .map(|f| {
            let s = &ranking.scored[f[0]];
            score_start(&ranking.candidates[s.candidate], s.step, f_hi)
        })
        .collect();
    let jobs: Vec<usize> = (0..partners.len()).collect();
    let ends = in_parallel(&jobs, |&k| {
        refit(setting, fit, partners[k], &steps[k], Some(&steps[k]), sigma2)
    });
    let Some((partner, next)) = ends
        .into_iter()
        .filter_map(Result::ok)
        .min_by(|a, b| a.0.criterion_after.total_cmp(&b.0.criterion_after))
    else {
        return Ok(None);
    };
    let mut pair = partner.clone();
    let described: Vec<String> = next
        .effects
        .iter()
        .skip(cur.effects.len())
        .map(Effect::describe)
        .collect();
    pair.effect = described.join(" + ");
    pair.kind = "pair".into();
    pair.criterion_before = 0.5 * cur.e.norm_squared();
    pair.lr = (2.0 * (pair.criterion_before - pair.criterion_after) / sigma2).max(0.0);
    pair.params = estimates(&pc_of(setting, &next), &next, f_hi, sigma2)
        .into_iter()
        .skip(cur.effects.len())
        .flatten()
        .collect();
    pair.dof = pair.params.len();
    pair.p_value = chi2_tail(pair.dof as f64, pair.lr).min(1.0);
    pair.aic_change = -pair.lr + 2.0 * pair.dof as f64;
    pair.bic_change = -pair.lr + pair.dof as f64 * (cur.e.len() as f64).ln();
    let crit = pc.criterion(&pc.realize(&pc.split(&fit.u).1)?)?;
    pair.rms_db_before = residuals::rms_db(&crit, &cur.e);
    Ok(Some((pair, partner)))
}

/// The problem of the fit `fit`'s effects.
fn pc_of<'a>(setting: Setting<'a>, fit: &Current) -> Problem<'a> {
    setting.problem(fit.effects.clone())
}

/// The first effect to accept in place of the round's best single `best`, when another first
/// effect's pair stands above the best single's own pair and passes the tests of the module
/// doc; `None` otherwise.
fn choose(
    setting: Setting,
    cur: &Current,
    Level { sigma2, threshold }: Level,
    Refitted { refits, fits, .. }: &Refitted,
    pairs: &[Pair],
    best: usize,
) -> Option<usize> {
    let m = |p: &Pair| margin(&p.refit, threshold);
    let winner = pairs.iter().max_by(|a, b| m(a).total_cmp(&m(b)))?;
    if winner.first == best {
        return None;
    }
    // Where the one-at-a-time loop would go: the best single with its best next effect, or the
    // best single alone where none could be refitted.
    let rival = pairs
        .iter()
        .find(|p| p.first == best)
        .map_or_else(|| margin(&refits[best], threshold), m);
    if m(winner) - rival <= PAIR_LEVEL {
        return None;
    }
    // The partner is significant beside the first effect, the first effect acceptable alone.
    let f_hi = setting.f_hi;
    let first = &refits[winner.first];
    let own = fits[winner.first].effects.last().map(|e| e.params(f_hi));
    let acceptable = own.is_some_and(|own| {
        unidentifiable(&own, &first.params, f_hi, threshold).is_none()
            && partial_fix(first, cur, sigma2).is_none()
    });
    (winner.partner.p_value < threshold && acceptable).then_some(winner.first)
}
