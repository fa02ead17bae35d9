//! Force control through a SCPI signal generator and a power amplifier on the simulated stand,
//! over a local TCP socket and over a pseudo-terminal: every line's force within the amplifier's
//! tolerance, the ramp rate held on the generator's timestamped log, the limits held; the
//! stepped sine against each emulated instrument (Keysight 33522B, Rigol DG1062Z, Tektronix
//! AFG31022) with no command refused; faults — an amplifier trip, an over-force, a dropped
//! connection before and after a setting, an error-queue entry mid-ramp, an instrument that stops
//! answering — ending with the generator's output off and a complete session; bad stand files
//! named by field.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod util;

use std::collections::BTreeSet;
use std::path::Path;

use acquire::generator::dialect;
use acquire::generator::limits::Load;
use acquire::record::{DriveKind, DriveRecord, SweepEvent};
use acquire::session;
use acquire::sim::generator::{CommandMatch, GeneratorFaults, GeneratorState};
use acquire::sim::{SimSetup, SimStand};
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

/// The plain simulated generator's idle amplitude (V peak): its smallest into a high impedance.
fn idle_v() -> f64 {
    let l = dialect::by_name("IDENT-SIM SIGGEN")
        .unwrap()
        .unwrap()
        .limits
        .unwrap();
    l.idle_peak(Load::HighImpedance).unwrap()
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
    run_with(stand, plan, path, usbtmc, GeneratorFaults::default()).await
}

