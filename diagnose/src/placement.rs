//! After an effect is accepted: a point mass or resonator moved to the body where it fits best
//! (and each earlier one, or an earlier spring, once the later effects are in), its place refined
//! (a point mass's position, a spring's line of action) and the backward check that drops an
//! earlier effect the new one made unnecessary.

use nalgebra::Vector3;

use super::round::{
    excess_removed, extended, in_parallel, look_alikes, refit, short_refit, unidentifiable,
    with_effect, Contender,
};
use super::tuning::{
    RELOCATIONS_REFITTED, RELOCATION_ITERATIONS, RELOCATION_MIN_SHARE, SPRING_RELOCATION_ITERATIONS,
};
use super::*;
use identify::stats::chi2_tail;

/// A fit without an effect (`base`) and with it (`fixed`, the effect last in its effects).
#[derive(Clone, Copy)]
pub(super) struct EffectFits<'a> {
    pub(super) base: &'a Current,
    pub(super) fixed: &'a Current,
}

/// The refit a round accepted, the fit with its effect, and every member refit the round could
/// have accepted (for the effect's look-alikes).
pub(super) struct Chosen<'a> {
    pub(super) refit: Refit,
    pub(super) next: Current,
    pub(super) contenders: &'a [Contender],
}

/// The steps after a round accepts the refit `chosen` (with its fit `next`) on the fit `cur`
/// with the effects `accepted` so far: a point mass or resonator moved to the body where it fits
/// best ([`relocate`]) and the effect's place refined ([`place`]), then added to `accepted` and
/// `cur` with the round's `contenders` the data cannot tell from it among its equivalents
/// ([`look_alikes`]); the earlier effects it made unnecessary dropped ([`remove_unneeded`]), and each earlier
/// point mass, resonator or spring moved where it fits best now ([`relocate_earlier`]). Each step
/// is recorded in `round`.
pub(super) fn after_acceptance(
    setting: Setting,
    level: Level,
    Chosen {
        refit: mut chosen,
        mut next,
        contenders,
    }: Chosen,
    so_far: &mut Diagnosed,
    round: &mut Round,
    progress: &mut dyn FnMut(&str),
) {
    let cur = &so_far.cur;
    let own = next.effects.last().cloned();
    // A spring is not moved here: see `relocate_earlier`.
    let places = own
        .as_ref()
        .map_or_else(Vec::new, |e| points(setting.model, e));
    // The family members the data cannot tell from the effect stand for its own place.
    let mut equivalent = std::mem::take(&mut chosen.equivalent);
    if let Some((moved, better)) = relocate(
        setting,
        level,
        EffectFits {
            base: cur,
            fixed: &next,
        },
        &places,
    ) {
        progress(&format!(
            "moved: {} → {} (J {:.1} → {:.1})",
            chosen.effect, moved.effect, chosen.criterion_after, moved.criterion_after
        ));
        round.relocated.push(moved.clone());
        (chosen, next) = (moved, better);
        equivalent.clear();
    }
    if let Some((placed, better)) = place(
        setting,
        level,
        EffectFits {
            base: cur,
            fixed: &next,
        },
        &chosen,
    ) {
        let params: Vec<String> = placed.params.iter().map(ParamEstimate::describe).collect();
        progress(&format!("placed: {}", params.join(", ")));
        round.placed = Some(placed.clone());
        (chosen, next) = (placed, better);
    }
    if let Some(own) = &own {
        let more = look_alikes(contenders, &chosen, own, &equivalent, level.threshold);
        equivalent.extend(more);
    }
    chosen.equivalent = equivalent;
    so_far.accepted.push(chosen);
    so_far.cur = next;
    remove_unneeded(setting, level, so_far, round, progress);
    relocate_earlier(setting, level, so_far, round, progress);
}

