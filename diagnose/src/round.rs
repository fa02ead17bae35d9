//! One round of the closed loop: rank every candidate by its score ([`rank`]), screen the
//! leading ones by a finite step ([`screen_leading`]), refit the most promising families
//! ([`refit_leading`]), and choose the most significant effect that is physical and identifiable.
//!
//! `refit_leading` escalates while the misfit stays above the noise level: first the `--refit`
//! families the screen puts first and the score's leading ones; when the misfit is large and
//! their best refit leaves it above the noise level, the kind jobs ([`kind_jobs`]: the best
//! screened family of each kind they leave out, where its screen is significant); if still
//! above, short refits ([`short_refits`], [`Short::Leading`]) of the plausible candidates, the
//! strongest pulls the score rules out and every candidate of the kinds without a point, whose
//! families are refitted in full when they end below the best refit. Where the misfit is small
//! but above the noise level, the damping splits get the short refits ([`Short::DampingSplits`]).
//! The refits' starts and the equivalents ("≡") of the chosen one are also decided here.

use super::lowrank::Solves;
use super::tuning::{
    EQUIVALENT_COS, FRESH_REFIT_RUNGS, FRESH_SIZES_PER_DECADE, FRESH_SIZE_DECADES, LARGE_MISFIT,
    MEMBERS_REFITTED, MIN_EXCESS_SHARE, PULLED_PER_KIND, SCORE_FAMILIES_REFITTED, SCREENED,
    SCREENED_PER_KIND, SHORT_REFITS_PER_KIND, SHORT_REFIT_ITERATIONS, SHORT_REFIT_KEPT,
    SHORT_REFIT_MIN_KEPT, SHORT_REFIT_RUNGS, SWAP_LEVEL,
};
use super::*;
use identify::stats::chi2_tail;

/// One round's candidates ranked by the score test at the current fit.
pub(super) struct Ranking {
    pub(super) candidates: Vec<Effect>,
    /// The scorable candidates, most significant first.
    pub(super) scored: Vec<score::Scored>,
    /// Families of near-identical candidates (indices into `scored`), representative first.
    pub(super) families: Vec<Vec<usize>>,
    /// The families as reported.
    pub(super) ranked: Vec<Ranked>,
    /// Bonferroni threshold of the round: α / candidates.
    pub(super) threshold: f64,
    /// σ̂² of the current fit.
    pub(super) sigma2: f64,
}

impl Ranking {
    /// The index in [`Ranking::families`] of the family holding scored candidate `j`, if any.
    fn family_index(&self, j: usize) -> Option<usize> {
        self.families.iter().position(|f| f.contains(&j))
    }

    /// The score p-value below which a candidate is plausible enough to screen or refit: 1000×
    /// the LR's threshold (the score and LR statistics agree for small effects and the score
    /// understates large ones, so the loose gate loses nothing).
    fn plausible(&self) -> f64 {
        (1000.0 * self.threshold).min(1.0)
    }

    /// The round's noise level and significance threshold.
    pub(super) fn level(&self) -> Level {
        Level {
            sigma2: self.sigma2,
            threshold: self.threshold,
        }
    }
}

/// Generates the candidates on the current fit of `pc` and ranks them at family-wise level
/// `alpha`; those that cannot be scored go to `not_tried`.
pub(super) fn rank(
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
    // Candidates live on the structure's bodies and SDEs, not on the masses, resonators,
    // springs and split joints the diagnosis added itself; a characteristic whose gain is already a variable gets no gain candidate.
    let mut candidates: Vec<Effect> = generate::candidates(
        &crit.model_at(&x),
        &realized.vars,
        &x,
        labels,
        f_lo,
        f_hi,
    )
    .into_iter()
    .filter(|c| c.on_structure(pc.base()))
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
    for (c, s) in candidates.iter_mut().zip(scores) {
        match s {
            Ok(s) => {
                // A resonator stands at the tuning frequency its score found.
                if let (Effect::Resonator { freq_hz, .. }, Some(f)) = (&mut *c, s.tuned_hz) {
                    *freq_hz = f;
                }
                scored.push(s);
            }
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
                family: f
                    .iter()
                    .map(|&j| candidates[scored[j].candidate].clone())
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

/// What a round's refits found.
pub(super) struct Refitted {
    /// The refit that stands for each family refitted.
    pub(super) refits: Vec<Refit>,
    /// The most significant of them that passes the round's threshold and is physical (index
    /// into `refits` and `fits`).
    pub(super) best: Option<usize>,
    /// The significant ones that were not physical or identifiable, and why.
    pub(super) not_identifiable: Vec<NotTried>,
    /// Every member refit the round could have accepted.
    pub(super) contenders: Vec<Contender>,
    /// The fit each of `refits` ended at, in the same order (the pair judgement starts from them).
    pub(super) fits: Vec<Current>,
}

/// What a round refits: the ranking, the leading candidates' screens, and the partner a pair
/// chose in the round before, if any.
#[derive(Clone, Copy)]
pub(super) struct Leading<'a> {
    pub(super) ranking: &'a Ranking,
    pub(super) screened: &'a [Screened],
    pub(super) carried: Option<&'a super::pairs::Carried>,
}

/// The families refitted and their members' refits (`outcomes[f]` for `jobs[f]`).
struct Escalation<'r> {
    jobs: Vec<Job<'r>>,
    outcomes: Vec<Vec<MemberRefit>>,
}

/// Refits the leading families (up to `opts.refit`) whose score makes them plausible: every
/// refit, the most significant one that passes the round's threshold with its fit, and the
/// others it could have accepted.
pub(super) fn refit_leading(
    setting: Setting,
    cur: &Current,
    leading: Leading,
    not_tried: &mut Vec<NotTried>,
    progress: &mut dyn FnMut(&str),
) -> Refitted {
    let escalation = escalate(setting, cur, leading, progress);
    judge_families(setting, cur, leading, escalation, not_tried, progress)
}

/// The refits of the leading families, escalated while the fit stays above the noise level (χ²
/// at the diagnosis's level): when the misfit is large and their best refit leaves it there,
/// the families of the kinds they leave out are refitted too (see [`kind_jobs`]), and if that
/// still leaves it there, those whose short refits went lower (see [`short_refits`]). When the
/// misfit is small but above the noise level, the joint-damping splits get short refits (see
/// [`Short::DampingSplits`]).
fn escalate<'r>(
    setting: Setting,
    cur: &Current,
    leading: Leading<'r>,
    progress: &mut dyn FnMut(&str),
) -> Escalation<'r> {
    let Setting { opts, f_hi, .. } = setting;
    let Leading {
        ranking,
        screened,
        carried,
    } = leading;
    let m = cur.e.len();
    // "Large" and "above the noise" are judged against R's level when it is known; when R is
    // known only up to scale (σ̂² would make every reduced χ² 1), against the data's own noise
    // level times the floor a real structure's model leaves above it (`noise.rs`).
    let gate = noise::gate_level(setting.data_noise, ranking.sigma2);
    let large = cur.e.norm_squared() / gate > LARGE_MISFIT * m as f64;
    let base_j = 0.5 * cur.e.norm_squared();
    let mut jobs = refit_jobs(ranking, screened, opts.refit, f_hi);
    if let Some(job) = carried_job(ranking, screened, &jobs, carried, f_hi) {
        progress(&format!(
            "refitting the partner the last round's pair judgement chose: {}",
            job.members[0].effect.describe()
        ));
        jobs.push(job);
    }
    let run = |jobs: &[Job]| run_jobs(setting, cur, jobs, large, ranking.sigma2);
    report_jobs(&jobs, screened, ranking, base_j, progress);
    let mut outcomes = run(&jobs);
    let least = |outcomes: &[Vec<MemberRefit>]| {
        outcomes
            .iter()
            .flatten()
            .filter_map(|(_, r)| r.as_ref().ok())
            .map(|(r, _)| r.criterion_after)
            .fold(base_j, f64::min)
    };
    // The noise level of a refit: χ² for the observations less the fit's parameters and the
    // candidate's size, as the verdict counts them. Counting all m observations would make the
    // test too lenient by p + 1 degrees of freedom: a refit at a reduced χ² near 1.5 can pass
    // for the noise level, the escalation below is skipped and a partial fix stands in for the
    // missing effect.
    let dof = m.saturating_sub(cur.u.len() + 1).max(1) as f64;
    let above_noise = |j: f64| chi2_tail(dof, 2.0 * j / gate) < opts.alpha;
    if large && above_noise(least(&outcomes)) {
        let more = kind_jobs(ranking, screened, &jobs, base_j, f_hi);
        let more = going_lower(setting, cur, more, least(&outcomes));
        if !more.is_empty() {
            progress(&format!(
                "the best refit leaves J {:.1}, above the noise level: refitting the best of {} kinds the leading families leave out",
                least(&outcomes),
                more.len()
            ));
            outcomes.extend(run(&more));
            jobs.extend(more);
        }
    }
    let least = least(&outcomes);
    let short = if large && above_noise(least) {
        Some(Short::Leading)
    } else if !large && above_noise(base_j) {
        Some(Short::DampingSplits)
    } else {
        None
    };
    if let Some(short) = short {
        let refined = short_refits(setting, cur, ranking, screened, &jobs, short);
        let more = refined_jobs(ranking, screened, &refined, &jobs, opts.refit, least, f_hi);
        if !more.is_empty() {
            progress(&format!(
                "the best refit still leaves J {least:.1}: refitting {} families whose short refits went lower",
                more.len()
            ));
            outcomes.extend(run(&more));
            jobs.extend(more);
        }
    }
    Escalation { jobs, outcomes }
}

