//! Measured data against a model: declared CSV units, measurement maps, the band and level
//! checks, and the misfit headline. Every bad input names its file, line or item and field.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use identify::measurement_map;
use identify::{self as idn, data, misfit, plausibility, report, variables, Options};
use rfe::channel::{ChannelName, MeasuredChannel};
use rfe::frf::{self, Method};
use rfe::frf_units::FrfUnit;
use rfe::measured::{MeasuredData, Measurement, QuantityName};
use rfe::model::Model;
use rfe::textbook;

fn model() -> Model {
    textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5)
}

/// Exact displacements of both outputs at `f`, scaled by `scale` on output `o_scaled`.
fn exact(m: &Model, f: &[f64], o_scaled: usize, scale: f64) -> MeasuredData {
    let r = frf::response(m, f, &[], Method::Direct).unwrap();
    MeasuredData {
        source: "exact".into(),
        characteristics: (0..2)
            .map(|o| Measurement {
                body: m.bodies[o].name.clone(),
                dof: 2,
                quantity: QuantityName::Displacement,
                freqs_hz: f.to_vec(),
                amplitude: r
                    .output(o)
                    .iter()
                    .map(|z| z.norm() * if o == o_scaled { scale } else { 1.0 })
                    .collect(),
                phase_rad: None,
                variance: None,
                coherence: None,
                averages: None,
                at: None,
                reference: None,
                relative: false,
            })
            .collect(),
    }
}

fn lines() -> Vec<f64> {
    (0..40).map(|i| 10.0 + 50.0 * i as f64 / 39.0).collect()
}

/// A scratch folder of this test process (removed and recreated per test).
fn scratch(test: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("ident-measured-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn write(dir: &std::path::Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn csv_unit_declarations_are_checked_and_never_guessed() {
    let m = model();
    let dir = &scratch("csv");
    let row = "body,dof,freq_hz,amplitude\nfirst,u3,20,1e-3\n";
    // Not a response unit: the line and what is accepted.
    let p = write(dir, "a.csv", &format!("# unit = N/mm\n{row}"));
    let e = data::load_for_model(&p, &m).unwrap_err().to_string();
    assert!(
        e.contains("a.csv:1:") && e.contains("not a receptance"),
        "{e}"
    );
    // A quantity that contradicts the unit.
    let p = write(
        dir,
        "b.csv",
        &format!("# quantity = accelerance, unit = mm/N\n{row}"),
    );
    let e = data::load_for_model(&p, &m).unwrap_err().to_string();
    assert!(e.contains("b.csv:1:") && e.contains("receptance"), "{e}");
    // A quantity column that contradicts the unit.
    let p = write(
        dir,
        "c.csv",
        "# unit = g/N\nbody,dof,quantity,freq_hz,amplitude\nfirst,u3,velocity,20,1\n",
    );
    let e = data::load_for_model(&p, &m).unwrap_err().to_string();
    assert!(
        e.contains("c.csv:1:") && e.contains("quantity column says velocity"),
        "{e}"
    );
    // The model-free reader refuses a declared unit rather than read it as SI.
    let e = data::parse_csv(&format!("# unit = mm/N\n{row}"), "d.csv")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("d.csv:1:") && e.contains("load_for_model"),
        "{e}"
    );
    // NaN lines name their line and column.
    let e = data::parse_csv(
        "body,dof,freq_hz,amplitude\nfirst,u3,20,1e-3\nfirst,u3,21,NaN\n",
        "e.csv",
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("e.csv:3:") && e.contains("amplitude") && e.contains("not a finite number"),
        "{e}"
    );
    // Duplicated frequencies name both lines.
    let e = data::parse_csv(
        "body,dof,freq_hz,amplitude\nfirst,u3,20,1e-3\nfirst,u3,20,2e-3\n",
        "f.csv",
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("f.csv:3:") && e.contains("repeats line 2"),
        "{e}"
    );
    // Without a declaration the data stay SI, and the notes say so.
    let p = write(dir, "g.csv", row);
    let d = data::load_for_model(&p, &m).unwrap();
    assert!(d.source.contains("none declared"), "{}", d.source);
    assert_eq!(d.characteristics[0].amplitude, vec![1e-3]);
    // Declared: µm per kN to the model's 1 N excitation is 1e-9 m per N.
    let p = write(dir, "h.csv", &format!("# unit = um/kN\n{row}"));
    let d = data::load_for_model(&p, &m).unwrap();
    assert!((d.characteristics[0].amplitude[0] - 1e-12).abs() < 1e-27);
    assert!(
        d.source.contains("receptance in um/kN converted to m/N"),
        "{}",
        d.source
    );
}

