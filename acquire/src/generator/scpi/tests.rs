//! The driver against recorded transcripts: the command lines a host sends and the answers the
//! instruments give, as their programming manuals show them.

use super::scripted;
use super::*;
use crate::transport::MemoryTransport;
use crate::transport::{Line, LineBuffer};
use tokio::task::JoinHandle;

/// One exchange: the line the host must send, and the lines the instrument answers.
type Exchange = (&'static str, &'static [&'static str]);

const OK_K: &[&str] = &["1"];
const NOERR_K: &[&str] = &["+0,\"No error\""];
const NOERR: &[&str] = &["0,\"No error\""];

/// A scripted instrument on text lines (answers end in CR LF). Returns every line it received.
fn instrument(script: Vec<Exchange>) -> (Box<dyn Transport>, JoinHandle<Vec<String>>) {
    let mut lines = LineBuffer::new();
    let frame = move |bytes: &[u8], out: &mut Vec<String>| {
        lines.feed(bytes, |l| {
            if let Line::Text(t) = l {
                out.push(t)
            }
        })
    };
    scripted::instrument(script, frame, |(cmd, answers), t| {
        (cmd == t).then(|| answers.iter().map(|a| format!("{a}\r\n")).collect())
    })
}

fn opts() -> GeneratorOptions {
    GeneratorOptions {
        timeout: Duration::from_millis(150),
        retries: 1,
        ..GeneratorOptions::default()
    }
}

/// A setting as the manuals' examples run it: the command, `*OPC?`, the error queue.
fn setting(
    cmd: &'static str,
    err_query: &'static str,
    no_error: &'static [&'static str],
) -> [Exchange; 3] {
    [(cmd, &[]), ("*OPC?", OK_K), (err_query, no_error)]
}

/// A setting, then its read-back: `query` answered by `answer`.
fn read_back(
    cmd: &'static str,
    err_query: &'static str,
    no_error: &'static [&'static str],
    query: &'static str,
    answer: &'static [&'static str],
) -> [Exchange; 4] {
    let [a, b, c] = setting(cmd, err_query, no_error);
    [a, b, c, (query, answer)]
}

fn commands(script: &[Exchange]) -> Vec<String> {
    script.iter().map(|(c, _)| c.to_string()).collect()
}

#[tokio::test]
async fn keysight_33512b_sine_setup_drive_and_output() {
    let e = "SYSTem:ERRor?";
    let mut script: Vec<Exchange> = vec![(
        "*IDN?",
        &["Keysight Technologies,33512B,MY52300123,5.03-3.15-2.00-58-00"],
    )];
    script.push(("*CLS", &[]));
    for c in [
        "*RST",
        "OUTPut1 OFF",
        "OUTPut1:LOAD INFinity",
        "SOURce1:FUNCtion SINusoid",
        "SOURce1:VOLTage:UNIT VPP",
        "SOURce1:VOLTage:OFFSet 0",
    ] {
        script.extend(setting(c, e, NOERR_K));
    }
    // The idle amplitude is the 33500B's smallest into a high impedance (2 mVpp; 1 mVpp is its
    // smallest into 50 Ω and answers -222 after `OUTPut1:LOAD INFinity`). Every amplitude and
    // frequency is read back in the instrument's own number format.
    let v = "SOURce1:VOLTage?";
    script.extend(read_back(
        "SOURce1:VOLTage 0.002",
        e,
        NOERR_K,
        v,
        &["+2.00000000000000E-03"],
    ));
    script.extend(read_back(
        "SOURce1:FREQuency 120.5",
        e,
        NOERR_K,
        "SOURce1:FREQuency?",
        &["+1.20500000000000E+02"],
    ));
    script.extend(read_back(
        "SOURce1:VOLTage 3",
        e,
        NOERR_K,
        v,
        &["+3.00000000000000E+00"],
    ));
    script.extend(read_back("OUTPut1 ON", e, NOERR_K, "OUTPut1?", &["1"]));
    script.push(("OUTPut1?", &["1"]));
    let (io, dev) = instrument(script.clone());
    let mut g = ScpiGenerator::new(io, opts());
    let id = g.identify().await.unwrap();
    assert_eq!(
        (id.manufacturer.as_str(), id.model.as_str()),
        ("Keysight Technologies", "33512B")
    );
    g.prepare_sine().await.unwrap();
    g.set_frequency(120.5).await.unwrap();
    assert_eq!(g.set_amplitude(1.5).await.unwrap(), 1.5);
    g.set_output(true).await.unwrap();
    assert!(g.output().await.unwrap());
    drop(g);
    assert_eq!(dev.await.unwrap(), commands(&script));
}

