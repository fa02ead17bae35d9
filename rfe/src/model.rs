//! The resolved RFE model: bodies, spring-damping elements (SDEs), excitation and output
//! characteristics, all in SI units and the global frame. Everything that computes (FRF, modes,
//! sensitivities, identification) takes a [`Model`]; model files (TOML, resolved JSON) load into it.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

/// A rigid finite element (RFE): a rigid body with six degrees of freedom.
///
/// Its generalized coordinates are `q = [u1, u2, u3, r1, r2, r3]`: small translations of the centre
/// of mass (m) and small rotations (rad), both along the body's principal central axes.
#[derive(Debug, Clone, PartialEq)]
pub struct Body {
    /// Unique name, as used in model files and reports.
    pub name: String,
    /// Mass (kg), > 0.
    pub mass: f64,
    /// Principal central moments of inertia (kg·m²), each > 0.
    pub inertia: [f64; 3],
    /// Centre of mass in the global frame (m).
    pub position: Vector3<f64>,
    /// `global_from_body`: its columns are the principal axes expressed in the global frame
    /// (orthonormal, right-handed).
    pub rotation: Matrix3<f64>,
}

impl Body {
    /// Diagonal of the body's 6×6 inertia block: `[m, m, m, J1, J2, J3]`.
    pub fn inertia_diagonal(&self) -> [f64; 6] {
        let [j1, j2, j3] = self.inertia;
        [self.mass, self.mass, self.mass, j1, j2, j3]
    }
}

/// How the tangential contact stiffness of a contact joint is given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tangential {
    /// `kt` directly (Pa/m).
    Value(f64),
    /// `kt = kn / ratio`: the ratio is held fixed when `kn` changes (the paper's kn/kt = 2.5).
    Ratio(f64),
}

/// Stiffness and damping law of an SDE, with its own parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SdeLaw {
    /// A contact joint (slideway or rotary joint): per-unit-area contact stiffnesses over a
    /// working area. `k = [A·kn, A·kt, A·kt, J1·kt, J2·kn, J3·kn]`,
    /// `psi = [ψn, ψt, ψt, ψt, ψn, ψn]` (paper eq. 3.6-3.7).
    Contact {
        /// Working area A (m²).
        area: f64,
        /// Second moments of the working area (m⁴): J1 polar about the normal (axis 1),
        /// J2 and J3 about the tangential axes 2 and 3.
        moments: [f64; 3],
        /// Normal contact stiffness per unit area (Pa/m; 1 MPa/µm = 1e12 Pa/m).
        kn: f64,
        /// Tangential contact stiffness per unit area.
        kt: Tangential,
        /// Relative energy dissipation ψ = ΔW/W in the normal direction (-).
        psi_n: f64,
        /// Relative energy dissipation in the tangential direction (-).
        psi_t: f64,
    },
    /// A single spring along axis 1 (lead screw, exciter): `k = [k, 0, 0, 0, 0, 0]` (eq. 3.9-3.10).
    Axial {
        /// Stiffness (N/m).
        k: f64,
        /// Relative energy dissipation (-).
        psi: f64,
    },
    /// A vibration isolator: `k = [kn, kt, kt, 0, 0, 0]` (eq. 3.11-3.12).
    Isolator {
        /// Normal stiffness along axis 1 (N/m).
        kn: f64,
        /// Tangential stiffness along axes 2 and 3 (N/m).
        kt: f64,
        /// Relative energy dissipation, normal (-).
        psi_n: f64,
        /// Relative energy dissipation, tangential (-).
        psi_t: f64,
    },
    /// Six independent springs: three translational (N/m) and three rotational (N·m/rad).
    General {
        /// Stiffnesses along/about axes 1-3.
        k: [f64; 6],
        /// Relative energy dissipation per spring (-).
        psi: [f64; 6],
    },
}

/// The named parameters an SDE law exposes to sensitivity analysis and identification.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ParamName {
    /// Normal stiffness (contact: Pa/m; isolator: N/m).
    Kn,
    /// Tangential stiffness (contact with `kt` given directly: Pa/m; isolator: N/m).
    Kt,
    /// Axial stiffness (N/m).
    K,
    /// Normal dissipation ψn.
    PsiN,
    /// Tangential dissipation ψt.
    PsiT,
    /// Axial dissipation ψ.
    Psi,
    /// Spring `i` (0-5) of a general element.
    Ki(u8),
    /// Dissipation of spring `i` (0-5) of a general element.
    PsiI(u8),
}

impl ParamName {
    /// The name as written in files: `kn`, `kt`, `k`, `psi_n`, `psi_t`, `psi`, `k1`..`k6`,
    /// `psi1`..`psi6`.
    pub fn as_str(&self) -> String {
        match self {
            ParamName::Kn => "kn".into(),
            ParamName::Kt => "kt".into(),
            ParamName::K => "k".into(),
            ParamName::PsiN => "psi_n".into(),
            ParamName::PsiT => "psi_t".into(),
            ParamName::Psi => "psi".into(),
            ParamName::Ki(i) => format!("k{}", i + 1),
            ParamName::PsiI(i) => format!("psi{}", i + 1),
        }
    }