/// Refits every member of `jobs` that is not a mirror image of another, in parallel; a large
/// misfit lets each family's first member explore further starts (see [`refit_member`]).
fn run_jobs(
    setting: Setting,
    cur: &Current,
    jobs: &[Job],
    large: bool,
    sigma2: f64,
) -> Vec<Vec<MemberRefit>> {
    let distinct: Vec<(usize, usize)> = jobs
        .iter()
        .enumerate()
        .flat_map(|(f, job)| {
            job.members
                .iter()
                .enumerate()
                .filter(|(_, m)| m.mirror_of.is_none())
                .map(move |(i, _)| (f, i))
        })
        .collect();
    let results = in_parallel(&distinct, |&(f, i)| {
        refit_member(setting, cur, &jobs[f].members[i], large && i == 0, sigma2)
    });
    let mut outcomes: Vec<Vec<MemberRefit>> = jobs.iter().map(|_| Vec::new()).collect();
    for ((f, i), r) in distinct.into_iter().zip(results) {
        outcomes[f].push((i, r));
    }
    outcomes
}

/// Each family's best refit stands for it, with the members the data cannot tell from it as
/// its equivalents; the most significant one that passes the round's threshold and is
/// identifiable and more than a partial fix is the round's best.
fn judge_families(
    setting: Setting,
    cur: &Current,
    Leading { ranking, .. }: Leading,
    Escalation { jobs, mut outcomes }: Escalation,
    not_tried: &mut Vec<NotTried>,
    progress: &mut dyn FnMut(&str),
) -> Refitted {
    let f_hi = setting.f_hi;
    let Ranking {
        threshold, sigma2, ..
    } = ranking;
    let mut refits: Vec<Refit> = Vec::new();
    let mut fits: Vec<Current> = Vec::new();
    let mut best: Option<usize> = None;
    let mut not_identifiable = Vec::new();
    let mut contenders = Vec::new();
    for (f, Job { family, members }) in jobs.iter().enumerate() {
        let mut outcomes = std::mem::take(&mut outcomes[f]);
        contenders.extend(contenders_of(
            members,
            &outcomes,
            cur,
            (f_hi, ranking.level()),
        ));
        let Some(b) = best_member(members, &outcomes, f_hi, *threshold) else {
            if let Some((_, Err(reason))) = outcomes.first() {
                not_tried.push(NotTried {
                    effect: format!("refit of {}", members[0].effect.describe()),
                    reason: reason.to_string(),
                });
            }
            continue;
        };
        let (i, Ok((mut r, next))) = outcomes.swap_remove(b) else {
            continue;
        };
        let cand = members[i].effect;
        r.equivalent = equivalents(members, i, &r, &outcomes, *threshold);
        r.family = family_of(ranking, *family, members[0].effect);
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
            .is_none_or(|b| margin(&r, *threshold) > margin(&refits[*b], *threshold));
        let why = unidentifiable(&cand.params(f_hi), &r.params, f_hi, *threshold)
            .or_else(|| partial_fix(&r, cur, *sigma2));
        if r.p_value < *threshold {
            match why {
                None if better => best = Some(refits.len()),
                None => {}
                Some(reason) => {
                    progress(&format!("indicated but not added: {} ({reason})", r.effect));
                    not_identifiable.push(NotTried {
                        effect: r.effect.clone(),
                        reason,
                    });
                }
            }
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
        fits.push(next);
    }
    Refitted {
        refits,
        best,
        not_identifiable,
        contenders,
        fits,
    }
}

/// The member refits of one family (`outcomes`, from the fit `cur`) the round could accept,
/// each with its mirror images (see [`Contender`]).
fn contenders_of(
    members: &[Member],
    outcomes: &[MemberRefit],
    cur: &Current,
    (f_hi, Level { sigma2, threshold }): (f64, Level),
) -> Vec<Contender> {
    outcomes
        .iter()
        .filter_map(|(i, r)| Some((*i, &r.as_ref().ok()?.0)))
        .filter(|(i, r)| {
            let params = members[*i].effect.params(f_hi);
            r.p_value < threshold
                && unidentifiable(&params, &r.params, f_hi, SWAP_LEVEL).is_none()
                && partial_fix(r, cur, sigma2).is_none()
        })
        .map(|(i, r)| Contender {
            effects: members
                .iter()
                .enumerate()
                .filter(|(k, m)| *k == i || m.mirror_of == Some(i))
                .map(|(_, m)| m.effect.clone())
                .collect(),
            margin: margin(r, threshold),
        })
        .collect()
}

/// One candidate's finite-step screen.
pub(super) struct Screened {
    /// Index into the ranking's scored candidates.
    pub(super) index: usize,
    /// The screened criterion J.
    pub(super) criterion: f64,
    /// The effect's parameters (SI) where it is least: the refit's start.
    pub(super) start: Vec<f64>,
}

/// The finite-step screen (see [`screen`]) of the leading candidates: up to [`SCREENED`] of
/// those whose score makes them plausible ([`Ranking::plausible`]: the gate saves the work
/// when there is nothing to find). `(index into ranking.scored, screened criterion J, the
/// effect's parameters there (SI))`, best (lowest J) first; candidates that cannot be evaluated
/// are left out.
pub(super) fn screen_leading(setting: Setting, cur: &Current, ranking: &Ranking) -> Vec<Screened> {
    let f_hi = setting.f_hi;
    let leading = leading_of_each_kind(ranking, SCREENED_PER_KIND);
    if leading.is_empty() {
        return Vec::new();
    }
    let pc = setting.problem(cur.effects.clone());
    let free = free_columns(&pc, &cur.u);
    let jfree = DMatrix::from_fn(cur.jac.nrows(), free.len(), |r, c| cur.jac[(r, free[c])]);
    let basis = score::orthonormal_columns(&jfree);
    let shared = setting.solves.at(&pc, &cur.u);
    let results = in_parallel(&leading, |&j| {
        let s = &ranking.scored[j];
        let cand = &ranking.candidates[s.candidate];
        let mut p = extended(setting, cur, cand);
        let params = cand.params(f_hi);
        let starts = screen::size_starts(&params, &score_start(cand, s.step, f_hi));
        let resonator = matches!(cand, Effect::Resonator { .. });
        screen::screen(
            &mut p,
            shared.as_deref(),
            &cur.u,
            &basis,
            &starts,
            resonator,
        )
        .map(|(criterion, start)| Screened {
            index: j,
            criterion,
            start,
        })
    });
    lowest_first(results)
}

/// The screens or short refits that ended, lowest criterion first.
pub(super) fn lowest_first(results: Vec<Option<Screened>>) -> Vec<Screened> {
    let mut out: Vec<Screened> = results.into_iter().flatten().collect();
    out.sort_by(|a, b| a.criterion.total_cmp(&b.criterion));
    out
}

/// The problem of the current effects and `cand`: the fit extended by one candidate.
pub(super) fn extended<'a>(setting: Setting<'a>, cur: &Current, cand: &Effect) -> Problem<'a> {
    let mut effects = cur.effects.clone();
    effects.push(cand.clone());
    setting.problem(effects)
}

/// The candidates screened (indices into `ranking.scored`, best score first): the first
/// [`SCREENED`] plausible ones ([`Ranking::plausible`]), then those of each kind's first
/// `per_kind` distinct plausible scores that are not among them.
pub(super) fn leading_of_each_kind(ranking: &Ranking, per_kind: usize) -> Vec<usize> {
    let gate = ranking.plausible();
    let passing = (0..ranking.scored.len()).filter(|&j| ranking.scored[j].p_value < gate);
    let mut leading: Vec<usize> = passing.clone().take(SCREENED).collect();
    let kind = |j: usize| ranking.candidates[ranking.scored[j].candidate].kind();
    let mut distinct: Vec<(&str, f64)> = Vec::new();
    for j in passing {
        let score = (kind(j), ranking.scored[j].statistic);
        let seen = distinct.contains(&score);
        let of_kind = distinct.iter().filter(|(k, _)| *k == score.0).count();
        if !seen && of_kind < per_kind {
            distinct.push(score);
            if !leading.contains(&j) {
                leading.push(j);
            }
        }
    }
    leading
}

/// The refits of one score family: its index in [`Ranking::families`] (`None` for a candidate
/// in none of the reported families) and the members refitted, the best-screened first.
pub(super) struct Job<'r> {
    pub(super) family: Option<usize>,
    pub(super) members: Vec<Member<'r>>,
}

/// A member of a refitted family: the effect, where its refit starts, and the member it is a
/// mirror image of, if any (see [`mirrors`]: the model's symmetry makes their refits equal, so
/// only one is refitted).
pub(super) struct Member<'r> {
    pub(super) effect: &'r Effect,
    pub(super) start: Vec<f64>,
    /// The effect's parameters (SI) at its score step: another start where the refit explores.
    pub(super) score_step: Vec<f64>,
    pub(super) mirror_of: Option<usize>,
}

/// A family member's refit: its index among the family's members, and the refit with its fit.
pub(super) type MemberRefit = (usize, Result<(Refit, Current), RefitError>);

/// Two screened candidates are mirror images: their screened criteria and parameters agree to
/// 1e-7. (Their score statistics are no guide: springs along z anywhere on a body that only
/// translates have the same slope at zero and very different finite effects.)
pub(super) fn mirrors(a: &Screened, b: &Screened) -> bool {
    let near = |x: f64, y: f64| (x - y).abs() <= 1e-7 * x.abs().max(y.abs()).max(1e-300);
    near(a.criterion, b.criterion) && a.start.iter().zip(&b.start).all(|(x, y)| near(*x, *y))
}

/// The refits of a round: up to `n` families, in the order of their best screened member, each
/// that member first (started where the screen left it) and then the family's other members
/// (from where the screen left them, or their score steps) in [`kinds_first`] order: the best of
/// each other kind always, then other sites and points up to [`MEMBERS_REFITTED`] distinct ones
/// in all, and their mirror images. The score's [`SCORE_FAMILIES_REFITTED`] leading families are
/// always among them.
pub(super) fn refit_jobs<'r>(
    ranking: &'r Ranking,
    screened: &[Screened],
    n: usize,
    f_hi: f64,
) -> Vec<Job<'r>> {
    let families = &ranking.families;
    let mut jobs = family_jobs(ranking, screened, screened, &[], n, f_hi);
    // The score's leading families are refitted too: the screen's first-order view of the fit's
    // own parameters can rank a large effect's true candidate below look-alikes (a moment
    // stiffness the score puts first can screen below springs to the ground that make a similar
    // moment), and a small effect's screen differs from its look-alikes' by less than the noise
    // (a difference in J of one or two), so the score's order is kept for its leaders.
    for (f, family) in families.iter().enumerate().take(SCORE_FAMILIES_REFITTED) {
        let leader = screened.iter().find(|s| family.contains(&s.index));
        if let Some(s) = leader.filter(|_| !jobs.iter().any(|job| job.family == Some(f))) {
            jobs.push(family_job(ranking, screened, s, Some(f), f_hi));
        }
    }
    jobs
}

