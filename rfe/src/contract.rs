//! The resolved model JSON: the interchange contract with other tools
//! (`docs/model-json.md`). SI units only, every SDE reduced to
//! six stiffnesses and six dissipations in its own frame, every excitation to forces at points.
//! Rotations are row-major 3×3 matrices whose **columns** are the body's principal axes (or the
//! SDE's axes) in the global frame. This module reads and writes exactly that form, and the
//! frequency-response JSON of `ident frf --json`.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::check::Item;
use crate::frf::Response;
use crate::model::{
    Body, Characteristic, Excitation, Model, PointForce, PointMass, PointOutput, Quantity,
    Reference, Sde, SdeKind, SdeLaw,
};

/// The resolved model as serialized.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelJson {
    /// Free text.
    pub name: String,
    /// Rigid finite elements.
    pub bodies: Vec<BodyJson>,
    /// Spring-damping elements (enabled ones only).
    pub sdes: Vec<SdeJson>,
    /// Forces at points.
    pub excitation: ExcitationJson,
    /// Further excitations (reference `i + 1` of an output), absent when there are none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub references: Vec<ReferenceJson>,
    /// Output characteristics.
    pub outputs: Vec<OutputJson>,
    /// Masses added rigidly to bodies at points, absent when there are none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub point_masses: Vec<PointMassJson>,
}

/// `point_masses[i]`: a mass added rigidly to a body (sensor, force gauge, fixture).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointMassJson {
    /// Unique name.
    pub name: String,
    /// Body index.
    pub body: usize,
    /// Global, m.
    pub point: [f64; 3],
    /// kg.
    pub mass: f64,
    /// Its own moments of inertia about its centre along global x, y, z, kg·m² (absent: 0).
    #[serde(default, skip_serializing_if = "is_zero3")]
    pub inertia: [f64; 3],
}

impl From<&PointMass> for PointMassJson {
    fn from(p: &PointMass) -> Self {
        PointMassJson {
            name: p.name.clone(),
            body: p.body,
            point: p.point.into(),
            mass: p.mass,
            inertia: p.inertia,
        }
    }
}

impl From<&PointMassJson> for PointMass {
    fn from(p: &PointMassJson) -> Self {
        PointMass {
            name: p.name.clone(),
            body: p.body,
            point: p.point.into(),
            mass: p.mass,
            inertia: p.inertia,
        }
    }
}

fn is_zero3(j: &[f64; 3]) -> bool {
    *j == [0.0; 3]
}

/// `bodies[i]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodyJson {
    /// Unique name.
    pub name: String,
    /// kg.
    pub mass: f64,
    /// Principal central moments, kg·m².
    pub inertia: [f64; 3],
    /// Centre of mass, global, m.
    pub position: [f64; 3],
    /// Row-major; columns are the principal axes in the global frame.
    pub rotation: [[f64; 3]; 3],
}

/// `sdes[k]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SdeJson {
    /// Unique name.
    pub name: String,
    /// `[p, r]`, `null` = ground.
    pub bodies: [Option<usize>; 2],
    /// Global, m.
    pub point: [f64; 3],
    /// Row-major; columns are the SDE's axes 1-3 in the global frame.
    pub rotation: [[f64; 3]; 3],
    /// N/m (1-3), N·m/rad (4-6).
    pub k: [f64; 6],
    /// ψ = ΔW/W per spring.
    pub psi: [f64; 6],
}

/// `excitation`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExcitationJson {
    /// Forces at points.
    pub forces: Vec<ForceJson>,
}

/// `references[i]`: a named excitation, forces or base motion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceJson {
    /// Unique name.
    pub name: String,
    /// Forces at points (when not base motion).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub forces: Vec<ForceJson>,
    /// Base motion: the ground's direction of motion (global, unit), 1 m amplitude.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_motion: Option<[f64; 3]>,
}

/// `excitation.forces[i]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceJson {
    /// Body index.
    pub body: usize,
    /// Global, m; default the body's centre of mass.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub point: Option<[f64; 3]>,
    /// N, global.
    pub force: [f64; 3],
    /// N·m, global.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moment: Option<[f64; 3]>,
}

