//! The simulated stand: a shaker controller and a DAQ that serve the real protocols (SCPI and the
//! COBS/CRC stream) over pseudo-terminals — or any [`Transport`] — driven by a truth
//! [`Plant`], with sensor noise and configurable faults. Every injected fault is
//! logged so tests can check that the host detected each one.

pub mod clock;
pub mod generator;
mod link;
pub mod plant;
pub mod signal;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rand::{Rng, SeedableRng};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::task::JoinHandle;

use crate::daq::frame::{self, kind, FrameDecoder, Message};
use crate::daq::{ChannelInfo, DaqConfig, StreamInfo};
use crate::device::DeviceIdentity;
use crate::shaker::scpi::{self, Command, Function, Line, LineBuffer, ScpiError};
use crate::stand::{ChannelKind, Faults, PortSpec, Stand};
use crate::transport::{pty_pair, Transport, TransportError};
use clock::{SimClock, SimClockedDaq};
pub use link::InjectedFault;
use link::{lock, read_host, send_answer, Shared, SharedRef};
use plant::{Interaction, Plant, PlantError};
use signal::{Excitation, SignalGenerator, SimChannel, Source, VOLTS_PER_COUNT};

/// Why the simulated stand could not start.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A pseudo-terminal could not be created.
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// The truth cannot be evaluated.
    #[error(transparent)]
    Plant(#[from] PlantError),
    /// The CAN interface could not be used.
    #[error(transparent)]
    Can(#[from] crate::can::CanError),
    /// The stand file has no truth section.
    #[error("{0}: the simulated stand needs a [truth] section")]
    NoTruth(String),
    /// A generator was to be served but the setup has none.
    #[error("the simulated stand has no [generator] to serve")]
    NoGenerator,
}

/// Identity strings the simulated devices answer with (override to test identity checks).
#[derive(Debug, Clone)]
pub struct SimIdentities {
    /// Shaker `*IDN?` answer.
    pub shaker: DeviceIdentity,
    /// DAQ HELLO answer.
    pub daq: DeviceIdentity,
}

impl Default for SimIdentities {
    fn default() -> Self {
        let id = |m: &str, s: &str| DeviceIdentity {
            manufacturer: "IDENT-SIM".into(),
            model: m.into(),
            serial: s.into(),
            firmware: env!("CARGO_PKG_VERSION").into(),
        };
        SimIdentities {
            shaker: id("SHAKER-4K", "S0001"),
            daq: id("DAQ-8", "D0001"),
        }
    }
}

/// Everything a simulated device pair needs.
pub struct SimSetup {
    /// Truth.
    pub plant: Arc<dyn Plant>,
    /// Shaker-structure interaction.
    pub interaction: Interaction,
    /// DAQ inputs (device channel numbers, sources, sensitivities, noise).
    pub channels: Vec<SimChannel>,
    /// Native sample rate (Hz); CONFIGURE may ask for another one, which is granted.
    pub sample_rate_hz: f64,
    /// Simulated time per wall-clock time.
    pub speed: f64,
    /// Noise seed.
    pub seed: u64,
    /// Faults to inject.
    pub faults: Faults,
    /// Largest force the controller accepts (N).
    pub max_force_n: f64,
    /// Identities.
    pub identities: SimIdentities,
    /// A signal generator + amplifier instead of the shaker controller (generator stands).
    pub generator: Option<SimGeneratorSetup>,
}

/// The simulated generator of a generator stand, and where it is served.
#[derive(Debug, Clone, PartialEq)]
pub struct SimGeneratorSetup {
    /// The instrument and its amplifier.
    pub device: generator::SimGeneratorSetup,
    /// Served on a local TCP port (127.0.0.1) rather than a pseudo-terminal.
    pub tcp: bool,
}

impl SimGeneratorSetup {
    /// The simulated generator a stand's `[generator]`, `[amplifier]`, `[truth]` and `[faults]`
    /// describe (`None` for a shaker-controller stand).
    pub fn from_stand(stand: &Stand) -> Option<SimGeneratorSetup> {
        let g = stand.generator.as_ref()?;
        let true_gain = stand
            .truth
            .as_ref()
            .and_then(|t| t.amplifier_gain_n_per_v)
            .unwrap_or(g.amplifier.gain_n_per_v);
        // The instrument the stand expects, when it is one the simulator emulates (a Keysight
        // 33522B, a Rigol DG1062Z, a Tektronix AFG31022); the plain simulated generator else.
        let emulated = generator::emulation::Emulation::for_identity(&g.identity);
        let identity = if emulated.manufacturer == "IDENT-SIM" {
            DeviceIdentity {
                manufacturer: "IDENT-SIM".into(),
                model: "SIGGEN-2".into(),
                serial: "G0001".into(),
                firmware: env!("CARGO_PKG_VERSION").into(),
            }
        } else {
            emulated.identity(env!("CARGO_PKG_VERSION"))
        };
        Some(SimGeneratorSetup {
            device: generator::SimGeneratorSetup {
                identity,
                channel: g.channel,
                amplifier_gain_n_per_v: true_gain,
                amplifier_trip_after_lines: stand.faults.amplifier_trip_after_lines,
                amplifier_surge_after_lines: stand.faults.amplifier_surge_after_lines,
                surge_factor: stand.faults.amplifier_surge_factor,
                faults: generator::GeneratorFaults::default(),
            },
            tcp: matches!(g.port, crate::stand::GeneratorAddress::Sim { tcp: true }),
        })
    }
}

impl SimSetup {
    /// The setup described by a stand file's `[truth]` and `[faults]`.
    pub fn from_stand(stand: &Stand) -> Result<SimSetup, SimError> {
        let truth = stand
            .truth
            .as_ref()
            .ok_or_else(|| SimError::NoTruth(stand.file.clone()))?;
        let plant: Arc<dyn Plant> = Arc::from(plant::plant_for(truth, &stand.channels)?);
        let mut sensor = 0;
        let channels = stand
            .channels
            .iter()
            .map(|c| {
                let (source, noise_rms) = match c.kind {
                    ChannelKind::Force => (Source::Force, truth.noise_force),
                    ChannelKind::Acceleration => {
                        sensor += 1;
                        (Source::Sensor(sensor - 1), truth.noise_acceleration)
                    }
                };
                SimChannel {
                    device_channel: c.device_channel,
                    source,
                    sensitivity: c.sensitivity,
                    noise_rms,
                }
            })
            .collect();
        Ok(SimSetup {
            plant,
            interaction: Interaction {
                gain: truth.shaker_gain,
                cutoff_hz: truth.shaker_cutoff_hz,
            },
            channels,
            sample_rate_hz: stand.daq.sample_rate_hz,
            speed: truth.speed,
            seed: truth.seed,
            faults: stand.faults.clone(),
            max_force_n: stand.shaker.max_force_n * 1.25,
            identities: SimIdentities::default(),
            generator: SimGeneratorSetup::from_stand(stand),
        })
    }
}

/// A running simulated stand.
pub struct SimStand {
    /// Path of the shaker controller's port (a pty, or `mem:` for in-memory transports).
    pub shaker_port: String,
    /// Path of the DAQ's port.
    pub daq_port: String,
    shared: SharedRef,
    tasks: Vec<JoinHandle<()>>,
    generator: Option<generator::SimGenerator>,
    /// The serial DAQ's sample clock (`None` for a DAQ on CAN).
    clock: Option<SimClock>,
}

impl SimStand {
    /// Serves the stand's simulated devices on two new pseudo-terminals. Call inside a tokio
    /// runtime; the devices run until [`SimStand::shutdown`] or drop.
    pub fn start(stand: &Stand) -> Result<SimStand, SimError> {
        if stand.daq.canopen.is_some() {
            return Err(crate::can::CanError::Config {
                detail: format!("{}: the DAQ is a CANopen node ([daq.canopen]): serve it on a CAN interface (`ident sim --can vcan0`, SimStand::start_can)", stand.file),
            }
            .into());
        }
        Self::start_with(SimSetup::from_stand(stand)?)
    }

    /// Like [`SimStand::start`] with an explicit setup.
    pub fn start_with(setup: SimSetup) -> Result<SimStand, SimError> {
        if setup.generator.is_some() {
            let shared: SharedRef = Arc::new(Mutex::new(Shared::default()));
            let (port, task, gen) = spawn_generator(&setup, shared.clone())?;
            let daq = pty_pair("daq")?;
            let daq_port = daq.path.clone();
            let s2 = shared.clone();
            let clock = SimClock::default();
            let c2 = clock.clone();
            let t2 = tokio::spawn(async move { serve_daq(daq.device, s2, setup, c2).await });
            return Ok(SimStand {
                shaker_port: port,
                daq_port,
                shared,
                tasks: vec![task, t2],
                generator: Some(gen),
                clock: Some(clock),
            });
        }
        let shaker = pty_pair("shaker")?;
        let daq = pty_pair("daq")?;
        let (shaker_port, daq_port) = (shaker.path.clone(), daq.path.clone());
        Ok(Self::serve(
            setup,
            shaker.device,
            daq.device,
            shaker_port,
            daq_port,
        ))
    }

    /// Serves the devices over given transports (e.g. [`crate::transport::MemoryTransport`]).
    pub fn serve<S: Transport + 'static, D: Transport + 'static>(
        setup: SimSetup,
        shaker_io: S,
        daq_io: D,
        shaker_port: String,
        daq_port: String,
    ) -> SimStand {
        let shared: SharedRef = Arc::new(Mutex::new(Shared::default()));
        let s1 = shared.clone();
        let s2 = shared.clone();
        let ids = setup.identities.clone();
        let faults = setup.faults.clone();
        let max_force = setup.max_force_n;
        let interaction = setup.interaction;
        let t1 = tokio::spawn(async move {
            serve_shaker(shaker_io, s1, ids.shaker, faults, max_force, interaction).await
        });
        let clock = SimClock::default();
        let c2 = clock.clone();
        let t2 = tokio::spawn(async move { serve_daq(daq_io, s2, setup, c2).await });
        SimStand {
            shaker_port,
            daq_port,
            shared,
            tasks: vec![t1, t2],
            generator: None,
            clock: Some(clock),
        }
    }

    /// The simulated serial DAQ's sample clock: the samples it has produced since START
    /// ([`clock`]); `None` for a DAQ served on CAN.
    pub fn clock(&self) -> Option<SimClock> {
        self.clock.clone()
    }

    /// `daq` (a host's driver connected to this simulator's DAQ) with the simulator's sample
    /// clock, so that a sweep in the same process counts settling from the stream the simulator
    /// has produced rather than from wall-clock time ([`clock`]). A DAQ on CAN is returned as it is.
    pub fn clocked(&self, daq: Box<dyn crate::daq::Daq>) -> Box<dyn crate::daq::Daq> {
        match &self.clock {
            Some(c) => Box::new(SimClockedDaq::new(daq, c.clone())),
            None => daq,
        }
    }

    /// `rig` (connected to this simulator's ports) with its DAQ [`SimStand::clocked`].
    pub fn clock_rig(&self, rig: crate::rig::Rig) -> crate::rig::Rig {
        crate::rig::Rig {
            daq: self.clocked(rig.daq),
            ..rig
        }
    }

    /// The stand with `port = "sim"` replaced by this simulator's ports.
    pub fn bind(&self, stand: &Stand) -> Stand {
        let mut s = stand.clone();
        if s.shaker.port == PortSpec::Sim {
            s.shaker.port = PortSpec::Path(self.shaker_port.clone());
        }
        if let Some(g) = &mut s.generator {
            if let crate::stand::GeneratorAddress::Sim { .. } = g.port {
                g.port = match self
                    .shaker_port
                    .strip_prefix("tcp:")
                    .and_then(crate::transport::SocketAddress::parse)
                {
                    Some(a) => crate::stand::GeneratorAddress::Tcp(a),
                    None => crate::stand::GeneratorAddress::Serial(self.shaker_port.clone()),
                };
            }
        }
        if s.daq.port == PortSpec::Sim {
            s.daq.port = match self.daq_port.strip_prefix("can:") {
                Some(iface) => PortSpec::Can(iface.to_string()),
                None => PortSpec::Path(self.daq_port.clone()),
            };
        }
        s
    }

    /// Faults injected so far.
    pub fn injected(&self) -> Vec<InjectedFault> {
        lock(&self.shared).injected.clone()
    }

    /// What the simulated controller currently drives.
    pub fn excitation(&self) -> Excitation {
        lock(&self.shared).excitation.clone()
    }

    /// The simulated signal generator's state (generator stands).
    pub fn generator_state(&self) -> Option<generator::GeneratorState> {
        self.generator.as_ref().map(|g| g.state())
    }

    /// Serves the stand's simulated shaker controller on a pseudo-terminal and its DAQ on the CAN
    /// interface `iface` (docs/daq-can.md, identifiers and frames from the stand's `[daq.can]`),
    /// both driven by the same truth. The DAQ's signals are those of [`SimStand::start`], and so
    /// are the stand's `[faults]`, per block ([`crate::can::sim::SimFaults::per_block`]: a
    /// dropped or corrupted block loses or damages one of its CAN frames; a pulled cable closes
    /// the shaker's pty and silences the DAQ). Every injected fault is in [`SimStand::injected`].
    /// A stand whose DAQ is a CANopen node (`[daq.canopen]`) gets the simulated CANopen node of
    /// [`crate::canopen::sim`] instead; of the stand's `[faults]` only `daq_silent_after_blocks`
    /// applies to it (the node falls silent: a lost heartbeat).
    pub fn start_can(stand: &Stand, iface: &str) -> Result<SimStand, SimError> {
        use crate::can::sim::{SimCanDaq, SimCanDaqSettings};
        let setup = SimSetup::from_stand(stand)?;
        let shaker = pty_pair("shaker")?;
        let shared: SharedRef = Arc::new(Mutex::new(Shared::default()));
        let can = &stand.daq.can;
        let mut dev = SimCanDaqSettings {
            command_id: can.command_id,
            status_id: can.status_id,
            data_id: can.data_id,
            frames: can.frames,
            volts_per_count: VOLTS_PER_COUNT as f32,
            real_time: true,
            speed: setup.speed,
            ..SimCanDaqSettings::default()
        };
        dev.identity = setup.identities.daq.clone();
        dev.channel_count = setup
            .channels
            .iter()
            .map(|c| c.device_channel + 1)
            .max()
            .unwrap_or(1);
        dev.faults.per_block = Some(setup.faults.clone());
        let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let t2 = match &stand.daq.canopen {
            // A CANopen node (docs/canopen.md) instead of the DAQ-over-CAN protocol. Its inputs
            // are 16-bit: the 24-bit counts of the signal scaled to the EDS's 10 V / 32768.
            Some(c) => {
                let config = |e: String| crate::can::CanError::Config { detail: e };
                let node = match &c.eds {
                    Some(p) => {
                        crate::canopen::eds::ObjectDictionary::load(p, c.node_id).map(|od| {
                            crate::canopen::sim::SimCanOpenNode::with_dictionary(c.node_id, od)
                        })
                    }
                    None => crate::canopen::sim::SimCanOpenNode::new(c.node_id),
                }
                .map_err(|e| config(e.to_string()))?;
                // Of the stand's [faults], a DAQ falling silent applies: the node stops (no
                // heartbeat, PDO or SDO answer) after that many blocks' SYNCs.
                let spb = stand.daq.samples_per_block as u64;
                let node = node.with_faults(crate::canopen::sim::SimNodeFaults {
                    silent_after_syncs: setup.faults.daq_silent_after_blocks.map(|b| b * spb),
                    ..Default::default()
                });
                let bus = crate::can::CanBus::open(iface)?;
                let mut counts = can_signal(&setup, shared.clone());
                let per_count = (10.0 / 32_768.0) / VOLTS_PER_COUNT;
                let signal: crate::can::sim::Signal =
                    Box::new(move |ch, k| (counts(ch, k) as f64 / per_count).round() as i32);
                tokio::spawn(async move {
                    let _ = node.serve(Box::new(bus), signal, stop_rx).await;
                })
            }
            None => {
                let s0 = shared.clone();
                let sim = SimCanDaq::bind(iface, dev)?.on_fault(Box::new(move |kind, seq| {
                    let mut sh = lock(&s0);
                    sh.injected.push(InjectedFault { kind, seq });
                    sh.cable_pulled |= kind == "cable_pull";
                }));
                let signal = can_signal(&setup, shared.clone());
                tokio::spawn(async move {
                    let _ = sim.serve(signal, None, stop_rx).await;
                })
            }
        };
        let (shaker_port, t1, generator) = if setup.generator.is_some() {
            drop(shaker);
            let (port, task, gen) = spawn_generator(&setup, shared.clone())?;
            (port, task, Some(gen))
        } else {
            let s1 = shared.clone();
            let ids = setup.identities.clone();
            let (faults, max_force, interaction) =
                (setup.faults.clone(), setup.max_force_n, setup.interaction);
            let shaker_port = shaker.path.clone();
            let io = shaker.device;
            let t1 = tokio::spawn(async move {
                serve_shaker(io, s1, ids.shaker, faults, max_force, interaction).await
            });
            (shaker_port, t1, None)
        };
        // Dropping the sender stops the CAN simulator with the tasks.
        let keep = tokio::spawn(async move {
            std::future::pending::<()>().await;
            drop(stop_tx);
        });
        Ok(SimStand {
            shaker_port,
            daq_port: format!("can:{iface}"),
            shared,
            tasks: vec![t1, t2, keep],
            generator,
            clock: None,
        })
    }

    /// Stops the devices and closes their ports.
    pub fn shutdown(self) {
        for t in &self.tasks {
            t.abort();
        }
    }
}

impl Drop for SimStand {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
    }
}

