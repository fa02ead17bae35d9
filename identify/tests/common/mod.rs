//! Helpers shared by the identify crate's integration tests: the repository's model files and the
//! synthetic FWD-32J measurement.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used, dead_code)]

use std::path::PathBuf;

use identify::identification::synthetic;
use identify::measured::MeasuredData;
use identify::model::Model;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

/// The repository's root folder.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A model of `configs/models/`, e.g. `fwd32j.toml`; panics naming the file when it cannot load.
pub fn load_model(name: &str) -> Model {
    let p = repo().join("configs/models").join(name);
    identify::modelfile::load(&p)
        .unwrap_or_else(|e| panic!("the model {} is needed by this test: {e}", p.display()))
        .model
}

/// The synthetic FWD-32J measurement (`identification::synthetic`): 38 log-spaced lines over
/// 20-400 Hz per characteristic, multiplicative Gaussian noise of relative σ `rel`, variances
/// stated.
pub fn fwd32j_data(truth: &Model, rel: f64, rng: &mut StdRng) -> MeasuredData {
    synthetic::amplitude_data(truth, &synthetic::fwd32j_lines(), rel, || {
        StandardNormal.sample(&mut *rng)
    })
    .expect("truth FRF")
}
