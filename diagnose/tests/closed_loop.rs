//! Closing the loop on the FWD-32J model: data generated from a truth with an effect the
//! identification model does not declare (the paper's hydraulic actuator, an added mass on the
//! table, a table that is not rigid) must be diagnosed — the true effect ranked first, added, and
//! the refit at the noise floor; data without such an effect must get nothing added. Seeded.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

#[path = "../../identify/tests/common/mod.rs"]
mod common;

use common::{load_model, load_variables};
use diagnose::{diagnose, Effect};
use identify::{self as idn, data, variables, Options};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rfe::frf::{self, Method};
use rfe::measured::MeasuredData;
use rfe::model::Model;

/// The FWD-32J measurement (38 log-spaced lines, 20-400 Hz, per table characteristic), amplitude
/// with relative noise `rel` and its stated variance.
fn measure(truth: &Model, rel: f64, seed: u64) -> MeasuredData {
    common::fwd32j_data(truth, rel, &mut StdRng::seed_from_u64(seed))
}

struct Case {
    model: Model,
    vars: variables::Variables,
    obs: idn::Observations,
    id: idn::Identification,
}

fn fit(model_file: &str, vars_file: &str, data: &MeasuredData) -> Case {
    let model = load_model(model_file);
    let vars = load_variables(vars_file, &model);
    let obs = data::validate(data, &model, "synthetic").expect("data");
    let id = idn::identify(&model, &obs, &vars, &Options::default(), &mut |_, _| {})
        .expect("identification");
    Case {
        model,
        vars,
        obs,
        id,
    }
}

fn run(c: &Case) -> diagnose::Diagnosis {
    let d = diagnose(
        &c.model,
        &c.obs,
        &c.vars,
        &c.id,
        &diagnose::Options::default(),
        &mut |_| {},
    )
    .expect("diagnosis");
    println!("{}", diagnose::text(&d));
    d
}

#[test]
fn the_missing_hydraulic_actuator_is_found_added_and_the_fit_reaches_the_noise_floor() {
    let truth = load_model("fwd32j.toml");
    let data = measure(
        &truth,
        0.01,
        std::env::var("IDENT_SUPPORT_SEED")
            .map(|v| v.parse().unwrap())
            .unwrap_or(11),
    );
    let case = fit("fwd32j-no-actuator.toml", "fwd32j-no-actuator.toml", &data);
    let d = run(&case);
    assert!(
        !d.before.explained,
        "the model without the actuator should not explain the data"
    );
    // The actuator: a spring between spindle head and table at the excitation point along the
    // excitation direction. Placements the data cannot tell apart form the first family.
    let actuator = "spring spindle head–table at (0, 900, 1150) mm along (0.494, 0.855, 0.156)";
    let first = &d.rounds[0].ranked[0];
    assert_eq!(first.kind, "spring", "ranked first: {}", first.effect);
    assert!(
        first.effect == actuator || first.equivalent.iter().any(|e| e == actuator),
        "ranked first: {first:?}"
    );
    let added = d.accepted.first().expect("an effect is added");
    assert!(
        added.effect == actuator || added.equivalent.iter().any(|e| e.describe() == actuator),
        "added: {added:?}"
    );
    // Its stiffness: the truth is 0.5639 N/µm.
    let k = &added.params[0];
    assert!(
        (k.value - 0.5639e6).abs() < 3.0 * k.std_error,
        "k = {} ± {}",
        k.value,
        k.std_error
    );
    assert_eq!(d.accepted.len(), 1, "nothing else should be added");
    // Its family's refit reaches the noise level, so round 1 refits the leading families only
    // (the score's leader among them), not also each kind they leave out.
    let leading = diagnose::Options::default().refit + 1;
    assert!(
        d.rounds[0].refits.len() <= leading,
        "round 1 refitted {} families: {:?}",
        d.rounds[0].refits.len(),
        d.rounds[0]
            .refits
            .iter()
            .map(|r| &r.effect)
            .collect::<Vec<_>>()
    );
    assert_eq!(
        d.outside_library, None,
        "explained: no outside-the-library verdict"
    );
    assert!(
        d.after.chi2_p.expect("R is known") > 0.001,
        "after: {}",
        d.after.verdict
    );
    for (b, a) in d
        .before
        .characteristics
        .iter()
        .zip(&d.after.characteristics)
    {
        assert!(
            a.rms_relative < 0.02 && a.rms_relative < b.rms_relative,
            "{}: {} → {}",
            a.label,
            b.rms_relative,
            a.rms_relative
        );
    }
    assert!(matches!(d.effects[0], Effect::Spring { .. }));
    // The final model is what a reader gets first: its variables at the final fit, with their
    // errors there. The first fit compensated for the missing actuator with nonsense; the final
    // values of the screws' stiffnesses are the truth's within three standard errors.
    let text = diagnose::final_text(&case.id, &d);
    assert!(
        text.starts_with("FINAL MODEL: the first fit above is superseded; 1 effect(s) added"),
        "{text}"
    );
    assert!(text.contains("\n  + spring spindle head–"), "{text}");
    assert_eq!(d.std_error.len(), case.vars.len());
    for name in ["k 22", "k 29"] {
        let i = case
            .vars
            .vars
            .iter()
            .position(|v| v.name == name)
            .expect(name);
        let t = case.vars.vars[i].targets[0];
        let p = t.param.sde().expect("an SDE parameter");
        let sde = &case.model.sdes[p.sde].name;
        let want = truth.sdes[truth.sde_index(sde).expect("in the truth")]
            .law
            .get(p.name)
            .expect("a parameter of the truth")
            / t.ratio;
        let (x, se) = (d.estimate[i], d.std_error[i]);
        assert!(
            se.is_finite() && se > 0.0 && (x - want).abs() < 3.0 * se,
            "{name}: final {x} ± {se}, truth {want}; first fit {}",
            case.id.estimate[i]
        );
        assert!(text.contains(&format!("\n  {name:<20}")), "{text}");
    }
}

