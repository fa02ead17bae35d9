//! End-to-end tests of `ident identify`: synthetic data written to files, the binary run on them,
//! the table (text, JSON, CSV) and the updated model (TOML, resolved JSON) checked against the
//! truth, exit codes (0 converged, 1 iteration limit with the best point kept, 2 bad input naming
//! the file and item), progress lines, the weak-direction threshold and the problem export.

mod common;

use std::path::PathBuf;
use std::process::Output;

use common::{ident, identify_two_mass, p, root, utf8, TWO_MASS};

use identify::{data, synthetic};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rfe::measured::MeasuredData;

/// Truth of the two-mass chain: k1 = 20 N/µm, k2 = 5 N/µm (the model file's values).
const K1: f64 = 2.0e7;
const K2: f64 = 5.0e6;

/// k1 and k2 of the two-mass chain started at 14 and 7 N/µm.
const TWO_MASS_VARS: &str = include_str!("../configs/identification/textbook-two-mass.toml");

/// 1 % noise on both outputs of the two-mass chain, 40 lines over 10-60 Hz, seeded.
fn two_mass_data(seed: u64) -> MeasuredData {
    let truth = rfe::modelfile::load(&root().join(TWO_MASS))
        .expect("two-mass model")
        .model;
    let mut rng = StdRng::seed_from_u64(seed);
    synthetic::amplitude_data(&truth, &synthetic::log_lines(10.0, 60.0, 40), 0.01, || {
        StandardNormal.sample(&mut rng)
    })
    .expect("truth solves")
}

struct Case {
    dir: tempfile::TempDir,
}

impl Case {
    fn new() -> Case {
        Case {
            dir: tempfile::tempdir().expect("temp dir"),
        }
    }
    fn file(&self, name: &str, content: &str) -> PathBuf {
        let f = self.dir.path().join(name);
        std::fs::write(&f, content).expect("write");
        f
    }
    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
    /// A case with the two-mass chain's seeded data (`data.json`) and variables (`vars.toml`).
    fn two_mass(seed: u64) -> Case {
        let c = Case::new();
        c.file("data.json", &json_data(&two_mass_data(seed)));
        c.file("vars.toml", TWO_MASS_VARS);
        c
    }
    /// `ident identify` of the two-mass model on this case's `data` and `vars.toml`, then `extra`.
    fn identify(&self, data: &str, extra: &[&str], env: &[(&str, &str)]) -> Output {
        identify_two_mass(&self.path(data), &self.path("vars.toml"), extra, env)
    }
}

fn json_data(d: &MeasuredData) -> String {
    serde_json::to_string(d).expect("data serialize")
}

