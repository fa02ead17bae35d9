//! The oriented tool–workpiece FRF: the relative receptance between a point on the tool's body
//! and a point on the workpiece's body in the cutting plane's two directions, computed by
//! `identify`'s FRF paths (direct or modal) on a dense grid, with its analytic Jacobian with
//! respect to the identification variables, optionally with a tool's own modes in series.
//!
//! The cutting force acts on the tool as `+F` and on the workpiece as `−F`, and chatter
//! regenerates the *relative* displacement `r = x_tool − x_workpiece`; so
//! `Φ_ij = e_i · r` per unit force along `e_j` applied as that pair. Both are computed in one
//! solve: each direction is one reference (a force pair) of an auxiliary copy of the model and
//! each reading one point output.

use nalgebra::Vector3;

use identify::variables::Variables;
use rfe::frf::{self, Method, ModalSolver};
use rfe::model::{
    Characteristic, Excitation, Model, Param, PointForce, PointOutput, Quantity, Reference,
};
use rfe::system::System;
use rfe::C64;

use crate::cut::{Contact, Cut};
use crate::StabilityError;

/// A 2×2 complex matrix `[i][j]`.
pub type Mat2 = [[C64; 2]; 2];

/// How far outside a body's equivalent box (the uniform box with its mass and principal
/// inertias) a tool or workpiece point may lie: a quarter of the half-size, at least 20 mm. The
/// box is an estimate of the body's extent (a spindle nose sticks out of its head's box); the
/// allowance catches a point typed on the wrong body or in the wrong unit, not a few centimetres.
const BOX_ALLOWANCE: f64 = 0.25;
const BOX_ALLOWANCE_MIN: f64 = 0.02;

/// The oriented FRF on a grid, and its derivatives with respect to the variables.
#[derive(Debug, Clone)]
pub struct OrientedFrf {
    /// Frequencies (Hz).
    pub freqs_hz: Vec<f64>,
    /// `phi[k][i][j]` (m/N) at line `k`.
    pub phi: Vec<Mat2>,
    /// `dphi[v][k][i][j]`: ∂Φ/∂x_v (m/N per SI unit of variable `v`); empty without variables.
    pub dphi: Vec<Vec<Mat2>>,
}

/// Where the cut is in the model: the auxiliary model whose outputs read the relative
/// displacements, and the bodies of the two points.
#[derive(Debug, Clone)]
pub struct Placement {
    /// The model with the two force pairs as references 1 and 2 and the point outputs.
    pub aux: Model,
    /// `(output, direction i, force direction j, sign)`: Φ_ij += sign · output.
    pub taps: Vec<(usize, usize, usize, f64)>,
    /// Tool body (`None`: ground).
    pub tool_body: Option<usize>,
    /// Workpiece body (`None`: ground).
    pub workpiece_body: Option<usize>,
    /// The two directions (global, unit).
    pub directions: [Vector3<f64>; 2],
}

