//! Shared helpers of the acquire integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::time::Duration;

use acquire::session::{self, Record};
use acquire::stand::Stand;

/// The repository's simulated stand, made faster than real time.
pub fn sim_stand(speed: f64) -> Stand {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/stands/fwd32j-sim.toml");
    let mut s = Stand::load(&p).unwrap_or_else(|e| panic!("{e}"));
    if let Some(t) = s.truth.as_mut() {
        t.speed = speed;
    }
    s
}

/// Runs a future with a hard time limit so no test can hang.
pub async fn bounded<F: std::future::Future>(secs: u64, f: F) -> F::Output {
    match tokio::time::timeout(Duration::from_secs(secs), f).await {
        Ok(v) => v,
        Err(_) => panic!("test exceeded its {secs} s limit"),
    }
}

/// All records of a session file, which must be complete.
pub fn records(path: &Path) -> Vec<Record> {
    let r = session::read(path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        r.truncated,
        None,
        "session file {} is not complete",
        path.display()
    );
    r.records
}

/// Records on one topic.
pub fn topic<'a>(rs: &'a [Record], name: &str) -> Vec<&'a Record> {
    rs.iter().filter(|r| r.topic == name).collect()
}

/// A fresh path in a temporary directory (kept alive by the returned guard).
pub fn temp_file(name: &str) -> (tempfile::TempDir, PathBuf) {
    let d = tempfile::tempdir().expect("temp dir");
    let p = d.path().join(name);
    (d, p)
}