/// Serves the setup's simulated generator on a new pseudo-terminal or a local TCP port
/// (127.0.0.1, a port the system picks): its port (`/dev/pts/N` or `tcp:127.0.0.1:PORT`), task
/// and handle.
fn spawn_generator(
    setup: &SimSetup,
    shared: SharedRef,
) -> Result<(String, JoinHandle<()>, generator::SimGenerator), SimError> {
    let Some(g) = &setup.generator else {
        return Err(SimError::NoGenerator);
    };
    let gen = generator::SimGenerator::new(g.device.clone(), shared);
    let served = gen.clone();
    if g.tcp {
        let socket_error = |e: std::io::Error| {
            SimError::Transport(TransportError::Socket {
                port: "tcp:127.0.0.1".into(),
                detail: e.to_string(),
            })
        };
        let std_listener = std::net::TcpListener::bind("127.0.0.1:0").map_err(socket_error)?;
        std_listener.set_nonblocking(true).map_err(socket_error)?;
        let port = std_listener.local_addr().map_err(socket_error)?.port();
        let listener = tokio::net::TcpListener::from_std(std_listener).map_err(socket_error)?;
        let task = tokio::spawn(async move { served.serve_tcp(listener).await });
        Ok((format!("tcp:127.0.0.1:{port}"), task, gen))
    } else {
        let pty = pty_pair("generator")?;
        let path = pty.path.clone();
        let task = tokio::spawn(async move { served.serve(pty.device, true).await });
        Ok((path, task, gen))
    }
}

