//! The whole chain on synthetic data: force + 8 accelerometers on a rigid table -> Welch H1 ->
//! principal-axis motion (with propagated variance) -> selected points -> rfe::Measurement.
#![allow(clippy::unwrap_used, clippy::needless_range_loop, missing_docs)]

mod common;

use nalgebra::{Matrix3, Rotation3, Vector3};
use process::principal::{Dofs, RigidFit, Sensor};
use process::selection::{select_points, to_measurement, CharacteristicSpec, SelectionConfig};
use process::{estimate, spectra::Welch, Estimator, WelchConfig, Window};
use rfe::{Body, Quantity};

#[test]
fn signals_to_principal_axis_measurement() {
    let body = Body {
        name: "table".into(),
        mass: 850.0,
        inertia: [40.0, 55.0, 80.0],
        position: Vector3::new(0.2, -0.1, 1.0),
        rotation: Matrix3::from(Rotation3::from_euler_angles(0.1, -0.2, 0.7)),
    };
    let dirs = [Vector3::x(), Vector3::y(), Vector3::z()];
    let sensors: Vec<Sensor> = (0..8)
        .map(|i| Sensor {
            name: format!("acc{i}"),
            position: body.position
                + Vector3::new(
                    if i % 2 == 0 { 0.6 } else { -0.6 },
                    if i % 4 < 2 { 0.4 } else { -0.4 },
                    if i < 4 { 0.2 } else { -0.2 },
                ),
            direction: dirs[i % 3] + 0.1 * dirs[(i + 1) % 3],
        })
        .collect();
    // Each DOF moves as gain_d × (a resonator driven by the force).
    let gains = [1.0, -0.5, 2.0, 0.3, -0.2, 0.1];
    let (b, a) = ([0.05, 0.02, 0.0], [-1.6, 0.8]);
    let n = 1 << 17;
    let fs = 1000.0;
    let force = common::noise(5, n, 1.0);
    let base = common::resonator(&force, b, a);
    let rt = body.rotation.transpose();
    let responses: Vec<Vec<f64>> = sensors
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let e = rt * s.direction.normalize();
            let sb = rt * (s.position - body.position);
            let m = sb.cross(&e);
            let coef: f64 = (0..3).map(|c| e[c] * gains[c] + m[c] * gains[3 + c]).sum();
            base.iter()
                .zip(common::noise(100 + i as u64, n, 0.02))
                .map(|(v, e)| coef * v + e)
                .collect()
        })
        .collect();
    let names: Vec<&str> = sensors.iter().map(|s| s.name.as_str()).collect();
    let mut w = Welch::new(WelchConfig::new(fs, 1024, Window::Hann), &["force"], &names).unwrap();
    let rs: Vec<&[f64]> = responses.iter().map(|v| v.as_slice()).collect();
    w.push(&[&force], &rs).unwrap();
    let frf = estimate(&w.finish().unwrap(), Estimator::H1).unwrap();

    let fit = RigidFit::new(&body, &sensors, Dofs::Six).unwrap();
    let order: Vec<usize> = (0..8).collect();
    let p = fit.transform_frf(&frf, 0, &order).unwrap();
    let var = p.variance.as_ref().unwrap();
    let (mut z, mut m) = (0.0, 0);
    for k in 1..frf.freqs_hz.len() - 1 {
        let truth = common::resonator_frf(b, a, frf.freqs_hz[k] / fs);
        for d in 0..6 {
            z += (p.q[k][d] - truth * gains[d]).norm_sqr() / var[k][d];
            m += 1;
        }
        assert!(p.residual[k] < 0.2, "line {k}: residual {}", p.residual[k]);
    }
    let z = z / m as f64;
    assert!(
        (0.6..1.6).contains(&z),
        "normalized squared error of principal-axis FRFs {z}"
    );

    // 38 points of u3, scaled to a 4 kN excitation.
    let u3 = p.dof(2);
    let mag: Vec<f64> = u3.iter().map(|v| v.norm()).collect();
    let coh: Vec<f64> = (0..frf.freqs_hz.len())
        .map(|k| frf.multiple_coherence(k, 2))
        .collect();
    let pts = select_points(
        "table u3",
        &frf.freqs_hz,
        &mag,
        Some(&coh),
        &SelectionConfig {
            band_hz: (5.0, 450.0),
            min_coherence: 0.5,
            ..Default::default()
        },
    )
    .unwrap();
    let v3: Vec<f64> = var.iter().map(|v| v[2]).collect();
    let spec = CharacteristicSpec {
        body: "table".into(),
        dof: 2,
        quantity: Quantity::Acceleration,
        nominal_force: 4000.0,
    };
    let meas = to_measurement(
        &spec,
        &frf.freqs_hz,
        &u3,
        Some(&coh),
        Some(&v3),
        Some(frf.averages),
        &pts,
    )
    .unwrap();
    assert_eq!(meas.freqs_hz.len(), 38);
    for (i, &k) in pts.iter().enumerate() {
        let truth = 4000.0 * 2.0 * common::resonator_frf(b, a, frf.freqs_hz[k] / fs).norm();
        assert!(
            (meas.amplitude[i] - truth).abs()
                < 5.0 * meas.variance.as_ref().unwrap()[i].sqrt() + 1e-9 * truth
        );
    }
}