/// The refit job of the partner a pair chose in the round before (`carried`), started from its
/// values in that pair, where no job of `jobs` holds its family. The partner is found among the
/// round's candidates by its description (a resonator retuned by this round's score is another
/// candidate, and is not carried).
pub(super) fn carried_job<'r>(
    ranking: &'r Ranking,
    screened: &[Screened],
    jobs: &[Job],
    carried: Option<&super::pairs::Carried>,
    f_hi: f64,
) -> Option<Job<'r>> {
    let carried = carried?;
    let described = carried.effect.describe();
    let index = (0..ranking.scored.len())
        .find(|&j| ranking.candidates[ranking.scored[j].candidate].describe() == described)?;
    let family = ranking.family_index(index);
    let held = jobs.iter().any(|job| {
        (family.is_some() && job.family == family)
            || job.members.iter().any(|m| m.effect.describe() == described)
    });
    let lead = Screened {
        index,
        criterion: f64::INFINITY,
        start: carried.values.clone(),
    };
    (!held).then(|| family_job(ranking, screened, &lead, family, f_hi))
}

/// The refits of the kinds the leading families' `jobs` leave out, for when the misfit was large
/// and their refits leave it above the noise level: of each such kind, the family of its
/// best-scored screened candidate, where that candidate's screen alone is significant against
/// the current criterion `base_j`.
///
/// The screen re-adjusts the fit's own variables to first order only, and a large effect of
/// one kind can screen far above its refit, below partial fixes of another kind (an isolator's
/// large missing moment stiffness screens barely below the fit without it while resonators
/// screen at a third of it; refitted, it alone reaches the noise level). Where the leading
/// families' refits bring the misfit down, these would only cost time.
pub(super) fn kind_jobs<'r>(
    ranking: &'r Ranking,
    screened: &[Screened],
    jobs: &[Job],
    base_j: f64,
    f_hi: f64,
) -> Vec<Job<'r>> {
    let significant = |s: &Screened, effect: &Effect| {
        let lr = 2.0 * (base_j - s.criterion) / ranking.sigma2;
        ChiSquared::new(effect.params(f_hi).len() as f64)
            .is_ok_and(|c| lr > c.inverse_cdf(1.0 - ranking.threshold))
    };
    let mut kinds: Vec<&str> = jobs
        .iter()
        .flat_map(|job| &job.members)
        .map(|m| m.effect.kind())
        .collect();
    let mut by_score: Vec<&Screened> = screened.iter().collect();
    by_score.sort_by_key(|s| s.index);
    let mut more = Vec::new();
    for s in by_score {
        let effect = &ranking.candidates[ranking.scored[s.index].candidate];
        if !kinds.contains(&effect.kind()) && significant(s, effect) {
            let job = family_job(ranking, screened, s, ranking.family_index(s.index), f_hi);
            kinds.extend(job.members.iter().map(|m| m.effect.kind()));
            more.push(job);
        }
    }
    more
}

/// The `jobs` whose leading member's short refit (from its screen's start and from the
/// variables' initial values, [`SHORT_REFIT_ITERATIONS`] at most) goes below `least`, the best
/// refit so far: a kind job only matters if it explains more than the leading families, and a
/// short refit that cannot get below them tells that at a fraction of a full refit's cost (its
/// several starts, each to convergence), which on large models is most of a round.
fn going_lower<'r>(
    setting: Setting,
    cur: &Current,
    jobs: Vec<Job<'r>>,
    least: f64,
) -> Vec<Job<'r>> {
    let ends = in_parallel(&jobs, |job| {
        let leader = job.members.first()?;
        short_refit_of(
            setting,
            cur,
            leader.effect,
            leader.start.clone(),
            None,
            true,
        )
        .map(|(criterion, _)| criterion)
    });
    jobs.into_iter()
        .zip(ends)
        .filter(|(_, end)| end.is_some_and(|j| j < least))
        .map(|(job, _)| job)
        .collect()
}

/// Each kind's `per_kind` candidates (the strongest pull first, [`score::Scored::pull`]) that a
/// one-sided score test rules out — its score would take a stiffness or a mass below its nested
/// value — though the data pull on them as hard as on a plausible one: a large effect can lower
/// J where a small one raises it: the fit's variables, moved to mimic the effect, make the first
/// step wrong-signed (an actuator's large missing lateral stiffness can score 0, last of a
/// thousand, while the data pull on it harder than on almost any other of its kind). Resonators are
/// left out: their score is taken at the tuning that lowers J most, which has no meaning where
/// none does.
pub(super) fn pulled_against(ranking: &Ranking, per_kind: usize) -> Vec<usize> {
    let gate = ranking.plausible();
    let mut against: Vec<usize> = (0..ranking.scored.len())
        .filter(|&j| {
            let s = &ranking.scored[j];
            s.statistic == 0.0 && s.tuned_hz.is_none() && chi2_tail(1.0, s.pull) < gate
        })
        .collect();
    against.sort_by(|&a, &b| ranking.scored[b].pull.total_cmp(&ranking.scored[a].pull));
    let kind = |j: usize| ranking.candidates[ranking.scored[j].candidate].kind();
    let mut taken: Vec<usize> = Vec::new();
    for j in against {
        if taken.iter().filter(|&&t| kind(t) == kind(j)).count() < per_kind {
            taken.push(j);
        }
    }
    taken
}

/// The candidates a round's short refits take (see [`short_refits`]).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Short {
    /// Where the misfit is large: the plausible candidates (the leading ones and each kind's
    /// first [`SHORT_REFITS_PER_KIND`] distinct scores), those the score rules out but the
    /// data pull on hardest ([`pulled_against`]) and every candidate of the kinds that have no
    /// point ([`unplaced`]), each also from the variables' initial values.
    Leading,
    /// Where the misfit is small but above the noise level: every joint-damping split, from
    /// the current fit only. A joint's own ψ several times its group's changes the resonance
    /// peaks far from linearly, and its score and screen, taken at the group's value, see
    /// little of it (a slideway's ψ several times its group's can score in the hundreds and
    /// screen within a few units of J of the fit without it, yet refit to the noise level). A
    /// model has few splits (about a dozen on FWD-32J), so refitting them all is cheap.
    DampingSplits,
}

/// Whether `effect` is of a kind with no point: an SDE's direction, a body's flexibility or
/// mass, a joint-damping split, a sensor's gain. There is one per element and axis (tens on
/// FWD-32J, against hundreds of springs, masses and resonators at points), and their scores are
/// no guide to a finite effect: the variables mimic their first-order action, not their finite
/// one (an actuator's missing lateral stiffness can score in the middle of a thousand
/// candidates, not plausible at first order, and still be the only effect whose refit reaches
/// the noise level).
pub(super) fn unplaced(effect: &Effect) -> bool {
    !matches!(
        effect,
        Effect::Spring { .. }
            | Effect::PlacedSpring { .. }
            | Effect::Mass { .. }
            | Effect::PlacedMass { .. }
            | Effect::Resonator { .. }
    )
}

/// The short refits of a round whose leading refits leave the misfit above the noise level:
/// the candidates `short` names that no refit job holds, each one's parameters and the fit's
/// variables fitted together for at most [`SHORT_REFIT_ITERATIONS`] iterations from the best of
/// the exploring starts (see [`screen::effect_starts`]), at the current fit and (for
/// [`Short::Leading`]) with the variables at their initial values ([`from_initial`]), the runs
/// from each kind of start thinned by successive halving where there are many ([`halve`]). The
/// lower criterion reached and the effect's parameters there, lowest first.
///
/// The screen moves the fit's variables to first order only, and a large effect can need them to
/// move far: an actuator's missing lateral stiffness (5.3 N/µm on FWD-32J, scored 238th) screens
/// at J 524 against 589 before, far above partial fixes at 286, and refitted it ends at the noise
/// level, J 35, after 26 iterations, the first ten of which gain little.
pub(super) fn short_refits(
    setting: Setting,
    cur: &Current,
    ranking: &Ranking,
    screened: &[Screened],
    jobs: &[Job],
    short: Short,
) -> Vec<Screened> {
    let f_hi = setting.f_hi;
    let effect = |j: usize| &ranking.candidates[ranking.scored[j].candidate];
    let refitted = |j: usize| {
        jobs.iter()
            .flat_map(|job| &job.members)
            .any(|m| std::ptr::eq(m.effect, effect(j)))
    };
    let against = match short {
        Short::Leading => pulled_against(ranking, PULLED_PER_KIND),
        Short::DampingSplits => Vec::new(),
    };
    let todo: Vec<usize> = match short {
        Short::Leading => leading_of_each_kind(ranking, SHORT_REFITS_PER_KIND)
            .into_iter()
            .chain(against.iter().copied())
            .chain((0..ranking.scored.len()).filter(|&j| unplaced(effect(j))))
            .fold(Vec::new(), |mut todo, j| {
                if !todo.contains(&j) {
                    todo.push(j);
                }
                todo
            }),
        Short::DampingSplits => (0..ranking.scored.len())
            .filter(|&j| matches!(effect(j), Effect::Damping { .. }))
            .collect(),
    };
    let todo: Vec<usize> = todo.into_iter().filter(|&j| !refitted(j)).collect();
    let fresh = short == Short::Leading;
    let arms = in_parallel(&todo, |&j| {
        let cand = effect(j);
        let params = cand.params(f_hi);
        let step = score_start(cand, ranking.scored[j].step, f_hi);
        // A score ruling the effect out steps below its nested value: start from the sizes
        // explored around its initial value instead.
        let ruled_out = against.contains(&j);
        let given = match screened.iter().find(|s| s.index == j) {
            Some(s) => s.start.clone(),
            None if ruled_out => params.iter().map(|np| np.initial).collect(),
            None => step.clone(),
        };
        let extra = (!ruled_out).then_some(step);
        short_refit_starts(setting, cur, cand, given, extra, fresh)
            .into_iter()
            .map(move |u| Arm::at(j, u))
    });
    // The runs from the current fit and from the variables' initial values are ranked apart:
    // the latter start far above (the variables' own misfit) and take more iterations before
    // their order tells anything.
    let (from_fit, from_initial): (Vec<_>, Vec<_>) = arms
        .into_iter()
        .flat_map(|starts| starts.enumerate())
        .partition(|(k, _)| *k == 0);
    let arms: Vec<Arm> = [
        (from_fit, SHORT_REFIT_RUNGS),
        (from_initial, FRESH_REFIT_RUNGS),
    ]
    .into_iter()
    .flat_map(|(arms, rungs)| {
        let arms = arms.into_iter().map(|(_, arm)| arm).collect();
        halve(setting, cur, ranking, arms, &rungs)
    })
    .collect();
    let ends = todo.iter().map(|&j| {
        let arm = arms
            .iter()
            .filter(|a| a.index == j && a.criterion.is_finite())
            .min_by(|a, b| a.criterion.total_cmp(&b.criterion))?;
        let q = effect(j).params(f_hi).len();
        let (_, gamma) = extended(setting, cur, effect(j)).split(&arm.u);
        Some(Screened {
            index: j,
            criterion: arm.criterion,
            start: gamma[gamma.len() - q..].to_vec(),
        })
    });
    lowest_first(ends.collect())
}

