//! The model files shipped in `configs/models/`: every file loads; the FWD-32J model has the
//! paper's structure (7 bodies, SDEs 1-34, Table 1 values) and plausible dynamics (mass, natural
//! frequencies, finite FRF); the textbook files match the models built in code and their closed
//! forms.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use faer::{Mat, Side};
use rfe::frf::{response, Method};
use rfe::model::{Model, ParamName, ParamRef, SdeKind};
use rfe::modelfile::load;
use rfe::system::System;
use rfe::{textbook, C64};

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

fn models_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/models")
}

fn load_model(file: &str) -> Model {
    let path = models_dir().join(file);
    match load(&path) {
        Ok(l) => l.model,
        Err(e) => panic!("{e}"),
    }
}

/// Undamped natural frequencies (Hz, ascending) from `M^-1/2 K M^-1/2`, with each mode's share of
/// kinetic energy per body.
fn natural_frequencies(model: &Model) -> Vec<(f64, Vec<f64>)> {
    let s = System::assemble(model);
    let n = s.n;
    let w: Vec<f64> = s.mass.iter().map(|m| 1.0 / m.sqrt()).collect();
    let a = Mat::from_fn(n, n, |i, j| w[i] * s.k[i * n + j] * w[j]);
    let eig = a
        .self_adjoint_eigen(Side::Lower)
        .expect("eigen-decomposition of M^-1/2 K M^-1/2");
    let (vals, vecs) = (eig.S().column_vector(), eig.U());
    (0..n)
        .map(|m| {
            let lambda = vals[m];
            // K is positive semi-definite: clip round-off below zero.
            let f = lambda.max(0.0).sqrt() / TWO_PI;
            // In mass-normalised coordinates the kinetic energy share of DOF i is v_i².
            let mut share = vec![0.0; model.bodies.len()];
            for i in 0..n {
                share[i / 6] += vecs[(i, m)] * vecs[(i, m)];
            }
            (f, share)
        })
        .collect()
}

fn print_modes(label: &str, model: &Model, below_hz: f64) -> Vec<f64> {
    let modes = natural_frequencies(model);
    println!("{label}: undamped natural frequencies below {below_hz} Hz");
    let mut out = Vec::new();
    for (f, share) in modes.iter().filter(|(f, _)| *f < below_hz) {
        let mut order: Vec<usize> = (0..share.len()).collect();
        order.sort_by(|a, b| share[*b].total_cmp(&share[*a]));
        let dominant: Vec<String> = order
            .iter()
            .take(3)
            .map(|b| format!("{} {:.2}", model.bodies[*b].name, share[*b]))
            .collect();
        println!("  {f:8.2} Hz   {}", dominant.join(", "));
        out.push(*f);
    }
    out
}

#[test]
fn every_model_file_loads() {
    let mut files: Vec<PathBuf> = std::fs::read_dir(models_dir())
        .expect("configs/models exists")
        .map(|e| e.expect("directory entry").path())
        .filter(|p| {
            matches!(
                p.extension().and_then(|e| e.to_str()),
                Some("toml" | "json")
            )
        })
        .collect();
    files.sort();
    let names: BTreeSet<String> = files
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    for expected in [
        "fwd32j.toml",
        "fwd32j-initial.toml",
        "fwd32j-no-actuator.toml",
        "textbook-two-mass.toml",
        "textbook-single.toml",
    ] {
        assert!(
            names.contains(expected),
            "configs/models/{expected} is missing"
        );
    }
    let mut failures = Vec::new();
    for f in &files {
        match load(f) {
            Ok(l) => {
                for w in &l.warnings {
                    println!("{w}");
                }
                assert!(!l.model.bodies.is_empty(), "{}: no bodies", f.display());
                assert!(!l.model.forces.is_empty(), "{}: no excitation", f.display());
                assert!(!l.model.outputs.is_empty(), "{}: no outputs", f.display());
            }
            Err(e) => failures.push(e.to_string()),
        }
    }
    assert!(
        failures.is_empty(),
        "model files that do not load:\n{}",
        failures.join("\n")
    );
}

