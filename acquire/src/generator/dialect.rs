//! Per-model command tables ("dialects") of SCPI function generators: the built-in table
//! (`models.toml`, data rather than code), chosen by the instrument's `*IDN?` answer or by name,
//! with per-command overrides from the stand file.

use serde::{Deserialize, Serialize};

use crate::device::DeviceIdentity;

/// The built-in command tables (`acquire/src/generator/models.toml`).
const MODELS_TOML: &str = include_str!("models.toml");

/// How the amplitude is written to the instrument.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "UPPERCASE")]
pub enum AmplitudeUnit {
    /// Volts peak to peak (every generator's default).
    Vpp,
    /// Volts RMS of the sine.
    Vrms,
}

impl AmplitudeUnit {
    /// The SCPI word (`VPP`, `VRMS`).
    pub fn word(&self) -> &'static str {
        match self {
            AmplitudeUnit::Vpp => "VPP",
            AmplitudeUnit::Vrms => "VRMS",
        }
    }

    /// A sine's peak voltage (V) in this unit.
    pub fn from_peak(&self, volts_peak: f64) -> f64 {
        match self {
            AmplitudeUnit::Vpp => 2.0 * volts_peak,
            AmplitudeUnit::Vrms => volts_peak / std::f64::consts::SQRT_2,
        }
    }

    /// A value in this unit as the sine's peak voltage (V).
    pub fn to_peak(&self, value: f64) -> f64 {
        match self {
            AmplitudeUnit::Vpp => 0.5 * value,
            AmplitudeUnit::Vrms => value * std::f64::consts::SQRT_2,
        }
    }
}

/// One model's command set. Templates: `{ch}` channel number, `{value}` number, `{unit}`
/// VPP/VRMS, `{state}` the `on`/`off` word.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Dialect {
    /// Selects the sine (`SOUR{ch}:FUNC SIN`).
    pub function_sine: String,
    /// Sets the frequency in Hz (`SOUR{ch}:FREQ {value}`).
    pub frequency: String,
    /// Selects the amplitude unit (`SOUR{ch}:VOLT:UNIT {unit}`).
    pub voltage_unit: String,
    /// Sets the amplitude in `unit` (`SOUR{ch}:VOLT {value}`).
    pub amplitude: String,
    /// Sets the DC offset in V (`SOUR{ch}:VOLT:OFFS {value}`).
    pub offset: String,
    /// Switches the output (`OUTP{ch} {state}`).
    pub output: String,
    /// Asks the output state (`OUTP{ch}?`, answered `1`/`0` or `ON`/`OFF`).
    pub output_query: String,
    /// Sets the load the output drives (`OUTP{ch}:LOAD {value}`).
    pub load: String,
    /// The load word for a high-impedance input such as a power amplifier's (`INF`).
    pub high_impedance: String,
    /// Reads the oldest error-queue entry (`SYST:ERR?`).
    pub error_query: String,
    /// The `{state}` word for on.
    pub on: String,
    /// The `{state}` word for off.
    pub off: String,
    /// The amplitude unit used.
    pub unit: AmplitudeUnit,
}

/// Per-command overrides of a [`Dialect`] (the stand file's `[generator.commands]`).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DialectOverrides {
    /// See [`Dialect::function_sine`].
    pub function_sine: Option<String>,
    /// See [`Dialect::frequency`].
    pub frequency: Option<String>,
    /// See [`Dialect::voltage_unit`].
    pub voltage_unit: Option<String>,
    /// See [`Dialect::amplitude`].
    pub amplitude: Option<String>,
    /// See [`Dialect::offset`].
    pub offset: Option<String>,
    /// See [`Dialect::output`].
    pub output: Option<String>,
    /// See [`Dialect::output_query`].
    pub output_query: Option<String>,
    /// See [`Dialect::load`].
    pub load: Option<String>,
    /// See [`Dialect::high_impedance`].
    pub high_impedance: Option<String>,
    /// See [`Dialect::error_query`].
    pub error_query: Option<String>,
    /// See [`Dialect::on`].
    pub on: Option<String>,
    /// See [`Dialect::off`].
    pub off: Option<String>,
    /// See [`Dialect::unit`].
    pub unit: Option<AmplitudeUnit>,
}

impl DialectOverrides {
    /// True when nothing is overridden.
    pub fn is_empty(&self) -> bool {
        *self == DialectOverrides::default()
    }

