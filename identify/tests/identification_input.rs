//! Bad and good input of identification: measured data (JSON, CSV: round trips, located errors,
//! fuzzing) and variables files (located errors naming the item).

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use identify::{data, variables};
use proptest::prelude::*;
use rfe::measured::{MeasuredData, Measurement, QuantityName};
use rfe::textbook;

fn model() -> rfe::Model {
    textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5)
}

fn sample() -> MeasuredData {
    MeasuredData {
        source: "sample.json".into(),
        characteristics: vec![
            Measurement {
                body: "first".into(),
                dof: 2,
                quantity: QuantityName::Displacement,
                freqs_hz: vec![10.0, 20.0, 30.5],
                amplitude: vec![1e-7, 2.5e-7, 1.25e-7],
                phase_rad: Some(vec![-0.1, -1.2, -2.9]),
                variance: Some(vec![1e-17, 2e-17, 3e-17]),
                coherence: None,
                averages: Some(8),
                at: None,
                reference: None,
                relative: false,
            },
            Measurement {
                body: "second".into(),
                dof: 2,
                quantity: QuantityName::Displacement,
                freqs_hz: vec![10.0, 20.0],
                amplitude: vec![3e-7, 4e-7],
                phase_rad: None,
                variance: None,
                coherence: Some(vec![0.9, 0.95]),
                averages: None,
                at: None,
                reference: None,
                relative: false,
            },
        ],
    }
}

#[test]
fn csv_and_json_round_trip() {
    let d = sample();
    let csv = data::to_csv(&d);
    let mut back = data::parse_csv(&csv, "sample.csv").unwrap();
    back.source = d.source.clone();
    assert_eq!(back, d);
    let json = serde_json::to_string(&d).unwrap();
    assert_eq!(data::parse_json(&json, "sample.json").unwrap(), d);
    assert!(data::validate(&d, &model(), "sample.json").is_ok());
}

#[test]
fn csv_rows_may_come_in_any_order_and_columns_are_named() {
    let text = "# comment\nfreq_hz,amplitude,dof,body\n20,2e-7,u3,first\n10,1e-7,u3,first\n";
    let d = data::parse_csv(text, "x.csv").unwrap();
    assert_eq!(d.characteristics[0].freqs_hz, vec![10.0, 20.0]);
    assert_eq!(d.characteristics[0].amplitude, vec![1e-7, 2e-7]);
    assert_eq!(d.characteristics[0].quantity, QuantityName::Displacement);
}

#[test]
fn csv_and_toml_with_a_byte_order_mark_read_as_without() {
    let csv = "body,dof,freq_hz,amplitude\nfirst,u3,10,1e-7\n";
    let with_bom = format!("\u{feff}{csv}");
    assert_eq!(
        data::parse_csv(&with_bom, "bom.csv").unwrap(),
        data::parse_csv(csv, "bom.csv").unwrap()
    );
    let model = "[[body]]\nname = \"b\"\nmass = 2\nposition = [0, 0, 0]\ninertia = [1, 1, 1]\n";
    let plain = rfe::modelfile::parse_toml(model, "m.toml").unwrap();
    let bom = rfe::modelfile::parse_toml(&format!("\u{feff}{model}"), "m.toml").unwrap();
    assert_eq!(bom.model, plain.model);
    // Errors in a file with a BOM still point at the right line and column.
    let bad = "\u{feff}[[body]]\nname = \"b\"\nmass = \"2 furlong\"\nposition = [0, 0, 0]\ninertia = [1, 1, 1]\n";
    let e = rfe::modelfile::parse_toml(bad, "m.toml")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("m.toml:3:8:"), "{e}");
}

#[test]
fn csv_fields_may_be_quoted_and_write_back_quoted() {
    // A reference whose name holds a comma, quoted as RFC 4180 has it, after a unit declaration.
    let text = "# quantity = accelerance, unit = g/N\nbody,dof,freq_hz,amplitude,reference\n\"first\",u3,10,1e-3,\"drive, left\"\nfirst, u3 ,20,2e-3,\"drive, left\"\n";
    let (d, declared) = data::parse_csv_declared(text, "q.csv").unwrap();
    assert_eq!(
        declared.map(|u| (u.unit.text, u.line)),
        Some(("g/N".to_string(), 1))
    );
    assert_eq!(d.characteristics.len(), 1);
    let m = &d.characteristics[0];
    assert_eq!(m.reference.as_deref(), Some("drive, left"));
    assert_eq!((m.body.as_str(), m.dof), ("first", 2));
    assert_eq!(m.freqs_hz, vec![10.0, 20.0]);
    let written = data::to_csv(&d);
    assert!(written.contains(",\"drive, left\","), "{written}");
    let mut back = data::parse_csv(&written, "q.csv").unwrap();
    back.source = d.source.clone();
    assert_eq!(back, d);
}

fn csv_err(text: &str) -> String {
    data::parse_csv(text, "bad.csv").unwrap_err().to_string()
}