async fn serve_shaker<T: Transport>(
    mut io: T,
    shared: SharedRef,
    identity: DeviceIdentity,
    faults: Faults,
    max_force: f64,
    interaction: Interaction,
) {
    let mut lines = LineBuffer::new();
    let mut buf = vec![0u8; 512];
    let mut errors: std::collections::VecDeque<ScpiError> = Default::default();
    let mut count: u64 = 0;
    let mut silent = false;
    loop {
        let Some(got) = read_lines(&mut io, &mut lines, &mut buf, &shared, true).await else {
            return;
        };
        for line in got {
            count += 1;
            if !silent
                && faults
                    .shaker_silent_after_commands
                    .is_some_and(|k| count > k)
            {
                silent = true;
                lock(&shared).injected.push(InjectedFault {
                    kind: "shaker_silent",
                    seq: count,
                });
            }
            if silent {
                continue;
            }
            let text = match line {
                Line::Text(t) => t,
                Line::Garbage(_) => {
                    push_error(
                        &mut errors,
                        ScpiError {
                            code: scpi::codes::COMMAND_ERROR,
                            message: "Command error;not text".into(),
                        },
                    );
                    continue;
                }
            };
            let answer = match scpi::parse_command(&text) {
                Err(e) => {
                    push_error(&mut errors, e);
                    None
                }
                Ok(cmd) => {
                    let mut sh = lock(&shared);
                    let exc = &mut sh.excitation;
                    match apply(cmd, exc, &identity, &mut errors, max_force, interaction) {
                        Ok(a) => a,
                        Err(e) => {
                            push_error(&mut errors, e);
                            None
                        }
                    }
                }
            };
            if !send_answer(&mut io, answer).await {
                return;
            }
        }
    }
}

