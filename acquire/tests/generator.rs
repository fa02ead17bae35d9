//! Force control through a SCPI signal generator and a power amplifier on the simulated stand,
//! over a local TCP socket and over a pseudo-terminal: every line's force within the amplifier's
//! tolerance, the ramp and limits held, an amplifier trip and an over-force ending with the
//! generator's output off and a complete session; bad stand files named by field.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod util;

use std::collections::BTreeSet;
use std::path::Path;

use acquire::generator::exciter::IDLE_V;
use acquire::record::{DriveKind, DriveRecord, SweepEvent};
use acquire::session;
use acquire::sim::generator::GeneratorState;
use acquire::sim::SimStand;
use acquire::stand::{GeneratorAddress, Stand};
use acquire::sweep::{self, FrequencyList, NoProgress, StepResult, SteppedSine, StopSignal};
use util::*;

/// The repository's generator stand, served on TCP (`tcp = true`) or a pty.
fn generator_stand(tcp: bool) -> Stand {
    let p =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/stands/fwd32j-generator-sim.toml");
    let mut s = Stand::load(&p).unwrap_or_else(|e| panic!("{e}"));
    s.generator.as_mut().unwrap().port = GeneratorAddress::Sim { tcp };
    // Twice real time: settling (0.25 s of stand time) stays well above a loaded machine's
    // scheduling hiccups, so no window holds blocks from before a setting.
    s.truth.as_mut().unwrap().speed = 2.0;
    s
}

fn plan(n: usize) -> SteppedSine {
    SteppedSine {
        frequencies: FrequencyList::Log {
            start: 20.0,
            stop: 400.0,
            n,
        },
        settle_s: 0.25,
        cycles: 10.0,
        min_window_s: 0.2,
        ..SteppedSine::log(20.0, 400.0, n, 4000.0)
    }
}

/// Runs `plan` on `stand`'s simulated generator stand into `path`; returns the sweep's result
/// (as text on error), the generator's final state and the stand's injected faults.
async fn run(
    stand: &Stand,
    plan: &SteppedSine,
    path: &Path,
) -> (
    Result<sweep::SweepOutcome, String>,
    GeneratorState,
    Vec<&'static str>,
) {
    run_over(stand, plan, path, false).await
}

/// [`run`], with the pty-served generator opened through the USBTMC transport when `usbtmc`
/// (the pty stands in for `/dev/usbtmc0`: see `acquire::transport::UsbtmcTransport`).
async fn run_over(
    stand: &Stand,
    plan: &SteppedSine,
    path: &Path,
    usbtmc: bool,
) -> (
    Result<sweep::SweepOutcome, String>,
    GeneratorState,
    Vec<&'static str>,
) {
    let sim = SimStand::start(stand).unwrap();
    let mut bound = sim.bind(stand);
    if usbtmc {
        let g = bound.generator.as_mut().unwrap();
        let GeneratorAddress::Serial(pty) = &g.port else {
            panic!(
                "the USBTMC run needs the pty-served generator, got {}",
                g.port
            )
        };
        g.port = GeneratorAddress::Usbtmc(pty.clone());
    }
    let r = recorded(stand, &bound, plan, path, async |rig, h| {
        let none = BTreeSet::new();
        sweep::stepped_sine(rig, plan, h, &NoProgress, &StopSignal::new(), &none).await
    })
    .await;
    let state = sim.generator_state().unwrap();
    let injected = sim.injected().iter().map(|f| f.kind).collect();
    (r, state, injected)
}

