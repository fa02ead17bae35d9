//! End-to-end: a variables file with a mass runs through `ident identify`, which prints the mass
//! in kg with its standard error, writes it into the updated model's `[[body]]` table and into the
//! next variables file; a bad mass variable exits 2 naming the file, line and fix. Seeded.

mod common;

use common::{identify_two_mass, p, root, utf8, TWO_MASS};

use identify::synthetic;
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

fn two_mass() -> rfe::Model {
    rfe::modelfile::load(&root().join(TWO_MASS))
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
    let model = rfe::modelfile::load(&out.join("model.toml"))
        .expect("updated model loads")
        .model;
    let m2 = model.bodies[model.body_index("second").expect("second")].mass;
    assert!((m2 - xj).abs() < 1e-6 * xj, "{m2} vs {xj}");
    let next_text = std::fs::read_to_string(&next).expect("next vars");
    assert!(next_text.contains("bodies = [\"second\"]"), "{next_text}");
    let reread = identify::variables::parse(&next_text, "next", &truth)
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

/// The two-mass chain with a 5 kg sensor block off the second body's centre, as a model file.
const SENSOR: &str = "\n[[point_mass]]\nname = \"sensor\"\nbody = \"second\"\npoint = \"80 -40 1030 mm\"\nmass = \"5 kg\"\ninertia = \"2e-3 kg m^2\"\n";

/// The two-mass model file with [`SENSOR`], written into `dir`: its path and text.
fn model_with_sensor(dir: &std::path::Path) -> (std::path::PathBuf, String) {
    let text = std::fs::read_to_string(root().join(TWO_MASS)).expect("model") + SENSOR;
    let path = dir.join("model.toml");
    std::fs::write(&path, &text).expect("write");
    (path, text)
}

#[test]
fn the_python_baseline_reads_mass_point_mass_and_gain_terms_and_reaches_the_same_fit() {
    // ident and bench/python/ident_baseline.py (numpy FRF, scipy least_squares, its own
    // assembly of M with the point mass's parallel-axis block) fit the exported problem: the
    // two springs, the first body's mass, the sensor's mass and the second output's gain.
    let dir = tempfile::tempdir().expect("temp dir");
    let (model_file, model_text) = model_with_sensor(dir.path());
    let truth = rfe::modelfile::parse_toml(&model_text, "model.toml")
        .expect("model with a sensor")
        .model;
    let mut rng = StdRng::seed_from_u64(3);
    let mut d =
        synthetic::amplitude_data(&truth, &synthetic::log_lines(10.0, 120.0, 60), 0.01, || {
            StandardNormal.sample(&mut rng)
        })
        .expect("truth solves");
    // The second sensor reads 7 % high.
    for a in &mut d.characteristics[1].amplitude {
        *a *= 1.07;
    }
    if let Some(v) = &mut d.characteristics[1].variance {
        v.iter_mut().for_each(|x| *x *= 1.07 * 1.07);
    }
    let data = dir.path().join("data.json");
    std::fs::write(&data, serde_json::to_string(&d).expect("json")).expect("write");
    let mut vars = include_str!("../configs/identification/textbook-two-mass.toml").to_string();
    vars.push_str("\n[[variable]]\nbodies = \"first\"\nparameter = \"m\"\ninitial = \"380 kg\"\n");
    vars.push_str(
        "\n[[variable]]\npoint_masses = \"sensor\"\nparameter = \"m\"\ninitial = \"4 kg\"\n",
    );
    vars.push_str("\n[[variable]]\ncharacteristics = \"second u3\"\nparameter = \"gain\"\n");
    let vars_file = dir.path().join("vars.toml");
    std::fs::write(&vars_file, vars).expect("write");
    let problem = dir.path().join("problem.json");
    let base = [
        "identify",
        p(&model_file),
        "--data",
        p(&data),
        "--vars",
        p(&vars_file),
        "--fit",
        "amplitude",
    ];
    let o = common::ident(&[&base[..], &["--export-problem", p(&problem)]].concat());
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
    let o = common::ident(&[&base[..], &["--format", "json"]].concat());
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    // The table is in display units: N/um for the springs, kg, and the gain's "-".
    let si = |r: &serde_json::Value, key: &str| {
        let f = if r["unit"] == "N/um" { 1e6 } else { 1.0 };
        r[key].as_f64().expect("number") * f
    };
    let rows = j["table"].as_array().expect("rows");
    let ident_x: Vec<f64> = rows.iter().map(|r| si(r, "identified")).collect();
    let se: Vec<f64> = rows.iter().map(|r| si(r, "std_error")).collect();
    let probe = std::process::Command::new("python3")
        .args(["-c", "import numpy, scipy"])
        .output();
    assert!(
        probe.is_ok_and(|o| o.status.success()),
        "python3 with numpy and scipy is needed for this cross-check: run `.ci/setup` (installs .ci/requirements.txt)"
    );
    let script = root().join("bench/python/ident_baseline.py");
    let o = std::process::Command::new("python3")
        .args([p(&script), p(&problem), "--repeat", "1"])
        .output()
        .expect("python3 runs");
    assert!(o.status.success(), "{}", utf8(&o.stderr));
    let b: serde_json::Value = serde_json::from_slice(&o.stdout).expect("baseline json");
    assert!(
        b["frf_check_max_rel"].as_f64().expect("number") < 1e-9,
        "{b}"
    );
    assert!(
        b["jacobian_check_max_rel"].as_f64().expect("number") < 1e-5,
        "{b}"
    );
    let x: Vec<f64> = b["x"]
        .as_array()
        .expect("x")
        .iter()
        .map(|v| v.as_f64().expect("number"))
        .collect();
    assert_eq!(x.len(), 5, "{b}");
    for (name, (a, c)) in ["k1", "k2", "m first", "m sensor", "gain"]
        .iter()
        .zip(x.iter().zip(&ident_x))
    {
        assert!(
            (a / c - 1.0).abs() < 1e-4,
            "{name}: scipy {a} vs ident {c}\n{b}\n{j}"
        );
    }
    // And the fit finds the truth within its errors: 400 kg, the sensor's 5 kg, the 7 % gain.
    for (i, truth) in [(2, 400.0), (3, 5.0), (4, 1.07)] {
        assert!(
            (ident_x[i] - truth).abs() < 3.0 * se[i],
            "{} {} ± {} (truth {truth})",
            rows[i]["variable"],
            ident_x[i],
            se[i]
        );
    }
}

#[test]
fn sensitivity_ranks_the_variables_files_masses_point_masses_and_gains() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (model_file, _) = model_with_sensor(dir.path());
    let vars_file = dir.path().join("vars.toml");
    std::fs::write(
        &vars_file,
        "[[variable]]\nbodies = \"first\"\nparameter = \"m\"\n\n[[variable]]\npoint_masses = \"sensor\"\nparameter = \"m\"\n\n[[variable]]\ncharacteristics = \"second u3\"\nparameter = \"gain\"\n",
    )
    .expect("write");
    let sensitivity = |extra: &[&str]| {
        let args = ["sensitivity", p(&model_file), "--from", "10", "--to", "120"];
        common::ident(&[&args[..], extra].concat())
    };
    let run = |extra: &[&str]| {
        let o = sensitivity(&[&["--json"][..], extra].concat());
        assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).expect("json")
    };
    let plain = run(&[]);
    let with = run(&["--vars", p(&vars_file)]);
    let rows = |j: &serde_json::Value| j["params"].as_array().expect("params").clone();
    // The SDE rows stay; three more follow.
    assert_eq!(rows(&with).len(), rows(&plain).len() + 3);
    let find = |key: &str, name: &str| {
        rows(&with)
            .into_iter()
            .find(|r| r[key] == name)
            .unwrap_or_else(|| panic!("no {key} {name} in {with}"))
    };
    let mass = find("body", "first");
    let sensor = find("point_mass", "sensor");
    let gain = find("characteristic", "second u3");
    assert_eq!(
        (mass["unit"].as_str(), mass["value"].as_f64()),
        (Some("kg"), Some(400.0))
    );
    assert_eq!(sensor["value"].as_f64(), Some(5.0));
    // The body mass moves both outputs; a gain moves only its own characteristic, by exactly its
    // level (relative MI 1).
    let rel = |r: &serde_json::Value| -> Vec<f64> {
        r["relative_mi"]
            .as_array()
            .expect("relative_mi")
            .iter()
            .map(|v| v.as_f64().expect("number"))
            .collect()
    };
    assert!(rel(&mass).iter().all(|v| *v > 0.1), "{mass}");
    assert!(rel(&sensor).iter().all(|v| *v > 0.0), "{sensor}");
    assert_eq!(rel(&gain), vec![0.0, 1.0], "{gain}");
    // The text table ranks them with the SDE parameters.
    let out = utf8(&sensitivity(&["--vars", p(&vars_file)]).stdout);
    assert!(
        out.contains("body first m")
            && out.contains("point mass sensor m")
            && out.contains("gain second u3"),
        "{out}"
    );
}