/// The complete lines the host's next bytes finish ([`read_host`]; `None` as there).
async fn read_lines<T: Transport>(
    io: &mut T,
    lines: &mut LineBuffer,
    buf: &mut [u8],
    shared: &SharedRef,
    pty: bool,
) -> Option<Vec<Line>> {
    let n = read_host(io, buf, shared, pty).await?;
    let mut got = Vec::new();
    lines.feed(&buf[..n], |l| got.push(l));
    Some(got)
}

fn push_error(q: &mut std::collections::VecDeque<ScpiError>, e: ScpiError) {
    if q.len() >= 10 {
        q.pop_back();
        q.push_back(ScpiError {
            code: scpi::codes::QUEUE_OVERFLOW,
            message: "Queue overflow".into(),
        });
    } else {
        q.push_back(e);
    }
}

fn apply(
    cmd: Command,
    exc: &mut Excitation,
    id: &DeviceIdentity,
    errors: &mut std::collections::VecDeque<ScpiError>,
    max_force: f64,
    interaction: Interaction,
) -> Result<Option<String>, ScpiError> {
    let range = |x: f64, lo: f64, hi: f64, what: &str| {
        if (lo..=hi).contains(&x) {
            Ok(x)
        } else {
            Err(ScpiError::out_of_range(&format!(
                "{what} {x} outside {lo}..{hi}"
            )))
        }
    };
    Ok(match cmd {
        Command::Identify => Some(id.to_idn()),
        Command::Reset => {
            *exc = Excitation::default();
            None
        }
        Command::ClearStatus => {
            errors.clear();
            None
        }
        Command::OperationComplete => Some("1".into()),
        Command::SetFunction(f) => {
            exc.function = f;
            None
        }
        Command::QueryFunction => Some(exc.function.short().into()),
        Command::SetFrequency(f) => {
            exc.freq_hz = range(f, 0.1, 10_000.0, "frequency")?;
            None
        }
        Command::QueryFrequency => Some(format!("{}", exc.freq_hz)),
        Command::SetBandStart(f) => {
            exc.band_hz.0 = range(f, 0.0, 10_000.0, "band start")?;
            None
        }
        Command::SetBandStop(f) => {
            exc.band_hz.1 = range(f, 0.0, 10_000.0, "band stop")?;
            None
        }
        Command::SetDutyCycle(d) => {
            exc.duty = range(d, 0.01, 1.0, "duty cycle")?;
            None
        }
        Command::SetPeriod(p) => {
            exc.period_s = range(p, 0.01, 100.0, "period")?;
            None
        }
        Command::SetForce(f) => {
            exc.force_n = range(f, 0.0, max_force, "force")?;
            None
        }
        Command::QueryForce => Some(format!("{}", exc.force_n)),
        Command::SetOutput(on) => {
            exc.output_on = on;
            None
        }
        Command::QueryOutput => Some(if exc.output_on { "1" } else { "0" }.into()),
        Command::MeasureForce => {
            let f = if exc.function == Function::Sine {
                exc.freq_hz
            } else {
                0.5 * (exc.band_hz.0 + exc.band_hz.1)
            };
            let v = if exc.output_on {
                exc.force_n * interaction.at(f).norm()
            } else {
                0.0
            };
            Some(format!("{v:.3}"))
        }
        Command::QuestionableCondition => Some("0".into()),
        Command::NextError => Some(match errors.pop_front() {
            Some(e) => scpi::format_error_entry(&e),
            None => "0,\"No error\"".into(),
        }),
    })
}

