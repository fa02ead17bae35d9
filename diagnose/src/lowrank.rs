//! The screen's model evaluations as low-rank updates of the current fit (`rfe::lowrank`).
//!
//! A screen fits one candidate's own parameters with the variables and earlier effects held at
//! the current fit: every evaluation is the current fit's model changed by that one candidate.
//! The current fit's solves are made once per round ([`Shared::new`]); each evaluation then
//! costs the candidate's update on its support per line — independent of the model's size — and
//! gives the same residuals as a full solve to rounding (`identify/tests/lowrank.rs`: 1e-9
//! relative on every kind). A candidate that is no update of the current fit's system (none
//! today; a change of the excitation under base motion would be one) falls back to the full
//! solve.

use nalgebra::DVector;

use super::problem::Problem;
use identify::EvalError;
use rfe::lowrank::Base;

/// The current fit's solves, shared by every screen of a round.
pub struct Shared {
    base: Base,
}

impl Shared {
    /// The solves of the problem `pc` (the current effects) at its scaled values `u`; `None`
    /// when the low-rank path cannot take this model (then every screen solves in full).
    pub fn new(pc: &Problem, u: &DVector<f64>) -> Option<Shared> {
        let (x, gamma) = pc.split(u);
        let r = pc.realize(&gamma).ok()?;
        let crit = pc.criterion(&r).ok()?;
        let model = crit.model_at(&x);
        let base = Base::new(&model, crit.lines(), pc.frf_method()).ok()?;
        Some(Shared { base })
    }

    /// The whitened residuals (gains applied) of the extended problem `p` — the current effects
    /// and one candidate — at scaled `u`, the current effects' and variables' values those of
    /// the shared fit; `None` when the change is no update of the shared system.
    pub fn residuals(
        &self,
        p: &Problem,
        u: &DVector<f64>,
    ) -> Option<Result<DVector<f64>, EvalError>> {
        let (x, gamma) = p.split(u);
        let r = match p.realize(&gamma) {
            Ok(r) => r,
            Err(e) => return Some(Err(e)),
        };
        let crit = match p.criterion(&r) {
            Ok(c) => c,
            Err(e) => return Some(Err(e)),
        };
        let update = self.base.update(&crit.model_at(&x)).ok()?;
        let y = self.base.changed_response(&update).ok()?;
        let mut e = crit.residuals_of(&x, |o, k| y[o][k]);
        Problem::gained(&crit, &mut e, &r.gains);
        if e.iter().any(|v| !v.is_finite()) {
            return Some(Err(EvalError::NotFinite("extended model's response")));
        }
        Some(Ok(e))
    }
}
