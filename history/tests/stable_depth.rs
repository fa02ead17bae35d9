//! The stable depth as a judged quantity: simulated nights of the 3-block chain (temperature-
//! driven scatter, identified with ident's fit), one joint's stiffness dropping by 30 % from a
//! given night. Each night's identified model gives the minimum critical depth of a turning cut
//! over its speed range (the `stability` crate, as `ident nightly` with `[stability]` does); the
//! history stores it beside the parameters and judges it like them. Asserts: no depth alarm
//! before the drop, the depth alarm within two nights of it, saying the depth fell, from and to
//! what; the depth stays out of Hotelling's T²; the trend page draws it; and the store keeps
//! the quantity.

#![allow(clippy::unwrap_used, clippy::expect_used, dead_code)]

mod common;
use common::nights::{self, Scenario};
use history::judge::{judge_series, BaselineWindow, JudgeConfig};
use history::record::ParameterRecord;

/// A turning cut across the chain's two joints: the tool on the last block, the workpiece on the
/// first, the chip thickness along the chain.
const CUT: &str = r#"
operation = "turning"
speed_rpm = [1500, 6000]
speeds = 60
lines = 1500
[tool]
body = "block 2"
point = [1.2, 0.0, 0.5]
[workpiece]
body = "block 0"
point = [0.0, 0.0, 0.5]
[cutting]
kt = "2000 MPa"
kr = "800 MPa"
[turning]
thickness = [1.0, 0.0, 0.0]
cutting = [0.0, 0.0, 1.0]
"#;

const STEP_NIGHT: usize = 16;

fn stable_depth(estimates: &[f64]) -> ParameterRecord {
    let (mut model, vars) = nights::stand();
    vars.apply(&mut model, estimates);
    let cut = stability::cut::parse(CUT, "chain-turning.toml").unwrap();
    let lobes = stability::lobes(&stability::Request::new(&model, &cut)).unwrap();
    let section = stability::section::Stability::new(&cut, &lobes, None, &[]);
    history::import::stable_depth(&section)
}

#[test]
fn a_loosening_joint_raises_the_stable_depth_alarm() {
    let sc = Scenario {
        nights: STEP_NIGHT + 4,
        trend: (0, usize::MAX, 0.0),
        // Joint 2 (variable 1) loses 30 % of its stiffness.
        step: (1, STEP_NIGHT, 0.7),
        ..Scenario::default()
    };
    let mut runs: Vec<_> = nights::simulate(&sc, 3)
        .into_iter()
        .map(|n| n.record)
        .collect();
    for r in &mut runs {
        let x: Vec<f64> = r.parameters.iter().map(|p| p.estimate).collect();
        r.quantities.push(stable_depth(&x));
    }
    let name = runs[0].quantities[0].variable.clone();
    assert_eq!(name, "stable depth 1500–6000 rpm (chain-turning)");
    let depth = |n: usize| runs[n].quantities[0].in_unit();
    let before = (0..STEP_NIGHT).map(depth).sum::<f64>() / STEP_NIGHT as f64;
    let after = depth(STEP_NIGHT + 1);
    println!("stable depth: {before:.4} mm before the drop, {after:.4} mm the night after");
    assert!(
        after < 0.95 * before,
        "a softer joint lowers the stable depth: {before} → {after} mm"
    );

    let cfg = JudgeConfig {
        baseline: BaselineWindow::First(10),
        covariate: Some("temperature".into()),
        ..JudgeConfig::default()
    };
    let js = judge_series(&runs, &cfg);
    for (n, j) in js.iter().enumerate() {
        let on_depth: Vec<&str> = j
            .alarms
            .iter()
            .filter(|a| a.subject == name)
            .map(|a| a.message.as_str())
            .collect();
        println!("night {n}: {} {:?}", j.summary(), on_depth);
        if n < STEP_NIGHT {
            assert!(
                on_depth.is_empty(),
                "night {n}: false depth alarm {on_depth:?}"
            );
        }
        // The depth is judged, but T² runs over the four parameters only (it is a function of
        // them).
        assert!(
            j.notes.iter().all(|m| !m.contains("over 5 parameters")),
            "night {n}: {:?}",
            j.notes
        );
    }
    let raised = (STEP_NIGHT..runs.len())
        .find_map(|n| {
            js[n]
                .alarms
                .iter()
                .find(|a| a.subject == name)
                .map(|a| (n, a.message.clone()))
        })
        .expect("the stable depth alarm is raised after the joint loosens");
    println!("{raised:?}");
    assert!(raised.0 <= STEP_NIGHT + 2, "raised on night {}", raised.0);
    assert!(
        raised.1.starts_with("drift alarm (")
            && raised.1.contains(&format!("): {name} fell from "))
            && raised.1.contains(" mm, "),
        "{}",
        raised.1
    );

    // The trend page draws the depth's series after the parameters' (five charts), with the
    // alarm in the runs table.
    let page = history::trend::page("nights", &runs, &js);
    assert_eq!(page.matches("data-chart=\"trend\"").count(), 5);
    assert!(page.contains(&report::html::escape(&raised.1)));

    // The store keeps the quantity and judges the same from what it reads back.
    let dir = tempfile::tempdir().unwrap();
    let mut store = history::store::Store::open(&dir.path().join("h.sqlite")).unwrap();
    for r in &runs {
        store.append(r).unwrap();
    }
    let back = store.runs().unwrap();
    assert_eq!(back, runs);
}
