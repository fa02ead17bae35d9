//! The instruments the simulated generator emulates, each as its own manual and data sheet
//! describe it — written from those documents, not from the driver's command tables, so that a
//! driver mistake shows up as the instrument's refusal: the header nodes its manual lists (which
//! optional nodes, `LOAD` or `IMPedance`), the parameter words its `FUNCtion` takes, its channels,
//! its amplitude, offset and frequency ranges by load, its arbitrary-waveform upload, and how it
//! answers (numbers, the output state, the error queue).

use crate::device::DeviceIdentity;

/// How an instrument writes its answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answers {
    /// Keysight 33500B/33600A: numbers `+1.00000000000000E+03`, the output `1`/`0`, the error
    /// queue `+0,"No error"`.
    Keysight,
    /// Rigol DG800/DG1000Z: numbers `1.000000E+03`, the output `ON`/`OFF`, `0,"No error"`.
    Rigol,
    /// Tektronix AFG31000: numbers `1.0000E+03`, the output `1`/`0`, `0,"No error"`.
    Tektronix,
    /// The plain simulated generator: numbers `1E3`, `1`/`0`, `0,"No error"`.
    Plain,
}

/// How an instrument takes an arbitrary waveform.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Upload {
    /// `SOURce1:DATA:ARBitrary:DAC name,<block>`: signed codes −32767..32767, most-significant
    /// byte first unless `FORMat:BORDer SWAPped`; `FUNCtion:ARBitrary name`, `FUNCtion ARB`,
    /// `FUNCtion:ARBitrary:SRATe`.
    KeysightDac,
    /// `:SOURce1:TRACe:DATA:DAC16 VOLATILE,END,<block>`: unsigned codes 0..16383, least-significant
    /// byte first; `END` switches the channel to the waveform; `FUNCtion:ARB:SRATe`.
    RigolDac16,
    /// `TRACe:DATA EMEMory1,<block>`: unsigned codes 0..16383, most-significant byte first, into
    /// the channel's edit memory; `FUNCtion:SHAPe EMEMory1` plays it at `FREQuency:FIXed`
    /// repetitions per second.
    TektronixEmem,
}

/// One emulated instrument.
#[derive(Debug, Clone, PartialEq)]
pub struct Emulation {
    /// The `*IDN?` manufacturer and model this emulation answers for.
    pub manufacturer: &'static str,
    /// Model.
    pub model: &'static str,
    /// The documents this emulation is written from.
    pub source: &'static str,
    /// Output channels.
    pub channels: u8,
    /// Optional header nodes its manual lists (long forms), beyond `SOURce`.
    pub optional_nodes: &'static [&'static str],
    /// The load header node(s) it has (`LOAD`, `IMPEDANCE`).
    pub load_nodes: &'static [&'static str],
    /// `FUNCtion` parameter words (long form, short form; equal when the manual lists one).
    pub functions: &'static [(&'static str, &'static str)],
    /// The word that selects the arbitrary waveform (`ARB`, `USER`, `EMEMORY1`).
    pub arbitrary_word: &'static str,
    /// Sine amplitude range into 50 Ω (Vpp); twice it into a high impedance.
    pub amplitude_50_ohm_vpp: (f64, f64),
    /// Largest |offset| + peak into 50 Ω (V); twice it into a high impedance.
    pub offset_50_ohm_v: f64,
    /// Highest sine frequency (Hz); the lowest is 1 µHz on all of them.
    pub max_frequency_hz: f64,
    /// Its arbitrary-waveform upload.
    pub upload: Upload,
    /// Most points of one upload.
    pub max_points: usize,
    /// Highest arbitrary sample rate (Sa/s).
    pub max_sample_rate_hz: f64,
    /// Answer formats.
    pub answers: Answers,
    /// The error-queue text of a value out of range.
    pub out_of_range: &'static str,
}

/// Lowest sine frequency of every emulated instrument (Hz).
pub const MIN_FREQUENCY_HZ: f64 = 1e-6;

