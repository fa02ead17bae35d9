//! The blind suite's fast subset (`diagnose::blind`): seeded FWD-32J cases with one or
//! two hidden effects of every kind in the candidate library (or none), 0.5-3 % noise, the
//! identification started ±30 % away — the closed loop must put the right effect first, end with
//! exactly the injected set, and add nothing to clean data, at the rates asserted below. The
//! rates over 200 cases come from `cargo run -p diagnose --profile test --example blind`.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

#[path = "../../identify/tests/common/mod.rs"]
mod common;

use common::{load_model, load_variables};
#[path = "support/blind.rs"]
mod blind;

use identify::synthetic;

/// The seeds of the subset (the first of the 200 the example runs).
const SEEDS: std::ops::RangeInclusive<u64> = 1..=SUBSET;
const SUBSET: u64 = 24;

#[test]
fn the_blind_subset_is_diagnosed_at_the_asserted_rates() {
    let model = load_model("fwd32j.toml");
    let vars = load_variables("fwd32j.toml", &model);
    let lines = synthetic::fwd32j_lines();
    let opts = diagnose::Options::default();
    // The cases are independent: two at a time (CI has two cores), each worker taking the next
    // seed (their times differ tenfold).
    let next = std::sync::atomic::AtomicU64::new(*SEEDS.start());
    let case = |seed: u64| {
        let case = blind::draw(&model, &vars, &lines, seed, None).expect("a blind case");
        // The generator injects what it says: a case with effects has data that differ from
        // the model's.
        assert!(case
            .injected
            .iter()
            .all(|i| i.signal >= blind::SIGNAL.0 * 0.9));
        let (o, _) = blind::run(&model, &case, &opts).expect("identification and diagnosis");
        println!("seed {seed}: {o:?}");
        o
    };
    let outcomes: Vec<_> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..2)
            .map(|_| {
                scope.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let seed = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        if seed > *SEEDS.end() {
                            break mine;
                        }
                        mine.push(case(seed));
                    }
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|w| w.join().expect("a blind worker"))
            .collect()
    });
    let r = blind::rates(&outcomes);
    println!("{r:?}");
    assert!(r.clean >= 3 && r.with_effects >= 5, "{r:?}");
    assert_eq!(r.false_add, 0.0, "something added to clean data: {r:?}");
    assert!(r.right_first >= RIGHT_FIRST, "{r:?}");
    assert!(r.exact >= EXACT, "{r:?}");
}

/// Share of the subset's cases with effects whose first added effect, or one it reports the
/// data cannot tell from it, is an injected one. The subset gets 14 of its 17 (seeds 1-24);
/// two cases of margin.
const RIGHT_FIRST: f64 = 0.70;
/// Share of the subset's cases that end with exactly the injected set. The subset gets 21 of 24
/// (19 before the short refits); two cases of margin.
const EXACT: f64 = 0.79;

#[test]
fn the_judge_matches_effects_by_kind_and_place() {
    let model = load_model("fwd32j.toml");
    let vars = load_variables("fwd32j.toml", &model);
    let lines = synthetic::fwd32j_lines();
    let clean = blind::draw(&model, &vars, &lines, 5, Some(true)).unwrap();
    assert!(clean.injected.is_empty());
    // Starts perturbed within ±30 % of the truth, inside the bounds.
    let truth: Vec<f64> = vars
        .vars
        .iter()
        .map(|v| model.value(v.targets[0].param).unwrap() / v.targets[0].ratio)
        .collect();
    // (A variable whose truth is 0 starts from its file's initial value, perturbed.)
    for ((v, x), v0) in clean.vars.vars.iter().zip(&truth).zip(&vars.vars) {
        let x = if *x != 0.0 { x } else { &v0.initial };
        assert!(
            (v.initial - x).abs() <= blind::PERTURBATION * x.abs() + 1e-12,
            "{}: {} vs {x}",
            v.name,
            v.initial
        );
    }
    assert!((blind::NOISE.0..blind::NOISE.1).contains(&clean.noise));
    let with = blind::draw(&model, &vars, &lines, 5, Some(false)).unwrap();
    assert!(!with.injected.is_empty());
    for i in &with.injected {
        assert!(blind::same_site(&model, &i.effect, &i.effect));
        assert!(
            (blind::SIGNAL.0 * 0.9..blind::SIGNAL.1 * 1.1).contains(&i.signal),
            "{i:?}"
        );
    }
    // A case drawn twice from its seed is the same case.
    let again = blind::draw(&model, &vars, &lines, 5, Some(false)).unwrap();
    assert_eq!(again.injected, with.injected);
    assert_eq!(
        again.data.characteristics[0].amplitude,
        with.data.characteristics[0].amplitude
    );
}

