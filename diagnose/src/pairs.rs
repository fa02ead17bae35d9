//! Two effects judged together: the pair judgement of a round whose best single refit leaves the
//! misfit above the noise level.
//!
//! A round adds one effect, the most significant single refit. With two effects A and B in the
//! data, a look-alike C of neither can explain about as much as A alone, or more (it mimics
//! part of both), so C is accepted first and the next rounds, and the swaps, must undo it.
//! Judging the round's leading refits by the pair each makes with its best next effect tells
//! them apart: A with B explains the data, C with any partner less.
//!
//! What it does, only where the best single refit C leaves the misfit above the noise level (χ²
//! for the observations less the fit's parameters, at the diagnosis's level, against the gates'
//! level of `noise.rs`, as the escalation judges it):
//!
//! 1. C and the round's next significant refits by margin (their likelihood ratio over its
//!    critical value at the round's Bonferroni threshold), [`PAIR_FIRSTS`] in all, are the
//!    possible first effects;
//! 2. for each, the candidates are ranked by their score at its single refit's fit, as a round
//!    ranks them, and the [`PAIR_PARTNERS`] leading families' first members are refitted from
//!    that fit (every variable and both effects' parameters free, exploring the partner's
//!    starts as a round's leaders do); the lowest end is that first effect's pair. The partners
//!    are not limited to the round's own refits: with A in, B can rank first although alone it
//!    ranked far down;
//! 3. each pair's margin is its likelihood ratio against the fit the round started from, on
//!    both effects' parameters, over the critical value at the round's threshold. When the
//!    pair with the largest margin is not C's, its first effect takes C's place only if
//!    - the pair explains the data (its fit is not above the noise level, the same test). Where
//!      even the best pair leaves misfit, a third effect, or the place the relocation after
//!      acceptance finds for a point mass or resonator, can reorder the pairs: on the blind
//!      suite, switching there put a resonator on the wrong body or of the wrong kind first in
//!      three cases of 64 where the one-at-a-time loop, its relocation moving the effect to its
//!      own body, was right;
//!    - its margin stands above C's pair's by more than [`PAIR_LEVEL`] (an LR of 3.84: the data
//!      tell the two answers apart; C with its best next effect is where the one-at-a-time loop
//!      would go, or C alone where no partner of C could be refitted);
//!    - its partner is significant at the round's threshold, and the first effect's own single
//!      refit is acceptable as the round's (physical, identified, more than a partial fix).
//!
//!    The next round then ranks and refits with the first effect in, as any round does, and
//!    refits the chosen pair's partner among its leaders ([`Carried`]).
//!
//! Each first effect's pair is reported in the round's `pairs` (JSON, text and progress lines)
//! as a refit whose `effect` names both effects and whose `dof` and `params` are both effects'.
//!
//! Cost: [`PAIR_FIRSTS`] rankings and `PAIR_FIRSTS·PAIR_PARTNERS` refits (each partner's in
//! parallel) in a round whose best refit is above the noise level; nothing in a round that
//! reaches it (the FWD-32J demo's).

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
    /// That pair's partner and its fitted parameters (SI): the next round refits it among its
    /// leaders (see [`Carried`]).
    pub(super) partner: Option<Carried>,
}

/// The partner of the pair that chose a round's first effect, carried into the next round:
/// ranked at the accepted fit, the partner can stand below the next round's own leaders — a
/// spring along the excitation's direction that the first effect's refit made room for scores
/// below springs the joints can imitate —, and the round that follows refits it with them,
/// from where the pair left it.
#[derive(Debug, Clone)]
pub(super) struct Carried {
    /// The partner, as the ranking generated it.
    pub(super) effect: Effect,
    /// Its parameters in the pair's fit (SI).
    pub(super) values: Vec<f64>,
}

/// One first effect's best pair: the round's refit `first` (index), the pair as a refit, and
/// the partner's own refit from the first's fit.
struct Pair {
    first: usize,
    refit: Refit,
    partner: Refit,
    /// The partner as the pair's ranking generated it, and its values there.
    carried: Option<Carried>,
    /// Whether the pair's fit explains the data: not above the noise level.
    explains: bool,
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
        partner: None,
    };
    let Refitted {
        refits, fits, best, ..
    } = refitted;
    let Some(best) = *best else {
        return judged;
    };
    if !above_noise(setting, level, &fits[best]) {
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
            Ok(Some((refit, partner, next))) => {
                progress(&format!(
                    "pair {}: J {:.1} → {:.1}, LR = {:.1} ({} dof)",
                    refit.effect,
                    refit.criterion_before,
                    refit.criterion_after,
                    refit.lr,
                    refit.dof
                ));
                let carried = next.effects.last().map(|effect| Carried {
                    effect: effect.clone(),
                    values: partner.params.iter().map(|p| p.value).collect(),
                });
                pairs.push(Pair {
                    first,
                    refit,
                    partner,
                    carried,
                    explains: !above_noise(setting, level, &next),
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
    judged.partner = judged.first.and_then(|first| {
        pairs
            .iter()
            .filter(|p| p.first == first)
            .min_by(|a, b| a.refit.criterion_after.total_cmp(&b.refit.criterion_after))
            .and_then(|p| p.carried.clone())
    });
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
        if out.len() < PAIR_FIRSTS && !out.iter().any(|&j| refits[j].effect == refits[i].effect) {
            out.push(i);
        }
    }
    out
}

/// The best next effect with the single refit's fit `fit` in: every candidate ranked by its
/// score there (as a round does), the [`PAIR_PARTNERS`] leading families' first members refitted
/// from `fit` with every parameter free; the lowest end as the pair (a refit against `cur`, the
/// fit the round started from, on both effects' parameters) and the partner's own refit.
/// `None` when no partner could be refitted. The pair's fit is the third.
fn best_partner(
    setting: Setting,
    cur: &Current,
    fit: &Current,
    sigma2: f64,
) -> Result<Option<(Refit, Refit, Current)>, DiagnoseError> {
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
        refit(
            setting,
            fit,
            partners[k],
            &steps[k],
            Some(&steps[k]),
            sigma2,
        )
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
    pair.params = estimates(&setting.problem(next.effects.clone()), &next, f_hi, sigma2)
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
    Ok(Some((pair, partner, next)))
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
    // Only a pair that explains the data settles the first effect: where the best pair still
    // leaves misfit above the noise level, a third effect or a place the relocation after
    // acceptance finds can reorder the pairs, and the one-at-a-time loop's own steps judge
    // better.
    if winner.first == best || !winner.explains {
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
