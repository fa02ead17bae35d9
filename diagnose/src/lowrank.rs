//! A candidate's model evaluations as low-rank updates of a fit's solves (`rfe::lowrank`).
//!
//! A screen fits one candidate's own parameters with the variables and earlier effects held at
//! the current fit, and a refit's starts (the sizes explored around its screen, the fresh start's
//! size grid with the variables at their initial values) change only the candidate's parameters
//! too: every such evaluation is one held model changed by that one candidate. The held fit's
//! solves are made once per round ([`Solves::hold`]); each evaluation then costs the candidate's
//! update on its support per line — independent of the model's size — and gives the same
//! residuals as a full solve to rounding (`diagnose/tests/lowrank.rs`: 1e-9 relative on every
//! kind). A candidate that is no update of the held system (none today; a change of the
//! excitation under base motion would be one), or a point that is not a held one, is solved in
//! full.

use std::sync::{Arc, Mutex};

use nalgebra::DVector;

use super::problem::Problem;
use super::tuning::LOW_RANK_MIN_DOFS;
use super::Effect;
use identify::optimize::Residuals as _;
use identify::EvalError;
use rfe::lowrank::Base;

/// One fit's solves: the problem's effects and its scaled values where they were made.
pub struct Shared {
    base: Base,
    effects: Vec<Effect>,
    at: DVector<f64>,
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
        Some(Shared {
            base,
            effects: pc.effects.clone(),
            at: u.clone(),
        })
    }

    /// Whether `u` of the extended problem `p` is this fit with one more effect: the same
    /// earlier effects at the same values, and the same variables; only the new effect's
    /// parameters (the last of `u`) free.
    pub fn holds(&self, p: &Problem, u: &DVector<f64>) -> bool {
        let n = self.at.len();
        p.effects.len() == self.effects.len() + 1
            && p.effects[..self.effects.len()] == self.effects[..]
            && u.len() > n
            && u.rows(0, n) == self.at
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

/// The solves a round holds for the evaluations that change one candidate only: the current
/// fit's and the same with the variables at their initial values (a refit's fresh start), made
/// once per round where the model is large enough for the update to pay (at or below
/// `LOW_RANK_MIN_DOFS`, 100 DOFs, a full solve costs no more than the update's Schur
/// complement).
#[derive(Default)]
pub struct Solves {
    held: Mutex<Vec<Arc<Shared>>>,
}

impl Solves {
    /// Holds the solves of the problem `pc` at each of `points` (scaled) in place of those held
    /// before; holds none on a model too small for them to pay.
    pub fn hold(&self, pc: &Problem, points: &[DVector<f64>]) {
        let large = 6 * pc.base().bodies.len() > LOW_RANK_MIN_DOFS;
        let held: Vec<Arc<Shared>> = points
            .iter()
            .filter(|_| large)
            .filter_map(|u| Shared::new(pc, u).map(Arc::new))
            .collect();
        if let Ok(mut h) = self.held.lock() {
            *h = held;
        }
    }

    /// The held solves made at `u` for the effects of `pc`, if any.
    pub fn at(&self, pc: &Problem, u: &DVector<f64>) -> Option<Arc<Shared>> {
        let held = self.held.lock().ok()?;
        held.iter()
            .find(|s| s.effects == pc.effects && s.at == *u)
            .cloned()
    }

    /// Σe² of the extended problem `p` at `u`: by the update of held solves that `u` changes in
    /// the new effect's parameters only, else by a full evaluation; infinite where the model
    /// cannot be evaluated.
    pub fn sum_of_squares(&self, p: &mut Problem, u: &DVector<f64>) -> f64 {
        let shared = self
            .held
            .lock()
            .ok()
            .and_then(|held| held.iter().find(|s| s.holds(p, u)).cloned());
        let low_rank = shared.and_then(|s| s.residuals(p, u));
        let e = match low_rank {
            Some(e) => e,
            None => p.eval(u, false).map(|(e, _)| e),
        };
        e.map_or(f64::INFINITY, |e| e.norm_squared())
    }
}
