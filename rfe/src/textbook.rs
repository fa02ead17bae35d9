//! Small models with closed-form answers, for tests, examples and sanity checks.
//!
//! - [`single_body`]: one body on a six-spring element at its centre of mass. Every DOF decouples:
//!   `q_i = P_i / (k_i (1 + jψ/2π) − ω² m_i)`.
//! - [`two_in_series`]: ground — k1 — body 1 — k2 — body 2 along the global z axis, force on
//!   body 2; the classic two-mass chain with hysteretic springs.

use nalgebra::{Matrix3, Vector3};

use crate::model::{Body, Characteristic, Model, PointForce, Quantity, Sde, SdeKind, SdeLaw};

fn body(name: &str, mass: f64, z: f64) -> Body {
    Body {
        name: name.into(),
        mass,
        inertia: [0.1 * mass, 0.2 * mass, 0.3 * mass],
        position: Vector3::new(0.0, 0.0, z),
        rotation: Matrix3::identity(),
    }
}

/// One body of `mass` (kg) on a general element at its centre of mass with translational
/// stiffness `k` (N/m) along all three axes, rotational stiffness `k·0.01 m²`, and dissipation
/// `psi`. Excitation: 1 N along global z at the centre of mass. Output: `u3` displacement.
pub fn single_body(mass: f64, k: f64, psi: f64) -> Model {
    let kr = 0.01 * k;
    Model {
        name: "single body on springs".into(),
        bodies: vec![body("mass", mass, 0.0)],
        sdes: vec![Sde {
            name: "spring".into(),
            kind: SdeKind::General,
            bodies: [None, Some(0)],
            point: Vector3::zeros(),
            rotation: Matrix3::identity(),
            law: SdeLaw::General {
                k: [k, k, k, kr, kr, kr],
                psi: [psi; 6],
            },
            enabled: true,
        }],
        forces: vec![PointForce {
            body: 0,
            point: Vector3::zeros(),
            force: Vector3::new(0.0, 0.0, 1.0),
            moment: Vector3::zeros(),
        }],
        references: Vec::new(),
        point_masses: Vec::new(),
        outputs: vec![Characteristic::dof(0, 2, Quantity::Displacement)],
    }
}

/// Ground — `k1` — body 1 (`m1`) — `k2` — body 2 (`m2`), axial springs along global z through the
/// centres of mass (bodies at z = 0 and z = 1 m), both with dissipation `psi`; every other DOF is
/// held by stiff general elements so that the chain is the only mode family in the z direction.
/// Excitation: 1 N along z on body 2. Outputs: `u3` displacement of body 1 and body 2.
pub fn two_in_series(m1: f64, m2: f64, k1: f64, k2: f64, psi: f64) -> Model {
    let axial = |name: &str, bodies: [Option<usize>; 2], z: f64, k: f64| Sde {
        name: name.into(),
        kind: SdeKind::Spring,
        bodies,
        point: Vector3::new(0.0, 0.0, z),
        // axis 1 along global z
        rotation: Matrix3::new(0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0),
        law: SdeLaw::Axial { k, psi },
        enabled: true,
    };
    // Lateral/rotational restraints on each body to ground (no z stiffness).
    let guide = |name: &str, b: usize, z: f64| Sde {
        name: name.into(),
        kind: SdeKind::General,
        bodies: [None, Some(b)],
        point: Vector3::new(0.0, 0.0, z),
        rotation: Matrix3::identity(),
        law: SdeLaw::General {
            k: [1e7, 1e7, 0.0, 1e6, 1e6, 1e6],
            psi: [0.1, 0.1, 0.0, 0.1, 0.1, 0.1],
        },
        enabled: true,
    };
    Model {
        name: "two masses in series".into(),
        bodies: vec![body("first", m1, 0.0), body("second", m2, 1.0)],
        sdes: vec![
            axial("k1", [None, Some(0)], 0.0, k1),
            axial("k2", [Some(0), Some(1)], 0.5, k2),
            guide("guide 1", 0, 0.0),
            guide("guide 2", 1, 1.0),
        ],
        forces: vec![PointForce {
            body: 1,
            point: Vector3::new(0.0, 0.0, 1.0),
            force: Vector3::new(0.0, 0.0, 1.0),
            moment: Vector3::zeros(),
        }],
        references: Vec::new(),
        point_masses: Vec::new(),
        outputs: vec![
            Characteristic::dof(0, 2, Quantity::Displacement),
            Characteristic::dof(1, 2, Quantity::Displacement),
        ],
    }
}

/// A chain of `n` steel blocks (200 kg, 0.6 m pitch along global x) joined by slideway joints
/// (0.02 m², kn = 0.05 MPa/µm, kn/kt = 2.5, ψn 0.8, ψt 1.6) with axes tilted differently at every
/// joint so that all DOFs couple, the first block on four isolators. Excitation: 1 kN force along
/// a skew direction at the last block; outputs: its three translations. For benchmarks and
/// scaling tests (6n DOFs, 4(n−1) + 16 parameters).
pub fn chain(n: usize) -> Model {
    use nalgebra::Rotation3;
    let n = n.max(1);
    let bodies: Vec<Body> = (0..n)
        .map(|i| Body {
            name: format!("block {i}"),
            mass: 200.0,
            inertia: [6.0, 8.0, 10.0],
            position: Vector3::new(0.6 * i as f64, 0.0, 0.5),
            rotation: *Rotation3::from_euler_angles(0.1 * i as f64, 0.05 * i as f64, 0.02).matrix(),
        })
        .collect();
    let mut sdes = Vec::new();
    for (j, (x, y)) in [(-0.3, -0.3), (-0.3, 0.3), (0.3, -0.3), (0.3, 0.3)]
        .into_iter()
        .enumerate()
    {
        sdes.push(Sde {
            name: format!("isolator {j}"),
            kind: SdeKind::Isolator,
            bodies: [None, Some(0)],
            point: Vector3::new(x, y, 0.0),
            rotation: Matrix3::new(0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0),
            law: SdeLaw::Isolator {
                kn: 5e6,
                kt: 2e6,
                psi_n: 0.3,
                psi_t: 0.3,
            },
            enabled: true,
        });
    }
    for i in 1..n {
        sdes.push(Sde {
            name: format!("joint {i}"),
            kind: SdeKind::Slideway,
            bodies: [Some(i - 1), Some(i)],
            point: Vector3::new(0.6 * i as f64 - 0.3, 0.05, 0.5),
            rotation: *Rotation3::from_euler_angles(0.3 * i as f64, 0.2, 0.1 * i as f64).matrix(),
            law: SdeLaw::Contact {
                area: 0.02,
                moments: [2e-4, 1e-4, 1e-4],
                kn: 0.05e12,
                kt: crate::model::Tangential::Ratio(2.5),
                psi_n: 0.8,
                psi_t: 1.6,
            },
            enabled: true,
        });
    }
    let last = n - 1;
    Model {
        name: format!("chain of {n} blocks"),
        forces: vec![PointForce {
            body: last,
            point: bodies[last].position + Vector3::new(0.1, 0.1, 0.2),
            force: Vector3::new(400.0, 300.0, 866.0),
            moment: Vector3::zeros(),
        }],
        references: Vec::new(),
        point_masses: Vec::new(),
        outputs: (0..3)
            .map(|dof| Characteristic::dof(last, dof, Quantity::Displacement))
            .collect(),
        bodies,
        sdes,
    }
}
