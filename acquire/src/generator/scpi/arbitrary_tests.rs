//! The arbitrary-waveform upload against transcripts of the programming manuals' command forms:
//! Keysight 33500B (`DATA:ARBitrary:DAC` with a byte-swapped binary block), Rigol DG1000Z
//! (`TRACe:DATA:DAC16`, refused with an error-queue answer), Tektronix AFG31000 (`TRACe:DATA
//! EMEMory`, MSB first, a repetition frequency), a model without uploads and one over its limits.

use super::scripted;
use super::*;
use crate::generator::arbitrary::{definite_block, CommandFramer};
use tokio::task::JoinHandle;

/// One exchange: the command text the host must send, the binary block it must carry (if any),
/// and the lines the instrument answers.
type Exchange = (String, Option<Vec<u8>>, Vec<&'static str>);

/// A command as received: its text and its binary block.
type Received = (String, Option<Vec<u8>>);

/// A scripted instrument that frames binary blocks as IEEE 488.2 instruments do (answers end in
/// LF). Returns every command (text, block) it received.
fn instrument(script: Vec<Exchange>) -> (Box<dyn Transport>, JoinHandle<Vec<Received>>) {
    let mut framer = CommandFramer::new();
    let frame = move |bytes: &[u8], out: &mut Vec<Received>| {
        framer.feed(bytes, |c| out.push((c.text, c.block)))
    };
    scripted::instrument(script, frame, |(text, block, answers), (t, b)| {
        (text == t && block == b).then(|| answers.iter().map(|a| format!("{a}\n")).collect())
    })
}

fn opts(channel: u8) -> GeneratorOptions {
    GeneratorOptions {
        channel,
        timeout: Duration::from_millis(150),
        retries: 1,
        ..GeneratorOptions::default()
    }
}

fn cmd(text: &str, answers: &[&'static str]) -> Exchange {
    (text.to_string(), None, answers.to_vec())
}

/// A setting: the command, `*OPC?` answered 1, the error queue empty.
fn setting(text: &str, err: &str, no_error: &'static str) -> Vec<Exchange> {
    vec![cmd(text, &[]), cmd("*OPC?", &["1"]), cmd(err, &[no_error])]
}

fn sent(script: &[Exchange]) -> Vec<Received> {
    script
        .iter()
        .map(|(t, b, _)| (t.clone(), b.clone()))
        .collect()
}

/// Eight samples whose codes include bytes that are a newline and a `#` in the block.
fn samples() -> Vec<f64> {
    vec![
        0.0,
        10.0 / 32767.0,
        1.0,
        -1.0,
        0.5,
        -0.5,
        35.0 / 32767.0,
        0.0,
    ]
}

#[tokio::test]
async fn keysight_33512b_uploads_a_byte_swapped_block_and_selects_it() {
    let e = "SYSTem:ERRor?";
    let ok = "+0,\"No error\"";
    // Signed codes, least-significant byte first after FORMat:BORDer SWAPped.
    let codes: [i16; 8] = [0, 10, 32767, -32767, 16384, -16384, 35, 0];
    let payload: Vec<u8> = codes.iter().flat_map(|c| c.to_le_bytes()).collect();
    assert!(payload.contains(&b'\n') && payload.contains(&b'#'));
    let mut script = vec![cmd(
        "*IDN?",
        &["Keysight Technologies,33512B,MY52300123,5.03-3.15-2.00-58-00"],
    )];
    script.extend(setting("FORMat:BORDer SWAPped", e, ok));
    script.extend(setting("SOURce1:DATA:VOLatile:CLEar", e, ok));
    script.push((
        "SOURce1:DATA:ARBitrary:DAC IDENT,".into(),
        Some(payload.clone()),
        vec![],
    ));
    script.push(cmd("*OPC?", &["1"]));
    script.push(cmd(e, &[ok]));
    script.extend(setting("SOURce1:FUNCtion:ARBitrary IDENT", e, ok));
    script.extend(setting("SOURce1:FUNCtion ARB", e, ok));
    script.extend(setting("SOURce1:FUNCtion:ARBitrary:SRATe 5120", e, ok));
    let (io, dev) = instrument(script.clone());
    let mut g = ScpiGenerator::new(io, opts(1));
    g.identify().await.unwrap();
    assert_eq!(g.model_name(), "Keysight 33500B/33600A");
    let a = g.arbitrary().unwrap();
    assert_eq!(
        &a.data_bytes(&[1])[..],
        &[b'#', b'1', b'2', 1, 0],
        "one point: #12 and LSB first"
    );
    let sent_codes = g.play_arbitrary(&samples(), 5120.0).await.unwrap();
    assert_eq!(
        sent_codes,
        codes.iter().map(|c| i32::from(*c)).collect::<Vec<_>>()
    );
    drop(g);
    assert_eq!(dev.await.unwrap(), sent(&script));
    assert_eq!(definite_block(&payload)[..3], *b"#21", "16 bytes: #216");
}

#[tokio::test]
async fn rigol_dg1062z_refuses_an_upload_and_the_error_queue_names_it() {
    let e = ":SYST:ERR?";
    let ok = "0,\"No error\"";
    // Unsigned codes 0..16383, least-significant byte first.
    let codes: [u16; 8] = [8192, 8194, 16383, 0, 12287, 4096, 8200, 8192];
    let payload: Vec<u8> = codes.iter().flat_map(|c| c.to_le_bytes()).collect();
    let mut script = vec![cmd(
        "*IDN?",
        &["Rigol Technologies,DG1062Z,DG1ZA2012604198,00.01.14"],
    )];
    script.extend(setting(":SOUR2:FUNC:ARB:MODE SRATe", e, ok));
    script.push((
        ":SOUR2:TRAC:DATA:DAC16 VOLATILE,END,".into(),
        Some(payload),
        vec![],
    ));
    script.push(cmd("*OPC?", &["1"]));
    script.push(cmd(e, &["-223,\"Too much data\""]));
    script.push(cmd(e, &[ok]));
    let (io, dev) = instrument(script.clone());
    let mut g = ScpiGenerator::new(io, opts(2));
    g.identify().await.unwrap();
    let err = g.play_arbitrary(&samples(), 5120.0).await.unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, GeneratorError::Instrument { code: -223, .. }),
        "{msg}"
    );
    assert!(
        msg.contains(
            "`:SOUR2:TRAC:DATA:DAC16 VOLATILE,END,<8 points>` failed: -223,\"Too much data\""
        ),
        "{msg}"
    );
    assert!(msg.contains("Rigol Technologies DG1062Z"), "{msg}");
    drop(g);
    assert_eq!(
        dev.await.unwrap(),
        sent(&script),
        "nothing selected after the refusal"
    );
}