/// One start of a candidate's short refit, run a rung at a time (see [`halve`]).
struct Arm {
    /// Index into the ranking's scored candidates.
    index: usize,
    /// The point reached (scaled: the fit's variables, then the effect's parameters).
    u: DVector<f64>,
    /// J at `u` (infinite until the first rung has evaluated it).
    criterion: f64,
    /// Levenberg-Marquardt iterations run so far.
    iterations: usize,
    /// The run converged, or cannot go on: it takes no more iterations.
    ended: bool,
}

impl Arm {
    /// Candidate `index`'s run from the start `u`, not yet evaluated.
    fn at(index: usize, u: DVector<f64>) -> Arm {
        Arm {
            index,
            u,
            criterion: f64::INFINITY,
            iterations: 0,
            ended: false,
        }
    }
}

/// Runs the short refits' `arms` by successive halving: while more than
/// [`SHORT_REFIT_MIN_KEPT`] are running, each runs on to the next rung's iterations (`rungs`,
/// in all) and only the lowest [`SHORT_REFIT_KEPT`] share of them (at least the minimum) goes
/// on; the rest then run to the last rung, [`SHORT_REFIT_ITERATIONS`]. An arm left behind keeps
/// the criterion it reached.
///
/// Where a large model makes hundreds of candidates (every SDE direction, body and joint group
/// is one), most explain nothing, and their criteria after a few iterations already put the
/// ones that end lowest among the lowest. Where they are fewer, the order after a few
/// iterations is a poor guide: near the noise level the candidates end within a few units of J
/// of each other along long curved paths (on FWD-32J the one that ended lowest of about 140
/// was 70th after 4 iterations), so every arm runs to the end in one run, as without halving.
fn halve(
    setting: Setting,
    cur: &Current,
    ranking: &Ranking,
    mut arms: Vec<Arm>,
    rungs: &[usize],
) -> Vec<Arm> {
    let run_to = |arms: &mut [Arm], running: &[usize], upto: usize| {
        let advanced = in_parallel(running, |&a| {
            let arm = &arms[a];
            let effect = &ranking.candidates[ranking.scored[arm.index].candidate];
            advance(setting, cur, effect, arm, upto)
        });
        for (&a, next) in running.iter().zip(advanced) {
            arms[a] = next;
        }
    };
    let mut running: Vec<usize> = (0..arms.len()).collect();
    let (&last, early) = rungs.split_last().unwrap_or((&SHORT_REFIT_ITERATIONS, &[]));
    for &upto in early {
        if running.len() <= SHORT_REFIT_MIN_KEPT {
            break;
        }
        run_to(&mut arms, &running, upto);
        let reached = running
            .iter()
            .filter(|&&a| !arms[a].ended)
            .map(|&a| (a, arms[a].criterion));
        running = going_on(reached.collect());
    }
    run_to(&mut arms, &running, last);
    arms
}

/// Of the arms still running (`(arm, criterion reached)`), those that go on to the next rung:
/// the lowest [`SHORT_REFIT_KEPT`] share, at least [`SHORT_REFIT_MIN_KEPT`], lowest first.
fn going_on(mut reached: Vec<(usize, f64)>) -> Vec<usize> {
    reached.sort_by(|a, b| a.1.total_cmp(&b.1));
    let kept = (reached.len() as f64 * SHORT_REFIT_KEPT).ceil() as usize;
    reached.truncate(kept.max(SHORT_REFIT_MIN_KEPT));
    reached.into_iter().map(|(a, _)| a).collect()
}

/// `arm` run on to `upto` iterations in all (the effect's problem built afresh, the
/// Levenberg-Marquardt damping started anew); an arm that cannot be evaluated ends where it
/// was, with an infinite criterion if it never was.
fn advance(setting: Setting, cur: &Current, effect: &Effect, arm: &Arm, upto: usize) -> Arm {
    let mut p = extended(setting, cur, effect);
    let fit = &setting.opts.identification;
    let settings = optimize::Settings {
        max_iterations: upto.saturating_sub(arm.iterations),
        ..fit.settings
    };
    let (lo, hi) = p.bounds();
    match optimize::minimize(
        fit.optimizer,
        &mut p,
        &arm.u,
        &lo,
        &hi,
        &settings,
        &mut |_| {},
    ) {
        Ok(out) => Arm {
            index: arm.index,
            ended: out.stop != optimize::StopReason::IterationLimit,
            iterations: arm.iterations + out.iterations,
            criterion: out.criterion,
            u: out.u,
        },
        Err(_) => Arm {
            index: arm.index,
            u: arm.u.clone(),
            criterion: arm.criterion,
            iterations: arm.iterations,
            ended: true,
        },
    }
}

/// The starts of `cand`'s short refit added to the fit `cur`: the best-fitting of its
/// parameters' starts around `given` (and at `extra`), and, when `fresh`, the one with the
/// variables at their initial values ([`fresh_start`]).
fn short_refit_starts(
    setting: Setting,
    cur: &Current,
    cand: &Effect,
    given: Vec<f64>,
    extra: Option<Vec<f64>>,
    fresh: bool,
) -> Vec<DVector<f64>> {
    let mut p = extended(setting, cur, cand);
    let params = cand.params(setting.f_hi);
    let mut starts = screen::effect_starts(&params, &given, true);
    starts.extend(extra);
    let starts = starts.iter().map(|x| with_effect(&cur.u, &params, x));
    let Some((_, u0)) = lowest_start(&mut p, setting.solves, starts) else {
        return Vec::new();
    };
    let fresh = fresh.then(|| fresh_start(&mut p, setting.solves, &u0, &params, setting.vars));
    std::iter::once(u0).chain(fresh).collect()
}

/// A short refit ([`SHORT_REFIT_ITERATIONS`] at most) of `cand` added to the fit `cur`: from the
/// best-fitting of its parameters' starts around `given` (and at `extra`), and, when `fresh`,
/// also from the variables' initial values. Its criterion and the effect's parameters where it
/// ended.
fn short_refit_of(
    setting: Setting,
    cur: &Current,
    cand: &Effect,
    given: Vec<f64>,
    extra: Option<Vec<f64>>,
    fresh: bool,
) -> Option<(f64, Vec<f64>)> {
    let starts = short_refit_starts(setting, cur, cand, given, extra, fresh);
    let mut p = extended(setting, cur, cand);
    let q = cand.params(setting.f_hi).len();
    short_refit(setting, &mut p, starts, q, SHORT_REFIT_ITERATIONS)
}

/// The refit jobs of the short refits `refined` that went below `least` (the best refit so
/// far): up to `n` families none of `jobs` holds, the lowest first, each led by its short
/// refit's candidate started where that refit ended (the other members from their screens in
/// `screened`).
pub(super) fn refined_jobs<'r>(
    ranking: &'r Ranking,
    screened: &[Screened],
    refined: &[Screened],
    jobs: &[Job],
    n: usize,
    least: f64,
    f_hi: f64,
) -> Vec<Job<'r>> {
    let below = refined.iter().filter(|s| s.criterion < least);
    family_jobs(ranking, screened, below, jobs, n, f_hi)
}

/// Up to `n` refit jobs (see [`family_job`]) led by `leads` in their order, one per family, none
/// of a family a job of `held` holds (a candidate in no family leads a job of its own).
pub(super) fn family_jobs<'r, 's>(
    ranking: &'r Ranking,
    screened: &[Screened],
    leads: impl IntoIterator<Item = &'s Screened>,
    held: &[Job],
    n: usize,
    f_hi: f64,
) -> Vec<Job<'r>> {
    let mut jobs: Vec<Job> = Vec::new();
    for s in leads {
        if jobs.len() == n {
            break;
        }
        let family = ranking.family_index(s.index);
        let holds = |job: &Job| family.is_some() && job.family == family;
        if held.iter().chain(&jobs).any(holds) {
            continue;
        }
        jobs.push(family_job(ranking, screened, s, family, f_hi));
    }
    jobs
}

