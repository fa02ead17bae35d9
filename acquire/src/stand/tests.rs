use super::*;

const GOOD: &str = concat!(
    r#"
name = "test stand"
[shaker]
port = "sim"
identity = "IDENT-SIM,SHAKER-4K"
max_force = "6 kN"
[daq]
port = "sim"
sample_rate = "5120 Hz"
samples_per_block = 64
"#,
    test_stand_channels!(),
    r#"[truth]
sdof = { body = "table", mass = "350 kg", stiffness = "2e8 N/m", loss_factor = 0.05, direction = [1, 0, 0] }
noise_acceleration = "0.01 m/s2"
"#
);

#[test]
fn good_stand_resolves_to_si() {
    let s = Stand::parse(GOOD, "good.toml").unwrap();
    assert_eq!(s.shaker.max_force_n, 6000.0);
    assert_eq!(s.channels[1].position_m, [0.32, 0.0, 0.045]);
    assert_eq!(s.channels[1].direction, [1.0, 0.0, 0.0]);
    assert!((s.channels[0].sensitivity - 2.25e-3).abs() < 1e-15);
    assert_eq!(s.force_channel(), 0);
    assert_eq!(s.daq_config().channels, vec![0, 1]);
}

fn err(text: &str) -> StandError {
    Stand::parse(text, "bad.toml").unwrap_err()
}

fn line_of(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.contains(needle)).unwrap() + 1
}

#[test]
fn duplicate_device_channel_names_both_channels_and_line() {
    let t = GOOD.replace("device_channel = 1", "device_channel = 0");
    let e = err(&t);
    let second = t
        .lines()
        .enumerate()
        .filter(|(_, l)| l.contains("device_channel = 0"))
        .nth(1)
        .unwrap()
        .0
        + 1;
    assert_eq!(e.line, second, "{e}");
    assert!(
        e.message
            .contains("device_channel 0 is already used by channel `force`"),
        "{e}"
    );
    assert!(e.to_string().starts_with("bad.toml:"));
}

#[test]
fn inconsistent_channel_maps_are_rejected_with_locations() {
    // (text of the good stand file, what it is replaced by, what the error says)
    let cases = [
        (
            "kind = \"force\"\nsensitivity = \"2.25 mV/N\"",
            "kind = \"acceleration\"\nsensitivity = \"1 V/g\"\nbody=\"table\"\nposition=[0,0,0]\ndirection=[0,0,1]",
            "exactly one `kind = \"force\"`",
        ),
        (
            "kind = \"force\"",
            "kind = \"acceleration\"\nbody=\"table\"\nposition=[0,0,0]\ndirection=[0,0,1]",
            "is the unit of a force sensor, but the channel's kind is Acceleration",
        ),
        ("name = \"table-x\"", "name = \"force\"", "already used on line"),
        ("direction = [2, 0, 0]", "direction = [0, 0, 0]", "zero length"),
        (
            "body = \"table\"\nposition",
            "body = \"spindle\"\nposition",
            "body `spindle` is not in the truth model",
        ),
        ("direction = [2, 0, 0]\n", "", "needs `direction`"),
        (
            "\"100 mV/g\"",
            "\"100 mm\"",
            "an accelerometer sensitivity, e.g. \"100 mV/g\"",
        ),
        ("\"100 mV/g\"", "-1", "must be > 0"),
        (
            "identity = \"IDENT-SIM,SHAKER-4K\"",
            "identity = \"IDENT-SIM,SHAKER-4K\"\nbaud = 0",
            "shaker.baud = 0: give the serial line's bit rate",
        ),
        (
            "samples_per_block = 64",
            "samples_per_block = 64\nbaud = 0",
            "daq.baud = 0",
        ),
        (
            "samples_per_block = 64",
            "samples_per_block = 64\ninputs = 0",
            "daq.inputs must be ≥ 1",
        ),
        (
            "samples_per_block = 64",
            "samples_per_block = 64\ninputs = 1",
            "device_channel 1 is beyond the DAQ's 1 inputs (numbered 0 to 0)",
        ),
        ("samples_per_block = 64", "samples_per_block = 4000", "do not fit"),
        ("kind = \"force\"", "kind = \"velocity\"", "unknown variant"),
        ("[truth]", "[truth]\nsped = 3", "unknown field"),
        // Both ports, the shaker's and the DAQ's.
        ("port = \"sim\"", "port = \"/dev/x\"", "also the shaker's port"),
    ];
    for (from, to, want) in cases {
        assert!(
            GOOD.contains(from),
            "{from:?} is not in the good stand file"
        );
        let e = err(&GOOD.replace(from, to));
        assert!(
            e.message.contains(want),
            "{from:?} → {to:?}: want {want:?}, got {e}"
        );
        assert!(e.line >= 1, "{from:?} → {to:?}: {e}");
    }
}

#[test]
fn syntax_errors_point_at_the_line() {
    let t = GOOD.replace("samples_per_block = 64", "samples_per_block = = 64");
    let e = err(&t);
    assert_eq!(e.line, line_of(&t, "= = 64"), "{e}");
}

#[test]
fn repository_stand_files_load() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/stands");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "toml") {
            Stand::load(&p).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(n >= 1, "no stand files in {}", dir.display());
}