const FWD_BODIES: [&str; 7] = [
    "column",
    "overarm",
    "spindle head",
    "knee",
    "lower saddle",
    "upper saddle",
    "table",
];

fn sde<'a>(model: &'a Model, name: &str) -> (usize, &'a rfe::Sde) {
    let i = model
        .sde_index(name)
        .unwrap_or_else(|| panic!("SDE {name} missing"));
    (i, &model.sdes[i])
}

fn param(model: &Model, name: &str, p: ParamName) -> f64 {
    let (i, _) = sde(model, name);
    model
        .param(ParamRef { sde: i, name: p })
        .unwrap_or_else(|| panic!("SDE {name} has no {}", p.as_str()))
}

fn body_pair(model: &Model, name: &str) -> [String; 2] {
    let (_, s) = sde(model, name);
    s.bodies.map(|b| match b {
        Some(b) => model.bodies[b].name.clone(),
        None => "ground".to_string(),
    })
}

#[test]
fn fwd32j_has_the_papers_structure() {
    for file in [
        "fwd32j.toml",
        "fwd32j-initial.toml",
        "fwd32j-no-actuator.toml",
    ] {
        let m = load_model(file);
        let bodies: Vec<&str> = m.bodies.iter().map(|b| b.name.as_str()).collect();
        assert_eq!(bodies.len(), 7, "{file}: bodies {bodies:?}");
        for b in FWD_BODIES {
            assert!(bodies.contains(&b), "{file}: body {b} missing");
        }
        let total: f64 = m.bodies.iter().map(|b| b.mass).sum();
        assert!(
            (2500.0..=3000.0).contains(&total),
            "{file}: total mass {total} kg"
        );
        let column = m.bodies[m.body_index("column").expect("column")].mass;
        assert!(
            m.bodies.iter().all(|b| b.mass <= column),
            "{file}: the column is the heaviest body"
        );
        let table = m.bodies[m.body_index("table").expect("table")].mass;
        assert!((150.0..=600.0).contains(&table), "{file}: table {table} kg");

        let names: BTreeSet<String> = m.sdes.iter().map(|s| s.name.clone()).collect();
        let expected: BTreeSet<String> = (1..=34).map(|i| i.to_string()).collect();
        assert_eq!(names, expected, "{file}: SDE names");
        for s in &m.sdes {
            let n: u32 = s.name.parse().expect("SDE names are the paper's numbers");
            let kind = match n {
                1 | 13 => SdeKind::Rotary,
                12 | 22 | 29 => SdeKind::Screw,
                30..=33 => SdeKind::Isolator,
                34 => SdeKind::Spring,
                _ => SdeKind::Slideway,
            };
            assert_eq!(s.kind, kind, "{file}: SDE {n} kind");
            assert_eq!(
                s.enabled,
                !(n == 34 && file == "fwd32j-no-actuator.toml"),
                "{file}: SDE {n} enabled"
            );
        }
        // The joint groups of Fig. 4b and the bodies they join.
        let joints: [(&[u32], [&str; 2]); 7] = [
            (&[1], ["overarm", "spindle head"]),
            (&[2, 3, 4, 5, 6, 7], ["column", "overarm"]),
            (&[8, 9, 10, 11, 12], ["column", "knee"]),
            (&[13], ["lower saddle", "upper saddle"]),
            (
                &[14, 15, 16, 17, 18, 19, 20, 21, 22],
                ["upper saddle", "table"],
            ),
            (&[23, 24, 25, 26, 27, 28, 29], ["knee", "lower saddle"]),
            (&[30, 31, 32, 33], ["ground", "column"]),
        ];
        for (sdes, pair) in joints {
            for n in sdes {
                assert_eq!(
                    body_pair(&m, &n.to_string()),
                    pair.map(String::from),
                    "{file}: SDE {n}"
                );
            }
        }
        assert_eq!(
            body_pair(&m, "34"),
            ["spindle head".to_string(), "table".to_string()]
        );
        let t = m.body_index("table").expect("table");
        let outs: Vec<(usize, u8)> = m.outputs.iter().map(|c| (c.body, c.dof)).collect();
        assert_eq!(
            outs,
            vec![(t, 0), (t, 1), (t, 2)],
            "{file}: outputs = table u1, u2, u3"
        );
        // 4 kN pair, alpha = 60 deg, beta = 81 deg: equal and opposite, on spindle head and table.
        assert_eq!(m.forces.len(), 2, "{file}: one force pair");
        let (a, b) = (&m.forces[0], &m.forces[1]);
        assert_eq!(a.body, m.body_index("spindle head").expect("spindle head"));
        assert_eq!(b.body, t);
        let (al, be) = (60f64.to_radians(), 81f64.to_radians());
        let d = nalgebra::Vector3::new(be.sin() * al.cos(), be.sin() * al.sin(), be.cos());
        assert!(
            (a.force - 4000.0 * d).norm() < 1e-9 && (a.force + b.force).norm() < 1e-9,
            "{file}: excitation"
        );
        // The pair acts along one line (no net moment).
        assert!(
            (b.point - a.point).cross(&d).norm() < 1e-5,
            "{file}: the pair is not collinear"
        );
    }
}