#[tokio::test]
async fn rigol_dg1062z_channel_2_refuses_a_voltage_out_of_range() {
    let e = ":SYST:ERR?";
    let mut script: Vec<Exchange> = vec![(
        "*IDN?",
        &["Rigol Technologies,DG1062Z,DG1ZA2012604198,00.01.14"],
    )];
    script.extend(read_back(
        ":SOUR2:FREQ 80",
        e,
        NOERR,
        ":SOUR2:FREQ?",
        &["8.000000E+01"],
    ));
    script.extend([
        (":SOUR2:VOLT 18", &[] as &[&str]),
        ("*OPC?", OK_K),
        (e, &["-222,\"Data out of range\""]),
        (e, NOERR),
    ]);
    script.push((":OUTP2?", &["OFF"]));
    let (io, dev) = instrument(script.clone());
    let mut g = ScpiGenerator::new(
        io,
        GeneratorOptions {
            channel: 2,
            ..opts()
        },
    );
    g.identify().await.unwrap();
    g.set_frequency(80.0).await.unwrap();
    // Beyond the data sheet's 20 Vpp into a high impedance: refused before anything is sent.
    let err = g.set_amplitude(15.0).await.unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, GeneratorError::Limits { .. }), "{msg}");
    assert!(
        msg.contains("Rigol DG800/DG1000Z") && msg.contains("0.002..20 Vpp into a high impedance"),
        "{msg}"
    );
    // Within it, the instrument's own refusal (here an offset that leaves no room).
    let err = g.set_amplitude(9.0).await.unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, GeneratorError::Instrument { code: -222, .. }),
        "{msg}"
    );
    assert!(
        msg.contains("Rigol Technologies DG1062Z on mem:gen"),
        "{msg}"
    );
    assert!(msg.contains("`:SOUR2:VOLT 18`"), "{msg}");
    assert!(msg.contains("Data out of range"), "{msg}");
    assert!(!g.output().await.unwrap(), "ON/OFF answers are understood");
    drop(g);
    assert_eq!(dev.await.unwrap(), commands(&script));
}

#[tokio::test]
async fn tektronix_afg31022_in_vrms_with_two_queued_errors() {
    let e = "SYSTem:ERRor?";
    let script: Vec<Exchange> = vec![
        ("*IDN?", &["TEKTRONIX,AFG31022,C012345,SCPI:99.0 FV:1.5.2"]),
        ("SOURce1:VOLTage:LEVel:IMMediate:AMPLitude 1.414214", &[]),
        ("*OPC?", OK_K),
        (e, NOERR),
        (
            "SOURce1:VOLTage:LEVel:IMMediate:AMPLitude?",
            &["1.4142E+00"],
        ),
        ("OUTPut1:STATe ON", &[]),
        ("*OPC?", OK_K),
        (e, &["-221,\"Settings conflict; amplitude\""]),
        (e, &["-350,\"Queue overflow\""]),
        (e, NOERR),
    ];
    let (io, dev) = instrument(script.clone());
    let mut g = ScpiGenerator::new(
        io,
        GeneratorOptions {
            overrides: DialectOverrides {
                unit: Some(dialect::AmplitudeUnit::Vrms),
                ..Default::default()
            },
            ..opts()
        },
    );
    g.identify().await.unwrap();
    assert_eq!(g.dialect().unwrap().unit, dialect::AmplitudeUnit::Vrms);
    g.set_amplitude(2.0).await.unwrap();
    let msg = g.set_output(true).await.unwrap_err().to_string();
    assert!(msg.contains("`OUTPut1:STATe ON` failed: -221"), "{msg}");
    assert!(msg.contains("also queued: -350"), "{msg}");
    drop(g);
    assert_eq!(dev.await.unwrap(), commands(&script));
}

/// A Siglent SDG is refused after `*IDN?`, before any setting, even when the stand names a
/// table: its command set and its list answers are not what the driver reads back.
#[tokio::test]
async fn a_siglent_sdg_is_refused_naming_the_model_and_what_to_use() {
    for named in [None, Some("generic".to_string())] {
        let idn: &[&str] = &["Siglent Technologies,SDG2042X,SDG2XCAD2R3456,2.01.01.35R3"];
        let (io, dev) = instrument(vec![("*IDN?", idn)]);
        let mut g = ScpiGenerator::new(
            io,
            GeneratorOptions {
                dialect: named.clone(),
                ..opts()
            },
        );
        let err = g.identify().await.unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, GeneratorError::Unsupported { .. }), "{msg}");
        assert!(msg.contains("SDG2042X"), "{msg}");
        assert!(msg.contains("C1:BSWV"), "{msg}");
        assert!(msg.contains("Keysight 33500B/33600A"), "{msg}");
        drop(g);
        assert_eq!(dev.await.unwrap(), vec!["*IDN?".to_string()], "{named:?}");
    }
}

