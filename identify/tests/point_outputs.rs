//! Point outputs (a sensor at a point of a body along any direction): the response against
//! `dᵀ(u + θ × (p − c))` computed by hand from the DOF solution, the analytic Jacobian against
//! finite differences on both solution paths, the same fit from principal-axis and from off-axis
//! point outputs, and the model file's `[[output]] point + direction` read and written back.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use common::load_model;
use identify::NoiseChoice;
use nalgebra::Vector3;
use rfe::frf::{self, Method};
use rfe::model::{Characteristic, Model, Param, PointOutput, Quantity};
use rfe::{textbook, C64};

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// Three sensors on `body` of `model`, off every principal-axis line and along oblique
/// directions, as `quantity`.
fn oblique_sensors(model: &Model, body: usize, quantity: Quantity) -> Vec<Characteristic> {
    let c = model.bodies[body].position;
    [
        (
            Vector3::new(0.12, -0.07, 0.31),
            Vector3::new(1.0, 0.4, -0.2),
        ),
        (
            Vector3::new(-0.25, 0.18, 0.05),
            Vector3::new(-0.3, 1.0, 0.5),
        ),
        (
            Vector3::new(0.04, 0.33, -0.21),
            Vector3::new(0.2, -0.6, 1.0),
        ),
    ]
    .into_iter()
    .map(|(r, d)| {
        let at = PointOutput::new(c + r, d).unwrap();
        Characteristic {
            body,
            dof: at.nearest_axis(&model.bodies[body]).0,
            quantity,
            at: Some(at),
            reference: 0,
            relative: false,
        }
    })
    .collect()
}

#[test]
fn a_point_output_reads_the_rigid_body_motion_at_its_point() {
    let mut model = load_model("fwd32j.toml");
    let freqs = [23.0, 61.0, 140.0, 333.0];
    let q = frf::dof_response(&model, &freqs).unwrap();
    let mut checked = 0;
    for body in 0..model.bodies.len() {
        for quantity in [Quantity::Displacement, Quantity::Acceleration] {
            model.outputs = oblique_sensors(&model, body, quantity);
            for method in [Method::Direct, Method::Modal] {
                let r = frf::response(&model, &freqs, &[], method).unwrap();
                let b = &model.bodies[body];
                for (o, c) in model.outputs.iter().enumerate() {
                    let at = c.at.unwrap();
                    let (p, d) = (Vector3::from(at.point), Vector3::from(at.direction));
                    for (k, f) in freqs.iter().enumerate() {
                        // Global motion of the point: R (u + θ × Rᵀ(p − c)), u and θ in body axes.
                        let dofs = &q[k][6 * body..6 * body + 6];
                        let u = nalgebra::Vector3::new(dofs[0], dofs[1], dofs[2]);
                        let th = nalgebra::Vector3::new(dofs[3], dofs[4], dofs[5]);
                        let arm =
                            (b.rotation.transpose() * (p - b.position)).map(|x| C64::new(x, 0.0));
                        let global = b.rotation.map(|x| C64::new(x, 0.0)) * (u + th.cross(&arm));
                        let by_hand = (global.x * d.x + global.y * d.y + global.z * d.z)
                            * quantity.factor(TWO_PI * f);
                        let got = r.output(o)[k];
                        let err = (got - by_hand).norm() / by_hand.norm();
                        let tol = if method == Method::Direct {
                            1e-12
                        } else {
                            1e-9
                        };
                        assert!(
                            err <= tol,
                            "{} sensor {o} at {f} Hz ({method:?}): {got} vs {by_hand}, relative {err:e}",
                            b.name
                        );
                        checked += 1;
                    }
                }
            }
        }
    }
    assert_eq!(checked, model.bodies.len() * 2 * 2 * 3 * freqs.len());
}

#[test]
fn a_principal_axis_output_is_a_point_output_at_the_centre_of_mass_along_its_axis() {
    let mut model = load_model("fwd32j.toml");
    let freqs = [40.0, 180.0];
    let axis = model.outputs.clone();
    let r_axis = frf::response(&model, &freqs, &[], Method::Direct).unwrap();
    model.outputs = axis
        .iter()
        .map(|c| {
            let b = &model.bodies[c.body];
            Characteristic {
                at: PointOutput::new(b.position, b.rotation.column(c.dof as usize).into_owned()),
                ..*c
            }
        })
        .collect();
    let r_point = frf::response(&model, &freqs, &[], Method::Direct).unwrap();
    for (a, p) in r_axis.values.iter().zip(&r_point.values) {
        assert!((a - p).norm() <= 1e-12 * a.norm(), "{a} vs {p}");
    }
}

