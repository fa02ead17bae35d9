use super::*;
use serde_json::json;

#[test]
fn every_topic_round_trips_and_schemas_are_registered() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    let s = Session::create(&path, SessionOptions::default()).unwrap();
    let h = s.handle();
    for (i, t) in crate::record::ALL.iter().enumerate() {
        h.log(*t, &json!({"i": i, "topic": t.name()})).unwrap();
    }
    h.bytes("/dev/pts/9", Direction::Rx, &[0, 1, 2, 255]);
    let summary = s.finish().unwrap();
    assert_eq!(summary.total(), crate::record::ALL.len() as u64 + 1);
    let r = read(&path).unwrap();
    assert_eq!(r.truncated, None);
    assert_eq!(r.records.len(), crate::record::ALL.len() + 1);
    for (i, t) in crate::record::ALL.iter().enumerate() {
        assert_eq!(r.records[i].topic, t.name());
        assert_eq!(r.records[i].value["i"], json!(i));
    }
    let raw = &r.records.last().unwrap().value;
    assert_eq!(raw["data"], json!("AAEC/w=="));
    assert_eq!(raw["direction"], json!("rx"));
    // Indexed read of the complete file: every channel has a jsonschema schema.
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(summary.channels.len(), crate::record::ALL.len());
    for c in summary.channels.values() {
        let sch = c.schema.as_ref().unwrap();
        assert_eq!(sch.encoding, "jsonschema");
        assert_eq!(c.message_encoding, "json");
        let v: serde_json::Value = serde_json::from_slice(&sch.data).unwrap();
        assert_eq!(v["type"], json!("object"));
    }
}

#[test]
fn refuses_to_overwrite_and_logging_after_finish_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    let s = Session::create(&path, SessionOptions::default()).unwrap();
    let h = s.handle();
    s.finish().unwrap();
    assert!(matches!(
        h.log(Topic::SweepEvent, &json!({})),
        Err(SessionError::Closed { .. })
    ));
    let e = Session::create(&path, SessionOptions::default())
        .err()
        .unwrap();
    assert!(e.to_string().contains("s.mcap"), "{e}");
}

#[test]
fn truncated_file_is_recovered_up_to_the_last_flush() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    let s = Session::create(
        &path,
        SessionOptions {
            flush_interval: Duration::from_secs(3600),
            ..Default::default()
        },
    )
    .unwrap();
    let h = s.handle();
    for i in 0..100 {
        h.log(
            Topic::SweepEvent,
            &json!({"kind": "x", "i": i, "detail": ""}),
        )
        .unwrap();
    }
    h.flush(Duration::from_secs(10)).unwrap();
    let flushed_len = std::fs::metadata(&path).unwrap().len();
    for i in 100..150 {
        h.log(
            Topic::SweepEvent,
            &json!({"kind": "x", "i": i, "detail": ""}),
        )
        .unwrap();
    }
    s.finish().unwrap();
    // Simulate a crash right after the flush, plus a torn write of a few extra bytes.
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..flushed_len as usize + 7]).unwrap();
    assert!(
        mcap::MessageStream::new(&std::fs::read(&cut).unwrap())
            .map(|s| s.count())
            .is_err()
            || mcap::MessageStream::new(&std::fs::read(&cut).unwrap())
                .unwrap()
                .any(|m| m.is_err())
    );
    let out = recovered_path(&cut);
    let rep = recover(&cut, &out).unwrap();
    assert_eq!(rep.messages, 100);
    assert!(rep.truncated.is_some());
    let back = read(&out).unwrap();
    assert_eq!(back.truncated, None);
    let idx: Vec<i64> = back
        .records
        .iter()
        .map(|r| r.value["i"].as_i64().unwrap())
        .collect();
    assert_eq!(idx, (0..100).collect::<Vec<_>>());
    assert!(recover(&cut, &out).is_err(), "must not overwrite");
}

#[test]
fn files_that_are_not_sessions_are_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, Vec<u8>, &str); 4] = [
        (
            "empty.mcap",
            Vec::new(),
            "is not an MCAP file (the file is empty)",
        ),
        (
            "random.mcap",
            (0..4096u32)
                .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
                .collect(),
            "is not an MCAP file (it starts with",
        ),
        (
            "text.mcap",
            b"time,force\n0,1\n".to_vec(),
            "not the MCAP magic",
        ),
        (
            "magic.mcap",
            mcap::MAGIC.to_vec(),
            "no message can be recovered",
        ),
    ];
    for (name, bytes, want) in cases {
        let input = dir.path().join(name);
        std::fs::write(&input, &bytes).unwrap();
        let out = recovered_path(&input);
        let e = recover(&input, &out).expect_err(name);
        assert!(e.to_string().contains(want), "{name}: {e}");
        assert!(!out.exists(), "{name}: an output was written");
        if name != "magic.mcap" {
            let e = read(&input).expect_err(name);
            assert!(matches!(e, SessionError::NotMcap { .. }), "{name}: {e}");
        }
    }
}
