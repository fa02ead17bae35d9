//! Small models with closed-form answers, for tests, examples and sanity checks.
//!
//! - [`single_body`]: one body on a six-spring element at its centre of mass. Every DOF decouples:
//!   `q_i = P_i / (k_i (1 + jψ/2π) − ω² m_i)`.
//! - [`two_in_series`]: ground — k1 — body 1 — k2 — body 2 along the global z axis, force on
//!   body 2; the classic two-mass chain with hysteretic springs.

use nalgebra::{Matrix3, Vector3};

use crate::model::{
    Body, Characteristic, Model, PointForce, Quantity, Sde, SdeKind, SdeLaw,
};

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
        outputs: vec![Characteristic {
            body: 0,
            dof: 2,
            quantity: Quantity::Displacement,
        }],
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
        outputs: vec![
            Characteristic { body: 0, dof: 2, quantity: Quantity::Displacement },
            Characteristic { body: 1, dof: 2, quantity: Quantity::Displacement },
        ],
    }
}