/// Backward elimination after an acceptance: drops, one at a time, every earlier effect the
/// later ones made unnecessary (recorded in `round.removed`).
fn remove_unneeded(
    setting: Setting,
    level: Level,
    Diagnosed { cur, accepted }: &mut Diagnosed,
    round: &mut Round,
    progress: &mut dyn FnMut(&str),
) {
    while let Some((k, r, next)) = backward(setting, level, cur) {
        progress(&format!(
            "removed: {} (no longer needed: LR = {:.1}, p = {:.2e})",
            r.effect, r.lr, r.p_value
        ));
        accepted.remove(k);
        round.removed.push(r);
        *cur = next;
    }
}

/// A point mass or resonator acts through the motion of the point it hangs on, and with a large
/// effect the score and the screen, both first-order statistics taken at the fit without it,
/// cannot tell which body's point that is: the same resonator on a dozen bodies' points scores
/// within 15 % (a large resonator on the overarm can be accepted on the knee, several times the
/// noise level above its refit on the overarm). So the effect last in `fixed`, at its fitted
/// values, is short-refitted
/// ([`RELOCATION_ITERATIONS`], [`SPRING_RELOCATION_ITERATIONS`] for a spring; the model's
/// variables free) from `base`, the fit without it, at each of `places` (with whether each is the
/// effect's own: [`points`], and for an earlier spring [`lines_of_action`]); those whose short
/// refit ends below its own place's ([`RELOCATIONS_REFITTED`] at most) are refitted in full, from
/// several starts, and the best replaces the effect when the data tell it from the effect's own
/// place (its likelihood ratio against `fixed` above [`EQUIVALENT_LR`]: among 65 places, the best
/// of those the data cannot tell apart would often be a wrong one) and its estimates are
/// identifiable. The moved refit and its fit (the effect last); `None` when there is nowhere else
/// to try, the effect is a [`partial`] fix or it stays where it is.
fn relocate(
    setting: Setting,
    Level { sigma2, threshold }: Level,
    EffectFits { base, fixed }: EffectFits,
    places: &[(Effect, bool)],
) -> Option<(Refit, Current)> {
    let f_hi = setting.f_hi;
    let effect = fixed.effects.last()?;
    // A partial fix is no guide to where the effect is.
    if places.len() < 2 || partial(base, fixed, sigma2) {
        return None;
    }
    let q = effect.params(f_hi).len();
    let gamma = setting.problem(fixed.effects.clone()).split(&fixed.u).1;
    let values = gamma[gamma.len() - q..].to_vec();
    // A placed spring's size and ψ start its candidates' (their place offsets are not theirs).
    let values_of = |cand: &Effect| values[..cand.params(f_hi).len().min(q)].to_vec();
    let max_iterations = match effect {
        Effect::Spring { .. } | Effect::PlacedSpring { .. } => SPRING_RELOCATION_ITERATIONS,
        _ => RELOCATION_ITERATIONS,
    };
    let short: Vec<Option<f64>> = in_parallel(places, |(cand, _)| {
        let mut p = extended(setting, base, cand);
        let params = cand.params(f_hi);
        let u0 = with_effect(&base.u, &params, &values_of(cand));
        short_refit(setting, &mut p, [u0], params.len(), max_iterations).map(|(j, _)| j)
    });
    let own_j = places
        .iter()
        .zip(&short)
        .find_map(|((_, own), j)| own.then_some(*j)?)
        .unwrap_or(f64::INFINITY);
    let mut better: Vec<(f64, &Effect)> = places
        .iter()
        .zip(short)
        .filter_map(|((cand, own), j)| j.filter(|j| !own && *j < own_j).map(|j| (j, cand)))
        .collect();
    better.sort_by(|a, b| a.0.total_cmp(&b.0));
    better.truncate(RELOCATIONS_REFITTED);
    let (r, next) = in_parallel(&better, |(_, cand)| {
        let start = values_of(cand);
        let (r, next) = refit(setting, base, cand, &start, Some(&start), sigma2).ok()?;
        let params = cand.params(f_hi);
        unidentifiable(&params, &r.params, f_hi, threshold)
            .is_none()
            .then_some((r, next))
    })
    .into_iter()
    .flatten()
    .min_by(|a, b| a.1.e.norm_squared().total_cmp(&b.1.e.norm_squared()))?;
    let lr = (fixed.e.norm_squared() - next.e.norm_squared()) / sigma2;
    (lr > EQUIVALENT_LR).then_some((r, next))
}