#[test]
fn the_quantity_follows_the_model_output_by_powers_of_j_omega() {
    let m = model();
    let dir = &scratch("acc");
    let p = write(
        dir,
        "acc.csv",
        "# unit = (m/s^2)/N\nbody,dof,freq_hz,amplitude,phase_rad\nsecond,u3,10,2,0.5\n",
    );
    let d = data::load_for_model(&p, &m).unwrap();
    let c = &d.characteristics[0];
    let w = 2.0 * std::f64::consts::PI * 10.0;
    assert_eq!(c.quantity, QuantityName::Displacement);
    assert!((c.amplitude[0] - 2.0 / (w * w)).abs() < 1e-15);
    // Dividing by (jω)² = −ω² turns the phase by π.
    let want = 0.5 - std::f64::consts::PI;
    assert!((c.phase_rad.as_ref().unwrap()[0] - want).abs() < 1e-12);
    assert!(
        d.source
            .contains("acceleration converted to the model's displacement output by (jω)^-2"),
        "{}",
        d.source
    );
}

fn channel(node: i64, dir: i64, unit: &str) -> MeasuredChannel {
    MeasuredChannel {
        name: ChannelName::Node { node, dir },
        item: format!("dataset {node} (line {})", 10 * node),
        reference: Some((9, 3)),
        unit: FrfUnit::parse(unit).map_err(|e| rfe::channel::NoUsableUnit(e.to_string())),
        unit_source: "records 9-10".into(),
        freqs_hz: vec![10.0, 20.0, 30.0],
        amplitude: vec![1.0, 2.0, 3.0],
        phase_rad: Some(vec![0.1, 0.2, 0.3]),
        coherence: None,
    }
}

#[test]
fn map_errors_name_the_file_line_and_field() {
    let m = model();
    let parse = |t: &str| {
        measurement_map::parse(t, "map.toml", &m)
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };
    let e = parse("[[channel]]\nnode = 1\ndir = \"+Z\"\nbody = \"tabel\"\n");
    assert!(
        e.starts_with("map.toml:4:8: body: the model has no body \"tabel\"")
            && e.contains("first, second"),
        "{e}"
    );
    let e = parse("[[channel]]\nnode = 1\ndir = \"+Q\"\nbody = \"first\"\n");
    assert!(e.starts_with("map.toml:3:7: dir:"), "{e}");
    // A channel declared as a principal-axis DOF keeps the 1° rule against its UFF direction.
    let e = parse("[[channel]]\nnode = 1\ndir = \"+X\"\nbody = \"first\"\ndof = \"u3\"\n");
    assert!(
        e.starts_with("map.toml:3:7: dir: +X is 90.00° from u3 of body \"first\""),
        "{e}"
    );
    // ... and takes no point; a zero direction has none.
    let e =
        parse("[[channel]]\nsensor = \"a\"\nbody = \"first\"\ndof = \"u3\"\npoint = [0.1, 0, 0]\n");
    assert!(
        e.starts_with("map.toml:5:9:") && e.contains("`point` goes with a direction"),
        "{e}"
    );
    let e = parse("[[channel]]\nsensor = \"a\"\nbody = \"first\"\ndirection = [0, 0, 0]\n");
    assert!(
        e.starts_with("map.toml:4:13: direction: the zero vector"),
        "{e}"
    );
    // 5° off a principal axis, or 100 mm off the centre line: point outputs, accepted.
    for ok in [
        "[[channel]]\nsensor = \"a\"\nbody = \"first\"\ndirection = [0.0872, 0, 0.9962]\n",
        "[[channel]]\nnode = 1\ndir = 3\nbody = \"first\"\npoint = \"100 0 0 mm\"\n",
        "[[channel]]\nsensor = \"a\"\nbody = \"first\"\ndirection = [0.0087, 0, 1]\n",
    ] {
        assert!(measurement_map::parse(ok, "map.toml", &m).is_ok(), "{ok}");
    }
    // Two channels on one DOF, unknown keys.
    let e = parse("[[channel]]\nnode = 1\ndir = 3\nbody = \"first\"\n[[channel]]\nnode = 2\ndir = 3\nbody = \"first\"\n");
    assert!(
        e.starts_with("map.toml:8:") && e.contains("already measured by node 1 +Z (line 4)"),
        "{e}"
    );
    let e = parse("[[channel]]\nnode = 1\ndir = 3\nbody = \"first\"\nbodyy = 2\n");
    assert!(
        e.starts_with("map.toml:5:") && e.contains("unknown field"),
        "{e}"
    );
}