/// Function words of the Keysight 33500B `FUNCtion` (Operating and Service Guide): `ARB` has no
/// long form.
const KEYSIGHT_FUNCTIONS: &[(&str, &str)] = &[
    ("SINUSOID", "SIN"),
    ("SQUARE", "SQU"),
    ("TRIANGLE", "TRI"),
    ("RAMP", "RAMP"),
    ("PULSE", "PULS"),
    ("PRBS", "PRBS"),
    ("NOISE", "NOIS"),
    ("ARB", "ARB"),
    ("DC", "DC"),
];

/// Function words of the Rigol DG1000Z `:SOURce<n>:FUNCtion[:SHAPe]` (Programming Guide).
const RIGOL_FUNCTIONS: &[(&str, &str)] = &[
    ("SINUSOID", "SIN"),
    ("SQUARE", "SQU"),
    ("RAMP", "RAMP"),
    ("PULSE", "PULS"),
    ("NOISE", "NOIS"),
    ("USER", "USER"),
    ("HARMONIC", "HARM"),
    ("DC", "DC"),
];

/// Function words of the Tektronix AFG31000 `FUNCtion:SHAPe` (Programmer Manual).
const TEKTRONIX_FUNCTIONS: &[(&str, &str)] = &[
    ("SINUSOID", "SIN"),
    ("SQUARE", "SQU"),
    ("PULSE", "PULS"),
    ("RAMP", "RAMP"),
    ("PRNOISE", "PRN"),
    ("DC", "DC"),
    ("EMEMORY1", "EMEM1"),
    ("EMEMORY2", "EMEM2"),
    ("EMEMORY", "EMEM"),
];

/// The plain simulated generator takes the words of all three, long forms included.
const PLAIN_FUNCTIONS: &[(&str, &str)] = &[
    ("SINUSOID", "SIN"),
    ("SQUARE", "SQU"),
    ("TRIANGLE", "TRI"),
    ("RAMP", "RAMP"),
    ("PULSE", "PULS"),
    ("PRBS", "PRBS"),
    ("NOISE", "NOIS"),
    ("ARBITRARY", "ARB"),
    ("DC", "DC"),
];

/// The optional nodes the Tektronix and Rigol manuals list (`VOLTage[:LEVel][:IMMediate]
/// [:AMPLitude]`, `FREQuency[:FIXed]`, `FUNCtion[:SHAPe]`, `OUTPut[:STATe]`).
const LEVEL_NODES: &[&str] = &[
    "LEVEL",
    "IMMEDIATE",
    "AMPLITUDE",
    "FIXED",
    "SHAPE",
    "STATE",
    "CW",
];

impl Emulation {
    /// Keysight 33522B (two channels, 30 MHz): the 33500B Series Operating and Service Guide and
    /// data sheet.
    pub fn keysight_33522b() -> Emulation {
        Emulation {
            manufacturer: "Keysight Technologies",
            model: "33522B",
            source: "Keysight 33500B Series Operating and Service Guide; 33500B Series data sheet",
            channels: 2,
            optional_nodes: &[],
            load_nodes: &["LOAD"],
            functions: KEYSIGHT_FUNCTIONS,
            arbitrary_word: "ARB",
            amplitude_50_ohm_vpp: (0.001, 10.0),
            offset_50_ohm_v: 5.0,
            max_frequency_hz: 30e6,
            upload: Upload::KeysightDac,
            max_points: 1_000_000,
            max_sample_rate_hz: 250e6,
            answers: Answers::Keysight,
            out_of_range: "Data out of range",
        }
    }

    /// Rigol DG1062Z (two channels, 60 MHz): the DG1000Z Programming Guide and data sheet.
    pub fn rigol_dg1062z() -> Emulation {
        Emulation {
            manufacturer: "Rigol Technologies",
            model: "DG1062Z",
            source: "Rigol DG1000Z Programming Guide; DG1000Z data sheet",
            channels: 2,
            optional_nodes: LEVEL_NODES,
            load_nodes: &["LOAD", "IMPEDANCE"],
            functions: RIGOL_FUNCTIONS,
            arbitrary_word: "USER",
            amplitude_50_ohm_vpp: (0.001, 10.0),
            offset_50_ohm_v: 5.0,
            max_frequency_hz: 60e6,
            upload: Upload::RigolDac16,
            max_points: 16_384,
            max_sample_rate_hz: 60e6,
            answers: Answers::Rigol,
            out_of_range: "Data out of range",
        }
    }