/// Reports a round's screen and the refits it leads to.
pub(super) fn report_jobs(
    jobs: &[Job],
    screened: &[Screened],
    ranking: &Ranking,
    base_j: f64,
    progress: &mut dyn FnMut(&str),
) {
    let Some((best, first)) = screened
        .first()
        .zip(jobs.first().and_then(|job| job.members.first()))
    else {
        return;
    };
    progress(&format!(
        "screened {} candidates by a finite step; best: {} (J {base_j:.1} → {:.1}); refitting {} families ({} distinct members), first {}",
        screened.len(),
        ranking.candidates[ranking.scored[best.index].candidate].describe(),
        best.criterion,
        jobs.len(),
        jobs.iter()
            .flat_map(|job| &job.members)
            .filter(|m| m.mirror_of.is_none())
            .count(),
        first.effect.describe()
    ));
}

/// The refit job of family `family` (of [`Ranking::families`]; `None` for a candidate in none)
/// led by its screened member `lead`: the leader, each other kind's and site's best member
/// (see [`kinds_first`]) and more points up to [`MEMBERS_REFITTED`] distinct refits, mirror
/// images marked.
pub(super) fn family_job<'r>(
    ranking: &'r Ranking,
    screened: &[Screened],
    lead: &Screened,
    family: Option<usize>,
    f_hi: f64,
) -> Job<'r> {
    let Ranking {
        candidates,
        scored,
        families,
        ..
    } = ranking;
    let j = lead.index;
    let lead_effect = &candidates[scored[j].candidate];
    let mut members = vec![Member {
        effect: lead_effect,
        start: lead.start.clone(),
        score_step: score_start(lead_effect, scored[j].step, f_hi),
        mirror_of: None,
    }];
    // Each member's screen, where it was screened: mirror images are refitted once.
    let screen_of = |k: usize| screened.iter().find(|s| s.index == k);
    let mut shown: Vec<Option<&Screened>> = vec![Some(lead)];
    let mut refitted = 1;
    let (order, other_kinds) =
        kinds_first(j, family.map_or(&[], |f| families[f].as_slice()), |k| {
            &candidates[scored[k].candidate]
        });
    for (place, k) in order.into_iter().enumerate() {
        let c = &candidates[scored[k].candidate];
        let own = screen_of(k);
        let mirror_of = members.iter().zip(&shown).position(|(m, s)| {
            m.mirror_of.is_none()
                && m.effect.kind() == c.kind()
                && s.zip(own).is_some_and(|(a, b)| mirrors(a, b))
        });
        if mirror_of.is_none() {
            if refitted >= MEMBERS_REFITTED && place >= other_kinds {
                continue;
            }
            refitted += 1;
        }
        shown.push(own);
        members.push(Member {
            effect: c,
            start: own.map_or_else(|| score_start(c, scored[k].step, f_hi), |s| s.start.clone()),
            score_step: score_start(c, scored[k].step, f_hi),
            mirror_of,
        });
    }
    Job { family, members }
}

/// A family's members but its `leader` (indices, best score first) reordered: each other kind's
/// best member first, then each other site's best ([`Effect::site`]: the bodies a spring joins,
/// the body a resonator hangs on ...), then the rest, each group in score order. The score
/// cannot tell a family's members apart — an isolator's moment stiffness from a spring to the
/// ground making the same moment, a resonator on the table from one on the knee tuned alike — a
/// finite effect can, so each kind and site gets a refit before a second point of the same.
/// With the order, how many of its first members are the other kinds' best (none of them can
/// be a mirror image of an earlier member: mirrors are of one kind).
pub(super) fn kinds_first<'r>(
    leader: usize,
    family: &[usize],
    effect: impl Fn(usize) -> &'r Effect,
) -> (Vec<usize>, usize) {
    let site_of = |e: &'r Effect| (e.kind(), e.site());
    let mut sites = vec![site_of(effect(leader))];
    let mut groups: [Vec<usize>; 3] = Default::default();
    for &k in family.iter().filter(|&&k| k != leader) {
        let site = site_of(effect(k));
        let group = if sites.iter().all(|(kind, _)| *kind != site.0) {
            0
        } else if !sites.contains(&site) {
            1
        } else {
            2
        };
        sites.push(site);
        groups[group].push(k);
    }
    (groups.concat(), groups[0].len())
}

/// `f` over `jobs` on the machine's cores (scoped threads taking the next job in turn); the
/// results in the jobs' order.
pub(super) fn in_parallel<J: Sync, R: Send>(jobs: &[J], f: impl Fn(&J) -> R + Sync) -> Vec<R> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(jobs.len());
    if threads <= 1 {
        return jobs.iter().map(&f).collect();
    }
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<R>>> = Mutex::new((0..jobs.len()).map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(job) = jobs.get(i) else { break };
                let r = f(job);
                if let Ok(mut all) = results.lock() {
                    all[i] = Some(r);
                }
            });
        }
    });
    results
        .into_inner()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
        .into_iter()
        .flatten()
        .collect()
}

/// Refits one member of a family from where the screen left its parameters (or its score
/// step); with `explore` also from its score step and the other starts of [`refit`]. The caller
/// explores a family's leader (its best-screened member) when the misfit is large (reduced χ²
/// above [`LARGE_MISFIT`]): a large missing effect bends the fit's own variables, and the screen
/// adjusts them to first order only. The other members only refit: exploring them too doubled
/// the blind suite's time and changed 1 of its 200 verdicts.
pub(super) fn refit_member(
    setting: Setting,
    cur: &Current,
    member: &Member,
    explore: bool,
    sigma2: f64,
) -> Result<(Refit, Current), RefitError> {
    let step = explore.then_some(member.score_step.as_slice());
    refit(setting, cur, member.effect, &member.start, step, sigma2)
}

/// The family's refit that stands for it: the one whose likelihood ratio stands furthest above
/// its critical value at the round's `threshold` ([`margin`]: the lowest criterion among members
/// with as many parameters, the fewer parameters otherwise — an isolator's one moment stiffness
/// before a two-parameter spring that does as well); of members the data cannot tell from it
/// ([`EQUIVALENT_LR`]), one whose estimates are physical and identified is preferred. Index
/// into `outcomes`; `None` when no refit succeeded.
pub(super) fn best_member(
    members: &[Member],
    outcomes: &[MemberRefit],
    f_hi: f64,
    threshold: f64,
) -> Option<usize> {
    let ok = || {
        outcomes
            .iter()
            .enumerate()
            .filter_map(|(k, (i, r))| r.as_ref().ok().map(|(r, _)| (k, (*i, r))))
    };
    let m = |(_, r): (usize, &Refit)| margin(r, threshold);
    let (_, highest) = ok().max_by(|a, b| m(a.1).total_cmp(&m(b.1)))?;
    let unphysical = |(i, r): (usize, &Refit)| {
        unidentifiable(&members[i].effect.params(f_hi), &r.params, f_hi, threshold).is_some()
    };
    ok().filter(|(_, x)| indistinguishable(x.1, highest.1, threshold))
        .min_by(|a, b| {
            unphysical(a.1)
                .cmp(&unphysical(b.1))
                .then(m(b.1).total_cmp(&m(a.1)))
        })
        .map(|(k, _)| k)
}

/// Every member of the score family `family` (described), or `leader` alone when it is in none.
pub(super) fn family_of(ranking: &Ranking, family: Option<usize>, leader: &Effect) -> Vec<String> {
    let effect = |k: usize| ranking.candidates[ranking.scored[k].candidate].describe();
    family.map_or_else(
        || vec![leader.describe()],
        |f| ranking.families[f].iter().map(|&k| effect(k)).collect(),
    )
}

/// Whether refit `r` is one the data cannot tell from `best`: its likelihood ratio's margin
/// over its critical value ([`margin`]) is within [`EQUIVALENT_LR`] of the best's (for the same
/// number of parameters, their likelihood ratio against each other is below it).
pub(super) fn indistinguishable(r: &Refit, best: &Refit, threshold: f64) -> bool {
    margin(best, threshold) - margin(r, threshold) < EQUIVALENT_LR
}

/// The members of a family the data cannot tell from its best refit (member `best`): those whose
/// refit (in `others`) is [`indistinguishable`] from it, and the mirror images of those and of
/// the best.
pub(super) fn equivalents(
    members: &[Member],
    best: usize,
    refit: &Refit,
    others: &[MemberRefit],
    threshold: f64,
) -> Vec<Effect> {
    let tied: Vec<usize> = std::iter::once(best)
        .chain(others.iter().filter_map(|(i, r)| {
            r.as_ref()
                .ok()
                .filter(|(r, _)| indistinguishable(r, refit, threshold))
                .map(|_| *i)
        }))
        .collect();
    members
        .iter()
        .enumerate()
        .filter(|(i, m)| {
            *i != best && (tied.contains(i) || m.mirror_of.is_some_and(|o| tied.contains(&o)))
        })
        .map(|(_, m)| m.effect.clone())
        .collect()
}

/// A member refit of a round that the round itself could have accepted: significant at its
/// threshold, physical, not a partial fix, and its size identifiable at 95 % (the swap's level,
/// [`SWAP_LEVEL`], for the same reason: an effect ranked against one already
/// significant, and a very stiff spring's Cramér-Rao interval is wide although its LR is
/// large, so the round's Bonferroni level would leave out true look-alikes). When its margin is
/// within
/// [`EQUIVALENT_LR`] of the accepted effect's, the data cannot tell the two apart
/// ([`look_alikes`]).
pub(super) struct Contender {
    /// The refitted effect, then its mirror images.
    pub(super) effects: Vec<Effect>,
    /// Its likelihood ratio's margin over its critical value at the round's threshold
    /// ([`margin`]).
    pub(super) margin: f64,
}