    /// Parses a name as written in files (see [`ParamName::as_str`]).
    pub fn parse(s: &str) -> Option<ParamName> {
        Some(match s {
            "kn" => ParamName::Kn,
            "kt" => ParamName::Kt,
            "k" => ParamName::K,
            "psi_n" => ParamName::PsiN,
            "psi_t" => ParamName::PsiT,
            "psi" => ParamName::Psi,
            _ => {
                let (prefix, digit) = if let Some(d) = s.strip_prefix("psi") {
                    (true, d)
                } else if let Some(d) = s.strip_prefix('k') {
                    (false, d)
                } else {
                    return None;
                };
                let i: u8 = digit.parse().ok()?;
                if !(1..=6).contains(&i) {
                    return None;
                }
                if prefix {
                    ParamName::PsiI(i - 1)
                } else {
                    ParamName::Ki(i - 1)
                }
            }
        })
    }

    /// True for dissipation (ψ) parameters, false for stiffnesses.
    pub fn is_dissipation(&self) -> bool {
        matches!(
            self,
            ParamName::PsiN | ParamName::PsiT | ParamName::Psi | ParamName::PsiI(_)
        )
    }
}

impl SdeLaw {
    /// Whether the law has no stiffness in direction `axis` (0-2 along, 3-5 about the SDE's
    /// axes 1-3) whatever its parameters' values: an axial spring's five other directions, an
    /// isolator's rotations, a contact's directions whose area or second moment is 0, a general
    /// element's springs at 0. (A contact whose fitted kn is 0 still has its normal direction.)
    pub fn leaves_out(&self, axis: usize) -> bool {
        match *self {
            SdeLaw::Contact {
                area,
                moments: [j1, j2, j3],
                ..
            } => [area, area, area, j1, j2, j3][axis] == 0.0,
            SdeLaw::Axial { .. } => axis != 0,
            SdeLaw::Isolator { .. } => axis >= 3,
            SdeLaw::General { k, .. } => k[axis] == 0.0,
        }
    }

    /// The six stiffnesses in the SDE frame (N/m for 1-3, N·m/rad for 4-6).
    pub fn stiffness(&self) -> [f64; 6] {
        match *self {
            SdeLaw::Contact {
                area,
                moments: [j1, j2, j3],
                kn,
                kt,
                ..
            } => {
                let kt = tangential_value(kn, kt);
                [area * kn, area * kt, area * kt, j1 * kt, j2 * kn, j3 * kn]
            }
            SdeLaw::Axial { k, .. } => [k, 0.0, 0.0, 0.0, 0.0, 0.0],
            SdeLaw::Isolator { kn, kt, .. } => [kn, kt, kt, 0.0, 0.0, 0.0],
            SdeLaw::General { k, .. } => k,
        }
    }

    /// The six dissipation coefficients ψ = ΔW/W (-).
    pub fn dissipation(&self) -> [f64; 6] {
        match *self {
            SdeLaw::Contact { psi_n, psi_t, .. } => [psi_n, psi_t, psi_t, psi_t, psi_n, psi_n],
            SdeLaw::Axial { psi, .. } => [psi, 0.0, 0.0, 0.0, 0.0, 0.0],
            SdeLaw::Isolator { psi_n, psi_t, .. } => [psi_n, psi_t, psi_t, 0.0, 0.0, 0.0],
            SdeLaw::General { psi, .. } => psi,
        }
    }

    /// The parameters this law exposes, in a fixed order.
    pub fn params(&self) -> Vec<ParamName> {
        match self {
            SdeLaw::Contact { kt, .. } => match kt {
                Tangential::Value(_) => vec![
                    ParamName::Kn,
                    ParamName::Kt,
                    ParamName::PsiN,
                    ParamName::PsiT,
                ],
                Tangential::Ratio(_) => vec![ParamName::Kn, ParamName::PsiN, ParamName::PsiT],
            },
            SdeLaw::Axial { .. } => vec![ParamName::K, ParamName::Psi],
            SdeLaw::Isolator { .. } => vec![
                ParamName::Kn,
                ParamName::Kt,
                ParamName::PsiN,
                ParamName::PsiT,
            ],
            SdeLaw::General { .. } => (0..6)
                .map(ParamName::Ki)
                .chain((0..6).map(ParamName::PsiI))
                .collect(),
        }
    }