/// Whether the effect `fixed` adds to `base` removes less than [`RELOCATION_MIN_SHARE`] of
/// `base`'s misfit above the noise level (`J − σ̂²(m − p)/2`): a partial fix, whose best place
/// chases the rest of the misfit (a resonator standing in for a missing spring to the ground
/// fits better wherever it takes some other part of the misfit, and moving it there leads the
/// later rounds astray).
fn partial(base: &Current, fixed: &Current, sigma2: f64) -> bool {
    let j = |c: &Current| 0.5 * c.e.norm_squared();
    let dof = fixed.e.len().saturating_sub(fixed.u.len()) as f64;
    excess_removed((j(base), j(fixed)), dof, sigma2)
        .is_some_and(|share| share < RELOCATION_MIN_SHARE)
}

/// Where [`relocate`] tries `effect`, and whether each is its own place: a point mass or
/// resonator at every attachment point of every body ([`generate::attachment_points`]). Empty
/// for the other kinds.
fn points(model: &Model, effect: &Effect) -> Vec<(Effect, bool)> {
    match effect {
        Effect::Mass { body, point, .. } | Effect::Resonator { body, point, .. } => {
            let at = |b: &rfe::model::Body, p: Vector3<f64>| {
                let (body, scale) = (b.name.clone(), 0.01 * b.mass);
                match effect {
                    Effect::Resonator { freq_hz, .. } => Effect::Resonator {
                        body,
                        point: p,
                        freq_hz: *freq_hz,
                        tuning: [*freq_hz, *freq_hz],
                        scale,
                    },
                    _ => Effect::Mass {
                        body,
                        point: p,
                        scale,
                    },
                }
            };
            (0..model.bodies.len())
                .flat_map(|b| {
                    let host = &model.bodies[b];
                    generate::attachment_points(model, b)
                        .into_iter()
                        .map(move |p| {
                            (at(host, p), host.name == *body && (p - point).norm() < 1e-9)
                        })
                })
                .collect()
        }
        _ => Vec::new(),
    }
}

/// The backward check after an effect was added: an earlier effect may only have compensated for
/// what the new one explains (a first identification in a poor local minimum, a placement next to
/// the true one). Refits without each earlier effect and returns the first one the data no longer
/// need (LR p-value not below `threshold`), with the fit without it.
fn backward(
    setting: Setting,
    Level { sigma2, threshold }: Level,
    cur: &Current,
) -> Option<(usize, Removed, Current)> {
    let f_hi = setting.f_hi;
    for k in 0..cur.effects.len().saturating_sub(1) {
        let Some(without) = refitted_without(setting, cur, k) else {
            continue;
        };
        let q = cur.effects[k].params(f_hi).len();
        let lr = ((without.e.norm_squared() - cur.e.norm_squared()) / sigma2).max(0.0);
        let searched = cur.effects[k].tunings_searched(&setting.obs.lines_hz(), f_hi) as f64;
        let p_value = (chi2_tail(q as f64, lr) * searched).min(1.0);
        if p_value >= threshold {
            let r = Removed {
                effect: cur.effects[k].describe(),
                lr,
                p_value,
            };
            return Some((k, r, without));
        }
    }
    None
}

/// Where effect `k`'s parameters sit in the point `u` of fit `cur`.
fn param_range(cur: &Current, k: usize, f_hi: f64) -> std::ops::Range<usize> {
    let size = |e: &Effect| e.params(f_hi).len();
    let nx = cur.u.len() - cur.effects.iter().map(size).sum::<usize>();
    let start = nx + cur.effects[..k].iter().map(size).sum::<usize>();
    start..start + size(&cur.effects[k])
}