/// How far the simulated DAQ may fall behind its schedule (wall-clock time at the stand's speed)
/// and still catch up; beyond it the schedule restarts from now and the simulated time has run
/// slower ([`clock`]). Catching up seconds of stream at once would flood the link and starve the
/// host's other devices of the very CPU the simulator lacked.
const MAX_BACKLOG: Duration = Duration::from_millis(200);

async fn serve_daq<T: Transport>(mut io: T, shared: SharedRef, setup: SimSetup, clock: SimClock) {
    let mut daq = SerialSimDaq::new(setup, clock);
    let mut dec = FrameDecoder::new();
    let mut rx = vec![0u8; 4096];
    let mut tx = Vec::with_capacity(8192);
    let mut next_tick = tokio::time::Instant::now();
    loop {
        let read = tokio::select! {
            r = io.read(&mut rx) => Some(r),
            _ = tokio::time::sleep_until(next_tick), if daq.streaming => None,
            _ = tokio::time::sleep(Duration::from_millis(50)), if !daq.streaming => { if lock(&shared).cable_pulled { return; } continue }
        };
        tx.clear();
        match read {
            Some(Ok(0)) | Some(Err(_)) => {
                if lock(&shared).cable_pulled {
                    return;
                }
                tokio::time::sleep(Duration::from_millis(10)).await;
                continue;
            }
            Some(Ok(n)) => {
                let mut msgs = Vec::new();
                dec.feed(&rx[..n], |f| {
                    if let Ok(f) = f {
                        msgs.push((f.seq, Message::parse(&f)));
                    }
                });
                if daq.silent {
                    continue;
                }
                for (id, m) in msgs {
                    let started = matches!(m, Ok(Message::Start));
                    let reply = daq.answer(m);
                    if started && daq.streaming {
                        next_tick = tokio::time::Instant::now();
                        daq.clock.restart();
                    }
                    reply.encode(id, &mut daq.p1, &mut daq.p2, &mut tx);
                }
            }
            None => {
                // Time for the next block.
                let now = tokio::time::Instant::now();
                next_tick = (next_tick + daq.block_period())
                    .max(now.checked_sub(MAX_BACKLOG).unwrap_or(now));
                match daq.next_block(&shared, &mut tx) {
                    Flow::Quit => return,
                    Flow::Continue => continue,
                    Flow::Send => {}
                    Flow::SendAfter(delay) => tokio::time::sleep(delay).await,
                }
            }
        }
        if !tx.is_empty() && io.write_all(&tx).await.is_err() {
            // The host closed the port mid-stream; keep serving (it may reopen).
            daq.streaming = false;
        }
    }
}