    /// The value of a parameter, or `None` if this law has no such parameter.
    pub fn get(&self, p: ParamName) -> Option<f64> {
        match (self, p) {
            (SdeLaw::Contact { kn, .. }, ParamName::Kn) => Some(*kn),
            (
                SdeLaw::Contact {
                    kt: Tangential::Value(kt),
                    ..
                },
                ParamName::Kt,
            ) => Some(*kt),
            (SdeLaw::Contact { psi_n, .. }, ParamName::PsiN) => Some(*psi_n),
            (SdeLaw::Contact { psi_t, .. }, ParamName::PsiT) => Some(*psi_t),
            (SdeLaw::Axial { k, .. }, ParamName::K) => Some(*k),
            (SdeLaw::Axial { psi, .. }, ParamName::Psi) => Some(*psi),
            (SdeLaw::Isolator { kn, .. }, ParamName::Kn) => Some(*kn),
            (SdeLaw::Isolator { kt, .. }, ParamName::Kt) => Some(*kt),
            (SdeLaw::Isolator { psi_n, .. }, ParamName::PsiN) => Some(*psi_n),
            (SdeLaw::Isolator { psi_t, .. }, ParamName::PsiT) => Some(*psi_t),
            (SdeLaw::General { k, .. }, ParamName::Ki(i)) => k.get(i as usize).copied(),
            (SdeLaw::General { psi, .. }, ParamName::PsiI(i)) => psi.get(i as usize).copied(),
            _ => None,
        }
    }

    /// Sets a parameter; returns `false` (and changes nothing) if this law has no such parameter.
    pub fn set(&mut self, p: ParamName, value: f64) -> bool {
        let slot: &mut f64 = match (self, p) {
            (SdeLaw::Contact { kn, .. }, ParamName::Kn) => kn,
            (
                SdeLaw::Contact {
                    kt: Tangential::Value(kt),
                    ..
                },
                ParamName::Kt,
            ) => kt,
            (SdeLaw::Contact { psi_n, .. }, ParamName::PsiN) => psi_n,
            (SdeLaw::Contact { psi_t, .. }, ParamName::PsiT) => psi_t,
            (SdeLaw::Axial { k, .. }, ParamName::K) => k,
            (SdeLaw::Axial { psi, .. }, ParamName::Psi) => psi,
            (SdeLaw::Isolator { kn, .. }, ParamName::Kn) => kn,
            (SdeLaw::Isolator { kt, .. }, ParamName::Kt) => kt,
            (SdeLaw::Isolator { psi_n, .. }, ParamName::PsiN) => psi_n,
            (SdeLaw::Isolator { psi_t, .. }, ParamName::PsiT) => psi_t,
            (SdeLaw::General { k, .. }, ParamName::Ki(i)) if i < 6 => &mut k[i as usize],
            (SdeLaw::General { psi, .. }, ParamName::PsiI(i)) if i < 6 => &mut psi[i as usize],
            _ => return false,
        };
        *slot = value;
        true
    }

    /// Derivatives of the six stiffnesses and six dissipations with respect to parameter `p`.
    /// Every law is linear in its parameters, so these do not depend on the parameter values.
    pub fn derivative(&self, p: ParamName) -> Option<([f64; 6], [f64; 6])> {
        let z = [0.0; 6];
        Some(match (*self, p) {
            (
                SdeLaw::Contact {
                    area,
                    moments: [j1, j2, j3],
                    kt,
                    ..
                },
                ParamName::Kn,
            ) => {
                let r = match kt {
                    Tangential::Ratio(r) => 1.0 / r,
                    Tangential::Value(_) => 0.0,
                };
                ([area, area * r, area * r, j1 * r, j2, j3], z)
            }
            (
                SdeLaw::Contact {
                    area,
                    moments: [j1, ..],
                    kt: Tangential::Value(_),
                    ..
                },
                ParamName::Kt,
            ) => ([0.0, area, area, j1, 0.0, 0.0], z),
            (SdeLaw::Contact { .. }, ParamName::PsiN) => (z, [1.0, 0.0, 0.0, 0.0, 1.0, 1.0]),
            (SdeLaw::Contact { .. }, ParamName::PsiT) => (z, [0.0, 1.0, 1.0, 1.0, 0.0, 0.0]),
            (SdeLaw::Axial { .. }, ParamName::K) => ([1.0, 0.0, 0.0, 0.0, 0.0, 0.0], z),
            (SdeLaw::Axial { .. }, ParamName::Psi) => (z, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
            (SdeLaw::Isolator { .. }, ParamName::Kn) => ([1.0, 0.0, 0.0, 0.0, 0.0, 0.0], z),
            (SdeLaw::Isolator { .. }, ParamName::Kt) => ([0.0, 1.0, 1.0, 0.0, 0.0, 0.0], z),
            (SdeLaw::Isolator { .. }, ParamName::PsiN) => (z, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
            (SdeLaw::Isolator { .. }, ParamName::PsiT) => (z, [0.0, 1.0, 1.0, 0.0, 0.0, 0.0]),
            (SdeLaw::General { .. }, ParamName::Ki(i)) if i < 6 => {
                let mut d = z;
                d[i as usize] = 1.0;
                (d, z)
            }
            (SdeLaw::General { .. }, ParamName::PsiI(i)) if i < 6 => {
                let mut d = z;
                d[i as usize] = 1.0;
                (z, d)
            }
            _ => return None,
        })
    }

    /// SI unit of a parameter of this law, for reports.
    pub fn unit(&self, p: ParamName) -> &'static str {
        match (self, p) {
            (_, p) if p.is_dissipation() => "-",
            (SdeLaw::Contact { .. }, _) => "Pa/m",
            (SdeLaw::General { .. }, ParamName::Ki(i)) if i >= 3 => "N·m/rad",
            _ => "N/m",
        }
    }
}

fn tangential_value(kn: f64, kt: Tangential) -> f64 {
    match kt {
        Tangential::Value(v) => v,
        Tangential::Ratio(r) => kn / r,
    }
}

/// What an SDE models, kept for display and for writing model files back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdeKind {
    /// Slideway joint (contact law).
    Slideway,
    /// Rotary joint / turntable (contact law over an annulus).
    Rotary,
    /// Lead screw (axial law).
    Screw,
    /// Single axial spring, e.g. an exciter (axial law).
    Spring,
    /// Vibration isolator.
    Isolator,
    /// Six independent springs.
    General,
}

