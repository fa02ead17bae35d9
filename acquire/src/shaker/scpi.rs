//! The shaker controller's SCPI dialect (docs/shaker-scpi.md), I/O free: command parsing (used by
//! the simulated controller and by any firmware test bench), canonical formatting (used by the
//! host driver) and answer parsing. Its line framing is the transport's ([`LineBuffer`]), shared
//! with every line-oriented instrument.

use std::fmt;

pub use crate::scpi::{
    also_queued, format_error_entry, parse_bool_answer, parse_error_entry, parse_number_answer,
    ScpiError,
};
pub use crate::transport::{Line, LineBuffer, MAX_LINE};

/// A waveform selector as sent with `SOURce:FUNCtion`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Function {
    /// `SINusoid`.
    Sine,
    /// `RANDom`.
    Random,
    /// `BURSt` (burst random).
    Burst,
    /// `CHIRp`.
    Chirp,
}

impl Function {
    /// Short form as answered by `SOUR:FUNC?`.
    pub fn short(&self) -> &'static str {
        match self {
            Function::Sine => "SIN",
            Function::Random => "RAND",
            Function::Burst => "BURS",
            Function::Chirp => "CHIR",
        }
    }

    /// Parses a short or long form, case-insensitively.
    pub fn parse(s: &str) -> Option<Function> {
        [
            (Function::Sine, "SINusoid"),
            (Function::Random, "RANDom"),
            (Function::Burst, "BURSt"),
            (Function::Chirp, "CHIRp"),
        ]
        .into_iter()
        .find(|(_, m)| mnemonic_matches(m, s))
        .map(|(f, _)| f)
    }
}

/// Every command of the dialect. Values in SI units (Hz, N, s, fraction).
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// `*IDN?`
    Identify,
    /// `*RST`
    Reset,
    /// `*CLS`
    ClearStatus,
    /// `*OPC?`
    OperationComplete,
    /// `SOURce:FUNCtion <SIN|RAND|BURS|CHIR>`
    SetFunction(Function),
    /// `SOURce:FUNCtion?`
    QueryFunction,
    /// `SOURce:FREQuency <Hz>`
    SetFrequency(f64),
    /// `SOURce:FREQuency?`
    QueryFrequency,
    /// `SOURce:FREQuency:STARt <Hz>`
    SetBandStart(f64),
    /// `SOURce:FREQuency:STOP <Hz>`
    SetBandStop(f64),
    /// `SOURce:BURSt:DCYCle <percent>` (stored here as a fraction 0-1)
    SetDutyCycle(f64),
    /// `SOURce:PERiod <s>`
    SetPeriod(f64),
    /// `SOURce:FORCe <N>`
    SetForce(f64),
    /// `SOURce:FORCe?`
    QueryForce,
    /// `OUTPut <ON|OFF>`
    SetOutput(bool),
    /// `OUTPut?`
    QueryOutput,
    /// `MEASure:FORCe?`
    MeasureForce,
    /// `STATus:QUEStionable:CONDition?`
    QuestionableCondition,
    /// `SYSTem:ERRor?`
    NextError,
}

impl Command {
    /// True if the command is a query (exactly one answer line follows).
    pub fn is_query(&self) -> bool {
        matches!(
            self,
            Command::Identify
                | Command::OperationComplete
                | Command::QueryFunction
                | Command::QueryFrequency
                | Command::QueryForce
                | Command::QueryOutput
                | Command::MeasureForce
                | Command::QuestionableCondition
                | Command::NextError
        )
    }
}

impl fmt::Display for Command {
    /// The canonical (short-form) line, without terminator.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Command::Identify => write!(f, "*IDN?"),
            Command::Reset => write!(f, "*RST"),
            Command::ClearStatus => write!(f, "*CLS"),
            Command::OperationComplete => write!(f, "*OPC?"),
            Command::SetFunction(x) => write!(f, "SOUR:FUNC {}", x.short()),
            Command::QueryFunction => write!(f, "SOUR:FUNC?"),
            Command::SetFrequency(x) => write!(f, "SOUR:FREQ {x}"),
            Command::QueryFrequency => write!(f, "SOUR:FREQ?"),
            Command::SetBandStart(x) => write!(f, "SOUR:FREQ:STAR {x}"),
            Command::SetBandStop(x) => write!(f, "SOUR:FREQ:STOP {x}"),
            Command::SetDutyCycle(x) => write!(f, "SOUR:BURS:DCYC {}", x * 100.0),
            Command::SetPeriod(x) => write!(f, "SOUR:PER {x}"),
            Command::SetForce(x) => write!(f, "SOUR:FORC {x}"),
            Command::QueryForce => write!(f, "SOUR:FORC?"),
            Command::SetOutput(on) => write!(f, "OUTP {}", if *on { "ON" } else { "OFF" }),
            Command::QueryOutput => write!(f, "OUTP?"),
            Command::MeasureForce => write!(f, "MEAS:FORC?"),
            Command::QuestionableCondition => write!(f, "STAT:QUES:COND?"),
            Command::NextError => write!(f, "SYST:ERR?"),
        }
    }
}

