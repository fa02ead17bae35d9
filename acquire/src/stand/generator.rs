//! The stand file's `[generator]` and `[amplifier]` sections: a SCPI signal generator (serial
//! port, raw TCP socket or USBTMC device) driving a power amplifier and shaker, with the limits the host's
//! force loop holds (docs/scpi-generator.md).

use std::ops::Range;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

use rfe::source::Quantity as Value;
use rfe::units::Dim;

use super::context::{baud, Ctx, StandError};
use super::ports::{PortSpec, ShakerPort};
use crate::device::DeviceIdentity;
use crate::generator::amplifier::{Amplifier, RAMP_TICK};
use crate::generator::dialect::{self, DialectOverrides, ModelEntry};
use crate::generator::limits::{LimitError, Load};
use crate::transport::SocketAddress;

/// Largest generator amplitude a stand may allow (V peak): what function generators deliver into
/// a high-impedance input (20 Vpp).
pub const GENERATOR_MAX_VOLTS_PEAK: f64 = 10.0;

/// Where the generator is.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GeneratorAddress {
    /// `"sim"` (pseudo-terminal) or `"sim:tcp"` (a local TCP port): served by the simulated stand.
    Sim {
        /// Served on a TCP port rather than a pseudo-terminal.
        tcp: bool,
    },
    /// A serial device path (`/dev/ttyUSB0`).
    Serial(String),
    /// `"tcp:HOST[:PORT]"`: a raw SCPI socket (port 5025 by default).
    Tcp(SocketAddress),
    /// `"usbtmc:/dev/usbtmcN"`: the Linux `usbtmc` driver's device (the path).
    Usbtmc(String),
}

impl std::fmt::Display for GeneratorAddress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            GeneratorAddress::Sim { tcp: false } => write!(f, "sim"),
            GeneratorAddress::Sim { tcp: true } => write!(f, "sim:tcp"),
            GeneratorAddress::Serial(p) => write!(f, "{p}"),
            GeneratorAddress::Tcp(a) => write!(f, "{a}"),
            GeneratorAddress::Usbtmc(p) => write!(f, "usbtmc:{p}"),
        }
    }
}

