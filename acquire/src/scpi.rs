//! What every SCPI instrument shares, I/O free: the error-queue entry (`<code>,"<message>"`) and
//! the numeric and boolean answers. Below the instruments that speak SCPI (the shaker
//! controller's dialect in `shaker::scpi`, the signal generators in `generator`), importing none.

/// A SCPI error: the code and message that go into the error queue.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{code},\"{message}\"")]
pub struct ScpiError {
    /// Standard SCPI error code (negative) or device-specific (positive).
    pub code: i32,
    /// Message.
    pub message: String,
}

impl ScpiError {
    /// An entry with this code and message.
    pub fn new(code: i32, message: impl Into<String>) -> Self {
        ScpiError {
            code,
            message: message.into(),
        }
    }
    /// `-113 Undefined header`.
    pub fn undefined_header(h: &str) -> Self {
        Self::new(-113, format!("Undefined header;{h}"))
    }
    /// `-222 Data out of range`.
    pub fn out_of_range(what: &str) -> Self {
        Self::new(-222, format!("Data out of range;{what}"))
    }
}

/// The rest of an error queue after its first entry, as the end of a message:
/// ` (also queued: A; B)`, or nothing when the first was alone.
pub fn also_queued(more: &[String]) -> String {
    if more.is_empty() {
        String::new()
    } else {
        format!(" (also queued: {})", more.join("; "))
    }
}

/// Parses an error-queue entry `<code>,"<message>"`.
pub fn parse_error_entry(line: &str) -> Option<ScpiError> {
    let (code, msg) = line.trim().split_once(',')?;
    let code: i32 = code.trim().parse().ok()?;
    let msg = msg.trim();
    let msg = msg.strip_prefix('"')?.strip_suffix('"')?;
    Some(ScpiError {
        code,
        message: msg.to_string(),
    })
}

/// Formats an error-queue entry.
pub fn format_error_entry(e: &ScpiError) -> String {
    format!("{},\"{}\"", e.code, e.message.replace('"', "'"))
}

/// Parses a numeric answer (`4.0E+03`, `100`).
pub fn parse_number_answer(line: &str) -> Option<f64> {
    line.trim().parse::<f64>().ok().filter(|x| x.is_finite())
}

/// Parses a boolean answer (`1`, `0`, `ON`, `OFF`).
pub fn parse_bool_answer(line: &str) -> Option<bool> {
    match line.trim().to_ascii_uppercase().as_str() {
        "1" | "ON" => Some(true),
        "0" | "OFF" => Some(false),
        _ => None,
    }
}
