//! Once no candidate is significant any more: each accepted effect tried against the effects of
//! other kinds that act on the same bodies, and replaced by the one the data prefer. Relocation
//! ([`super::placement`]) moves an effect to another place of its own kind; a look-alike of
//! another kind (a spring between the two bodies an SDE joins for that SDE's missing stiffness)
//! can only be put right by a swap.

use super::placement::{place, put_back, refitted_without, EffectFits};
use super::round::{
    add_new, critical, extended, fresh_start, in_parallel, margin, refit, short_refit, tied,
    unidentifiable, with_effect,
};
use super::tuning::{LOOK_ALIKE_WINDOW, SWAPS_REFITTED, SWAP_ITERATIONS, SWAP_LEVEL};
use super::*;

/// Each accepted effect not yet in `tried` (by description; each is then added to it) replaced,
/// when the data prefer it, by an effect of another kind on the same bodies
/// ([`generate::alternatives`]): from the fit without it (the other effects in), every
/// alternative gets a short refit ([`SWAP_ITERATIONS`], the model's variables free, from their
/// initial values); those ending below the accepted fit or just above it ([`LOOK_ALIKE_WINDOW`];
/// [`SWAPS_REFITTED`] at most) are refitted in full, and the best replaces the effect when its
/// likelihood ratio against the accepted fit is above [`EQUIVALENT_LR`] and its estimates are
/// identifiable at [`SWAP_LEVEL`]. Its place is then refined ([`place`]). When none replaces
/// it, those the data cannot tell from it join its equivalents.
/// A swap replaces the effect in place, in `accepted` and in `cur` (recorded in
/// `round.replaced`). Whether any effect was replaced.
///
/// The case it is for: an SDE's missing stiffness along one of its axes accepted as a spring
/// between the same two bodies, at the noise level; the SDE's direction itself was never
/// refitted in its round, and refitted it ends lower, with one parameter fewer.
pub(super) fn swap_accepted(
    setting: Setting,
    level: Level,
    Diagnosed { cur, accepted }: &mut Diagnosed,
    round: &mut Round,
    tried: &mut Vec<String>,
    progress: &mut dyn FnMut(&str),
) -> bool {
    let f_hi = setting.f_hi;
    let n = cur.effects.len();
    let mut swapped = false;
    for (k, earlier) in accepted.iter_mut().enumerate().take(n) {
        let effect = cur.effects[k].clone();
        if tried.contains(&effect.describe()) {
            continue;
        }
        tried.push(effect.describe());
        let alternatives = generate::alternatives(setting.model, setting.vars, &effect);
        if alternatives.is_empty() {
            continue;
        }
        let Some(base) = refitted_without(setting, cur, k) else {
            continue;
        };
        let (swap, alike) = best_alternative(
            setting,
            level,
            EffectFits {
                base: &base,
                fixed: cur,
            },
            k,
            &alternatives,
        );
        let Some((mut by, mut next)) = swap else {
            add_new(&mut earlier.equivalent, alike);
            continue;
        };
        if let Some(placed) = place(
            setting,
            level,
            EffectFits {
                base: &base,
                fixed: &next,
            },
            &by,
        ) {
            (by, next) = placed;
        }
        progress(&format!(
            "replaced: {} → {} (J {:.1} → {:.1}, an effect of another kind on the same bodies)",
            effect.describe(),
            by.effect,
            0.5 * cur.e.norm_squared(),
            by.criterion_after
        ));
        *cur = put_back(&next, k, f_hi);
        tried.push(cur.effects[k].describe());
        round.replaced.push(Replaced {
            effect: earlier.effect.clone(),
            by: by.clone(),
        });
        *earlier = by;
        swapped = true;
    }
    swapped
}

/// Of `alternatives`, each added to `base` (the accepted fit `fixed` without its effect `k`),
/// the one that fits best (see [`swap_accepted`]), with its fit (the alternative last); `None`
/// when none beats `fixed` by [`EQUIVALENT_LR`] with identifiable estimates. Then the
/// alternatives refitted in full, identifiable, that the data cannot tell from effect `k`: their
/// LR's margins over their critical values at the round's threshold, both from `base`, within
/// [`EQUIVALENT_LR`] (as [`super::round::look_alikes`]).
fn best_alternative(
    setting: Setting,
    Level { sigma2, threshold }: Level,
    EffectFits { base, fixed }: EffectFits,
    k: usize,
    alternatives: &[Effect],
) -> (Option<(Refit, Current)>, Vec<Effect>) {
    let Setting { vars, f_hi, .. } = setting;
    let short = in_parallel(alternatives, |cand| {
        let mut p = extended(setting, base, cand);
        let params = cand.params(f_hi);
        let initial: Vec<f64> = params.iter().map(|np| np.initial).collect();
        let u = fresh_start(
            &mut p,
            setting.solves,
            &with_effect(&base.u, &params, &initial),
            &params,
            vars,
        );
        short_refit(setting, &mut p, [u], params.len(), SWAP_ITERATIONS)
    });
    let fixed_j = 0.5 * fixed.e.norm_squared();
    let window = fixed_j + 0.5 * LOOK_ALIKE_WINDOW * sigma2;
    let mut better: Vec<(f64, Vec<f64>, &Effect)> = alternatives
        .iter()
        .zip(short)
        .filter_map(|(cand, end)| end.map(|(j, start)| (j, start, cand)))
        .filter(|(j, ..)| *j < window)
        .collect();
    better.sort_by(|a, b| a.0.total_cmp(&b.0));
    better.truncate(SWAPS_REFITTED);
    let refitted: Vec<(Refit, Current, &Effect)> = in_parallel(&better, |(_, start, cand)| {
        let (r, next) = refit(setting, base, cand, start, Some(start), sigma2).ok()?;
        let params = cand.params(f_hi);
        unidentifiable(&params, &r.params, f_hi, SWAP_LEVEL)
            .is_none()
            .then_some((r, next, *cand))
    })
    .into_iter()
    .flatten()
    .collect();
    let q = fixed.effects[k].params(f_hi).len();
    let fixed_margin =
        (base.e.norm_squared() - fixed.e.norm_squared()) / sigma2 - critical(q, threshold);
    let alike = refitted
        .iter()
        .filter(|(r, ..)| tied(margin(r, threshold), fixed_margin))
        .map(|(.., cand)| (*cand).clone())
        .collect();
    let best = refitted
        .into_iter()
        .min_by(|a, b| a.1.e.norm_squared().total_cmp(&b.1.e.norm_squared()))
        .map(|(r, next, _)| (r, next))
        .filter(|(_, next)| {
            (fixed.e.norm_squared() - next.e.norm_squared()) / sigma2 > EQUIVALENT_LR
        });
    (best, alike)
}