/// The fit `cur` refitted without its effect `k` (from `cur`'s point); `None` when the refit
/// fails.
pub(super) fn refitted_without(setting: Setting, cur: &Current, k: usize) -> Option<Current> {
    let opts = setting.opts;
    let skip = param_range(cur, k, setting.f_hi);
    let effects: Vec<Effect> = (0..cur.effects.len())
        .filter(|&j| j != k)
        .map(|j| cur.effects[j].clone())
        .collect();
    let u0 = DVector::from_iterator(
        cur.u.len() - skip.len(),
        (0..cur.u.len())
            .filter(|i| !skip.contains(i))
            .map(|i| cur.u[i]),
    );
    let mut p = setting.problem(effects);
    let (lo, hi) = p.bounds();
    let settings = &opts.identification.settings;
    let out = optimize::minimize(
        opts.identification.optimizer,
        &mut p,
        &u0,
        &lo,
        &hi,
        settings,
        &mut |_| {},
    )
    .ok()?;
    let Ok((e, Some(jac))) = p.eval(&out.u, true) else {
        return None;
    };
    Some(Current {
        effects: p.effects.clone(),
        u: out.u,
        e,
        jac,
    })
}

/// `cur` with its effects in the order `order` (indices into `cur.effects`): the variables
/// first, then each effect's parameters in the new order, in `u` and in the Jacobian's columns.
pub(super) fn reordered(cur: &Current, order: &[usize], f_hi: f64) -> Current {
    let nx = param_range(cur, 0, f_hi).start;
    let index: Vec<usize> = (0..nx)
        .chain(order.iter().flat_map(|&k| param_range(cur, k, f_hi)))
        .collect();
    Current {
        effects: order.iter().map(|&k| cur.effects[k].clone()).collect(),
        u: DVector::from_iterator(index.len(), index.iter().map(|&i| cur.u[i])),
        e: cur.e.clone(),
        jac: DMatrix::from_fn(cur.jac.nrows(), index.len(), |r, c| cur.jac[(r, index[c])]),
    }
}

/// `cur` with its last effect put back at index `k` (the others keep their order): an earlier
/// effect refitted last, as [`relocate_earlier`] and the swap refit it, returned to its place.
pub(super) fn put_back(cur: &Current, k: usize, f_hi: f64) -> Current {
    let n = cur.effects.len();
    let order: Vec<usize> = (0..k).chain([n - 1]).chain(k..n - 1).collect();
    reordered(cur, &order, f_hi)
}

/// Where [`relocate_earlier`] tries an earlier spring `effect`: the effect itself (its own
/// place) and every spring candidate along its direction, between every pair of bodies and to
/// the ground ([`generate::springs`]). Empty for the other kinds.
fn lines_of_action(model: &Model, effect: &Effect) -> Vec<(Effect, bool)> {
    let (direction, psi) = match effect {
        Effect::Spring { direction, psi, .. } => (direction, *psi),
        Effect::PlacedSpring { direction, .. } => (direction, 0.0),
        _ => return Vec::new(),
    };
    let others = generate::springs(model, psi).into_iter().filter(|cand| {
        matches!(cand, Effect::Spring { direction: d, .. } if d.dot(direction).abs() > 0.999)
            && cand != effect
    });
    std::iter::once((effect.clone(), true))
        .chain(others.map(|cand| (cand, false)))
        .collect()
}