/// Checks the ramp: while the output was on, no amplitude setting rose by more than one ramp step.
fn assert_ramp_respected(stand: &Stand, state: &GeneratorState) {
    let amp = &stand.generator.as_ref().unwrap().amplifier;
    let step = amp.ramp_step_v();
    let mut last: Option<f64> = None;
    let mut on = false;
    let mut ramps = 0;
    for a in &state.log {
        match a.what {
            "output" => {
                // Switched on at the idle amplitude only.
                if a.output_on && !on {
                    assert!(last.unwrap() <= IDLE_V + 1e-9, "output on at {last:?} V");
                }
                on = a.output_on;
            }
            "amplitude" => {
                if let (true, Some(prev)) = (on, last) {
                    assert!(
                        a.value - prev <= step + 1e-9,
                        "amplitude rose {prev} → {} V in one setting (ramp step {step} V)",
                        a.value
                    );
                    if (a.value - prev).abs() > 1e-9 {
                        ramps += 1;
                    }
                }
                assert!(
                    a.value <= amp.voltage_limit_v + 1e-12,
                    "{} V above the limit",
                    a.value
                );
                last = Some(a.value);
            }
            _ => {}
        }
    }
    assert!(ramps > 0, "no amplitude change while on");
}

/// The `/drive` records and the session's steps.
fn drive_and_steps(path: &Path) -> (Vec<DriveRecord>, Vec<StepResult>, Vec<SweepEvent>) {
    let _complete = records(path);
    let r = session::read(path).unwrap();
    (r.all().unwrap(), r.all().unwrap(), r.all().unwrap())
}

async fn holds_every_line(tcp: bool) {
    holds_every_line_over(tcp, false).await
}