impl SdeKind {
    /// The name used in model files.
    pub fn as_str(&self) -> &'static str {
        match self {
            SdeKind::Slideway => "slideway",
            SdeKind::Rotary => "rotary",
            SdeKind::Screw => "screw",
            SdeKind::Spring => "spring",
            SdeKind::Isolator => "isolator",
            SdeKind::General => "general",
        }
    }
}

/// A spring-damping element between two bodies, or between a body and the fixed ground.
#[derive(Debug, Clone, PartialEq)]
pub struct Sde {
    /// Unique name (the paper's global SDE number for the FWD-32J model, e.g. `"34"`).
    pub name: String,
    /// What it models.
    pub kind: SdeKind,
    /// `[p, r]`: indices into [`Model::bodies`], `None` for the fixed ground. The deformation is
    /// the motion of `r` relative to `p` at `point`.
    pub bodies: [Option<usize>; 2],
    /// Where it acts on both bodies, global frame (m).
    pub point: Vector3<f64>,
    /// `global_from_sde`: columns are the SDE's axes 1, 2, 3 in the global frame; axis 1 is the
    /// normal / screw axis.
    pub rotation: Matrix3<f64>,
    /// Stiffness/damping law and its parameters.
    pub law: SdeLaw,
    /// Disabled elements stay in the file (and can be switched on) but contribute nothing.
    pub enabled: bool,
}

/// A mass added rigidly to a body at a point: a sensor, the force gauge, a fixture, bolts. It
/// adds its exact 6×6 block to the body's mass matrix (in the body's coordinates, principal axes
/// at the body's centre of mass): with the arm `a = R_bᵀ(p − c_b)` and `S = [a]×`,
///
/// ```text
/// ΔM = | m I      −m S              |
///      | m S      m SᵀS + R_bᵀ J R_b |
/// ```
///
/// (`m SᵀS` is the parallel-axis term; `J` its own inertia about its centre, global axes), so
/// the body's centre of mass and principal axes stay where the drawing puts them.
#[derive(Debug, Clone, PartialEq)]
pub struct PointMass {
    /// Unique name, as variables files and reports call it.
    pub name: String,
    /// Index into [`Model::bodies`].
    pub body: usize,
    /// Where it sits, global frame (m).
    pub point: Vector3<f64>,
    /// Mass (kg), > 0.
    pub mass: f64,
    /// Its own moments of inertia about its centre along the global x, y, z axes (kg·m², ≥ 0;
    /// zero for a point).
    pub inertia: [f64; 3],
}

impl PointMass {
    /// Its 6×6 mass block on `body` (see [`PointMass`]).
    pub fn block(&self, body: &Body) -> Matrix6<f64> {
        let mut b = Self::unit_block(body, &self.point) * self.mass;
        let rt = body.rotation.transpose();
        let own = rt * Matrix3::from_diagonal(&Vector3::from(self.inertia)) * body.rotation;
        let mut jj = b.fixed_view_mut::<3, 3>(3, 3);
        jj += own;
        b
    }

    /// The block of 1 kg at `point` on `body`, no inertia of its own: `∂ΔM/∂m`.
    pub fn unit_block(body: &Body, point: &Vector3<f64>) -> Matrix6<f64> {
        let a = body.rotation.transpose() * (point - body.position);
        let s = a.cross_matrix();
        let mut b = Matrix6::zeros();
        b.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::identity());
        b.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-s));
        b.fixed_view_mut::<3, 3>(3, 0).copy_from(&s);
        b.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(s.transpose() * s));
        b
    }
}

/// A harmonic force (and optional moment) applied at a point of a body.
#[derive(Debug, Clone, PartialEq)]
pub struct PointForce {
    /// Index into [`Model::bodies`].
    pub body: usize,
    /// Point of application, global frame (m).
    pub point: Vector3<f64>,
    /// Force amplitude, global frame (N).
    pub force: Vector3<f64>,
    /// Moment amplitude, global frame (N·m).
    pub moment: Vector3<f64>,
}