/// A support under the table the model lacks: a vertical spring (2 N/µm, ψ 0.3) from the ground
/// to the table's underside near its end, at (570, 980, 830) mm — not a candidate point.
fn with_support(mut m: Model) -> Model {
    use nalgebra::Vector3;
    use rfe::model::{Sde, SdeKind, SdeLaw};
    use rfe::modelfile::frame_from_axis;
    let table = m.body_index("table").unwrap();
    m.sdes.push(Sde {
        name: "support".into(),
        kind: SdeKind::Spring,
        bodies: [None, Some(table)],
        point: Vector3::new(0.57, 0.98, 0.83),
        rotation: frame_from_axis(&Vector3::z()),
        law: SdeLaw::Axial { k: 2.0e6, psi: 0.3 },
        enabled: true,
    });
    m
}

#[test]
fn an_unmodelled_support_under_the_table_is_found_and_the_refit_reaches_the_noise_floor() {
    let truth = with_support(load_model("fwd32j.toml"));
    let case = fit(
        "fwd32j.toml",
        "fwd32j.toml",
        &measure(
            &truth,
            0.01,
            std::env::var("IDENT_SUPPORT_SEED")
                .map(|v| v.parse().unwrap())
                .unwrap_or(11),
        ),
    );
    let d = run(&case);
    assert!(!d.before.explained);
    // One effect: a vertical spring from the ground, to the table or to a saddle it rests on (the
    // table's joints to the saddles are stiff: the data hardly tell those apart), at the nearest
    // candidate and then with its line of action fitted. (The place is poorly determined by the
    // table's three translations, σ ≈ 0.1-0.15 m; on the table, k agrees with the truth within
    // 4σ: the uncertain place biases it a little.) Seeds 1-7 and 11 pass
    // (`IDENT_SUPPORT_SEED=N`).
    assert_eq!(d.accepted.len(), 1, "{}", diagnose::text(&d));
    let a = &d.accepted[0];
    let host_ok = [
        "spring ground–table",
        "spring ground–lower saddle",
        "spring ground–upper saddle",
    ]
    .iter()
    .any(|h| a.effect.starts_with(h));
    assert!(
        host_ok && a.effect.contains("along (0, 0, 1)"),
        "{}",
        a.effect
    );
    if a.effect.starts_with("spring ground–table") {
        let k = &a.params[0];
        assert!(
            (k.value - 2.0e6).abs() < 4.0 * k.std_error,
            "k = {} ± {} N/m, truth 2e6",
            k.value,
            k.std_error
        );
    }
    assert!(
        d.after.chi2_p.expect("R known") > 0.001,
        "after: {}",
        d.after.verdict
    );
}

