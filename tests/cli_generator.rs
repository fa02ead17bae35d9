//! `ident demo --generator`: the main job through the generator stand (simulated SCPI signal
//! generator + power amplifier on a pseudo-terminal, the force loop closed by ident) end to end —
//! every line's force within the amplifier's tolerance, every setting recorded, and diagnosis
//! finding the actuator the identification model lacks, as on the shaker-controller stand.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::PathBuf;

use acquire::record::{DriveKind, DriveRecord};
use acquire::sweep::StepResult;
use common::{ident, text};

#[test]
fn demo_through_the_generator_stand_finds_the_actuator() {
    let dir = tempfile::tempdir().unwrap();
    let o = ident(&[
        "demo",
        "--generator",
        "--out",
        dir.path().to_str().unwrap(),
        "--quiet",
    ]);
    let out = text(&o);
    assert!(o.status.success(), "{out}");
    assert!(out.contains("SCPI signal generator"), "{out}");
    assert!(out.contains("(38 steps, 0 stream faults)"), "{out}");
    // The demo's 38 lines (10 are too few observations for diagnosis to add an effect). Diagnosis
    // brings the fit to the noise floor and adds one spring between spindle head and table (or upper saddle) along the
    // actuator's axis, as the shaker-controller demo does.
    let added: Vec<&str> = out
        .lines()
        .filter(|l| l.trim_start().starts_with("added: "))
        .collect();
    assert_eq!(added.len(), 1, "{out}");
    let (before, after) = common::reduced_chi2_before_after(&out);
    let reduced = [before, after];
    assert!(reduced[0] > 100.0 && reduced[1] < 1.5, "{reduced:?}\n{out}");
    assert!(added[0].contains("spring spindle head"), "{}", added[0]);

    // The session is the generator stand's: every line's force within the amplifier's 2 %,
    // measured after generator settings that are all recorded, and the output left off.
    let report = PathBuf::from(
        out.lines()
            .find_map(|l| l.strip_prefix("report: "))
            .unwrap_or_else(|| panic!("no report path: {out}")),
    );
    let r = acquire::session::read(&report.join("session.mcap")).unwrap();
    let steps: Vec<StepResult> = r.all().unwrap();
    let drive: Vec<DriveRecord> = r.all().unwrap();
    assert_eq!(steps.len(), 38);
    for s in &steps {
        let err = (s.force_amplitude_n - 4000.0).abs() / 4000.0;
        assert!(
            err <= 0.02,
            "{} Hz: {} N",
            s.frequency_hz,
            s.force_amplitude_n
        );
        // The frequency, and an amplitude when the drive changes on the generator's grid
        // (0.1 mVpp): a line whose drive rounds to the previous one needs none.
        assert!(s.generator_settings.unwrap() >= 1, "{s:?}");
    }
    assert!(drive.iter().all(|d| d.volts_peak <= 8.0));
    assert_eq!(
        drive
            .iter()
            .filter(|d| d.kind == DriveKind::Measurement)
            .count() as u32,
        steps.iter().map(|s| s.iterations + 1).sum::<u32>()
    );
    assert_eq!(
        drive.last().map(|d| (d.kind, d.output_on)),
        Some((DriveKind::Output, false))
    );
}