    /// Tektronix AFG31022 (two channels, 25 MHz): the AFG31000 Programmer Manual and data sheet.
    pub fn tektronix_afg31022() -> Emulation {
        Emulation {
            manufacturer: "TEKTRONIX",
            model: "AFG31022",
            source: "Tektronix AFG31000 Series Programmer Manual; AFG31000 data sheet",
            channels: 2,
            optional_nodes: LEVEL_NODES,
            load_nodes: &["IMPEDANCE"],
            functions: TEKTRONIX_FUNCTIONS,
            arbitrary_word: "EMEMORY1",
            amplitude_50_ohm_vpp: (0.001, 10.0),
            offset_50_ohm_v: 5.0,
            max_frequency_hz: 25e6,
            upload: Upload::TektronixEmem,
            max_points: 131_072,
            max_sample_rate_hz: 250e6,
            answers: Answers::Tektronix,
            out_of_range: "Data out of range",
        }
    }

    /// The plain simulated generator (`IDENT-SIM,SIGGEN-2`): the 33500B's ranges and upload,
    /// every optional node of the three manuals, `LOAD` and `IMPedance`.
    pub fn plain() -> Emulation {
        Emulation {
            manufacturer: "IDENT-SIM",
            model: "SIGGEN-2",
            source: "acquire::sim::generator",
            channels: 2,
            optional_nodes: LEVEL_NODES,
            load_nodes: &["LOAD", "IMPEDANCE"],
            functions: PLAIN_FUNCTIONS,
            arbitrary_word: "ARB",
            amplitude_50_ohm_vpp: (0.001, 10.0),
            offset_50_ohm_v: 5.0,
            max_frequency_hz: 20e6,
            upload: Upload::KeysightDac,
            max_points: 65_536,
            max_sample_rate_hz: 1e6,
            answers: Answers::Plain,
            out_of_range: "Data out of range",
        }
    }

    /// Every emulation.
    pub fn all() -> [Emulation; 4] {
        [
            Emulation::keysight_33522b(),
            Emulation::rigol_dg1062z(),
            Emulation::tektronix_afg31022(),
            Emulation::plain(),
        ]
    }

    /// The emulation for a stand's expected identity (`manufacturer,model`, compared
    /// case-insensitively): the plain simulated generator for any other.
    pub fn for_identity(identity: &str) -> Emulation {
        let (maker, model) = identity.split_once(',').unwrap_or((identity, ""));
        Emulation::all()
            .into_iter()
            .find(|e| {
                e.manufacturer.eq_ignore_ascii_case(maker.trim())
                    && e.model.eq_ignore_ascii_case(model.trim())
            })
            .unwrap_or_else(Emulation::plain)
    }

    /// The `*IDN?` identity.
    pub fn identity(&self, firmware: &str) -> DeviceIdentity {
        DeviceIdentity {
            manufacturer: self.manufacturer.into(),
            model: self.model.into(),
            serial: "SIM00001".into(),
            firmware: firmware.into(),
        }
    }

    /// The amplitude range (Vpp) at a load (`high_z`): the data sheet's 50 Ω range, doubled
    /// into a high impedance (the same output voltage).
    pub fn amplitude_vpp(&self, high_z: bool) -> (f64, f64) {
        let k = if high_z { 2.0 } else { 1.0 };
        (
            k * self.amplitude_50_ohm_vpp.0,
            k * self.amplitude_50_ohm_vpp.1,
        )
    }

    /// Largest |offset| + peak (V) at a load.
    pub fn offset_limit_v(&self, high_z: bool) -> f64 {
        if high_z {
            2.0 * self.offset_50_ohm_v
        } else {
            self.offset_50_ohm_v
        }
    }

