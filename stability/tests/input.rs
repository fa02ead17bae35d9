//! Bad input: each error names the file, the field and the fix.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use stability::cut::{self, CutError};
use stability::{oriented, Request, StabilityError};

const GOOD: &str = r#"
operation = "milling"
speed_rpm = [200, 2000]
[tool]
body = "spindle head"
point = [0.0, 0.9, 1.15]
[workpiece]
body = "table"
point = [0.0, 0.9, 0.95]
[cutting]
kt = "1800 MPa"
kr = "540 MPa"
[milling]
teeth = 4
diameter = "80 mm"
radial_depth = "40 mm"
direction = "down"
feed = [1.0, 0.0, 0.0]
"#;

fn fwd32j() -> rfe::Model {
    let p =
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/models/fwd32j.toml");
    rfe::modelfile::load(&p).unwrap().model
}

#[test]
fn the_example_parses_and_units_convert() {
    let c = cut::parse(GOOD, "cut.toml").unwrap();
    assert_eq!(c.kt, 1.8e9);
    assert_eq!(c.kr, 5.4e8);
    assert_eq!(c.periods_per_rev(), 4);
    let d = c.directions();
    assert!(
        (d[1] - nalgebra::Vector3::y()).norm() < 1e-15,
        "y = axis × feed"
    );
}

#[test]
fn a_cutting_file_without_coefficients_names_the_field_and_the_fix() {
    let text = GOOD.replace("[cutting]\nkt = \"1800 MPa\"\nkr = \"540 MPa\"\n", "");
    let e = cut::parse(&text, "cut.toml").unwrap_err();
    let m = e.to_string();
    assert!(
        matches!(e, CutError::Field { ref field, .. } if field == "cutting"),
        "{m}"
    );
    assert!(
        m.starts_with("cut.toml: cutting:") && m.contains("kt = "),
        "{m}"
    );

    let text = GOOD.replace("kt = \"1800 MPa\"\n", "");
    let m = cut::parse(&text, "cut.toml").unwrap_err().to_string();
    assert!(
        m.starts_with("cut.toml: cutting.kt: missing;") && m.contains("pressure"),
        "{m}"
    );

    let text = GOOD.replace("\"1800 MPa\"", "\"1800 kg\"");
    let m = cut::parse(&text, "cut.toml").unwrap_err().to_string();
    assert!(
        m.contains("cutting.kt") && m.contains("\"kg\" is not a pressure unit"),
        "{m}"
    );
}

#[test]
fn cutting_coefficients_need_a_pressure_unit() {
    // N/mm² = MPa: the handbooks' unit and the SI one give the same coefficient.
    for (text, si) in [
        ("1800 MPa", 1.8e9),
        ("1800 N/mm^2", 1.8e9),
        ("1800N/mm²", 1.8e9),
        ("1.8 GPa", 1.8e9),
        ("1.8e9 Pa", 1.8e9),
        ("1.8e9 N/m^2", 1.8e9),
    ] {
        let c = cut::parse(
            &GOOD.replace("\"1800 MPa\"", &format!("\"{text}\"")),
            "cut.toml",
        )
        .unwrap();
        assert!((c.kt - si).abs() < 1e-6 * si, "{text}: {}", c.kt);
    }
    // A bare number, a number without a unit, and a pressure per length are refused, naming
    // the field and the units it takes.
    for (value, problem) in [
        ("1800", "has no unit"),
        ("\"1800\"", "has no unit"),
        ("\"1800 MPa/m\"", "\"MPa/m\" is not a pressure unit"),
        ("\"1800 psi\"", "\"psi\" is not a pressure unit"),
        ("\"MPa\"", "does not start with a number"),
    ] {
        let text = GOOD.replace("kr = \"540 MPa\"", &format!("kr = {value}"));
        let m = cut::parse(&text, "cut.toml").unwrap_err().to_string();
        assert!(
            m.starts_with("cut.toml: cutting.kr:") && m.contains(problem) && m.contains("N/mm^2"),
            "{value}: {m}"
        );
    }
}

#[test]
fn other_fields_are_checked() {
    for (from, to, field) in [
        ("teeth = 4", "teeth = 0", "milling.teeth"),
        (
            "radial_depth = \"40 mm\"",
            "radial_depth = \"90 mm\"",
            "milling.radial_depth",
        ),
        (
            "direction = \"down\"",
            "direction = \"climb\"",
            "milling.direction",
        ),
        (
            "feed = [1.0, 0.0, 0.0]",
            "feed = [0.0, 0.0, 1.0]",
            "milling.feed",
        ),
        (
            "speed_rpm = [200, 2000]",
            "speed_rpm = [2000, 200]",
            "speed_rpm",
        ),
        (
            "operation = \"milling\"",
            "operation = \"drilling\"",
            "operation",
        ),
    ] {
        let m = cut::parse(&GOOD.replace(from, to), "cut.toml")
            .unwrap_err()
            .to_string();
        assert!(m.starts_with(&format!("cut.toml: {field}:")), "{m}");
    }
    let m = cut::parse(&format!("{GOOD}\nbogus = 1\n"), "cut.toml")
        .unwrap_err()
        .to_string();
    assert!(m.starts_with("cut.toml:") && m.contains("bogus"), "{m}");
}

#[test]
fn points_not_on_the_named_bodies_are_refused() {
    let model = fwd32j();
    // The table's point typed in millimetres as metres.
    let c = cut::parse(
        &GOOD.replace("[0.0, 0.9, 0.95]", "[0.0, 900.0, 950.0]"),
        "cut.toml",
    )
    .unwrap();
    let e = oriented::place(&model, &c).unwrap_err();
    let m = e.to_string();
    assert!(matches!(e, StabilityError::Placement { .. }), "{m}");
    assert!(
        m.starts_with("cut.toml: workpiece.point:")
            && m.contains("outside body \"table\"")
            && m.contains("metres"),
        "{m}"
    );
    // The spindle nose named on the knee.
    let c = cut::parse(
        &GOOD.replace("body = \"spindle head\"", "body = \"knee\""),
        "cut.toml",
    )
    .unwrap();
    let m = oriented::place(&model, &c).unwrap_err().to_string();
    assert!(m.starts_with("cut.toml: tool.point:"), "{m}");
    // A body the model does not have.
    let c = cut::parse(&GOOD.replace("\"spindle head\"", "\"spindle\""), "cut.toml").unwrap();
    let m = oriented::place(&model, &c).unwrap_err().to_string();
    assert!(
        m.contains("tool.body") && m.contains("\"spindle head\""),
        "{m}"
    );
}

#[test]
fn a_speed_range_with_no_lobe_is_an_error() {
    let model = fwd32j();
    // The FRF's band below every mode: the oriented FRF has no negative real part.
    let c = cut::parse(&format!("band_hz = [0.01, 0.1]\n{GOOD}"), "cut.toml").unwrap();
    let e = stability::lobes(&Request::new(&model, &c)).unwrap_err();
    let m = e.to_string();
    assert!(matches!(e, StabilityError::NoLobe { .. }), "{m}");
    assert!(
        m.starts_with("cut.toml: speed_rpm: no stability lobe"),
        "{m}"
    );
    // Speeds far above the highest lobe of the band.
    let c = cut::parse(
        &format!(
            "band_hz = [5, 400]\n{}",
            GOOD.replace("[200, 2000]", "[1e8, 2e8]")
        ),
        "cut.toml",
    )
    .unwrap();
    let m = stability::lobes(&Request::new(&model, &c))
        .unwrap_err()
        .to_string();
    assert!(m.contains("widen speed_rpm"), "{m}");
}