#[tokio::test]
async fn an_unknown_model_is_refused_unless_the_stand_names_a_table() {
    let idn: &[&str] = &["ACME Instruments,FG-9000,0001,1.0"];
    let (io, dev) = instrument(vec![("*IDN?", idn)]);
    let mut g = ScpiGenerator::new(io, opts());
    let err = g.identify().await.unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, GeneratorError::UnknownModel { .. }), "{msg}");
    assert!(msg.contains("ACME Instruments,FG-9000"), "{msg}");
    assert!(
        msg.contains("dialect = \\\"generic\\\"") || msg.contains("dialect = \"generic\""),
        "{msg}"
    );
    assert!(msg.contains("Keysight 33500B/33600A"), "{msg}");
    drop(g);
    dev.await.unwrap();

    // Named explicitly, the generic SCPI-99 table drives it.
    let mut script: Vec<Exchange> = vec![("*IDN?", idn)];
    script.extend(read_back(
        "SOUR1:FREQ 50",
        "SYST:ERR?",
        NOERR,
        "SOUR1:FREQ?",
        &["50"],
    ));
    let (io, dev) = instrument(script.clone());
    let mut g = ScpiGenerator::new(
        io,
        GeneratorOptions {
            dialect: Some("generic".into()),
            ..opts()
        },
    );
    g.identify().await.unwrap();
    g.set_frequency(50.0).await.unwrap();
    drop(g);
    assert_eq!(dev.await.unwrap(), commands(&script));

    // A table name that does not exist.
    let (io, _dev) = instrument(vec![("*IDN?", idn)]);
    let mut g = ScpiGenerator::new(
        io,
        GeneratorOptions {
            dialect: Some("Keysight 99999".into()),
            ..opts()
        },
    );
    let msg = g.identify().await.unwrap_err().to_string();
    assert!(
        msg.contains("no command table named `Keysight 99999`"),
        "{msg}"
    );
}

#[tokio::test]
async fn an_undefined_header_names_the_command_and_garbage_is_not_accepted() {
    let script: Vec<Exchange> = vec![
        ("*IDN?", &["IDENT-SIM,SIGGEN-2,G0001,1.0"]),
        ("SOUR1:FREQ 10", &[]),
        ("*OPC?", OK_K),
        ("SYST:ERR?", &["-113,\"Undefined header\""]),
        ("SYST:ERR?", NOERR),
        ("SOUR1:FREQ 20", &[]),
        ("*OPC?", &["maybe"]),
    ];
    let (io, _dev) = instrument(script);
    let mut g = ScpiGenerator::new(io, opts());
    g.identify().await.unwrap();
    let msg = g.set_frequency(10.0).await.unwrap_err().to_string();
    assert!(
        msg.contains("`SOUR1:FREQ 10` failed: -113,\"Undefined header\""),
        "{msg}"
    );
    let err = g.set_frequency(20.0).await.unwrap_err();
    assert!(matches!(err, GeneratorError::Garbled { .. }), "{err}");
}

