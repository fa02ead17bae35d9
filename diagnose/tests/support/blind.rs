//! The blind suite of the closed loop: a seeded generator of truths — a model with one or two
//! undeclared effects drawn across every kind of the candidate library (or none), placed across
//! the model's bodies and body pairs, sized from barely detectable to dominant — their noisy data,
//! an identification started from parameters perturbed ±30 %, and the judgement of a diagnosis of
//! it (the right effect first? exactly the injected set? anything added to clean data?), and of
//! a case it got wrong: could the data tell its answer from the truth at all ([`truth_form`],
//! [`miss`])?
//!
//! One generator for the CI test (`diagnose/tests/blind.rs`, a few dozen seeded cases asserting
//! the rates) and the example that measures them over hundreds (`diagnose/examples/blind.rs`,
//! which includes this file): test support, not library code.
//!
//! Sizes are set by what the effect does to the data, not by its parameter: each effect's
//! parameter is chosen (bisection on a log scale) so that its noise-free change of the data is
//! `signal` in χ² units (Σ((|q₁| − |q₀|)/(ε|q₀|))² over every point, less the part the
//! identification's variables can absorb to first order: what a fit cannot explain away), with `signal` drawn
//! log-uniform over [`SIGNAL`]: from about twice the Bonferroni critical value of one candidate
//! among a thousand (barely detectable once the fitted variables absorb part of it) to
//! dominant (a misfit of reduced χ² in the hundreds). Sizes stay physical: a body's mass within
//! a factor [`BODY_MASS_FACTOR`] of the model's, a point mass or resonator at most
//! [`ADDED_MASS_SHARE`] of its host body, a joint's own ψ within the candidate's range (0 to 4π);
//! an effect that cannot reach its signal within them is
//! drawn again.

// Each test target and the example use a part of the harness.
#![allow(dead_code)]

use std::time::Instant;

use nalgebra::{DMatrix, DVector};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};

use diagnose::effects::{Effect, EffectError, Realized};
use diagnose::{diagnose, DiagnoseError, Diagnosis, Options};
use identify::{data, synthetic, IdentifyError, Variables};
use rfe::frf::{self, Method};
use rfe::measured::MeasuredData;
use rfe::model::Model;

/// Range of an injected effect's signal: its noise-free change of the data in χ² units, less
/// what the variables absorb.
pub const SIGNAL: (f64, f64) = (100.0, 1.0e5);
/// An injected body mass is the model's times or divided by at most this: a body twice or half
/// as heavy as drawn is a wrong model, a tenfold one a different machine.
pub const BODY_MASS_FACTOR: f64 = 2.0;
/// An injected point mass or resonator weighs at most this share of the body it is fixed to (a
/// workpiece, a fixture, a loose cover; not a second machine on the table).
pub const ADDED_MASS_SHARE: f64 = 0.5;
/// Range of the relative noise σ/|q| of the data (0.5-3 %).
pub const NOISE: (f64, f64) = (0.005, 0.03);
/// The identification starts from the truth's values times a factor in 1 ± this.
pub const PERTURBATION: f64 = 0.3;
/// Share of cases with no effect (clean data).
pub const CLEAN_SHARE: f64 = 0.25;
/// Share of the cases with effects that have two.
pub const TWO_SHARE: f64 = 0.3;

/// One injected effect and its parameter values (SI, in [`Effect::params`] order).
#[derive(Debug, Clone, PartialEq)]
pub struct Injected {
    /// What and where.
    pub effect: Effect,
    /// Its parameters.
    pub values: Vec<f64>,
    /// Its noise-free change of the data (χ² units).
    pub signal: f64,
}

