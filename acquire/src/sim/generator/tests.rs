//! Conformance of the emulated instruments, written from the manuals' own command examples and
//! the data sheets' ranges: what each accepts, what it refuses with which error, and how it
//! answers; then the driver's command tables against each emulation, whole.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use super::*;
use crate::generator::{Generator, GeneratorOptions, ScpiGenerator};
use crate::sim::link::Shared;
use crate::transport::MemoryTransport;

fn generator(e: &Emulation) -> SimGenerator {
    let shared: SharedRef = Arc::new(Mutex::new(Shared::default()));
    SimGenerator::new(
        SimGeneratorSetup {
            identity: e.identity("1.0"),
            channel: 1,
            amplifier_gain_n_per_v: 1000.0,
            amplifier_trip_after_lines: None,
            amplifier_surge_after_lines: None,
            surge_factor: 2.0,
            faults: GeneratorFaults::default(),
        },
        shared,
    )
}

/// Sends `line`; returns its answer (queries) and the error-queue entry it left.
fn exchange(g: &SimGenerator, line: &str) -> (Option<String>, String) {
    let answer = g.handle(&FramedCommand {
        text: line.into(),
        block: None,
        garbage: false,
    });
    let err = g.apply("SYSTem:ERRor?").unwrap().unwrap();
    (answer, err)
}

/// Each line is accepted (the error queue stays empty).
fn accepts(g: &SimGenerator, lines: &[&str]) {
    let ok = g.emulation.error_entry(0, "No error");
    for l in lines {
        let (_, err) = exchange(g, l);
        assert_eq!(err, ok, "{}: `{l}`", g.emulation.model);
    }
}

/// The line is refused with `code`.
fn refuses(g: &SimGenerator, line: &str, code: i32) {
    let (_, err) = exchange(g, line);
    let want = format!("{code:+}");
    let got = err.split(',').next().unwrap().to_string();
    assert!(
        got == want || got == code.to_string(),
        "{}: `{line}` answered {err}, expected {code}",
        g.emulation.model
    );
}

fn answer(g: &SimGenerator, query: &str) -> String {
    exchange(g, query).0.unwrap()
}

#[test]
fn keysight_33522b_as_its_guide_and_data_sheet_describe_it() {
    let g = generator(&Emulation::keysight_33522b());
    // The guide's examples: sine, frequency, amplitude, offset, output; both channels.
    accepts(
        &g,
        &[
            "*RST",
            "FUNCtion SINusoid",
            "FREQuency +1.0E+03",
            "VOLTage 1.2",
            "VOLTage:OFFSet 0.4",
            "OUTPut ON",
            "SOURce2:FUNCtion SQUare",
            "OUTPut1:LOAD INFinity",
            "SOURce1:FUNCtion ARB",
            "OUTPut1 OFF",
        ],
    );
    assert_eq!(answer(&g, "SYSTem:ERRor?"), "+0,\"No error\"");
    assert_eq!(answer(&g, "FREQuency?"), "+1.00000000000000E+03");
    // The load changed to a high impedance: the amplitude shown doubles, the voltage stays.
    assert_eq!(answer(&g, "SOURce1:VOLTage?"), "+2.40000000000000E+00");
    assert_eq!(answer(&g, "OUTPut1?"), "0");
    // Refused: 1 mVpp into a high impedance (2 mVpp is the least), 20.1 Vpp, a long form the
    // guide does not list, nodes of other manuals, a third channel, 31 MHz.
    refuses(&g, "SOURce1:VOLTage 0.001", -222);
    refuses(&g, "SOURce1:VOLTage 20.1", -222);
    refuses(&g, "SOURce1:FUNCtion ARBitrary", -224);
    refuses(&g, "SOURce1:FUNCtion:SHAPe SINusoid", -113);
    refuses(&g, "OUTPut1:IMPedance INFinity", -113);
    refuses(&g, "OUTPut1:STATe ON", -113);
    refuses(&g, "SOURce3:VOLTage 1", -114);
    refuses(&g, "SOURce1:FREQuency 31E6", -222);
    // Into 50 Ω the range is 1 mVpp to 10 Vpp.
    accepts(&g, &["OUTPut1:LOAD 50", "SOURce1:VOLTage 0.001"]);
    refuses(&g, "SOURce1:VOLTage 10.1", -222);
    assert_eq!(answer(&g, "SOURce1:VOLTage?"), "+1.00000000000000E-03");
}