/// The effects of `contenders` the data cannot tell from `chosen` (their margins within
/// [`EQUIVALENT_LR`] of its own; all are refits from the same fit), other than `chosen`'s own
/// and those in `listed`, in the order given.
pub(super) fn look_alikes(
    contenders: &[Contender],
    chosen: &Refit,
    own: &Effect,
    listed: &[Effect],
    threshold: f64,
) -> Vec<Effect> {
    let m = margin(chosen, threshold);
    let mut out: Vec<Effect> = Vec::new();
    let tied = contenders.iter().filter(|c| tied(c.margin, m));
    let others = tied
        .flat_map(|c| &c.effects)
        .filter(|e| *e != own && !listed.contains(e));
    add_new(&mut out, others.cloned());
    out
}

/// Whether two refits from the same fit, with LR margins `a` and `b` over their critical values
/// ([`margin`]), are ones the data cannot tell apart: the margins within [`EQUIVALENT_LR`],
/// either way.
pub(super) fn tied(a: f64, b: f64) -> bool {
    (a - b).abs() < EQUIVALENT_LR
}

/// Appends to `list` each of `effects` not in it yet, in order.
pub(super) fn add_new(list: &mut Vec<Effect>, effects: impl IntoIterator<Item = Effect>) {
    for e in effects {
        if !list.contains(&e) {
            list.push(e);
        }
    }
}

/// A refit's start for `cand`'s parameters: the first (its size) at the score's Gauss-Newton
/// `step` from its nested value, the others at their initial values.
pub(super) fn score_start(cand: &Effect, step: f64, f_hi: f64) -> Vec<f64> {
    cand.params(f_hi)
        .iter()
        .enumerate()
        .map(|(j, np)| if j == 0 { np.nested + step } else { np.initial })
        .collect()
}

/// Why a significant refit is only a partial fix, or `None`: an effect that removes less than
/// [`MIN_EXCESS_SHARE`] of the misfit above the noise level (`2J/σ² − m`) is significant because
/// the misfit is large, not because it is the effect the data lack — stacking such fixes hides an
/// effect outside the library instead of naming it.
pub(super) fn partial_fix(r: &Refit, cur: &Current, sigma2: f64) -> Option<String> {
    let dof = cur.e.len() as f64;
    let share = excess_removed((r.criterion_before, r.criterion_after), dof, sigma2)?;
    (share < MIN_EXCESS_SHARE).then(|| {
        format!(
            "removes only {:.0} % of the misfit above the noise level: a partial fix",
            100.0 * share
        )
    })
}

/// The share of the misfit above the noise level that going from criterion `before` to `after`
/// removes (`(J₀ − J₁)/(J₀ − σ̂²·dof/2)`, with `dof` the lines less what the noise level counts
/// as fitted); `None` when `before` is at or below the noise level (nothing to remove).
pub(super) fn excess_removed((before, after): (f64, f64), dof: f64, sigma2: f64) -> Option<f64> {
    let excess = before - 0.5 * sigma2 * dof;
    (excess > 0.0).then(|| (before - after) / excess)
}

/// Why an effect's refitted estimates `est` (of parameters `params`) do not make it a physical,
/// identified effect, or `None` when they do: every parameter away from its bounds (but the
/// nested bound of its size, and a ψ of zero), a tuning frequency within the measured band (top
/// `f_hi`, Hz: a resonator tuned above it shows the data no resonance, and within the band acts
/// as the point mass it carries), and the size parameter away from its nested value
/// by at least [`size_z`]`(threshold)` Cramér-Rao standard errors — its confidence interval at
/// the round's own significance level excludes the effect's absence, as its likelihood ratio
/// does. (On the blind suite every effect added with its size within 4.4 standard errors of
/// nothing at a 95 % interval — ten of them, one on clean data — was a wrong one.)
pub(super) fn unidentifiable(
    params: &[EffectParam],
    est: &[ParamEstimate],
    f_hi: f64,
    threshold: f64,
) -> Option<String> {
    let z_min = size_z(threshold);
    for (j, (np, pe)) in params.iter().zip(est).enumerate() {
        let v = pe.value;
        if np.unit == "Hz" && v > f_hi {
            return Some(format!(
                "{}: tuned above the band's top, {} Hz; the data show no resonance, only the mass",
                pe.describe(),
                rfe::display::sig(f_hi, 4)
            ));
        }
        let tol = 1e-3 * np.scale;
        let size = j == 0;
        let lower_hit = np.lower.is_finite()
            && v <= np.lower + tol
            && !(size && np.lower == np.nested)
            && np.lower != 0.0;
        let upper_hit = np.upper.is_finite() && v >= np.upper - tol;
        if lower_hit || upper_hit {
            let bound = ParamEstimate {
                value: if upper_hit { np.upper } else { np.lower },
                ..pe.clone()
            };
            let (b, _, u) = bound.display();
            let u = if u == "-" {
                String::new()
            } else {
                format!(" {u}")
            };
            return Some(format!(
                "{} at its {} bound {}{u}",
                pe.describe(),
                if upper_hit { "upper" } else { "lower" },
                rfe::display::sig(b, 4),
            ));
        }
        if size && !(pe.std_error.is_finite() && (v - np.nested).abs() > z_min * pe.std_error) {
            return Some(format!(
                "{}: within {z_min:.1} standard errors of {}, the round's significance level",
                pe.describe(),
                rfe::display::sig(np.nested, 4)
            ));
        }
    }
    None
}

/// The standard errors an effect's size must stand from its nested value: the two-sided normal
/// quantile at the round's significance level `threshold` (the LR test's, 1 degree of freedom),
/// and at least the 95 % interval's.
pub(super) fn size_z(threshold: f64) -> f64 {
    ChiSquared::new(1.0)
        .ok()
        .map(|c| c.inverse_cdf(1.0 - threshold.clamp(1e-300, 0.05)).sqrt())
        .filter(|z| z.is_finite())
        .map_or(Z95, |z| z.max(Z95))
}

/// How far a refit's LR exceeds the critical value of its test at `threshold`.
pub(super) fn margin(r: &Refit, threshold: f64) -> f64 {
    r.lr - critical(r.dof, threshold)
}

/// The critical value of an LR test on `dof` parameters at level `threshold`.
pub(super) fn critical(dof: usize, threshold: f64) -> f64 {
    ChiSquared::new(dof as f64)
        .map(|c| c.inverse_cdf(1.0 - threshold))
        .unwrap_or(f64::INFINITY)
}

