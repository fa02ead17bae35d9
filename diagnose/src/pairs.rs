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
    critical, in_parallel, lowest_start, margin, partial_fix, unidentifiable, Refitted,
};
use super::tuning::{PAIR_CONTENDERS, PAIR_LEVEL};
use super::*;
use identify::stats::chi2_tail;

/// What the pair judgement decided in a round.
pub(super) struct Judged {
    /// The pairs refitted, as refits (both effects named, both effects' parameters).
    pub(super) pairs: Vec<Refit>,
    /// The round's refit to accept instead of its best single (index into its refits), when
    /// a pair without that single wins.
    pub(super) first: Option<usize>,
}

/// One refitted pair: the round's refits `members` (indices), its refit and fit.
struct Pair {
    members: (usize, usize),
    refit: Refit,
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
    let members = leading(refits, level.threshold);
    if members.len() < 2 {
        return judged;
    }
    let couples: Vec<(usize, usize)> = members
        .iter()
        .enumerate()
        .flat_map(|(k, &a)| members[k + 1..].iter().map(move |&b| (a, b)))
        .collect();
    progress(&format!(
        "the best refit leaves J {:.1}, above the noise level: refitting {} pairs of the {} leading refits jointly",
        refits[best].criterion_after,
        couples.len(),
        members.len()
    ));
    let ends = in_parallel(&couples, |&(a, b)| {
        refit_pair(setting, cur, (&fits[a], &fits[b]), level.sigma2)
    });
    let mut pairs: Vec<Pair> = Vec::new();
    for (&(a, b), end) in couples.iter().zip(ends) {
        match end {
            Ok(refit) => {
                progress(&format!(
                    "pair {}: J {:.1} → {:.1}, LR = {:.1} ({} dof)",
                    refit.effect, refit.criterion_before, refit.criterion_after, refit.lr, refit.dof
                ));
                pairs.push(Pair {
                    members: (a, b),
                    refit,
                });
            }
            Err(e) => progress(&format!(
                "pair {} + {}: not refitted ({e})",
                refits[a].effect, refits[b].effect
            )),
        }
    }
    judged.first = choose(setting, cur, level, refitted, &pairs, best);
    if let Some(first) = judged.first {
        progress(&format!(
            "pair judgement: adding {} first in place of {} (the pair without it explains the data better)",
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

/// The round's significant refits (indices into `refits`) with the largest margins over their
/// critical values at `threshold`, at most [`PAIR_CONTENDERS`], each effect once.
fn leading(refits: &[Refit], threshold: f64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..refits.len())
        .filter(|&i| refits[i].p_value < threshold)
        .collect();
    order.sort_by(|&a, &b| margin(&refits[b], threshold).total_cmp(&margin(&refits[a], threshold)));
    let mut out: Vec<usize> = Vec::new();
    for i in order {
        if out.len() < PAIR_CONTENDERS && !out.iter().any(|&j| refits[j].effect == refits[i].effect)
        {
            out.push(i);
        }
    }
    out
}

/// The pair's stronger member to accept in place of the round's best single `best`, when the
/// best pair does not hold it and passes the tests of the module doc; `None` otherwise.
fn choose(
    setting: Setting,
    cur: &Current,
    Level { sigma2, threshold }: Level,
    Refitted { refits, fits, .. }: &Refitted,
    pairs: &[Pair],
    best: usize,
) -> Option<usize> {
    let holds = |p: &Pair, i: usize| p.members.0 == i || p.members.1 == i;
    let m = |p: &Pair| margin(&p.refit, threshold);
    let winner = pairs.iter().max_by(|a, b| m(a).total_cmp(&m(b)))?;
    if holds(winner, best) {
        return None;
    }
    // Where the one-at-a-time loop would go: the best single with its best partner.
    let with_best = pairs
        .iter()
        .filter(|p| holds(p, best))
        .map(m)
        .fold(f64::NEG_INFINITY, f64::max);
    let rival = if with_best.is_finite() {
        with_best
    } else {
        margin(&refits[best], threshold)
    };
    if m(winner) - rival <= PAIR_LEVEL {
        return None;
    }
    let (a, b) = winner.members;
    let j_pair = winner.refit.criterion_after;
    // Each member is needed beside the other: the other's single refit against the pair.
    let needed = |without: usize, dropped: usize| {
        2.0 * (refits[without].criterion_after - j_pair) / sigma2
            > critical(refits[dropped].dof, threshold)
    };
    if !(needed(a, b) && needed(b, a)) {
        return None;
    }
    // Both members physical and identified in the pair fit.
    let f_hi = setting.f_hi;
    let effect = |i: usize| fits[i].effects.last();
    let (ea, eb) = (effect(a)?, effect(b)?);
    let qa = ea.params(f_hi).len();
    let (pa, pb) = winner.refit.params.split_at(qa.min(winner.refit.params.len()));
    if unidentifiable(&ea.params(f_hi), pa, f_hi, threshold).is_some()
        || unidentifiable(&eb.params(f_hi), pb, f_hi, threshold).is_some()
    {
        return None;
    }
    // The stronger member first, if it stands alone as the round would accept it.
    let mut order = [a, b];
    order.sort_by(|&x, &y| margin(&refits[y], threshold).total_cmp(&margin(&refits[x], threshold)));
    order.into_iter().find(|&i| {
        let own = fits[i].effects.last().map(|e| e.params(f_hi));
        own.is_some_and(|own| {
            unidentifiable(&own, &refits[i].params, f_hi, threshold).is_none()
                && partial_fix(&refits[i], cur, sigma2).is_none()
        })
    })
}

/// The joint refit of the two single refits' fits `(fa, fb)` (each the round's fit `cur` with
/// one more effect): both effects' parameters and every variable free, from each single's end
/// with the other's parameters at its own single refit's values or at its nested value,
/// whichever fits better; the lower end kept. Its
/// likelihood ratio is against `cur`, on both effects' parameters.
fn refit_pair(
    setting: Setting,
    cur: &Current,
    (fa, fb): (&Current, &Current),
    sigma2: f64,
) -> Result<Refit, RefitError> {
    let Setting {
        obs, opts, f_hi, ..
    } = setting;
    let n = cur.u.len();
    let (Some(ea), Some(eb)) = (fa.effects.last(), fb.effects.last()) else {
        return Err(RefitError::TooFewObservations {
            observations: cur.e.len(),
            parameters: n,
        });
    };
    let mut effects = cur.effects.clone();
    effects.extend([ea.clone(), eb.clone()]);
    let mut p = setting.problem(effects);
    let m = cur.e.len();
    if m <= p.scale.len() + 1 {
        return Err(RefitError::TooFewObservations {
            observations: m,
            parameters: p.scale.len(),
        });
    }
    let (ta, tb) = (&fa.u.as_slice()[n..], &fb.u.as_slice()[n..]);
    let join = |head: &[f64], a: &[f64], b: &[f64]| {
        DVector::from_iterator(
            head.len() + a.len() + b.len(),
            head.iter().chain(a).chain(b).copied(),
        )
    };
    // The other effect at its nested value: the single's own end, which the joint refit can
    // only improve on.
    let nested = |e: &Effect| -> Vec<f64> {
        e.params(f_hi).iter().map(|np| np.nested / np.scale).collect()
    };
    let (na, nb) = (nested(ea), nested(eb));
    let (ha, hb) = (&fa.u.as_slice()[..n], &fb.u.as_slice()[..n]);
    let starts = [
        [join(ha, ta, tb), join(ha, ta, &nb)],
        [join(hb, ta, tb), join(hb, &na, tb)],
    ];
    let (lo, hi) = p.bounds();
    let settings = opts.identification.settings;
    let mut best: Option<optimize::Outcome> = None;
    for from_end in starts {
        // A start the model cannot evaluate is skipped; the other may still be.
        let Some((j, u)) = lowest_start(&mut p, setting.solves, from_end) else {
            continue;
        };
        if !j.is_finite() {
            continue;
        }
        let end = optimize::minimize(
            opts.identification.optimizer,
            &mut p,
            &u,
            &lo,
            &hi,
            &settings,
            &mut |_| {},
        )?;
        if best.as_ref().is_none_or(|b| end.criterion < b.criterion) {
            best = Some(end);
        }
    }
    let Some(out) = best else {
        return Err(RefitError::TooFewObservations {
            observations: m,
            parameters: p.scale.len(),
        });
    };
    let (e, jac) = p.eval(&out.u, true)?;
    let jac = jac.ok_or(EvalError::NoJacobian)?;
    let q = ta.len() + tb.len();
    let j0 = 0.5 * cur.e.norm_squared();
    let j1 = 0.5 * e.norm_squared();
    let lr = (2.0 * (j0 - j1) / sigma2).max(0.0);
    // A resonator's LR is maximised over its tuning frequency too: its p-value counts them.
    let lines = obs.lines_hz();
    let searched = (ea.tunings_searched(&lines, f_hi) * eb.tunings_searched(&lines, f_hi)) as f64;
    let p_value = (chi2_tail(q as f64, lr) * searched).min(1.0);
    let next = Current {
        effects: p.effects.clone(),
        u: out.u,
        e,
        jac,
    };
    let mut all = estimates(&p, &next, f_hi, sigma2);
    let pb = all.pop().unwrap_or_default();
    let mut params = all.pop().unwrap_or_default();
    params.extend(pb);
    let crit = p.criterion(&p.realize(&p.split(&next.u).1)?)?;
    let n_obs = m as f64;
    Ok(Refit {
        effect: format!("{} + {}", ea.describe(), eb.describe()),
        kind: "pair".into(),
        criterion_before: j0,
        criterion_after: j1,
        rms_db_before: residuals::rms_db(&crit, &cur.e),
        rms_db_after: residuals::rms_db(&crit, &next.e),
        lr,
        dof: q,
        p_value,
        aic_change: -lr + 2.0 * q as f64,
        bic_change: -lr + q as f64 * n_obs.ln(),
        params,
        stop: out.stop.describe(),
        converged: out.stop.converged(),
        equivalent: Vec::new(),
        family: Vec::new(),
        place: None,
    })
}