/// What the serial DAQ does after producing a block.
enum Flow {
    /// Nothing to send (not configured, dropped or silent).
    Continue,
    /// Send what is in the output buffer.
    Send,
    /// Send it after a delay (an injected late block).
    SendAfter(Duration),
    /// Stop serving (the cable was pulled or the plant failed).
    Quit,
}

/// The state of the simulated serial DAQ: its stream configuration, the signal generator and
/// the fault injector.
struct SerialSimDaq {
    setup: SimSetup,
    /// Fault injection's random numbers.
    frng: rand::rngs::StdRng,
    gen: SignalGenerator,
    stream: Option<(StreamInfo, Vec<usize>)>,
    streaming: bool,
    seq: u32,
    blocks: u64,
    silent: bool,
    rate: f64,
    counts: Vec<i32>,
    /// Frame encoding buffers.
    p1: Vec<u8>,
    p2: Vec<u8>,
    /// Samples produced since START.
    clock: SimClock,
}

impl SerialSimDaq {
    fn new(setup: SimSetup, clock: SimClock) -> SerialSimDaq {
        let gen = SignalGenerator::new(
            setup.sample_rate_hz,
            setup.plant.clone(),
            setup.interaction,
            setup.channels.clone(),
            setup.seed,
        );
        SerialSimDaq {
            frng: rand::rngs::StdRng::seed_from_u64(setup.faults.seed),
            gen,
            stream: None,
            streaming: false,
            seq: 0,
            blocks: 0,
            silent: false,
            rate: setup.sample_rate_hz,
            counts: Vec::new(),
            p1: Vec::new(),
            p2: Vec::new(),
            setup,
            clock,
        }
    }