#[tokio::test]
async fn a_silent_instrument_times_out_after_the_retries() {
    let (io, dev) = instrument(vec![("*IDN?", &[] as &[&str])]);
    let mut g = ScpiGenerator::new(io, opts());
    let err = g.identify().await.unwrap_err();
    assert!(
        matches!(err, GeneratorError::Timeout { attempts: 2, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("`*IDN?`"), "{err}");
    drop(g);
    assert_eq!(dev.await.unwrap(), vec!["*IDN?", "*IDN?"]);
}

#[tokio::test]
async fn a_dropped_connection_is_reopened_once() {
    // The first connection closes at once; the reconnect hands over a working one.
    let (first, dead) = MemoryTransport::pair("gen", "gone", 64);
    drop(dead);
    let (io2, dev) = instrument(vec![("*IDN?", &["IDENT-SIM,SIGGEN-2,G0001,1.0"])]);
    let mut spare = Some(io2);
    let mut g = ScpiGenerator::new(Box::new(first), opts()).with_reconnect(Box::new(move || {
        let next = spare.take();
        Box::pin(async move {
            next.ok_or_else(|| TransportError::Socket {
                port: "mem:gen".into(),
                detail: "no more connections".into(),
            })
        })
    }));
    let id = g.identify().await.unwrap();
    assert_eq!(id.model, "SIGGEN-2");
    drop(g);
    assert_eq!(dev.await.unwrap(), vec!["*IDN?"]);
}

#[tokio::test]
async fn refuses_nonsense_values_and_settings_before_identification() {
    let (io, _dev) = instrument(vec![]);
    let mut g = ScpiGenerator::new(io, opts());
    assert!(matches!(
        g.set_amplitude(1.0).await.unwrap_err(),
        GeneratorError::NotIdentified { .. }
    ));
    assert!(matches!(
        g.set_amplitude(f64::NAN).await.unwrap_err(),
        GeneratorError::InvalidValue { .. }
    ));
    assert!(matches!(
        g.set_frequency(-1.0).await.unwrap_err(),
        GeneratorError::InvalidValue { .. }
    ));
}

/// The first connection answers `*IDN?` as a 33512B and drops at the next command: what a
/// socket reset looks like to the host while a setting is on its way.
fn dropping_connection() -> Box<dyn Transport> {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let (host, mut dev) = MemoryTransport::pair("gen", "gen-dev", 1 << 12);
    tokio::spawn(async move {
        let mut buf = vec![0u8; 256];
        let mut seen = String::new();
        loop {
            let Ok(n) = dev.read(&mut buf).await else {
                return;
            };
            if n == 0 {
                return;
            }
            seen.push_str(&String::from_utf8_lossy(&buf[..n]));
            while let Some(i) = seen.find('\n') {
                let line: String = seen.drain(..=i).collect();
                if line.trim() != "*IDN?" {
                    return;
                }
                let idn = b"Keysight Technologies,33512B,MY1,1.0\r\n";
                let _ = dev.write_all(idn).await;
            }
        }
    });
    Box::new(host)
}

/// A reconnect that hands over `next` once.
fn reconnect_once(next: Box<dyn Transport>) -> Reconnect {
    let mut spare = Some(next);
    Box::new(move || {
        let next = spare.take();
        Box::pin(async move {
            next.ok_or_else(|| TransportError::Socket {
                port: "mem:gen".into(),
                detail: "no more connections".into(),
            })
        })
    })
}

#[tokio::test]
async fn a_setting_lost_with_the_connection_is_sent_again_and_read_back() {
    // The frequency setting is lost with the first connection; on the second, `*OPC?` and the
    // error queue answer, then the setting in flight is sent again and read back.
    let e = "SYSTem:ERRor?";
    let mut script: Vec<Exchange> = vec![("*OPC?", OK_K), (e, NOERR_K)];
    script.extend(read_back(
        "SOURce1:FREQuency 120",
        e,
        NOERR_K,
        "SOURce1:FREQuency?",
        &["+1.20000000000000E+02"],
    ));
    let (io2, dev) = instrument(script.clone());
    let mut g =
        ScpiGenerator::new(dropping_connection(), opts()).with_reconnect(reconnect_once(io2));
    g.identify().await.unwrap();
    g.set_frequency(120.0).await.unwrap();
    drop(g);
    assert_eq!(dev.await.unwrap(), commands(&script));
}

#[tokio::test]
async fn an_error_after_a_dropped_connection_says_the_connection_dropped() {
    // On the second connection the setting sent again is refused: the error says the
    // connection dropped while it was on its way, and what the instrument answered then.
    let e = "SYSTem:ERRor?";
    let script: Vec<Exchange> = vec![
        ("*OPC?", OK_K),
        (e, NOERR_K),
        ("SOURce1:FREQuency 120", &[]),
        ("*OPC?", OK_K),
        (e, &["-221,\"Settings conflict\""]),
        (e, NOERR_K),
    ];
    let (io2, _dev) = instrument(script);
    let mut g =
        ScpiGenerator::new(dropping_connection(), opts()).with_reconnect(reconnect_once(io2));
    g.identify().await.unwrap();
    let err = g.set_frequency(120.0).await.unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, GeneratorError::AfterReconnect { .. }),
        "{msg}"
    );
    assert!(
        msg.contains("connection dropped while `SOURce1:FREQuency 120` was being sent"),
        "{msg}"
    );
    assert!(msg.contains("-221,\"Settings conflict\""), "{msg}");
}

#[tokio::test]
async fn a_setting_that_does_not_read_back_is_an_error() {
    let e = "SYSTem:ERRor?";
    let mut script: Vec<Exchange> = vec![("*IDN?", &["Keysight Technologies,33512B,MY1,1.0"])];
    script.extend(read_back(
        "SOURce1:FREQuency 120",
        e,
        NOERR_K,
        "SOURce1:FREQuency?",
        &["+1.00000000000000E+03"],
    ));
    let (io, _dev) = instrument(script);
    let mut g = ScpiGenerator::new(io, opts());
    g.identify().await.unwrap();
    let err = g.set_frequency(120.0).await.unwrap_err();
    assert!(matches!(err, GeneratorError::ReadBack { .. }), "{err}");
    assert!(
        err.to_string().contains("`SOURce1:FREQuency?` reads back"),
        "{err}"
    );
}