/// A moment stiffness acts on its bodies' relative rotation, the same at every point: the four
/// isolators' stiffnesses about their common vertical axis are one element, judged as one; their
/// stiffnesses along it (lever arms differ) and the actuator's about it (other bodies) are not.
#[test]
fn a_moment_stiffness_is_the_same_element_on_every_sde_joining_the_same_bodies() {
    let model = load_model("fwd32j.toml");
    let direction = |sde: &str, axis| diagnose::effects::Effect::Direction {
        sde: sde.into(),
        axis,
        held: 0.0,
        psi: 0.3,
        scale: 1e6,
    };
    // (SDE, direction 0-5) pairs and whether they are one element.
    let cases = [
        (("30", 3), ("31", 3), true),
        (("32", 5), ("33", 5), true),
        (("30", 0), ("31", 0), false),
        (("30", 3), ("31", 4), false),
        (("30", 3), ("34", 3), false),
    ];
    for ((a, i), (b, j), same) in cases {
        assert_eq!(
            blind::same_site(&model, &direction(a, i), &direction(b, j)),
            same,
            "SDE {a} direction {i} against SDE {b} direction {j}"
        );
    }
}

/// The suite's own yardstick for a miss: the truth's form (the model with exactly the hidden
/// effect), refitted from the identification's start with the effect at its true size, ends at
/// the noise level — J near half the number of residuals — and a fit without the effect is
/// judged to have missed it, while one within 3.84 in likelihood ratio of the truth is not.
#[test]
fn the_truth_s_own_form_fits_to_the_noise_and_judges_a_miss() {
    let model = load_model("fwd32j.toml");
    let vars = load_variables("fwd32j.toml", &model);
    let lines = synthetic::fwd32j_lines();
    let mass = diagnose::effects::Effect::Mass {
        body: "upper saddle".into(),
        point: nalgebra::Vector3::new(0.3, 0.68, 0.83),
        scale: 10.0,
    };
    let case = blind::with_effect(&model, &vars, &lines, &mass, (900.0, 0.02), 7)
        .unwrap()
        .expect("a 900-signal point mass");
    let opts = diagnose::Options::default();
    let truth = blind::truth_form(&model, &case, &[case.vars.initial()], &opts).unwrap();
    let m: usize = case
        .data
        .characteristics
        .iter()
        .map(|c| c.amplitude.len())
        .sum();
    let m = m as f64;
    assert!(
        truth < 0.5 * (m + 4.0 * (2.0 * m).sqrt()),
        "J {truth} for {m} residuals"
    );
    let obs = identify::data::validate(&case.data, &model, "blind case").unwrap();
    let without = identify::identify(
        &model,
        &obs,
        &case.vars,
        &opts.identification,
        &mut |_, _| {},
    )
    .unwrap();
    let m = m as usize;
    assert_eq!(
        blind::miss(without.criterion, truth, m),
        blind::Miss::Missed,
        "J {} without the mass, {truth} with it",
        without.criterion
    );
    assert_eq!(blind::miss(truth + 1.9, truth, m), blind::Miss::CannotTell);
    assert_eq!(blind::miss(truth + 2.0, truth, m), blind::Miss::Missed);
    // A truth's form that ends far above the noise gives no verdict.
    assert_eq!(
        blind::miss(truth, 10.0 * m as f64, m),
        blind::Miss::Undecided
    );
}

/// A large resonator scores nearly alike on a dozen bodies' points, and the screen puts another
/// body first: blind seed 3703's 61.5 kg resonator at 34.9 Hz on the overarm's centre scores
/// 37th and the round accepts it on the knee (J 152 where the truth refits at 33). Refitted at
/// every body's attachment points it is moved to the overarm, found alone and sized right.
#[test]
fn a_large_resonator_accepted_on_the_wrong_body_is_moved_to_its_own() {
    let (case, o, d) = diagnosed(3703);
    assert!(o.right_first && o.exact, "{o:?}");
    let first = &d.rounds[0];
    let accepted = &first.refits[first.accepted.unwrap()];
    assert!(!accepted.effect.contains("overarm"), "{}", accepted.effect);
    assert!(
        first.relocated.iter().any(|m| m.effect.contains("overarm")),
        "{:?}",
        first.relocated
    );
    // The resonator's mass and tuning against the injected ones, within 3 standard errors.
    let truth = &case.injected[0].values;
    for (p, x) in d.accepted[0].params.iter().zip(truth) {
        assert!(
            (p.value - x).abs() <= 3.0 * p.std_error,
            "{p:?} against {x}"
        );
    }
}

/// A joint's own ψ several times its group's changes the peaks far from linearly: blind seed
/// 3711's slideway ψ_t of 4.76 scores 261st (LM 3.7) and screens at J 63.7 against 65.9 before,
/// and nothing was added. The misfit is small but above the noise level, so every damping split
/// gets a short refit; this one ends at the noise level and is found alone, sized right.
#[test]
fn a_damping_split_the_score_misses_is_found_by_its_short_refit() {
    let (case, o, d) = diagnosed(3711);
    assert!(o.right_first && o.exact, "{o:?}");
    // The score alone would not have put it among the plausible candidates.
    let first = &d.rounds[0];
    let split = "psi_t for SDE 8, 9, 10, 11";
    assert!(
        !first
            .ranked
            .iter()
            .take(10)
            .any(|r| r.effect.contains(split) || r.equivalent.iter().any(|e| e.contains(split))),
        "{:?}",
        first.ranked
    );
    let truth = case.injected[0].values[0];
    let psi = &d.accepted[0].params[0];
    assert!(
        (psi.value - truth).abs() <= 3.0 * psi.std_error,
        "{psi:?} against {truth}"
    );
}