/// Each earlier accepted point mass, resonator or spring moved where it fits best now that the
/// later effects are in (see [`relocate`], from the fit without it; a spring along its direction
/// to any pair of bodies, [`lines_of_action`]), its place then refined ([`place`]); a move
/// replaces it in place, in `accepted` and in `cur` (recorded in `round.relocated`). An effect
/// placed while another was missing is then put right: two neighbouring places can fit alike
/// while the other effect's misfit dominates, and once it is in, the data tell them apart
/// (by an LR well above the threshold, where the χ² test already passes).
///
/// A spring is moved only here, not when it is accepted: accepted while another effect is
/// missing, its best place chases that one too (a vertical spring to the ground under the table,
/// accepted while a sensor's gain error is still missing, fits better elsewhere then; moved at
/// acceptance it would stay there).
fn relocate_earlier(
    setting: Setting,
    level: Level,
    Diagnosed { cur, accepted }: &mut Diagnosed,
    round: &mut Round,
    progress: &mut dyn FnMut(&str),
) {
    let f_hi = setting.f_hi;
    let n = cur.effects.len();
    for (k, earlier) in accepted.iter_mut().enumerate().take(n.saturating_sub(1)) {
        let effect = &cur.effects[k];
        let places = [
            points(setting.model, effect),
            lines_of_action(setting.model, effect),
        ]
        .concat();
        if places.len() < 2 {
            continue;
        }
        let Some(base) = refitted_without(setting, cur, k) else {
            continue;
        };
        let last: Vec<usize> = (0..n).filter(|&j| j != k).chain([k]).collect();
        let fixed = reordered(cur, &last, f_hi);
        let Some((mut moved, mut next)) = relocate(
            setting,
            level,
            EffectFits {
                base: &base,
                fixed: &fixed,
            },
            &places,
        ) else {
            continue;
        };
        if let Some(placed) = place(
            setting,
            level,
            EffectFits {
                base: &base,
                fixed: &next,
            },
            &moved,
        ) {
            (moved, next) = placed;
        }
        progress(&format!(
            "moved: {} → {} (J {:.1} → {:.1}, the later effects in)",
            earlier.effect,
            moved.effect,
            0.5 * cur.e.norm_squared(),
            moved.criterion_after
        ));
        *cur = put_back(&next, k, f_hi);
        *earlier = moved.clone();
        round.relocated.push(moved);
    }
}