#[test]
fn a_map_applies_signs_units_and_references() {
    let m = model();
    let map = measurement_map::parse(
        "[[channel]]\nnode = 1\ndir = \"-Z\"\nbody = \"first\"\n[[channel]]\nnode = 2\ndir = \"+Z\"\nbody = \"second\"\nunit = \"mm/N\"\n",
        "map.toml",
        &m,
    )
    .unwrap();
    let chans = vec![
        channel(1, -3, "m/N"),
        channel(2, 3, "m/N"),
        channel(3, 1, "m/N"),
    ];
    let d = map.apply(&chans, "run.uff", &m).unwrap();
    // -Z against the body's +u3: the phase turns by π; the map's mm/N overrides the file's m/N.
    let p = d.characteristics[0].phase_rad.as_ref().unwrap();
    assert!((p[0] - (0.1 - std::f64::consts::PI)).abs() < 1e-12, "{p:?}");
    assert_eq!(d.characteristics[1].amplitude, vec![1e-3, 2e-3, 3e-3]);
    assert!(
        d.source.contains("node 3 +X (dataset 3 (line 30))") && d.source.contains("not used"),
        "{}",
        d.source
    );
    // Two references and no choice: an error listing them; the choice resolves it.
    let mut other = channel(1, -3, "m/N");
    other.reference = Some((8, 1));
    let two = vec![channel(1, -3, "m/N"), channel(2, 3, "m/N"), other];
    let e = map.apply(&two, "run.uff", &m).unwrap_err().to_string();
    assert!(e.contains("2 references (node 8 +X, node 9 +Z)"), "{e}");
    let chosen = measurement_map::parse(
        "[reference]\nnode = 9\ndir = \"Z\"\n[[channel]]\nnode = 1\ndir = \"-Z\"\nbody = \"first\"\n",
        "map.toml",
        &m,
    )
    .unwrap();
    assert_eq!(
        chosen
            .apply(&two, "run.uff", &m)
            .unwrap()
            .characteristics
            .len(),
        1
    );
    // Unsorted and NaN lines name the dataset and the line of the function.
    let mut bad = channel(1, -3, "m/N");
    bad.freqs_hz = vec![10.0, 30.0, 20.0];
    let e = chosen.apply(&[bad], "run.uff", &m).unwrap_err().to_string();
    assert!(
        e.contains("run.uff: dataset 1 (line 10), line 2 of the function (20 Hz)")
            && e.contains("below the previous"),
        "{e}"
    );
    let mut bad = channel(1, -3, "m/N");
    bad.freqs_hz = vec![10.0, 20.0, 20.0];
    let e = chosen.apply(&[bad], "run.uff", &m).unwrap_err().to_string();
    assert!(
        e.contains("run.uff: dataset 1 (line 10), line 2 of the function (20 Hz)")
            && e.contains("repeats the previous"),
        "{e}"
    );
    let mut bad = channel(1, -3, "m/N");
    bad.amplitude[1] = f64::NAN;
    let e = chosen.apply(&[bad], "run.uff", &m).unwrap_err().to_string();
    assert!(
        e.contains("line 1 of the function") && e.contains("NaN"),
        "{e}"
    );
}