/// Reads an MCAP file with the Python `mcap` reader (indexed, default options) and returns
/// (message count, topics). Fails with a setup hint if Python or `mcap` is missing.
pub fn python_read(path: &Path) -> (u64, Vec<String>) {
    let script = r#"
import json, sys
try:
    from mcap.reader import make_reader
except ImportError:
    print("MISSING-MCAP"); sys.exit(3)
with open(sys.argv[1], "rb") as f:
    r = make_reader(f)
    summ = r.get_summary()
    assert summ is not None, "no summary"
    n = 0
    topics = set()
    for schema, channel, message in r.iter_messages():
        assert schema.encoding == "jsonschema", schema.encoding
        assert channel.message_encoding == "json"
        json.loads(message.data)
        json.loads(schema.data)
        topics.add(channel.topic)
        n += 1
    assert n == sum(summ.statistics.channel_message_counts.values()), "statistics disagree"
print(n)
print(",".join(sorted(topics)))
"#;
    let out = std::process::Command::new("python3")
        .arg("-c")
        .arg(script)
        .arg(path)
        .output();
    let out = match out {
        Ok(o) => o,
        Err(e) => panic!(
            "python3 is not available ({e}); run .ci/setup to install the test prerequisites"
        ),
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    if stdout.contains("MISSING-MCAP") {
        panic!("the Python `mcap` package is missing; run .ci/setup (it installs .ci/requirements.txt)");
    }
    assert!(
        out.status.success(),
        "python mcap reader failed on {}:\n{}\n{}",
        path.display(),
        stdout,
        String::from_utf8_lossy(&out.stderr)
    );
    let mut lines = stdout.lines();
    let n = lines
        .next()
        .and_then(|l| l.trim().parse().ok())
        .expect("count");
    let topics = lines
        .next()
        .unwrap_or("")
        .split(',')
        .map(str::to_string)
        .collect();
    (n, topics)
}

/// The FWD-32J stand with the RFE model as truth, written with its two model files into `dir`
/// (from texts compiled into the test binary, so it also works inside the vcan VM) and loaded.
pub fn model_sim_stand_in(dir: &Path, speed: Option<f64>) -> Stand {
    let stands = dir.join("stands");
    let models = dir.join("models");
    std::fs::create_dir_all(&stands).expect("stands dir");
    std::fs::create_dir_all(&models).expect("models dir");
    std::fs::write(
        stands.join("fwd32j-model-sim.toml"),
        include_str!("../../../configs/stands/fwd32j-model-sim.toml"),
    )
    .expect("write stand");
    std::fs::write(
        models.join("fwd32j.toml"),
        include_str!("../../../configs/models/fwd32j.toml"),
    )
    .expect("write truth");
    std::fs::write(
        models.join("fwd32j-no-actuator.toml"),
        include_str!("../../../configs/models/fwd32j-no-actuator.toml"),
    )
    .expect("write geometry");
    let mut s =
        Stand::load(&stands.join("fwd32j-model-sim.toml")).unwrap_or_else(|e| panic!("{e}"));
    if let (Some(t), Some(x)) = (s.truth.as_mut(), speed) {
        t.speed = x;
    }
    s
}

/// Checks the measured characteristics of a session against the truth model's FRF at the swept
/// lines: every point within 4.5 standard deviations of its own stated variance (a complex
/// Gaussian error exceeds that with probability e^-20) plus 0.1 % for ADC quantisation, and the
/// stated noise is not absurdly pessimistic (the median error is at least 1/20 σ).
/// Returns the number of points checked.
pub fn assert_matches_truth(a: &acquire::analysis::SessionAnalysis, truth_model: &Path) {
    let truth = rfe::modelfile::load(truth_model)
        .unwrap_or_else(|e| panic!("{e}"))
        .model;
    let mut ratios = Vec::new();
    for m in &a.measured.characteristics {
        let c = m.resolve(&truth).expect("characteristic of a truth body");
        let o = truth
            .outputs
            .iter()
            .position(|x| *x == c)
            .expect("a declared output of the truth model");
        let r = rfe::frf::response(&truth, &m.freqs_hz, &[], rfe::frf::Method::Auto)
            .expect("truth FRF");
        let phase = m.phase_rad.as_ref().expect("phases measured");
        let var = m.variance.as_ref().expect("variances stated");
        for (k, f) in m.freqs_hz.iter().enumerate() {
            let want = r.output(o)[k];
            let got = num_complex::Complex::from_polar(m.amplitude[k], phase[k]);
            let sigma = var[k].sqrt();
            let err = (got - want).norm();
            assert!(
                err <= 4.5 * sigma + 1e-3 * want.norm(),
                "{} dof {} at {f:.2} Hz: measured {got:.4e}, truth {want:.4e}, error {err:.3e} > 4.5 σ = {:.3e}",
                m.body,
                m.dof,
                4.5 * sigma
            );
            ratios.push(err / sigma);
        }
    }
    ratios.sort_by(f64::total_cmp);
    let median = ratios[ratios.len() / 2];
    assert!(
        median > 0.05 && median < 3.0,
        "median error / σ = {median}: the stated variances do not describe the errors"
    );
    eprintln!(
        "truth check: {} points, median |error|/σ = {median:.2}, max {:.2}",
        ratios.len(),
        ratios[ratios.len() - 1]
    );
}

/// Runs `measure` (of `plan`, recorded in the session start) on the rig of `bound` (the stand
/// bound to its simulated devices) into a new session file at `path`, finished whatever
/// happens; a failure to connect or measure comes back as text.
pub async fn recorded<T>(
    stand: &Stand,
    bound: &Stand,
    plan: &impl serde::Serialize,
    path: &Path,
    measure: impl AsyncFnOnce(
        &mut acquire::rig::Rig,
        &acquire::session::SessionHandle,
    ) -> Result<T, acquire::sweep::SweepError>,
) -> Result<T, String> {
    let session = session::Session::create(path, session::SessionOptions::default())
        .unwrap_or_else(|e| panic!("{e}"));
    let h = session.handle();
    acquire::sweep::log_session_start(&h, &stand.file, plan, None, &Default::default())
        .unwrap_or_else(|e| panic!("{e}"));
    let r = async {
        let mut rig = acquire::rig::Rig::connect(bound, Some(&h))
            .await
            .map_err(|e| e.to_string())?;
        measure(&mut rig, &h).await.map_err(|e| e.to_string())
    }
    .await;
    session.finish().unwrap_or_else(|e| panic!("{e}"));
    r
}