async fn holds_every_line_over(tcp: bool, usbtmc: bool) {
    let stand = generator_stand(tcp);
    let plan = plan(10);
    let (_d, path) = temp_file("gen.mcap");
    let (r, state, injected) = run_over(&stand, &plan, &path, usbtmc).await;
    let o = r.unwrap_or_else(|e| panic!("{e}"));
    assert!(injected.is_empty(), "{injected:?}");
    assert_eq!(o.steps.len(), 10);
    let tol = stand.generator.as_ref().unwrap().amplifier.tolerance;
    assert_eq!(tol, 0.02);
    for s in &o.steps {
        let err = (s.force_amplitude_n - 4000.0).abs() / 4000.0;
        assert!(
            err <= tol,
            "{} Hz: {} N is {:.2} % off",
            s.frequency_hz,
            s.force_amplitude_n,
            100.0 * err
        );
        assert!(
            s.generator_settings.unwrap() >= 2,
            "frequency and at least one amplitude"
        );
    }
    // The transfer is learned: after the first line, lines converge in one or two corrections.
    let later: Vec<u32> = o.steps.iter().skip(1).map(|s| s.iterations).collect();
    assert!(
        later.iter().all(|&n| n <= 2),
        "corrections per line {later:?}"
    );
    assert!(
        o.steps[0].iterations >= 1,
        "the first line corrects the 4 % gain error"
    );
    assert!(!state.output_on, "output left on");
    assert!(
        state.load_ohm.is_infinite(),
        "the amplifier input is high impedance"
    );
    assert_ramp_respected(&stand, &state);

    // Every setting and every measured force is in the session, and it matches the steps.
    let (drive, steps, _) = drive_and_steps(&path);
    assert_eq!(steps, o.steps);
    for s in &steps {
        let m: Vec<&DriveRecord> = drive
            .iter()
            .filter(|d| d.kind == DriveKind::Measurement && d.step == Some(s.step))
            .collect();
        assert_eq!(
            m.len() as u32,
            s.iterations + 1,
            "one measurement per correction and the last"
        );
        assert_eq!(m.last().unwrap().force_n, Some(s.force_amplitude_n));
    }
    let amplitude_settings = drive
        .iter()
        .filter(|d| d.kind == DriveKind::Amplitude)
        .count();
    let logged = state.log.iter().filter(|a| a.what == "amplitude").count();
    assert_eq!(
        amplitude_settings, logged,
        "every amplitude the generator accepted is recorded"
    );
    let last = drive.last().unwrap();
    assert_eq!((last.kind, last.output_on), (DriveKind::Output, false));
    if usbtmc {
        assert!(
            drive.iter().all(|d| d.port.starts_with("usbtmc:/dev/")),
            "drive records name the USBTMC port: {}",
            last.port
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn force_control_over_tcp_holds_every_line_within_tolerance() {
    bounded(180, holds_every_line(true)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn force_control_over_a_pty_holds_every_line_within_tolerance() {
    bounded(180, holds_every_line(false)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn force_control_over_usbtmc_holds_every_line_within_tolerance() {
    // The simulated generator's pty opened as a USBTMC device: one write per command, reads only
    // after a query. The session names the port `usbtmc:/dev/pts/N`.
    bounded(180, holds_every_line_over(false, true)).await;
}

/// A fault mid-sweep ends the sweep with an error containing `expect`, the output off, the
/// amplitude ramped down and a complete session recording the error.
async fn fault_ends_safely(tcp: bool, fault: &str, expect: &str, injected_kind: &str) {
    let mut stand = generator_stand(tcp);
    match fault {
        "trip" => stand.faults.amplifier_trip_after_lines = Some(3),
        _ => {
            stand.faults.amplifier_surge_after_lines = Some(3);
            stand.faults.amplifier_surge_factor = 2.5;
        }
    }
    let (_d, path) = temp_file("fault.mcap");
    let (r, state, injected) = run(&stand, &plan(8), &path).await;
    let e = r.unwrap_err();
    assert!(e.contains(expect), "{e}");
    assert!(e.contains("output switched off"), "{e}");
    assert_eq!(injected, vec![injected_kind]);
    assert!(!state.output_on, "the generator's output was left on");
    assert!(
        state.volts_peak <= IDLE_V + 1e-9,
        "not ramped down: {} V",
        state.volts_peak
    );
    assert_ramp_respected(&stand, &state);
    let (drive, steps, events) = drive_and_steps(&path);
    assert_eq!(steps.len(), 2, "the lines before the fault are kept");
    assert!(events
        .iter()
        .any(|e| e.kind == "error" && e.detail.contains(expect)));
    assert!(drive
        .iter()
        .any(|d| d.kind == DriveKind::Measurement && d.step == Some(2)));
    assert_eq!(
        drive.last().map(|d| (d.kind, d.output_on)),
        Some((DriveKind::Output, false))
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_clipped_force_channel_ends_with_the_output_off() {
    bounded(180, async {
        // A load cell twice as sensitive: the DAQ's ±10 V input clips at 10 V / 4.5 mV/N = 2.2 kN,
        // below the 4 kN target and below force_limit (4.4 kN), so the clipped force reads low
        // and never trips the over-force: only the clipping check stops the loop driving harder.
        let mut stand = generator_stand(true);
        let force = stand.force_channel();
        stand.channels[force].sensitivity = 4.5e-3;
        assert_eq!(stand.daq.input_range_v, 10.0, "the default input range");
        let (_d, path) = temp_file("clip.mcap");
        let (r, state, injected) = run(&stand, &plan(4), &path).await;
        let e = r.unwrap_err();
        assert!(
            e.contains("force channel `force` clipped") && e.contains("±10 V input range"),
            "{e}"
        );
        assert!(e.contains("output switched off"), "{e}");
        assert!(injected.is_empty(), "{injected:?}");
        assert!(!state.output_on, "the generator's output was left on");
        assert!(state.volts_peak <= IDLE_V + 1e-9, "not ramped down");
        let (drive, steps, events) = drive_and_steps(&path);
        assert!(
            steps.is_empty(),
            "no line measured on a clipped force is kept"
        );
        assert!(events
            .iter()
            .any(|e| e.kind == "error" && e.detail.contains("clipped")));
        // The clipped reading is recorded, and stayed below the over-force limit.
        let m: Vec<f64> = drive
            .iter()
            .filter(|d| d.kind == DriveKind::Measurement)
            .filter_map(|d| d.force_n)
            .collect();
        let last = *m.last().unwrap();
        assert!(last < 4400.0 && last > 1500.0, "{m:?}");
        assert_eq!(
            drive.last().map(|d| (d.kind, d.output_on)),
            Some((DriveKind::Output, false))
        );
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_amplifier_trip_mid_sweep_ends_with_the_output_off() {
    bounded(
        180,
        fault_ends_safely(true, "trip", "lost force signal", "amplifier_trip"),
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_over_force_ends_with_the_output_off() {
    bounded(
        180,
        fault_ends_safely(false, "surge", "over-force", "amplifier_surge"),
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drive_above_the_voltage_limit_is_refused_and_the_output_goes_off() {
    bounded(120, async {
        // The amplifier is far weaker than the stand believes (300 instead of 1000 N/V): the
        // loop would need 4000 N / (300 N/V · 0.85) ≈ 16 V, above the 5 V limit.
        let mut stand = generator_stand(true);
        stand.truth.as_mut().unwrap().amplifier_gain_n_per_v = Some(300.0);
        stand.generator.as_mut().unwrap().amplifier.voltage_limit_v = 5.0;
        let (_d, path) = temp_file("ov.mcap");
        let (r, state, _) = run(&stand, &plan(4), &path).await;
        let e = r.unwrap_err();
        assert!(
            e.contains("over-voltage") && e.contains("voltage_limit 5.000 V"),
            "{e}"
        );
        assert!(!state.output_on);
        assert!(state
            .log
            .iter()
            .all(|a| a.what != "amplitude" || a.value <= 5.0));
        let (drive, _, _) = drive_and_steps(&path);
        assert!(drive.iter().all(|d| d.volts_peak <= 5.0));
    })
    .await;
}

#[test]
fn bad_generator_stand_files_name_the_field_and_the_fix() {
    let good = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/stands/fwd32j-generator-sim.toml"),
    )
    .unwrap();
    // Relative model paths are not resolved by parse; geometry is not needed here.
    let good = good.replace(
        "[geometry]\nmodel = \"../models/fwd32j-no-actuator.toml\"\n",
        "",
    );
    let parse = |t: &str| Stand::parse(t, "gen.toml");
    let s = parse(&good).unwrap_or_else(|e| panic!("{e}"));
    let g = s.generator.as_ref().unwrap();
    assert_eq!(g.amplifier.gain_n_per_v, 1000.0);
    assert_eq!(g.amplifier.voltage_limit_v, 8.0);
    assert_eq!(g.amplifier.force_limit_n, 4400.0);
    assert_eq!(g.amplifier.ramp_rate_v_per_s, 20.0);
    assert_eq!(
        s.shaker.max_force_n, 4400.0,
        "the sweep's force limit is the amplifier's"
    );
    assert_eq!(
        s.truth.as_ref().unwrap().amplifier_gain_n_per_v,
        Some(1040.0)
    );

    let err = |from: &str, to: &str| {
        assert!(good.contains(from), "{from}");
        let e = parse(&good.replacen(from, to, 1)).unwrap_err();
        (e.line, e.message)
    };
    for (field, line) in [
        ("gain = \"1000 N/V\"\n", "gain"),
        ("voltage_limit = \"8 V\"\n", "voltage_limit"),
        ("force_limit = \"4.4 kN\"\n", "force_limit"),
        ("ramp_rate = \"20 V/s\"\n", "ramp_rate"),
    ] {
        let (_, m) = err(field, "");
        assert!(m.contains(&format!("[amplifier] has no `{line}`")), "{m}");
        assert!(m.contains("gain = \"1000 N/V\""), "shows an example: {m}");
    }
    let (l, m) = err("voltage_limit = \"8 V\"", "voltage_limit = \"15 V\"");
    assert_eq!(l, line_of(&good, "voltage_limit = "));
    assert!(
        m.contains("amplifier.voltage_limit 15 V") && m.contains("20 Vpp"),
        "{m}"
    );
    let (_, m) = err("gain = \"1000 N/V\"", "gain = \"1 N/V\"");
    assert!(
        m.contains("amplifier.gain × voltage_limit = 8 N") && m.contains("gain's unit"),
        "{m}"
    );
    let (_, m) = err("gain = \"1000 N/V\"", "gain = \"1000 N\"");
    assert!(
        m.contains("amplifier.gain: write it like \"1000 N/V\""),
        "{m}"
    );
    let (_, m) = err("ramp_rate = \"20 V/s\"", "ramp_rate = \"500 V/s\"");
    assert!(
        m.contains("amplifier.ramp_rate 500 V/s") && m.contains("lower it"),
        "{m}"
    );
    let (_, m) = err("tolerance = 0.02", "tolerance = 0.5");
    assert!(m.contains("amplifier.tolerance"), "{m}");
    let (_, m) = err("force_limit = \"4.4 kN\"", "force_limit = \"-6 kN\"");
    assert!(m.contains("amplifier.force_limit must be > 0"), "{m}");
    // Sections missing or doubled.
    let (_, m) = err("[amplifier]", "[not_amplifier]");
    assert!(
        m.contains("unknown field") || m.contains("needs an [amplifier]"),
        "{m}"
    );
    let no_amp: String = {
        let i = good.find("[amplifier]").unwrap();
        let j = good[i..].find("\n\n").unwrap() + i;
        format!("{}{}", &good[..i], &good[j..])
    };
    let m = parse(&no_amp).unwrap_err().message;
    assert!(
        m.contains("a [generator] stand needs an [amplifier] section"),
        "{m}"
    );
    let (_, m) = err("[generator]", "[shaker]\nport = \"sim\"\n\n[generator]");
    assert!(m.contains("both [shaker] and [generator]"), "{m}");
    let (_, m) = err(
        "port = \"sim\"\nidentity = \"IDENT-SIM,SIGGEN-2\"",
        "port = \"tcp:\"\nidentity = \"IDENT-SIM,SIGGEN-2\"",
    );
    assert!(m.contains("tcp:HOST:PORT"), "{m}");
    let (_, m) = err(
        "port = \"sim\"\nidentity = \"IDENT-SIM,SIGGEN-2\"",
        "port = \"usbtmc:\"\nidentity = \"IDENT-SIM,SIGGEN-2\"",
    );
    assert!(m.contains("usbtmc:/dev/usbtmc0"), "{m}");
    let (_, m) = err(
        "samples_per_block = 64",
        "samples_per_block = 64\ninput_range = \"-5 V\"",
    );
    assert!(m.contains("daq.input_range"), "{m}");
    let ranged = good.replacen(
        "samples_per_block = 64",
        "samples_per_block = 64\ninput_range = \"5 V\"",
        1,
    );
    let d = parse(&ranged).unwrap_or_else(|e| panic!("{e}")).daq;
    assert_eq!(d.input_range_v, 5.0);
    let usb = good.replacen("port = \"sim\"", "port = \"usbtmc:/dev/usbtmc0\"", 1);
    let g = parse(&usb)
        .unwrap_or_else(|e| panic!("{e}"))
        .generator
        .unwrap();
    assert_eq!(g.port, GeneratorAddress::Usbtmc("/dev/usbtmc0".into()));
    assert_eq!(g.port.to_string(), "usbtmc:/dev/usbtmc0");
    let (_, m) = err("channel = 1", "channel = 0\ndialect = \"Keysight 99\"");
    assert!(m.contains("generator.channel counts from 1"), "{m}");
    let (_, m) = err("channel = 1", "dialect = \"Keysight 99\"");
    assert!(
        m.contains("not a built-in command table") && m.contains("Rigol DG800/DG1000Z"),
        "{m}"
    );
    let (_, m) = err(
        "# The power amplifier and shaker behind it",
        "[generator.commands]\nvolts = \"X\"\n# The power amplifier and shaker behind it",
    );
    assert!(m.contains("volts"), "{m}");
}

fn line_of(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.contains(needle)).unwrap() + 1
}
