//! One diagnosis as a library call: a [`Request`] — the prepared identification problem
//! (`identify::request::Problem`: the model with its measured outputs, the validated
//! observations, the variables at their start, the fit options), its identification and the
//! diagnosis's own options — becomes a [`Diagnosis`]. The command line (`ident diagnose`) and the
//! workflows (`pipeline::analyse`: demo, replay, nightly) call this, so both diagnose the same
//! problem the same way:
//!
//! ```text
//! identify::request::prepare ─► Problem ─► Problem::identify ─► Identification ─┐
//!                                  └──────────────────────────────────────────────┴─► Request::diagnose ─► Diagnosis
//! ```
//!
//! The refits run with the problem's own fit options (fit kind, noise model, optimizer,
//! iterations), so that a likelihood ratio measures the effect added and not a change of settings.
//!
//! ```no_run
//! # fn run(problem: &identify::request::Problem) -> Result<(), Box<dyn std::error::Error>> {
//! let id = problem.identify(&mut |_, _| {})?;
//! let mut req = diagnose::request::Request::new(problem, &id);
//! req.alpha = 0.01;
//! let d = req.diagnose(&mut |line| eprintln!("{line}"))?;
//! println!("{}", diagnose::text(&d));
//! # Ok(())
//! # }
//! ```

use identify::request::Problem;
use identify::Identification;

use crate::{DiagnoseError, Diagnosis, Options};

/// A diagnosis to run: the problem, its identification and how to diagnose it.
#[derive(Debug, Clone, Copy)]
pub struct Request<'a> {
    /// The identification problem, as prepared (`identify::request::prepare`, or built by a
    /// workflow from a session).
    pub problem: &'a Problem,
    /// The problem's identification: the diagnosis starts from its estimate.
    pub identification: &'a Identification,
    /// Family-wise significance level: the accepted false-alarm rate of one diagnosis.
    pub alpha: f64,
    /// At most this many effects are added.
    pub max_effects: usize,
    /// Candidate families refitted per round ([`Options::refit`]).
    pub refit: usize,
}

impl<'a> Request<'a> {
    /// The diagnosis of `identification` of `problem` with the default options ([`Options`]).
    pub fn new(problem: &'a Problem, identification: &'a Identification) -> Request<'a> {
        let defaults = Options::default();
        Request {
            problem,
            identification,
            alpha: defaults.alpha,
            max_effects: defaults.max_effects,
            refit: defaults.refit,
        }
    }

    /// The options the diagnosis runs with: this request's, and the problem's fit options for
    /// the refits.
    pub fn options(&self) -> Options {
        Options {
            alpha: self.alpha,
            max_effects: self.max_effects,
            refit: self.refit,
            identification: self.problem.options,
        }
    }

    /// Runs the diagnosis ([`crate::diagnose()`]); `progress` gets one line per step (ranking,
    /// each refit, each decision).
    pub fn diagnose(&self, progress: &mut dyn FnMut(&str)) -> Result<Diagnosis, DiagnoseError> {
        let p = self.problem;
        crate::diagnose(
            &p.model,
            &p.observations,
            &p.variables,
            self.identification,
            &self.options(),
            progress,
        )
    }
}