/// A 20 kg fixture bolted to a corner of the table: a body on a mount stiff enough to be rigid
/// in the band (built here, independently of the diagnosis' own realization).
fn with_fixture(mut m: Model, kg: f64) -> Model {
    use nalgebra::{Matrix3, Vector3};
    use rfe::{Body, Sde, SdeKind, SdeLaw};
    let table = m.body_index("table").expect("table");
    let p = Vector3::new(0.55, 1.02, 0.95);
    let j = kg * 0.05f64.powi(2);
    m.bodies.push(Body {
        name: "fixture".into(),
        mass: kg,
        inertia: [j; 3],
        position: p,
        rotation: Matrix3::identity(),
    });
    let b = m.bodies.len() - 1;
    let (kt, kr) = (1.0e11, 1.0e9);
    m.sdes.push(Sde {
        name: "fixture bolts".into(),
        kind: SdeKind::General,
        bodies: [Some(table), Some(b)],
        point: p,
        rotation: Matrix3::identity(),
        law: SdeLaw::General {
            k: [kt, kt, kt, kr, kr, kr],
            psi: [0.05; 6],
        },
        enabled: true,
    });
    m
}

/// The table as five RFEs along its length joined by four elastic beam sections of Young's
/// modulus `e` (Pa) — a different discretization from the diagnosis' three-RFE candidate. The
/// centre piece keeps the name "table": the characteristics stay the motion at its centre.
fn with_flexible_table(mut m: Model, e: f64) -> Model {
    use nalgebra::Vector3;
    use rfe::{Body, Sde, SdeKind, SdeLaw};
    const PIECES: usize = 5;
    let t = m.body_index("table").expect("table");
    let table = m.bodies[t].clone();
    let (lx, ly, lz) = (1.25, 0.32, 0.12);
    let mass = table.mass / PIECES as f64;
    let seg = lx / PIECES as f64;
    let inertia = [
        mass * (ly * ly + lz * lz) / 12.0,
        mass * (seg * seg + lz * lz) / 12.0,
        mass * (seg * seg + ly * ly) / 12.0,
    ];
    let mut idx = Vec::new();
    for i in 0..PIECES {
        let x = (i as f64 - (PIECES as f64 - 1.0) / 2.0) * seg;
        let body = Body {
            name: format!("table piece {i}"),
            mass,
            inertia,
            position: table.position + Vector3::new(x, 0.0, 0.0),
            rotation: table.rotation,
        };
        if i == PIECES / 2 {
            m.bodies[t] = Body {
                name: "table".into(),
                ..body
            };
            idx.push(t);
        } else {
            m.bodies.push(body);
            idx.push(m.bodies.len() - 1);
        }
    }
    let piece = |x: f64| -> usize {
        idx[(((x - table.position.x) / seg + PIECES as f64 / 2.0)
            .floor()
            .clamp(0.0, PIECES as f64 - 1.0)) as usize]
    };
    for s in m.sdes.iter_mut() {
        for side in 0..2 {
            if s.bodies[side] == Some(t) {
                s.bodies[side] = Some(piece(s.point.x));
            }
        }
    }
    for f in m.forces.iter_mut().filter(|f| f.body == t) {
        f.body = piece(f.point.x);
    }
    for i in 0..PIECES - 1 {
        let x = table.position.x + (i as f64 + 1.0 - PIECES as f64 / 2.0) * seg;
        m.sdes.push(Sde {
            name: format!("table section {i}"),
            kind: SdeKind::General,
            bodies: [Some(idx[i]), Some(idx[i + 1])],
            point: Vector3::new(x, table.position.y, table.position.z),
            rotation: table.rotation,
            // Beam section of length `seg`: axial EA/L, shear GA/L, torsion GJ/L, bending EI/L.
            law: SdeLaw::General {
                k: [
                    e * ly * lz / seg,
                    0.4 * e * ly * lz / seg,
                    0.4 * e * ly * lz / seg,
                    0.4 * e * 0.229 * ly * lz.powi(3) / seg,
                    e * ly * lz.powi(3) / 12.0 / seg,
                    e * lz * ly.powi(3) / 12.0 / seg,
                ],
                psi: [0.06; 6],
            },
            enabled: true,
        });
    }
    m
}