    /// Wall-clock time between blocks at the simulated stand's speed.
    fn block_period(&self) -> Duration {
        self.stream
            .as_ref()
            .map(|(i, _)| {
                Duration::from_secs_f64(
                    i.samples_per_block as f64 / self.rate / self.setup.speed.max(1e-6),
                )
            })
            .unwrap_or(Duration::from_millis(50))
    }

    /// The answer to one host command.
    fn answer(&mut self, m: Result<Message, frame::PayloadError>) -> Message {
        let all = &self.setup.channels;
        match m {
            Err(e) => Message::Nak {
                command: 0,
                code: -100,
                message: e.to_string(),
            },
            Ok(Message::Hello) => Message::Identity(self.setup.identities.daq.to_idn()),
            Ok(Message::Configure(c)) => match configure(&c, all) {
                Ok((info, idx)) => {
                    self.streaming = false;
                    self.rate = info.sample_rate_hz;
                    self.gen = SignalGenerator::new(
                        self.rate,
                        self.setup.plant.clone(),
                        self.setup.interaction,
                        idx.iter().map(|&i| all[i].clone()).collect(),
                        self.setup.seed,
                    );
                    self.stream = Some((info.clone(), idx));
                    Message::Announce(info)
                }
                Err((code, message)) => Message::Nak {
                    command: kind::CONFIGURE,
                    code,
                    message,
                },
            },
            Ok(Message::Start) => {
                if self.stream.is_some() {
                    self.streaming = true;
                    self.seq = 0;
                    self.gen.restart();
                    Message::Ack(kind::START)
                } else {
                    Message::Nak {
                        command: kind::START,
                        code: -221,
                        message: "not configured".into(),
                    }
                }
            }
            Ok(Message::Stop) => {
                self.streaming = false;
                Message::Ack(kind::STOP)
            }
            Ok(other) => Message::Nak {
                command: other.kind(),
                code: -113,
                message: "not a host command".into(),
            },
        }
    }

    /// Generates the next block into `tx`, with the stand's injected faults.
    fn next_block(&mut self, shared: &SharedRef, tx: &mut Vec<u8>) -> Flow {
        let Some((info, _)) = &self.stream else {
            return Flow::Continue;
        };
        // The block's samples are taken now: counted under the lock a drive change takes, so a
        // change is either in this block or after it on the clock.
        let exc = {
            let sh = lock(shared);
            self.clock.advance(info.samples_per_block as u64);
            sh.excitation.clone()
        };
        self.counts.clear();
        if self
            .gen
            .block(&exc, info.samples_per_block as usize, &mut self.counts)
            .is_err()
        {
            return Flow::Quit;
        }
        self.blocks += 1;
        let this = self.seq;
        self.seq = self.seq.wrapping_add(1);
        let faults = &self.setup.faults;
        if faults
            .cable_pull_after_blocks
            .is_some_and(|k| self.blocks > k)
        {
            let mut sh = lock(shared);
            sh.injected.push(InjectedFault {
                kind: "cable_pull",
                seq: this as u64,
            });
            sh.cable_pulled = true;
            return Flow::Quit;
        }
        if !self.silent
            && faults
                .daq_silent_after_blocks
                .is_some_and(|k| self.blocks > k)
        {
            self.silent = true;
            lock(shared).injected.push(InjectedFault {
                kind: "daq_silent",
                seq: this as u64,
            });
        }
        if self.silent {
            return Flow::Continue;
        }
        let mut frame_bytes = Vec::new();
        Message::Data(std::mem::take(&mut self.counts)).encode(
            this,
            &mut self.p1,
            &mut self.p2,
            &mut frame_bytes,
        );
        let u: f64 = self.frng.random();
        let f = faults;
        let note = |k: &'static str| {
            lock(shared).injected.push(InjectedFault {
                kind: k,
                seq: this as u64,
            })
        };
        if u < f.drop {
            note("drop");
            return Flow::Continue;
        }
        if u < f.drop + f.corrupt {
            note("corrupt");
            let i = self.frng.random_range(1..frame_bytes.len() - 1);
            let mut b = frame_bytes[i] ^ 0x5A;
            if b == 0 {
                b = frame_bytes[i] ^ 0x3C;
            }
            frame_bytes[i] = b;
            tx.extend_from_slice(&frame_bytes);
        } else if u < f.drop + f.corrupt + f.duplicate {
            note("duplicate");
            tx.extend_from_slice(&frame_bytes);
            tx.extend_from_slice(&frame_bytes);
        } else if u < f.drop + f.corrupt + f.duplicate + f.delay {
            note("delay");
            tx.extend_from_slice(&frame_bytes);
            return Flow::SendAfter(f.delay_time);
        } else {
            tx.extend_from_slice(&frame_bytes);
        }
        Flow::Send
    }
}

