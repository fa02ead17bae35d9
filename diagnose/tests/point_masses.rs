//! Point masses declared in the model (`[[point_mass]]`: sensors, the force gauge, fixtures):
//! their exact 6×6 block against a hand computation and against the composite rigid body, the
//! mass as a decision variable (Jacobian against finite differences, recovered by a fit, written
//! back), the JSON contract, and the model file's errors.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

#[path = "../../identify/tests/common/mod.rs"]
mod common;

use identify::{self as idn, data, synthetic, variables};
use nalgebra::{Matrix3, Vector3};
use rfe::frf::{response, response_params, Method};
use rfe::model::{Model, Param};
use rfe::modelfile::parse_toml;
use rfe::system::System;

/// A 10 kg plate (centre at the origin, principal axes global) on a general mount to the
/// ground, a 2 kg sensor block at (100, 50, 20) mm with 1e-4 kg·m² of its own about each axis,
/// a force at a point, and point outputs (`outputs`) plus a shaker-table reference.
fn plate(extra: &str) -> String {
    format!(
        r#"
name = "plate with a sensor"

[[body]]
name = "plate"
mass = "10 kg"
position = "0 0 0 mm"
inertia = "0.05 0.08 0.12 kg m^2"

[[sde]]
name = "mount"
kind = "general"
bodies = ["ground", "plate"]
point = "20 -30 -50 mm"
axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
k = ["2 N/um", "3 N/um", "5 N/um", "2e4 N*m/rad", "3e4 N*m/rad", "4e4 N*m/rad"]
psi = 0.05

[[excitation.force]]
body = "plate"
point = "-40 20 10 mm"
force = [0.3, 0.5, 0.8]

[[reference]]
name = "table"
base_motion = [0, 0.6, 0.8]

[[output]]
body = "plate"
point = "100 50 20 mm"
direction = [0, 0, 1]

[[output]]
body = "plate"
point = "-80 60 0 mm"
direction = [1, 1, 0]

[[output]]
body = "plate"
point = "30 -70 10 mm"
direction = [0, 1, 0]
quantity = "acceleration"

[[output]]
body = "plate"
point = "100 50 20 mm"
direction = [0, 0, 1]
reference = "table"
{extra}"#
    )
}

const SENSOR: &str = r#"
[[point_mass]]
name = "sensor"
body = "plate"
point = "100 50 20 mm"
mass = "2 kg"
inertia = "1e-4 kg m^2"
note = "accelerometer on its mounting block"
"#;

fn model(extra: &str) -> Model {
    parse_toml(&plate(extra), "plate.toml").unwrap().model
}

#[test]
fn a_point_mass_adds_its_hand_computed_block() {
    let s = System::assemble(&model(SENSOR));
    // Arm a = (0.1, 0.05, 0.02) m from the plate's centre, m = 2 kg, J = 1e-4 kg·m².
    // Diagonal: m, m, m; J_plate + m (|a|² − a_i²) + J.
    let want_diag = [
        12.0,
        12.0,
        12.0,
        0.05 + 2.0 * (0.05f64.powi(2) + 0.02f64.powi(2)) + 1e-4,
        0.08 + 2.0 * (0.1f64.powi(2) + 0.02f64.powi(2)) + 1e-4,
        0.12 + 2.0 * (0.1f64.powi(2) + 0.05f64.powi(2)) + 1e-4,
    ];
    for (i, w) in want_diag.iter().enumerate() {
        assert!(
            (s.mass[i] - w).abs() < 1e-15,
            "M[{i}][{i}] {} vs {w}",
            s.mass[i]
        );
    }
    // Couplings: the sensor's velocity is u̇ + θ̇ × a, so M(u_i, r_j) = m ε_ijk a_k ... written out:
    // M(u1,r2) = m a3, M(u1,r3) = −m a2, M(u2,r1) = −m a3, M(u2,r3) = m a1, M(u3,r1) = m a2,
    // M(u3,r2) = −m a1; rotations: M(r_i, r_j) = −m a_i a_j.
    let (a1, a2, a3) = (0.1, 0.05, 0.02);
    let m = 2.0;
    let want: &[(usize, usize, f64)] = &[
        (0, 4, m * a3),
        (0, 5, -m * a2),
        (1, 3, -m * a3),
        (1, 5, m * a1),
        (2, 3, m * a2),
        (2, 4, -m * a1),
        (3, 4, -m * a1 * a2),
        (3, 5, -m * a1 * a3),
        (4, 5, -m * a2 * a3),
    ];
    let at = |i: usize, j: usize| {
        s.mass_coupling
            .iter()
            .find(|c| c.0 == i && c.1 == j)
            .map_or(0.0, |c| c.2)
    };
    for &(i, j, w) in want {
        assert!(
            (at(i, j) - w).abs() < 1e-15,
            "M[{i}][{j}] {} vs {w}",
            at(i, j)
        );
        assert_eq!(at(i, j), at(j, i), "symmetric");
    }
    assert_eq!(
        s.mass_coupling.len(),
        2 * want.len(),
        "{:?}",
        s.mass_coupling
    );
}