#[test]
fn a_fixture_mass_on_the_table_is_found_and_the_refit_reaches_the_noise_floor() {
    let truth = with_fixture(load_model("fwd32j.toml"), 20.0);
    let case = fit("fwd32j.toml", "fwd32j.toml", &measure(&truth, 0.01, 5));
    let d = run(&case);
    assert!(!d.before.explained);
    // One effect: a point mass on the table. The truth's point (550, 1020, 950) mm is not a
    // candidate: the nearest candidate corner is accepted, then its position is fitted, and
    // mass and place must agree with the truth within 3 standard errors.
    assert_eq!(d.accepted.len(), 1, "{}", diagnose::text(&d));
    let first = &d.accepted[0];
    assert_eq!(first.kind, "mass", "first added: {first:?}");
    assert!(
        first.effect.contains("on table") && first.effect.contains("position fitted"),
        "first added: {}",
        first.effect
    );
    // The placed effect is named after the candidate corner it started from ("… near (x, y, z)
    // mm …"), whichever round accepted it (an earlier round may accept a stand-in that the
    // backward check later removes).
    let corner: Vec<f64> = first
        .effect
        .split(" near (")
        .nth(1)
        .unwrap()
        .split(") mm")
        .next()
        .unwrap()
        .split(", ")
        .map(|v| v.parse::<f64>().unwrap() / 1e3)
        .collect();
    let truth = [20.0, 0.55 - corner[0], 1.02 - corner[1], 0.95 - corner[2]];
    for (p, t) in first.params.iter().zip(truth) {
        assert!(
            (p.value - t).abs() < 3.0 * p.std_error,
            "{} = {} ± {} {}, truth {t}",
            p.name,
            p.value,
            p.std_error,
            p.unit
        );
    }
    // The reported place is the fitted point (not the corner it started from), and its 95 %
    // region holds the truth's point to within its half-widths (1.5× for a 3-axis box at 95 %).
    let place = first
        .place
        .as_deref()
        .expect("a placed mass reports its fitted place");
    let numbers = |text: &str| -> Vec<f64> {
        text.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-'))
            .filter_map(|v| v.parse::<f64>().ok())
            .collect()
    };
    let fitted = numbers(place.split(" mm").next().unwrap());
    let region = numbers(place.split('±').nth(1).unwrap());
    assert_eq!((fitted.len(), region.len()), (3, 3), "{place}");
    for ((at, half), truth) in fitted.iter().zip(&region).zip([550.0, 1020.0, 950.0]) {
        assert!(
            (at - truth).abs() <= 1.5 * half,
            "{place}: truth {truth} mm"
        );
    }
    assert!(
        diagnose::text(&d).contains(place),
        "the added: line names the place"
    );
    assert!(
        d.after.chi2_p.expect("R known") > 0.001,
        "after: {}",
        d.after.verdict
    );
    for a in &d.after.characteristics {
        assert!(a.rms_relative < 0.02, "{}: {}", a.label, a.rms_relative);
    }
}

/// Whole-model check of the flexible-body candidate: at a vanishing compliance the split model
/// is the rigid one (its three thirds sum to the body's mass and inertia), and a finite one
/// changes the response.
#[test]
fn a_body_split_at_vanishing_compliance_is_the_rigid_body() {
    let m = load_model("fwd32j.toml");
    let freqs: Vec<f64> = (0..30).map(|i| 20.0 + 13.0 * i as f64).collect();
    let rigid = frf::response(&m, &freqs, &[], Method::Direct).unwrap();
    for axis in 0..3 {
        // The difference shrinks in proportion to the compliance (c · stiffness of the model).
        let diff = |c: f64| {
            let mut split = m.clone();
            diagnose::effects::split_body(&mut split, "table", axis, c).unwrap();
            assert_eq!(split.bodies.len(), m.bodies.len() + 2);
            let r = frf::response(&split, &freqs, &[], Method::Direct).unwrap();
            rigid
                .values
                .iter()
                .zip(&r.values)
                .map(|(a, b)| (a - b).norm() / a.norm())
                .fold(0.0, f64::max)
        };
        // (Far stiffer joints only add round-off: the LU then mixes 1e17 N/m with ω²m.)
        let (d11, d12, d13) = (diff(1e-12), diff(1e-13), diff(1e-14));
        assert!(
            d12 < d11 / 5.0 && d13 < d12 / 5.0 && d13 < 1e-3,
            "axis {axis}: {d11:e}, {d12:e}, {d13:e} at 1e-12, 1e-13, 1e-14 m/N"
        );
        let mut soft = m.clone();
        diagnose::effects::split_body(&mut soft, "table", axis, 1e-8).unwrap();
        let r = frf::response(&soft, &freqs, &[], Method::Direct).unwrap();
        let change = rigid
            .values
            .iter()
            .zip(&r.values)
            .map(|(a, b)| (a - b).norm() / a.norm())
            .fold(0.0, f64::max);
        assert!(
            change > 1e-3,
            "axis {axis}: a 10 nm/N joint should show, max change {change}"
        );
    }
}