/// [`run_over`] with the simulated generator's connection and instrument `faults`.
async fn run_with(
    stand: &Stand,
    plan: &SteppedSine,
    path: &Path,
    usbtmc: bool,
    faults: GeneratorFaults,
) -> (
    Result<sweep::SweepOutcome, String>,
    GeneratorState,
    Vec<&'static str>,
) {
    let mut setup = SimSetup::from_stand(stand).unwrap();
    setup.generator.as_mut().unwrap().device.faults = faults;
    let sim = SimStand::start_with(setup).unwrap();
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

/// Checks the ramp on the generator's timestamped log: the output was switched on at the idle
/// amplitude only, and while it was on every amplitude change moved by at most `ramp_rate` ×
/// the stand time since the previous change (or the switch-on) — on every path: switch-on, between
/// lines, corrections, ramp-down, abort. Stand time is wall-clock time × the stand's speed.
fn assert_ramp_respected(stand: &Stand, state: &GeneratorState) {
    let amp = &stand.generator.as_ref().unwrap().amplifier;
    let step = amp.ramp_step_v();
    let speed = stand.truth.as_ref().map_or(1.0, |t| t.speed);
    // One amplitude step of the instrument (0.1 mVpp): what its rounding may add.
    let quantum = 0.5e-4 + 1e-9;
    let mut last: Option<f64> = None;
    let mut changed_at: Option<std::time::Duration> = None;
    let mut on = false;
    let mut ramps = 0;
    let mut fastest: f64 = 0.0;
    for a in &state.log {
        match a.what {
            "output" => {
                // Switched on at the idle amplitude only.
                if a.output_on && !on {
                    assert!(last.unwrap() <= idle_v() + 1e-9, "output on at {last:?} V");
                    changed_at = Some(a.at);
                }
                on = a.output_on;
            }
            "amplitude" => {
                if let (true, Some(prev)) = (on, last) {
                    let dv = (a.value - prev).abs();
                    assert!(
                        dv <= step + quantum,
                        "amplitude moved {prev} → {} V in one setting (ramp step {step} V)",
                        a.value
                    );
                    if dv > 1e-9 {
                        ramps += 1;
                        let since = changed_at.map_or(0.0, |t| (a.at - t).as_secs_f64()) * speed;
                        assert!(
                            dv <= amp.ramp_rate_v_per_s * since + quantum,
                            "amplitude moved {prev} → {} V {:.1} ms (stand time) after the previous change: {:.0} V/s against ramp_rate {} V/s",
                            a.value,
                            1e3 * since,
                            dv / since,
                            amp.ramp_rate_v_per_s
                        );
                        fastest = fastest.max(dv / since);
                        changed_at = Some(a.at);
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
    assert!(fastest <= amp.ramp_rate_v_per_s * 1.01, "{fastest} V/s");
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
            s.generator_settings.unwrap() >= 1,
            "the frequency, and an amplitude when the drive changes on the generator's grid"
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
        state.volts_peak <= idle_v() + 1e-9,
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
        assert!(state.volts_peak <= idle_v() + 1e-9, "not ramped down");
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

/// The generator stand driving the emulation of `identity` (`manufacturer,model`) over TCP.
fn emulated_stand(identity: &str) -> Stand {
    let mut s = generator_stand(true);
    s.generator.as_mut().unwrap().identity = identity.into();
    s.shaker.identity = identity.into();
    s
}

/// The whole stepped sine against an emulated instrument, with the command table `*IDN?`
/// picks: no command refused (any error-queue entry would stop the sweep), every line's force
/// within tolerance, the ramp held, the idle amplitude the model's smallest at high impedance.
async fn sweeps_clean_against(identity: &str, model: &str) {
    let stand = emulated_stand(identity);
    let (_d, path) = temp_file("emulated.mcap");
    let (r, state, injected) = run(&stand, &plan(4), &path).await;
    let o = r.unwrap_or_else(|e| panic!("{identity}: {e}"));
    assert!(injected.is_empty(), "{injected:?}");
    assert_eq!(o.steps.len(), 4);
    for s in &o.steps {
        assert!((s.force_amplitude_n / 4000.0 - 1.0).abs() <= 0.02, "{s:?}");
    }
    assert!(!state.output_on && state.load_ohm.is_infinite());
    let idle = dialect::by_name(model).unwrap().unwrap().limits.unwrap();
    let idle = idle.idle_peak(Load::HighImpedance).unwrap();
    assert_eq!(idle, 0.001, "2 mVpp into a high impedance");
    let first = state.log.iter().find(|a| a.what == "amplitude").unwrap();
    assert_eq!(first.value, idle, "{identity}: the idle amplitude");
    assert_ramp_respected(&stand, &state);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_stepped_sine_runs_clean_against_a_keysight_33522b() {
    // Regression: the idle amplitude was 1 mVpp after `OUTPut1:LOAD INFinity`, which the
    // 33500B refuses (-222) — the sweep stopped during preparation.
    bounded(
        120,
        sweeps_clean_against("Keysight Technologies,33522B", "Keysight 33500B/33600A"),
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_stepped_sine_runs_clean_against_a_rigol_dg1062z() {
    bounded(
        120,
        sweeps_clean_against("Rigol Technologies,DG1062Z", "Rigol DG800/DG1000Z"),
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_stepped_sine_runs_clean_against_a_tektronix_afg31022() {
    bounded(
        120,
        sweeps_clean_against("TEKTRONIX,AFG31022", "Tektronix AFG31000"),
    )
    .await;
}

fn at(contains: &str, nth: u64) -> Option<CommandMatch> {
    Some(CommandMatch {
        contains: contains.into(),
        nth,
    })
}

/// A connection dropped around the third line's frequency setting: the driver reopens it, sends
/// the setting again and reads it back, and the sweep completes with every line at its own
/// frequency.
async fn a_dropped_connection_completes(faults: GeneratorFaults, kind: &str) {
    let stand = generator_stand(true);
    let plan = plan(5);
    let (_d, path) = temp_file("drop.mcap");
    let (r, state, injected) = run_with(&stand, &plan, &path, false, faults).await;
    let o = r.unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(injected, vec![kind]);
    assert_eq!(o.steps.len(), 5);
    let want = plan.frequencies.frequencies().unwrap();
    let set: Vec<f64> = state
        .log
        .iter()
        .filter(|a| a.what == "frequency")
        .map(|a| a.value)
        .collect();
    for (s, f) in o.steps.iter().zip(&want) {
        assert!((s.frequency_hz - f).abs() < 1e-6 * f, "{s:?}");
        assert!((s.force_amplitude_n / 4000.0 - 1.0).abs() <= 0.02, "{s:?}");
        assert!(
            set.iter().any(|x| (x - f).abs() < 1e-6 * f),
            "{f} Hz never reached the generator: {set:?}"
        );
    }
    // The generator's last frequency setting was the last line's.
    assert!((set.last().unwrap() - want.last().unwrap()).abs() < 1e-3);
    assert!(!state.output_on);
    assert_ramp_respected(&stand, &state);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_setting_lost_with_a_dropped_connection_is_sent_again() {
    // Regression: the driver re-sent only `*OPC?` and `SYSTem:ERRor?` after reconnecting; the
    // frequency setting was lost and the line ran at the previous frequency.
    let faults = GeneratorFaults {
        drop_before: at("FREQ ", 3),
        ..Default::default()
    };
    bounded(
        120,
        a_dropped_connection_completes(faults, "generator_drop_before"),
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_connection_dropped_after_a_setting_completes() {
    let faults = GeneratorFaults {
        drop_after: at("FREQ ", 3),
        ..Default::default()
    };
    bounded(
        120,
        a_dropped_connection_completes(faults, "generator_drop_after"),
    )
    .await;
}

/// A fault that stops the sweep: the error names the instrument, the command and `cause`; the
/// output is off (the generator's state, which the driver read back), the amplitude ramped down
/// at the ramp rate, the lines before kept in a complete session with the error recorded.
async fn stops_safely(
    faults: GeneratorFaults,
    kind: &str,
    command: &str,
    cause: &str,
    min_steps: usize,
) {
    let mut stand = generator_stand(true);
    stand.generator.as_mut().unwrap().timeout = std::time::Duration::from_millis(300);
    stand.generator.as_mut().unwrap().retries = 1;
    let (_d, path) = temp_file("stop.mcap");
    let (r, state, injected) = run_with(&stand, &plan(5), &path, false, faults).await;
    let e = r.unwrap_err();
    assert_eq!(injected, vec![kind]);
    assert!(e.contains("IDENT-SIM SIGGEN-2 on tcp:127.0.0.1:"), "{e}");
    assert!(e.contains(command) && e.contains(cause), "{e}");
    assert!(!state.output_on, "the generator's output was left on");
    assert!(state.volts_peak <= idle_v() + 1e-9, "not ramped down");
    assert_ramp_respected(&stand, &state);
    let last_output = state.log.iter().rev().find(|a| a.what == "output").unwrap();
    assert!(!last_output.output_on);
    let (drive, steps, events) = drive_and_steps(&path);
    assert!(
        steps.len() >= min_steps,
        "the lines before the fault are kept"
    );
    assert!(events
        .iter()
        .any(|ev| ev.kind == "error" && ev.detail.contains(cause)));
    assert_eq!(
        drive.last().map(|d| (d.kind, d.output_on)),
        Some((DriveKind::Output, false))
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_error_queue_entry_mid_ramp_ends_with_the_output_off() {
    // Amplitude settings: the idle one of the preparation, the switch-on drive while off, the
    // idle one before the output goes on, then the switch-on ramp: the fourth is its first step.
    let faults = GeneratorFaults {
        error_at: Some((
            CommandMatch {
                contains: "VOLT ".into(),
                nth: 4,
            },
            -222,
            "Data out of range".into(),
        )),
        ..Default::default()
    };
    bounded(
        120,
        stops_safely(
            faults,
            "generator_error",
            "`SOUR1:VOLT ",
            "-222,\"Data out of range\"",
            0,
        ),
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_instrument_that_stops_answering_ends_with_the_output_off() {
    // The socket hangs at the third line's frequency: the driver times out naming the command,
    // then reopens the connection to ramp down and switch the output off.
    let faults = GeneratorFaults {
        silent_from: at("FREQ ", 3),
        ..Default::default()
    };
    bounded(
        120,
        stops_safely(faults, "generator_silent", "`SOUR1:FREQ ", "no answer", 1),
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_channel_the_daq_does_not_have_is_refused_before_the_drive_is_on() {
    bounded(60, async {
        // device_channel = 99 on the 8-input simulated DAQ: refused when the stream is
        // configured, naming the stand file, the field and the fix; the generator's output was
        // never switched on.
        let mut stand = generator_stand(false);
        let last = stand.channels.len() - 1;
        stand.channels[last].device_channel = 99;
        let (_d, path) = temp_file("ch99.mcap");
        let (r, state, _) = run(&stand, &plan(3), &path).await;
        let e = r.unwrap_err();
        assert!(e.contains("fwd32j-generator-sim.toml"), "{e}");
        assert!(
            e.contains("table-c-z = 99") && e.contains("no input 99"),
            "{e}"
        );
        assert!(e.contains("fix `device_channel`"), "{e}");
        assert!(state.log.iter().all(|a| !a.output_on), "{:?}", state.log);
    })
    .await;
}

#[test]
fn a_ramp_rate_of_zero_is_refused_naming_the_field() {
    let good = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/stands/fwd32j-generator-sim.toml"),
    )
    .unwrap()
    .replace(
        "[geometry]\nmodel = \"../models/fwd32j-no-actuator.toml\"\n",
        "",
    );
    let bad = good.replacen("ramp_rate = \"20 V/s\"", "ramp_rate = \"0 V/s\"", 1);
    let e = Stand::parse(&bad, "gen.toml").unwrap_err();
    assert_eq!(e.line, line_of(&good, "ramp_rate = \""));
    assert!(e.message.contains("amplifier.ramp_rate must be > 0"), "{e}");
    assert!(e.to_string().contains("gen.toml"), "{e}");
}