/// Which derivative of the generalized coordinate a characteristic reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Quantity {
    /// m or rad.
    Displacement,
    /// m/s or rad/s (jω times displacement).
    Velocity,
    /// m/s² or rad/s² (−ω² times displacement).
    Acceleration,
}

impl Quantity {
    /// The name used in files: `displacement`, `velocity`, `acceleration`.
    pub fn as_str(&self) -> &'static str {
        match self {
            Quantity::Displacement => "displacement",
            Quantity::Velocity => "velocity",
            Quantity::Acceleration => "acceleration",
        }
    }

    /// Parses a file name of a quantity.
    pub fn parse(s: &str) -> Option<Quantity> {
        match s {
            "displacement" => Some(Quantity::Displacement),
            "velocity" => Some(Quantity::Velocity),
            "acceleration" => Some(Quantity::Acceleration),
            _ => None,
        }
    }

    /// The factor `(jω)^n` that turns a displacement into this quantity at `omega` (rad/s).
    pub fn factor(&self, omega: f64) -> num_complex::Complex<f64> {
        use num_complex::Complex;
        match self {
            Quantity::Displacement => Complex::new(1.0, 0.0),
            Quantity::Velocity => Complex::new(0.0, omega),
            Quantity::Acceleration => Complex::new(-omega * omega, 0.0),
        }
    }
}

/// One output characteristic: `q_body[dof]` in the body's principal central axes, as a quantity —
/// or, with [`Characteristic::at`], the reading of a sensor at a point of the body along a
/// direction.
///
/// This is the one meaning of "characteristic" across the project: model outputs, processed
/// measurements, identification data and reports all use it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Characteristic {
    /// Index into [`Model::bodies`].
    pub body: usize,
    /// 0-2 translations u1..u3, 3-5 rotations r1..r3, along/about the principal axes. For a
    /// point output, the principal translation nearest to its direction (labels, unit notes).
    pub dof: u8,
    /// Displacement, velocity or acceleration.
    pub quantity: Quantity,
    /// `None`: the principal-axis DOF `dof`. `Some`: a point output, `dᵀ(u + θ × (p − c))` in
    /// global axes (see [`PointOutput`]).
    pub at: Option<PointOutput>,
    /// Which excitation the output responds to: 0 the model's `forces`, `i ≥ 1`
    /// [`Model::references`]`[i − 1]`.
    pub reference: u8,
    /// Under base motion: the response relative to the base (`false`: absolute, the
    /// transmissibility). Always `false` for a force reference.
    pub relative: bool,
}

impl Characteristic {
    /// The principal-axis DOF `dof` of `body` as `quantity`.
    pub fn dof(body: usize, dof: u8, quantity: Quantity) -> Characteristic {
        Characteristic {
            body,
            dof,
            quantity,
            at: None,
            reference: 0,
            relative: false,
        }
    }
}

/// Where a point output reads and along what: a sensor at `point` (global, m) whose axis is
/// `direction` (global, unit length). On a rigid body it reads `dᵀ (u + θ × (p − c))`, with `u`
/// and `θ` the body's translation and rotation and `c` its centre of mass.
///
/// Two point outputs are the same output when their coordinates are bit for bit equal (equality,
/// order and hash compare the bits), so it can identify a characteristic.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct PointOutput {
    /// Sensor location, global frame (m).
    pub point: [f64; 3],
    /// Sensor axis, global frame, unit length.
    pub direction: [f64; 3],
}

impl PointOutput {
    /// A point output along `direction` (any non-zero length, normalized here) at `point` (m);
    /// `None` if the direction is zero or either vector is not finite.
    pub fn new(point: Vector3<f64>, direction: Vector3<f64>) -> Option<PointOutput> {
        let n = direction.norm();
        let finite = point.iter().chain(direction.iter()).all(|x| x.is_finite());
        // A direction already of unit length (within rounding) is kept bit for bit, so that a
        // point output written out and read back is the same output.
        let unit = if (n - 1.0).abs() <= 4.0 * f64::EPSILON {
            direction
        } else {
            direction / n
        };
        (finite && n > 0.0).then(|| PointOutput {
            point: point.into(),
            direction: unit.into(),
        })
    }

    /// The principal translation u1-u3 of `body` nearest to the direction, and the cosine of the
    /// angle between them (negative when the direction points along the negative axis).
    pub fn nearest_axis(&self, body: &Body) -> (u8, f64) {
        let d = Vector3::from(self.direction);
        (0..3u8)
            .map(|k| (k, d.dot(&body.rotation.column(k as usize))))
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .unwrap_or((0, 0.0))
    }

    /// `"at (100, 0, 450) mm along (0, 0.6, 0.8)"`.
    pub fn label(&self) -> String {
        let mm = self.point.map(|x| crate::display::sig(x * 1e3, 6));
        let d = self.direction.map(|x| crate::display::sig(x, 6));
        format!(
            "at ({}, {}, {}) mm along ({}, {}, {})",
            mm[0], mm[1], mm[2], d[0], d[1], d[2]
        )
    }