/// An accepted point mass or spring sits at the nearest candidate point, not where the effect
/// is: refit it with its place free too — a mass's position (±half the host body's largest
/// side), a spring's line of action across its direction (±half the largest side of the bodies
/// it joins) — from `base` (the fit before it was added), from several starting places. Kept
/// when the place parameters beat the round's threshold against the candidate placement `fixed`
/// (LR test).
pub(super) fn place(
    setting: Setting,
    Level { sigma2, threshold }: Level,
    EffectFits { base, fixed }: EffectFits,
    accepted: &Refit,
) -> Option<(Refit, Current)> {
    let Setting { model, f_hi, .. } = setting;
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
    let cand_params = cand.params(f_hi);
    // The starting places are refitted in parallel.
    let (r, next) = in_parallel(&offsets, |o| {
        let st: Vec<f64> = start.iter().chain(o).copied().collect();
        refit(setting, base, &cand, &st, None, sigma2).ok()
    })
    .into_iter()
    .flatten()
    .min_by(|a, b| a.1.e.norm_squared().total_cmp(&b.1.e.norm_squared()))?;
    let lr = ((fixed.e.norm_squared() - next.e.norm_squared()) / sigma2).max(0.0);
    let p = chi2_tail(dof, lr);
    // A place at the edge of its reach, or a size the data cannot tell from zero, is not a
    // placement: the candidate's stays.
    (p < threshold && unidentifiable(&cand_params, &r.params, f_hi, threshold).is_none())
        .then_some((r, next))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Effect `k` moved last and back is the fit it was: each effect's parameters travel with it
    /// in `u` and in the Jacobian's columns, the variables stay first.
    #[test]
    fn an_effect_moved_last_and_back_keeps_its_parameters() {
        let point = Vector3::new(0.1, 0.2, 0.3);
        let effects = vec![
            Effect::Resonator {
                body: "table".into(),
                point,
                freq_hz: 100.0,
                tuning: [80.0, 120.0],
                scale: 1.0,
            },
            Effect::Mass {
                body: "knee".into(),
                point,
                scale: 1.0,
            },
            Effect::Spring {
                bodies: [None, Some("column".into())],
                point,
                direction: Vector3::z(),
                psi: 0.3,
            },
        ];
        let f_hi = 500.0;
        let sizes: Vec<usize> = effects.iter().map(|e| e.params(f_hi).len()).collect();
        assert_eq!(sizes, [2, 1, 2]);
        // Two variables, then 2 + 1 + 2 effect parameters; column c of the Jacobian holds c.
        let n = 2 + 5;
        let cur = Current {
            effects,
            u: DVector::from_fn(n, |i, _| i as f64),
            e: DVector::from_element(3, 1.0),
            jac: DMatrix::from_fn(3, n, |_, c| c as f64),
        };
        assert_eq!(param_range(&cur, 0, f_hi), 2..4);
        assert_eq!(param_range(&cur, 2, f_hi), 5..7);
        // The resonator (effect 0) last: the variables, the mass, the spring, the resonator.
        let last = reordered(&cur, &[1, 2, 0], f_hi);
        let order: Vec<f64> = last.u.iter().copied().collect();
        assert_eq!(order, [0.0, 1.0, 4.0, 5.0, 6.0, 2.0, 3.0]);
        assert_eq!(last.jac.row(0).transpose(), last.u);
        assert!(matches!(last.effects[2], Effect::Resonator { .. }));
        // And back where it was, as `relocate_earlier` and the swap put a moved effect.
        let back = put_back(&last, 0, f_hi);
        assert_eq!(back.u, cur.u);
        assert_eq!(back.jac, cur.jac);
        assert_eq!(back.effects, cur.effects);
    }

    /// An earlier spring is tried again along its own direction between every pair of bodies and
    /// to the ground, its own place first (so a spring on the upper saddle can move to the face
    /// under the table), and never at its own place twice; other kinds have no lines of action.
    #[test]
    fn an_earlier_spring_is_tried_along_its_direction_on_every_pair_of_bodies() {
        let model = crate::test_support::fwd32j();
        let library = generate::springs(&model, 0.3);
        let spring = |body: &str, point: [f64; 3]| {
            library
                .iter()
                .find(|e| {
                    matches!(e, Effect::Spring { bodies, point: p, direction, .. }
                        if bodies == &[None, Some(body.to_string())]
                            && (p - Vector3::from(point)).norm() < 1e-3
                            && direction == &Vector3::z())
                })
                .unwrap_or_else(|| panic!("no vertical spring to the {body} at {point:?}"))
                .clone()
        };
        let own = spring("upper saddle", [0.3, 0.9, 0.78]);
        let places = lines_of_action(&model, &own);
        assert_eq!(places[0], (own.clone(), true));
        assert_eq!(places.iter().filter(|(e, _)| *e == own).count(), 1);
        assert!(places[1..].iter().all(|(_, is_own)| !is_own));
        let under_table = spring("table", [0.625, 0.9, 0.89]);
        assert!(places.contains(&(under_table, false)));
        let pairs: std::collections::BTreeSet<Vec<Option<&str>>> =
            places.iter().map(|(e, _)| e.site()).collect();
        let n = model.bodies.len();
        assert_eq!(
            pairs.len(),
            n + n * (n - 1) / 2,
            "to the ground and between every pair"
        );
        for (e, _) in &places {
            let Effect::Spring { direction, .. } = e else {
                panic!("{} is not a spring", e.describe());
            };
            assert!(
                (direction - Vector3::z()).norm() < 1e-12,
                "{}",
                e.describe()
            );
        }
        let mass = Effect::Mass {
            body: "table".into(),
            point: Vector3::zeros(),
            scale: 1.0,
        };
        assert!(lines_of_action(&model, &mass).is_empty());
    }
}
