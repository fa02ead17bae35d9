//! Everything after a measurement, from the session file alone: process → identify → diagnose
//! ([`analyse`]). The session's characteristics become an `identify::request::Problem` — the
//! same prepared problem `ident identify` and `ident diagnose` fit — which is identified
//! (`Problem::identify`) and diagnosed (`diagnose::request`). Deterministic: a replay of the same
//! file gives bit-identical results.

use std::path::Path;

use acquire::analysis::{characteristics, AnalysisOptions, SessionAnalysis};
use identify::request::Problem;
use identify::{data, report as table, Identification};

use crate::error::PipelineError;
use crate::setup::Setup;

/// How the workflows identify: the library's defaults with four starts. From Table 1's initial
/// values alone, the 19-variable fit of the demo's model (which lacks the actuator) lands in a poor
/// local minimum for about one sweep in five — data that differ by under 1 % send it there (a
/// criterion 38× the good minimum's); three more starts spread over the bounds find the good
/// minimum (0.24 s instead of 0.1 s in release).
pub fn identification_options() -> identify::Options {
    identify::Options {
        starts: 4,
        ..identify::Options::default()
    }
}

/// Results of processing, identification and diagnosis of one session.
#[derive(Debug)]
pub struct Analysis {
    /// The session's characteristics, steps, dropped steps and faults.
    pub session: SessionAnalysis,
    /// The identification problem: the set-up's model and variables, the characteristics
    /// validated against the model, the fit options.
    pub problem: Problem,
    /// The identification.
    pub identification: Identification,
    /// The diagnosis (its report section, and the full result with the final model), when it ran.
    pub diagnosis: Option<(report::Diagnosis, diagnose::Diagnosis)>,
    /// What the operator should know: data not used, faults, truncation, non-convergence.
    pub messages: Vec<String>,
}

/// Process → identify → diagnose, from the session file alone (deterministic: a replay of the same
/// file gives bit-identical results). A diagnosis that cannot run is a message, not a failure: the
/// identification is still reported.
pub fn analyse(
    session: &Path,
    setup: &Setup,
    opts: &identify::Options,
) -> Result<Analysis, PipelineError> {
    let a = characteristics(session, &AnalysisOptions::default())?;
    let mut messages = a.messages();
    let problem = problem(&a, setup, opts, session)?;
    let id = problem.identify(&mut |_, p| tracing::info!(?p, "iteration"))?;
    // The score test projects the fit's own directions out of the residual, so it ranks candidates
    // from the best point of an identification that hit its iteration limit too; the refits then
    // free every variable again.
    if !id.stop.converged() {
        messages.push(
            "diagnosis started from the best point of the identification, which did not converge"
                .into(),
        );
    }
    let request = diagnose::request::Request::new(&problem, &id);
    let diagnosis = match request.diagnose(&mut |line| tracing::info!("diagnose: {line}")) {
        Ok(d) => Some((report::build::diagnosis(&d, &setup.model_name(), &id), d)),
        Err(e) => {
            messages.push(format!("diagnosis not run: {e}"));
            None
        }
    };
    Ok(Analysis {
        session: a,
        problem,
        identification: id,
        diagnosis,
        messages,
    })
}

/// The identification problem of a session: the set-up's model and variables (at their start),
/// the session's characteristics validated against that model (`identify::data::validate`) and
/// the fit options `opts` as given.
fn problem(
    a: &SessionAnalysis,
    setup: &Setup,
    opts: &identify::Options,
    session: &Path,
) -> Result<Problem, PipelineError> {
    let observations = data::validate(&a.measured, &setup.model, &session.display().to_string())?;
    Ok(Problem {
        model: setup.model.clone(),
        observations,
        variables: setup.vars.clone(),
        options: *opts,
    })
}

/// The Table-1-like summary printed by the workflows.
pub fn summary_text(a: &Analysis) -> String {
    let mut s = table::text(&a.identification);
    match &a.diagnosis {
        Some((_, d)) => {
            s.push('\n');
            s.push_str(&diagnose::text(d));
            s.push('\n');
            s.push_str(&diagnose::final_text(&a.identification, d));
        }
        None => s.push_str("\ndiagnosis: not run (see the notes)\n"),
    }
    s
}