#[tokio::test]
async fn tektronix_afg31022_takes_msb_first_codes_and_a_repetition_frequency() {
    let e = "SYSTem:ERRor?";
    let ok = "0,\"No error\"";
    let codes: [u16; 8] = [8192, 8194, 16383, 0, 12287, 4096, 8200, 8192];
    let payload: Vec<u8> = codes.iter().flat_map(|c| c.to_be_bytes()).collect();
    let mut script = vec![cmd(
        "*IDN?",
        &["TEKTRONIX,AFG31022,C012345,SCPI:99.0 FV:1.5.2"],
    )];
    script.push(("TRACe:DATA EMEMory1,".into(), Some(payload), vec![]));
    script.push(cmd("*OPC?", &["1"]));
    script.push(cmd(e, &[ok]));
    script.extend(setting("SOURce1:FUNCtion:SHAPe EMEMory1", e, ok));
    // 8 points at 80 Sa/s repeat 10 times a second.
    script.extend(setting("SOURce1:FREQuency:FIXed 10", e, ok));
    let (io, dev) = instrument(script.clone());
    let mut g = ScpiGenerator::new(io, opts(1));
    g.identify().await.unwrap();
    g.play_arbitrary(&samples(), 80.0).await.unwrap();
    // Over the edit memory: refused before a byte is sent.
    let err = g
        .play_arbitrary(&vec![0.0; 200_000], 80.0)
        .await
        .unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, GeneratorError::ArbitraryLimit { .. }),
        "{msg}"
    );
    assert!(
        msg.contains("Tektronix AFG31000")
            && msg.contains("200000 points")
            && msg.contains("2..131072"),
        "{msg}"
    );
    drop(g);
    assert_eq!(dev.await.unwrap(), sent(&script));
}

#[tokio::test]
async fn a_model_without_uploads_says_so_before_sending_anything() {
    let script = vec![cmd("*IDN?", &["ACME Instruments,FG-9000,0001,1.0"])];
    let (io, dev) = instrument(script.clone());
    let mut g = ScpiGenerator::new(
        io,
        GeneratorOptions {
            dialect: Some("generic".into()),
            ..opts(1)
        },
    );
    g.identify().await.unwrap();
    assert!(g.arbitrary().is_none());
    let err = g.play_arbitrary(&samples(), 5120.0).await.unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, GeneratorError::NoArbitrary { .. }), "{msg}");
    assert!(
        msg.contains("`generic`") && msg.contains("sines only"),
        "{msg}"
    );
    drop(g);
    assert_eq!(dev.await.unwrap(), sent(&script));
}
