//! The base fit the diagnosis starts from: the identification's estimate continued until it
//! converges, and a multi-start fit when it does not or explains nothing, so that every candidate
//! is judged against a converged fit refitted with the same effort.

use super::tuning::{BASE_CONTINUATIONS, BASE_STARTS};
use super::*;

/// How the base fit the diagnosis starts from was reached: the identification's estimate
/// continued until converged and, when it did not converge or does not explain the data, the
/// best of a multi-start fit. Every candidate is then judged against this fit, refitted with
/// the same optimizer and settings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BaseFit {
    /// Unit of the criteria: `"-"` (J = ½ Σe², dimensionless residuals).
    pub unit: &'static str,
    /// Criterion J of the identification's estimate.
    pub criterion_identification: f64,
    /// Criterion J of the base fit.
    pub criterion: f64,
    /// Whether the base fit converged.
    pub converged: bool,
    /// Why it stopped.
    pub stop: String,
    /// Continuations run from the identification's estimate.
    pub continuations: usize,
    /// Starts of the multi-start fit (0: not needed).
    pub starts: usize,
    /// Optimizer iterations spent on the base fit in all.
    pub iterations: usize,
}

/// The converged base fit as the starting state: no effect, its residuals and Jacobian. From the
/// identification's estimate, continued up to [`BASE_CONTINUATIONS`] times until the optimizer
/// converges; when it does not, or the fit does not explain the data (a local minimum explains
/// nothing either), the best of a [`BASE_STARTS`]-start fit is taken too.
pub(super) fn base_fit(
    model: &Model,
    vars: &Variables,
    obs: &Observations,
    p0: &mut Problem,
    id: &Identification,
    opts: &Options,
    progress: &mut dyn FnMut(&str),
) -> Result<(Current, BaseFit), DiagnoseError> {
    let iopts = &opts.identification;
    let scaled = |x: &[f64], scale: &[f64]| {
        DVector::from_iterator(x.len(), x.iter().zip(scale).map(|(x, s)| x / s))
    };
    let (lo, hi) = p0.bounds();
    let u_id = scaled(&id.estimate, &p0.scale);
    let (e_id, _) = p0.eval(&u_id, false)?;
    let j_id = 0.5 * e_id.norm_squared();
    let mut info = BaseFit {
        unit: "-",
        criterion_identification: j_id,
        criterion: j_id,
        converged: false,
        stop: id.stop.describe(),
        continuations: 0,
        starts: 0,
        iterations: 0,
    };
    let mut u = u_id;
    let continued = |p0: &mut Problem, u: &mut DVector<f64>, info: &mut BaseFit| {
        for _ in 0..BASE_CONTINUATIONS {
            let Ok(out) = optimize::minimize(
                iopts.optimizer,
                p0,
                u,
                &lo,
                &hi,
                &iopts.settings,
                &mut |_| {},
            ) else {
                break;
            };
            info.continuations += 1;
            info.iterations += out.iterations;
            if out.criterion <= info.criterion {
                info.criterion = out.criterion;
                *u = out.u;
            }
            info.stop = out.stop.describe();
            info.converged = out.stop.converged();
            if info.converged {
                break;
            }
        }
    };
    continued(p0, &mut u, &mut info);
    // A converged fit that does not explain the data may be a local minimum when the start was
    // far off (its misfit would then be "explained" by effects that do nothing): the extra
    // starts are tried then too.
    let explained = {
        let (e, _) = p0.eval(&u, false)?;
        let cur = Current {
            effects: Vec::new(),
            u: u.clone(),
            e,
            jac: DMatrix::zeros(0, 0),
        };
        analysis(p0, &cur, opts).is_ok_and(|a| a.explained)
    };
    if !info.converged || !explained {
        let mopts = identify::Options {
            starts: iopts.starts.max(BASE_STARTS),
            ..*iopts
        };
        if let Ok(ms) = identify::identify(model, obs, vars, &mopts, &mut |_, _| {}) {
            info.starts = mopts.starts;
            info.iterations += ms.starts.iter().map(|s| s.iterations).sum::<usize>();
            let um = scaled(&ms.estimate, &p0.scale);
            let (em, _) = p0.eval(&um, false)?;
            let jm = 0.5 * em.norm_squared();
            if jm < info.criterion * (1.0 - 1e-9) {
                info.criterion = jm;
                info.converged = ms.stop.converged();
                info.stop = ms.stop.describe();
                u = um;
                if !info.converged {
                    continued(p0, &mut u, &mut info);
                }
            }
        }
    }
    progress(&format!(
        "base fit: J {:.1} → {:.1} ({}; {} continuation(s), {} start(s))",
        info.criterion_identification, info.criterion, info.stop, info.continuations, info.starts
    ));
    let (e, jac) = p0.eval(&u, true)?;
    let jac = jac.unwrap_or_else(|| DMatrix::zeros(e.len(), 0));
    Ok((
        Current {
            effects: Vec::new(),
            u,
            e,
            jac,
        },
        info,
    ))
}