#[test]
fn the_jacobian_of_a_point_output_matches_finite_differences() {
    let mut model = load_model("fwd32j.toml");
    let table = model.body_index("table").unwrap();
    model.outputs = oblique_sensors(&model, table, Quantity::Acceleration);
    let params: Vec<Param> = model
        .all_params()
        .into_iter()
        .step_by(7)
        .map(Into::into)
        .collect();
    assert!(params.len() >= 8, "{} parameters", params.len());
    common::assert_jacobian_matches_central_differences(
        &model,
        &params,
        &[37.0, 97.0, 211.0],
        1e-8,
    );
}

#[test]
fn principal_axis_and_off_axis_point_outputs_give_the_same_estimates() {
    let truth = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
    let mut sensors = truth.clone();
    sensors.outputs = vec![];
    for body in 0..2 {
        let c = truth.bodies[body].position;
        for (r, d) in [
            (Vector3::new(0.2, 0.1, 0.0), Vector3::new(0.1, 0.3, 1.0)),
            (
                Vector3::new(-0.15, 0.0, 0.05),
                Vector3::new(0.5, -0.2, -1.0),
            ),
        ] {
            let at = PointOutput::new(c + r, d).unwrap();
            sensors.outputs.push(Characteristic {
                body,
                dof: at.nearest_axis(&truth.bodies[body]).0,
                quantity: Quantity::Displacement,
                at: Some(at),
                reference: 0,
                relative: false,
            });
        }
    }
    let fit = |model: &Model| {
        common::fit_two_mass(&truth, &common::exact(model, None), NoiseChoice::default()).estimate
    };
    let on_axis = fit(&truth);
    let off_axis = fit(&sensors);
    for ((a, p), t) in on_axis.iter().zip(&off_axis).zip([2.0e7, 5.0e6, 0.5]) {
        assert!((a / t - 1.0).abs() < 1e-6, "principal axes: {on_axis:?}");
        assert!((p / t - 1.0).abs() < 1e-6, "point outputs: {off_axis:?}");
        assert!((a / p - 1.0).abs() < 1e-6, "{on_axis:?} vs {off_axis:?}");
    }
}

#[test]
fn a_model_file_declares_a_point_output_and_writes_it_back() {
    let text = String::from(common::ONE_BODY_ON_A_SPRING)
        + r#"[[output]]
body = "mass"
point = "100 50 0 mm"
direction = [0, 3, 4]
quantity = "acceleration"
"#;
    let loaded = rfe::modelfile::parse_toml(&text, "point.toml").unwrap();
    let m = &loaded.model;
    assert_eq!(m.outputs.len(), 2);
    assert_eq!(m.outputs[0].at, None);
    let at = m.outputs[1].at.unwrap();
    assert!((Vector3::from(at.point) - Vector3::new(0.1, 0.05, 0.0)).norm() < 1e-15);
    assert!((Vector3::from(at.direction) - Vector3::new(0.0, 0.6, 0.8)).norm() < 1e-15);
    assert_eq!(m.outputs[1].dof, 2, "nearest principal axis: u3");
    // JSON contract round trip.
    let json = rfe::contract::to_json(m);
    let back = rfe::contract::from_json(&json).unwrap();
    assert_eq!(back.outputs, m.outputs);

    for (bad, says) in [
        (
            text.replace("direction = [0, 3, 4]", "direction = [0, 0, 0]"),
            "zero vector",
        ),
        (
            text.replace("direction = [0, 3, 4]\n", ""),
            "needs `direction",
        ),
        (
            text.replace(
                "direction = [0, 3, 4]",
                "direction = [0, 3, 4]\ndof = \"u1\"",
            ),
            "no `dof`",
        ),
    ] {
        let e = rfe::modelfile::parse_toml(&bad, "point.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("point.toml:") && e.contains(says), "{e}");
    }
}
