//! What every device reports about itself: its identity, shared by shakers and DAQs.

use serde::{Deserialize, Serialize};

/// A device's answer to an identification query (`*IDN?` or the DAQ's `HELLO`): who made it,
/// which model, which unit, which firmware.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeviceIdentity {
    /// Manufacturer, e.g. `IDENT-SIM`.
    pub manufacturer: String,
    /// Model, e.g. `SHAKER-4K`.
    pub model: String,
    /// Serial number of this unit.
    pub serial: String,
    /// Firmware version.
    pub firmware: String,
}

impl DeviceIdentity {
    /// Parses the SCPI `*IDN?` convention: four comma-separated fields
    /// `manufacturer,model,serial,firmware`. Returns `None` for anything else.
    pub fn parse_idn(line: &str) -> Option<DeviceIdentity> {
        let fields: Vec<&str> = line.trim().split(',').map(str::trim).collect();
        match fields.as_slice() {
            [m, model, s, fw] if !m.is_empty() && !model.is_empty() => Some(DeviceIdentity {
                manufacturer: (*m).to_string(),
                model: (*model).to_string(),
                serial: (*s).to_string(),
                firmware: (*fw).to_string(),
            }),
            _ => None,
        }
    }

    /// The `*IDN?` form: `manufacturer,model,serial,firmware`.
    pub fn to_idn(&self) -> String {
        format!(
            "{},{},{},{}",
            self.manufacturer, self.model, self.serial, self.firmware
        )
    }

    /// True if this identity matches an expectation written as `manufacturer,model` (or just
    /// `manufacturer`), compared case-insensitively; an empty expectation matches anything.
    pub fn matches(&self, expected: &str) -> bool {
        let mut parts = expected.split(',').map(str::trim);
        let m = parts.next().unwrap_or("");
        let model = parts.next();
        (m.is_empty() || m.eq_ignore_ascii_case(&self.manufacturer))
            && model.is_none_or(|x| x.is_empty() || x.eq_ignore_ascii_case(&self.model))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn idn_round_trip_and_rejects_short_answers() {
        let id = DeviceIdentity::parse_idn("ACME, SHK-4K ,1234,2.1\r\n").unwrap();
        assert_eq!(id.model, "SHK-4K");
        assert_eq!(DeviceIdentity::parse_idn(&id.to_idn()).unwrap(), id);
        assert!(DeviceIdentity::parse_idn("ACME,SHK").is_none());
        assert!(DeviceIdentity::parse_idn("garbage").is_none());
        assert!(DeviceIdentity::parse_idn(",,,").is_none());
        assert!(id.matches("acme,shk-4k"));
        assert!(id.matches("ACME"));
        assert!(!id.matches("ACME,OTHER"));
        assert!(!id.matches("OTHER"));
    }
}
