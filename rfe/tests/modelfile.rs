//! Model files: TOML with units, the resolved JSON contract, errors that point at the problem, and
//! a fuzzed loader that never panics.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use proptest::prelude::*;
use rfe::contract::{to_json, ModelJson};
use rfe::frf::{response, Method};
use rfe::modelfile::{parse_json, parse_toml, LoadError};
use rfe::textbook;

const TWO_MASS: &str = r#"
name = "two masses in series"

[[body]]
name = "first"
mass = "0.4 t"
position = [0, 0, 0]
inertia = ["40 kg m^2", "80 kg m^2", "120 kg m^2"]

[[body]]
name = "second"
mass = 120
position = "0 0 1000 mm"
inertia = [12, 24, 36]

[[sde]]
name = "k1"
kind = "spring"
bodies = ["ground", "first"]
point = [0, 0, 0]
axis = [0, 0, 1]
k = "20 N/um"
psi = 0.5

[[sde]]
name = "k2"
kind = "spring"
bodies = ["first", "second"]
point = "0 0 500 mm"
axis = [0, 0, 1]
k = "5 N/um"
psi = 0.5

[[sde]]
name = "guide 1"
kind = "general"
bodies = ["ground", "first"]
point = [0, 0, 0]
axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
k = ["10 N/um", "10 N/um", 0, "1e6 N*m/rad", "1e6 N m/rad", 1e6]
psi = [0.1, 0.1, 0, 0.1, 0.1, 0.1]

[[sde]]
name = "guide 2"
kind = "general"
bodies = ["ground", "second"]
point = [0, 0, 1]
axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
k = [1e7, 1e7, 0, 1e6, 1e6, 1e6]
psi = [0.1, 0.1, 0, 0.1, 0.1, 0.1]

[[excitation.force]]
body = "second"
point = [0, 0, 1]
force = "0 0 1 N"

[[output]]
body = "first"
dof = "u3"

[[output]]
body = "second"
dof = "u3"
"#;

#[test]
fn toml_with_units_equals_the_code_built_model() {
    let loaded = parse_toml(TWO_MASS, "two.toml").unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    let built = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
    let freqs: Vec<f64> = (1..100).map(|i| i as f64).collect();
    let a = response(&loaded.model, &freqs, &[], Method::Direct).unwrap();
    let b = response(&built, &freqs, &[], Method::Direct).unwrap();
    for (x, y) in a.values.iter().zip(&b.values) {
        assert!((x - y).norm() <= 1e-12 * y.norm(), "{x} vs {y}");
    }
}

#[test]
fn resolved_json_round_trips_exactly() {
    let model = parse_toml(TWO_MASS, "two.toml").unwrap().model;
    let json = serde_json::to_string_pretty(&to_json(&model)).unwrap();
    let again = parse_json(&json, "two.json").unwrap().model;
    assert_eq!(
        serde_json::to_string_pretty(&to_json(&again)).unwrap(),
        json
    );
    let freqs = [3.0, 30.0, 300.0];
    let a = response(&model, &freqs, &[], Method::Direct).unwrap();
    let b = response(&again, &freqs, &[], Method::Direct).unwrap();
    assert_eq!(a.values, b.values);
    // the contract's shape: keys exactly as specified
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let keys = |v: &serde_json::Value| v.as_object().unwrap().keys().cloned().collect::<Vec<_>>();
    assert_eq!(
        keys(&v),
        ["bodies", "excitation", "name", "outputs", "sdes"]
    );
    assert_eq!(
        keys(&v["bodies"][0]),
        ["inertia", "mass", "name", "position", "rotation"]
    );
    assert_eq!(
        keys(&v["sdes"][0]),
        ["bodies", "k", "name", "point", "psi", "rotation"]
    );
    assert_eq!(v["sdes"][0]["bodies"], serde_json::json!([null, 0]));
    assert_eq!(keys(&v["outputs"][0]), ["body", "dof", "quantity"]);
    let _: ModelJson = serde_json::from_value(v).unwrap();
}