    fn bits(&self) -> [u64; 6] {
        let [a, b, c] = self.point;
        let [d, e, f] = self.direction;
        [a, b, c, d, e, f].map(f64::to_bits)
    }
}

impl PartialEq for PointOutput {
    fn eq(&self, other: &Self) -> bool {
        self.bits() == other.bits()
    }
}

impl Eq for PointOutput {}

impl std::hash::Hash for PointOutput {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.bits().hash(state);
    }
}

impl PartialOrd for PointOutput {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for PointOutput {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        let (a, b) = (
            self.point.iter().chain(&self.direction),
            other.point.iter().chain(&other.direction),
        );
        a.zip(b)
            .map(|(x, y)| x.total_cmp(y))
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    }
}

/// Names of the six DOFs as written in files and reports.
pub const DOF_NAMES: [&str; 6] = ["u1", "u2", "u3", "r1", "r2", "r3"];

/// A complete, resolved model.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    /// Free-text name.
    pub name: String,
    /// Rigid finite elements.
    pub bodies: Vec<Body>,
    /// Spring-damping elements.
    pub sdes: Vec<Sde>,
    /// Excitation: forces at points (reference 0 of an output, see [`Characteristic::reference`]).
    pub forces: Vec<PointForce>,
    /// Further excitations, each one column of an FRF matrix (several shakers, a roving hammer, a
    /// shaker table): reference `i ≥ 1` of an output is `references[i − 1]`.
    pub references: Vec<Reference>,
    /// Output characteristics.
    pub outputs: Vec<Characteristic>,
    /// Masses added rigidly to bodies at points (sensors, the force gauge, fixtures).
    pub point_masses: Vec<PointMass>,
}

/// A named excitation beside the model's `forces`.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    /// Unique name, as data and measurement maps call it.
    pub name: String,
    /// What excites the structure.
    pub excitation: Excitation,
}

/// What a [`Reference`] is.
#[derive(Debug, Clone, PartialEq)]
pub enum Excitation {
    /// Forces (and moments) at points of bodies, amplitudes in N (N·m).
    Forces(Vec<PointForce>),
    /// Prescribed base motion (shaker table): the ground — every SDE attached to it — moves as a
    /// rigid whole along `direction` (global, unit length) with a displacement of 1 m, so the
    /// outputs are transmissibilities (m/m, or any quantity over the same quantity of the base).
    /// The structure responds through its SDEs: with `q = z + T u_b` (`T u_b` every body
    /// following the base rigidly), `A(ω) z = ω² M T u_b`.
    BaseMotion {
        /// Direction of the base motion, global, unit length.
        direction: [f64; 3],
    },
}

/// A reference to one parameter of one SDE.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ParamRef {
    /// Index into [`Model::sdes`].
    pub sde: usize,
    /// Which parameter of that SDE's law.
    pub name: ParamName,
}

/// One parameter a decision variable can set: an SDE's, a body's mass or principal inertia, or the
/// gain of a measured characteristic.
///
/// The dynamic stiffness `K + jD − ω²M` is linear in each of the physical ones: an SDE parameter
/// enters through its law ([`SdeLaw::derivative`]), a mass or inertia through `−ω² ∂M/∂p`, M being
/// diagonal in each body's principal axes ([`Param::inertia_derivative`]). A gain `g` is not in
/// the model: it multiplies a measured characteristic's model output (the identification applies
/// it), so `∂(g q)/∂g = q`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Param {
    /// A parameter of an SDE's law.
    Sde(ParamRef),
    /// The mass of body `body` (kg): the three translational entries of its inertia block.
    Mass {
        /// Index into [`Model::bodies`].
        body: usize,
    },
    /// The principal central moment of inertia `J[axis]` (kg·m², axis 0-2) of body `body`.
    Inertia {
        /// Index into [`Model::bodies`].
        body: usize,
        /// Principal axis, 0-2 (`J1`-`J3` in files).
        axis: u8,
    },
    /// The mass (kg) of point mass `index` ([`Model::point_masses`]); its own inertia is held.
    PointMass {
        /// Index into [`Model::point_masses`].
        index: usize,
    },
    /// The gain (-, 1 = nominal) of the characteristics of body `body`, DOF `dof` (0-5), whatever
    /// their quantity: the model output is multiplied by it.
    Gain {
        /// Index into [`Model::bodies`].
        body: usize,
        /// 0-2 translations u1..u3, 3-5 rotations r1..r3.
        dof: u8,
    },
}

impl From<ParamRef> for Param {
    fn from(p: ParamRef) -> Param {
        Param::Sde(p)
    }
}

impl Param {
    /// The SDE parameter, if it is one.
    pub fn sde(&self) -> Option<ParamRef> {
        match self {
            Param::Sde(r) => Some(*r),
            _ => None,
        }
    }