/// Standard codes used by the dialect.
pub mod codes {
    /// No error.
    pub const NO_ERROR: i32 = 0;
    /// Command error (unparseable line).
    pub const COMMAND_ERROR: i32 = -100;
    /// Data type error.
    pub const DATA_TYPE: i32 = -104;
    /// Parameter not allowed.
    pub const PARAMETER_NOT_ALLOWED: i32 = -108;
    /// Missing parameter.
    pub const MISSING_PARAMETER: i32 = -109;
    /// Undefined header.
    pub const UNDEFINED_HEADER: i32 = -113;
    /// Invalid suffix (unit).
    pub const INVALID_SUFFIX: i32 = -131;
    /// Settings conflict (e.g. output on with the interlock open).
    pub const SETTINGS_CONFLICT: i32 = -221;
    /// Data out of range.
    pub const OUT_OF_RANGE: i32 = -222;
    /// Illegal parameter value.
    pub const ILLEGAL_VALUE: i32 = -224;
    /// Error queue overflow.
    pub const QUEUE_OVERFLOW: i32 = -350;
}

/// Bits of the questionable-status condition register (`STAT:QUES:COND?`).
pub mod questionable {
    /// Armature over-travel.
    pub const OVERTRAVEL: u16 = 1 << 0;
    /// Amplifier fault or over-current.
    pub const AMPLIFIER: u16 = 1 << 1;
    /// Safety interlock open.
    pub const INTERLOCK: u16 = 1 << 2;
    /// Over-temperature.
    pub const OVERTEMP: u16 = 1 << 3;
    /// Force limit reached: the requested force cannot be delivered.
    pub const FORCE_LIMIT: u16 = 1 << 4;

    /// Names of the set bits.
    pub fn names(bits: u16) -> Vec<&'static str> {
        [
            (OVERTRAVEL, "armature over-travel"),
            (AMPLIFIER, "amplifier fault"),
            (INTERLOCK, "interlock open"),
            (OVERTEMP, "over-temperature"),
            (FORCE_LIMIT, "force limit reached"),
        ]
        .into_iter()
        .filter(|(b, _)| bits & b != 0)
        .map(|(_, n)| n)
        .collect()
    }
}

/// True if `token` is the long or short form of a mnemonic written as `FREQuency` (short form =
/// the upper-case prefix), compared case-insensitively.
fn mnemonic_matches(mnemonic: &str, token: &str) -> bool {
    let short: String = mnemonic
        .chars()
        .take_while(|c| !c.is_ascii_lowercase())
        .collect();
    token.eq_ignore_ascii_case(mnemonic) || token.eq_ignore_ascii_case(&short)
}

#[derive(Clone, Copy)]
enum Arg {
    None,
    Freq,
    Force,
    Time,
    Percent,
    Func,
    Bool,
}

