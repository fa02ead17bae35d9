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

#[cfg(test)]
mod tests {
    //! The request against the direct call on the two-mass chain whose truth has a spring to
    //! ground the model lacks (1 % noise, seeded): same diagnosis, the problem's fit options used
    //! by the refits, a bad level refused.

    // Test helpers unwrap: a panic with its message is the failure report.
    #![allow(clippy::unwrap_used)]

    use identify::{data, synthetic, variables, FitKind};
    use nalgebra::{Matrix3, Vector3};
    use rand::rngs::StdRng;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    use rfe::model::{Sde, SdeKind, SdeLaw};

    use super::*;

    const VARS: &str = r#"
[[variable]]
sdes = "k1"
parameter = "k"
initial = "14 N/um"

[[variable]]
sdes = "k2"
parameter = "k"
initial = "7 N/um"

[[variable]]
name = "psi springs"
sdes = ["k1", "k2"]
parameter = "psi"
initial = 0.4
"#;

    /// The chain without the spring, and data of the chain with a 3 N/µm spring from the
    /// ground to its second body.
    fn problem(options: identify::Options) -> Problem {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../configs/models/textbook-two-mass.toml"
        );
        let model = rfe::modelfile::load(std::path::Path::new(path))
            .unwrap()
            .model;
        let mut truth = model.clone();
        truth.sdes.push(Sde {
            name: "support".into(),
            kind: SdeKind::Spring,
            bodies: [None, Some(1)],
            point: Vector3::new(0.0, 0.0, 1.0),
            rotation: Matrix3::from_columns(&[Vector3::z(), Vector3::x(), Vector3::y()]),
            law: SdeLaw::Axial { k: 3.0e6, psi: 0.3 },
            enabled: true,
        });
        let mut rng = StdRng::seed_from_u64(7);
        let lines = synthetic::log_lines(10.0, 60.0, 40);
        let measured =
            synthetic::amplitude_data(&truth, &lines, 0.01, || StandardNormal.sample(&mut rng))
                .unwrap();
        Problem {
            variables: variables::parse(VARS, "vars.toml", &model).unwrap(),
            observations: data::validate(&measured, &model, "synthetic").unwrap(),
            model,
            options,
        }
    }

    #[test]
    fn the_request_diagnoses_as_the_direct_call_with_the_problems_fit_options() {
        let p = problem(identify::Options {
            fit: FitKind::LogAmplitude,
            ..identify::Options::default()
        });
        let id = p.identify(&mut |_, _| {}).unwrap();
        let req = Request {
            max_effects: 2,
            ..Request::new(&p, &id)
        };
        let opts = req.options();
        assert_eq!(opts.identification, p.options);
        assert_eq!(opts.max_effects, 2);
        assert_eq!(opts.alpha, Options::default().alpha);
        let by_request = req.diagnose(&mut |_| {}).unwrap();
        let direct = crate::diagnose(
            &p.model,
            &p.observations,
            &p.variables,
            &id,
            &opts,
            &mut |_| {},
        )
        .unwrap();
        let effects = |d: &Diagnosis| -> Vec<(String, f64)> {
            d.accepted
                .iter()
                .map(|r| (r.effect.clone(), r.criterion_after))
                .collect()
        };
        assert!(
            !by_request.accepted.is_empty(),
            "the missing spring is found"
        );
        assert_eq!(effects(&by_request), effects(&direct));
        assert_eq!(by_request.estimate, direct.estimate);
        assert_eq!(by_request.after.explained, direct.after.explained);
    }

    #[test]
    fn a_level_outside_zero_one_is_refused() {
        let p = problem(identify::Options::default());
        let id = p.identify(&mut |_, _| {}).unwrap();
        let req = Request {
            alpha: 1.5,
            ..Request::new(&p, &id)
        };
        assert!(matches!(
            req.diagnose(&mut |_| {}),
            Err(DiagnoseError::Alpha(a)) if a == 1.5
        ));
    }
}
