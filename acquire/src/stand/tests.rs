use super::*;

const GOOD: &str = r#"
name = "test stand"
[shaker]
port = "sim"
identity = "IDENT-SIM,SHAKER-4K"
max_force = "6 kN"
[daq]
port = "sim"
sample_rate = "5120 Hz"
samples_per_block = 64
[[channel]]
name = "force"
device_channel = 0
kind = "force"
sensitivity = "2.25 mV/N"
[[channel]]
name = "table-x"
device_channel = 1
kind = "acceleration"
body = "table"
position = ["320 mm", "0 mm", "45 mm"]
direction = [2, 0, 0]
sensitivity = "100 mV/g"
[truth]
sdof = { body = "table", mass = "350 kg", stiffness = "2e8 N/m", loss_factor = 0.05, direction = [1, 0, 0] }
noise_acceleration = "0.01 m/s2"
"#;

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
    let second = t.lines().enumerate().filter(|(_, l)| l.contains("device_channel = 0")).nth(1).unwrap().0 + 1;
    assert_eq!(e.line, second, "{e}");
    assert!(e.message.contains("device_channel 0 is already used by channel `force`"), "{e}");
    assert!(e.to_string().starts_with("bad.toml:"));
}

#[test]
fn inconsistent_channel_maps_are_rejected_with_locations() {
    let cases = [
        (GOOD.replace("kind = \"force\"", "kind = \"acceleration\"\nbody=\"table\"\nposition=[0,0,0]\ndirection=[0,0,1]"), "exactly one `kind = \"force\"`"),
        (GOOD.replace("name = \"table-x\"", "name = \"force\""), "already used on line"),
        (GOOD.replace("direction = [2, 0, 0]", "direction = [0, 0, 0]"), "zero length"),
        (GOOD.replace("body = \"table\"\nposition", "body = \"spindle\"\nposition"), "body `spindle` is not in the truth model"),
        (GOOD.replace("direction = [2, 0, 0]\n", ""), "needs `direction`"),
        (GOOD.replace("\"100 mV/g\"", "\"100 mm\""), "not a Sensitivity unit"),
        (GOOD.replace("\"100 mV/g\"", "-1"), "must be > 0"),
        (GOOD.replace("samples_per_block = 64", "samples_per_block = 4000"), "do not fit"),
        (GOOD.replace("kind = \"force\"", "kind = \"velocity\""), "unknown variant"),
        (GOOD.replace("[truth]", "[truth]\nsped = 3"), "unknown field"),
        (GOOD.replace("port = \"sim\"\nsample_rate", "port = \"/dev/x\"\nsample_rate").replace("port = \"sim\"\nidentity", "port = \"/dev/x\"\nidentity"), "also the shaker's port"),
    ];
    for (text, want) in cases {
        let e = err(&text);
        assert!(e.message.contains(want), "want {want:?}, got {e}");
        assert!(e.line >= 1, "{e}");
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
