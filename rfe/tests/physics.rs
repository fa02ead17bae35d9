//! Physics checks of the model core: analytic cases, the analytic Jacobian against finite
//! differences, direct vs modal paths, invariance under rigid motion of the whole model.

use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rfe::frf::{dof_response, response, Method};
use rfe::model::*;
use rfe::system::System;
use rfe::{textbook, C64};

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

fn rel_err(a: C64, b: C64) -> f64 {
    (a - b).norm() / b.norm().max(1e-300)
}

fn hyst(k: f64, psi: f64) -> C64 {
    C64::new(k, k * psi / TWO_PI)
}

#[test]
fn single_body_matches_closed_form_on_both_paths() {
    let (m, k, psi) = (250.0, 3.0e6, 0.3);
    let model = textbook::single_body(m, k, psi);
    let freqs: Vec<f64> = (0..200).map(|i| 0.5 * i as f64).collect();
    for method in [Method::Direct, Method::Modal] {
        let r = response(&model, &freqs, &[], method).unwrap();
        for (i, &f) in freqs.iter().enumerate() {
            let w = TWO_PI * f;
            let exact = C64::new(1.0, 0.0) / (hyst(k, psi) - w * w * m);
            let e = rel_err(r.output(0)[i], exact);
            assert!(e < 1e-12, "{method:?} at {f} Hz: rel err {e:e}");
        }
    }
}

#[test]
fn two_in_series_matches_closed_form() {
    let (m1, m2, k1, k2, psi) = (400.0, 120.0, 2.0e7, 5.0e6, 0.5);
    let model = textbook::two_in_series(m1, m2, k1, k2, psi);
    let freqs: Vec<f64> = (1..300).map(|i| 0.37 * i as f64).collect();
    for method in [Method::Direct, Method::Modal] {
        let r = response(&model, &freqs, &[], method).unwrap();
        for (i, &f) in freqs.iter().enumerate() {
            let w2 = (TWO_PI * f).powi(2);
            let (c1, c2) = (hyst(k1, psi), hyst(k2, psi));
            let a11 = c1 + c2 - w2 * m1;
            let a22 = c2 - w2 * m2;
            let det = a11 * a22 - c2 * c2;
            let q1 = c2 / det;
            let q2 = a11 / det;
            let (e1, e2) = (rel_err(r.output(0)[i], q1), rel_err(r.output(1)[i], q2));
            assert!(
                e1 < 1e-12 && e2 < 1e-12,
                "{method:?} at {f} Hz: {e1:e} {e2:e}"
            );
        }
    }
}

#[test]
fn velocity_and_acceleration_are_jw_multiples() {
    let mut model = textbook::single_body(10.0, 1e5, 0.1);
    let c = model.outputs[0];
    model.outputs.push(Characteristic {
        quantity: Quantity::Velocity,
        ..c
    });
    model.outputs.push(Characteristic {
        quantity: Quantity::Acceleration,
        ..c
    });
    let r = response(&model, &[3.0, 17.0], &[], Method::Direct).unwrap();
    for i in 0..2 {
        let w = TWO_PI * r.freqs_hz[i];
        let d = r.output(0)[i];
        assert!(rel_err(r.output(1)[i], d * C64::new(0.0, w)) < 1e-14);
        assert!(rel_err(r.output(2)[i], d * (-w * w)) < 1e-14);
    }
}

fn random_rotation(rng: &mut StdRng) -> Matrix3<f64> {
    let axis = Vector3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    );
    *Rotation3::from_scaled_axis(axis.normalize() * rng.random_range(0.0..3.0)).matrix()
}

fn random_vec(rng: &mut StdRng, s: f64) -> Vector3<f64> {
    Vector3::new(
        rng.random_range(-s..s),
        rng.random_range(-s..s),
        rng.random_range(-s..s),
    )
}