    /// `base` with these overrides applied.
    pub fn apply(&self, base: &Dialect) -> Dialect {
        let pick = |o: &Option<String>, b: &String| o.clone().unwrap_or_else(|| b.clone());
        Dialect {
            function_sine: pick(&self.function_sine, &base.function_sine),
            frequency: pick(&self.frequency, &base.frequency),
            voltage_unit: pick(&self.voltage_unit, &base.voltage_unit),
            amplitude: pick(&self.amplitude, &base.amplitude),
            offset: pick(&self.offset, &base.offset),
            output: pick(&self.output, &base.output),
            output_query: pick(&self.output_query, &base.output_query),
            load: pick(&self.load, &base.load),
            high_impedance: pick(&self.high_impedance, &base.high_impedance),
            error_query: pick(&self.error_query, &base.error_query),
            on: pick(&self.on, &base.on),
            off: pick(&self.off, &base.off),
            unit: self.unit.unwrap_or(base.unit),
        }
    }
}

/// One entry of the built-in table.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelEntry {
    /// Name a stand file selects it by (`dialect = "Rigol DG800/DG1000Z"`).
    pub name: String,
    /// `*IDN?` manufacturers it applies to (compared case-insensitively).
    pub manufacturers: Vec<String>,
    /// Prefixes of the `*IDN?` model it applies to (case-insensitive).
    pub model_prefixes: Vec<String>,
    /// Its commands.
    pub commands: Dialect,
    /// Its ranges from the data sheet.
    #[serde(default)]
    pub limits: Option<super::limits::ModelLimits>,
    /// Its arbitrary-waveform upload, if it has one.
    #[serde(default)]
    pub arbitrary: Option<super::arbitrary::ArbitraryDialect>,
}

/// A generator family the driver refuses, and why (`[[unsupported]]` in the built-in table).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Unsupported {
    /// `*IDN?` manufacturers (compared case-insensitively).
    pub manufacturers: Vec<String>,
    /// Prefixes of the `*IDN?` model (case-insensitive).
    pub model_prefixes: Vec<String>,
    /// Why the driver does not drive it, and what to use instead.
    pub why: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Table {
    model: Vec<ModelEntry>,
    #[serde(default)]
    unsupported: Vec<Unsupported>,
}

/// True when `id` is of `manufacturers` and its model starts with one of `prefixes`.
fn matches(id: &DeviceIdentity, manufacturers: &[String], prefixes: &[String]) -> bool {
    manufacturers
        .iter()
        .any(|x| x.eq_ignore_ascii_case(id.manufacturer.trim()))
        && prefixes.iter().any(|p| {
            id.model
                .trim()
                .to_ascii_uppercase()
                .starts_with(&p.to_ascii_uppercase())
        })
}

/// The built-in table's refusal of `id`, if the driver does not drive its family.
pub fn unsupported(id: &DeviceIdentity) -> Result<Option<Unsupported>, TableError> {
    Ok(toml::from_str::<Table>(MODELS_TOML)
        .map_err(|e| TableError(e.to_string()))?
        .unsupported
        .into_iter()
        .find(|u| matches(id, &u.manufacturers, &u.model_prefixes)))
}

/// The built-in table could not be read (a defect of this build, reported rather than panicking).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the built-in generator command table (acquire/src/generator/models.toml) is invalid: {0}")]
pub struct TableError(pub String);

/// The built-in command tables.
pub fn builtin() -> Result<Vec<ModelEntry>, TableError> {
    toml::from_str::<Table>(MODELS_TOML)
        .map(|t| t.model)
        .map_err(|e| TableError(e.to_string()))
}

/// The built-in entry named `name` (case-insensitive).
pub fn by_name(name: &str) -> Result<Option<ModelEntry>, TableError> {
    Ok(builtin()?
        .into_iter()
        .find(|m| m.name.eq_ignore_ascii_case(name.trim())))
}

/// The built-in entry for an instrument's identity, if its manufacturer and model are known.
pub fn for_identity(id: &DeviceIdentity) -> Result<Option<ModelEntry>, TableError> {
    Ok(builtin()?
        .into_iter()
        .find(|m| matches(id, &m.manufacturers, &m.model_prefixes)))
}

/// Names of the built-in entries, for messages.
pub fn known_names() -> Vec<String> {
    builtin()
        .map(|t| t.into_iter().map(|m| m.name).collect())
        .unwrap_or_default()
}

/// Fills a template: `{ch}`, `{value}`, `{unit}`, `{state}`.
pub fn fill(template: &str, channel: u8, value: &str) -> String {
    template
        .replace("{ch}", &channel.to_string())
        .replace("{value}", value)
        .replace("{unit}", value)
        .replace("{state}", value)
}