#[test]
fn bands_that_do_not_overlap_are_an_error_and_levels_off_by_g_are_named() {
    let m = model();
    // Frequencies written in kHz under freq_hz: 0.01-0.06 "Hz".
    let khz: Vec<f64> = lines().iter().map(|f| f / 1000.0).collect();
    let obs = data::validate(&exact(&m, &khz, 0, 1.0), &m, "khz.csv").unwrap();
    let e = plausibility::check_band(&m, &obs).unwrap_err().to_string();
    assert!(
        e.starts_with("khz.csv: frequencies:") && e.contains("kHz"),
        "{e}"
    );
    let obs = data::validate(&exact(&m, &lines(), 0, 1.0), &m, "ok.csv").unwrap();
    assert!(plausibility::check_band(&m, &obs).is_ok());
    let levels = plausibility::check_level(&m, &obs);
    assert!(
        levels
            .iter()
            .all(|l| l.warning.is_none() && l.median_log10.abs() < 1e-9),
        "{levels:?}"
    );
    // One output 9.81x too high: g taken as m/s².
    let obs = data::validate(&exact(&m, &lines(), 1, 9.80665), &m, "g.csv").unwrap();
    let levels = plausibility::check_level(&m, &obs);
    assert!(levels[0].warning.is_none());
    let w = levels[1].warning.as_deref().unwrap();
    assert!(
        w.starts_with("second u3 displacement")
            && w.contains("9.81x")
            && w.contains("g read as m/s²"),
        "{w}"
    );
    let obs = data::validate(&exact(&m, &lines(), 0, 1e-3), &m, "mm.csv").unwrap();
    let w = plausibility::check_level(&m, &obs)[0]
        .warning
        .clone()
        .unwrap();
    assert!(w.contains("m read as mm"), "{w}");
}

/// k1 and k2 of the two-mass chain started at 14 and 7 N/µm, and their common ψ at 0.3.
const VARS: &str = include_str!("../../configs/identification/textbook-two-mass-psi.toml");

#[test]
fn a_fit_the_model_cannot_explain_says_so_in_its_headline() {
    let m = model();
    let vars = variables::parse(VARS, "vars.toml", &m).unwrap();
    // Frequencies in kHz-like disguise: the data of a band 3x higher fitted as if at these lines.
    let f = lines();
    let mut d = exact(&m, &f.iter().map(|x| x * 3.0).collect::<Vec<_>>(), 0, 1.0);
    for c in &mut d.characteristics {
        c.freqs_hz = f.clone();
    }
    let obs = data::validate(&d, &m, "wrong.csv").unwrap();
    let id = idn::identify(&m, &obs, &vars, &Options::default(), &mut |_, _| {}).unwrap();
    let v = misfit::misfit(&id).unwrap();
    assert!(v.reduced_chi2 > 3.0 && v.p_value < 1e-6, "{v:?}");
    let text = report::text(&id);
    assert!(
        text.starts_with("THE MODEL DOES NOT EXPLAIN THE DATA"),
        "{text}"
    );
    assert!(
        text.lines().next().unwrap().contains("NOT to be trusted") && text.contains("units"),
        "{text}"
    );
    let json = serde_json::to_value(report::json(&id)).unwrap();
    assert!(json["misfit"]["message"]
        .as_str()
        .unwrap()
        .contains("does not explain".to_uppercase().as_str()));
    // Data the model explains (exact): no verdict, and the JSON says null.
    let obs = data::validate(&exact(&m, &f, 0, 1.0), &m, "ok.csv").unwrap();
    let id = idn::identify(&m, &obs, &vars, &Options::default(), &mut |_, _| {}).unwrap();
    assert!(misfit::misfit(&id).is_none());
    assert!(!report::text(&id).contains("DOES NOT EXPLAIN"));
    assert!(serde_json::to_value(report::json(&id)).unwrap()["misfit"].is_null());
}