#[test]
fn rigol_dg1062z_as_its_programming_guide_describes_it() {
    let g = generator(&Emulation::rigol_dg1062z());
    accepts(
        &g,
        &[
            "*RST",
            ":SOUR1:FUNC SIN",
            ":SOUR1:FREQ 10000",
            ":OUTP1:LOAD INF",
            ":SOUR1:VOLT:UNIT VPP",
            ":SOUR1:VOLT 2",
            ":SOUR1:VOLT:OFFS 0",
            ":SOURce1:VOLTage:LEVel:IMMediate:AMPLitude 2.5",
            ":OUTP1 ON",
            ":OUTPut2:STATe OFF",
        ],
    );
    assert_eq!(answer(&g, ":SYST:ERR?"), "0,\"No error\"");
    assert_eq!(answer(&g, ":OUTP1?"), "ON");
    assert_eq!(answer(&g, ":SOUR1:FREQ?"), "1.000000E+04");
    assert_eq!(answer(&g, ":SOUR1:VOLT?"), "2.500000E+00");
    refuses(&g, ":SOUR1:VOLT 30", -222);
    refuses(&g, ":SOUR1:VOLT 0.001", -222);
    refuses(&g, ":SOUR1:FUNC ARB", -224);
    refuses(&g, ":SOUR3:FREQ 10", -114);
}

#[test]
fn tektronix_afg31022_as_its_programmer_manual_describes_it() {
    let g = generator(&Emulation::tektronix_afg31022());
    accepts(
        &g,
        &[
            "*RST",
            "SOURce1:FUNCtion:SHAPe SINusoid",
            "SOURce1:FREQuency:FIXed 500",
            "OUTPut1:IMPedance INFinity",
            "SOURce1:VOLTage:LEVel:IMMediate:AMPLitude 1",
            "SOURce1:VOLTage:LEVel:IMMediate:OFFSet 0",
            "OUTPut1:STATe ON",
        ],
    );
    assert_eq!(answer(&g, "SYSTem:ERRor?"), "0,\"No error\"");
    assert_eq!(answer(&g, "OUTPut1:STATe?"), "1");
    assert_eq!(answer(&g, "SOURce1:FREQuency:FIXed?"), "5.0000E+02");
    refuses(&g, "OUTPut1:LOAD INF", -113);
    refuses(&g, "SOURce1:FREQuency:FIXed 26E6", -222);
    refuses(&g, "SOURce1:FUNCtion:SHAPe ARB", -224);
}

#[test]
fn the_plain_generator_takes_every_manuals_forms_within_the_same_ranges() {
    let g = generator(&Emulation::plain());
    accepts(
        &g,
        &[
            "SOUR1:FUNC SIN",
            "OUTP1:LOAD INF",
            "SOUR1:VOLT 0.002",
            "SOURce1:VOLTage:LEVel:IMMediate:AMPLitude 3",
            "OUTPut1:STATe ON",
            "SOUR1:FUNC ARBitrary",
        ],
    );
    refuses(&g, "SOUR1:VOLT 0.001", -222);
    refuses(&g, "SOUR1:FORCe 3", -113);
    assert_eq!(answer(&g, "SYST:ERR?"), "0,\"No error\"");
}

#[test]
fn the_error_queue_overflows_into_350_as_the_standard_says() {
    let g = generator(&Emulation::keysight_33522b());
    for _ in 0..12 {
        g.handle(&FramedCommand {
            text: "SOUR1:FORCe 1".into(),
            block: None,
            garbage: false,
        });
    }
    let entries: Vec<String> = (0..11)
        .map(|_| g.apply("SYST:ERR?").unwrap().unwrap())
        .collect();
    assert_eq!(entries[0], "-113,\"Undefined header\"");
    assert_eq!(entries[9], "-350,\"Queue overflow\"");
    assert_eq!(entries[10], "+0,\"No error\"");
}