/// An SDE's missing stiffness is taken for a spring between the two bodies it joins: blind seed
/// 3818's SDE 12 (the column-knee screw) lacks 1518 N/µm along its axis 2, and round 1 accepts a
/// spring between the column and the knee at the noise level (J 50.9), never refitting the SDE's
/// own direction. Once nothing more is significant, the swap tries the other kinds on the column
/// and the knee and replaces the spring by the SDE's direction (J 46.0, one parameter fewer).
#[test]
fn an_sde_stiffness_taken_for_a_spring_between_its_bodies_is_swapped_for_it() {
    let (case, o, d) = diagnosed(3818);
    assert!(o.exact, "{o:?}");
    let first = &d.rounds[0];
    let accepted = &first.refits[first.accepted.unwrap()];
    assert_eq!(accepted.kind, "spring", "{}", accepted.effect);
    let replaced: Vec<_> = d.rounds.iter().flat_map(|r| &r.replaced).collect();
    assert_eq!(replaced.len(), 1, "{replaced:?}");
    assert!(
        replaced[0].effect.contains("spring column–knee"),
        "{replaced:?}"
    );
    assert_eq!(d.accepted.len(), 1);
    assert_eq!(
        d.accepted[0].kind, "SDE direction",
        "{}",
        d.accepted[0].effect
    );
    // The stiffness against the injected one, within 3 standard errors.
    let truth = case.injected[0].values[0];
    let k = &d.accepted[0].params[0];
    assert!(
        (k.value - truth).abs() <= 3.0 * k.std_error,
        "{k:?} against {truth}"
    );
}

/// A weak spring to the ground along x moves the whole machine on its isolators, and the data
/// cannot tell on which body it acts: blind seed 3883's 0.52 N/µm under the spindle head refits
/// there to J 38.8, and on the overarm to J 37.4. The diagnosis accepts the overarm's and reports
/// the truth among the effects the data cannot tell from it ("≡"), which the truth's own form
/// refitted confirms (within LR 3.84 of the answer).
#[test]
fn a_weak_spring_to_the_ground_is_reported_with_the_places_the_data_cannot_tell_apart() {
    let (case, o, d) = diagnosed(3883);
    assert!(!o.named_first && o.right_first, "{o:?}");
    let alike: Vec<String> = d.accepted[0]
        .equivalent
        .iter()
        .map(|e| e.describe())
        .collect();
    assert!(
        d.accepted[0]
            .equivalent
            .iter()
            .any(|e| blind::found(&d.model, &case.injected[0], e, &[])),
        "{alike:?}"
    );
    assert!(
        diagnose::text(&d).contains("≡ the data cannot tell it from: "),
        "{}",
        diagnose::text(&d)
    );
    let model = load_model("fwd32j.toml");
    let starts = [d.estimate.clone(), case.vars.initial()];
    let opts = diagnose::Options::default();
    let truth = blind::truth_form(&model, &case, &starts, &opts).unwrap();
    assert_eq!(
        blind::miss(d.after.criterion, truth, d.after.observations),
        blind::Miss::CannotTell,
        "J {} against the truth's {truth}",
        d.after.criterion
    );
}

/// An SDE's missing stiffness the data cannot tell from a spring between its bodies: blind seed
/// 3923's SDE 29 lacks 7131 N/µm along its axis 2, and round 1 accepts a spring between the knee
/// and the lower saddle. The SDE's direction, refitted in full in the swap step, ends a little
/// above it with one parameter fewer: no swap, but it is listed among the spring's equivalents.
#[test]
fn an_sde_stiffness_the_data_cannot_tell_from_a_spring_is_listed_with_it() {
    let (case, o, d) = diagnosed(3923);
    assert!(!o.named_first && o.right_first, "{o:?}");
    assert_eq!(d.accepted.len(), 1);
    assert_eq!(d.accepted[0].kind, "spring", "{}", d.accepted[0].effect);
    assert!(d.rounds.iter().all(|r| r.replaced.is_empty()));
    // SDE 29's direction is listed by the swap step: no round refitted it.
    assert!(!d
        .rounds
        .iter()
        .flat_map(|r| &r.refits)
        .any(|r| r.effect.starts_with("SDE 29:")));
    assert!(
        d.accepted[0]
            .equivalent
            .iter()
            .any(|e| blind::found(&d.model, &case.injected[0], e, &[])),
        "{:?}",
        d.accepted[0].equivalent
    );
}

/// Blind case `seed` drawn on FWD-32J and diagnosed with the default options.
fn diagnosed(seed: u64) -> (blind::BlindCase, blind::Outcome, diagnose::Diagnosis) {
    let model = load_model("fwd32j.toml");
    let vars = load_variables("fwd32j.toml", &model);
    let lines = synthetic::fwd32j_lines();
    let case = blind::draw(&model, &vars, &lines, seed, None).unwrap();
    let (o, d) = blind::run(&model, &case, &diagnose::Options::default()).unwrap();
    (case, o, d)
}