/// Finds the body a contact names and checks that its point is on it.
fn body_of(
    model: &Model,
    c: &Contact,
    role: &str,
    file: &str,
) -> Result<Option<usize>, StabilityError> {
    if c.body == "ground" {
        return Ok(None);
    }
    let b = model
        .body_index(&c.body)
        .ok_or_else(|| StabilityError::Placement {
            file: file.into(),
            field: format!("{role}.body"),
            message: format!(
                "no body \"{}\" in model \"{}\"; its bodies are: {}, or \"ground\"",
                c.body,
                model.name,
                model
                    .bodies
                    .iter()
                    .map(|b| format!("\"{}\"", b.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        })?;
    let body = &model.bodies[b];
    // Points the model itself already attaches to the body are on it.
    let used = model
        .sdes
        .iter()
        .filter(|s| s.bodies.contains(&Some(b)))
        .map(|s| s.point)
        .chain(model.forces.iter().filter(|f| f.body == b).map(|f| f.point))
        .any(|p| (p - c.point).norm() <= 1e-3);
    let half = equivalent_half_sizes(body.mass, body.inertia);
    let local = body.rotation.transpose() * (c.point - body.position);
    let outside: f64 = (0..3)
        .map(|k| {
            let allowed = half[k] + (BOX_ALLOWANCE * half[k]).max(BOX_ALLOWANCE_MIN);
            (local[k].abs() - allowed).max(0.0)
        })
        .fold(0.0, f64::max);
    if outside > 0.0 && !used {
        return Err(StabilityError::Placement {
            file: file.into(),
            field: format!("{role}.point"),
            message: format!(
                "({:.4}, {:.4}, {:.4}) m is {:.0} mm outside body \"{}\" (its equivalent box: centre ({:.3}, {:.3}, {:.3}) m, half-sizes {:.0} × {:.0} × {:.0} mm along its principal axes); give a point on that body (coordinates in metres, global frame) or name the body the point is on",
                c.point.x,
                c.point.y,
                c.point.z,
                outside * 1e3,
                body.name,
                body.position.x,
                body.position.y,
                body.position.z,
                half[0] * 1e3,
                half[1] * 1e3,
                half[2] * 1e3
            ),
        });
    }
    Ok(Some(b))
}

/// Half-sizes (m) of the uniform box with mass `m` and principal inertias `j`:
/// `a² = 6 (J2 + J3 − J1) / m` for the full side along axis 1, and so on.
fn equivalent_half_sizes(m: f64, j: [f64; 3]) -> [f64; 3] {
    let side = |a: usize, b: usize, c: usize| (6.0 * (j[b] + j[c] - j[a]) / m).max(0.0).sqrt();
    [
        0.5 * side(0, 1, 2),
        0.5 * side(1, 0, 2),
        0.5 * side(2, 0, 1),
    ]
}

/// Places the cut in the model: resolves the bodies, checks the points, builds the auxiliary
/// model.
pub fn place(model: &Model, cut: &Cut) -> Result<Placement, StabilityError> {
    let tool_body = body_of(model, &cut.tool, "tool", &cut.origin)?;
    let workpiece_body = body_of(model, &cut.workpiece, "workpiece", &cut.origin)?;
    if tool_body.is_none() && workpiece_body.is_none() {
        return Err(StabilityError::Placement {
            file: cut.origin.clone(),
            field: "tool.body".into(),
            message: "the tool and the workpiece are both on the ground, so nothing can vibrate; name the body that carries the spindle".into(),
        });
    }
    let directions = cut.directions();
    let mut aux = model.clone();
    aux.forces.clear();
    aux.outputs.clear();
    aux.references = directions
        .iter()
        .enumerate()
        .map(|(j, d)| Reference {
            name: format!("cutting direction {}", j + 1),
            excitation: Excitation::Forces(
                [
                    (tool_body, &cut.tool, 1.0),
                    (workpiece_body, &cut.workpiece, -1.0),
                ]
                .iter()
                .filter_map(|(b, c, s)| {
                    b.map(|b| PointForce {
                        body: b,
                        point: c.point,
                        force: d * *s,
                        moment: Vector3::zeros(),
                    })
                })
                .collect(),
            ),
        })
        .collect();
    let mut taps = Vec::new();
    for (b, c, sign) in [
        (tool_body, &cut.tool, 1.0),
        (workpiece_body, &cut.workpiece, -1.0),
    ] {
        let Some(b) = b else { continue };
        for j in 0..2 {
            for (i, d) in directions.iter().enumerate() {
                let at =
                    PointOutput::new(c.point, *d).ok_or_else(|| StabilityError::Placement {
                        file: cut.origin.clone(),
                        field: "directions".into(),
                        message: "a cutting direction is zero or not finite".into(),
                    })?;
                let dof = at.nearest_axis(&model.bodies[b]).0;
                taps.push((aux.outputs.len(), i, j, sign));
                aux.outputs.push(Characteristic {
                    body: b,
                    dof,
                    quantity: Quantity::Displacement,
                    at: Some(at),
                    reference: (j + 1) as u8,
                    relative: false,
                });
            }
        }
    }
    Ok(Placement {
        aux,
        taps,
        tool_body,
        workpiece_body,
        directions,
    })
}

/// The tool's clamped modes in series at the tool point:
/// `H_ij = Σ (e_i·d)(e_j·d) / (k (1 − r² + 2jζr))`, `r = ω/ω_n`, added to the machine's relative
/// receptance (rigid coupling at the spindle nose, translations only: the rotation–moment
/// receptances of the nose are left out).
pub fn tool_receptance(cut: &Cut, directions: &[Vector3<f64>; 2], freq_hz: f64) -> Mat2 {
    let mut h = [[C64::new(0.0, 0.0); 2]; 2];
    let mut add = |frf: C64, d: &Vector3<f64>| {
        for i in 0..2 {
            for j in 0..2 {
                h[i][j] += frf * directions[i].dot(d) * directions[j].dot(d);
            }
        }
    };
    for m in &cut.tool_modes {
        let r = freq_hz / m.freq_hz;
        add(
            C64::new(1.0 - r * r, 2.0 * m.damping_ratio * r).inv() / m.stiffness,
            &m.direction,
        );
    }
    // A measured tool receptance (UFF) along its direction, the same way.
    for t in &cut.tool_frfs {
        add(t.at(freq_hz), &t.direction);
    }
    h
}

/// The oriented FRF of `model` on `freqs_hz` (m/N), with ∂Φ/∂x for each variable of `vars` when
/// given (gains are not model parameters and are left out).
pub fn oriented_frf(
    placement: &Placement,
    cut: &Cut,
    freqs_hz: &[f64],
    vars: Option<&Variables>,
    method: Method,
) -> Result<OrientedFrf, StabilityError> {
    let params: Vec<Param> = vars.map(|v| v.model_params()).unwrap_or_default();
    let r = frf::response_params(&placement.aux, freqs_hz, &params, method)?;
    let lines = freqs_hz.len();
    let zero = [[C64::new(0.0, 0.0); 2]; 2];
    let mut phi: Vec<Mat2> = freqs_hz
        .iter()
        .map(|&f| tool_receptance(cut, &placement.directions, f))
        .collect();
    for &(o, i, j, s) in &placement.taps {
        for (k, v) in r.output(o).iter().enumerate() {
            phi[k][i][j] += v * s;
        }
    }
    let mut dphi = Vec::new();
    if let Some(vars) = vars {
        for v in &vars.vars {
            let mut d = vec![zero; lines];
            for t in &v.targets {
                let Some(p) = params.iter().position(|p| *p == t.param) else {
                    continue;
                };
                for &(o, i, j, s) in &placement.taps {
                    for (k, x) in r.derivative(p, o).iter().enumerate() {
                        d[k][i][j] += x * (s * t.ratio);
                    }
                }
            }
            dphi.push(d);
        }
    }
    Ok(OrientedFrf {
        freqs_hz: freqs_hz.to_vec(),
        phi,
        dphi,
    })
}

/// The oriented FRF as a sum over the model's modes, `Φ(ω) = Σ_m R_m / (λ_m − ω²)` with the
/// residues `R_m = (row·x_m)(y_m·load)` of the modal path ([`ModalSolver`]), and what each mode
/// is: frequency, loss factor, kinetic energy by body, strain energy by SDE.
pub struct ModalSplit {
    /// Eigenvalue λ per mode (rad²/s²).
    pub lambda: Vec<C64>,
    /// Residue per mode (m/N · rad²/s²).
    pub residues: Vec<Mat2>,
    /// Natural frequency (Hz) per mode.
    pub freq_hz: Vec<f64>,
    /// Loss factor per mode.
    pub loss_factor: Vec<f64>,
    /// Kinetic-energy share per body, per mode.
    pub body_energy: Vec<Vec<f64>>,
    /// Strain-energy share per enabled SDE `(index into Model::sdes, share)`, per mode.
    pub sde_energy: Vec<Vec<(usize, f64)>>,
}

impl ModalSplit {
    /// Mode `m`'s contribution to Φ at `freq_hz`.
    pub fn contribution(&self, m: usize, freq_hz: f64) -> Mat2 {
        let w2 = (2.0 * std::f64::consts::PI * freq_hz).powi(2);
        let den = (self.lambda[m] - w2).inv();
        self.residues[m].map(|row| row.map(|v| v * den))
    }
}

/// The modal split of a placed cut (one eigen-decomposition).
pub fn modal_split(placement: &Placement) -> Result<ModalSplit, StabilityError> {
    let s = System::assemble(&placement.aux);
    let modal = ModalSolver::new(&s)?;
    let n = s.n;
    let outputs = s.output_rows.len();
    let mut split = ModalSplit {
        lambda: modal.lambda.clone(),
        residues: Vec::with_capacity(n),
        freq_hz: Vec::with_capacity(n),
        loss_factor: Vec::with_capacity(n),
        body_energy: Vec::with_capacity(n),
        sde_energy: Vec::with_capacity(n),
    };
    for m in 0..n {
        let lam = modal.lambda[m];
        let mut c = [[C64::new(0.0, 0.0); 2]; 2];
        for &(o, i, j, sign) in &placement.taps {
            let row = s.output_rows[o].apply(|d| modal.x[(d, m)]);
            let col = 1 + outputs + j;
            let load: C64 = (0..n).map(|d| modal.y[(m, d)] * s.load_entry(col, d)).sum();
            c[i][j] += row * load * sign;
        }
        split.residues.push(c);
        split
            .freq_hz
            .push(lam.re.max(0.0).sqrt() / (2.0 * std::f64::consts::PI));
        split
            .loss_factor
            .push(if lam.re > 0.0 { lam.im / lam.re } else { 0.0 });
        let mut e: Vec<f64> = (0..n / 6)
            .map(|b| {
                (0..6)
                    .map(|i| s.mass[6 * b + i] * modal.x[(6 * b + i, m)].norm_sqr())
                    .sum()
            })
            .collect();
        let total: f64 = e.iter().sum();
        if total > 0.0 {
            e.iter_mut().for_each(|v| *v /= total);
        }
        split.body_energy.push(e);
        let mut se: Vec<(usize, f64)> = s
            .sdes
            .iter()
            .map(|b| {
                let d = b.deformation(|i| modal.x[(i, m)]);
                (b.sde, (0..6).map(|i| b.k[i] * d[i].norm_sqr()).sum::<f64>())
            })
            .collect();
        let total: f64 = se.iter().map(|x| x.1).sum();
        if total > 0.0 {
            se.iter_mut().for_each(|x| x.1 /= total);
        }
        split.sde_energy.push(se);
    }
    Ok(split)
}