/// A signal generator driving the shaker through a power amplifier (SI units).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GeneratorStand {
    /// Where it is.
    pub port: GeneratorAddress,
    /// Baud rate on a serial port (bit/s).
    pub baud: u32,
    /// Expected identity `manufacturer,model` (empty: accept any).
    pub identity: String,
    /// Output channel wired to the amplifier (1-based).
    pub channel: u8,
    /// Answer timeout.
    pub timeout: Duration,
    /// Retries after a timeout.
    pub retries: u32,
    /// Line terminator sent after each command.
    pub terminator: String,
    /// Command table by name (`None`: chosen from `*IDN?`).
    pub dialect: Option<String>,
    /// Commands overridden.
    pub commands: DialectOverrides,
    /// The amplifier and shaker, and the loop's limits.
    pub amplifier: Amplifier,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawGenerator {
    port: Spanned<String>,
    baud: Option<Spanned<u32>>,
    identity: Option<String>,
    channel: Option<Spanned<u8>>,
    timeout: Option<Spanned<Value>>,
    retries: Option<u32>,
    terminator: Option<Spanned<String>>,
    dialect: Option<Spanned<String>>,
    commands: Option<DialectOverrides>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAmplifier {
    gain: Option<Spanned<Value>>,
    voltage_limit: Option<Spanned<Value>>,
    force_limit: Option<Spanned<Value>>,
    ramp_rate: Option<Spanned<Value>>,
    tolerance: Option<Spanned<f64>>,
}

/// The example every "missing field" message shows.
const AMPLIFIER_EXAMPLE: &str = "[amplifier]\ngain = \"1000 N/V\"\nvoltage_limit = \"5 V\"\nforce_limit = \"6 kN\"\nramp_rate = \"20 V/s\"";

/// `[generator]` and `[amplifier]`: the generator's settings, and the exciter as the sweep sees
/// it (a [`ShakerPort`] whose `max_force_n` is the amplifier's force limit).
pub(super) fn generator_section(
    cx: &Ctx<'_>,
    rg: &Spanned<RawGenerator>,
    ra: Option<&Spanned<RawAmplifier>>,
) -> Result<(GeneratorStand, ShakerPort), StandError> {
    let g = rg.get_ref();
    let port = address(cx, &g.port)?;
    let Some(ra) = ra else {
        return Err(cx.at(
            rg.span(),
            format!("a [generator] stand needs an [amplifier] section with the loop's limits, e.g.\n{AMPLIFIER_EXAMPLE}"),
        ));
    };
    let amplifier = amplifier(cx, ra)?;
    let channel = match &g.channel {
        Some(c) if *c.get_ref() == 0 => {
            return Err(cx.at(
                c.span(),
                "generator.channel counts from 1 (the output wired to the amplifier's input)",
            ))
        }
        Some(c) => *c.get_ref(),
        None => 1,
    };
    let terminator =
        match &g.terminator {
            None => "\n".to_string(),
            Some(t) if t.get_ref() == "\n" || t.get_ref() == "\r\n" => t.get_ref().clone(),
            Some(t) => return Err(cx.at(
                t.span(),
                "generator.terminator must be \"\\n\" (LF, every LXI socket) or \"\\r\\n\" (CR LF)",
            )),
        };
    let dialect = match &g.dialect {
        None => None,
        Some(d) => {
            let known = dialect::builtin().map_err(|e| cx.at(d.span(), e.to_string()))?;
            if !known
                .iter()
                .any(|m| m.name.eq_ignore_ascii_case(d.get_ref().trim()))
            {
                let names: Vec<&str> = known.iter().map(|m| m.name.as_str()).collect();
                return Err(cx.at(
                    d.span(),
                    format!(
                        "generator.dialect = {:?} is not a built-in command table; use one of: {} (or leave it out to choose from *IDN?)",
                        d.get_ref(),
                        names.join(", ")
                    ),
                ));
            }
            Some(d.get_ref().trim().to_string())
        }
    };
    let timeout = match &g.timeout {
        Some(t) => Duration::from_secs_f64(cx.positive(t, Dim::TIME, "generator.timeout")?),
        None => Duration::from_secs(1),
    };
    let stand = GeneratorStand {
        baud: baud(cx, &g.baud, "generator.baud", 9600)?,
        identity: g.identity.clone().unwrap_or_default(),
        channel,
        timeout,
        retries: g.retries.unwrap_or(2),
        terminator,
        dialect,
        commands: g.commands.clone().unwrap_or_default(),
        amplifier,
        port,
    };
    check_model_range(cx, rg, ra, &stand)?;
    let shaker = ShakerPort {
        port: match &stand.port {
            GeneratorAddress::Sim { .. } => PortSpec::Sim,
            other => PortSpec::Path(other.to_string()),
        },
        baud: stand.baud,
        identity: stand.identity.clone(),
        timeout: stand.timeout,
        retries: stand.retries,
        max_force_n: stand.amplifier.force_limit_n,
    };
    Ok((stand, shaker))
}

/// When the stand names its generator's model (`dialect`, or `identity` with manufacturer and
/// model): the model's table has an amplitude range into a high impedance (the load the driver
/// sets) and `voltage_limit` lies within it. A model chosen from `*IDN?` only is checked when it
/// answers, before the output is switched on.
fn check_model_range(
    cx: &Ctx<'_>,
    rg: &Spanned<RawGenerator>,
    ra: &Spanned<RawAmplifier>,
    g: &GeneratorStand,
) -> Result<(), StandError> {
    let Some((entry, from)) = model_of(g) else {
        return Ok(());
    };
    let range = entry
        .limits
        .as_ref()
        .ok_or(LimitError::NoRange {
            field: "[model.limits]",
            load: "or any other range",
        })
        .and_then(|l| Ok((l.amplitude_peak(Load::HighImpedance)?, l.source.clone())));
    let ([_, hi], source) = range.map_err(|e| {
        cx.at(
            rg.span(),
            format!(
                "the generator's command table `{}` ({from}): {e}",
                entry.name
            ),
        )
    })?;
    let limit = g.amplifier.voltage_limit_v;
    if limit > hi + 1e-12 {
        let span = ra
            .get_ref()
            .voltage_limit
            .as_ref()
            .map_or(ra.span(), |v| v.span());
        return Err(cx.at(
            span,
            format!("amplifier.voltage_limit {limit} V is above what the {} ({from}) delivers into the amplifier's high impedance: {hi} V peak = {} Vpp ({source}); lower voltage_limit to at most {hi} V", entry.name, 2.0 * hi),
        ));
    }
    Ok(())
}

fn address(cx: &Ctx<'_>, p: &Spanned<String>) -> Result<GeneratorAddress, StandError> {
    let text = p.get_ref().trim();
    Ok(match text {
        "sim" => GeneratorAddress::Sim { tcp: false },
        "sim:tcp" => GeneratorAddress::Sim { tcp: true },
        _ if text.starts_with("can:") => {
            return Err(cx.at(
                p.span(),
                "generator.port: a signal generator speaks SCPI over a serial port or a TCP socket; give a device path, \"tcp:HOST[:PORT]\", \"usbtmc:/dev/usbtmcN\" or \"sim\", not a CAN interface",
            ))
        }
        _ if text.starts_with("usbtmc:") => match text["usbtmc:".len()..].trim() {
            "" => return Err(cx.at(
                p.span(),
                format!("generator.port = {text:?}: name the usbtmc driver's device, e.g. \"usbtmc:/dev/usbtmc0\""),
            )),
            path => GeneratorAddress::Usbtmc(path.to_string()),
        },
        _ => match text.strip_prefix("tcp:") {
            Some(rest) => GeneratorAddress::Tcp(SocketAddress::parse(rest).ok_or_else(|| {
                cx.at(
                    p.span(),
                    format!("generator.port = {text:?}: write \"tcp:HOST\" or \"tcp:HOST:PORT\", e.g. \"tcp:192.168.1.20:5025\" (the LXI raw SCPI socket)"),
                )
            })?),
            None if text.is_empty() => {
                return Err(cx.at(p.span(), "generator.port is empty; give a device path, \"tcp:HOST[:PORT]\" or \"sim\""))
            }
            None => GeneratorAddress::Serial(text.to_string()),
        },
    })
}

/// A quantity per unit of something (`"1000 N/V"`, `"20 V/s"`): the numerator in `dim`, the
/// denominator one of `per` (name, SI factor). A bare number is SI.
pub(super) fn per(
    cx: &Ctx<'_>,
    v: &Spanned<Value>,
    dim: Dim,
    per: &[(&str, f64)],
    field: &str,
    example: &str,
) -> Result<f64, StandError> {
    let bad = || cx.at(v.span(), format!("{field}: write it like {example:?}"));
    let x = match v.get_ref() {
        Value::Number(x) => *x,
        Value::Text(t) => {
            let (num, den) = t.rsplit_once('/').ok_or_else(bad)?;
            let factor = per
                .iter()
                .find(|(name, _)| *name == den.trim())
                .map(|(_, f)| *f)
                .ok_or_else(bad)?;
            rfe::units::parse_quantity(num, dim).map_err(|_| bad())? / factor
        }
    };
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(cx.at(v.span(), format!("{field} must be > 0, e.g. {example:?}")))
    }
}