/// The plate and the sensor as one rigid body: mass, centre and inertia tensor by the
/// parallel-axis theorem, written as a `[[body]]` with `inertia_tensor`.
fn composite_body() -> String {
    let (mp, ms) = (10.0, 2.0);
    let a = Vector3::new(0.1, 0.05, 0.02);
    let c = a * ms / (mp + ms);
    let shift =
        |m: f64, r: Vector3<f64>| (Matrix3::identity() * r.norm_squared() - r * r.transpose()) * m;
    let j = Matrix3::from_diagonal(&Vector3::new(0.05, 0.08, 0.12))
        + shift(mp, -c)
        + Matrix3::identity() * 1e-4
        + shift(ms, a - c);
    let row = |i: usize| format!("[{:?}, {:?}, {:?}]", j[(i, 0)], j[(i, 1)], j[(i, 2)]);
    format!(
        "[[body]]\nname = \"plate\"\nmass = {:?}\nposition = [{:?}, {:?}, {:?}]\ninertia_tensor = [{}, {}, {}]\n",
        mp + ms,
        c.x,
        c.y,
        c.z,
        row(0),
        row(1),
        row(2)
    )
}

#[test]
fn a_point_mass_gives_the_frequency_response_of_the_composite_rigid_body() {
    let with = model(SENSOR);
    let text = plate("");
    let start = text.find("[[body]]").unwrap();
    let end = text.find("[[sde]]").unwrap();
    let composite = format!("{}{}{}", &text[..start], composite_body(), &text[end..]);
    let composite = parse_toml(&composite, "composite.toml").unwrap().model;
    // The composite body's principal axes are not the global ones: its DOFs differ, its point
    // outputs are the same physical readings.
    assert!(
        (composite.bodies[0].rotation - Matrix3::identity())
            .abs()
            .max()
            > 1e-3
    );
    let f: Vec<f64> = synthetic::log_lines(5.0, 400.0, 60);
    let want = response(&composite, &f, &[], Method::Direct).unwrap();
    for method in [Method::Direct, Method::Modal] {
        let got = response(&with, &f, &[], method).unwrap();
        for o in 0..with.outputs.len() {
            for (k, (g, w)) in got.output(o).iter().zip(want.output(o)).enumerate() {
                assert!(
                    (g - w).norm() <= 1e-9 * w.norm(),
                    "{method:?} output {o} at {} Hz: {g} vs {w}",
                    f[k]
                );
            }
        }
    }
    // Modes: the same frequencies and loss factors.
    let (a, b) = (
        rfe::modes::complex(&with).unwrap(),
        rfe::modes::complex(&composite).unwrap(),
    );
    for (x, y) in a.iter().zip(&b) {
        assert!(
            (x.freq_hz / y.freq_hz - 1.0).abs() < 1e-9,
            "{} vs {}",
            x.freq_hz,
            y.freq_hz
        );
        assert!((x.loss_factor - y.loss_factor).abs() < 1e-9);
        assert!((x.energy.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }
    let u = rfe::modes::undamped(&with).unwrap();
    for (x, y) in u.iter().zip(&b) {
        assert!(
            (x.freq_hz / y.freq_hz - 1.0).abs() < 1e-9,
            "{} vs {}",
            x.freq_hz,
            y.freq_hz
        );
    }
}

#[test]
fn a_point_mass_jacobian_matches_finite_differences_on_both_paths_and_under_base_motion() {
    let model = model(SENSOR);
    let p = Param::PointMass { index: 0 };
    assert_eq!(model.value(p), Some(2.0));
    assert_eq!(model.label(p), "point mass sensor m");
    let f = [3.0, 40.0, 90.0, 150.0, 420.0];
    let h = 1e-4;
    let eval = |x: f64| {
        let mut m = model.clone();
        assert!(m.set_value(p, x));
        response(&m, &f, &[], Method::Direct).unwrap()
    };
    let (up, down) = (eval(2.0 + h), eval(2.0 - h));
    for method in [Method::Direct, Method::Modal] {
        let r = response_params(&model, &f, &[p], method).unwrap();
        for o in 0..model.outputs.len() {
            for (k, fk) in f.iter().enumerate() {
                // A is affine in the mass: the central difference is exact up to rounding.
                let fd = (up.output(o)[k] - down.output(o)[k]) / (2.0 * h);
                let an = r.derivative(0, o)[k];
                assert!(
                    (fd - an).norm() <= 1e-6 * an.norm() + 1e-9 * up.output(o)[k].norm(),
                    "{method:?} output {o} at {fk} Hz: {an} vs {fd}"
                );
            }
        }
    }
}

const VARS: &str = r#"
[[variable]]
point_masses = "sensor"
parameter = "m"
initial = "1.9 kg"

[[variable]]
sdes = "mount"
parameter = "k3"
initial = "4.8 N/um"
"#;

#[test]
fn a_point_mass_is_identified_and_written_back() {
    let truth = model(SENSOR);
    let start = model(&SENSOR.replace("2 kg", "1.9 kg"));
    let lines = synthetic::log_lines(10.0, 300.0, 50);
    let mut d = synthetic::amplitude_data(&truth, &lines, 0.0, || 0.0).unwrap();
    for c in &mut d.characteristics {
        c.variance = None;
    }
    let obs = data::validate(&d, &start, "exact").unwrap();
    let vars = variables::parse(VARS, "vars.toml", &start).unwrap();
    assert_eq!(vars.vars[0].unit.symbol, "kg");
    assert_eq!(vars.vars[0].sdes, "point mass sensor");
    let id = common::identify_at_one_percent_noise(&start, &obs, &vars);
    assert!(
        (id.estimate[0] / 2.0 - 1.0).abs() < 1e-6,
        "{:?} {} after {} iterations, J = {}",
        id.estimate,
        id.stop.describe(),
        id.iterations,
        id.criterion
    );
    assert!(
        (id.estimate[1] / 5e6 - 1.0).abs() < 1e-6,
        "{:?}",
        id.estimate
    );
    assert!((id.model.point_masses[0].mass - id.estimate[0]).abs() < 1e-12);
    // Written back into the file's own [[point_mass]], which loads to the fitted model.
    let text = plate(&SENSOR.replace("2 kg", "1.9 kg"));
    let back = idn::report::update_toml(&text, "plate.toml", &id).unwrap();
    let reloaded = parse_toml(&back, "back.toml").unwrap().model;
    assert!((reloaded.point_masses[0].mass / id.estimate[0] - 1.0).abs() < 1e-11);
    assert!(back.contains("note = \"accelerometer on its mounting block\""));
    let source = diagnose::final_model::Source {
        origin: "plate.toml",
        text: Some(&text),
    };
    let fin = diagnose::final_model::model_toml(source, &id, None).unwrap();
    let reloaded = parse_toml(&fin, "final.toml").unwrap().model;
    assert!((reloaded.point_masses[0].mass / id.estimate[0] - 1.0).abs() < 1e-11);
    let next = diagnose::final_model::variables_toml("final.toml", &id, None).unwrap();
    assert!(next.contains("point_masses = [\"sensor\"]"), "{next}");
    assert!(
        variables::parse(&next, "next.toml", &reloaded).is_ok(),
        "{next}"
    );
    // The resolved form (a JSON source) writes the point mass whole.
    let whole = diagnose::final_model::resolved_toml(&id.model);
    let again = parse_toml(&whole, "whole.toml").unwrap().model;
    assert!(diagnose::final_model::differences(&again, &id.model, 1e-11).is_empty());
}

#[test]
fn point_masses_go_through_the_json_contract() {
    let m = model(SENSOR);
    let json = serde_json::to_string(&rfe::contract::to_json(&m)).unwrap();
    assert!(json.contains("\"point_masses\""), "{json}");
    let back = rfe::modelfile::parse_json(&json, "m.json").unwrap().model;
    assert_eq!(back.point_masses, m.point_masses);
    // Without point masses the key is absent, as before.
    let plain = serde_json::to_string(&rfe::contract::to_json(&model(""))).unwrap();
    assert!(!plain.contains("point_masses"));
    // A bad body index names its JSON path.
    let bad = json.replace("\"body\":0,\"point\":[0.1", "\"body\":3,\"point\":[0.1");
    assert_ne!(bad, json);
    let e = rfe::modelfile::parse_json(&bad, "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("$.point_masses[0].body"), "{e}");
}

#[test]
fn bad_point_masses_name_the_file_line_and_field() {
    let err = |extra: &str| {
        parse_toml(&plate(extra), "plate.toml")
            .unwrap_err()
            .to_string()
    };
    let line_of = |extra: &str, key: &str| {
        let text = plate(extra);
        let at = text.find(&format!("\n{key}")).unwrap();
        text[..at].lines().count() + 1
    };
    let bad = SENSOR.replace("body = \"plate\"", "body = \"plat\"");
    let e = err(&bad);
    assert!(
        e.starts_with(&format!(
            "plate.toml:{}:",
            line_of(&bad, "body = \"plat\"\n")
        )) && e.contains("unknown body \"plat\"")
            && e.contains("plate"),
        "{e}"
    );
    let bad = SENSOR.replace("mass = \"2 kg\"", "mass = \"-2 kg\"");
    let e = err(&bad);
    assert!(
        e.starts_with(&format!("plate.toml:{}:", line_of(&bad, "mass = \"-2")))
            && e.contains("mass must be positive"),
        "{e}"
    );
    let bad = SENSOR.replace("mass = \"2 kg\"", "mass = \"2 mm\"");
    assert!(err(&bad).contains("mass:"), "{}", err(&bad));
    let bad = format!("{SENSOR}{SENSOR}");
    assert!(
        err(&bad).contains("\"sensor\" is used twice"),
        "{}",
        err(&bad)
    );
    let bad = SENSOR.replace("body = \"plate\"", "body = \"ground\"");
    assert!(
        err(&bad).contains("on the ground does not move"),
        "{}",
        err(&bad)
    );
    let bad = SENSOR.replace("inertia = \"1e-4 kg m^2\"", "inertia = [1e-4, -1e-4, 0]");
    assert!(err(&bad).contains("≥ 0"), "{}", err(&bad));
    let bad = SENSOR.replace("note", "nott");
    assert!(err(&bad).contains("unknown field"), "{}", err(&bad));
    // A variable naming a point mass the model does not declare.
    let m = model(SENSOR);
    let e = variables::parse(
        "[[variable]]\npoint_masses = \"gauge\"\nparameter = \"m\"\n",
        "vars.toml",
        &m,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.starts_with("vars.toml:2:")
            && e.contains("unknown point mass \"gauge\"")
            && e.contains("sensor"),
        "{e}"
    );
    let e = variables::parse(
        "[[variable]]\npoint_masses = \"sensor\"\nparameter = \"J1\"\n",
        "vars.toml",
        &m,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.starts_with("vars.toml:3:") && e.contains("parameter = \"m\""),
        "{e}"
    );
}
