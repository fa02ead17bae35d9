//! The fit problem as JSON, for external tools (`ident identify --export-problem FILE`): the
//! resolved model at the initial values, the observations with their σ, and the decision
//! variables as linear maps onto the SDEs' six stiffnesses and dissipations. With it another
//! implementation (the Python baseline `bench/python/ident_baseline.py`, a notebook) fits exactly
//! the problem `ident identify` fits. Format: docs/identification.md, "Problem export".

use serde_json::{json, Value};

use super::criterion::{Criterion, FitKind};
use super::data::Observations;
use super::variables::Variables;
use super::{IdentifyError, Options};
use rfe::contract;
use rfe::model::{Model, Param, DOF_NAMES};

/// Format tag of [`to_json`]'s output.
pub const FORMAT: &str = "ident identification problem 1";

/// The problem of identifying `vars` from `data` on `model` with `opts` (fit kind, noise model),
/// as JSON:
///
/// - `model`: the resolved model (docs/model-json.md) at the initial values, its `outputs` the
///   measured characteristics in data order;
/// - `lines_hz`: the frequency grid (the union of the measured frequencies);
/// - `observations[i]`: `characteristic` (index into `model.outputs`), `line` (index into
///   `lines_hz`), measured `amplitude` (SI), `phase_rad` (or null), `sigma` (σ of the amplitude,
///   or of each of the real and imaginary parts for a complex fit; SI) and `model_amplitude`
///   (|q| of the model at the initial values, for checking another implementation's FRF);
/// - `variables[v]`: `name`, `initial`, `lower`, `upper` (null when none), `scale` (SI), and
///   `terms`: per SDE it moves, `sde` (index into `model.sdes`) and `dk`, `dpsi`, the change of
///   the SDE's six stiffnesses (N/m, N·m/rad) and six ψ per unit of the variable. Every law is
///   linear in its parameters, so `k(x) = k(x0) + Σ_v (x_v − x0_v) dk_v`, likewise ψ. A body's
///   mass or inertia is a term `body` (index into `model.bodies`), `dm` (change of its
///   `[m, m, m, J1, J2, J3]` per unit of the variable); a point mass a term `point_mass` (index
///   into `model.point_masses`), `dmass` (change of its mass per unit of the variable); a sensor
///   gain a term `gain` (`body`, `dof`) with its `ratio` (the model output of that
///   characteristic is multiplied by it).
pub fn to_json(
    model: &Model,
    data: &Observations,
    vars: &Variables,
    opts: &Options,
) -> Result<Value, IdentifyError> {
    let mut crit = Criterion::new(model, data, vars, opts.fit, opts.noise, opts.frf_method)?;
    let x0 = vars.initial();
    let at_initial = crit.model_at(&x0);
    let q0 = crit
        .predicted(&x0)
        .map_err(|e| IdentifyError::Initial(e.into()))?;
    let enabled: Vec<usize> = (0..at_initial.sdes.len())
        .filter(|&i| at_initial.sdes[i].enabled)
        .collect();
    let mut variables = Vec::with_capacity(vars.len());
    for v in &vars.vars {
        let mut terms = Vec::with_capacity(v.targets.len());
        for t in &v.targets {
            let p = match t.param {
                Param::Sde(p) => p,
                Param::Gain { body, dof } => {
                    terms.push(json!({
                        "gain": {"body": at_initial.bodies[body].name, "dof": DOF_NAMES[dof as usize % 6]},
                        "ratio": t.ratio,
                    }));
                    continue;
                }
                Param::PointMass { index } => {
                    terms.push(json!({ "point_mass": index, "dmass": t.ratio }));
                    continue;
                }
                other => {
                    let (body, dm) = other.inertia_derivative().unwrap_or((0, [0.0; 6]));
                    terms.push(json!({ "body": body, "dm": dm.map(|d| d * t.ratio) }));
                    continue;
                }
            };
            let sde = &at_initial.sdes[p.sde];
            let (Some((dk, dpsi)), Some(index)) = (
                sde.law.derivative(p.name),
                enabled.iter().position(|&i| i == p.sde),
            ) else {
                return Err(IdentifyError::Noise {
                    item: format!("{}: variable {}", vars.origin, v.name),
                    message: format!(
                        "SDE {} has no parameter {} that can be exported",
                        sde.name, v.parameter
                    ),
                });
            };
            terms.push(json!({
                "sde": index,
                "dk": dk.map(|d| d * t.ratio),
                "dpsi": dpsi.map(|d| d * t.ratio),
            }));
        }
        variables.push(json!({
            "name": v.name,
            "initial": v.initial,
            "lower": v.lower,
            "upper": if v.upper.is_finite() { json!(v.upper) } else { Value::Null },
            "scale": v.scale,
            "terms": terms,
        }));
    }
    let measured = crit.measured();
    let observations: Vec<Value> = crit
        .points()
        .into_iter()
        .zip(&measured)
        .zip(&q0)
        .map(|(((characteristic, line, sigma), z), q)| {
            json!({
                "characteristic": characteristic,
                "line": line,
                "amplitude": z.norm(),
                "phase_rad": if crit.fit() == FitKind::Complex { json!(z.arg()) } else { Value::Null },
                "sigma": sigma,
                "model_amplitude": q.norm(),
            })
        })
        .collect();
    Ok(json!({
        "format": FORMAT,
        "fit": crit.fit().as_str(),
        "noise": crit.noise.describe(),
        "model": contract::to_json(&at_initial),
        "lines_hz": crit.lines(),
        "observations": observations,
        "variables": variables,
    }))
}