/// The command tree: nodes (`[x]` optional), whether it is a query, argument type, constructor.
type Ctor = fn(f64, Option<Function>) -> Command;
const TREE: &[(&[&str], bool, Arg, Ctor)] = &[
    (&["*IDN"], true, Arg::None, |_, _| Command::Identify),
    (&["*RST"], false, Arg::None, |_, _| Command::Reset),
    (&["*CLS"], false, Arg::None, |_, _| Command::ClearStatus),
    (&["*OPC"], true, Arg::None, |_, _| {
        Command::OperationComplete
    }),
    (
        &["[SOURce]", "FUNCtion", "[SHAPe]"],
        false,
        Arg::Func,
        |_, f| Command::SetFunction(f.unwrap_or(Function::Sine)),
    ),
    (
        &["[SOURce]", "FUNCtion", "[SHAPe]"],
        true,
        Arg::None,
        |_, _| Command::QueryFunction,
    ),
    (
        &["[SOURce]", "FREQuency", "[CW]"],
        false,
        Arg::Freq,
        |x, _| Command::SetFrequency(x),
    ),
    (
        &["[SOURce]", "FREQuency", "[CW]"],
        true,
        Arg::None,
        |_, _| Command::QueryFrequency,
    ),
    (
        &["[SOURce]", "FREQuency", "STARt"],
        false,
        Arg::Freq,
        |x, _| Command::SetBandStart(x),
    ),
    (
        &["[SOURce]", "FREQuency", "STOP"],
        false,
        Arg::Freq,
        |x, _| Command::SetBandStop(x),
    ),
    (
        &["[SOURce]", "BURSt", "DCYCle"],
        false,
        Arg::Percent,
        |x, _| Command::SetDutyCycle(x),
    ),
    (&["[SOURce]", "PERiod"], false, Arg::Time, |x, _| {
        Command::SetPeriod(x)
    }),
    (
        &["[SOURce]", "FORCe", "[AMPLitude]"],
        false,
        Arg::Force,
        |x, _| Command::SetForce(x),
    ),
    (
        &["[SOURce]", "FORCe", "[AMPLitude]"],
        true,
        Arg::None,
        |_, _| Command::QueryForce,
    ),
    (&["OUTPut", "[STATe]"], false, Arg::Bool, |x, _| {
        Command::SetOutput(x != 0.0)
    }),
    (&["OUTPut", "[STATe]"], true, Arg::None, |_, _| {
        Command::QueryOutput
    }),
    (&["MEASure", "FORCe"], true, Arg::None, |_, _| {
        Command::MeasureForce
    }),
    (
        &["STATus", "QUEStionable", "[CONDition]"],
        true,
        Arg::None,
        |_, _| Command::QuestionableCondition,
    ),
    (&["SYSTem", "ERRor", "[NEXT]"], true, Arg::None, |_, _| {
        Command::NextError
    }),
];

fn header_matches(pattern: &[&str], tokens: &[&str]) -> bool {
    match (pattern.split_first(), tokens.split_first()) {
        (None, None) => true,
        (None, Some(_)) => false,
        (Some((p, rest)), _) => {
            let (optional, name) = match p.strip_prefix('[').and_then(|s| s.strip_suffix(']')) {
                Some(n) => (true, n),
                None => (false, *p),
            };
            let here = match tokens.split_first() {
                Some((t, trest)) if mnemonic_matches(name, t) => header_matches(rest, trest),
                _ => false,
            };
            here || (optional && header_matches(rest, tokens))
        }
    }
}

fn parse_number(s: &str, arg: Arg) -> Result<f64, ScpiError> {
    let s = s.trim();
    let split = s
        .find(|c: char| c.is_ascii_alphabetic() && c != 'e' && c != 'E')
        .unwrap_or(s.len());
    let (num, unit) = s.split_at(split);
    let x: f64 = num.trim().parse().map_err(|_| {
        ScpiError::new(
            codes::DATA_TYPE,
            format!("Data type error;numeric value expected, got {s:?}"),
        )
    })?;
    if !x.is_finite() {
        return Err(ScpiError::new(
            codes::ILLEGAL_VALUE,
            "Illegal parameter value;not finite",
        ));
    }
    let unit = unit.trim().to_ascii_uppercase();
    let scale = match (arg, unit.as_str()) {
        (_, "") => 1.0,
        (Arg::Freq, "HZ") | (Arg::Force, "N") | (Arg::Time, "S") | (Arg::Percent, "PCT") => 1.0,
        (Arg::Freq, "KHZ") | (Arg::Force, "KN") => 1e3,
        (Arg::Time, "MS") => 1e-3,
        _ => {
            return Err(ScpiError::new(
                codes::INVALID_SUFFIX,
                format!("Invalid suffix;{unit}"),
            ))
        }
    };
    Ok(x * scale)
}