/// Analog inputs of the simulated serial DAQ (`IDENT-SIM,DAQ-8`), numbered 0 to 7.
pub const SIM_DAQ_INPUTS: u16 = 8;

fn configure(c: &DaqConfig, all: &[SimChannel]) -> Result<(StreamInfo, Vec<usize>), (i16, String)> {
    if !(1.0..=200_000.0).contains(&c.sample_rate_hz) {
        return Err((
            -222,
            format!("sample rate {} Hz outside 1..200000", c.sample_rate_hz),
        ));
    }
    if c.samples_per_block == 0 || c.channels.is_empty() {
        return Err((-109, "need ≥ 1 channel and ≥ 1 sample per block".into()));
    }
    if c.channels.len() * c.samples_per_block as usize * 4 + frame::HEADER + frame::TRAILER
        > frame::MAX_FRAME
    {
        return Err((-222, "block does not fit a frame".into()));
    }
    if let Some(ch) = c.channels.iter().find(|&&ch| ch >= SIM_DAQ_INPUTS) {
        return Err((
            -224,
            format!(
                "no input {ch}: this unit has {SIM_DAQ_INPUTS} inputs, 0 to {}",
                SIM_DAQ_INPUTS - 1
            ),
        ));
    }
    let mut idx = Vec::new();
    for ch in &c.channels {
        match all.iter().position(|a| a.device_channel == *ch) {
            Some(i) => idx.push(i),
            None => {
                return Err((
                    -224,
                    format!(
                        "no input {ch} (this unit has inputs {:?})",
                        all.iter().map(|a| a.device_channel).collect::<Vec<_>>()
                    ),
                ))
            }
        }
    }
    let info = StreamInfo {
        sample_rate_hz: c.sample_rate_hz,
        samples_per_block: c.samples_per_block,
        channels: c
            .channels
            .iter()
            .map(|&d| ChannelInfo {
                device_channel: d,
                volts_per_count: VOLTS_PER_COUNT,
            })
            .collect(),
    };
    Ok((info, idx))
}

/// The CAN simulator's signal: ADC counts of the truth driven by what the simulated shaker
/// controller currently commands, generated in chunks of 64 samples.
fn can_signal(setup: &SimSetup, shared: SharedRef) -> crate::can::sim::Signal {
    const CHUNK: u64 = 64;
    let mut gen = SignalGenerator::new(
        setup.sample_rate_hz,
        setup.plant.clone(),
        setup.interaction,
        setup.channels.clone(),
        setup.seed,
    );
    let position: Vec<(u16, usize)> = setup
        .channels
        .iter()
        .enumerate()
        .map(|(i, c)| (c.device_channel, i))
        .collect();
    let nch = setup.channels.len();
    let mut chunk: Vec<i32> = Vec::with_capacity(CHUNK as usize * nch);
    let mut chunk_start: Option<u64> = None;
    Box::new(move |device_channel: u16, index: u64| {
        let fresh = match chunk_start {
            Some(s) => index < s || index >= s + CHUNK,
            None => true,
        };
        if fresh {
            let start = index - index % CHUNK;
            if chunk_start.is_none_or(|s| start < s) {
                gen.restart();
            }
            let exc = lock(&shared).excitation.clone();
            chunk.clear();
            if gen.block(&exc, CHUNK as usize, &mut chunk).is_err() {
                chunk.resize(CHUNK as usize * nch, 0);
            }
            chunk_start = Some(start);
        }
        let Some(&(_, c)) = position.iter().find(|(d, _)| *d == device_channel) else {
            return 0;
        };
        let i = (index - chunk_start.unwrap_or(0)) as usize;
        chunk.get(i * nch + c).copied().unwrap_or(0)
    })
}