#[test]
fn a_converged_fit_reports_the_table_and_writes_the_updated_model() {
    let c = Case::two_mass(3);
    let out_dir = c.path("out");

    // Text on stdout, files in --out.
    let o = c.identify("data.json", &["--out", p(&out_dir)], &[]);
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
    let report = utf8(&o.stdout);
    assert!(
        report.contains("k k1") && report.contains("k k2") && report.contains("N/um"),
        "{report}"
    );
    assert!(report.contains("converged"), "{report}");
    assert!(
        o.stderr.is_empty(),
        "no progress lines without --progress or -v: {}",
        utf8(&o.stderr)
    );

    // report.json and report.html: the identify workflow's report with the dense model curves.
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("report.json")).unwrap())
            .unwrap();
    assert_eq!(r["source"]["workflow"], "identify");
    assert!(r["diagnosis"].is_null());
    let chars = r["characteristics"].as_array().unwrap();
    assert_eq!(chars.len(), 2);
    for ch in chars {
        let identified = ch["stages"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["stage"] == "identified")
            .unwrap();
        let dense = identified["dense"]["freqs_hz"].as_array().unwrap();
        assert!(dense.len() >= 400, "{}", dense.len());
        assert_eq!(
            dense[0], ch["freqs_hz"][0],
            "the curve starts at the first line"
        );
    }
    let html = std::fs::read_to_string(out_dir.join("report.html")).unwrap();
    assert_eq!(html.matches("data-chart=\"amplitude\"").count(), 2);
    assert!(html.contains("model, identified") && !html.contains("<script"));

    // table.json: the estimates within 3 standard errors of the truth, J decreased.
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("table.json")).unwrap())
            .unwrap();
    assert_eq!(j["converged"], true);
    assert!(j["criterion"].as_f64().unwrap() < j["criterion_initial"].as_f64().unwrap());
    let rows = j["table"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    let mut identified = Vec::new();
    for (row, truth) in rows.iter().zip([K1, K2]) {
        assert_eq!(row["unit"], "N/um");
        let x = row["identified"].as_f64().unwrap() * 1e6;
        let se = row["std_error"].as_f64().unwrap() * 1e6;
        assert!(
            se > 0.0 && (x - truth).abs() <= 3.0 * se,
            "{row}: truth {truth}"
        );
        identified.push(x);
    }
    // --format json on stdout is the same report.
    let o = c.identify("data.json", &["--format", "json"], &[]);
    assert_eq!(o.status.code(), Some(0));
    let j2: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j2["table"], j["table"]);

    // table.csv and --format csv: a header and one row per variable, the same numbers.
    let csv = std::fs::read_to_string(out_dir.join("table.csv")).unwrap();
    let o = c.identify("data.json", &["--format", "csv"], &[]);
    assert_eq!(o.status.code(), Some(0));
    assert_eq!(utf8(&o.stdout), csv);
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(
        lines[0],
        "variable,sdes,parameter,unit,initial,identified,std_error,variability,at_bound"
    );
    assert_eq!(lines.len(), 3);
    for (line, x) in lines[1..].iter().zip(&identified) {
        let v: f64 = line.split(',').nth(5).unwrap().parse().unwrap();
        assert!((v * 1e6 - x).abs() <= 1e-9 * x, "{line}");
    }
    assert!(std::fs::read_to_string(out_dir.join("report.txt"))
        .unwrap()
        .contains("k k1"));

    // The updated model: TOML (comments kept) and resolved JSON load, with the estimates in.
    let toml = std::fs::read_to_string(out_dir.join("model.toml")).unwrap();
    assert!(
        toml.contains("# Textbook case: two masses in series"),
        "comments kept"
    );
    let back = rfe::modelfile::parse_toml(&toml, "model.toml")
        .unwrap()
        .model;
    let json = rfe::modelfile::load(&out_dir.join("model.json"))
        .unwrap()
        .model;
    for (name, x) in ["k1", "k2"].iter().zip(&identified) {
        for m in [&back, &json] {
            let s = m.sdes.iter().find(|s| s.name == *name).unwrap();
            let k = s.law.stiffness()[0];
            assert!((k - x).abs() <= 1e-9 * x, "{name}: {k} vs {x}");
        }
    }
    // `ident model check` accepts the written model.
    let o = ident(&["model", "check", p(&out_dir.join("model.toml"))]);
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
}

#[test]
fn the_fwd32j_problem_is_identified_from_the_papers_initial_values() {
    let c = Case::new();
    let truth = rfe::modelfile::load(&root().join("configs/models/fwd32j.toml"))
        .unwrap()
        .model;
    let mut rng = StdRng::seed_from_u64(32);
    let d = synthetic::amplitude_data(&truth, &synthetic::fwd32j_lines(), 0.01, || {
        StandardNormal.sample(&mut rng)
    })
    .unwrap();
    // CSV this time (data::to_csv, the documented format).
    let data = c.file("fwd32j.csv", &data::to_csv(&d));
    let model = root().join("configs/models/fwd32j-initial.toml");
    let vars = root().join("configs/identification/fwd32j.toml");
    let out_dir = c.path("out");
    let o = ident(&[
        "identify",
        p(&model),
        "--data",
        p(&data),
        "--vars",
        p(&vars),
        "--out",
        p(&out_dir),
        "--progress",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("table.json")).unwrap())
            .unwrap();
    // One plain progress line per iteration.
    let iterations = j["iterations"].as_u64().unwrap() as usize;
    let progress = utf8(&o.stderr)
        .lines()
        .filter(|l| l.starts_with("iteration "))
        .count();
    assert_eq!(progress, iterations, "{}", utf8(&o.stderr));
    let rows = j["table"].as_array().unwrap();
    assert_eq!(rows.len(), 20);
    let kn6 = rows.iter().find(|r| r["sdes"] == "6").unwrap();
    assert_eq!(
        kn6["identified"].as_f64(),
        Some(0.0),
        "SDE 6 ends at its bound: {kn6}"
    );
    assert_eq!(kn6["at_bound"], "lower");
    // The TOML write-back keeps the paper's units.
    let toml = std::fs::read_to_string(out_dir.join("model.toml")).unwrap();
    assert!(
        toml.contains("MPa/um\""),
        "contact stiffness keeps its unit"
    );
    let back = rfe::modelfile::parse_toml(&toml, "model.toml")
        .unwrap()
        .model;
    assert!(rfe::modelfile::load(&out_dir.join("model.json")).is_ok());
    let s6 = back.sdes.iter().find(|s| s.name == "6").unwrap();
    assert_eq!(s6.law.stiffness()[0], 0.0);
}