#[test]
fn can_ports_and_identifiers_are_read_and_checked() {
    let t = GOOD.replace(
        "port = \"sim\"\nsample_rate",
        "port = \"can:can0\"\nsample_rate",
    )
        + "\n[daq.can]\nframes = \"fd\"\ncommand_id = 0x310\nstatus_id = 0x311\ndata_id = 0x312\n";
    // `[daq.can]` after `[truth]` is still the daq table's sub-table.
    let s = Stand::parse(&t, "can.toml").unwrap();
    assert_eq!(s.daq.port, PortSpec::Can("can0".into()));
    assert_eq!(s.daq.can.frames, crate::can::FrameKind::Fd);
    assert_eq!(s.daq.can.data_id, crate::can::CanId::Standard(0x312));
    // Without `daq.timeout` the CAN DAQ keeps its own default; with it, the stand file decides.
    assert_eq!(
        s.daq.can.answer_timeout,
        crate::can::CanDaqSettings::default().answer_timeout
    );
    let timed = t.replace(
        "samples_per_block = 64",
        "samples_per_block = 64\ntimeout = \"3 s\"\nretries = 5",
    );
    let s = Stand::parse(&timed, "can.toml").unwrap();
    assert_eq!(
        (s.daq.can.answer_timeout, s.daq.can.retries),
        (std::time::Duration::from_secs(3), 5)
    );
    let e = err(&t.replace("frames = \"fd\"", "frames = \"flexible\""));
    assert!(
        e.message
            .contains("daq.can.frames = \"flexible\": write \"classic\""),
        "{e}"
    );
    assert_eq!(e.line, line_of(&t, "frames = \"fd\""), "{e}");
    let e = err(&t.replace("status_id = 0x311", "status_id = 0x310"));
    assert!(e.message.contains("must all differ"), "{e}");
    let e = err(&t.replace("data_id = 0x312", "data_id = 0x912"));
    assert!(
        e.message.contains("daq.can.data_id") && e.message.contains("out of range"),
        "{e}"
    );
    let e = err(&GOOD.replace(
        "port = \"sim\"\nidentity = \"IDENT-SIM,SHAKER-4K\"",
        "port = \"can:can0\"\nidentity = \"x\"",
    ));
    assert!(
        e.message
            .contains("shaker controller speaks SCPI over serial"),
        "{e}"
    );
}

#[test]
fn sensors_must_sit_on_the_body_they_name() {
    let dir = tempfile::tempdir().unwrap();
    let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../configs/models/fwd32j-no-actuator.toml");
    let with = |pos: &str| {
        GOOD.replace("position = [\"320 mm\", \"0 mm\", \"45 mm\"]", pos)
            .replace(
                "[truth]",
                &format!("[geometry]\nmodel = \"{}\"\n[truth]", models.display()),
            )
    };
    // On the table's top surface (x -625..625, y 740..1060, z up to 950 mm): accepted, geometry recorded.
    let p = dir.path().join("ok.toml");
    std::fs::write(&p, with("position = [\"600 mm\", \"1050 mm\", \"950 mm\"]")).unwrap();
    let s = Stand::load(&p).unwrap_or_else(|e| panic!("{e}"));
    let g = s.geometry.as_ref().unwrap();
    assert_eq!(g.bodies.len(), 1);
    assert_eq!(g.bodies[0].name, "table");
    assert!((g.nominal_force_n - 4000.0).abs() < 1e-9);
    let h = g.bodies[0].equivalent_box_half_extents();
    assert!(
        (h[0] - 0.625).abs() < 1e-3 && (h[1] - 0.16).abs() < 1e-3 && (h[2] - 0.06).abs() < 1e-3,
        "{h:?}"
    );
    assert_eq!(
        g.outputs.iter().map(|o| o.dof).collect::<Vec<_>>(),
        vec![0, 1, 2]
    );
    // 250 mm beyond the table's side (yesterday's stand file): refused, naming file, line and fix.
    let t = with("position = [\"0 mm\", \"1150 mm\", \"950 mm\"]");
    let p = dir.path().join("off.toml");
    std::fs::write(&p, &t).unwrap();
    let e = Stand::load(&p).unwrap_err();
    assert_eq!(e.line, line_of(&t, "name = \"table-x\"") - 1, "{e}");
    assert!(
        e.message
            .starts_with("channel `table-x`: position [0, 1150, 950] mm is not on body `table`"),
        "{e}"
    );
    assert!(
        e.message.contains("reaches only ±[625, 160, 60] mm") && e.message.contains("y 740..1060"),
        "{e}"
    );
    // A body the geometry model does not have.
    let t = with("position = [\"0 mm\", \"900 mm\", \"950 mm\"]")
        .replace("body = \"table\"\nposition", "body = \"tabel\"\nposition")
        .replace("sdof = { body = \"table\"", "sdof = { body = \"tabel\"");
    std::fs::write(&p, &t).unwrap();
    let e = Stand::load(&p).unwrap_err();
    assert!(
        e.message
            .contains("body `tabel` is not in the geometry model")
            && e.message.contains("table"),
        "{e}"
    );
}
