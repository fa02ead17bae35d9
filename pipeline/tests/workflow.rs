//! The workflow calls' contracts that need no simulated sweep (the whole chain, live and replayed,
//! is `tests/cli_pipeline.rs`): a set-up reads the model and variables and names a bad file; a
//! measurement whose devices cannot be reached still leaves a completed session file, the failure
//! in its result; one that cannot start (a CAN interface for a stand without simulated ports)
//! creates no file; run folders are made unique; the newest-session search skips a newer
//! unfinished session with a note.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use acquire::stand::{PortSpec, Stand};
use acquire::sweep::{NoProgress, SteppedSine};
use pipeline::{MeasureError, Note, PipelineError, Setup, SweepOptions};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The simulated FWD-32J stand with both devices on paths that do not exist.
fn unreachable_stand(dir: &Path) -> Stand {
    let mut stand = Stand::load(&root().join("configs/stands/fwd32j-model-sim.toml")).unwrap();
    let missing = |name: &str| PortSpec::Path(dir.join(name).display().to_string());
    stand.shaker.port = missing("no-shaker");
    stand.daq.port = missing("no-daq");
    stand
}

#[test]
fn a_setup_reads_model_and_variables_and_names_a_bad_variables_file() {
    let model = root().join("configs/models/textbook-two-mass.toml");
    let vars = root().join("configs/identification/textbook-two-mass.toml");
    let mut notes = Vec::new();
    let s = Setup::load(&model, &vars, &mut |n| notes.push(n)).unwrap();
    assert_eq!(s.model_name(), "textbook-two-mass");
    assert!(s.model_text.is_some(), "a TOML model keeps its text");
    assert!(!s.vars.is_empty());
    assert!(notes.iter().all(|n| matches!(n, Note::Model(_))));

    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("vars.toml");
    std::fs::write(
        &bad,
        "[[variable]]\nsdes = \"no-such-sde\"\nparameter = \"k\"\n",
    )
    .unwrap();
    let e = Setup::load(&model, &bad, &mut |_| {}).unwrap_err();
    assert!(matches!(e, PipelineError::Variables(_)), "{e:?}");
    assert!(e.to_string().contains("vars.toml"), "{e}");
}

#[test]
fn a_sweep_whose_devices_cannot_be_reached_completes_its_session_file() {
    let dir = tempfile::tempdir().unwrap();
    let stand = unreachable_stand(dir.path());
    let session = dir.path().join("session.mcap");
    let plan = SteppedSine::log(20.0, 400.0, 5, 4000.0);
    let mut notes = Vec::new();
    let swept = pipeline::sweep(
        &stand,
        &plan,
        &session,
        &SweepOptions::default(),
        &NoProgress,
        &mut |n| notes.push(n),
    )
    .unwrap();
    assert_eq!(swept.planned, 5);
    assert!(
        matches!(swept.outcome, Err(MeasureError::Rig(_))),
        "{:?}",
        swept.outcome
    );
    assert!(swept.finish_error.is_none(), "{:?}", swept.finish_error);
    assert!(swept.messages >= 1, "the session start is recorded");
    assert_eq!(notes, vec![Note::Recording(session.clone())]);
    // Completed: the file ends with the MCAP magic.
    let bytes = std::fs::read(&session).unwrap();
    assert!(bytes.ends_with(b"\x89MCAP0\r\n"));
}

#[test]
fn a_can_interface_for_a_stand_without_simulated_ports_creates_no_session() {
    let dir = tempfile::tempdir().unwrap();
    let stand = unreachable_stand(dir.path());
    let session = dir.path().join("session.mcap");
    let opts = SweepOptions {
        can: Some("vcan0"),
        ..SweepOptions::default()
    };
    let plan = SteppedSine::log(20.0, 400.0, 5, 4000.0);
    let e = pipeline::sweep(&stand, &plan, &session, &opts, &NoProgress, &mut |_| {}).unwrap_err();
    assert!(matches!(e, PipelineError::CanWithoutSim { .. }), "{e:?}");
    assert!(e.to_string().contains("fwd32j-model-sim.toml"), "{e}");
    assert!(!session.exists());
}

#[test]
fn run_folders_are_made_unique() {
    let dir = tempfile::tempdir().unwrap();
    let parent = dir.path().join("reports");
    let a = pipeline::dated_folder(&parent, "demo").unwrap();
    let b = pipeline::dated_folder(&parent, "demo").unwrap();
    assert_ne!(a, b);
    assert!(a.is_dir() && b.is_dir());
    let name = a.file_name().unwrap().to_string_lossy().into_owned();
    assert!(name.starts_with("demo-") && name.ends_with('Z'), "{name}");
}

#[test]
fn the_newest_finished_session_is_taken_and_a_newer_unfinished_one_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let e = pipeline::sessions::newest_finished(dir.path(), &mut |_| {}).unwrap_err();
    assert!(
        matches!(
            e,
            PipelineError::NoSession {
                unfinished: false,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(e.to_string().starts_with("no *.mcap session in "), "{e}");

    let done = dir.path().join("a.mcap");
    let file = acquire::session::Session::create(&done, Default::default()).unwrap();
    file.finish().unwrap();
    assert!(pipeline::sessions::finished(&done).unwrap());
    // A killed writer's file: the start of a finished one, without its end.
    let bytes = std::fs::read(&done).unwrap();
    let cut = dir.path().join("b.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() - 4]).unwrap();
    let later =
        std::fs::metadata(&done).unwrap().modified().unwrap() + std::time::Duration::from_secs(60);
    std::fs::File::options()
        .write(true)
        .open(&cut)
        .unwrap()
        .set_modified(later)
        .unwrap();
    assert!(!pipeline::sessions::finished(&cut).unwrap());

    let mut notes = Vec::new();
    let found = pipeline::sessions::newest_finished(dir.path(), &mut |n| notes.push(n)).unwrap();
    assert_eq!(found, done);
    assert_eq!(
        notes,
        vec![Note::SkippedSession {
            path: cut.clone(),
            unreadable: None
        }]
    );
    assert!(notes[0].to_string().contains("ident mcap recover"));

    std::fs::remove_file(&done).unwrap();
    let e = pipeline::sessions::newest_finished(dir.path(), &mut |_| {}).unwrap_err();
    assert!(
        e.to_string().starts_with("no finished *.mcap session in "),
        "{e}"
    );
}