#[test]
fn the_iteration_limit_exits_1_and_keeps_the_best_point() {
    let c = Case::two_mass(5);
    let out_dir = c.path("out");
    let o = c.identify(
        "data.json",
        &[
            "--max-iterations",
            "1",
            "--format",
            "json",
            "--out",
            p(&out_dir),
        ],
        &[],
    );
    assert_eq!(o.status.code(), Some(1), "{}", utf8(&o.stderr));
    let err = utf8(&o.stderr);
    assert!(
        err.contains("NOT converged")
            && err.contains("iteration limit")
            && err.contains("best point is kept"),
        "{err}"
    );
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["converged"], false);
    assert_eq!(j["iterations"], 1);
    assert!(
        j["criterion"].as_f64().unwrap() < j["criterion_initial"].as_f64().unwrap(),
        "the best point, not the start"
    );
    // The files are still written, with the best point in the model.
    let toml = std::fs::read_to_string(out_dir.join("model.toml")).unwrap();
    let back = rfe::modelfile::parse_toml(&toml, "model.toml")
        .unwrap()
        .model;
    let k1 = back
        .sdes
        .iter()
        .find(|s| s.name == "k1")
        .unwrap()
        .law
        .stiffness()[0];
    let x = j["table"][0]["identified"].as_f64().unwrap() * 1e6;
    assert!(
        (k1 - x).abs() <= 1e-9 * x && (k1 - 1.4e7).abs() > 1.0,
        "k1 {k1}"
    );
}