/// `[amplifier]`: every limit present, positive and consistent.
fn amplifier(cx: &Ctx<'_>, ra: &Spanned<RawAmplifier>) -> Result<Amplifier, StandError> {
    let a = ra.get_ref();
    let missing = |field: &str, what: &str| {
        cx.at(
            ra.span(),
            format!("[amplifier] has no `{field}` ({what}); the force loop needs all of its limits, e.g.\n{AMPLIFIER_EXAMPLE}"),
        )
    };
    let gain = a
        .gain
        .as_ref()
        .ok_or_else(|| missing("gain", "the estimated force per generator volt, N/V"))?;
    let voltage = a
        .voltage_limit
        .as_ref()
        .ok_or_else(|| missing("voltage_limit", "the largest generator amplitude, V peak"))?;
    let force = a.force_limit.as_ref().ok_or_else(|| {
        missing(
            "force_limit",
            "the measured force that stops the sweep, N peak",
        )
    })?;
    let ramp = a.ramp_rate.as_ref().ok_or_else(|| {
        missing(
            "ramp_rate",
            "the fastest change of the amplitude while on, V/s",
        )
    })?;
    let gain_n_per_v = per(
        cx,
        gain,
        Dim::FORCE,
        &[("V", 1.0), ("mV", 1e-3)],
        "amplifier.gain",
        "1000 N/V",
    )?;
    let voltage_limit_v = cx.positive(voltage, Dim::VOLTAGE, "amplifier.voltage_limit")?;
    let force_limit_n = cx.positive(force, Dim::FORCE, "amplifier.force_limit")?;
    let ramp_rate_v_per_s = per(
        cx,
        ramp,
        Dim::VOLTAGE,
        &[("s", 1.0), ("ms", 1e-3)],
        "amplifier.ramp_rate",
        "20 V/s",
    )?;
    let tolerance = match &a.tolerance {
        None => 0.02,
        Some(t) if *t.get_ref() > 0.0 && *t.get_ref() <= 0.2 => *t.get_ref(),
        Some(t) => {
            return Err(cx.at(
                t.span(),
                "amplifier.tolerance is the accepted relative force error, within 0..0.2 (default 0.02 = 2 %)",
            ))
        }
    };
    let at = |s: &Spanned<Value>| -> Range<usize> { s.span() };
    if voltage_limit_v > GENERATOR_MAX_VOLTS_PEAK {
        return Err(cx.at(
            at(voltage),
            format!("amplifier.voltage_limit {voltage_limit_v} V is above what a function generator delivers into the amplifier's high-impedance input ({GENERATOR_MAX_VOLTS_PEAK} V peak = 20 Vpp); give the peak voltage the amplifier's input is rated for"),
        ));
    }
    let reachable = gain_n_per_v * voltage_limit_v;
    if reachable < 0.1 * force_limit_n {
        return Err(cx.at(
            at(gain),
            format!("amplifier.gain × voltage_limit = {reachable:.0} N, less than a tenth of force_limit {force_limit_n:.0} N: the limits do not fit together; check gain's unit (newtons of force per volt at the generator) and the limits"),
        ));
    }
    let step = ramp_rate_v_per_s * RAMP_TICK.as_secs_f64();
    if step >= voltage_limit_v {
        return Err(cx.at(
            at(ramp),
            format!("amplifier.ramp_rate {ramp_rate_v_per_s} V/s reaches voltage_limit {voltage_limit_v} V within one {} ms ramp step, which is no ramp at all; lower it (a few V/s is usual)", RAMP_TICK.as_millis()),
        ));
    }
    Ok(Amplifier {
        gain_n_per_v,
        voltage_limit_v,
        force_limit_n,
        ramp_rate_v_per_s,
        tolerance,
    })
}

/// The built-in table a generator stand names, and which field named it.
pub(super) fn model_of(g: &GeneratorStand) -> Option<(ModelEntry, &'static str)> {
    if let Some(d) = &g.dialect {
        return dialect::by_name(d)
            .ok()
            .flatten()
            .map(|e| (e, "generator.dialect"));
    }
    let (manufacturer, model) = g.identity.split_once(',')?;
    let id = DeviceIdentity {
        manufacturer: manufacturer.trim().into(),
        model: model.trim().into(),
        serial: String::new(),
        firmware: String::new(),
    };
    dialect::for_identity(&id)
        .ok()
        .flatten()
        .map(|e| (e, "generator.identity"))
}