#[test]
fn the_mass_line_names_a_unit_error_that_misplaced_resonances_hide_from_the_band_level() {
    // The structure's stiffnesses are 2.5x and 0.4x the model's, so its resonances sit far
    // from the model's and the level over the band says nothing clear; its second output is
    // in g read as m/s² (9.81x). Above every resonance both follow the mass line, which the
    // model's masses fix: there the factor shows.
    let m = model();
    let truth = textbook::two_in_series(400.0, 120.0, 5.0e7, 2.0e6, 0.5);
    let f: Vec<f64> = (0..120).map(|i| 2.0 * 1.04f64.powi(i)).collect();
    let obs = data::validate(&exact(&truth, &f, 1, 9.80665), &m, "g.csv").unwrap();
    let levels = plausibility::check_level(&m, &obs);
    let w = levels[1].warning.clone().unwrap_or_default();
    assert!(
        w.contains("above the model's resonances (the mass line)") && w.contains("g read as m/s²"),
        "{w}"
    );
    assert!(
        (levels[1].median_log10 - 9.80665f64.log10()).abs() > 0.12,
        "the band level alone would not have named g: {}",
        levels[1].median_log10
    );
    // The unscaled output: no unit warning.
    let w0 = levels[0].warning.clone().unwrap_or_default();
    assert!(!w0.contains("looks like"), "{w0}");
}

#[test]
fn a_sensor_off_the_principal_axis_lines_maps_to_a_point_output() {
    let m = model();
    let map = measurement_map::parse(
        "[[channel]]\nnode = 1\ndir = \"-Z\"\nbody = \"first\"\npoint = \"100 0 0 mm\"\n\
         [[channel]]\nsensor = \"tilted\"\nbody = \"second\"\ndirection = [0, 3, 4]\n\
         [[channel]]\nnode = 2\ndir = \"+Z\"\nbody = \"second\"\n",
        "map.toml",
        &m,
    )
    .unwrap();
    let mut tilted = channel(7, 3, "m/N");
    tilted.name = ChannelName::Sensor("tilted".into());
    let chans = vec![channel(1, -3, "m/N"), tilted, channel(2, 3, "m/N")];
    let d = map.apply(&chans, "run.uff", &m).unwrap();
    let [first, second, axis] = &d.characteristics[..] else {
        panic!("{:?}", d.characteristics)
    };
    // Off the centre line: a point output whose direction carries the sign, phase untouched.
    let at = first.at.unwrap();
    assert_eq!(at.point, [0.1, 0.0, 0.0]);
    assert_eq!(at.direction, [0.0, 0.0, -1.0]);
    assert_eq!(first.phase_rad.as_ref().unwrap()[0], 0.1);
    // Oblique at the centre of mass: a point output there.
    let at = second.at.unwrap();
    assert_eq!(at.point, <[f64; 3]>::from(m.bodies[1].position));
    assert!((at.direction[1] - 0.6).abs() < 1e-15 && (at.direction[2] - 0.8).abs() < 1e-15);
    assert_eq!(second.dof, 2, "nearest principal axis u3");
    // On the axis: the principal-axis DOF, as before.
    assert_eq!((axis.at, axis.dof), (None, 2));
    // The model gains the two point outputs and the data validate against it.
    let with = data::with_measured_outputs(&m, &d);
    assert_eq!(with.outputs.len(), m.outputs.len() + 2);
    let obs = data::validate(&d, &with, "run.uff").unwrap();
    assert_eq!(obs.characteristics.len(), 3);
    assert!(obs.characteristics[0]
        .label
        .contains("at (100, 0, 0) mm along (0, 0, -1)"));
    // Without them, the data do not validate: the outputs are not the model's.
    let e = data::validate(&d, &m, "run.uff").unwrap_err().to_string();
    assert!(e.contains("not among the model's outputs"), "{e}");
}
