//! SCPI headers as the simulated generator reads them: long or short form of each mnemonic
//! (IEEE 488.2 / SCPI-99 rules), a channel suffix on `SOURce`/`OUTPut`, and the optional nodes —
//! which an emulated instrument accepts only when its manual lists them.

/// A command's header reduced to its canonical short-form path.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    /// The path without optional nodes (`SOURce2:VOLTage:LEVel:IMMediate:AMPLitude` → `[VOLT]`).
    pub path: Vec<&'static str>,
    /// The channel suffix (1 when none).
    pub channel: u8,
    /// The optional nodes used (long forms), for the emulation to check against its manual.
    pub optional: Vec<&'static str>,
}

/// An error-queue entry: code and message.
pub type ScpiFault = (i32, String);

/// `-113,"Undefined header"`.
pub fn undefined() -> ScpiFault {
    (-113, "Undefined header".into())
}

/// Long form, short form of the mnemonics the simulated generator knows; `None` = an optional
/// node that changes nothing (`SOURce`, `LEVel`, `IMMediate`, …).
const MNEMONICS: [(&str, &str, Option<&str>); 30] = [
    ("NEXT", "NEXT", None),
    ("SOURCE", "SOUR", None),
    ("LEVEL", "LEV", None),
    ("IMMEDIATE", "IMM", None),
    ("AMPLITUDE", "AMPL", None),
    ("STATE", "STAT", None),
    ("FIXED", "FIX", None),
    ("SHAPE", "SHAP", None),
    ("CW", "CW", None),
    ("FUNCTION", "FUNC", Some("FUNC")),
    ("FREQUENCY", "FREQ", Some("FREQ")),
    ("VOLTAGE", "VOLT", Some("VOLT")),
    ("UNIT", "UNIT", Some("UNIT")),
    ("OFFSET", "OFFS", Some("OFFS")),
    ("OUTPUT", "OUTP", Some("OUTP")),
    ("LOAD", "LOAD", Some("LOAD")),
    ("IMPEDANCE", "IMP", Some("IMP")),
    ("SYSTEM", "SYST", Some("SYST")),
    ("ERROR", "ERR", Some("ERR")),
    ("DATA", "DATA", Some("DATA")),
    ("ARBITRARY", "ARB", Some("ARB")),
    ("DAC", "DAC", Some("DAC")),
    ("DAC16", "DAC16", Some("DAC16")),
    ("VOLATILE", "VOL", Some("VOL")),
    ("CLEAR", "CLE", Some("CLE")),
    ("SRATE", "SRAT", Some("SRAT")),
    ("FORMAT", "FORM", Some("FORM")),
    ("BORDER", "BORD", Some("BORD")),
    ("TRACE", "TRAC", Some("TRAC")),
    ("MODE", "MODE", Some("MODE")),
];

/// The mnemonic `name` (no suffix) as (long form, canonical), if known.
fn mnemonic(name: &str) -> Option<(&'static str, Option<&'static str>)> {
    let upper = name.to_ascii_uppercase();
    MNEMONICS
        .iter()
        .find(|(long, short, _)| upper == *long || upper == *short)
        .map(|(long, _, canon)| (*long, *canon))
}

/// A header as its canonical path, channel and optional nodes. Unknown mnemonics are
/// `-113 Undefined header`; a suffix other than on `SOURce`/`OUTPut` too.
pub fn canonical(header: &str) -> Result<Header, ScpiFault> {
    let mut h = Header {
        path: Vec::new(),
        channel: 1,
        optional: Vec::new(),
    };
    for node in header.trim_start_matches(':').split(':') {
        // A mnemonic that ends in digits (`DAC16`) is whole; otherwise the digits are a suffix.
        let (long, canon) = match mnemonic(node) {
            Some(m) => m,
            None => {
                let digits = node.len() - node.trim_end_matches(|c: char| c.is_ascii_digit()).len();
                let (name, suffix) = node.split_at(node.len() - digits);
                let (long, canon) = mnemonic(name).ok_or_else(undefined)?;
                if suffix.is_empty() || !matches!(long, "SOURCE" | "OUTPUT") {
                    return Err(undefined());
                }
                h.channel = suffix
                    .parse()
                    .map_err(|_| (-114, "Header suffix out of range".to_string()))?;
                (long, canon)
            }
        };
        match canon {
            Some(c) => h.path.push(c),
            None => h.optional.push(long),
        }
    }
    Ok(h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_of_the_three_manuals_reduce_to_one_path() {
        let c = |h: &str| {
            let h = canonical(h).unwrap();
            (h.path, h.channel)
        };
        assert_eq!(
            c("SOURce1:VOLTage:LEVel:IMMediate:AMPLitude"),
            (vec!["VOLT"], 1)
        );
        assert_eq!(c(":SOUR2:VOLT"), (vec!["VOLT"], 2));
        assert_eq!(c("sour:volt:offs"), (vec!["VOLT", "OFFS"], 1));
        assert_eq!(c("SOURce1:FUNCtion:SHAPe"), (vec!["FUNC"], 1));
        assert_eq!(c("SOURce1:FREQuency:FIXed"), (vec!["FREQ"], 1));
        assert_eq!(c("OUTPut2:STATe"), (vec!["OUTP"], 2));
        assert_eq!(c("OUTP1:IMPedance"), (vec!["OUTP", "IMP"], 1));
        assert_eq!(c("SYSTem:ERRor"), (vec!["SYST", "ERR"], 1));
        assert_eq!(c("SYST:ERR:NEXT"), (vec!["SYST", "ERR"], 1));
        assert_eq!(
            c(":SOUR1:TRAC:DATA:DAC16"),
            (vec!["TRAC", "DATA", "DAC16"], 1)
        );
        let h = canonical("SOURce1:VOLTage:LEVel:IMMediate:AMPLitude").unwrap();
        assert_eq!(h.optional, ["SOURCE", "LEVEL", "IMMEDIATE", "AMPLITUDE"]);
        assert!(canonical("SOUR1:FORCe").is_err());
        assert!(
            canonical("VOLT3").is_err(),
            "a suffix only on SOURce/OUTPut"
        );
        assert!(
            canonical("SOURc:VOLT").is_err(),
            "neither long nor short form"
        );
    }
}