/// One blind case: the truth's hidden effects, the noisy data and the perturbed start.
#[derive(Debug, Clone)]
pub struct BlindCase {
    /// The seed it was drawn from.
    pub seed: u64,
    /// The effects the identification model lacks (empty: clean data).
    pub injected: Vec<Injected>,
    /// Relative noise σ/|q| of the data.
    pub noise: f64,
    /// The data (amplitude characteristics of the truth with the effects, noise, variances).
    pub data: MeasuredData,
    /// The identification variables with their initial values perturbed.
    pub vars: Variables,
}

/// What a diagnosis of a blind case got right.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// The case's seed.
    pub seed: u64,
    /// Number of injected effects.
    pub injected: usize,
    /// The first effect of the final answer — the first the diagnosis accepted, as a later
    /// relocation or swap left it — is one of the injected ones (same kind and place, see
    /// [`same_site`]), or one of the effects it reports the data cannot tell from it (its
    /// `equivalent`, "≡"); false on clean data.
    pub right_first: bool,
    /// The first effect of the final answer is itself one of the injected ones: `right_first`
    /// without its equivalents.
    pub named_first: bool,
    /// The first family of the first round's ranking holds an injected effect.
    pub ranked_first: bool,
    /// The final set of added effects is the injected set, one to one (on clean data: nothing).
    pub exact: bool,
    /// Clean data and something was added.
    pub false_add: bool,
    /// The effects added, described.
    pub added: Vec<String>,
    /// Wall time of the identification and the diagnosis (s).
    pub seconds: f64,
    /// Wall time of the diagnosis alone (s).
    pub diagnosis_seconds: f64,
}