    /// `∂[m, m, m, J1, J2, J3]/∂p` of the parameter's body, with the body: `Some` only for a mass
    /// or an inertia (the entries are 0 or 1: M is linear in them).
    pub fn inertia_derivative(&self) -> Option<(usize, [f64; 6])> {
        match *self {
            Param::Mass { body } => Some((body, [1.0, 1.0, 1.0, 0.0, 0.0, 0.0])),
            Param::Inertia { body, axis } if axis < 3 => {
                let mut d = [0.0; 6];
                d[3 + axis as usize] = 1.0;
                Some((body, d))
            }
            _ => None,
        }
    }

    /// The parameter's name as written in variables files: the SDE law's (`kn`, `psi`, …), `m`,
    /// `J1`-`J3`, `gain`.
    pub fn name(&self) -> String {
        match self {
            Param::Sde(p) => p.name.as_str(),
            Param::Mass { .. } | Param::PointMass { .. } => "m".into(),
            Param::Inertia { axis, .. } => format!("J{}", axis + 1),
            Param::Gain { .. } => "gain".into(),
        }
    }

    /// SI unit, for reports.
    pub fn unit(&self, model: &Model) -> &'static str {
        match self {
            Param::Sde(p) => model
                .sdes
                .get(p.sde)
                .map(|s| s.law.unit(p.name))
                .unwrap_or("-"),
            Param::Mass { .. } | Param::PointMass { .. } => "kg",
            Param::Inertia { .. } => "kg·m²",
            Param::Gain { .. } => "-",
        }
    }
}

impl Model {
    /// Number of degrees of freedom (6 per body).
    pub fn dof_count(&self) -> usize {
        6 * self.bodies.len()
    }

    /// Index of the body with this name.
    pub fn body_index(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }

    /// Index of the point mass with this name.
    pub fn point_mass_index(&self, name: &str) -> Option<usize> {
        self.point_masses.iter().position(|p| p.name == name)
    }

    /// Mass (kg) a body carries: its own and its point masses'.
    pub fn carried_mass(&self, body: usize) -> f64 {
        let own = self.bodies.get(body).map_or(0.0, |b| b.mass);
        own + self
            .point_masses
            .iter()
            .filter(|p| p.body == body)
            .map(|p| p.mass)
            .sum::<f64>()
    }

    /// Index of the reference with this name, as [`Characteristic::reference`] counts it (1 for
    /// `references[0]`).
    pub fn reference_index(&self, name: &str) -> Option<u8> {
        let i = self.references.iter().position(|r| r.name == name)?;
        u8::try_from(i + 1).ok()
    }

    /// The name of reference `r` (`"excitation"` for 0, the model's forces).
    pub fn reference_name(&self, r: u8) -> &str {
        match r {
            0 => "excitation",
            r => self
                .references
                .get(r as usize - 1)
                .map(|x| x.name.as_str())
                .unwrap_or("?"),
        }
    }

    /// Index of the SDE with this name.
    pub fn sde_index(&self, name: &str) -> Option<usize> {
        self.sdes.iter().position(|s| s.name == name)
    }

    /// Every parameter of every enabled SDE, in model order.
    pub fn all_params(&self) -> Vec<ParamRef> {
        self.sdes
            .iter()
            .enumerate()
            .filter(|(_, s)| s.enabled)
            .flat_map(|(i, s)| {
                s.law
                    .params()
                    .into_iter()
                    .map(move |name| ParamRef { sde: i, name })
            })
            .collect()
    }

    /// Value of a parameter (SI), `None` if the SDE has no such parameter.
    pub fn param(&self, p: ParamRef) -> Option<f64> {
        self.sdes.get(p.sde)?.law.get(p.name)
    }

    /// Sets a parameter (SI); returns `false` if the SDE has no such parameter.
    pub fn set_param(&mut self, p: ParamRef, value: f64) -> bool {
        match self.sdes.get_mut(p.sde) {
            Some(s) => s.law.set(p.name, value),
            None => false,
        }
    }

    /// Every physical parameter of the model: each enabled SDE's law parameters, each body's
    /// mass and principal inertias, each point mass's mass.
    pub fn physical_params(&self) -> Vec<Param> {
        let sdes = self.all_params().into_iter().map(Param::Sde);
        let bodies = (0..self.bodies.len()).flat_map(|body| {
            std::iter::once(Param::Mass { body })
                .chain((0..3).map(move |axis| Param::Inertia { body, axis }))
        });
        let point_masses = (0..self.point_masses.len()).map(|index| Param::PointMass { index });
        sdes.chain(bodies).chain(point_masses).collect()
    }