/// The driver, with the command table it picks from `*IDN?`, against the emulation of `e`:
/// preparation, a line (frequency, amplitude, output on and off, each read back) and an
/// arbitrary-waveform upload selected and playing — with no command refused.
async fn driver_runs_clean_against(e: Emulation) {
    let sim = generator(&e);
    let (host, dev) = MemoryTransport::pair("gen", "gen-dev", 1 << 20);
    let served = sim.clone();
    let task = tokio::spawn(async move { served.serve(dev, true).await });
    let mut g = ScpiGenerator::new(Box::new(host), GeneratorOptions::default());
    let id = g.identify().await.unwrap();
    assert_eq!(id.model, e.model);
    g.prepare_sine().await.unwrap();
    assert_eq!(
        sim.state().volts_peak,
        0.001,
        "{}: idles at 2 mVpp",
        e.model
    );
    g.set_frequency(123.4).await.unwrap();
    assert_eq!(g.set_amplitude(2.5).await.unwrap(), 2.5);
    g.set_output(true).await.unwrap();
    g.set_output(false).await.unwrap();
    let st = sim.state();
    assert!(st.load_ohm.is_infinite() && st.sine && !st.output_on);
    assert_eq!((st.frequency_hz, st.volts_peak), (123.4, 2.5));
    // Broadband: 1000 points at 5120 Sa/s.
    let samples: Vec<f64> = (0..1000)
        .map(|i| (2.0 * std::f64::consts::PI * i as f64 / 1000.0).sin())
        .collect();
    g.play_arbitrary(&samples, 5120.0).await.unwrap();
    let st = sim.state();
    let (_, played) = st.uploaded.clone().unwrap();
    assert_eq!(played.samples.len(), 1000, "{}", e.model);
    assert!((played.sample_rate_hz - 5120.0).abs() < 1e-6, "{}", e.model);
    assert!(
        st.arbitrary && st.selected.is_some(),
        "{}: selected",
        e.model
    );
    let worst = samples
        .iter()
        .zip(&played.samples)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst < 2.0 / 16383.0, "{}: codes off by {worst}", e.model);
    assert!(st.errors.is_empty(), "{}: {:?}", e.model, st.errors);
    drop(g);
    task.abort();
}

#[tokio::test]
async fn the_driver_runs_clean_against_the_keysight_33522b() {
    driver_runs_clean_against(Emulation::keysight_33522b()).await;
}

#[tokio::test]
async fn the_driver_runs_clean_against_the_rigol_dg1062z() {
    driver_runs_clean_against(Emulation::rigol_dg1062z()).await;
}

#[tokio::test]
async fn the_driver_runs_clean_against_the_tektronix_afg31022() {
    driver_runs_clean_against(Emulation::tektronix_afg31022()).await;
}

#[tokio::test]
async fn the_driver_runs_clean_against_the_plain_generator() {
    driver_runs_clean_against(Emulation::plain()).await;
}

#[tokio::test]
async fn an_upload_cut_by_a_dropped_connection_is_sent_again_whole() {
    // The connection closes as the 33522B receives the upload: the driver reopens it, finds the
    // waveform missing when it selects it, and repeats the whole sequence on the new connection.
    let mut sim = generator(&Emulation::keysight_33522b());
    sim.setup.faults.drop_before = Some(CommandMatch {
        contains: "DATA:ARBitrary:DAC".into(),
        nth: 1,
    });
    let connect = |sim: &SimGenerator| -> Box<dyn crate::transport::Transport> {
        let (host, dev) = MemoryTransport::pair("gen", "gen-dev", 1 << 20);
        let served = sim.clone();
        tokio::spawn(async move { served.serve(dev, false).await });
        Box::new(host)
    };
    let first = connect(&sim);
    let mut spare = Some(connect(&sim));
    let mut g = ScpiGenerator::new(first, GeneratorOptions::default()).with_reconnect(Box::new(
        move || {
            let next = spare.take();
            Box::pin(async move {
                next.ok_or_else(|| crate::transport::TransportError::Socket {
                    port: "mem:gen".into(),
                    detail: "no more connections".into(),
                })
            })
        },
    ));
    g.identify().await.unwrap();
    g.prepare_sine().await.unwrap();
    let samples: Vec<f64> = (0..512).map(|i| ((i % 64) as f64 / 32.0) - 1.0).collect();
    let codes = g.play_arbitrary(&samples, 5120.0).await.unwrap();
    assert_eq!(codes.len(), 512);
    let kinds: Vec<&str> = lock(&sim.shared).injected.iter().map(|f| f.kind).collect();
    assert_eq!(kinds, ["generator_drop_before"]);
    let st = sim.state();
    let (name, played) = st.uploaded.clone().unwrap();
    assert_eq!((name.as_str(), played.samples.len()), ("IDENT", 512));
    assert_eq!(st.selected.as_deref(), Some("IDENT"));
    assert!(st.arbitrary && (st.sample_rate_hz - 5120.0).abs() < 1e-9);
}
