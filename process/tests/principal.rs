//! Principal-axes transformation: exact recovery of synthetic rigid-body motion from any
//! non-degenerate layout, a raised rigidity indicator for a flexible solid, clear errors for
//! degenerate layouts.
#![allow(clippy::unwrap_used, clippy::needless_range_loop, missing_docs)]

use nalgebra::{Matrix3, Rotation3, Vector3};
use process::principal::{Dofs, RigidFit, Sensor};
use process::C64;
use rand::{Rng, SeedableRng};
use rfe::Body;

fn body(rng: &mut impl Rng) -> Body {
    let rot = Rotation3::from_euler_angles(
        rng.random_range(-3.0..3.0),
        rng.random_range(-1.5..1.5),
        rng.random_range(-3.0..3.0),
    );
    Body {
        name: "table".into(),
        mass: 850.0,
        inertia: [40.0, 55.0, 80.0],
        position: Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(0.0..2.0),
        ),
        rotation: Matrix3::from(rot),
    }
}

fn unit(rng: &mut impl Rng) -> Vector3<f64> {
    loop {
        let v = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        if v.norm() > 0.2 && v.norm() < 1.0 {
            return v.normalize();
        }
    }
}

/// `n` sensors named `{prefix}0`, `{prefix}1`... at random points around the body's centre, each
/// along a random direction.
fn random_sensors(b: &Body, n: usize, prefix: &str, rng: &mut impl Rng) -> Vec<Sensor> {
    (0..n)
        .map(|i| Sensor {
            name: format!("{prefix}{i}"),
            position: b.position
                + Vector3::new(
                    rng.random_range(-0.8..0.8),
                    rng.random_range(-0.5..0.5),
                    rng.random_range(-0.3..0.3),
                ),
            direction: unit(rng),
        })
        .collect()
}

/// A channel's reading for rigid motion q, straight from the definition R(u + r × Rᵀ(x−c))·d.
fn reading(b: &Body, s: &Sensor, q: &[C64; 6]) -> C64 {
    let sb = b.rotation.transpose() * (s.position - b.position);
    let mut out = C64::default();
    for part in 0..2 {
        let pick = |i: usize| if part == 0 { q[i].re } else { q[i].im };
        let u = Vector3::new(pick(0), pick(1), pick(2));
        let r = Vector3::new(pick(3), pick(4), pick(5));
        let disp = b.rotation * (u + r.cross(&sb));
        let v = disp.dot(&s.direction.normalize());
        if part == 0 {
            out.re = v
        } else {
            out.im = v
        }
    }
    out
}

fn random_q(rng: &mut impl Rng) -> [C64; 6] {
    std::array::from_fn(|_| {
        C64::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)) * 1e-6
    })
}

#[test]
fn rigid_motion_is_recovered_exactly_by_random_layouts() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(2024);
    for trial in 0..50 {
        let b = body(&mut rng);
        let n = 6 + trial % 7;
        let sensors = random_sensors(&b, n, "acc", &mut rng);
        let fit = RigidFit::new(&b, &sensors, Dofs::Six).unwrap();
        assert_eq!(fit.dofs(), 6);
        let freqs = [10.0, 20.0, 30.0];
        let qs: Vec<[C64; 6]> = (0..3).map(|_| random_q(&mut rng)).collect();
        let channels: Vec<Vec<C64>> = sensors
            .iter()
            .map(|s| qs.iter().map(|q| reading(&b, s, q)).collect())
            .collect();
        let out = fit.transform(&freqs, &channels).unwrap();
        for (k, q) in qs.iter().enumerate() {
            for d in 0..6 {
                assert!(
                    (out.q[k][d] - q[d]).norm() < 1e-9 * 1e-6,
                    "trial {trial} dof {d}: {} vs {}",
                    out.q[k][d],
                    q[d]
                );
            }
            assert!(out.residual[k] < 1e-9, "rigid residual {}", out.residual[k]);
        }
    }
}

#[test]
fn a_flexible_solid_raises_the_rigidity_indicator() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let b = body(&mut rng);
    let sensors: Vec<Sensor> = (0..12)
        .map(|i| Sensor {
            name: format!("acc{i}"),
            position: b.position
                + b.rotation
                    * Vector3::new(
                        -0.8 + 0.15 * i as f64,
                        if i % 2 == 0 { 0.4 } else { -0.4 },
                        0.1 * (i % 3) as f64,
                    ),
            direction: b.rotation * [Vector3::x(), Vector3::y(), Vector3::z()][i % 3],
        })
        .collect();
    let fit = RigidFit::new(&b, &sensors, Dofs::Auto).unwrap();
    let q = random_q(&mut rng);
    // Below resonance: rigid. At "resonance": first bending of the table along body axis 1,
    // out-of-plane (axis 3) deflection ∝ s1² − mean.
    let rigid: Vec<C64> = sensors.iter().map(|s| reading(&b, s, &q)).collect();
    let bent: Vec<C64> = sensors
        .iter()
        .zip(&rigid)
        .map(|(s, y)| {
            let sb = b.rotation.transpose() * (s.position - b.position);
            let dir_b = b.rotation.transpose() * s.direction;
            *y + C64::new(0.0, 3e-6) * (sb.x * sb.x - 0.2) * dir_b.z
        })
        .collect();
    let mut qq = [C64::default(); 6];
    let r_rigid = fit.fit_line(&rigid, &mut qq).unwrap();
    let r_bent = fit.fit_line(&bent, &mut qq).unwrap();
    assert!(r_rigid < 1e-9, "{r_rigid}");
    assert!(r_bent > 0.05, "flexible solid not flagged: {r_bent}");
}