    /// How `other` differs from this model, `(p, other's value − this one's)` for each physical
    /// parameter that differs, when the two differ in nothing else (the same bodies, SDEs, point
    /// masses, geometry, laws and outputs); `None` otherwise. The dynamic stiffness is linear in
    /// each physical parameter, so a change of the model that moves only these has its
    /// derivative from the parameters' own ([`crate::frf::response_params`]).
    pub fn param_changes(&self, other: &Model) -> Option<Vec<(Param, f64)>> {
        if self.bodies.len() != other.bodies.len()
            || self.sdes.len() != other.sdes.len()
            || self.point_masses.len() != other.point_masses.len()
        {
            return None;
        }
        let mut same = other.clone();
        let mut changes = Vec::new();
        for p in self.physical_params() {
            let (a, b) = (self.value(p)?, other.value(p)?);
            if a != b {
                changes.push((p, b - a));
                same.set_value(p, a);
            }
        }
        (same == *self).then_some(changes)
    }

    /// Value of any parameter (SI); `None` if it does not exist, and for a gain (not part of the
    /// model).
    pub fn value(&self, p: Param) -> Option<f64> {
        match p {
            Param::Sde(r) => self.param(r),
            Param::Mass { body } => self.bodies.get(body).map(|b| b.mass),
            Param::Inertia { body, axis } => {
                self.bodies.get(body)?.inertia.get(axis as usize).copied()
            }
            Param::PointMass { index } => self.point_masses.get(index).map(|p| p.mass),
            Param::Gain { .. } => None,
        }
    }

    /// `∂M/∂p` of a physical mass parameter: the body whose 6×6 block it changes and that
    /// block's derivative (a body's mass or inertia: 0/1 on the diagonal; a point mass: its
    /// [`PointMass::unit_block`]). `None` for SDE parameters and gains.
    pub fn mass_derivative(&self, p: Param) -> Option<(usize, Matrix6<f64>)> {
        match p {
            Param::PointMass { index } => {
                let pm = self.point_masses.get(index)?;
                let body = self.bodies.get(pm.body)?;
                Some((pm.body, PointMass::unit_block(body, &pm.point)))
            }
            _ => {
                let (body, dm) = p.inertia_derivative()?;
                Some((body, Matrix6::from_diagonal(&Vector6::from(dm))))
            }
        }
    }

    /// Sets any parameter (SI); returns `false` if it does not exist or is a gain.
    pub fn set_value(&mut self, p: Param, value: f64) -> bool {
        match p {
            Param::Sde(r) => self.set_param(r, value),
            Param::Mass { body } => match self.bodies.get_mut(body) {
                Some(b) => {
                    b.mass = value;
                    true
                }
                None => false,
            },
            Param::Inertia { body, axis } => {
                match self
                    .bodies
                    .get_mut(body)
                    .and_then(|b| b.inertia.get_mut(axis as usize))
                {
                    Some(j) => {
                        *j = value;
                        true
                    }
                    None => false,
                }
            }
            Param::PointMass { index } => match self.point_masses.get_mut(index) {
                Some(p) => {
                    p.mass = value;
                    true
                }
                None => false,
            },
            Param::Gain { .. } => false,
        }
    }

    /// Human label of any parameter: `"sde 17 kn"`, `"body table m"`, `"body table J2"`,
    /// `"gain table u1"`.
    pub fn label(&self, p: Param) -> String {
        let body = |b: usize| {
            self.bodies
                .get(b)
                .map(|b| b.name.clone())
                .unwrap_or_else(|| format!("#{b}"))
        };
        match p {
            Param::Sde(r) => self.param_label(r),
            Param::Mass { body: b } | Param::Inertia { body: b, .. } => {
                format!("body {} {}", body(b), p.name())
            }
            Param::PointMass { index } => format!(
                "point mass {} m",
                self.point_masses
                    .get(index)
                    .map(|p| p.name.clone())
                    .unwrap_or_else(|| format!("#{index}"))
            ),
            Param::Gain { body: b, dof } => format!(
                "gain {} {}",
                body(b),
                DOF_NAMES.get(dof as usize).copied().unwrap_or("?")
            ),
        }
    }

    /// Human label of a parameter: `"sde 17 kn"`.
    pub fn param_label(&self, p: ParamRef) -> String {
        match self.sdes.get(p.sde) {
            Some(s) => format!("sde {} {}", s.name, p.name.as_str()),
            None => format!("sde #{} {}", p.sde, p.name.as_str()),
        }
    }

    /// Human label of a characteristic: `"table u1 displacement"`.
    pub fn characteristic_label(&self, c: Characteristic) -> String {
        let body = self
            .bodies
            .get(c.body)
            .map(|b| b.name.as_str())
            .unwrap_or("?");
        let mut s = match c.at {
            None => {
                let dof = DOF_NAMES.get(c.dof as usize).copied().unwrap_or("?");
                format!("{body} {dof} {}", c.quantity.as_str())
            }
            Some(p) => format!("{body} {} {}", p.label(), c.quantity.as_str()),
        };
        if c.relative {
            s.push_str(" relative");
        }
        if c.reference != 0 {
            s.push_str(&format!(" / {}", self.reference_name(c.reference)));
        }
        s
    }
}
