//! The model as a drawing against the FWD-32J model file: the boxes derived from the bodies'
//! masses and inertias are the boxes the file's notes describe, the actuator the diagnosis would
//! add is marked, the modes in the band are stored with their shapes; and the report page carries
//! the picture and one figure per stored mode, drawn from the report's JSON alone.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::PathBuf;

use report::picture;

fn configs() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/models")
}

/// `(body name, [a, b, c])` of every `note = "... inertia of a A x B x C m box"` in a model file.
fn noted_boxes(text: &str) -> Vec<(String, [f64; 3])> {
    let mut out = Vec::new();
    let mut name = None;
    for line in text.lines() {
        if let Some(n) = line.strip_prefix("name = \"") {
            name = n.strip_suffix('"').map(str::to_string);
        }
        if let Some(i) = line.find("inertia of a ") {
            let sides: Vec<f64> = line[i + "inertia of a ".len()..]
                .split(" m box")
                .next()
                .unwrap()
                .split(" x ")
                .map(|s| s.trim().parse().unwrap())
                .collect();
            out.push((name.clone().unwrap(), [sides[0], sides[1], sides[2]]));
        }
    }
    out
}

#[test]
fn fwd32j_boxes_from_masses_and_inertias_are_the_noted_boxes() {
    let path = configs().join("fwd32j.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let model = rfe::modelfile::load(&path).unwrap().model;
    let p = picture::describe(&model, &model, [10.0, 300.0]).unwrap();
    let noted = noted_boxes(&text);
    assert_eq!(noted.len(), model.bodies.len(), "every body notes its box");
    for (name, sides) in noted {
        let b = p.bodies.iter().find(|b| b.name == name).unwrap();
        assert!(!b.clamped, "{name}");
        let m = b.mass_kg;
        for (axis, side) in sides.iter().enumerate() {
            // The side along global axis `axis` (the file gives no rotations: principal axes are
            // the global ones, which this checks too).
            assert!((b.axes[axis][axis] - 1.0).abs() < 1e-12, "{name} axes");
            let derived = 2.0 * b.half_sizes_m[axis];
            // The file prints inertias to 0.01 kg m² (error ≤ 0.005 each); a² = 6(J2 + J3 − J1)/m
            // then errs by ≤ 6 · 3 · 0.005 / m, the side by that over 2a.
            let tol = 0.045 / (m * side) + 1e-9;
            assert!(
                (derived - side).abs() <= tol,
                "{name}: side {} derived {derived} m, noted {side} m (tolerance {tol} m)",
                axis + 1
            );
        }
    }
}

#[test]
fn the_actuator_a_diagnosis_adds_is_marked_and_the_band_modes_are_stored() {
    let full = rfe::modelfile::load(&configs().join("fwd32j.toml"))
        .unwrap()
        .model;
    let without = rfe::modelfile::load(&configs().join("fwd32j-no-actuator.toml"))
        .unwrap()
        .model;
    let band = [20.0, 200.0];
    let p = picture::describe(&full, &without, band).unwrap();
    let added: Vec<&str> = p
        .sdes
        .iter()
        .filter(|s| s.added)
        .map(|s| s.name.as_str())
        .collect();
    assert_eq!(
        added,
        ["34"],
        "SDE 34 is disabled in the identification model"
    );
    assert!(p.bodies.iter().all(|b| !b.added));
    // The band's modes, as rfe::modes finds them.
    let all = rfe::modes::complex(&full).unwrap();
    let expected: Vec<f64> = all
        .iter()
        .map(|m| m.freq_hz)
        .filter(|f| *f >= band[0] && *f <= band[1])
        .collect();
    assert!(!expected.is_empty());
    assert_eq!(p.modes.len() + p.modes_omitted, expected.len());
    assert_eq!(p.modes.len(), expected.len().min(picture::MAX_MODES));
    for (m, f) in p.modes.iter().zip(&expected) {
        assert_eq!(m.freq_hz, *f);
        assert_eq!(m.shape.len(), full.bodies.len());
        let sum: f64 = m.energy.iter().sum();
        assert!((sum - 1.0).abs() < 1e-9, "energy shares sum to 1: {sum}");
        let most = m
            .energy
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .unwrap()
            .0;
        assert_eq!(m.moves_most, full.bodies[most].name);
        // Normalised: the largest component is 1.
        let largest = m.shape.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
        assert!((largest - 1.0).abs() < 1e-6, "{largest}");
    }
    // The exciter pair and the table's three measured translations.
    assert_eq!(p.exciters.len(), 2);
    assert_eq!(p.outputs.len(), 3);
    // A model the picture was not made from cannot mark anything as added.
    let same = picture::describe(&full, &full, band).unwrap();
    assert!(same.sdes.iter().all(|s| !s.added));
}

#[test]
fn the_page_draws_the_picture_and_one_figure_per_band_mode_from_the_json_alone() {
    let f = common::fixture(7);
    let r = common::full_report(&f, 1.0);
    let p = r.picture.as_ref().expect("a report carries the picture");
    assert!(
        !p.modes.is_empty(),
        "the two-mass fixture has modes in 8-80 Hz"
    );
    assert_eq!(p.band_hz, [8.0, 80.0]);
    // Round trip through JSON: the page needs nothing but the report.
    let back: report::Report = serde_json::from_str(&serde_json::to_string(&r).unwrap()).unwrap();
    let html = report::html::render(&back).unwrap();
    assert!(html.contains("<h2 id=\"model\">"), "the picture section");
    assert_eq!(html.matches("data-chart=\"model\"").count(), 1);
    assert_eq!(
        html.matches("data-chart=\"mode\"").count(),
        p.modes.len(),
        "one figure per stored mode"
    );
    for (i, m) in p.modes.iter().enumerate() {
        let title = format!("Mode {}: {} Hz", i + 1, rfe::display::sig(m.freq_hz, 4));
        assert!(html.contains(&title), "{title}");
    }
    // Every body is labelled in the picture.
    for b in &p.bodies {
        assert!(html.contains(&format!("{}\n</text>", b.name)), "{}", b.name);
    }
    // A report without a picture (written before it existed) still renders, without the section.
    let mut old = serde_json::to_value(&r).unwrap();
    old.as_object_mut().unwrap().remove("picture");
    let old: report::Report = serde_json::from_value(old).unwrap();
    assert!(old.picture.is_none());
    assert!(!report::html::render(&old).unwrap().contains("id=\"model\""));
}