/// No undeclared effect: nothing may be added beyond the chosen false-alarm rate. The default
/// is 8 seeds; `IDENT_FALSE_ALARM_SEEDS=100` measures the rate over more.
#[test]
fn data_without_an_undeclared_effect_gets_nothing_added() {
    let seeds: u64 = std::env::var("IDENT_FALSE_ALARM_SEEDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(8);
    let truth = load_model("fwd32j.toml");
    let opts = diagnose::Options::default();
    let mut alarms = 0;
    for seed in 0..seeds {
        let case = fit(
            "fwd32j.toml",
            "fwd32j.toml",
            &measure(&truth, 0.01, 1000 + seed),
        );
        let d = diagnose(
            &case.model,
            &case.obs,
            &case.vars,
            &case.id,
            &opts,
            &mut |_| {},
        )
        .expect("diagnosis");
        if !d.accepted.is_empty() {
            alarms += 1;
            println!("seed {seed}: added {}", d.accepted[0].effect);
        } else {
            // Nothing added: the final model is the first fit, and the text says so.
            let text = diagnose::final_text(&case.id, &d);
            assert!(
                text.starts_with("FINAL MODEL = the first fit above: the diagnosis added nothing"),
                "{text}"
            );
            assert!(d.std_error.is_empty());
        }
    }
    println!("false alarms: {alarms} of {seeds} at α = {}", opts.alpha);
    // Binomial(seeds, α): more than this has probability < 0.5 %.
    let allowed = 1 + (seeds as f64 * opts.alpha * 3.0).ceil() as usize;
    assert!(
        alarms <= allowed,
        "{alarms} false alarms in {seeds} data sets at α = {}",
        opts.alpha
    );
}

/// A table that is not rigid: a stiff ribbed table (five-RFE beam, E = 1.2e12 Pa equivalent)
/// whose bending shows in the band.
#[test]
fn a_table_that_is_not_rigid_is_found_and_the_refit_reaches_the_noise_floor() {
    let truth = with_flexible_table(load_model("fwd32j.toml"), 1.2e12);
    let case = fit("fwd32j.toml", "fwd32j.toml", &measure(&truth, 0.01, 5));
    let d = run(&case);
    assert!(!d.before.explained);
    let first = &d.rounds[0].ranked[0];
    assert_eq!(
        first.effect, "table not rigid: three RFEs along its principal axis 1",
        "{first:?}"
    );
    assert_eq!(
        d.accepted.first().map(|a| a.effect.as_str()),
        Some(first.effect.as_str())
    );
    assert!(
        d.after.chi2_p.expect("R known") > 0.001,
        "after: {}",
        d.after.verdict
    );
}

/// Data whose amplitudes carry a ripple along frequency that no element of a rigid-body model
/// makes (a sensor's own resonance-free frequency response, say): the diagnosis must end by saying
/// plainly that an effect outside its library remains, where, and on which characteristics —
/// whatever partial fixes it tried.
#[test]
fn a_misfit_no_candidate_explains_is_reported_as_outside_the_library() {
    let truth = load_model("fwd32j.toml");
    let mut data = measure(&truth, 0.01, 5);
    for c in &mut data.characteristics {
        for (a, f) in c.amplitude.iter_mut().zip(&c.freqs_hz) {
            *a *= 1.0 + 0.2 * (2.0 * std::f64::consts::PI * f.log10() / 0.25).sin();
        }
    }
    let case = fit("fwd32j.toml", "fwd32j.toml", &data);
    let d = run(&case);
    assert!(!d.after.explained, "after: {}", d.after.verdict);
    let verdict = d
        .outside_library
        .as_deref()
        .expect("an outside-the-library verdict");
    assert!(verdict.starts_with("OUTSIDE THE LIBRARY"), "{verdict}");
    assert!(
        verdict.contains("table u"),
        "names the characteristics: {verdict}"
    );
    assert!(
        diagnose::final_text(&case.id, &d).contains("OUTSIDE THE LIBRARY"),
        "the final-model lines say it too"
    );
}