    /// The canonical function word (long form) for `word`, if the manual lists it.
    pub fn function(&self, word: &str) -> Option<&'static str> {
        let w = word.to_ascii_uppercase();
        self.functions
            .iter()
            .find(|(long, short)| w == *long || w == *short)
            .map(|(long, _)| *long)
    }

    /// A number as the instrument writes it.
    pub fn number(&self, x: f64) -> String {
        match self.answers {
            Answers::Keysight => nr3(x, 14, true),
            Answers::Rigol => nr3(x, 6, false),
            Answers::Tektronix => nr3(x, 4, false),
            Answers::Plain => format!("{x:E}"),
        }
    }

    /// The output state as the instrument writes it.
    pub fn state(&self, on: bool) -> &'static str {
        match (self.answers, on) {
            (Answers::Rigol, true) => "ON",
            (Answers::Rigol, false) => "OFF",
            (_, true) => "1",
            (_, false) => "0",
        }
    }

    /// An error-queue entry as the instrument writes it.
    pub fn error_entry(&self, code: i32, message: &str) -> String {
        match self.answers {
            Answers::Keysight => format!("{code:+},\"{message}\""),
            _ => format!("{code},\"{message}\""),
        }
    }
}

/// `x` in IEEE 488.2 NR3 form with `decimals` mantissa digits and a two-digit signed exponent
/// (`+1.00000000000000E+03` with `plus`, `1.000000E+03` without).
fn nr3(x: f64, decimals: usize, plus: bool) -> String {
    let sign = if x < 0.0 {
        "-"
    } else if plus {
        "+"
    } else {
        ""
    };
    let a = x.abs();
    let (mut m, mut e) = if a == 0.0 {
        (0.0, 0i32)
    } else {
        let e = a.log10().floor() as i32;
        (a / 10f64.powi(e), e)
    };
    // Rounding the mantissa to its digits may carry into the next power of ten.
    let scale = 10f64.powi(decimals as i32);
    if (m * scale).round() / scale >= 10.0 {
        m /= 10.0;
        e += 1;
    }
    let esign = if e < 0 { '-' } else { '+' };
    format!("{sign}{m:.decimals$}E{esign}{:02}", e.abs())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn answers_in_each_manuals_form() {
        let k = Emulation::keysight_33522b();
        assert_eq!(k.number(1000.0), "+1.00000000000000E+03");
        assert_eq!(k.number(0.002), "+2.00000000000000E-03");
        assert_eq!(k.error_entry(0, "No error"), "+0,\"No error\"");
        assert_eq!(
            k.error_entry(-222, "Data out of range"),
            "-222,\"Data out of range\""
        );
        let r = Emulation::rigol_dg1062z();
        assert_eq!(r.number(120.5), "1.205000E+02");
        assert_eq!(r.state(true), "ON");
        assert_eq!(r.error_entry(0, "No error"), "0,\"No error\"");
        assert_eq!(
            Emulation::tektronix_afg31022().number(9.99996),
            "1.0000E+01"
        );
        for e in Emulation::all() {
            for x in [1e-6, 0.002, 3.5, 120.5, 2.5e7] {
                let back: f64 = e.number(x).parse().unwrap();
                assert!((back - x).abs() <= 1e-4 * x, "{} {x}", e.model);
            }
        }
    }

    #[test]
    fn the_33500b_takes_arb_and_not_a_long_form_it_does_not_list() {
        let k = Emulation::keysight_33522b();
        assert_eq!(k.function("ARB"), Some("ARB"));
        assert_eq!(k.function("ARBitrary"), None);
        assert_eq!(k.function("sinusoid"), Some("SINUSOID"));
        assert_eq!(
            Emulation::tektronix_afg31022().function("EMEM1"),
            Some("EMEMORY1")
        );
        assert_eq!(
            Emulation::for_identity("Keysight Technologies,33522B").model,
            "33522B"
        );
        assert_eq!(
            Emulation::for_identity("IDENT-SIM,SIGGEN-2").model,
            "SIGGEN-2"
        );
        assert_eq!(Emulation::for_identity("").model, "SIGGEN-2");
        assert_eq!(k.amplitude_vpp(true), (0.002, 20.0));
    }
}