/// Why a blind case could not be drawn or run.
#[derive(Debug, thiserror::Error)]
pub enum BlindError {
    /// An effect could not be applied to the truth.
    #[error(transparent)]
    Effect(#[from] EffectError),
    /// The truth cannot be solved at a line.
    #[error(transparent)]
    Solve(#[from] frf::SolveError),
    /// The data do not fit the model.
    #[error(transparent)]
    Data(#[from] data::DataError),
    /// The identification could not start.
    #[error(transparent)]
    Identify(#[from] IdentifyError),
    /// The diagnosis could not run.
    #[error(transparent)]
    Diagnose(#[from] DiagnoseError),
    /// The library has no candidate of any kind for this model.
    #[error("the candidate library is empty for this model")]
    NoCandidates,
}

/// Whether `a` and `b` are the same effect for the suite: the same kind at the same place — a
/// spring between the same two bodies (or body and ground), a mass, resonator or flexibility of
/// the same body, the gain of the same characteristic, the damping of the same joint, a
/// direction of the same SDE or the same moment stiffness ([`same_moment`]). (Point and
/// direction are not compared: the fitted placement refines them.)
pub fn same_site(model: &Model, a: &Effect, b: &Effect) -> bool {
    same_moment(model, a, b) || same_kind_and_place(a, b)
}

/// Whether `a` and `b` change the stiffness about parallel axes (|cos| > 0.999) of two SDEs of
/// `model` that join the same two bodies: a moment stiffness acts on the bodies' relative
/// rotation, which is the same at every point, so the two are one element (the four isolators'
/// stiffnesses about their common vertical axis, say) and no data can tell them apart.
pub fn same_moment(model: &Model, a: &Effect, b: &Effect) -> bool {
    let (
        Effect::Direction {
            sde: x, axis: i, ..
        },
        Effect::Direction {
            sde: y, axis: j, ..
        },
    ) = (a, b)
    else {
        return false;
    };
    let sde = |name: &str| model.sdes.iter().find(|s| s.name == name);
    let (Some(p), Some(q)) = (sde(x), sde(y)) else {
        return false;
    };
    let pair = |s: &rfe::model::Sde| {
        let mut v = s.bodies.to_vec();
        v.sort();
        v
    };
    *i >= 3
        && *j >= 3
        && pair(p) == pair(q)
        && p.rotation
            .column(i - 3)
            .dot(&q.rotation.column(j - 3))
            .abs()
            > 0.999
}

/// The same kind at the same place: the same bodies (springs), body (masses, resonators, body
/// masses), element and axis (flexibility, directions), characteristic (gains) or joint
/// (damping).
fn same_kind_and_place(a: &Effect, b: &Effect) -> bool {
    use Effect::*;
    let pair = |x: &[Option<String>; 2]| {
        let mut v = x.to_vec();
        v.sort();
        v
    };
    match (a, b) {
        (
            Spring { bodies: x, .. } | PlacedSpring { bodies: x, .. },
            Spring { bodies: y, .. } | PlacedSpring { bodies: y, .. },
        ) => pair(x) == pair(y),
        (
            Mass { body: x, .. } | PlacedMass { body: x, .. },
            Mass { body: y, .. } | PlacedMass { body: y, .. },
        ) => x == y,
        (Resonator { body: x, .. }, Resonator { body: y, .. }) => x == y,
        (
            Flexible {
                body: x, axis: i, ..
            },
            Flexible {
                body: y, axis: j, ..
            },
        )
        | (
            Direction {
                sde: x, axis: i, ..
            },
            Direction {
                sde: y, axis: j, ..
            },
        ) => x == y && i == j,
        (Gain { output: x, .. }, Gain { output: y, .. }) => x == y,
        (BodyMass { body: x, .. }, BodyMass { body: y, .. }) => x == y,
        (
            Damping {
                variable: x,
                sdes: s,
                ..
            },
            Damping {
                variable: y,
                sdes: t,
                ..
            },
        ) => x == y && s == t,
        _ => false,
    }
}

/// A found resonator's tuning frequency must be within this fraction of the injected one.
pub const RESONATOR_TOLERANCE: f64 = 0.1;

/// Whether the added effect `e` with fitted parameter `values` (empty: not fitted, its own
/// starting values stand) is the injected `i`: the same site ([`same_site`]) and, for a
/// resonator, the same tuning frequency within [`RESONATOR_TOLERANCE`] (a resonator on the right
/// body at another frequency is another effect).
pub fn found(model: &Model, i: &Injected, e: &Effect, values: &[f64]) -> bool {
    if !same_site(model, &i.effect, e) {
        return false;
    }
    let Effect::Resonator { freq_hz, .. } = e else {
        return true;
    };
    let f = values.get(1).copied().unwrap_or(*freq_hz);
    i.values
        .get(1)
        .is_some_and(|f0| (f / f0 - 1.0).abs() <= RESONATOR_TOLERANCE)
}

/// The amplitude of every characteristic of `r` at `lines` (gains applied), flattened.
fn amplitudes(r: &Realized, lines: &[f64]) -> Result<Vec<f64>, frf::SolveError> {
    let resp = frf::response(&r.model, lines, &[], Method::Auto)?;
    Ok((0..r.model.outputs.len())
        .flat_map(|o| {
            let g = r.gains.get(o).copied().unwrap_or(1.0);
            resp.output(o)
                .iter()
                .map(move |v| g * v.norm())
                .collect::<Vec<_>>()
        })
        .collect())
}

/// The effect's first parameter as a function of a size `t ∈ (0, ∞)` (t → 0: nested), the
/// others fixed; `extra` is a second parameter drawn once (a resonator's frequency, a spring's ψ).
fn values_at(effect: &Effect, nested: &[f64], t: f64, sign: f64, extra: f64) -> Vec<f64> {
    let mut v = nested.to_vec();
    match effect {
        Effect::Gain { .. } => v[0] = sign * t.min(0.45),
        Effect::Damping { value, .. } => v[0] = value * (sign * t).exp(),
        Effect::BodyMass { mass, .. } => v[0] = mass * (sign * t).exp(),
        Effect::Spring { .. } => {
            v[0] = t;
            v[1] = extra;
        }
        Effect::Resonator { .. } => {
            v[0] = t;
            v[1] = extra;
        }
        _ => v[0] = t,
    }
    v
}

/// Orthonormal columns spanning how the identification's variables move the data `q0` of `r`
/// at `lines` (whitened by the relative noise `noise`; forward differences at the truth's
/// values): what a fit can absorb of an effect, to first order.
fn absorbed(
    r: &Realized,
    q0: &[f64],
    lines: &[f64],
    noise: f64,
) -> Result<DMatrix<f64>, BlindError> {
    let x = truth_values(&r.model, &r.vars);
    let mut jac = DMatrix::zeros(q0.len(), x.len());
    for (i, v) in r.vars.vars.iter().enumerate() {
        let h = 1e-6 * x[i].abs().max(v.scale.abs()).max(f64::MIN_POSITIVE);
        let mut xh = x.clone();
        xh[i] += h;
        let mut m = r.clone();
        r.vars.apply(&mut m.model, &xh);
        let q = amplitudes(&m, lines)?;
        for (k, (a, b)) in q.iter().zip(q0).enumerate() {
            jac[(k, i)] = (a - b) / (h * noise * b);
        }
    }
    // The variables' units differ by ten decades (Pa/m against ψ): columns of unit length, so
    // that the basis drops only columns that truly depend on the others.
    for mut c in jac.column_iter_mut() {
        let n = c.norm();
        if n > 0.0 {
            c /= n;
        }
    }
    Ok(diagnose::score::orthonormal_columns(&jac))
}

/// Injects `effect` into `r` with a size such that its noise-free change of the data `q0` is
/// `signal` in χ² units at relative noise `noise` — the part of the change the identification's
/// variables cannot absorb (projected off [`absorbed`]): an effect the variables can mimic is
/// not detectable, whatever it does to the data. Returns the values used.
#[allow(clippy::too_many_arguments)]
fn sized(
    r: &Realized,
    effect: &Effect,
    q0: &[f64],
    lines: &[f64],
    (noise, f_max): (f64, f64),
    signal: f64,
    rng: &mut StdRng,
) -> Result<Option<(Vec<f64>, f64)>, BlindError> {
    let params = effect.params(f_max);
    let nested: Vec<f64> = params.iter().map(|p| p.nested).collect();
    let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    let extra = match effect {
        Effect::Spring { .. } => rng.random_range(0.05..0.6),
        Effect::Resonator { .. } => {
            let (lo, hi) = (lines[0] * 1.2, lines[lines.len() - 1] / 1.2);
            lo * (hi / lo).powf(rng.random::<f64>())
        }
        _ => 0.0,
    };
    let absorbed = absorbed(r, q0, lines, noise)?;
    let chi2 = |t: f64| -> Result<Option<f64>, BlindError> {
        let mut x = r.clone();
        let v = values_at(effect, &nested, t, sign, extra);
        effect.apply(&mut x, &v, f_max)?;
        let Ok(q) = amplitudes(&x, lines) else {
            return Ok(None);
        };
        let d = DVector::from_iterator(
            q.len(),
            q.iter().zip(q0).map(|(a, b)| (a - b) / (noise * b)),
        );
        Ok(Some(
            (d.norm_squared() - (absorbed.transpose() * &d).norm_squared()).max(0.0),
        ))
    };
    // Bracket on a log scale from the parameter's own scale, then bisect.
    let (mut lo, mut hi) = match effect {
        Effect::Gain { .. } => (1e-6, 0.45),
        // A joint's own ψ up to 20× or 1/20 of its group's, within the range the candidate fits
        // (at most 4π: a loss factor of 2).
        Effect::Damping { value, .. } if sign > 0.0 => {
            (1e-6, (params[0].upper / value).ln().min(3.0))
        }
        Effect::Damping { .. } => (1e-6, 3.0),
        // A body half or twice as heavy as the model says (within the fitted range).
        Effect::BodyMass { .. } => (1e-6, BODY_MASS_FACTOR.ln()),
        // An added mass or resonator at most a share of the body it is fixed to.
        Effect::Mass { body, .. } | Effect::Resonator { body, .. } => {
            let host = r
                .model
                .body_index(body)
                .map_or(f64::INFINITY, |b| r.model.bodies[b].mass);
            let hi = (params[0].scale * 1e8).min(ADDED_MASS_SHARE * host);
            (params[0].scale * 1e-8, hi)
        }
        _ => (params[0].scale * 1e-8, params[0].scale * 1e8),
    };
    match chi2(hi)? {
        Some(c) if c >= signal => {}
        _ => return Ok(None),
    }
    for _ in 0..60 {
        let mid = (lo * hi).sqrt();
        match chi2(mid)? {
            Some(c) if c < signal => lo = mid,
            Some(_) => hi = mid,
            None => return Ok(None),
        }
        if hi / lo < 1.02 {
            break;
        }
    }
    let v = values_at(effect, &nested, hi, sign, extra);
    Ok(Some((v, chi2(hi)?.unwrap_or(signal))))
}

/// Draws blind case `seed` on `model` (the truth without effects, its values the truth's) with
/// identification variables `vars`, measured at `lines` (Hz). `clean` forces a case without
/// effects; otherwise one in four is clean.
pub fn draw(
    model: &Model,
    vars: &Variables,
    lines: &[f64],
    seed: u64,
    clean: Option<bool>,
) -> Result<BlindCase, BlindError> {
    let mut rng = StdRng::seed_from_u64(seed);
    let f_max = lines.iter().copied().fold(0.0, f64::max);
    let f_min = lines.iter().copied().fold(f64::INFINITY, f64::min);
    let noise = rng.random_range(NOISE.0..NOISE.1);
    let clean = clean.unwrap_or_else(|| rng.random_bool(CLEAN_SHARE));
    let n_effects = if clean {
        0
    } else if rng.random_bool(TWO_SHARE) {
        2
    } else {
        1
    };
    let x = truth_values(model, vars);
    let labels: Vec<String> = (0..model.outputs.len()).map(|o| format!("#{o}")).collect();
    let library = diagnose::generate::candidates(model, vars, &x, &labels, f_min, f_max);
    let mut kinds: Vec<&'static str> = library.iter().map(Effect::kind).collect();
    kinds.dedup();
    kinds.sort();
    kinds.dedup();
    if kinds.is_empty() {
        return Err(BlindError::NoCandidates);
    }
    let mut truth = pristine(model, vars);
    let mut injected: Vec<Injected> = Vec::new();
    let mut attempts = 0;
    while injected.len() < n_effects && attempts < 200 {
        // The kind is drawn once per effect and kept: a candidate of it that cannot reach its
        // drawn signal (the variables absorb most of what it does) is drawn again within the
        // kind, so that kinds the variables partly absorb are not left out of the suite.
        let kind = kinds[rng.random_range(0..kinds.len())];
        let of_kind: Vec<&Effect> = library.iter().filter(|e| e.kind() == kind).collect();
        for _ in 0..ATTEMPTS_PER_KIND {
            attempts += 1;
            let effect = of_kind[rng.random_range(0..of_kind.len())].clone();
            if injected
                .iter()
                .any(|i| same_site(model, &i.effect, &effect))
            {
                continue;
            }
            let signal = SIGNAL.0 * (SIGNAL.1 / SIGNAL.0).powf(rng.random::<f64>());
            if let Some(i) = inject(&mut truth, &effect, lines, (signal, noise), &mut rng)? {
                injected.push(i);
                break;
            }
        }
    }
    finish(
        (&truth, injected),
        (vars, &x),
        (lines, noise),
        (&mut rng, seed),
    )
}

/// Candidates (and signals) of one drawn kind tried before another kind is drawn.
const ATTEMPTS_PER_KIND: usize = 20;

/// The case of one given `effect` on `model` (the truth's values) sized so that its noise-free
/// change of the data is `signal` (χ² units at relative noise `noise`), measured at `lines`
/// (Hz), the identification started from `vars` perturbed ±[`PERTURBATION`] as [`draw`] does.
/// `None` when no size of the effect reaches `signal`.
pub fn with_effect(
    model: &Model,
    vars: &Variables,
    lines: &[f64],
    effect: &Effect,
    (signal, noise): (f64, f64),
    seed: u64,
) -> Result<Option<BlindCase>, BlindError> {
    let mut rng = StdRng::seed_from_u64(seed);
    let x = truth_values(model, vars);
    let mut truth = pristine(model, vars);
    let Some(injected) = inject(&mut truth, effect, lines, (signal, noise), &mut rng)? else {
        return Ok(None);
    };
    finish(
        (&truth, vec![injected]),
        (vars, &x),
        (lines, noise),
        (&mut rng, seed),
    )
    .map(Some)
}

/// The truth before any effect: `model` with `vars`, every gain 1.
fn pristine(model: &Model, vars: &Variables) -> Realized {
    Realized {
        model: model.clone(),
        vars: vars.clone(),
        gains: vec![1.0; model.outputs.len()],
    }
}

/// Injects `effect` into `truth` sized so that the part of its noise-free change of the data at
/// `lines` the variables cannot absorb is `signal` (χ² units at relative noise `noise`);
/// `None` (and `truth` unchanged) when no size of the effect reaches it.
fn inject(
    truth: &mut Realized,
    effect: &Effect,
    lines: &[f64],
    (signal, noise): (f64, f64),
    rng: &mut StdRng,
) -> Result<Option<Injected>, BlindError> {
    let f_max = lines.iter().copied().fold(0.0, f64::max);
    let q0 = amplitudes(truth, lines)?;
    let Some((values, got)) = sized(truth, effect, &q0, lines, (noise, f_max), signal, rng)? else {
        return Ok(None);
    };
    effect.apply(truth, &values, f_max)?;
    Ok(Some(Injected {
        effect: effect.clone(),
        values,
        signal: got,
    }))
}

/// The variables' values in `model` (a variable whose parameter is not found keeps its initial
/// value).
fn truth_values(model: &Model, vars: &Variables) -> Vec<f64> {
    vars.vars
        .iter()
        .map(|v| {
            v.targets
                .first()
                .and_then(|t| model.value(t.param).map(|p| p / t.ratio))
                .unwrap_or(v.initial)
        })
        .collect()
}

/// A case from its `truth` (the effects `injected` applied): the noisy data at `lines` and the
/// variables `vars` started from their truth's values `x` perturbed ±[`PERTURBATION`].
fn finish(
    (truth, injected): (&Realized, Vec<Injected>),
    (vars, x): (&Variables, &[f64]),
    (lines, noise): (&[f64], f64),
    (rng, seed): (&mut StdRng, u64),
) -> Result<BlindCase, BlindError> {
    let mut data = synthetic::amplitude_data(&truth.model, lines, noise, || {
        StandardNormal.sample(&mut *rng)
    })?;
    for (c, g) in data.characteristics.iter_mut().zip(&truth.gains) {
        c.amplitude.iter_mut().for_each(|a| *a *= g);
        if let Some(v) = c.variance.as_mut() {
            v.iter_mut().for_each(|s| *s *= g * g);
        }
    }
    let mut vars = vars.clone();
    for (v, xi) in vars.vars.iter_mut().zip(x) {
        let f = 1.0 + rng.random_range(-PERTURBATION..PERTURBATION);
        let x0 = if *xi != 0.0 { xi * f } else { v.initial * f };
        v.initial = x0.clamp(v.lower, v.upper);
    }
    Ok(BlindCase {
        seed,
        injected,
        noise,
        data,
        vars,
    })
}

/// Identifies `case` on `model` (default options but `identification`), diagnoses it with
/// `opts`, and judges the diagnosis.
pub fn run(
    model: &Model,
    case: &BlindCase,
    opts: &Options,
) -> Result<(Outcome, Diagnosis), BlindError> {
    let t0 = Instant::now();
    let obs = data::validate(&case.data, model, "blind case")?;
    let id = identify::identify(
        model,
        &obs,
        &case.vars,
        &opts.identification,
        &mut |_, _| {},
    )?;
    let t1 = Instant::now();
    let d = diagnose(model, &obs, &case.vars, &id, opts, &mut |_| {})?;
    let t2 = Instant::now();
    let outcome = judge(case, &d, (t2 - t0).as_secs_f64(), (t2 - t1).as_secs_f64());
    Ok((outcome, d))
}

/// Judges diagnosis `d` of `case`.
pub fn judge(case: &BlindCase, d: &Diagnosis, seconds: f64, diagnosis_seconds: f64) -> Outcome {
    // The fitted values of each added effect (a resonator's tuning frequency is compared).
    let fitted = |k: usize| -> Vec<f64> {
        d.accepted
            .get(k)
            .map(|a| a.params.iter().map(|p| p.value).collect())
            .unwrap_or_default()
    };
    let hit =
        |e: &Effect, values: &[f64]| case.injected.iter().any(|i| found(&d.model, i, e, values));
    let named_first = d.effects.first().is_some_and(|e| hit(e, &fitted(0)));
    let right_first = named_first
        || d.accepted
            .first()
            .is_some_and(|a| a.equivalent.iter().any(|e| hit(e, &[])));
    let ranked_first = d
        .rounds
        .first()
        .and_then(|r| r.ranked.first())
        .is_some_and(|r| r.family.iter().any(|e| hit(e, &[])));
    // One to one: every injected effect matched by a distinct added one and nothing else added.
    let mut used = vec![false; d.effects.len()];
    let all_found = case.injected.iter().all(|i| {
        match d
            .effects
            .iter()
            .enumerate()
            .find(|(k, e)| !used[*k] && found(&d.model, i, e, &fitted(*k)))
        {
            Some((k, _)) => {
                used[k] = true;
                true
            }
            None => false,
        }
    });
    let exact = all_found && used.iter().all(|u| *u);
    Outcome {
        seed: case.seed,
        injected: case.injected.len(),
        right_first,
        named_first,
        ranked_first,
        exact,
        false_add: case.injected.is_empty() && !d.effects.is_empty(),
        added: d.effects.iter().map(Effect::describe).collect(),
        seconds,
        diagnosis_seconds,
    }
}

/// The rates of a set of outcomes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rates {
    /// Cases with effects.
    pub with_effects: usize,
    /// Clean cases.
    pub clean: usize,
    /// Share of the cases with effects whose first accepted effect, or one it reports the data
    /// cannot tell from it, is an injected one ([`Outcome::right_first`]).
    pub right_first: f64,
    /// Share of the cases with effects whose first accepted effect is itself an injected one.
    pub named_first: f64,
    /// Share of the cases with effects whose first ranked family holds an injected one.
    pub ranked_first: f64,
    /// Share of all cases whose final set is exactly the injected one.
    pub exact: f64,
    /// Share of the clean cases where something was added.
    pub false_add: f64,
    /// Median wall time per case, identification included (s).
    pub median_seconds: f64,
    /// Median wall time of the diagnosis alone (s).
    pub median_diagnosis_seconds: f64,
}

/// The rates over `outcomes` (NaN where a share has no cases).
pub fn rates(outcomes: &[Outcome]) -> Rates {
    let share = |n: usize, d: usize| {
        if d == 0 {
            f64::NAN
        } else {
            n as f64 / d as f64
        }
    };
    let with: Vec<&Outcome> = outcomes.iter().filter(|o| o.injected > 0).collect();
    let clean = outcomes.len() - with.len();
    let median = |f: &dyn Fn(&Outcome) -> f64| {
        let mut t: Vec<f64> = outcomes.iter().map(f).collect();
        t.sort_by(f64::total_cmp);
        t.get(t.len() / 2).copied().unwrap_or(f64::NAN)
    };
    Rates {
        with_effects: with.len(),
        clean,
        right_first: share(with.iter().filter(|o| o.right_first).count(), with.len()),
        named_first: share(with.iter().filter(|o| o.named_first).count(), with.len()),
        ranked_first: share(with.iter().filter(|o| o.ranked_first).count(), with.len()),
        exact: share(outcomes.iter().filter(|o| o.exact).count(), outcomes.len()),
        false_add: share(outcomes.iter().filter(|o| o.false_add).count(), clean),
        median_seconds: median(&|o| o.seconds),
        median_diagnosis_seconds: median(&|o| o.diagnosis_seconds),
    }
}

/// The criterion J (½‖e‖², χ² units over two) the truth's own form reaches on `case`: the
/// identification model with exactly the injected effects, every variable and effect parameter
/// refitted from each of `starts` (variable values, SI; the example gives the diagnosis' final
/// variables and the identification's start) with the effects at their true values — the lowest
/// end; [`miss`] judges a diagnosis that is not exact by it.
pub fn truth_form(
    model: &Model,
    case: &BlindCase,
    starts: &[Vec<f64>],
    opts: &Options,
) -> Result<f64, BlindError> {
    let obs = data::validate(&case.data, model, "blind case")?;
    let f_hi = obs.band_hz().1;
    let effects: Vec<Effect> = case.injected.iter().map(|i| i.effect.clone()).collect();
    let truth: Vec<f64> = case
        .injected
        .iter()
        .flat_map(|i| i.values.iter().copied())
        .collect();
    let mut p = diagnose::problem::Problem::new(
        model,
        &case.vars,
        &obs,
        &opts.identification,
        effects,
        f_hi,
    );
    let (lo, hi) = p.bounds();
    let mut best = f64::INFINITY;
    for x in starts {
        let u = DVector::from_iterator(
            p.scale.len(),
            x.iter().chain(&truth).zip(&p.scale).map(|(v, s)| v / s),
        );
        let out = identify::optimize::minimize(
            opts.identification.optimizer,
            &mut p,
            &u,
            &lo,
            &hi,
            &opts.identification.settings,
            &mut |_| {},
        )
        .map_err(DiagnoseError::from)?;
        best = best.min(out.criterion);
    }
    Ok(best)
}

/// What a case that is not exact says of its diagnosis, judged by the truth's own form refitted
/// ([`truth_form`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Miss {
    /// The diagnosis ends within [`diagnose::EQUIVALENT_LR`] of the truth's form in likelihood
    /// ratio (or below it): the data cannot tell its answer from the truth.
    CannotTell,
    /// The truth's form fits the data better by more than that: the search missed it.
    Missed,
    /// The diagnosis ends no higher than the truth's form refitted from the starts given, but
    /// that refit is off the noise level (2J above the number of residuals by more than four of
    /// its standard deviations): the truth's best fit may be lower still; no verdict.
    Undecided,
}

/// The verdict on a diagnosis ending at criterion `diagnosed` against the truth's form's
/// `truth` (both J = ½χ²) over `observations` residuals.
pub fn miss(diagnosed: f64, truth: f64, observations: usize) -> Miss {
    // The truth's refit is a point of its form: its best fit is at least as good.
    let m = observations as f64;
    if 2.0 * (diagnosed - truth) > diagnose::EQUIVALENT_LR {
        Miss::Missed
    } else if 2.0 * truth > m + 4.0 * (2.0 * m).sqrt() {
        Miss::Undecided
    } else {
        Miss::CannotTell
    }
}