#[test]
fn csv_errors_name_the_line() {
    let e = csv_err("body,dof,freq_hz,amplitude\nfirst,u3,10,1e-7\nfirst,u3,10,2e-7\n");
    assert!(
        e.starts_with("bad.csv:3:") && e.contains("repeats line 2"),
        "{e}"
    );
    let e = csv_err("body,dof,freq_hz,amplitude\nfirst,u3,ten,1e-7\n");
    assert!(
        e.starts_with("bad.csv:2:") && e.contains("\"ten\" is not a number"),
        "{e}"
    );
    let e = csv_err("body,dof,freq_hz,amp\n");
    assert!(
        e.starts_with("bad.csv:1:") && e.contains("unknown column \"amp\""),
        "{e}"
    );
    let e = csv_err("body,dof,freq_hz\n");
    assert!(e.contains("missing column \"amplitude\""), "{e}");
    let e = csv_err("body,dof,freq_hz,amplitude\nfirst,u7,10,1e-7\n");
    assert!(
        e.starts_with("bad.csv:2:") && e.contains("unknown dof \"u7\""),
        "{e}"
    );
    let e =
        csv_err("body,dof,freq_hz,amplitude,variance\nfirst,u3,10,1e-7,1e-17\nfirst,u3,20,1e-7,\n");
    assert!(e.starts_with("bad.csv:3:") && e.contains("variance"), "{e}");
    let e = csv_err("body,dof,freq_hz,amplitude\nfirst,u3,10\n");
    assert!(e.starts_with("bad.csv:2:") && e.contains("3 cells"), "{e}");
}

fn invalid(edit: impl Fn(&mut MeasuredData)) -> String {
    let mut d = sample();
    edit(&mut d);
    data::validate(&d, &model(), "data.json")
        .unwrap_err()
        .to_string()
}

#[test]
fn invalid_data_is_named_by_file_characteristic_and_point() {
    let e = invalid(|d| d.characteristics[0].amplitude[1] = f64::NAN);
    assert!(
        e.contains("data.json")
            && e.contains("$.characteristics[0] (first u3 displacement), point 1 (20 Hz)")
            && e.contains("NaN"),
        "{e}"
    );
    let e = invalid(|d| d.characteristics[1].amplitude[0] = -1e-7);
    assert!(
        e.contains("characteristics[1]") && e.contains("negative"),
        "{e}"
    );
    let e = invalid(|d| d.characteristics[0].freqs_hz[1] = 10.0);
    assert!(
        e.contains("point 1") && e.contains("repeats point 0"),
        "{e}"
    );
    let e = invalid(|d| d.characteristics[0].freqs_hz[2] = 15.0);
    assert!(e.contains("point 2") && e.contains("must increase"), "{e}");
    let e = invalid(|d| d.characteristics[0].body = "tabel".into());
    assert!(
        e.contains("unknown body \"tabel\"") && e.contains("first, second"),
        "{e}"
    );
    let e = invalid(|d| d.characteristics[0].dof = 0);
    assert!(
        e.contains("not among the model's outputs") && e.contains("first u3 displacement"),
        "{e}"
    );
    let e = invalid(|d| {
        d.characteristics[0]
            .amplitude
            .pop()
            .map(|_| ())
            .unwrap_or(())
    });
    assert!(
        e.contains("amplitude has 2 values but freqs_hz has 3"),
        "{e}"
    );
    let e = invalid(|d| d.characteristics[1].coherence = Some(vec![0.9, 1.5]));
    assert!(e.contains("coherence 1.5"), "{e}");
    let e = invalid(|d| d.characteristics[0].variance = Some(vec![1e-17, 0.0, 1e-17]));
    assert!(e.contains("variance 0"), "{e}");
    let e = invalid(|d| {
        let c = d.characteristics[0].clone();
        d.characteristics.push(c)
    });
    assert!(
        e.contains("characteristics[2]") && e.contains("appears twice"),
        "{e}"
    );
    let e = invalid(|d| d.characteristics[0].averages = Some(0));
    assert!(e.contains("averages is 0"), "{e}");
}

#[test]
fn json_errors_give_the_path() {
    let e = data::parse_json(
        r#"{"characteristics": [{"body": "first", "dof": "x"}]}"#,
        "d.json",
    )
    .unwrap_err()
    .to_string();
    assert!(e.starts_with("d.json: at $.characteristics[0].dof"), "{e}");
}