#[test]
fn degenerate_layouts_name_what_is_missing() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let b = body(&mut rng);
    // Three orthogonal sensors at one point: rotations unobservable.
    let triax: Vec<Sensor> = (0..3)
        .map(|i| Sensor {
            name: format!("t{i}"),
            position: b.position + Vector3::new(0.3, 0.2, 0.1),
            direction: [Vector3::x(), Vector3::y(), Vector3::z()][i],
        })
        .collect();
    let e = RigidFit::new(&b, &triax, Dofs::Six)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("table") && e.contains(" r") && e.contains("3 channel"),
        "{e}"
    );
    let auto = RigidFit::new(&b, &triax, Dofs::Auto).unwrap();
    assert_eq!(auto.dofs(), 3);
    // Translations recovered exactly when the solid only translates.
    let q: [C64; 6] = [
        C64::new(1.0, 0.5),
        C64::new(-2.0, 0.0),
        C64::new(0.3, 0.1),
        C64::default(),
        C64::default(),
        C64::default(),
    ];
    let y: Vec<C64> = triax.iter().map(|s| reading(&b, s, &q)).collect();
    let mut out = [C64::default(); 6];
    auto.fit_line(&y, &mut out).unwrap();
    for d in 0..3 {
        assert!((out[d] - q[d]).norm() < 1e-12);
    }
    // Six sensors all measuring along global x: y and z motions missing.
    let xs: Vec<Sensor> = (0..6)
        .map(|i| Sensor {
            name: format!("x{i}"),
            position: b.position
                + Vector3::new(0.1 * i as f64, 0.3 * (i % 2) as f64, 0.2 * (i % 3) as f64),
            direction: Vector3::x(),
        })
        .collect();
    let e = RigidFit::new(&b, &xs, Dofs::Auto).unwrap_err().to_string();
    assert!(e.contains("no sensor sees the motion"), "{e}");
    // Zero direction.
    let mut bad = triax.clone();
    bad[0].direction = Vector3::zeros();
    assert!(RigidFit::new(&b, &bad, Dofs::Auto)
        .unwrap_err()
        .to_string()
        .contains("'t0'"));
    // Wrong channel count at fit time.
    assert!(auto.fit_line(&y[..2], &mut out).is_err());
}

#[test]
fn principal_axes_from_an_inertia_tensor_and_variance_propagation() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let b = body(&mut rng);
    let tensor = b.rotation
        * Matrix3::from_diagonal(&Vector3::new(40.0, 55.0, 80.0))
        * b.rotation.transpose();
    let got =
        process::principal::body_from_inertia_tensor("table", 850.0, b.position, &tensor).unwrap();
    for i in 0..3 {
        assert!((got.inertia[i] - b.inertia[i]).abs() < 1e-9);
        // Same axis up to sign.
        assert!((got.rotation.column(i).dot(&b.rotation.column(i)).abs() - 1.0).abs() < 1e-9);
    }
    assert!((got.rotation.determinant() - 1.0).abs() < 1e-12);
    let asym = tensor + Matrix3::new(0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    assert!(process::principal::body_from_inertia_tensor("t", 850.0, b.position, &asym).is_err());

    // Variance of the fitted DOFs: Monte-Carlo check of var(q) = Σ P² var(y).
    let sensors = random_sensors(&b, 9, "a", &mut rng);
    let fit = RigidFit::new(&b, &sensors, Dofs::Six).unwrap();
    let sd = 1e-3;
    let pred = fit.variance(&[sd * sd; 9]).unwrap();
    let normal = rand_distr::Normal::new(0.0, sd).unwrap();
    let trials = 4000;
    let mut acc = [0.0; 6];
    let mut q = [C64::default(); 6];
    for _ in 0..trials {
        let y: Vec<C64> = (0..9).map(|_| C64::new(rng.sample(normal), 0.0)).collect();
        fit.fit_line(&y, &mut q).unwrap();
        for d in 0..6 {
            acc[d] += q[d].norm_sqr() / trials as f64;
        }
    }
    for d in 0..6 {
        assert!(
            (acc[d] / pred[d] - 1.0).abs() < 0.1,
            "dof {d}: MC {} vs predicted {}",
            acc[d],
            pred[d]
        );
    }
}