/// A number as sent to an instrument: rounded to 1e-6 of its unit, without float noise.
pub fn number(x: f64) -> String {
    let r = (x * 1e6).round() / 1e6;
    if r == 0.0 {
        "0".to_string()
    } else {
        format!("{r}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(m: &str, model: &str) -> DeviceIdentity {
        DeviceIdentity {
            manufacturer: m.into(),
            model: model.into(),
            serial: "X".into(),
            firmware: "1".into(),
        }
    }

    #[test]
    fn the_builtin_table_reads_and_recognises_the_manuals_identities() {
        let t = builtin().unwrap();
        assert!(t.len() >= 5);
        // (manufacturer, model, the table recognising it; none for a DMM and an unknown maker)
        let identities = [
            (
                "Keysight Technologies",
                "33512B",
                Some("Keysight 33500B/33600A"),
            ),
            (
                "Agilent Technologies",
                "33522A",
                Some("Keysight 33500B/33600A"),
            ),
            (
                "Keysight Technologies",
                "33622A",
                Some("Keysight 33500B/33600A"),
            ),
            ("Rigol Technologies", "DG1062Z", Some("Rigol DG800/DG1000Z")),
            ("Rigol Technologies", "DG812", Some("Rigol DG800/DG1000Z")),
            ("TEKTRONIX", "AFG31022", Some("Tektronix AFG31000")),
            ("Keysight Technologies", "34461A", None),
            ("ACME", "FG-1", None),
        ];
        for (maker, model, want) in identities {
            let got = for_identity(&id(maker, model)).unwrap().map(|e| e.name);
            assert_eq!(got.as_deref(), want, "{maker} {model}");
        }
        assert!(by_name("generic").unwrap().is_some());
        // Arbitrary waveforms: every named model but the plain SCPI-99 table. Ranges: every
        // table, both loads, the high-impedance range twice the 50 Ω one (the same voltage).
        for m in &t {
            let l = m
                .limits
                .as_ref()
                .unwrap_or_else(|| panic!("{} has no limits", m.name));
            let (a, b) = (
                l.amplitude_50_ohm_vpp.unwrap(),
                l.amplitude_high_z_vpp.unwrap(),
            );
            assert_eq!([2.0 * a[0], 2.0 * a[1]], b, "{}", m.name);
            assert!(!l.source.is_empty() && l.frequency_hz[0] < l.frequency_hz[1]);
            assert_eq!(m.arbitrary.is_some(), m.name != "generic", "{}", m.name);
            if let Some(a) = &m.arbitrary {
                assert!(a.upload.contains("{block}"), "{}", m.name);
                assert!(a.code_min < a.code_max && a.min_points < a.max_points);
                assert!(a.check(5120, 5120.0).is_ok(), "{}", m.name);
                // The manual's spelling of the arbitrary function: `ARB` (33500B), never a
                // long form the manual does not list.
                assert!(
                    a.select.iter().all(|c| !c.ends_with("ARBitrary")),
                    "{}",
                    m.name
                );
            }
        }
        assert!(by_name("nonsense").unwrap().is_none());
    }

    #[test]
    fn templates_units_and_overrides() {
        let k = by_name("Keysight 33500B/33600A").unwrap().unwrap().commands;
        assert_eq!(fill(&k.amplitude, 2, &number(1.25)), "SOURce2:VOLTage 1.25");
        assert_eq!(fill(&k.output, 1, &k.on), "OUTPut1 ON");
        assert_eq!(number(0.1 + 0.2), "0.3");
        assert_eq!(number(-0.0), "0");
        assert_eq!(AmplitudeUnit::Vpp.from_peak(1.5), 3.0);
        let rms = AmplitudeUnit::Vrms;
        assert!((rms.to_peak(rms.from_peak(2.0)) - 2.0).abs() < 1e-12);
        let o = DialectOverrides {
            load: Some("OUTP{ch}:IMP {value}".into()),
            unit: Some(AmplitudeUnit::Vrms),
            ..Default::default()
        };
        let d = o.apply(&k);
        assert_eq!(d.load, "OUTP{ch}:IMP {value}");
        assert_eq!(d.unit, AmplitudeUnit::Vrms);
        assert_eq!(d.amplitude, k.amplitude);
        assert!(!o.is_empty() && DialectOverrides::default().is_empty());
    }
}