#[test]
fn slideway_stiffness_follows_the_paper() {
    let text = r#"
[[body]]
name = "table"
mass = 300
position = [0, 0, 0]
inertia = [10, 20, 30]

[[sde]]
name = 2
kind = "slideway"
bodies = ["ground", "table"]
point = [0, 0, -0.1]
axes = [[0, 0, 1], [1, 0, 0], [0, 1, 0]]
size = ["400 mm", "50 mm"]
kn = "0.05 MPa/um"
kn_kt_ratio = 2.5
psi_n = 0.8
psi_t = 1.6
"#;
    let m = parse_toml(text, "s.toml").unwrap().model;
    let k = m.sdes[0].law.stiffness();
    let (a2, a3) = (0.4, 0.05);
    let (area, j2, j3) = (a2 * a3, a2 * a3f(a3), a3 * a3f(a2));
    fn a3f(x: f64) -> f64 {
        x * x * x / 12.0
    }
    let (kn, kt) = (0.05e12, 0.05e12 / 2.5);
    let want = [
        area * kn,
        area * kt,
        area * kt,
        (j2 + j3) * kt,
        j2 * kn,
        j3 * kn,
    ];
    for (g, w) in k.iter().zip(want) {
        assert!((g - w).abs() <= 1e-12 * w, "{k:?} vs {want:?}");
    }
    assert_eq!(m.sdes[0].law.dissipation(), [0.8, 1.6, 1.6, 1.6, 0.8, 0.8]);
    assert_eq!(m.sdes[0].name, "2");
}

fn error_of(text: &str) -> (usize, usize, String) {
    match parse_toml(text, "bad.toml") {
        Err(LoadError::Toml(at)) => {
            assert_eq!(at.file, "bad.toml");
            (at.line, at.column, at.message)
        }
        Err(e) => panic!("unexpected error kind: {e}"),
        Ok(_) => panic!("accepted a bad model:\n{text}"),
    }
}

fn replace_once(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "{from}");
    text.replacen(from, to, 1)
}

fn line_of(text: &str, needle: &str) -> usize {
    // the last occurrence: for duplicates, the second definition is the culprit
    text.lines()
        .collect::<Vec<_>>()
        .iter()
        .rposition(|l| l.contains(needle))
        .unwrap()
        + 1
}