/// Table 1 of the paper: (SDE, parameter, initial, identified), SI units.
fn table1() -> Vec<(String, ParamName, f64, f64)> {
    let mpa_um = 1e12;
    let n_um = 1e6;
    let mut t: Vec<(String, ParamName, f64, f64)> = [
        ("2", ParamName::Kn, 0.05 * mpa_um, 0.0199 * mpa_um),
        ("3", ParamName::Kn, 0.05 * mpa_um, 0.0073 * mpa_um),
        ("6", ParamName::Kn, 0.1 * mpa_um, 0.0),
        ("7", ParamName::Kn, 0.1 * mpa_um, 0.0128 * mpa_um),
        ("8", ParamName::Kn, 0.05 * mpa_um, 0.0795 * mpa_um),
        ("11", ParamName::Kn, 0.025 * mpa_um, 0.3242 * mpa_um),
        ("17", ParamName::Kn, 0.05 * mpa_um, 0.0294 * mpa_um),
        ("20", ParamName::Kn, 0.05 * mpa_um, 0.1401 * mpa_um),
        ("21", ParamName::Kn, 0.025 * mpa_um, 0.0607 * mpa_um),
        ("23", ParamName::Kn, 0.036 * mpa_um, 0.0397 * mpa_um),
        ("24", ParamName::Kn, 0.036 * mpa_um, 0.0133 * mpa_um),
        ("27", ParamName::Kn, 0.071 * mpa_um, 0.0976 * mpa_um),
        ("28", ParamName::Kn, 0.048 * mpa_um, 0.1093 * mpa_um),
        ("22", ParamName::K, 10.0 * n_um, 9.706 * n_um),
        ("29", ParamName::K, 16.7 * n_um, 8.942 * n_um),
        ("34", ParamName::K, 0.5 * n_um, 0.5639 * n_um),
    ]
    .into_iter()
    .map(|(s, p, a, b)| (s.to_string(), p, a, b))
    .collect();
    for s in ["12", "22", "29", "34"] {
        t.push((s.into(), ParamName::Psi, 0.6, 0.840));
    }
    for s in ["30", "31", "32", "33"] {
        t.push((s.into(), ParamName::Kn, 0.459 * n_um, 0.4941 * n_um));
    }
    // The slideway ψ group: every slideway SDE and rotary joint 13 (docs/fwd32j.md's reading of
    // the paper's footnote; rotary joint 1 is outside it; see the comment atop fwd32j.toml).
    for n in (2..=11).chain(13..=21).chain([23, 24, 25, 26, 27, 28]) {
        t.push((n.to_string(), ParamName::PsiN, 0.8, 1.093));
        t.push((n.to_string(), ParamName::PsiT, 1.6, 1.608));
    }
    t
}

