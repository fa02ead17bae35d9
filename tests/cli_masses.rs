//! End-to-end: a variables file with a mass runs through `ident identify`, which prints the mass
//! in kg with its standard error, writes it into the updated model's `[[body]]` table and into the
//! next variables file; a bad mass variable exits 2 naming the file, line and fix. Seeded.

mod common;

use common::{identify_two_mass, p, root, utf8, TWO_MASS};

use identify::identification::synthetic;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// Truth of the second body's mass (the model file's value).
const M2: f64 = 120.0;

/// The two springs of `configs/identification/textbook-two-mass.toml` and the second body's
/// mass, started 1/6 low.
fn vars() -> String {
    let mut s = include_str!("../configs/identification/textbook-two-mass.toml").to_string();
    s.push_str("\n[[variable]]\nbodies = \"second\"\nparameter = \"m\"\ninitial = \"100 kg\"\n");
    s
}

fn two_mass() -> identify::Model {
    identify::modelfile::load(&root().join(TWO_MASS))
        .expect("two-mass model")
        .model
}

/// 1 % noise on both outputs over 10-120 Hz: both resonances (26, 44 Hz) and the mass line above
/// them, written to `dir/data.json`.
fn write_data(dir: &std::path::Path) -> std::path::PathBuf {
    let mut rng = StdRng::seed_from_u64(7);
    let d = synthetic::amplitude_data(
        &two_mass(),
        &synthetic::log_lines(10.0, 120.0, 60),
        0.01,
        || StandardNormal.sample(&mut rng),
    )
    .expect("truth solves");
    let data = dir.join("data.json");
    std::fs::write(&data, serde_json::to_string(&d).expect("json")).expect("write");
    data
}

#[test]
fn a_mass_variable_is_identified_and_printed_in_kg_with_its_error() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truth = two_mass();
    let data = write_data(dir.path());
    let vars_file = dir.path().join("vars.toml");
    std::fs::write(&vars_file, vars()).expect("write");
    let out = dir.path().join("out");
    let next = dir.path().join("next-vars.toml");
    let o = identify_two_mass(
        &data,
        &vars_file,
        &["--out", p(&out), "--write-vars", p(&next)],
        &[],
    );
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
    let text = utf8(&o.stdout);
    let row = text
        .lines()
        .find(|l| l.starts_with("m second"))
        .unwrap_or_else(|| panic!("no mass row in\n{text}"));
    let cells: Vec<&str> = row.split_whitespace().collect();
    // variable (2 words), sdes ("body second"), unit, initial, identified, std error, sigma/x
    assert_eq!(cells[4], "kg", "{row}");
    assert_eq!(cells[5].parse::<f64>().ok(), Some(100.0), "{row}");
    let (x, se): (f64, f64) = (cells[6].parse().expect(row), cells[7].parse().expect(row));
    assert!(se > 0.0 && se < 5.0, "{row}");
    assert!((x - M2).abs() <= 3.0 * se, "{row}: truth {M2} kg");

    // table.json says the same in kg.
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table.json")).expect("table"))
            .expect("json");
    let mass = j["table"]
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| r["variable"] == "m second")
        .expect("mass row");
    assert_eq!(mass["unit"], "kg");
    assert_eq!(mass["sdes"], "body second");
    let xj = mass["identified"].as_f64().expect("number");
    assert!((xj - x).abs() < 1e-3, "{mass}");

    // The updated model carries the fitted mass; the next variables file starts there.
    let model = identify::modelfile::load(&out.join("model.toml"))
        .expect("updated model loads")
        .model;
    let m2 = model.bodies[model.body_index("second").expect("second")].mass;
    assert!((m2 - xj).abs() < 1e-6 * xj, "{m2} vs {xj}");
    let next_text = std::fs::read_to_string(&next).expect("next vars");
    assert!(next_text.contains("bodies = [\"second\"]"), "{next_text}");
    let reread = identify::identification::variables::parse(&next_text, "next", &truth)
        .expect("the next variables file loads");
    let v = reread
        .vars
        .iter()
        .find(|v| v.parameter == "m")
        .expect("mass variable");
    assert!((v.initial - xj).abs() < 1e-6 * xj, "{}", v.initial);
}

#[test]
fn a_bad_mass_variable_exits_2_naming_the_file_line_and_fix() {
    let dir = tempfile::tempdir().expect("temp dir");
    let vars_file = dir.path().join("vars.toml");
    std::fs::write(
        &vars_file,
        "[[variable]]\nbodies = \"second\"\nparameter = \"m\"\nlower = \"0 kg\"\n",
    )
    .expect("write");
    let data = write_data(dir.path());
    let o = identify_two_mass(&data, &vars_file, &[], &[]);
    assert_eq!(o.status.code(), Some(2));
    let err = utf8(&o.stderr);
    assert!(err.contains("vars.toml:4"), "{err}");
    assert!(err.contains("give lower > 0"), "{err}");
}
