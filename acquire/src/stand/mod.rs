//! Stand files (`configs/stands/*.toml`): which ports the devices are on, the DAQ channel map
//! with each sensor's body, position, direction and calibration, and — for the simulated stand —
//! the truth model, noise and faults. Every error names file:line:column and what to fix.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

use rfe::source::Quantity as Value;
use rfe::units::Dim;

/// The force and table-x channels of the stand files in this module's tests (a string
/// literal, for `concat!`).
#[cfg(test)]
macro_rules! test_stand_channels {
    () => {
        r#"[[channel]]
name = "force"
device_channel = 0
kind = "force"
sensitivity = "2.25 mV/N"
[[channel]]
name = "table-x"
device_channel = 1
kind = "acceleration"
body = "table"
position = ["320 mm", "0 mm", "45 mm"]
direction = [2, 0, 0]
sensitivity = "100 mV/g"
"#
    };
}

mod broadband;
mod canopen;
mod context;
mod generator;
mod ports;

pub use crate::faults::Faults;
pub use crate::record::{BodyGeometry, Channel, ChannelKind, Geometry, GeometryOutput};
pub use broadband::Broadband;
pub use canopen::CanOpenPort;
pub use context::StandError;
use context::{baud, Ctx};
pub use generator::{GeneratorAddress, GeneratorStand, GENERATOR_MAX_VOLTS_PEAK};
pub use ports::{DaqPort, PortSpec, ShakerPort};

/// How far (m) outside its body's equivalent box a sensor may sit (mounting blocks, rounding).
pub const SENSOR_MOUNT_TOLERANCE_M: f64 = 0.005;

/// A resolved, validated stand (SI units throughout).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Stand {
    /// Free-text name.
    pub name: String,
    /// File it was read from (empty when parsed from a string).
    pub file: String,
    /// The file's text, recorded verbatim in each session.
    pub text: String,
    /// The exciter as the sweep sees it: the shaker controller, or — on a stand with a
    /// [`Stand::generator`] — the generator's port and identity with the amplifier's force limit.
    pub shaker: ShakerPort,
    /// The signal generator and power amplifier (`[generator]`, `[amplifier]`), when the stand
    /// drives its shaker that way instead of through a shaker controller.
    pub generator: Option<GeneratorStand>,
    /// The DAQ.
    pub daq: DaqPort,
    /// DAQ channels in stream order.
    pub channels: Vec<Channel>,
    /// The simulated stand's truth (only used by [`crate::sim`]).
    pub truth: Option<Truth>,
    /// Faults the simulated stand injects.
    pub faults: Faults,
    /// `[geometry] model`: the model file whose bodies give the sensors' bodies their mass
    /// properties (centre of mass, principal axes) and whose excitation gives the nominal force.
    /// Never the truth: use the identification model. Resolved relative to the stand file by
    /// [`Stand::load`].
    pub geometry_model: Option<PathBuf>,
    /// The geometry read from `geometry_model` by [`Stand::load`] (recorded in every session).
    pub geometry: Option<Geometry>,
    /// `[broadband]`: the broadband measurement `ident sweep --broadband` runs.
    pub broadband: Option<Broadband>,
}

/// The DAQ input range assumed when the stand file gives no `daq.input_range` (V, ±): what most
/// measurement DAQs' inputs take.
pub const DEFAULT_INPUT_RANGE_V: f64 = 10.0;

/// A force sample at this fraction of `daq.input_range` or beyond counts as clipped (the ADC at
/// its last codes).
pub const CLIP_FRACTION: f64 = 0.999;

/// The simulated stand's truth.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Truth {
    /// The structure.
    pub model: TruthModel,
    /// Shaker-structure interaction: delivered force = commanded · gain / (1 + j f / cutoff).
    pub shaker_gain: f64,
    /// Cut-off frequency of the shaker's force roll-off (Hz).
    pub shaker_cutoff_hz: f64,
    /// Sensor noise RMS on acceleration channels (m/s²).
    pub noise_acceleration: f64,
    /// Sensor noise RMS on the force channel (N).
    pub noise_force: f64,
    /// Simulated time per wall-clock time (1 = real time; larger runs faster).
    pub speed: f64,
    /// Seed of the noise generator.
    pub seed: u64,
    /// True force per generator volt of the simulated amplifier and shaker (N/V; generator
    /// stands). Absent: the stand's `amplifier.gain` estimate, exact.
    pub amplifier_gain_n_per_v: Option<f64>,
}