#[test]
fn fwd32j_files_carry_table1_and_differ_only_in_it() {
    let identified = load_model("fwd32j.toml");
    let initial = load_model("fwd32j-initial.toml");
    let no_actuator = load_model("fwd32j-no-actuator.toml");
    let t1 = table1();
    for (s, p, init, ident) in &t1 {
        let (a, b) = (param(&initial, s, *p), param(&identified, s, *p));
        assert!(
            (a - init).abs() <= 1e-9 * init.abs(),
            "initial SDE {s} {}: {a}, Table 1: {init}",
            p.as_str()
        );
        assert!(
            (b - ident).abs() <= 1e-9 * ident.abs(),
            "identified SDE {s} {}: {b}, Table 1: {ident}",
            p.as_str()
        );
    }
    // kn/kt = 2.5 on every contact joint.
    for s in identified
        .sdes
        .iter()
        .filter(|s| matches!(s.kind, SdeKind::Slideway | SdeKind::Rotary))
    {
        let k = s.law.stiffness();
        assert!(
            (k[0] / k[1] - 2.5).abs() < 1e-12 || k[0] == 0.0,
            "SDE {}: kn/kt",
            s.name
        );
    }
    // Same geometry, bodies, excitation and outputs; the same value of every parameter not in
    // Table 1.
    assert_eq!(identified.bodies, initial.bodies);
    assert_eq!(identified.bodies, no_actuator.bodies);
    assert_eq!(identified.forces, initial.forces);
    assert_eq!(identified.forces, no_actuator.forces);
    assert_eq!(identified.outputs, initial.outputs);
    let in_table: BTreeSet<(String, String)> = t1
        .iter()
        .map(|(s, p, _, _)| (s.clone(), p.as_str()))
        .collect();
    for ((a, b), c) in identified
        .sdes
        .iter()
        .zip(&initial.sdes)
        .zip(&no_actuator.sdes)
    {
        assert_eq!(
            (&a.name, a.kind, a.bodies, a.point, a.rotation),
            (&b.name, b.kind, b.bodies, b.point, b.rotation)
        );
        assert_eq!(a.law, c.law, "SDE {}: no-actuator differs", a.name);
        for p in a.law.params() {
            if !in_table.contains(&(a.name.clone(), p.as_str())) {
                assert_eq!(
                    a.law.get(p),
                    b.law.get(p),
                    "SDE {} {}: not in Table 1 but differs",
                    a.name,
                    p.as_str()
                );
            }
        }
    }
}

#[test]
fn fwd32j_dynamics_are_plausible() {
    let freqs: Vec<f64> = (1..=200).map(f64::from).collect();
    for file in [
        "fwd32j.toml",
        "fwd32j-initial.toml",
        "fwd32j-no-actuator.toml",
    ] {
        let m = load_model(file);
        let r = response(&m, &freqs, &[], Method::Direct).unwrap_or_else(|e| panic!("{file}: {e}"));
        for o in 0..3 {
            let q = r.output(o);
            assert!(
                q.iter().all(|x| x.re.is_finite() && x.im.is_finite()),
                "{file}: table u{} not finite",
                o + 1
            );
            assert!(
                q.iter().all(|x| x.norm() > 0.0),
                "{file}: table u{} is zero somewhere",
                o + 1
            );
            // Resonances seen in the table's characteristic: local maxima of |q| in 5-200 Hz.
            let peaks: Vec<f64> = (1..q.len() - 1)
                .filter(|&k| {
                    freqs[k] >= 5.0
                        && q[k].norm() > q[k - 1].norm()
                        && q[k].norm() > q[k + 1].norm()
                })
                .map(|k| freqs[k])
                .collect();
            println!("{file}: table u{} peaks in 5-200 Hz at {peaks:?} Hz", o + 1);
            assert!(
                !peaks.is_empty(),
                "{file}: table u{} has no resonance in 5-200 Hz",
                o + 1
            );
        }
        let f = print_modes(file, &m, 300.0);
        // No free rigid-body motion; six rigid-body modes of the machine on its isolators.
        assert!(f[0] > 0.5, "{file}: lowest natural frequency {} Hz", f[0]);
        let isolator = f.iter().filter(|f| **f < 20.0).count();
        assert_eq!(isolator, 6, "{file}: modes below 20 Hz: {f:?}");
        // Structural (joint) modes: a gap above the isolator modes, several in the measured band.
        assert!(f[6] > 30.0, "{file}: first structural mode at {} Hz", f[6]);
        let band = f.iter().filter(|f| (30.0..=250.0).contains(*f)).count();
        assert!(
            band >= 4,
            "{file}: only {band} structural modes in 30-250 Hz: {f:?}"
        );
    }
}

