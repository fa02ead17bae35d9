//! The session records' shapes: the schemas in docs/mcap-session.md are the ones generated from
//! the record types; a session recorded before the records were typed (version 1, the fixture
//! `fixtures/session-v1.mcap`, recorded by `ident sweep` at commit 8d87698) still reads, processes
//! to the characteristics that code computed, and validates against today's schemas by an
//! independent validator (Python `jsonschema` over the Python `mcap` reader).

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

use acquire::analysis::{characteristics, AnalysisOptions};
use acquire::record::{self as records, SessionStart, StandRecord};
use acquire::record::{Topic, ALL};
use acquire::session::{self as session_file};
use acquire::sweep::StepResult;

const BEGIN: &str = "<!-- generated schemas: begin -->\n";
const END: &str = "<!-- generated schemas: end -->";

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

#[test]
fn documented_schemas_are_the_generated_ones() {
    let doc_path = root().join("docs/mcap-session.md");
    let doc = std::fs::read_to_string(&doc_path).unwrap();
    let (Some(b), Some(e)) = (doc.find(BEGIN), doc.find(END)) else {
        panic!("docs/mcap-session.md has no `{BEGIN}` … `{END}` section");
    };
    let generated = records::schemas_markdown();
    let documented = &doc[b + BEGIN.len()..e];
    if documented != generated && std::env::var_os("IDENT_BLESS").is_some() {
        let new = format!("{}{BEGIN}{generated}{}", &doc[..b], &doc[e..]);
        std::fs::write(&doc_path, new).unwrap();
        return;
    }
    assert!(
        documented == generated,
        "docs/mcap-session.md's schemas differ from the record types' (rerun with IDENT_BLESS=1 \
         to rewrite the section, and review the diff)"
    );
    for t in ALL {
        let s = t.schema();
        assert_eq!(s["title"], t.schema_name(), "{}", t.name());
        assert_eq!(
            s["$schema"],
            "https://json-schema.org/draft/2020-12/schema",
            "{}",
            t.name()
        );
    }
}

#[test]
fn a_version_1_session_reads_and_processes_as_it_did() {
    let path = fixture("session-v1.mcap");
    let rep = session_file::read(&path).unwrap();
    assert_eq!(rep.truncated, None);
    let start: SessionStart = rep.first().unwrap().unwrap();
    assert_eq!(start.version, 1, "no version field: version 1");
    let stand: StandRecord = rep.first().unwrap().unwrap();
    assert_eq!(stand.channels.len(), 8);
    let steps: Vec<StepResult> = rep.all().unwrap();
    assert_eq!(steps.len(), 3);

    let a = characteristics(&path, &AnalysisOptions::default()).unwrap();
    assert!(a.steps.iter().all(|s| s.matches_live));
    assert!(a.dropped.is_empty(), "{:?}", a.dropped);
    let then: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(fixture("session-v1.measured.json")).unwrap(),
    )
    .unwrap();
    let now = serde_json::to_value(&a.measured).unwrap();
    assert_eq!(
        now["characteristics"], then["characteristics"],
        "the characteristics differ from what the code that recorded the session computed"
    );
}

#[test]
fn a_session_recorded_today_is_version_2_and_decodes_record_by_record() {
    // The pipeline tests record full sessions; here one record of each kind the sweep writes
    // goes through the writer and back.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    let s = session_file::Session::create(&path, Default::default()).unwrap();
    let h = s.handle();
    acquire::sweep::log_session_start(
        &h,
        "stand.toml",
        &acquire::sweep::SteppedSine::default(),
        None,
        &Default::default(),
    )
    .unwrap();
    h.record(&records::SweepEvent {
        kind: "started".into(),
        step: None,
        frequency_hz: None,
        detail: "test".into(),
    })
    .unwrap();
    s.finish().unwrap();
    let rep = session_file::read(&path).unwrap();
    let start: SessionStart = rep.first().unwrap().unwrap();
    assert_eq!(start.version, records::VERSION);
    assert_eq!(start.version, 2);
    let events: Vec<records::SweepEvent> = rep.all().unwrap();
    assert_eq!(events[0].detail, "test");
    // A record of the wrong shape is an error naming the topic and the field.
    let event = rep
        .records
        .iter()
        .find(|r| r.is::<records::SweepEvent>())
        .unwrap();
    let e = event.decode::<StandRecord>().unwrap_err();
    let e = rep.malformed::<StandRecord>(0, e).to_string();
    assert!(
        e.contains("/stand record 0") && e.contains("missing field `name`"),
        "{e}"
    );
}

#[test]
fn every_record_of_an_old_session_validates_against_todays_schemas() {
    let dir = tempfile::tempdir().unwrap();
    let schemas: serde_json::Map<String, serde_json::Value> = ALL
        .iter()
        .map(|t| (t.name().to_string(), t.schema()))
        .collect();
    let schema_file = dir.path().join("schemas.json");
    std::fs::write(&schema_file, serde_json::to_vec(&schemas).unwrap()).unwrap();
    let script = r#"
import json, sys
from mcap.reader import make_reader
from jsonschema import Draft202012Validator
schemas = json.load(open(sys.argv[2]))
counts = {}
with open(sys.argv[1], "rb") as f:
    for schema, channel, message in make_reader(f).iter_messages():
        Draft202012Validator(schemas[channel.topic]).validate(json.loads(message.data))
        # The file's own recorded schema names the same record.
        assert json.loads(schema.data)["title"] == schemas[channel.topic]["title"]
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
print(json.dumps(counts))
"#;
    let out = Command::new("python3")
        .args(["-c", script])
        .arg(fixture("session-v1.mcap"))
        .arg(&schema_file)
        .output()
        .expect("python3 with mcap and jsonschema: run .ci/setup");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let counts: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // Every topic a stepped sweep of a shaker-controller stand writes (no faults, no broadband,
    // no signal generator's `/drive`) was checked.
    for t in ALL {
        let n = counts[t.name()].as_u64().unwrap_or(0);
        let expected = !matches!(t, Topic::DaqFault | Topic::SweepBroadband | Topic::Drive);
        assert_eq!(n > 0, expected, "{}: {counts}", t.name());
    }
}