#[test]
fn a_model_whose_stiffnesses_are_all_zero_is_warned_of_its_free_bodies() {
    let before = parse_toml(TWO_MASS, "m.toml").unwrap();
    assert!(before.warnings.is_empty(), "{:?}", before.warnings);
    let zero: String = TWO_MASS
        .lines()
        .map(|l| match l {
            l if l.starts_with("k = [") => "k = [0, 0, 0, 0, 0, 0]",
            l if l.starts_with("k = ") => "k = 0",
            l => l,
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert!(!zero.contains("N/um"), "every stiffness is zeroed:\n{zero}");
    let loaded = parse_toml(&zero, "zero.toml").unwrap();
    for body in ["first", "second"] {
        let want = format!("\"{body}\" is held only by SDEs whose stiffnesses are all 0");
        assert!(
            loaded
                .warnings
                .iter()
                .any(|w| w.contains(&want) && w.starts_with("zero.toml:")),
            "{body}: {:?}",
            loaded.warnings
        );
    }
}

#[test]
fn bad_models_are_located_and_explained() {
    let cases: Vec<(String, &str, &str)> = vec![
        (
            replace_once(
                TWO_MASS,
                r#"bodies = ["first", "second"]"#,
                r#"bodies = ["first", "secnod"]"#,
            ),
            "secnod",
            "unknown body \"secnod\"; known bodies: first, second",
        ),
        (
            replace_once(
                TWO_MASS,
                r#"bodies = ["first", "second"]"#,
                r#"bodies = ["first", "first"]"#,
            ),
            r#"bodies = ["first", "first"]"#,
            "to itself",
        ),
        (
            replace_once(TWO_MASS, "mass = 120", "mass = -120"),
            "mass = -120",
            "mass must be positive",
        ),
        (
            replace_once(TWO_MASS, "mass = 120", "mass = nan"),
            "mass = nan",
            "not a finite number",
        ),
        (
            replace_once(TWO_MASS, "inertia = [12, 24, 36]", "inertia = [12, 0, 36]"),
            "inertia = [12, 0, 36]",
            "must be positive",
        ),
        (
            replace_once(TWO_MASS, "psi = 0.5", "psi = -0.5"),
            "psi = -0.5",
            "sde k1: `psi` must be ≥ 0, got -0.5",
        ),
        (
            replace_once(
                TWO_MASS,
                "psi = [0.1, 0.1, 0, 0.1, 0.1, 0.1]",
                "psi = [0.1, 0.1, 0, -0.1, 0.1, 0.1]",
            ),
            "psi = [0.1, 0.1, 0, -0.1, 0.1, 0.1]",
            "must be ≥ 0",
        ),
        (
            replace_once(TWO_MASS, r#"k = "20 N/um""#, r#"k = "20 N/furlong""#),
            "20 N/furlong",
            "unknown unit \"furlong\"",
        ),
        (
            replace_once(TWO_MASS, r#"k = "20 N/um""#, r#"k = "20 MPa/um""#),
            "20 MPa/um",
            "a stiffness",
        ),
        (
            replace_once(
                TWO_MASS,
                "axis = [0, 0, 1]\nk = \"20",
                "axis = [0, 0, 0]\nk = \"20",
            ),
            "axis = [0, 0, 0]",
            "zero length",
        ),
        (
            replace_once(
                TWO_MASS,
                "axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\nk = [\"10",
                "axes = [[1, 0, 0], [0.5, 1, 0], [0, 0, 1]]\nk = [\"10",
            ),
            "[0.5, 1, 0]",
            "not orthonormal",
        ),
        (
            replace_once(
                TWO_MASS,
                "axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\nk = [\"10",
                "axes = [[1, 0, 0], [0, 0, 1], [0, 1, 0]]\nk = [\"10",
            ),
            "[0, 0, 1], [0, 1, 0]",
            "left-handed",
        ),
        (
            replace_once(TWO_MASS, "name = \"k2\"", "name = \"k1\""),
            "name = \"k1\"",
            "used twice",
        ),
        (
            replace_once(
                TWO_MASS,
                "name = \"second\"\nmass",
                "name = \"first\"\nmass",
            ),
            "name = \"first\"\nmass",
            "used twice",
        ),
        (
            replace_once(
                TWO_MASS,
                "psi = 0.5\n\n[[sde]]\nname = \"k2\"",
                "psi = 0.5\nkn = 3\n\n[[sde]]\nname = \"k2\"",
            ),
            "kn = 3",
            "does not apply to a spring",
        ),
        (
            replace_once(TWO_MASS, "kind = \"spring\"", "kind = \"sprung\""),
            "kind = \"sprung\"",
            "unknown kind",
        ),
        (
            replace_once(TWO_MASS, "dof = \"u3\"", "dof = \"z\""),
            "dof = \"z\"",
            "unknown dof",
        ),
        (
            replace_once(TWO_MASS, "position = [0, 0, 0]", "positoin = [0, 0, 0]"),
            "positoin",
            "unknown field",
        ),
    ];
    for (text, needle, want) in cases {
        let (line, col, message) = error_of(&text);
        let needle_line = line_of(&text, needle.lines().next().unwrap());
        assert!(message.contains(want), "expected \"{want}\" in: {message}");
        assert!(col >= 1);
        // errors about a whole element may point at its name a few lines above the bad field
        assert!(
            line <= needle_line && needle_line - line <= 8,
            "{message}: reported line {line}, problem on line {needle_line}"
        );
    }
}

#[test]
fn inertia_tensor_gives_principal_axes() {
    // a box rotated 30° about z: tensor R diag(J) Rᵀ
    let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let j = [10.0, 20.0, 30.0];
    let r = nalgebra::Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
    let t = r * nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::from(j)) * r.transpose();
    let text = format!(
        "[[body]]\nname = \"b\"\nmass = 5\nposition = [0, 0, 0]\ninertia_tensor = [[{}, {}, {}], [{}, {}, {}], [{}, {}, {}]]\n",
        t[(0, 0)], t[(0, 1)], t[(0, 2)], t[(1, 0)], t[(1, 1)], t[(1, 2)], t[(2, 0)], t[(2, 1)], t[(2, 2)]
    );
    let loaded = parse_toml(&text, "t.toml").unwrap();
    let b = &loaded.model.bodies[0];
    for (got, want) in b.inertia.iter().zip(j) {
        assert!((got - want).abs() < 1e-9);
    }
    // principal axis 1 (smallest moment) is R's first column up to sign
    assert!((b.rotation.column(0).dot(&r.column(0)).abs() - 1.0).abs() < 1e-9);
    assert!(b.rotation.determinant() > 0.0);
    // connected to nothing: warned, naming the body
    assert!(
        loaded
            .warnings
            .iter()
            .any(|w| w.contains("\"b\" is connected to nothing")),
        "{:?}",
        loaded.warnings
    );
    // not positive definite
    let bad = text.replace(
        &format!("[[{}, ", t[(0, 0)]),
        &format!("[[{}, ", -t[(0, 0)]),
    );
    let (_, _, message) = error_of(&bad);
    assert!(message.contains("not positive definite"), "{message}");
}

#[test]
fn json_errors_name_the_path() {
    let model = parse_toml(TWO_MASS, "two.toml").unwrap().model;
    let good = serde_json::to_value(to_json(&model)).unwrap();
    let mut bad = good.clone();
    bad["sdes"][1]["bodies"] = serde_json::json!([0, 0]);
    let e = parse_json(&bad.to_string(), "m.json")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("$.sdes[1].bodies") && e.contains("itself"),
        "{e}"
    );
    let mut bad = good.clone();
    bad["bodies"][0]["mass"] = serde_json::json!(-1.0);
    let e = parse_json(&bad.to_string(), "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("$.bodies[0].mass"), "{e}");
    let mut bad = good.clone();
    bad["sdes"][0]["k"] = serde_json::json!([1, 2, 3]);
    let e = parse_json(&bad.to_string(), "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("sdes[0].k"), "{e}");
    let mut bad = good;
    bad["outputs"][0]["quantity"] = serde_json::json!("jerk");
    let e = parse_json(&bad.to_string(), "m.json")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("$.outputs[0].quantity") && e.contains("jerk"),
        "{e}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    /// Arbitrary text never panics the loader.
    #[test]
    fn arbitrary_text_never_panics(text in "\\PC{0,400}") {
        let _ = parse_toml(&text, "fuzz.toml");
        let _ = parse_json(&text, "fuzz.json");
    }

    /// Valid files with a span of bytes replaced never panic the loader, and a success is a model
    /// whose frequency response can be computed or reported as an error (never a panic).
    #[test]
    fn mutated_models_never_panic(start in 0usize..TWO_MASS.len(), len in 0usize..12, junk in "[ -~\\n]{0,12}") {
        let mut bytes = TWO_MASS.as_bytes().to_vec();
        let end = (start + len).min(bytes.len());
        bytes.splice(start..end, junk.bytes());
        if let Ok(text) = String::from_utf8(bytes) {
            if let Ok(loaded) = parse_toml(&text, "fuzz.toml") {
                let _ = response(&loaded.model, &[0.0, 10.0], &loaded.model.all_params(), Method::Direct);
                let _ = response(&loaded.model, &[10.0], &[], Method::Modal);
            }
        }
    }
}
