//! Machine-tool-like models of any size, for measuring how the closed loop scales: a seeded
//! generator of a model, its identification variables and a case with one undeclared spring
//! between the column and the table (`identify/examples/scaling.rs`, docs/diagnosis.md
//! "Scaling").
//!
//! A model of `n ≥ 4` bodies has two chains on a bed, as a bed-type milling machine:
//!
//! - the **bed** (one or more segments along x, the first on four isolators to the ground,
//!   each further one on two and joined to the one before);
//! - the **column** chain on the first bed segment: one or more column segments stacked along z
//!   (a casting split into several RFEs), then a **ram** along x and the spindle **head** hanging
//!   from it;
//! - the **table** chain on the first bed segment beside the column: one or more **saddles**
//!   stacked along z, then the **table**.
//!
//! Four bodies are bed, column, table and head; the fifth is a saddle, the sixth the ram, and
//! each further body is, in turn, a column segment, a bed segment, a saddle, a column segment. Every pair of
//! stacked bodies is joined by a joint of 2-6 contact SDEs (slideway law, kn/kt = 2.5, ψn 0.8,
//! ψt 1.6) spread over the interface; the feed joints (bed–saddle, saddle–saddle, saddle–table,
//! column–ram) carry a lead screw too (axial law along the feed). Body masses, sizes and joint
//! stiffnesses are drawn around steel-casting values (a seeded `StdRng`).
//!
//! The excitation is a force between the tool (below the head) and the table's top along a
//! skew direction (1 kN); the three characteristics are the head's translations along x and y and
//! the table's along z (displacement).
//!
//! The identification variables are each joint's normal contact stiffness (one per joint, its
//! SDEs share it), each lead screw's stiffness, the isolators' normal stiffness, and the ψ groups
//! of the contacts (ψn, ψt) and screws. The truth's values are the variables' values; a case
//! ([`case`]) starts them a given share away (±, uniform), adds the undeclared spring sized to a
//! given signal (χ² units, see `blind`) and measures 300 log-spaced lines across the
//! model's band with relative noise.