/// Parses one command line (terminator already removed). Leading/trailing blanks are ignored.
pub fn parse_command(line: &str) -> Result<Command, ScpiError> {
    let line = line.trim();
    if line.is_empty() {
        return Err(ScpiError::new(
            codes::COMMAND_ERROR,
            "Command error;empty line",
        ));
    }
    let (header, args) = match line.find(|c: char| c.is_ascii_whitespace()) {
        Some(i) => (&line[..i], line[i..].trim()),
        None => (line, ""),
    };
    let (header, query) = match header.strip_suffix('?') {
        Some(h) => (h, true),
        None => (header, false),
    };
    let tokens: Vec<&str> = header.trim_start_matches(':').split(':').collect();
    if tokens.iter().any(|t| t.is_empty()) {
        return Err(ScpiError::new(
            codes::COMMAND_ERROR,
            format!("Command error;{header}"),
        ));
    }
    let Some(&(_, _, arg, ctor)) = TREE
        .iter()
        .find(|(p, q, _, _)| *q == query && header_matches(p, &tokens))
    else {
        return Err(ScpiError::undefined_header(header));
    };
    match arg {
        Arg::None if !args.is_empty() => Err(ScpiError::new(
            codes::PARAMETER_NOT_ALLOWED,
            "Parameter not allowed",
        )),
        Arg::None => Ok(ctor(0.0, None)),
        _ if args.is_empty() => Err(ScpiError::new(
            codes::MISSING_PARAMETER,
            "Missing parameter",
        )),
        Arg::Func => match Function::parse(args) {
            Some(f) => Ok(ctor(0.0, Some(f))),
            None => Err(ScpiError::new(
                codes::ILLEGAL_VALUE,
                format!("Illegal parameter value;{args}"),
            )),
        },
        Arg::Bool => match args.to_ascii_uppercase().as_str() {
            "ON" | "1" => Ok(ctor(1.0, None)),
            "OFF" | "0" => Ok(ctor(0.0, None)),
            _ => Err(ScpiError::new(
                codes::ILLEGAL_VALUE,
                format!("Illegal parameter value;{args}"),
            )),
        },
        Arg::Percent => Ok(ctor(parse_number(args, arg)? / 100.0, None)),
        _ => Ok(ctor(parse_number(args, arg)?, None)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn long_short_and_optional_forms() {
        for l in [
            "SOURce:FREQuency 100",
            "sour:freq 100",
            ":FREQ 100",
            "FREQ:CW 0.1 kHz",
            "source:frequency:cw 100HZ",
        ] {
            assert_eq!(parse_command(l), Ok(Command::SetFrequency(100.0)), "{l}");
        }
        assert_eq!(
            parse_command("SOUR:FORC 4 kN"),
            Ok(Command::SetForce(4000.0))
        );
        assert_eq!(
            parse_command("FORC:AMPL 4000"),
            Ok(Command::SetForce(4000.0))
        );
        assert_eq!(parse_command("outp on"), Ok(Command::SetOutput(true)));
        assert_eq!(
            parse_command("OUTPut:STATe 0"),
            Ok(Command::SetOutput(false))
        );
        assert_eq!(
            parse_command("FUNC random"),
            Ok(Command::SetFunction(Function::Random))
        );
        assert_eq!(
            parse_command("SOUR:BURS:DCYC 25"),
            Ok(Command::SetDutyCycle(0.25))
        );
        assert_eq!(parse_command("SYST:ERR:NEXT?"), Ok(Command::NextError));
        assert_eq!(
            parse_command("stat:ques?"),
            Ok(Command::QuestionableCondition)
        );
        assert_eq!(parse_command("*idn?"), Ok(Command::Identify));
    }

    #[test]
    fn errors_carry_scpi_codes() {
        let code = |l: &str| parse_command(l).unwrap_err().code;
        assert_eq!(code("FREQ:BOGUS 1"), codes::UNDEFINED_HEADER);
        assert_eq!(code("FREQ"), codes::MISSING_PARAMETER);
        assert_eq!(code("FREQ abc"), codes::DATA_TYPE);
        assert_eq!(code("FREQ 10 N"), codes::INVALID_SUFFIX);
        assert_eq!(code("*IDN? 3"), codes::PARAMETER_NOT_ALLOWED);
        assert_eq!(code("OUTP maybe"), codes::ILLEGAL_VALUE);
        assert_eq!(code("FREQ NaN"), codes::DATA_TYPE);
        assert_eq!(code("FREQ 1e999"), codes::ILLEGAL_VALUE);
        assert_eq!(code("SOUR::FREQ 1"), codes::COMMAND_ERROR);
        assert_eq!(code("   "), codes::COMMAND_ERROR);
    }

    #[test]
    fn error_entries_round_trip() {
        let e = ScpiError::out_of_range("force 9000 N > 5000 N");
        assert_eq!(parse_error_entry(&format_error_entry(&e)), Some(e));
        assert_eq!(parse_error_entry("0,\"No error\"").map(|e| e.code), Some(0));
        assert_eq!(parse_error_entry("garbage"), None);
        assert_eq!(parse_error_entry("-1,unquoted"), None);
    }

    #[test]
    fn line_buffer_frames_and_flags_garbage() {
        let mut lb = LineBuffer::new();
        let mut got = Vec::new();
        lb.feed(b"1\r\n0,\"No", |l| got.push(l));
        lb.feed(b" error\"\n\xff\xfe\n", |l| got.push(l));
        lb.feed(&[b'x'; 300], |l| got.push(l));
        lb.feed(b"\nok\n", |l| got.push(l));
        assert_eq!(got[0], Line::Text("1".into()));
        assert_eq!(got[1], Line::Text("0,\"No error\"".into()));
        assert!(matches!(got[2], Line::Garbage(_)));
        assert!(matches!(got[3], Line::Garbage(_)));
        assert_eq!(got[4], Line::Text("ok".into()));
    }

    fn any_command() -> impl Strategy<Value = Command> {
        let v = 1e-3f64..1e5;
        prop_oneof![
            Just(Command::Identify),
            Just(Command::Reset),
            Just(Command::ClearStatus),
            Just(Command::OperationComplete),
            prop_oneof![
                Just(Function::Sine),
                Just(Function::Random),
                Just(Function::Burst),
                Just(Function::Chirp)
            ]
            .prop_map(Command::SetFunction),
            Just(Command::QueryFunction),
            v.clone().prop_map(Command::SetFrequency),
            Just(Command::QueryFrequency),
            v.clone().prop_map(Command::SetBandStart),
            v.clone().prop_map(Command::SetBandStop),
            (0u32..=100).prop_map(|p| Command::SetDutyCycle(p as f64 / 100.0)),
            v.clone().prop_map(Command::SetPeriod),
            v.prop_map(Command::SetForce),
            Just(Command::QueryForce),
            any::<bool>().prop_map(Command::SetOutput),
            Just(Command::QueryOutput),
            Just(Command::MeasureForce),
            Just(Command::QuestionableCondition),
            Just(Command::NextError),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 1000, rng_seed: proptest::test_runner::RngSeed::Fixed(55), ..ProptestConfig::default() })]

        #[test]
        fn canonical_form_round_trips(c in any_command()) {
            let line = c.to_string();
            let back = parse_command(&line).map_err(|e| TestCaseError::fail(e.to_string()))?;
            match (&c, &back) {
                (Command::SetDutyCycle(a), Command::SetDutyCycle(b)) => prop_assert!((a - b).abs() < 1e-12),
                _ => prop_assert_eq!(&back, &c),
            }
            prop_assert_eq!(back.is_query(), line.contains('?'));
        }

        #[test]
        fn parser_never_panics_on_garbage(s in "\\PC{0,80}") {
            let _ = parse_command(&s);
            let _ = parse_error_entry(&s);
            let _ = parse_number_answer(&s);
        }

        #[test]
        fn parser_never_panics_on_scpi_like_garbage(s in "[:*?A-Za-z0-9 .eE+-]{0,40}") {
            if let Ok(c) = parse_command(&s) {
                // Anything accepted re-formats to something that parses to the same command.
                let again = parse_command(&c.to_string()).map_err(|e| TestCaseError::fail(e.to_string()))?;
                match (&c, &again) {
                    (Command::SetDutyCycle(a), Command::SetDutyCycle(b)) => prop_assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0)),
                    _ => prop_assert_eq!(again, c),
                }
            }
        }

        #[test]
        fn line_buffer_never_panics_and_bounds_lines(bytes in proptest::collection::vec(any::<u8>(), 0..2000)) {
            let mut lb = LineBuffer::new();
            let mut n = 0;
            lb.feed(&bytes, |l| { n += 1; if let Line::Text(t) = l { assert!(t.len() <= MAX_LINE); } });
            prop_assert_eq!(n, bytes.iter().filter(|b| **b == b'\n').count());
        }
    }
}