/// Structure models the simulated stand can use as truth.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TruthModel {
    /// A rigid body on a spring with hysteretic damping, moving along `direction`.
    Sdof {
        /// Body name the sensors refer to.
        body: String,
        /// Mass (kg).
        mass: f64,
        /// Stiffness (N/m).
        stiffness: f64,
        /// Loss factor η (hysteretic damping, = ψ / 2π).
        loss_factor: f64,
        /// Direction of motion, global, unit.
        direction: [f64; 3],
    },
    /// An `identify` model file (resolved relative to the stand file).
    ModelFile(PathBuf),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStand {
    name: Option<String>,
    shaker: Option<Spanned<RawShaker>>,
    generator: Option<Spanned<generator::RawGenerator>>,
    amplifier: Option<Spanned<generator::RawAmplifier>>,
    daq: Spanned<RawDaq>,
    #[serde(default)]
    channel: Vec<Spanned<RawChannel>>,
    truth: Option<Spanned<RawTruth>>,
    faults: Option<RawFaults>,
    geometry: Option<Spanned<RawGeometry>>,
    broadband: Option<Spanned<broadband::RawBroadband>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGeometry {
    model: Spanned<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCan {
    frames: Option<Spanned<String>>,
    command_id: Option<Spanned<u32>>,
    status_id: Option<Spanned<u32>>,
    data_id: Option<Spanned<u32>>,
    extended_ids: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawShaker {
    port: Spanned<String>,
    baud: Option<Spanned<u32>>,
    identity: Option<String>,
    timeout: Option<Spanned<Value>>,
    retries: Option<u32>,
    max_force: Option<Spanned<Value>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDaq {
    port: Spanned<String>,
    baud: Option<Spanned<u32>>,
    inputs: Option<Spanned<u16>>,
    identity: Option<String>,
    sample_rate: Spanned<Value>,
    samples_per_block: Option<Spanned<u16>>,
    timeout: Option<Spanned<Value>>,
    retries: Option<u32>,
    input_range: Option<Spanned<Value>>,
    can: Option<Spanned<RawCan>>,
    canopen: Option<Spanned<canopen::RawCanOpen>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawChannel {
    name: Spanned<String>,
    device_channel: Spanned<u16>,
    kind: Spanned<ChannelKind>,
    sensitivity: Spanned<Value>,
    body: Option<Spanned<String>>,
    position: Option<Spanned<Vec<Value>>>,
    direction: Option<Spanned<Vec<f64>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTruth {
    model: Option<Spanned<String>>,
    sdof: Option<Spanned<RawSdof>>,
    shaker_gain: Option<f64>,
    shaker_cutoff: Option<Spanned<Value>>,
    noise_acceleration: Option<Spanned<Value>>,
    noise_force: Option<Spanned<Value>>,
    speed: Option<Spanned<f64>>,
    seed: Option<u64>,
    amplifier_gain: Option<Spanned<Value>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSdof {
    body: String,
    mass: Spanned<Value>,
    stiffness: Spanned<Value>,
    loss_factor: Spanned<f64>,
    direction: Spanned<Vec<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFaults {
    seed: Option<u64>,
    drop: Option<Spanned<f64>>,
    corrupt: Option<Spanned<f64>>,
    duplicate: Option<Spanned<f64>>,
    delay: Option<Spanned<f64>>,
    delay_time: Option<Spanned<Value>>,
    daq_silent_after_blocks: Option<u64>,
    shaker_silent_after_commands: Option<u64>,
    cable_pull_after_blocks: Option<u64>,
    amplifier_trip_after_lines: Option<u64>,
    amplifier_surge_after_lines: Option<u64>,
    amplifier_surge_factor: Option<Spanned<f64>>,
}

fn port_spec(p: &str) -> PortSpec {
    if p == "sim" {
        PortSpec::Sim
    } else if let Some(iface) = p.strip_prefix("can:") {
        PortSpec::Can(iface.to_string())
    } else {
        PortSpec::Path(p.to_string())
    }
}

fn can_settings(
    cx: &Ctx<'_>,
    raw: Option<&Spanned<RawCan>>,
) -> Result<crate::can::CanDaqSettings, StandError> {
    use crate::can::{CanDaqSettings, CanId, FrameKind};
    let mut s = CanDaqSettings::default();
    let Some(rc) = raw else { return Ok(s) };
    let r = rc.get_ref();
    if let Some(f) = &r.frames {
        s.frames = match f.get_ref().as_str() {
            "classic" => FrameKind::Classic,
            "fd" => FrameKind::Fd,
            other => return Err(cx.at(f.span(), format!("daq.can.frames = {other:?}: write \"classic\" (8-byte frames) or \"fd\" (CAN FD, 64 bytes)"))),
        };
    }
    let ext = r.extended_ids.unwrap_or(false);
    let id = |v: &Option<Spanned<u32>>, dflt: CanId, what: &str| -> Result<CanId, StandError> {
        let Some(v) = v else { return Ok(dflt) };
        let x = *v.get_ref();
        let id = if ext {
            CanId::Extended(x)
        } else {
            CanId::Standard(u16::try_from(x).unwrap_or(u16::MAX))
        };
        id.validate(what)
            .map_err(|e| cx.at(v.span(), format!("daq.can.{what}_id: {e}")))?;
        Ok(id)
    };
    s.command_id = id(&r.command_id, s.command_id, "command")?;
    s.status_id = id(&r.status_id, s.status_id, "status")?;
    s.data_id = id(&r.data_id, s.data_id, "data")?;
    s.validate()
        .map_err(|e| cx.at(rc.span(), format!("daq.can: {e}")))?;
    Ok(s)
}

impl Stand {
    /// Reads and validates a stand file.
    pub fn load(path: &Path) -> Result<Stand, StandError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| StandError {
            file: file.clone(),
            line: 0,
            column: 0,
            message: format!("cannot read the stand file: {e}"),
        })?;
        let mut stand = Stand::parse(&text, &file)?;
        let dir = path.parent().unwrap_or(Path::new("."));
        if let Some(Truth {
            model: TruthModel::ModelFile(p),
            ..
        }) = &mut stand.truth
        {
            if p.is_relative() {
                *p = dir.join(&*p);
            }
        }
        if let Some(p) = &mut stand.geometry_model {
            if p.is_relative() {
                *p = dir.join(&*p);
            }
        }
        if let Some(c) = &mut stand.daq.canopen {
            if let Some(p) = &mut c.eds {
                if p.is_relative() {
                    *p = dir.join(&*p);
                }
            }
            // The EDS must be readable now, not when the sweep opens the DAQ.
            c.settings().map_err(|e| StandError {
                file: file.clone(),
                line: 0,
                column: 0,
                message: format!("daq.canopen.eds: {e}"),
            })?;
        }
        stand.resolve_geometry(SENSOR_MOUNT_TOLERANCE_M)?;
        Ok(stand)
    }

    /// Parses and validates stand-file text; `file` is used in messages.
    pub fn parse(text: &str, file: &str) -> Result<Stand, StandError> {
        let text = rfe::source::strip_bom(text);
        let cx = Ctx::new(file, text);
        let raw: RawStand = toml::from_str(text).map_err(|e| {
            let span = e.span().unwrap_or(0..0);
            cx.at(span, e.message().to_string())
        })?;
        let rd = raw.daq.get_ref();
        let (shaker, generator, exciter_span) = exciter(&cx, &raw)?;
        let daq = daq_port(&cx, rd)?;
        check_ports(&cx, &shaker, &daq, exciter_span.clone(), rd)?;
        let channels = channel_map(&cx, &raw, &daq)?;
        let truth = match &raw.truth {
            None => None,
            Some(st) => Some(truth(&cx, st, &channels)?),
        };
        let faults = match &raw.faults {
            None => Faults::default(),
            Some(f) => faults(&cx, f)?,
        };
        let geometry_model = raw
            .geometry
            .as_ref()
            .map(|g| PathBuf::from(g.get_ref().model.get_ref()));
        let broadband = match &raw.broadband {
            None => None,
            Some(rb) => Some(broadband::broadband_section(
                &cx,
                rb,
                daq.sample_rate_hz,
                shaker.max_force_n,
                generator.as_ref(),
            )?),
        };
        let uses_sim = shaker.port == PortSpec::Sim || daq.port == PortSpec::Sim;
        if uses_sim && truth.is_none() {
            return Err(cx.at(
                exciter_span,
                "port = \"sim\" needs a [truth] section (the simulated structure)",
            ));
        }
        Ok(Stand {
            name: raw.name.unwrap_or_else(|| file.to_string()),
            file: file.to_string(),
            text: text.to_string(),
            shaker,
            generator,
            daq,
            channels,
            truth,
            faults,
            geometry_model,
            geometry: None,
            broadband,
        })
    }

    /// Reads the `[geometry] model` (already resolved to a path) and checks that every
    /// accelerometer sits on the body it names: inside the homogeneous box with that body's mass
    /// and principal moments, within `tolerance_m`.
    pub fn resolve_geometry(&mut self, tolerance_m: f64) -> Result<(), StandError> {
        let Some(path) = self.geometry_model.clone() else {
            return Ok(());
        };
        let text = self.text.clone();
        let span_of = |key: &str| text.find(key).unwrap_or(0);
        let cx = Ctx::new(&self.file, &text);
        let at_geometry = |msg: String| cx.at(span_of("[geometry]")..span_of("[geometry]"), msg);
        let loaded = rfe::modelfile::load(&path)
            .map_err(|e| at_geometry(format!("geometry.model {}: {e}", path.display())))?;
        let model = loaded.model;
        let nominal_force_n = model.forces.first().map(|f| f.force.norm()).unwrap_or(0.0);
        if !(nominal_force_n > 0.0) {
            return Err(at_geometry(format!(
                "geometry.model {} declares no excitation force; the characteristics are scaled to the model's excitation, so give the identification model",
                path.display()
            )));
        }
        let mut bodies: Vec<BodyGeometry> = Vec::new();
        for c in self
            .channels
            .iter()
            .filter(|c| c.kind == ChannelKind::Acceleration)
        {
            let name = c.body.as_deref().unwrap_or("");
            let Some(b) = model.bodies.iter().find(|b| b.name == name) else {
                let names: Vec<&str> = model.bodies.iter().map(|b| b.name.as_str()).collect();
                return Err(StandError {
                    file: self.file.clone(),
                    line: c.line,
                    column: 1,
                    message: format!(
                        "channel `{}`: body `{name}` is not in the geometry model {} (bodies: {})",
                        c.name,
                        path.display(),
                        names.join(", ")
                    ),
                });
            };
            let g = BodyGeometry::from_body(b);
            let s = g.body_from_global(c.position_m);
            let h = g.equivalent_box_half_extents();
            if (0..3).any(|k| s[k].abs() > h[k] + tolerance_m) {
                let lo = |k: usize| g.position[k] - h[k];
                return Err(StandError {
                    file: self.file.clone(),
                    line: c.line,
                    column: 1,
                    message: format!(
                        "channel `{}`: position [{:.0}, {:.0}, {:.0}] mm is not on body `{name}`: in its principal axes the point is at [{:.0}, {:.0}, {:.0}] mm from the centre of mass, but the body (a {:.0} × {:.0} × {:.0} mm box of its mass and inertia in {}) reaches only ±[{:.0}, {:.0}, {:.0}] mm; put the sensor on the body (e.g. x {:.0}..{:.0}, y {:.0}..{:.0}, z {:.0}..{:.0} mm for axis-aligned bodies) or name the body it is on",
                        c.name,
                        c.position_m[0] * 1e3, c.position_m[1] * 1e3, c.position_m[2] * 1e3,
                        s[0] * 1e3, s[1] * 1e3, s[2] * 1e3,
                        2e3 * h[0], 2e3 * h[1], 2e3 * h[2],
                        path.display(),
                        h[0] * 1e3, h[1] * 1e3, h[2] * 1e3,
                        lo(0) * 1e3, (lo(0) + 2.0 * h[0]) * 1e3, lo(1) * 1e3, (lo(1) + 2.0 * h[1]) * 1e3, lo(2) * 1e3, (lo(2) + 2.0 * h[2]) * 1e3,
                    ),
                });
            }
            if !bodies.iter().any(|x| x.name == g.name) {
                bodies.push(g);
            }
        }
        let outputs = model
            .outputs
            .iter()
            .filter(|o| bodies.iter().any(|b| b.name == model.bodies[o.body].name))
            .map(|o| GeometryOutput {
                body: model.bodies[o.body].name.clone(),
                dof: o.dof,
                quantity: o.quantity.as_str().to_string(),
            })
            .collect();
        self.geometry = Some(Geometry {
            source: path.display().to_string(),
            bodies,
            nominal_force_n,
            outputs,
        });
        Ok(())
    }

    /// The force channel's index in stream order (validated to exist exactly once).
    pub fn force_channel(&self) -> usize {
        force_channel(&self.channels)
    }

    /// The DAQ configuration this stand asks for.
    pub fn daq_config(&self) -> crate::daq::DaqConfig {
        crate::daq::DaqConfig {
            sample_rate_hz: self.daq.sample_rate_hz,
            channels: self.channels.iter().map(|c| c.device_channel).collect(),
            samples_per_block: self.daq.samples_per_block,
        }
    }
}

/// The index of the force channel among `channels` (stream order), the first one when none is a
/// force channel (a stand file has exactly one).
pub fn force_channel(channels: &[Channel]) -> usize {
    channels
        .iter()
        .position(|c| c.kind == ChannelKind::Force)
        .unwrap_or(0)
}

/// The stand's exciter: `[shaker]`, or `[generator]` with `[amplifier]` (never both), and the
/// span of its port for later messages.
fn exciter(
    cx: &Ctx<'_>,
    raw: &RawStand,
) -> Result<(ShakerPort, Option<GeneratorStand>, Range<usize>), StandError> {
    match (&raw.shaker, &raw.generator) {
        (Some(_), Some(g)) => Err(cx.at(
            g.span(),
            "the stand has both [shaker] and [generator]; it has one exciter: a shaker controller ([shaker]) or a signal generator driving a power amplifier ([generator] and [amplifier]); remove one",
        )),
        (None, None) => Err(cx.at(
            0..0,
            "the stand has no exciter: add [shaker] (a shaker controller) or [generator] and [amplifier] (a signal generator driving a power amplifier)",
        )),
        (Some(rs), None) => {
            if let Some(a) = &raw.amplifier {
                return Err(cx.at(
                    a.span(),
                    "[amplifier] belongs to a [generator] stand; a shaker controller holds its force itself (shaker.max_force); remove [amplifier]",
                ));
            }
            let r = rs.get_ref();
            Ok((shaker_port(cx, r)?, None, r.port.span()))
        }
        (None, Some(rg)) => {
            let (g, shaker) = generator::generator_section(cx, rg, raw.amplifier.as_ref())?;
            Ok((shaker, Some(g), rg.span()))
        }
    }
}

/// `[shaker]`: its port and settings.
fn shaker_port(cx: &Ctx<'_>, rs: &RawShaker) -> Result<ShakerPort, StandError> {
    Ok(ShakerPort {
        port: port_spec(rs.port.get_ref()),
        baud: baud(cx, &rs.baud, "shaker.baud", 115_200)?,
        identity: rs.identity.clone().unwrap_or_default(),
        timeout: match &rs.timeout {
            Some(t) => Duration::from_secs_f64(cx.positive(t, Dim::TIME, "shaker.timeout")?),
            None => Duration::from_millis(500),
        },
        retries: rs.retries.unwrap_or(2),
        max_force_n: match &rs.max_force {
            Some(f) => cx.positive(f, Dim::FORCE, "shaker.max_force")?,
            None => 5000.0,
        },
    })
}

/// `[daq]`: its port and settings (`timeout` and `retries` hold on CAN too).
fn daq_port(cx: &Ctx<'_>, rd: &RawDaq) -> Result<DaqPort, StandError> {
    let mut daq = DaqPort {
        port: port_spec(rd.port.get_ref()),
        baud: baud(cx, &rd.baud, "daq.baud", 3_000_000)?,
        inputs: match &rd.inputs {
            Some(n) if *n.get_ref() == 0 => {
                return Err(cx.at(
                    n.span(),
                    "daq.inputs must be ≥ 1 (the number of analog inputs the DAQ has)",
                ))
            }
            Some(n) => Some(*n.get_ref()),
            None => None,
        },
        identity: rd.identity.clone().unwrap_or_default(),
        sample_rate_hz: cx.positive(&rd.sample_rate, Dim::FREQUENCY, "daq.sample_rate")?,
        samples_per_block: match &rd.samples_per_block {
            Some(s) if *s.get_ref() == 0 => {
                return Err(cx.at(s.span(), "daq.samples_per_block must be ≥ 1"))
            }
            Some(s) => *s.get_ref(),
            None => 64,
        },
        timeout: match &rd.timeout {
            Some(t) => Duration::from_secs_f64(cx.positive(t, Dim::TIME, "daq.timeout")?),
            None => Duration::from_millis(500),
        },
        retries: rd.retries.unwrap_or(2),
        input_range_v: match &rd.input_range {
            Some(r) => cx.positive(r, Dim::VOLTAGE, "daq.input_range")?,
            None => DEFAULT_INPUT_RANGE_V,
        },
        can: can_settings(cx, rd.can.as_ref())?,
        canopen: None,
    };
    if let Some(c) = &rd.canopen {
        let on_can = matches!(daq.port, PortSpec::Can(_) | PortSpec::Sim);
        daq.canopen = Some(canopen::canopen_port(cx, c, rd.port.span(), on_can)?);
    }
    // `daq.timeout` and `daq.retries` hold for a DAQ on CAN too (when given: a CAN DAQ's own
    // default answer timeout is 1 s).
    if rd.timeout.is_some() {
        daq.can.answer_timeout = daq.timeout;
    }
    daq.can.retries = daq.retries;
    Ok(daq)
}

/// The shaker on serial (never CAN), a CAN DAQ with an interface name, two distinct ports.
fn check_ports(
    cx: &Ctx<'_>,
    shaker: &ShakerPort,
    daq: &DaqPort,
    shaker_span: Range<usize>,
    rd: &RawDaq,
) -> Result<(), StandError> {
    if matches!(shaker.port, PortSpec::Can(_)) {
        return Err(cx.at(shaker_span, "shaker.port: the shaker controller speaks SCPI over serial; give a device path (or \"sim\"), not a CAN interface"));
    }
    if let PortSpec::Can(iface) = &daq.port {
        if iface.is_empty() {
            return Err(cx.at(
                rd.port.span(),
                "daq.port = \"can:\" needs an interface name, e.g. \"can:can0\" or \"can:vcan0\"",
            ));
        }
    }
    if let (PortSpec::Path(a), PortSpec::Path(b)) = (&shaker.port, &daq.port) {
        if a == b {
            return Err(cx.at(
                rd.port.span(),
                format!("daq.port {b} is also the shaker's port; each device needs its own port"),
            ));
        }
    }
    Ok(())
}

/// The `[[channel]]` entries: one force channel, at least one accelerometer, unique names and
/// inputs, blocks that fit a frame.
fn channel_map(cx: &Ctx<'_>, raw: &RawStand, daq: &DaqPort) -> Result<Vec<Channel>, StandError> {
    if raw.channel.is_empty() {
        return Err(cx.at(
            raw.daq.span(),
            "no [[channel]] entries; list at least the force channel and one accelerometer",
        ));
    }
    let mut channels: Vec<Channel> = Vec::new();
    for sc in &raw.channel {
        let c = channel(cx, sc, &channels, daq)?;
        channels.push(c);
    }
    let rd = raw.daq.get_ref();
    let forces: Vec<&Channel> = channels
        .iter()
        .filter(|c| c.kind == ChannelKind::Force)
        .collect();
    if forces.len() != 1 {
        let span = raw.channel.first().map(|c| c.span()).unwrap_or(0..0);
        return Err(cx.at(
            span,
            format!("the channel map needs exactly one `kind = \"force\"` channel (the closed loop and every FRF refer to it); found {}", forces.len()),
        ));
    }
    if !channels.iter().any(|c| c.kind == ChannelKind::Acceleration) {
        return Err(cx.at(
            raw.daq.span(),
            "the channel map has no acceleration channel",
        ));
    }
    let frame = channels.len() * daq.samples_per_block as usize * 4 + 9;
    if frame > crate::daq::frame::MAX_FRAME {
        let span = rd
            .samples_per_block
            .as_ref()
            .map(|s| s.span())
            .unwrap_or(raw.daq.span());
        return Err(cx.at(
            span,
            format!("{} channels × {} samples per block do not fit a {}-byte frame; lower daq.samples_per_block", channels.len(), daq.samples_per_block, crate::daq::frame::MAX_FRAME),
        ));
    }
    Ok(channels)
}

/// One `[[channel]]`; `earlier` are the ones before it.
fn channel(
    cx: &Ctx<'_>,
    sc: &Spanned<RawChannel>,
    earlier: &[Channel],
    daq: &DaqPort,
) -> Result<Channel, StandError> {
    let c = sc.get_ref();
    let name = c.name.get_ref().trim().to_string();
    if name.is_empty() {
        return Err(cx.at(c.name.span(), "channel name is empty"));
    }
    if let Some(o) = earlier.iter().find(|o| o.name == name) {
        return Err(cx.at(
            c.name.span(),
            format!(
                "channel name `{name}` is already used on line {}; names must be unique",
                o.line
            ),
        ));
    }
    let dc = *c.device_channel.get_ref();
    if let Some(n) = daq.inputs.filter(|n| dc >= *n) {
        return Err(cx.at(
            c.device_channel.span(),
            format!("channel `{name}`: device_channel {dc} is beyond the DAQ's {n} inputs (numbered 0 to {}); check the wiring, the channel number or daq.inputs", n - 1),
        ));
    }
    if let Some(o) = earlier.iter().find(|o| o.device_channel == dc) {
        return Err(cx.at(
            c.device_channel.span(),
            format!("channel `{name}`: device_channel {dc} is already used by channel `{}` (line {}); each channel needs its own DAQ input", o.name, o.line),
        ));
    }
    let kind = *c.kind.get_ref();
    let sensitivity = sensitivity(cx, &c.sensitivity, kind, &name)?;
    let (body, position_m, direction) = match kind {
        ChannelKind::Force => {
            let position = match &c.position {
                Some(p) => vec3(cx, p, &name)?,
                None => [0.0; 3],
            };
            let direction = match &c.direction {
                Some(d) => cx.unit_vector(d, &format!("channel `{name}`: direction"))?,
                None => [0.0; 3],
            };
            (
                c.body.as_ref().map(|b| b.get_ref().clone()),
                position,
                direction,
            )
        }
        ChannelKind::Acceleration => {
            let missing = |what: &str| {
                cx.at(
                    sc.span(),
                    format!("acceleration channel `{name}` needs `{what}`"),
                )
            };
            let body = c
                .body
                .as_ref()
                .ok_or_else(|| missing("body"))?
                .get_ref()
                .clone();
            let position = vec3(
                cx,
                c.position.as_ref().ok_or_else(|| missing("position"))?,
                &name,
            )?;
            let direction = cx.unit_vector(
                c.direction.as_ref().ok_or_else(|| missing("direction"))?,
                &format!("channel `{name}`: direction"),
            )?;
            (Some(body), position, direction)
        }
    };
    Ok(Channel {
        name,
        device_channel: dc,
        kind,
        sensitivity,
        body,
        position_m,
        direction,
        line: cx.line_of(sc.span()),
    })
}

/// `[faults]`: injected stream and device faults of a simulated stand.
fn faults(cx: &Ctx<'_>, f: &RawFaults) -> Result<Faults, StandError> {
    Ok(Faults {
        seed: f.seed.unwrap_or(1),
        drop: cx.probability(&f.drop, "drop")?,
        corrupt: cx.probability(&f.corrupt, "corrupt")?,
        duplicate: cx.probability(&f.duplicate, "duplicate")?,
        delay: cx.probability(&f.delay, "delay")?,
        delay_time: match &f.delay_time {
            Some(t) => Duration::from_secs_f64(cx.positive(t, Dim::TIME, "faults.delay_time")?),
            None => Duration::from_millis(20),
        },
        daq_silent_after_blocks: f.daq_silent_after_blocks,
        shaker_silent_after_commands: f.shaker_silent_after_commands,
        cable_pull_after_blocks: f.cable_pull_after_blocks,
        amplifier_trip_after_lines: f.amplifier_trip_after_lines,
        amplifier_surge_after_lines: f.amplifier_surge_after_lines,
        amplifier_surge_factor: match &f.amplifier_surge_factor {
            None => 2.0,
            Some(x) if *x.get_ref() > 0.0 && x.get_ref().is_finite() => *x.get_ref(),
            Some(x) => return Err(cx.at(
                x.span(),
                "faults.amplifier_surge_factor must be > 0 (the amplifier's gain multiplies by it)",
            )),
        },
    })
}

/// A channel's sensitivity (V per N or per m/s²), in the unit its `kind` needs; a unit of the
/// other kind's says that `kind` or the unit is wrong.
fn sensitivity(
    cx: &Ctx<'_>,
    v: &Spanned<Value>,
    kind: ChannelKind,
    name: &str,
) -> Result<f64, StandError> {
    let (dim, other, other_kind) = match kind {
        ChannelKind::Force => (
            Dim::FORCE_SENSITIVITY,
            Dim::ACCELERATION_SENSITIVITY,
            "acceleration",
        ),
        ChannelKind::Acceleration => (
            Dim::ACCELERATION_SENSITIVITY,
            Dim::FORCE_SENSITIVITY,
            "force",
        ),
    };
    let what = format!("channel `{name}`: sensitivity");
    cx.positive(v, dim, &what).map_err(|e| match v.get_ref() {
        Value::Text(t) if v.get_ref().si(dim).is_err() && v.get_ref().si(other).is_ok() => cx.at(
            v.span(),
            format!("{what} \"{t}\" is the unit of a {other_kind} sensor, but the channel's kind is {kind:?}; fix `kind` or the unit"),
        ),
        _ => e,
    })
}

fn vec3(cx: &Ctx<'_>, p: &Spanned<Vec<Value>>, name: &str) -> Result<[f64; 3], StandError> {
    let v = p.get_ref();
    if v.len() != 3 {
        return Err(cx.at(p.span(), format!("channel `{name}`: position must be three values [x, y, z], e.g. [\"320 mm\", \"0 mm\", \"45 mm\"]")));
    }
    let mut out = [0.0; 3];
    for (o, x) in out.iter_mut().zip(v) {
        *o = x
            .si(Dim::LENGTH)
            .map_err(|e| cx.at(p.span(), format!("channel `{name}`: position: {e}")))?;
    }
    Ok(out)
}

fn truth(cx: &Ctx<'_>, st: &Spanned<RawTruth>, channels: &[Channel]) -> Result<Truth, StandError> {
    let t = st.get_ref();
    let model = match (&t.model, &t.sdof) {
        (Some(_), Some(s)) => {
            return Err(cx.at(s.span(), "[truth] has both `model` and `sdof`; keep one"))
        }
        (None, Some(s)) => {
            let r = s.get_ref();
            let eta = *r.loss_factor.get_ref();
            if !(0.0..1.0).contains(&eta) {
                return Err(cx.at(
                    r.loss_factor.span(),
                    "truth.sdof.loss_factor must be within 0..1 (η = ψ/2π)",
                ));
            }
            TruthModel::Sdof {
                body: r.body.clone(),
                mass: cx.positive(&r.mass, Dim::MASS, "truth.sdof.mass")?,
                stiffness: cx.positive(&r.stiffness, Dim::STIFFNESS, "truth.sdof.stiffness")?,
                loss_factor: eta,
                direction: cx.unit_vector(&r.direction, "truth.sdof.direction")?,
            }
        }
        (Some(m), None) => TruthModel::ModelFile(PathBuf::from(m.get_ref())),
        (None, None) => {
            return Err(cx.at(
                st.span(),
                "[truth] needs `model = \"path\"` or an `sdof = {...}` table",
            ))
        }
    };
    if let TruthModel::Sdof { body, .. } = &model {
        for c in channels
            .iter()
            .filter(|c| c.kind == ChannelKind::Acceleration)
        {
            if c.body.as_deref() != Some(body) {
                return Err(StandError {
                    file: cx.src.file.to_string(),
                    line: c.line,
                    column: 1,
                    message: format!(
                        "channel `{}`: body `{}` is not in the truth model (it has one body, `{body}`)",
                        c.name,
                        c.body.as_deref().unwrap_or("")
                    ),
                });
            }
        }
    }
    let speed = match &t.speed {
        Some(s) if *s.get_ref() > 0.0 && s.get_ref().is_finite() => *s.get_ref(),
        Some(s) => return Err(cx.at(s.span(), "truth.speed must be > 0 (1 = real time)")),
        None => 1.0,
    };
    Ok(Truth {
        model,
        shaker_gain: t.shaker_gain.unwrap_or(1.0),
        shaker_cutoff_hz: match &t.shaker_cutoff {
            Some(v) => cx.positive(v, Dim::FREQUENCY, "truth.shaker_cutoff")?,
            None => f64::INFINITY,
        },
        noise_acceleration: match &t.noise_acceleration {
            Some(v) => cx
                .value(v, Dim::ACCELERATION, "truth.noise_acceleration")?
                .abs(),
            None => 0.0,
        },
        noise_force: match &t.noise_force {
            Some(v) => cx.value(v, Dim::FORCE, "truth.noise_force")?.abs(),
            None => 0.0,
        },
        speed,
        seed: t.seed.unwrap_or(1),
        amplifier_gain_n_per_v: match &t.amplifier_gain {
            None => None,
            Some(v) => Some(generator::per(
                cx,
                v,
                Dim::FORCE,
                &[("V", 1.0), ("mV", 1e-3)],
                "truth.amplifier_gain",
                "1040 N/V",
            )?),
        },
    })
}

#[cfg(test)]
mod tests;
