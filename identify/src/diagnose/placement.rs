//! After an effect is accepted: its place refined (a point mass's position, a spring's line of
//! action) and the backward check that drops an earlier effect the new one made unnecessary.

use super::round::{in_parallel, refit, unidentifiable};
use super::*;

/// Backward elimination after an acceptance: drops, one at a time, every earlier effect the
/// later ones made unnecessary (recorded in `round.removed`).
pub(super) fn remove_unneeded(
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

/// The accepted refit with its location refined where that is significantly better (recorded
/// in `round.placed`), and the fit that goes with it.
pub(super) fn placed(
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
pub(super) fn backward(
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
        let searched = cur.effects[k].tunings_searched(&lines(obs), f_hi) as f64;
        let p_value = (residuals::chi2_tail(q as f64, lr) * searched).min(1.0);
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
pub(super) fn place(
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
    let cand_params = cand.params(f_hi);
    // The starting places are refitted in parallel.
    let (r, next) = in_parallel(&offsets, |o| {
        let st: Vec<f64> = start.iter().chain(o).copied().collect();
        refit(
            model,
            vars,
            obs,
            opts,
            base,
            &cand,
            (&st, None),
            f_hi,
            sigma2,
        )
        .ok()
    })
    .into_iter()
    .flatten()
    .min_by(|a, b| a.1.e.norm_squared().total_cmp(&b.1.e.norm_squared()))?;
    let lr = ((fixed.e.norm_squared() - next.e.norm_squared()) / sigma2).max(0.0);
    let p = residuals::chi2_tail(dof, lr);
    // A place at the edge of its reach, or a size the data cannot tell from zero, is not a
    // placement: the candidate's stays.
    (p < threshold && unidentifiable(&cand_params, &r.params, (f_hi, threshold)).is_none())
        .then_some((r, next))
}