proptest! {
    #[test]
    fn csv_parsing_never_panics(text in "[a-z0-9_,.#\\n -]{0,300}") {
        let _ = data::parse_csv(&text, "fuzz.csv");
    }

    #[test]
    fn csv_round_trips_any_valid_data(
        amps in proptest::collection::vec(0.0f64..1.0, 1..20),
        start in 0.0f64..100.0,
    ) {
        let freqs: Vec<f64> = (0..amps.len()).map(|i| start + i as f64 * 0.5).collect();
        let d = MeasuredData {
            source: "p".into(),
            characteristics: vec![Measurement {
                body: "second".into(), dof: 2, quantity: QuantityName::Velocity,
                freqs_hz: freqs, amplitude: amps, phase_rad: None, variance: None, coherence: None, averages: None, at: None, reference: None, relative: false,
            }],
        };
        let mut back = data::parse_csv(&data::to_csv(&d), "p").unwrap();
        back.source = "p".into();
        prop_assert_eq!(back, d);
    }

    #[test]
    fn variables_parsing_never_panics(text in "[a-z0-9_=\"\\[\\]\\n ,.-]{0,200}") {
        let _ = variables::parse(&text, "fuzz.toml", &model());
    }
}

fn vars_err(text: &str) -> String {
    variables::parse(text, "vars.toml", &model())
        .unwrap_err()
        .to_string()
}

#[test]
fn variables_file_errors_are_located_and_explained() {
    // Each file, the location its error starts with ("" where not asserted) and what it says.
    for (text, at, says) in [
        (
            "[[variable]]\nsdes = \"k3\"\nparameter = \"k\"\n",
            "vars.toml:2:",
            &["unknown SDE \"k3\"", "k1, k2"][..],
        ),
        (
            "[[variable]]\nsdes = \"k1\"\nparameter = \"kk\"\n",
            "vars.toml:3:",
            &["unknown parameter \"kk\""],
        ),
        (
            "[[variable]]\nsdes = \"k1\"\nparameter = \"kn\"\n",
            "",
            &["SDE \"k1\" (spring) has no parameter \"kn\"; its parameters: k, psi"],
        ),
        (
            "[[variable]]\nsdes = \"k1\"\nparameter = \"k\"\nlower = \"-1 N/um\"\n",
            "vars.toml:4:",
            &["outside the physical range"],
        ),
        (
            "[[variable]]\nsdes = \"k1\"\nparameter = \"k\"\ninitial = \"30 N/um\"\nupper = \"25 N/um\"\n",
            "vars.toml:4:",
            &["outside the bounds"],
        ),
        (
            "[[variable]]\nsdes = \"k1\"\nparameter = \"k\"\ninitial = \"3 m\"\n",
            "",
            &["initial", "stiffness"],
        ),
        (
            "[[variable]]\nsdes = \"k1\"\nparameter = \"k\"\n[[variable]]\nsdes = [\"k2\", \"k1\"]\nparameter = \"k\"\n",
            "vars.toml:5:",
            &["already set by variable \"k k1\""],
        ),
        (
            "[[variable]]\nsdes = \"k1\"\nparameter = \"k\"\nbogus = 1\n",
            "vars.toml:4:",
            &["unknown field"],
        ),
        (
            "[[variable]]\nsdes = [\"k1\", \"guide 1\"]\nparameter = \"psi\"\n",
            "",
            &["\"guide 1\" (general) has no parameter \"psi\""],
        ),
        (
            "[[variable]]\nsdes = \"k1\"\nparameter = \"k\"\ninitial = 0\n",
            "",
            &["no natural scale"],
        ),
        (
            "[[variable]]\nsdes = \"k1, k2\"\nparameter = \"k\"\n",
            "",
            &["values of these SDEs differ", "give `initial`"],
        ),
        (
            "[[variable]]\nsdes = \"k1, k2\"\nparameter = \"k\"\nratios = [1.0]\ninitial = 1e6\n",
            "",
            &["1 ratios for 2 SDEs"],
        ),
        ("", "", &["no [[variable]]"]),
    ] {
        let e = vars_err(text);
        assert!(e.starts_with(at), "{e}");
        for want in says {
            assert!(e.contains(want), "{e}");
        }
    }
}

#[test]
fn the_fwd32j_variables_file_has_the_papers_twenty_variables() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let m = rfe::modelfile::load(&root.join("configs/models/fwd32j-initial.toml"))
        .unwrap()
        .model;
    let v = variables::load(&root.join("configs/identification/fwd32j.toml"), &m).unwrap();
    assert_eq!(v.len(), 20);
    let by = |n: &str| v.vars.iter().find(|x| x.name == n).unwrap();
    assert_eq!(by("isolator kn").targets.len(), 4);
    assert_eq!(by("screw/actuator psi").targets.len(), 4);
    assert_eq!(by("slideway psi_n").targets.len(), 25);
    assert_eq!(by("kn 2").unit.symbol, "MPa/um");
    assert_eq!(by("kn 2").initial, 0.05e12);
    assert_eq!(by("k 34").initial, 0.5e6);
    assert!(v
        .vars
        .iter()
        .all(|x| x.lower == 0.0 && x.upper.is_infinite()));
    // The initial values are the model's (fwd32j-initial.toml).
    for x in &v.vars {
        for t in &x.targets {
            assert!(
                (m.value(t.param).unwrap() / (t.ratio * x.initial) - 1.0).abs() < 1e-12,
                "{}",
                x.name
            );
        }
    }
}