/// Groups the ranked candidates (best first) into families of near-identical projected
/// directions; returns up to `n` families as indices into `ranked`, representative first.
pub(super) fn families(ranked: &[score::Scored], n: usize) -> Vec<Vec<usize>> {
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

/// Refits the current effects plus `cand` with every parameter free, from `start` (the new
/// parameters' values) or, with `explore` (the score step's values), from the best of the starts
/// around it (see `tuning::REFIT_START_FRACTIONS` and `tuning::REFIT_SIZE_DECADES`; a
/// resonator's tuning frequency also on a grid across its range, refined around the best), from
/// the score step and from a [`fresh_start`] too; the lowest end wins.
pub(super) fn refit(
    setting: Setting,
    cur: &Current,
    cand: &Effect,
    start: &[f64],
    explore: Option<&[f64]>,
    sigma2: f64,
) -> Result<(Refit, Current), RefitError> {
    let Setting {
        vars,
        obs,
        opts,
        f_hi,
        ..
    } = setting;
    let step = explore.filter(|step| *step != start);
    let explore = explore.is_some();
    let mut p = extended(setting, cur, cand);
    let new_params = cand.params(f_hi);
    let q = new_params.len();
    let m = cur.e.len();
    if m <= p.scale.len() + 1 {
        return Err(RefitError::TooFewObservations {
            observations: m,
            parameters: p.scale.len(),
        });
    }
    // Start: the current point, the new parameters at `start` or on the way there from their
    // nested values, whichever fits best: a score step far outside the linear range (a large
    // effect) must not start the refit in a worse valley than the current fit's.
    let (lo, hi) = p.bounds();
    // The given start itself (the first) is always refitted: the best-fitting start is a
    // better valley for a large effect but can be a worse one for a small effect (a start that
    // fits best before the refit is not the one that fits best after it). The better end wins.
    let start_at = |st: &[f64]| with_effect(&cur.u, &new_params, st);
    let starts: Vec<DVector<f64>> = screen::effect_starts(&new_params, start, explore)
        .iter()
        .map(|st| start_at(st))
        .collect();
    let given = starts.first().cloned();
    let (Some((j_start, mut u0)), Some(given)) =
        (lowest_start(&mut p, setting.solves, starts), given)
    else {
        return Err(RefitError::TooFewObservations {
            observations: m,
            parameters: p.scale.len(),
        });
    };
    if explore && matches!(cand, Effect::Resonator { .. }) {
        let mut objective = |u: &DVector<f64>| {
            p.eval(u, false)
                .map_or(f64::INFINITY, |(e, _)| e.norm_squared())
        };
        screen::tune_resonator(&mut objective, &mut u0, j_start, (&lo, &hi));
    }
    let settings = opts.identification.settings;
    let fresh = explore.then(|| fresh_start(&mut p, setting.solves, &u0, &new_params, vars));
    let mut starts = vec![u0.clone()];
    if given != u0 {
        starts.push(given);
    }
    // The score step is a start of its own: the screen's best size, where the fit's variables
    // moved to first order only, can lie in another valley than the effect's refit (a large
    // moment stiffness refitted from the screen's size can stop at the misfit it started from,
    // and from its score step reach the noise level).
    if let Some(step) = step {
        starts.push(start_at(step));
    }
    // A large missing effect bends the fit's own parameters to mimic it, and the refit can stay
    // in that valley: the variables' initial values are a start outside it.
    starts.extend(fresh);
    // The starts are minimized in parallel (a round refits a handful of members, the first of
    // each family from up to four starts: run one after the other they leave a core idle);
    // the first start's end stands unless another ends strictly lower.
    let ends = in_parallel(&starts, |u| {
        let mut p = extended(setting, cur, cand);
        optimize::minimize(
            opts.identification.optimizer,
            &mut p,
            u,
            &lo,
            &hi,
            &settings,
            &mut |_| {},
        )
    });
    let mut ends = ends.into_iter();
    // `starts` begins with `u0`: the first end is its.
    let Some(first) = ends.next() else {
        return Err(RefitError::TooFewObservations {
            observations: m,
            parameters: p.scale.len(),
        });
    };
    let mut out = first?;
    for other in ends.flatten() {
        if other.criterion < out.criterion {
            out = other;
        }
    }
    let (e, jac) = p.eval(&out.u, true)?;
    let jac = jac.ok_or(EvalError::NoJacobian)?;
    let j0 = 0.5 * cur.e.norm_squared();
    let j1 = 0.5 * e.norm_squared();
    let lr = (2.0 * (j0 - j1) / sigma2).max(0.0);
    // A resonator's LR is maximised over its tuning frequency too: its p-value counts them.
    let searched = cand.tunings_searched(&obs.lines_hz(), f_hi) as f64;
    let p_value = (chi2_tail(q as f64, lr) * searched).min(1.0);
    let n = m as f64;
    let stop = out.stop.describe();
    let next = Current {
        effects: p.effects.clone(),
        u: out.u,
        e,
        jac,
    };
    // Standard errors from the Fisher information at the refit (σ̂² scaled when R is unknown):
    // the new effect's are the last.
    let params = estimates(&p, &next, f_hi, sigma2).pop().unwrap_or_default();
    let crit = p.criterion(&p.realize(&p.split(&next.u).1)?)?;
    let r = Refit {
        effect: cand.describe(),
        kind: cand.kind().into(),
        criterion_before: j0,
        criterion_after: j1,
        rms_db_before: residuals::rms_db(&crit, &cur.e),
        rms_db_after: residuals::rms_db(&crit, &next.e),
        lr,
        dof: q,
        p_value,
        aic_change: -lr + 2.0 * q as f64,
        bic_change: -lr + q as f64 * n.ln(),
        params,
        stop,
        converged: out.stop.converged(),
        equivalent: Vec::new(),
        family: Vec::new(),
        place: None,
    };
    Ok((r, next))
}

/// A short refit of `p`, the fit extended by one effect with `q` parameters (the last of its
/// point): minimized from each of `starts`, `max_iterations` at most, the lowest end's criterion
/// and the effect's parameters there (SI). `None` when no start could be minimized.
pub(super) fn short_refit(
    setting: Setting,
    p: &mut Problem,
    starts: impl IntoIterator<Item = DVector<f64>>,
    q: usize,
    max_iterations: usize,
) -> Option<(f64, Vec<f64>)> {
    let fit = &setting.opts.identification;
    let settings = optimize::Settings {
        max_iterations,
        ..fit.settings
    };
    let (lo, hi) = p.bounds();
    let out = starts
        .into_iter()
        .filter_map(|u| {
            optimize::minimize(fit.optimizer, p, &u, &lo, &hi, &settings, &mut |_| {}).ok()
        })
        .min_by(|a, b| a.criterion.total_cmp(&b.criterion))?;
    let (_, gamma) = p.split(&out.u);
    Some((out.criterion, gamma[gamma.len() - q..].to_vec()))
}

/// The start of `starts` where the criterion is lowest (the first of equals), and that criterion;
/// a start that cannot be evaluated counts as infinitely bad (so that, when none can be, the
/// minimizer started from the first reports why). `None` when there is no start. A start that
/// changes only the new effect's parameters of a fit `solves` holds is evaluated as an update of
/// its solves.
pub(super) fn lowest_start(
    p: &mut Problem,
    solves: &Solves,
    starts: impl IntoIterator<Item = DVector<f64>>,
) -> Option<(f64, DVector<f64>)> {
    starts
        .into_iter()
        .map(|u| (solves.sum_of_squares(p, &u), u))
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

/// The point `u` (scaled) with the variables at their initial values: a start outside the valley
/// where a large missing effect has bent the fit's own parameters to mimic it.
pub(super) fn from_initial(u: &DVector<f64>, vars: &Variables, scale: &[f64]) -> DVector<f64> {
    let mut fresh = u.clone();
    for (i, x) in vars.initial().iter().enumerate() {
        fresh[i] = x / scale[i];
    }
    fresh
}

/// The start of problem `p` (extended by a new effect with parameters `params`, the last of
/// `u`) outside the valley where a large missing effect has bent the fit's own parameters: the
/// variables at their initial values ([`from_initial`]) and the effect's size (its first
/// parameter) the one of `u` or of a grid ([`FRESH_SIZES_PER_DECADE`] steps a decade across
/// [`FRESH_SIZE_DECADES`] of its scale on either side of its nested value) where the
/// misfit there is least. With the variables back at their nominal values, the misfit is least
/// in the effect's own valley, which the bent fit hides: with a large missing flexibility the
/// fit's stiffnesses move to mimic it, short refits from that fit stop at a fraction of the
/// true compliance with the misfit still tens of times the noise level, whatever size they
/// start from, while from the nominal variables they reach the noise level.
pub(super) fn fresh_start(
    p: &mut Problem,
    solves: &Solves,
    u: &DVector<f64>,
    params: &[EffectParam],
    vars: &Variables,
) -> DVector<f64> {
    let fresh = from_initial(u, vars, &p.scale);
    let Some(np) = params.first() else {
        return fresh;
    };
    let at = u.len() - params.len();
    let (first, last) = (
        FRESH_SIZE_DECADES.start() * FRESH_SIZES_PER_DECADE,
        FRESH_SIZE_DECADES.end() * FRESH_SIZES_PER_DECADE,
    );
    let sizes = (first..=last)
        .map(|k| np.scale * 10f64.powf(f64::from(k) / f64::from(FRESH_SIZES_PER_DECADE)))
        .flat_map(|step| [np.nested + step, np.nested - step])
        .filter(|x| *x > np.lower && *x < np.upper);
    let grid = sizes.map(|x| {
        let mut v = fresh.clone();
        v[at] = x / np.scale;
        v
    });
    lowest_start(p, solves, std::iter::once(fresh.clone()).chain(grid)).map_or(fresh, |(_, v)| v)
}

/// The fit's scaled variables `u` followed by a new effect's parameters at `x` (SI, clamped to
/// their bounds), scaled: a point of the problem extended by that effect.
pub(super) fn with_effect(u: &DVector<f64>, params: &[EffectParam], x: &[f64]) -> DVector<f64> {
    let new = params
        .iter()
        .zip(x)
        .map(|(np, v)| v.clamp(np.lower, np.upper) / np.scale);
    DVector::from_iterator(u.len() + params.len(), u.iter().copied().chain(new))
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;

    fn resonator(body: &str) -> Effect {
        Effect::Resonator {
            body: body.into(),
            point: Vector3::zeros(),
            freq_hz: 100.0,
            tuning: [80.0, 120.0],
            scale: 1.0,
        }
    }

    fn spring(a: &str, b: &str) -> Effect {
        Effect::Spring {
            bodies: [Some(a.into()), Some(b.into())],
            point: Vector3::zeros(),
            direction: Vector3::z(),
            psi: 0.3,
        }
    }

    /// A refit of `effect` with likelihood ratio `lr` on `dof` parameters.
    fn refit_of(effect: &Effect, lr: f64, dof: usize) -> Refit {
        Refit {
            effect: effect.describe(),
            kind: effect.kind().into(),
            criterion_before: 100.0,
            criterion_after: 100.0 - lr / 2.0,
            lr,
            dof,
            p_value: chi2_tail(dof as f64, lr),
            aic_change: 0.0,
            bic_change: 0.0,
            rms_db_before: 0.0,
            rms_db_after: 0.0,
            params: Vec::new(),
            stop: String::new(),
            converged: true,
            equivalent: Vec::new(),
            family: Vec::new(),
            place: None,
        }
    }

    /// The round's other refits whose margins are within 3.84 of the accepted one's, either
    /// side, are its look-alikes with their mirror images; the accepted effect itself and those
    /// already listed are left out. A margin counts the refit's parameters: a one-parameter
    /// refit's is its LR less a lower critical value than a two-parameter one's.
    #[test]
    fn the_rounds_refits_within_a_likelihood_ratio_of_384_are_look_alikes() {
        let threshold = 1e-5;
        let own = spring("ground", "overarm");
        let chosen = refit_of(&own, 100.0, 2);
        let m = margin(&chosen, threshold);
        let contender = |effects: Vec<Effect>, margin: f64| Contender { effects, margin };
        let contenders = [
            contender(vec![own.clone()], m),
            contender(
                vec![spring("ground", "head"), spring("ground", "head2")],
                m - 3.5,
            ),
            contender(vec![resonator("knee")], m + 3.0),
            contender(vec![spring("ground", "column")], m - 4.0),
            contender(vec![resonator("table")], m + 1.0),
            contender(vec![resonator("saddle")], m - 3.83),
            contender(vec![resonator("column")], m + 3.85),
        ];
        let listed = [resonator("table")];
        let alike = look_alikes(&contenders, &chosen, &own, &listed, threshold);
        assert_eq!(
            alike,
            vec![
                spring("ground", "head"),
                spring("ground", "head2"),
                resonator("knee"),
                resonator("saddle"),
            ]
        );
        assert!(margin(&refit_of(&own, 100.0, 1), threshold) > m + 3.0);
    }

    /// Each other kind's best member comes first, then each other site's, then the rest, each in
    /// score order; the leader is left out wherever it stands.
    #[test]
    fn a_familys_members_are_refitted_each_kind_and_site_first() {
        let family = [
            spring("knee", "table"),   // 0: a second point of the leader's site
            spring("column", "table"), // 1: another site
            resonator("table"),        // 2: another kind
            spring("knee", "table"),   // 3: the leader
            resonator("knee"),         // 4: another site of that kind
            resonator("table"),        // 5: a second point of a site already taken
            spring("column", "table"), // 6: likewise
        ];
        let order = kinds_first(3, &[0, 1, 2, 3, 4, 5, 6], |k| &family[k]);
        assert_eq!(order, (vec![2, 1, 4, 0, 5, 6], 1));
    }

    /// A round's ranking of `candidates` in the order given, each its own family, at threshold
    /// 1e-5 and σ̂² = 1.
    fn ranked_as_listed(candidates: Vec<Effect>) -> Ranking {
        let scored: Vec<score::Scored> = (0..candidates.len())
            .map(|i| score::Scored {
                candidate: i,
                statistic: 100.0 - i as f64,
                pull: 100.0 - i as f64,
                p_value: 1e-9 * (i + 1) as f64,
                step: 1.0,
                direction: DVector::zeros(1),
                tuned_hz: None,
            })
            .collect();
        Ranking {
            families: (0..candidates.len()).map(|i| vec![i]).collect(),
            candidates,
            scored,
            ranked: Vec::new(),
            threshold: 1e-5,
            sigma2: 1.0,
        }
    }

    /// The candidates a one-sided score rules out enter the short refits by their pull: each
    /// kind's strongest first, up to the number per kind, none whose pull is implausible and no
    /// resonator (its tuning means nothing where no tuning lowers J).
    #[test]
    fn the_strongest_pulls_a_score_rules_out_get_short_refits() {
        let mut ranking = ranked_as_listed(vec![
            spring("knee", "table"),   // 0: plausible, not ruled out
            spring("column", "table"), // 1: ruled out, pull 30
            spring("knee", "column"),  // 2: ruled out, pull 50
            spring("knee", "saddle"),  // 3: ruled out, pull 40
            spring("column", "knee"),  // 4: ruled out, pull 20: beyond the number per kind
            resonator("table"),        // 5: ruled out, pull 90: a resonator
            spring("table", "saddle"), // 6: ruled out, pull 1: implausible
        ]);
        let pulls = [30.0, 50.0, 40.0, 20.0, 90.0, 1.0];
        for (s, pull) in ranking.scored[1..].iter_mut().zip(pulls) {
            (s.statistic, s.p_value, s.step, s.pull) = (0.0, 1.0, -1.0, pull);
        }
        ranking.scored[5].tuned_hz = Some(100.0);
        assert_eq!(pulled_against(&ranking, 3), vec![2, 3, 1]);
        assert_eq!(pulled_against(&ranking, 1), vec![2]);
    }

    /// The screen of the scored candidates `order` (indices), best first, at J = 10, 11, …,
    /// each left at `start`.
    fn screened_in_order(order: &[usize], start: &[f64]) -> Vec<Screened> {
        order
            .iter()
            .enumerate()
            .map(|(r, &index)| Screened {
                index,
                criterion: 10.0 + r as f64,
                start: start.to_vec(),
            })
            .collect()
    }

    /// The refits go to the `n` families the screen puts first, and to the score's leading
    /// family as well when the screen puts it after them.
    #[test]
    fn the_score_s_leading_family_is_refitted_wherever_the_screen_puts_it() {
        let candidates = vec![
            spring("ground", "column"), // the score's first family
            resonator("table"),
            resonator("knee"),
            spring("knee", "table"),
        ];
        let ranking = ranked_as_listed(candidates);
        // The screen puts the score's leader last.
        let screened = screened_in_order(&[3, 1, 2, 0], &[1.0]);
        let families = |n: usize| -> Vec<Option<usize>> {
            refit_jobs(&ranking, &screened, n, 400.0)
                .iter()
                .map(|job| job.family)
                .collect()
        };
        assert_eq!(families(2), [Some(3), Some(1), Some(0)]);
        // Where the screen already takes it, nothing is added.
        assert_eq!(families(4), [Some(3), Some(1), Some(2), Some(0)]);
    }

    /// A kind none of the leading families holds gets the family of its best-scored screened
    /// candidate refitted, where that candidate's screen is significant by itself (LR =
    /// 2ΔJ/σ̂² above the round's critical value for its parameters); otherwise it is left out.
    #[test]
    fn a_kind_left_out_of_the_leading_families_is_refitted_where_its_screen_is_significant() {
        let candidates = vec![
            spring("ground", "column"),
            spring("ground", "knee"),
            resonator("table"),
            resonator("knee"),
        ];
        let ranking = ranked_as_listed(candidates);
        // The resonator on the knee screens better than the one on the table, which the
        // score put first.
        let screened = screened_in_order(&[0, 1, 3, 2], &[1.0, 100.0]);
        let leading = refit_jobs(&ranking, &screened, 2, 400.0);
        let families = |jobs: &[Job]| -> Vec<(Option<usize>, usize)> {
            jobs.iter()
                .map(|job| (job.family, job.members.len()))
                .collect()
        };
        assert_eq!(families(&leading), [(Some(0), 1), (Some(1), 1)]);
        // LR 2 × (100 − 13) = 174 for 2 parameters: the table's resonator's family.
        let more = kind_jobs(&ranking, &screened, &leading, 100.0, 400.0);
        assert_eq!(families(&more), [(Some(2), 1)]);
        // LR 2 × (14 − 13) = 2: not significant, no resonator is refitted.
        assert!(kind_jobs(&ranking, &screened, &leading, 14.0, 400.0).is_empty());
        // Where the leading families hold every kind there is nothing to add.
        let all = refit_jobs(&ranking, &screened, 4, 400.0);
        assert!(kind_jobs(&ranking, &screened, &all, 100.0, 400.0).is_empty());
    }

    #[test]
    fn the_halving_keeps_the_lowest_share_and_never_fewer_than_the_minimum() {
        let reached = |n: usize| -> Vec<(usize, f64)> {
            (0..n).map(|a| (a, ((a * 7919) % n) as f64)).collect()
        };
        let lowest = |n: usize, k: usize| -> Vec<usize> {
            let mut by_j = reached(n);
            by_j.sort_by(|a, b| a.1.total_cmp(&b.1));
            by_j.into_iter().take(k).map(|(a, _)| a).collect()
        };
        // Fewer than the minimum: all go on, lowest first.
        let few = SHORT_REFIT_MIN_KEPT - 10;
        assert_eq!(going_on(reached(few)), lowest(few, few));
        // A share below the minimum: the minimum goes on.
        let some = 2 * SHORT_REFIT_MIN_KEPT;
        assert_eq!(going_on(reached(some)), lowest(some, SHORT_REFIT_MIN_KEPT));
        // Many: the lowest share.
        let many = 10 * SHORT_REFIT_MIN_KEPT + 1;
        let share = (many as f64 * SHORT_REFIT_KEPT).ceil() as usize;
        assert!(share > SHORT_REFIT_MIN_KEPT);
        assert_eq!(going_on(reached(many)), lowest(many, share));
    }

    /// The short refits that went below the best refit so far lead refits of their families,
    /// lowest first, up to `n`, and none of a family a job already holds; those that did not go
    /// below it lead none.
    #[test]
    fn a_short_refit_below_the_best_refit_leads_its_family_s_refit() {
        let candidates = vec![
            spring("ground", "column"),
            spring("ground", "knee"),
            resonator("table"),
            resonator("knee"),
        ];
        let ranking = ranked_as_listed(candidates);
        let screened = screened_in_order(&[0, 1, 2, 3], &[1.0, 100.0]);
        let leading = refit_jobs(&ranking, &screened, 1, 400.0);
        // Short refits: the knee's resonator ends at J 12, the table's at 30, the knee's spring
        // at 50, and the column's spring (refitted already) at 5.
        let refined: Vec<Screened> = [(0, 5.0), (3, 12.0), (2, 30.0), (1, 50.0)]
            .into_iter()
            .map(|(index, criterion)| Screened {
                index,
                criterion,
                start: vec![2.0, 200.0],
            })
            .collect();
        let families = |least: f64, n: usize| -> Vec<Option<usize>> {
            refined_jobs(&ranking, &screened, &refined, &leading, n, least, 400.0)
                .iter()
                .map(|job| job.family)
                .collect()
        };
        assert_eq!(families(40.0, 5), [Some(3), Some(2)]);
        assert_eq!(families(40.0, 1), [Some(3)]);
        assert!(families(10.0, 5).is_empty());
        // The job starts where the short refit ended.
        let jobs = refined_jobs(&ranking, &screened, &refined, &leading, 5, 40.0, 400.0);
        assert_eq!(jobs[0].members[0].start, [2.0, 200.0]);
    }

    fn estimate(name: &str, unit: &str, value: f64, std_error: f64) -> ParamEstimate {
        ParamEstimate {
            name: name.into(),
            unit: unit.into(),
            value,
            std_error,
        }
    }

    /// A resonator the data put above the measured band is not added as one (its size is
    /// otherwise clear); within the band the same estimates are an identified effect.
    #[test]
    fn a_resonator_tuned_above_the_band_is_not_identifiable() {
        let params = resonator("table").params(400.0);
        let at = |f: f64| {
            vec![
                estimate("m", "kg", 90.0, 2.0),
                estimate("f", "Hz", f, 0.2 * f),
            ]
        };
        let why = unidentifiable(&params, &at(450.0), 400.0, 1e-5)
            .expect("a resonance above the band is not identified");
        assert!(
            why.contains("above the band") && why.contains("400 Hz"),
            "{why}"
        );
        assert_eq!(unidentifiable(&params, &at(350.0), 400.0, 1e-5), None);
    }

    /// The share of the misfit above the noise level an effect removes: 100 lines at σ̂² = 1
    /// expect J = 50, so J 150 → 100 removes half of the excess of 100; a fit already at the
    /// noise level has no excess to share.
    #[test]
    fn an_effect_s_share_counts_only_the_misfit_above_the_noise_level() {
        let share = excess_removed((150.0, 100.0), 100.0, 1.0).expect("an excess");
        assert!((share - 0.5).abs() < 1e-12, "{share}");
        assert!((excess_removed((150.0, 140.0), 100.0, 1.0).unwrap() - 0.1).abs() < 1e-12);
        assert_eq!(excess_removed((50.0, 40.0), 100.0, 1.0), None);
        assert_eq!(excess_removed((45.0, 40.0), 100.0, 1.0), None);
    }
}