/// `outputs[i]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputJson {
    /// Body index.
    pub body: usize,
    /// 0-5: u1 u2 u3 r1 r2 r3.
    pub dof: u8,
    /// `displacement`, `velocity` or `acceleration`.
    pub quantity: String,
    /// A point output: sensor location (global, m) and axis (global, unit); absent for a
    /// principal-axis DOF (then `dof` is the output, else the principal axis nearest the axis).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at: Option<PointOutput>,
    /// The excitation: 0 (absent) `excitation`, `i ≥ 1` `references[i − 1]`.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub reference: u8,
    /// Under base motion: relative to the base (absent: absolute).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub relative: bool,
}

fn is_zero(r: &u8) -> bool {
    *r == 0
}

fn force_json(f: &PointForce) -> ForceJson {
    ForceJson {
        body: f.body,
        point: Some(f.point.into()),
        force: f.force.into(),
        moment: (f.moment != Vector3::zeros()).then(|| f.moment.into()),
    }
}

fn output_json(c: &Characteristic) -> OutputJson {
    OutputJson {
        body: c.body,
        dof: c.dof,
        quantity: c.quantity.as_str().into(),
        at: c.at,
        reference: c.reference,
        relative: c.relative,
    }
}

fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

fn from_rows(r: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|i, j| r[i][j])
}

/// The resolved JSON of a model (disabled SDEs are left out: they do not exist in the resolved
/// form).
pub fn to_json(model: &Model) -> ModelJson {
    ModelJson {
        name: model.name.clone(),
        bodies: model
            .bodies
            .iter()
            .map(|b| BodyJson {
                name: b.name.clone(),
                mass: b.mass,
                inertia: b.inertia,
                position: b.position.into(),
                rotation: rows(&b.rotation),
            })
            .collect(),
        sdes: model
            .sdes
            .iter()
            .filter(|s| s.enabled)
            .map(|s| SdeJson {
                name: s.name.clone(),
                bodies: s.bodies,
                point: s.point.into(),
                rotation: rows(&s.rotation),
                k: s.law.stiffness(),
                psi: s.law.dissipation(),
            })
            .collect(),
        excitation: ExcitationJson {
            forces: model.forces.iter().map(force_json).collect(),
        },
        outputs: model.outputs.iter().map(output_json).collect(),
        references: model
            .references
            .iter()
            .map(|r| match &r.excitation {
                Excitation::Forces(f) => ReferenceJson {
                    name: r.name.clone(),
                    forces: f.iter().map(force_json).collect(),
                    base_motion: None,
                },
                Excitation::BaseMotion { direction } => ReferenceJson {
                    name: r.name.clone(),
                    forces: Vec::new(),
                    base_motion: Some(*direction),
                },
            })
            .collect(),
        point_masses: model.point_masses.iter().map(PointMassJson::from).collect(),
    }
}

/// A problem located by JSON path.
#[derive(Debug, Clone, PartialEq)]
pub struct JsonProblem {
    /// e.g. `$.sdes[3].bodies`.
    pub path: String,
    /// What is wrong.
    pub message: String,
}

/// The JSON path of a model item.
pub fn json_path(item: Item) -> String {
    match item {
        Item::Body(i, f) => format!("$.bodies[{i}].{f}"),
        Item::Sde(i, f) => format!("$.sdes[{i}].{f}"),
        Item::Force(i, f) => format!("$.excitation.forces[{i}].{f}"),
        Item::Output(i, f) => format!("$.outputs[{i}].{f}"),
        Item::PointMass(i, f) => format!("$.point_masses[{i}].{f}"),
        Item::Model => "$".into(),
    }
}