fn assert_same_system(file: &str, a: &Model, b: &Model) {
    let (sa, sb) = (System::assemble(a), System::assemble(b));
    assert_eq!(sa.n, sb.n);
    assert_eq!(sa.output_rows, sb.output_rows, "{file}: outputs");
    for (what, x, y) in [
        ("M", &sa.mass, &sb.mass),
        ("K", &sa.k, &sb.k),
        ("D", &sa.d, &sb.d),
        ("P", &sa.load, &sb.load),
    ] {
        let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let diff = x
            .iter()
            .zip(y)
            .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
        assert!(
            diff <= 1e-12 * scale,
            "{file}: {what} differs from the code-built model by {diff:e}"
        );
    }
}

#[test]
fn textbook_files_match_the_code_built_models_and_closed_forms() {
    let hyst = |k: f64, psi: f64| C64::new(k, k * psi / TWO_PI);

    let (m1, m2, k1, k2, psi) = (400.0, 120.0, 2.0e7, 5.0e6, 0.5);
    let file = load_model("textbook-two-mass.toml");
    assert_same_system(
        "textbook-two-mass.toml",
        &file,
        &textbook::two_in_series(m1, m2, k1, k2, psi),
    );
    let freqs: Vec<f64> = (1..300).map(|i| 0.37 * f64::from(i)).collect();
    let r = response(&file, &freqs, &[], Method::Direct).expect("FRF of a textbook file");
    for (i, &f) in freqs.iter().enumerate() {
        let w2 = (TWO_PI * f).powi(2);
        let (c1, c2) = (hyst(k1, psi), hyst(k2, psi));
        let a11 = c1 + c2 - w2 * m1;
        let det = a11 * (c2 - w2 * m2) - c2 * c2;
        for (o, exact) in [(0, c2 / det), (1, a11 / det)] {
            let e = (r.output(o)[i] - exact).norm() / exact.norm();
            assert!(e < 1e-10, "two-mass output {o} at {f} Hz: rel err {e:e}");
        }
    }
    // The chain's undamped natural frequencies (quoted in the file) are among the model's.
    let a = (k1 + k2) / m1 + k2 / m2;
    let d = (a * a - 4.0 * k1 * k2 / (m1 * m2)).sqrt();
    let modes = natural_frequencies(&file);
    for w2 in [(a - d) / 2.0, (a + d) / 2.0] {
        let f = w2.sqrt() / TWO_PI;
        assert!(
            modes.iter().any(|(g, _)| (g - f).abs() < 1e-9 * f),
            "two-mass: {f} Hz not found"
        );
    }

    let (m, k, psi) = (250.0, 3.0e6, 0.3);
    let file = load_model("textbook-single.toml");
    assert_same_system(
        "textbook-single.toml",
        &file,
        &textbook::single_body(m, k, psi),
    );
    let r = response(&file, &freqs, &[], Method::Direct).expect("FRF of a textbook file");
    for (i, &f) in freqs.iter().enumerate() {
        let exact = C64::new(1.0, 0.0) / (hyst(k, psi) - (TWO_PI * f).powi(2) * m);
        let e = (r.output(0)[i] - exact).norm() / exact.norm();
        assert!(e < 1e-10, "single body at {f} Hz: rel err {e:e}");
    }
}