/// A random, fully connected model with every law, rotated bodies and SDE frames.
fn random_model(seed: u64, bodies: usize) -> Model {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut m = Model {
        name: "random".into(),
        bodies: Vec::new(),
        sdes: Vec::new(),
        forces: Vec::new(),
        references: Vec::new(),
        outputs: Vec::new(),
        point_masses: Vec::new(),
    };
    for b in 0..bodies {
        let mass = rng.random_range(50.0..800.0);
        m.bodies.push(Body {
            name: format!("b{b}"),
            mass,
            inertia: [
                mass * rng.random_range(0.02..0.2),
                mass * rng.random_range(0.02..0.2),
                mass * rng.random_range(0.02..0.2),
            ],
            position: random_vec(&mut rng, 1.0) + Vector3::new(0.0, 0.0, b as f64 * 0.5),
            rotation: random_rotation(&mut rng),
        });
    }
    let mut add = |rng: &mut StdRng, p: Option<usize>, r: usize, law: SdeLaw, kind: SdeKind| {
        let anchor = m.bodies[r].position;
        m.sdes.push(Sde {
            name: format!("s{}", m.sdes.len()),
            kind,
            bodies: [p, Some(r)],
            point: anchor + random_vec(rng, 0.3),
            rotation: random_rotation(rng),
            law,
            enabled: true,
        });
    };
    for b in 0..bodies {
        let p = if b == 0 { None } else { Some(b - 1) };
        // contact joint carries rotations; isolators/axial springs add variety
        let (area, kn) = (
            rng.random_range(0.01..0.05),
            rng.random_range(0.02..0.2) * 1e12,
        );
        add(
            &mut rng,
            p,
            b,
            SdeLaw::Contact {
                area,
                moments: [1e-4, 5e-5, 8e-5],
                kn,
                kt: if b % 2 == 0 {
                    Tangential::Ratio(2.5)
                } else {
                    Tangential::Value(0.03e12)
                },
                psi_n: 0.8,
                psi_t: 1.6,
            },
            SdeKind::Slideway,
        );
        add(
            &mut rng,
            p,
            b,
            SdeLaw::Isolator {
                kn: 2e8,
                kt: 1e8,
                psi_n: 0.4,
                psi_t: 0.5,
            },
            SdeKind::Isolator,
        );
        add(
            &mut rng,
            p,
            b,
            SdeLaw::Axial { k: 1e8, psi: 0.6 },
            SdeKind::Screw,
        );
        add(
            &mut rng,
            p,
            b,
            SdeLaw::General {
                k: [1e8, 2e8, 3e8, 1e6, 2e6, 3e6],
                psi: [0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
            },
            SdeKind::General,
        );
    }
    m.forces.push(PointForce {
        body: bodies - 1,
        point: m.bodies[bodies - 1].position + Vector3::new(0.1, -0.2, 0.3),
        force: Vector3::new(300.0, -200.0, 1000.0),
        moment: Vector3::new(5.0, 0.0, -3.0),
    });
    m.forces.push(PointForce {
        body: 0,
        point: m.bodies[0].position,
        force: Vector3::new(-300.0, 200.0, -1000.0),
        moment: Vector3::zeros(),
    });
    for dof in 0..6 {
        m.outputs
            .push(Characteristic::dof(bodies - 1, dof, Quantity::Displacement));
    }
    m.outputs
        .push(Characteristic::dof(0, 1, Quantity::Acceleration));
    m
}

#[test]
fn direct_and_modal_paths_agree() {
    // Every parameter (more SDE rows than DOFs: the modal path's deformations come from the full
    // states) and the first two (from the SDE rows of the mode shapes).
    for (seed, few) in (0..5).flat_map(|s| [(s, false), (s, true)]) {
        let model = random_model(seed, 4);
        let freqs: Vec<f64> = (0..120).map(|i| 1.0 + 2.5 * i as f64).collect();
        let mut params = model.all_params();
        if few {
            params.truncate(2);
        }
        let d = response(&model, &freqs, &params, Method::Direct).unwrap();
        let m = response(&model, &freqs, &params, Method::Modal).unwrap();
        let scale_v = d.values.iter().map(|v| v.norm()).fold(0.0, f64::max);
        for (a, b) in d.values.iter().zip(&m.values) {
            assert!((a - b).norm() <= 1e-9 * scale_v, "seed {seed}: {a} vs {b}");
        }
        for p in 0..params.len() {
            for o in 0..model.outputs.len() {
                let (jd, jm) = (d.derivative(p, o), m.derivative(p, o));
                let s = jd.iter().map(|v| v.norm()).fold(0.0, f64::max);
                for (a, b) in jd.iter().zip(jm) {
                    assert!(
                        (a - b).norm() <= 1e-8 * s.max(1e-300),
                        "seed {seed} param {p} output {o}: {a} vs {b}"
                    );
                }
            }
        }
    }
}

#[test]
fn analytic_jacobian_matches_finite_differences() {
    let model = random_model(11, 3);
    let freqs = [2.0, 20.0, 75.0, 230.0, 610.0];
    let params = model.all_params();
    let r = response(&model, &freqs, &params, Method::Direct).unwrap();
    for (pi, &p) in params.iter().enumerate() {
        let x0 = model.param(p).unwrap();
        // Each parameter enters A = K + jD − ω²M affinely, so q(p) is smooth and a step that
        // changes q by ~1e-3 at most keeps the Richardson-extrapolated difference's truncation
        // error far below 1e-6; weak parameters get up to a 10 % step so that their effect rises
        // above round-off.
        let mut s_max: f64 = 0.0;
        for o in 0..model.outputs.len() {
            for k in 0..freqs.len() {
                s_max = s_max.max(x0 * r.derivative(pi, o)[k].norm() / r.output(o)[k].norm());
            }
        }
        let h = x0 * (1e-3 / s_max.max(1e-12)).min(0.1);
        let eval = |x: f64| {
            let mut m = model.clone();
            assert!(m.set_param(p, x));
            response(&m, &freqs, &[], Method::Direct).unwrap()
        };
        let (up, down) = (eval(x0 + h), eval(x0 - h));
        let (up2, down2) = (eval(x0 + h / 2.0), eval(x0 - h / 2.0));
        for o in 0..model.outputs.len() {
            let an = r.derivative(pi, o);
            let scale = an.iter().map(|v| v.norm()).fold(0.0, f64::max);
            for (k, an_k) in an.iter().enumerate() {
                let d1 = (up.output(o)[k] - down.output(o)[k]) / (2.0 * h);
                let d2 = (up2.output(o)[k] - down2.output(o)[k]) / h;
                let fd = (d2 * 4.0 - d1) / 3.0;
                let err = (fd - an_k).norm();
                // truncation (1e-5 relative) + round-off of q (~1e-11 relative) amplified by 1/h;
                // a wrong term in the formula (a missing ψ/2π, a sign) is off by ≥ 1e-1.
                let tol = 1e-5 * an_k.norm() + 1e-11 * r.output(o)[k].norm() / h + 1e-9 * scale;
                assert!(
                    err <= tol,
                    "{} output {o} line {k}: fd {fd} analytic {an_k} (tol {tol:e})",
                    model.param_label(p)
                );
            }
        }
    }
}

#[test]
fn rigid_motion_of_the_whole_model_changes_nothing() {
    let model = random_model(5, 4);
    let mut rng = StdRng::seed_from_u64(99);
    let q = random_rotation(&mut rng);
    let t = random_vec(&mut rng, 5.0);
    let mut moved = model.clone();
    for b in &mut moved.bodies {
        b.position = q * b.position + t;
        b.rotation = q * b.rotation;
    }
    for s in &mut moved.sdes {
        s.point = q * s.point + t;
        s.rotation = q * s.rotation;
    }
    for f in &mut moved.forces {
        f.point = q * f.point + t;
        f.force = q * f.force;
        f.moment = q * f.moment;
    }
    let freqs: Vec<f64> = (0..50).map(|i| 0.5 + 4.0 * i as f64).collect();
    let a = response(&model, &freqs, &[], Method::Direct).unwrap();
    let b = response(&moved, &freqs, &[], Method::Direct).unwrap();
    for (x, y) in a.values.iter().zip(&b.values) {
        assert!((x - y).norm() <= 1e-10 * x.norm().max(1e-12), "{x} vs {y}");
    }
}

#[test]
fn stiffness_and_damping_are_symmetric_and_k_is_positive_semidefinite() {
    let model = random_model(3, 5);
    let s = System::assemble(&model);
    let n = s.n;
    let kmax = s.k.iter().map(|v| v.abs()).fold(0.0, f64::max);
    for i in 0..n {
        for j in 0..n {
            assert!((s.k[i * n + j] - s.k[j * n + i]).abs() <= 1e-12 * kmax);
            assert!((s.d[i * n + j] - s.d[j * n + i]).abs() <= 1e-12 * kmax);
        }
    }
    let k = faer::Mat::<f64>::from_fn(n, n, |i, j| s.k[i * n + j]);
    let ev = k.self_adjoint_eigenvalues(faer::Side::Lower).unwrap();
    assert!(
        ev.iter().all(|&l| l >= -1e-9 * kmax),
        "negative eigenvalue: {ev:?}"
    );
}

#[test]
fn free_floating_model_has_rigid_modes_and_zero_hz_is_an_error() {
    let mut model = textbook::two_in_series(10.0, 10.0, 1e6, 1e6, 0.1);
    // cut body 1 and 2 loose from the ground: the chain can now float freely along z
    model.sdes[0].enabled = false;
    model.sdes.retain(|s| !s.name.starts_with("guide"));
    let err = response(&model, &[0.0], &[], Method::Direct).unwrap_err();
    assert!(
        matches!(err, rfe::frf::SolveError::Singular { .. }),
        "{err}"
    );
    // away from 0 Hz the response exists and the paths agree
    let d = response(&model, &[5.0, 50.0], &[], Method::Direct).unwrap();
    let m = response(&model, &[5.0, 50.0], &[], Method::Modal).unwrap();
    for (a, b) in d.values.iter().zip(&m.values) {
        assert!((a - b).norm() <= 1e-9 * a.norm());
    }
}

#[test]
fn dof_response_agrees_with_outputs() {
    let model = random_model(8, 3);
    let freqs = [3.0, 30.0];
    let r = response(&model, &freqs, &[], Method::Direct).unwrap();
    let full = dof_response(&model, &freqs).unwrap();
    for (k, q) in full.iter().enumerate() {
        assert_eq!(q.len(), model.dof_count());
        for (o, c) in model.outputs.iter().enumerate() {
            let v = q[6 * c.body + c.dof as usize] * c.quantity.factor(TWO_PI * freqs[k]);
            assert!(rel_err(r.output(o)[k], v) < 1e-13);
        }
    }
}

#[test]
fn jacobian_of_single_body_matches_closed_form_derivatives() {
    let (m, k, psi) = (80.0, 2.0e6, 0.4);
    let model = textbook::single_body(m, k, psi);
    let params = [
        ParamRef {
            sde: 0,
            name: ParamName::Ki(2),
        },
        ParamRef {
            sde: 0,
            name: ParamName::PsiI(2),
        },
        ParamRef {
            sde: 0,
            name: ParamName::Ki(0),
        },
    ];
    let freqs = [0.0, 5.0, 25.2, 80.0];
    for method in [Method::Direct, Method::Modal] {
        let r = response(&model, &freqs, &params, method).unwrap();
        for (i, &f) in freqs.iter().enumerate() {
            let w2 = (TWO_PI * f).powi(2);
            let den = hyst(k, psi) - w2 * m;
            // q = 1/den: dq/dk = -(1 + jψ/2π)/den², dq/dψ = -(j k/2π)/den²
            let dk = -C64::new(1.0, psi / TWO_PI) / (den * den);
            let dpsi = -C64::new(0.0, k / TWO_PI) / (den * den);
            assert!(
                rel_err(r.derivative(0, 0)[i], dk) < 1e-12,
                "{method:?} dq/dk at {f} Hz"
            );
            assert!(
                rel_err(r.derivative(1, 0)[i], dpsi) < 1e-12,
                "{method:?} dq/dpsi at {f} Hz"
            );
            // the x spring does not move the z response
            assert!(r.derivative(2, 0)[i].norm() < 1e-12 * dk.norm());
        }
    }
}

#[test]
fn modes_of_the_single_body_are_closed_form() {
    let (m, k, psi) = (250.0, 3.0e6, 0.3);
    let model = textbook::single_body(m, k, psi);
    // translations: sqrt(k/m); rotations: sqrt(0.01 k / J) with J = 0.1 m, 0.2 m, 0.3 m
    let mut want: Vec<f64> = vec![(k / m).sqrt(); 3];
    for f in [0.1, 0.2, 0.3] {
        want.push((0.01 * k / (f * m)).sqrt());
    }
    want.sort_by(f64::total_cmp);
    for modes in [
        rfe::modes::undamped(&model).unwrap(),
        rfe::modes::complex(&model).unwrap(),
    ] {
        let mut got: Vec<f64> = modes.iter().map(|md| md.freq_hz * TWO_PI).collect();
        got.sort_by(f64::total_cmp);
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() < 1e-9 * w, "{got:?} vs {want:?}");
        }
    }
    for md in rfe::modes::complex(&model).unwrap() {
        // hysteretic: λ = ω²(1 + jψ/2π), so the loss factor is ψ/2π for every mode
        assert!(
            (md.loss_factor - psi / TWO_PI).abs() < 1e-12,
            "{}",
            md.loss_factor
        );
        assert!((md.energy.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }
}

#[test]
fn band_sensitivity_of_the_single_body_is_closed_form() {
    let (m, k, psi) = (80.0, 2.0e6, 0.4);
    let model = textbook::single_body(m, k, psi);
    let freqs: Vec<f64> = (1..60).map(|i| i as f64).collect();
    let p = ParamRef {
        sde: 0,
        name: ParamName::Ki(2),
    };
    let s = rfe::sensitivity::band_sensitivity(&model, &freqs, &[p], Method::Direct).unwrap();
    // |q| = 1/|den|, ∂|q|/∂k = −Re(conj(den)(1 + jψ/2π))/|den|³
    let (mut num, mut den_sum) = (0.0, 0.0);
    for f in &freqs {
        let d = hyst(k, psi) - (TWO_PI * f).powi(2) * m;
        num += ((d.conj() * C64::new(1.0, psi / TWO_PI)).re / d.norm().powi(3)).abs();
        den_sum += 1.0 / d.norm();
    }
    let mi = num / den_sum;
    assert!((s.mi[0] - mi).abs() < 1e-10 * mi, "{} vs {mi}", s.mi[0]);
    assert!((s.relative[0] - mi * k).abs() < 1e-10 * mi * k);
}