/// Converts the serialized form to a model (structural conversion only; [`crate::check::check`]
/// validates the physics). Errors: an unknown quantity, or a body index out of range.
pub fn from_json(j: &ModelJson) -> Result<Model, JsonProblem> {
    let forces = forces_from_json(j, &j.excitation.forces, "$.excitation.forces")?;
    let mut references = Vec::new();
    for (i, r) in j.references.iter().enumerate() {
        let excitation = match (&r.base_motion, r.forces.is_empty()) {
            (Some(d), true) => {
                let n = Vector3::from(*d).norm();
                if !(n.is_finite() && n > 0.0) {
                    return Err(JsonProblem {
                        path: format!("$.references[{i}].base_motion"),
                        message: "the base motion needs a finite, non-zero direction".into(),
                    });
                }
                Excitation::BaseMotion {
                    direction: (Vector3::from(*d) / n).into(),
                }
            }
            (None, _) => Excitation::Forces(forces_from_json(
                j,
                &r.forces,
                &format!("$.references[{i}].forces"),
            )?),
            (Some(_), false) => {
                return Err(JsonProblem {
                    path: format!("$.references[{i}]"),
                    message: "a reference is either forces or a base motion, not both".into(),
                })
            }
        };
        references.push(Reference {
            name: r.name.clone(),
            excitation,
        });
    }
    let mut outputs = Vec::new();
    for (i, o) in j.outputs.iter().enumerate() {
        let quantity = Quantity::parse(&o.quantity).ok_or_else(|| JsonProblem {
            path: format!("$.outputs[{i}].quantity"),
            message: format!(
                "unknown quantity \"{}\"; use displacement, velocity or acceleration",
                o.quantity
            ),
        })?;
        outputs.push(Characteristic {
            body: o.body,
            dof: o.dof,
            quantity,
            at: match o.at {
                None => None,
                Some(p) => Some(
                    PointOutput::new(p.point.into(), p.direction.into()).ok_or_else(|| {
                        JsonProblem {
                            path: format!("$.outputs[{i}].at"),
                            message: "a point output needs a finite point and a non-zero, finite direction".into(),
                        }
                    })?,
                ),
            },
            reference: o.reference,
            relative: o.relative,
        });
    }
    Ok(Model {
        name: j.name.clone(),
        bodies: j
            .bodies
            .iter()
            .map(|b| Body {
                name: b.name.clone(),
                mass: b.mass,
                inertia: b.inertia,
                position: b.position.into(),
                rotation: from_rows(&b.rotation),
            })
            .collect(),
        sdes: j
            .sdes
            .iter()
            .map(|s| Sde {
                name: s.name.clone(),
                kind: SdeKind::General,
                bodies: s.bodies,
                point: s.point.into(),
                rotation: from_rows(&s.rotation),
                law: SdeLaw::General { k: s.k, psi: s.psi },
                enabled: true,
            })
            .collect(),
        forces,
        references,
        outputs,
        point_masses: j.point_masses.iter().map(PointMass::from).collect(),
    })
}

/// The forces of a JSON list at `path`, body indices checked.
fn forces_from_json(
    j: &ModelJson,
    list: &[ForceJson],
    path: &str,
) -> Result<Vec<PointForce>, JsonProblem> {
    let nb = j.bodies.len();
    let mut forces = Vec::new();
    for (i, f) in list.iter().enumerate() {
        let Some(body) = j.bodies.get(f.body) else {
            return Err(JsonProblem {
                path: format!("{path}[{i}].body"),
                message: format!(
                    "body index {} does not exist; there are {nb} bodies (0-based)",
                    f.body
                ),
            });
        };
        forces.push(PointForce {
            body: f.body,
            point: f
                .point
                .map(Vector3::from)
                .unwrap_or_else(|| Vector3::from(body.position)),
            force: f.force.into(),
            moment: f.moment.map(Vector3::from).unwrap_or_else(Vector3::zeros),
        });
    }
    Ok(forces)
}

/// `ident frf --json` output: `{ "freqs_hz": [...], "outputs": [ {body, dof, quantity, re, im} ] }`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrfJson {
    /// Hz.
    pub freqs_hz: Vec<f64>,
    /// One entry per output characteristic.
    pub outputs: Vec<FrfOutputJson>,
}

/// One characteristic of [`FrfJson`]: the output as in the model's `outputs` and its values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrfOutputJson {
    /// Which output: body, DOF, quantity, point, reference and motion, as in [`OutputJson`].
    #[serde(flatten)]
    pub output: OutputJson,
    /// Real parts, SI.
    pub re: Vec<f64>,
    /// Imaginary parts, SI.
    pub im: Vec<f64>,
}

/// The contract's FRF JSON of a response.
pub fn frf_json(model: &Model, r: &Response) -> FrfJson {
    FrfJson {
        freqs_hz: r.freqs_hz.clone(),
        outputs: model
            .outputs
            .iter()
            .enumerate()
            .map(|(o, c)| FrfOutputJson {
                output: output_json(c),
                re: r.output(o).iter().map(|v| v.re).collect(),
                im: r.output(o).iter().map(|v| v.im).collect(),
            })
            .collect(),
    }
}