use nalgebra::{Matrix3, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::blind::{self, BlindCase, BlindError};
use diagnose::effects::Effect;
use identify::variables::{self, VarsError};
use identify::Variables;
use rfe::model::Tangential;
use rfe::model::{Body, Characteristic, Model, PointForce, Quantity, Sde, SdeKind, SdeLaw};

/// A generated machine: the truth and its identification variables (initial values = the
/// truth's).
#[derive(Debug, Clone)]
pub struct Machine {
    /// The model (the truth without the undeclared spring).
    pub model: Model,
    /// Its identification variables.
    pub vars: Variables,
    /// Index of the column body the undeclared spring starts from (the lowest column segment).
    pub column: usize,
    /// Index of the table.
    pub table: usize,
}

/// Why a machine or case could not be generated.
#[derive(Debug, thiserror::Error)]
pub enum MachineError {
    /// Fewer than four bodies asked for.
    #[error("a machine needs at least 4 bodies (bed, column, table, head), {0} asked for")]
    TooFewBodies(usize),
    /// The generated variables file did not parse (a bug of the generator).
    #[error(transparent)]
    Vars(#[from] VarsError),
    /// The case could not be drawn.
    #[error(transparent)]
    Case(#[from] BlindError),
    /// No size of any column–table spring reaches the asked signal.
    #[error("no column-table spring reaches a signal of {0}")]
    NoSpring(f64),
    /// The model has no modes to set the band from.
    #[error("cannot compute the model's modes: {0}")]
    Modes(#[from] rfe::frf::SolveError),
}

/// A body's role in its chain.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Bed,
    Column,
    Ram,
    Head,
    Saddle,
    Table,
}

/// The roles of an `n`-body machine: bed, column, table, head, then a saddle, the ram, and
/// the further bodies in turn ([`EXTRA`]).
fn roles(n: usize) -> Vec<Role> {
    let mut out = vec![Role::Bed, Role::Column, Role::Table, Role::Head];
    let first = [Role::Saddle, Role::Ram];
    out.extend(
        first
            .into_iter()
            .chain((0..).map(|i| EXTRA[i % EXTRA.len()]))
            .take(n.saturating_sub(4)),
    );
    out
}

/// The order in which a machine grows beyond six bodies (it has one ram).
const EXTRA: [Role; 4] = [Role::Column, Role::Bed, Role::Saddle, Role::Column];

/// A box-shaped body: centre, size (m) and mass (kg, steel at ~40 % fill for castings).
fn body(name: String, centre: Vector3<f64>, size: Vector3<f64>, rng: &mut StdRng) -> Body {
    let volume = size.x * size.y * size.z;
    let mass = 7850.0 * volume * rng.random_range(0.3..0.5);
    let inertia = [
        mass * (size.y * size.y + size.z * size.z) / 12.0,
        mass * (size.x * size.x + size.z * size.z) / 12.0,
        mass * (size.x * size.x + size.y * size.y) / 12.0,
    ];
    Body {
        name,
        mass,
        inertia,
        position: centre,
        rotation: Matrix3::identity(),
    }
}

/// The SDE frame with axis 1 along `normal` (a global axis 0-2) and axes 2, 3 the next two.
fn frame(normal: usize) -> Matrix3<f64> {
    let e = |i: usize| Vector3::ith(i % 3, 1.0);
    Matrix3::from_columns(&[e(normal), e(normal + 1), e(normal + 2)])
}

/// Builder of the SDEs and variables.
struct Joints {
    sdes: Vec<Sde>,
    contacts: Vec<usize>,
    screws: Vec<usize>,
    isolators: Vec<usize>,
    /// Each joint's contact SDEs (1-based names) and its kn (Pa/m).
    kn_groups: Vec<(Vec<usize>, f64)>,
}

impl Joints {
    fn push(
        &mut self,
        kind: SdeKind,
        bodies: [Option<usize>; 2],
        point: Vector3<f64>,
        rotation: Matrix3<f64>,
        law: SdeLaw,
    ) -> usize {
        let id = self.sdes.len() + 1;
        self.sdes.push(Sde {
            name: id.to_string(),
            kind,
            bodies,
            point,
            rotation,
            law,
            enabled: true,
        });
        id
    }

    /// A joint of 2-6 contact SDEs between `lower` and `upper` over the rectangle of half sides
    /// `half` (global, the `normal` component ignored) centred at `at`, and a lead screw along
    /// `feed` when it is a feed joint.
    fn joint(
        &mut self,
        (lower, upper): (Option<usize>, usize),
        (at, half, normal): (Vector3<f64>, Vector3<f64>, usize),
        feed: Option<usize>,
        rng: &mut StdRng,
    ) {
        let count = rng.random_range(2..=6usize);
        let kn = 0.05e12 * rng.random_range(0.5..2.0);
        let (a1, a2) = ((normal + 1) % 3, (normal + 2) % 3);
        let mut ids = Vec::new();
        for i in 0..count {
            // Spread along the interface: alternate sides of axis a2, walking along a1.
            let s1 = if count == 1 {
                0.0
            } else {
                -1.0 + 2.0 * (i / 2) as f64 / ((count - 1) / 2).max(1) as f64
            };
            let s2 = if i % 2 == 0 { -1.0 } else { 1.0 };
            let mut p = at;
            p[a1] += 0.8 * s1 * half[a1];
            p[a2] += 0.8 * s2 * half[a2];
            let area = 4.0 * half[a1] * half[a2] / count as f64 * 0.3;
            let (l1, l2) = (2.0 * half[a1] / count as f64, 2.0 * half[a2] / 2.0);
            let moments = [
                area * (l1 * l1 + l2 * l2) / 12.0,
                area * l2 * l2 / 12.0,
                area * l1 * l1 / 12.0,
            ];
            let id = self.push(
                SdeKind::Slideway,
                [lower, Some(upper)],
                p,
                frame(normal),
                SdeLaw::Contact {
                    area,
                    moments,
                    kn,
                    kt: Tangential::Ratio(2.5),
                    psi_n: 0.8,
                    psi_t: 1.6,
                },
            );
            self.contacts.push(id);
            ids.push(id);
        }
        self.kn_groups.push((ids, kn));
        if let Some(f) = feed {
            let id = self.push(
                SdeKind::Screw,
                [lower, Some(upper)],
                at,
                frame(f),
                SdeLaw::Axial {
                    k: 1.5e8 * rng.random_range(0.5..2.0),
                    psi: 0.6,
                },
            );
            self.screws.push(id);
        }
    }
}

/// The machine of `n` bodies drawn from `seed`.
pub fn machine(n: usize, seed: u64) -> Result<Machine, MachineError> {
    if n < 4 {
        return Err(MachineError::TooFewBodies(n));
    }
    let mut rng = StdRng::seed_from_u64(seed);
    let roles = roles(n);
    let count = |r: Role| roles.iter().filter(|x| **x == r).count();
    let (beds, columns, saddles) = (count(Role::Bed), count(Role::Column), count(Role::Saddle));
    let has_ram = count(Role::Ram) > 0;
    let mut bodies: Vec<Body> = Vec::new();
    let mut joints = Joints {
        sdes: Vec::new(),
        contacts: Vec::new(),
        screws: Vec::new(),
        isolators: Vec::new(),
        kn_groups: Vec::new(),
    };
    // Bed segments along x: 1.6 × 1.2 × 0.5 m each, top at z = 0.5.
    let bed_size = Vector3::new(1.6, 1.2, 0.5);
    for i in 0..beds {
        let c = Vector3::new(1.6 * i as f64, 0.0, 0.25);
        bodies.push(body(format!("bed {}", i + 1), c, bed_size, &mut rng));
        let b = bodies.len() - 1;
        let corners: &[(f64, f64)] = if i == 0 {
            &[(-0.7, -0.5), (-0.7, 0.5), (0.7, -0.5), (0.7, 0.5)]
        } else {
            &[(0.7, -0.5), (0.7, 0.5)]
        };
        for &(dx, dy) in corners {
            let id = joints.push(
                SdeKind::Isolator,
                [None, Some(b)],
                Vector3::new(c.x + dx, dy, 0.0),
                frame(2),
                SdeLaw::Isolator {
                    kn: 2e8,
                    kt: 8e7,
                    psi_n: 0.3,
                    psi_t: 0.3,
                },
            );
            joints.isolators.push(id);
        }
        if i > 0 {
            // Bolted to the segment before across their common face (normal x).
            let at = Vector3::new(1.6 * i as f64 - 0.8, 0.0, 0.25);
            joints.joint((Some(b - 1), b), (at, bed_size / 2.0, 0), None, &mut rng);
        }
    }
    // Column segments on the first bed at x = −0.4: 0.6 × 0.7 × 0.9 m each.
    let col_size = Vector3::new(0.6, 0.7, 0.9);
    let mut below = 0;
    let mut z = 0.5;
    let mut column = 0;
    for i in 0..columns {
        let c = Vector3::new(-0.4, 0.0, z + col_size.z / 2.0);
        bodies.push(body(format!("column {}", i + 1), c, col_size, &mut rng));
        let b = bodies.len() - 1;
        if i == 0 {
            column = b;
        }
        joints.joint(
            (Some(below), b),
            (Vector3::new(-0.4, 0.0, z), col_size / 2.0, 2),
            None,
            &mut rng,
        );
        below = b;
        z += col_size.z;
    }
    // The ram on the column top, along x, and the head at its front (or on the column's front
    // face without a ram).
    let head_size = Vector3::new(0.35, 0.35, 0.6);
    let head_centre;
    if has_ram {
        let ram_size = Vector3::new(1.0, 0.35, 0.35);
        let c = Vector3::new(0.1, 0.0, z + ram_size.z / 2.0);
        bodies.push(body("ram".into(), c, ram_size, &mut rng));
        let b = bodies.len() - 1;
        joints.joint(
            (Some(below), b),
            (Vector3::new(-0.4, 0.0, z), Vector3::new(0.3, 0.17, 0.0), 2),
            Some(0),
            &mut rng,
        );
        let face = c.x + ram_size.x / 2.0;
        head_centre = Vector3::new(face + head_size.x / 2.0, 0.0, z);
        bodies.push(body("head".into(), head_centre, head_size, &mut rng));
        let h = bodies.len() - 1;
        joints.joint(
            (Some(b), h),
            (Vector3::new(face, 0.0, z), Vector3::new(0.0, 0.17, 0.17), 0),
            Some(2),
            &mut rng,
        );
    } else {
        let face = -0.1;
        head_centre = Vector3::new(face + head_size.x / 2.0, 0.0, z - 0.4);
        bodies.push(body("head".into(), head_centre, head_size, &mut rng));
        let h = bodies.len() - 1;
        joints.joint(
            (Some(below), h),
            (
                Vector3::new(face, 0.0, z - 0.4),
                Vector3::new(0.0, 0.17, 0.3),
                0,
            ),
            Some(2),
            &mut rng,
        );
    }
    // Saddles and the table on the first bed at x = 0.5 (under the head).
    let mut below = 0;
    let mut z = 0.5;
    let saddle_size = Vector3::new(0.7, 0.7, 0.15);
    for i in 0..saddles {
        let c = Vector3::new(0.5, 0.0, z + saddle_size.z / 2.0);
        bodies.push(body(format!("saddle {}", i + 1), c, saddle_size, &mut rng));
        let b = bodies.len() - 1;
        joints.joint(
            (Some(below), b),
            (Vector3::new(0.5, 0.0, z), saddle_size / 2.0, 2),
            Some(if i % 2 == 0 { 1 } else { 0 }),
            &mut rng,
        );
        below = b;
        z += saddle_size.z;
    }
    let table_size = Vector3::new(1.2, 0.5, 0.15);
    let tc = Vector3::new(0.5, 0.0, z + table_size.z / 2.0);
    bodies.push(body("table".into(), tc, table_size, &mut rng));
    let table = bodies.len() - 1;
    joints.joint(
        (Some(below), table),
        (Vector3::new(0.5, 0.0, z), Vector3::new(0.5, 0.2, 0.0), 2),
        Some(0),
        &mut rng,
    );
    let head = bodies
        .iter()
        .position(|b| b.name == "head")
        .unwrap_or(bodies.len() - 1);
    let dir = Vector3::new(400.0, 300.0, 866.0);
    let tool = head_centre - Vector3::new(0.0, 0.0, head_size.z / 2.0 + 0.1);
    let top = tc + Vector3::new(0.0, 0.0, table_size.z / 2.0);
    let model = Model {
        name: format!("generated machine tool of {n} bodies (seed {seed})"),
        forces: vec![
            PointForce {
                body: head,
                point: tool,
                force: dir,
                moment: Vector3::zeros(),
            },
            PointForce {
                body: table,
                point: top,
                force: -dir,
                moment: Vector3::zeros(),
            },
        ],
        references: Vec::new(),
        point_masses: Vec::new(),
        outputs: vec![
            Characteristic::dof(head, 0, Quantity::Displacement),
            Characteristic::dof(head, 1, Quantity::Displacement),
            Characteristic::dof(table, 2, Quantity::Displacement),
        ],
        bodies,
        sdes: joints.sdes.clone(),
    };
    let vars = variables::parse(&variables_toml(&joints), "generated machine", &model)?;
    Ok(Machine {
        model,
        vars,
        column,
        table,
    })
}

/// The variables file of a generated machine (initial values = the truth's).
fn variables_toml(j: &Joints) -> String {
    let list = |ids: &[usize]| {
        ids.iter()
            .map(usize::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut s = String::from("note = \"generated machine tool\"\n");
    let mut var = |name: &str, sdes: &str, parameter: &str, initial: String| {
        s.push_str(&format!(
            "\n[[variable]]\nname = \"{name}\"\nsdes = \"{sdes}\"\nparameter = \"{parameter}\"\ninitial = {initial}\n"
        ));
    };
    for (ids, kn) in &j.kn_groups {
        var(
            &format!("kn {}", list(ids)),
            &list(ids),
            "kn",
            format!("\"{} MPa/um\"", kn / 1e12),
        );
    }
    for &id in &j.screws {
        if let SdeLaw::Axial { k, .. } = j.sdes[id - 1].law {
            var(
                &format!("k {id}"),
                &id.to_string(),
                "k",
                format!("\"{} N/um\"", k / 1e6),
            );
        }
    }
    var(
        "isolator kn",
        &list(&j.isolators),
        "kn",
        format!("\"{} N/um\"", 2e8 / 1e6),
    );
    var("contact psi_n", &list(&j.contacts), "psi_n", "0.8".into());
    var("contact psi_t", &list(&j.contacts), "psi_t", "1.6".into());
    if !j.screws.is_empty() {
        var("screw psi", &list(&j.screws), "psi", "0.6".into());
    }
    s
}

/// The band of a machine's measurement (Hz): from 0.7× its first natural frequency to 1.2× its
/// `(3 · bodies / 2)`-th, so that about half of its modes lie in it whatever its size.
pub fn band(model: &Model) -> Result<(f64, f64), MachineError> {
    let modes = rfe::modes::undamped(model)?;
    let f: Vec<f64> = modes.iter().map(|m| m.freq_hz).collect();
    let k = (3 * model.bodies.len() / 2).min(f.len()).max(1) - 1;
    Ok((0.7 * f[0], 1.2 * f[k]))
}

/// A case on machine `m`: an undeclared spring between the column and the table (the column–
/// table spring candidate drawn from `seed`, sized so that its noise-free change of the data is
/// `signal` χ² units at relative noise `noise`), `lines` log-spaced lines across [`band`], and the
/// variables started `offset` (a share, e.g. 0.2) away from the truth (uniform within ±).
pub fn case(
    m: &Machine,
    lines: usize,
    (signal, noise): (f64, f64),
    offset: f64,
    seed: u64,
) -> Result<BlindCase, MachineError> {
    let (f_lo, f_hi) = band(&m.model)?;
    let freqs = identify::synthetic::log_lines(f_lo, f_hi, lines);
    let x = m.vars.initial();
    let labels: Vec<String> = (0..m.model.outputs.len())
        .map(|o| format!("#{o}"))
        .collect();
    let names = [
        m.model.bodies[m.column].name.clone(),
        m.model.bodies[m.table].name.clone(),
    ];
    let springs: Vec<Effect> =
        diagnose::generate::candidates(&m.model, &m.vars, &x, &labels, f_lo, f_hi)
            .into_iter()
            .filter(|e| match e {
                Effect::Spring { bodies, .. } => {
                    let b = [bodies[0].as_deref(), bodies[1].as_deref()];
                    b.contains(&Some(names[0].as_str())) && b.contains(&Some(names[1].as_str()))
                }
                _ => false,
            })
            .collect();
    let mut rng = StdRng::seed_from_u64(seed);
    for _ in 0..springs.len().max(1) * 2 {
        let Some(effect) = springs.get(rng.random_range(0..springs.len().max(1))) else {
            break;
        };
        let Some(mut c) =
            blind::with_effect(&m.model, &m.vars, &freqs, effect, (signal, noise), seed)?
        else {
            continue;
        };
        for (v, xi) in c.vars.vars.iter_mut().zip(&x) {
            let f = 1.0 + rng.random_range(-offset..offset);
            v.initial = (xi * f).clamp(v.lower, v.upper);
        }
        return Ok(c);
    }
    Err(MachineError::NoSpring(signal))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn machines_grow_as_documented() {
        for n in [4, 7, 14, 28] {
            let m = machine(n, 1).unwrap();
            assert_eq!(m.model.bodies.len(), n);
            assert!(
                m.model.sdes.len() >= 2 * (n - 1) + 4,
                "{n}: {} SDEs",
                m.model.sdes.len()
            );
            assert!(m.vars.len() >= n, "{n}: {} variables", m.vars.len());
            assert!(m.model.bodies[m.column].name.starts_with("column"));
            assert_eq!(m.model.bodies[m.table].name, "table");
            let (lo, hi) = band(&m.model).unwrap();
            assert!(lo > 0.0 && hi > lo, "{n}: band {lo}-{hi}");
        }
    }
}