/// Runs `ident identify` on the two-mass model with `vars` and `data` (file names decide the
/// format) and returns stderr, asserting exit status 2.
fn bad_input(vars: &str, data_name: &str, data: &str) -> (String, Case) {
    let c = Case::new();
    c.file(data_name, data);
    c.file("vars.toml", vars);
    let o = c.identify(data_name, &[], &[]);
    let err = utf8(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(o.stdout.is_empty(), "no report on bad input");
    assert!(err.starts_with("error: "), "{err}");
    (err, c)
}

#[test]
fn bad_variables_exit_2_naming_the_file_line_and_item() {
    let good = json_data(&two_mass_data(1));
    let cases: &[(&str, &[&str])] = &[
        ("[[variable]]\nsdes = \"k9\"\nparameter = \"k\"\n", &["vars.toml:2:", "unknown SDE \"k9\"", "k1, k2"]),
        ("[[variable]]\nsdes = \"k1\"\nparameter = \"kk\"\n", &["vars.toml:3:", "unknown parameter \"kk\""]),
        ("[[variable]]\nsdes = \"k1\"\nparameter = \"k\"\nlower = \"-1 N/um\"\n", &["vars.toml:4:", "outside the physical range"]),
        (
            "[[variable]]\nsdes = \"k1\"\nparameter = \"k\"\ninitial = \"30 N/um\"\nupper = \"25 N/um\"\n",
            &["vars.toml:4:", "outside the bounds"],
        ),
    ];
    for (vars, needles) in cases {
        let (err, _c) = bad_input(vars, "data.json", &good);
        for n in *needles {
            assert!(err.contains(n), "expected {n:?} in: {err}");
        }
    }
}

#[test]
fn bad_data_exit_2_naming_the_file_characteristic_and_point() {
    let good = two_mass_data(1);
    // More variables than observations: one point, two variables.
    let mut one = good.clone();
    one.characteristics.truncate(1);
    let c0 = &mut one.characteristics[0];
    c0.freqs_hz.truncate(1);
    c0.amplitude.truncate(1);
    c0.variance.as_mut().unwrap().truncate(1);
    let (err, _c) = bad_input(TWO_MASS_VARS, "data.json", &json_data(&one));
    assert!(err.contains("2 variables but only 1 observations"), "{err}");

    // A negative amplitude (JSON): the characteristic and the point are named.
    let mut neg = good.clone();
    neg.characteristics[1].amplitude[4] = -1e-9;
    let (err, _c) = bad_input(TWO_MASS_VARS, "data.json", &json_data(&neg));
    assert!(
        err.contains("data.json") && err.contains("$.characteristics[1] (second u3 displacement)"),
        "{err}"
    );
    assert!(err.contains("point 4") && err.contains("negative"), "{err}");

    // A characteristic the model does not have.
    let mut other = good.clone();
    other.characteristics[0].dof = 0;
    let (err, _c) = bad_input(TWO_MASS_VARS, "data.json", &json_data(&other));
    assert!(
        err.contains("$.characteristics[0] (first u1 displacement)")
            && err.contains("not among the model's outputs"),
        "{err}"
    );

    // NaN and a repeated frequency (CSV): the line is named.
    let csv = data::to_csv(&good);
    let mut rows: Vec<String> = csv.lines().map(String::from).collect();
    let header = rows.iter().position(|l| !l.starts_with('#')).unwrap();
    let cols: Vec<&str> = rows[header].split(',').collect();
    let amp = cols.iter().position(|c| *c == "amplitude").unwrap();
    let mut nan = rows.clone();
    let mut cells: Vec<String> = nan[header + 3].split(',').map(String::from).collect();
    cells[amp] = "NaN".into();
    nan[header + 3] = cells.join(",");
    let (err, _c) = bad_input(TWO_MASS_VARS, "data.csv", &(nan.join("\n") + "\n"));
    assert!(err.contains("data.csv") && err.contains("NaN"), "{err}");
    let dup = rows[header + 2].clone();
    rows.insert(header + 3, dup);
    let (err, _c) = bad_input(TWO_MASS_VARS, "data.csv", &(rows.join("\n") + "\n"));
    let line = header + 4; // 1-based line of the inserted copy
    assert!(
        err.contains(&format!("data.csv:{line}:"))
            && err.contains(&format!("repeats line {}", line - 1)),
        "{err}"
    );
}

#[test]
fn progress_is_logged_with_verbose_or_ident_log() {
    let c = Case::two_mass(2);
    let quiet = c.identify("data.json", &["--format", "json"], &[]);
    assert_eq!(quiet.status.code(), Some(0));
    let iterations = serde_json::from_slice::<serde_json::Value>(&quiet.stdout).unwrap()
        ["iterations"]
        .as_u64()
        .unwrap() as usize;
    assert!(iterations >= 2);
    let count = |o: &Output| {
        utf8(&o.stderr)
            .lines()
            .filter(|l| l.contains("INFO") && l.contains("gradient="))
            .count()
    };
    let o = c.identify("data.json", &["--format", "json", "-v"], &[]);
    assert_eq!(o.status.code(), Some(0));
    assert_eq!(count(&o), iterations, "{}", utf8(&o.stderr));
    assert!(utf8(&o.stderr).contains("criterion="));
    let o = c.identify("data.json", &["--format", "json"], &[("IDENT_LOG", "info")]);
    assert_eq!(count(&o), iterations, "{}", utf8(&o.stderr));
    assert_eq!(count(&quiet), 0);
}

/// `--timing` prints one line on stderr whose steps add up to no more than the run, with the
/// fit's iterations and evaluations as the report has them; without it, no such line.
#[test]
fn timing_prints_the_steps_with_the_fit_alone() {
    let c = Case::two_mass(2);
    let o = c.identify("data.json", &["--format", "json", "--timing"], &[]);
    assert_eq!(o.status.code(), Some(0));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let err = utf8(&o.stderr);
    let line = err
        .lines()
        .find(|l| l.starts_with("timing: "))
        .unwrap_or_else(|| panic!("no timing line in {err}"));
    let ms = |step: &str| -> f64 {
        let at = line
            .find(step)
            .unwrap_or_else(|| panic!("{step} in {line}"))
            + step.len();
        line[at..]
            .split(" ms")
            .next()
            .unwrap()
            .trim()
            .parse()
            .unwrap()
    };
    let (setup, fit, around, output, run) = (
        ms("set-up "),
        ms(", fit "),
        ms("around it "),
        ms("output "),
        ms("run "),
    );
    assert!(fit >= 0.0 && setup > 0.0, "{line}");
    // Each figure is rounded to 0.01 ms; the run also holds what lies between the steps.
    assert!(setup + fit + around + output <= run + 0.03, "{line}");
    assert!(line.contains(&format!(
        "({} iterations, {} model evaluations in all)",
        report["iterations"], report["model_evaluations"]
    )));
    let quiet = c.identify("data.json", &["--format", "json"], &[]);
    assert!(!utf8(&quiet.stderr).contains("timing: "));
}

#[test]
fn the_weak_direction_threshold_is_a_flag() {
    let c = Case::two_mass(2);
    let weak = |t: &str| {
        let o = c.identify(
            "data.json",
            &["--format", "json", "--weak-threshold", t],
            &[],
        );
        assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()["weak_directions"]
            .as_array()
            .unwrap()
            .len()
    };
    // Both variables are determined to well under 50 %; at a threshold of 1e-9 every direction
    // is "weak".
    assert_eq!(weak("0.5"), 0);
    assert_eq!(weak("1e-9"), 2);
    let o = c.identify("data.json", &["--weak-threshold=-1"], &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        utf8(&o.stderr).contains("--weak-threshold -1"),
        "{}",
        utf8(&o.stderr)
    );
}

#[test]
fn the_problem_export_holds_what_an_external_fit_needs() {
    let c = Case::two_mass(2);
    let out = c.path("problem.json");
    let o = c.identify("data.json", &["--export-problem", p(&out)], &[]);
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
    assert!(o.stdout.is_empty(), "no fit, no report");
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(j["format"], identify::problem::FORMAT);
    assert_eq!(j["fit"], "amplitude");
    assert_eq!(j["lines_hz"].as_array().unwrap().len(), 40);
    let obs = j["observations"].as_array().unwrap();
    assert_eq!(obs.len(), 80);
    let vars = j["variables"].as_array().unwrap();
    assert_eq!(vars[0]["initial"].as_f64(), Some(1.4e7));
    assert_eq!(vars[0]["upper"], serde_json::Value::Null);
    // k1 moves the first SDE's axial stiffness one for one.
    assert_eq!(vars[0]["terms"][0]["sde"], 0);
    assert_eq!(vars[0]["terms"][0]["dk"][0].as_f64(), Some(1.0));
    // The model is at the initial values, and sigma is the stated amplitude σ (1 %).
    assert_eq!(j["model"]["sdes"][0]["k"][0].as_f64(), Some(1.4e7));
    for o in obs {
        let (z, s) = (
            o["amplitude"].as_f64().unwrap(),
            o["sigma"].as_f64().unwrap(),
        );
        assert!(s > 0.0 && (s / z - 0.01).abs() < 0.005, "{o}");
    }
}

#[test]
fn a_missing_file_is_named_once_with_its_cause() {
    let c = Case::new();
    c.file("vars.toml", TWO_MASS_VARS);
    let o = c.identify("nothere.json", &[], &[]);
    assert_eq!(o.status.code(), Some(2));
    let err = utf8(&o.stderr);
    assert!(
        err.contains("nothere.json: cannot read the data file"),
        "{err}"
    );
    assert_eq!(err.matches("os error").count(), 1, "the cause once: {err}");
}
