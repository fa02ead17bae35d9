//! A connected stand: the exciter (shaker controller, or signal generator + amplifier) and DAQ
//! named by a stand file, opened, identified
//! (checked against the stand file), configured, and recorded in the session.

use std::sync::Arc;

use crate::daq::{Daq, DaqError, DaqOptions, SerialDaq, StreamInfo};
use crate::device::DeviceIdentity;
use crate::generator::{GeneratorOptions, ScpiGenerator};
use crate::record::{DaqStreamRecord, DeviceIdentityRecord, Role, StandRecord};
use crate::session::{SessionError, SessionHandle};
use crate::shaker::GeneratorExciter;
use crate::shaker::{ScpiShaker, Shaker, ShakerError, ShakerOptions};
use crate::stand::{GeneratorAddress, GeneratorStand, PortSpec, Stand};
use crate::transport::{
    connect_tcp, open_serial, open_usbtmc, ByteTap, SerialSettings, Tapped, Transport,
    TransportError,
};

/// Why a stand could not be brought up.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RigError {
    /// A port is still `"sim"`.
    #[error("{file}: {role} port is \"sim\"; start the simulated stand (acquire::sim::SimStand / `ident sim`) or give a device path")]
    Unbound {
        /// Stand file.
        file: String,
        /// `shaker` or `daq`.
        role: &'static str,
    },
    /// Shaker controller problem.
    #[error(transparent)]
    Shaker(#[from] ShakerError),
    /// DAQ problem.
    #[error(transparent)]
    Daq(#[from] DaqError),
    /// Session problem.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// The DAQ's CAN interface could not be opened.
    #[error(transparent)]
    Can(#[from] crate::can::CanError),
    /// The DAQ refused the stand file's channels (an input it does not have): found when the
    /// stream is configured, before the drive is switched on.
    #[error("{file}: the DAQ ({identity}) has no input for the stand's channels {channels}: {source}; fix `device_channel` of the [[channel]] sections to the DAQ's inputs (and give their number as daq.inputs, so the stand file is checked when it is read)")]
    Channels {
        /// Stand file.
        file: String,
        /// The DAQ's identity.
        identity: String,
        /// The channels asked for, `name = device_channel`.
        channels: String,
        /// The DAQ's refusal.
        source: DaqError,
    },
}

/// Opens a generator stand's signal generator (serial port or raw TCP socket, every byte tapped
/// into `session`, reconnecting once when the connection drops) as the stand's exciter.
async fn generator_exciter(
    stand: &Stand,
    g: &GeneratorStand,
    session: Option<&SessionHandle>,
) -> Result<GeneratorExciter, RigError> {
    let mut open = open_generator(g.port.clone(), g.baud, g.timeout, session.cloned());
    let io = open().await.map_err(|e| ShakerError::Generator(e.into()))?;
    let gen = ScpiGenerator::new(
        io,
        GeneratorOptions {
            channel: g.channel,
            timeout: g.timeout,
            retries: g.retries,
            terminator: g.terminator.clone(),
            dialect: g.dialect.clone(),
            overrides: g.commands.clone(),
        },
    )
    .with_reconnect(Box::new(open));
    let speed = stand.truth.as_ref().map(|t| t.speed).unwrap_or(1.0);
    Ok(
        GeneratorExciter::new(Box::new(gen), g.amplifier.clone(), session.cloned(), speed)
            .with_sample_rate(stand.daq.sample_rate_hz),
    )
}

/// Opens a generator's connection (again).
type OpenGenerator = dyn FnMut() -> std::pin::Pin<
        Box<dyn std::future::Future<Output = Result<Box<dyn Transport>, TransportError>> + Send>,
    > + Send;

/// The function that opens the generator's connection at `address` (again).
fn open_generator(
    address: GeneratorAddress,
    baud: u32,
    timeout: std::time::Duration,
    session: Option<SessionHandle>,
) -> Box<OpenGenerator> {
    Box::new(move || {
        let (address, session) = (address.clone(), session.clone());
        Box::pin(async move {
            match &address {
                GeneratorAddress::Serial(p) => {
                    let io = open_serial(p, &SerialSettings { baud })?;
                    Ok(tapped(io, session.as_ref()))
                }
                GeneratorAddress::Tcp(a) => {
                    // Connecting may take longer than an answer: a few answer timeouts.
                    let wait = (timeout * 3).max(std::time::Duration::from_secs(1));
                    let io = connect_tcp(a, wait).await?;
                    Ok(tapped(io, session.as_ref()))
                }
                GeneratorAddress::Usbtmc(p) => {
                    let io = open_usbtmc(p)?;
                    Ok(tapped(io, session.as_ref()))
                }
                GeneratorAddress::Sim { .. } => Err(TransportError::Open {
                    port: "sim".into(),
                    detail: "the generator's port is still \"sim\"; start the simulated stand (`ident sim`) or give a device path or tcp:HOST".into(),
                }),
            }
        })
    })
}

/// A configure refusal that names an input (`-224`, "no input"): the stand file's channels,
/// named; any other error as it is.
fn channels_refused(stand: &Stand, identity: &DeviceIdentity, e: DaqError) -> RigError {
    match &e {
        DaqError::Rejected { code: -224, .. } | DaqError::Announcement { .. } => {
            let channels: Vec<String> = stand
                .channels
                .iter()
                .map(|c| format!("{} = {}", c.name, c.device_channel))
                .collect();
            RigError::Channels {
                file: stand.file.clone(),
                identity: identity.to_idn(),
                channels: channels.join(", "),
                source: e,
            }
        }
        _ => e.into(),
    }
}

/// A connected stand.
pub struct Rig {
    /// The stand file.
    pub stand: Stand,
    /// The shaker controller.
    pub shaker: Box<dyn Shaker>,
    /// The DAQ.
    pub daq: Box<dyn Daq>,
    /// What the DAQ announced.
    pub stream: StreamInfo,
    /// Shaker identity.
    pub shaker_identity: DeviceIdentity,
    /// DAQ identity.
    pub daq_identity: DeviceIdentity,
}

fn tapped(t: impl Transport + 'static, session: Option<&SessionHandle>) -> Box<dyn Transport> {
    match session {
        Some(s) => Box::new(Tapped::new(t, Arc::new(s.clone()) as Arc<dyn ByteTap>)),
        None => Box::new(t),
    }
}

impl Rig {
    /// Opens the stand's serial ports (every byte tapped into `session`), then [`Rig::from_devices`].
    pub async fn connect(stand: &Stand, session: Option<&SessionHandle>) -> Result<Rig, RigError> {
        let unbound = |role| RigError::Unbound {
            file: stand.file.clone(),
            role,
        };
        let shaker: Box<dyn Shaker> = match &stand.generator {
            Some(g) => Box::new(generator_exciter(stand, g, session).await?),
            None => {
                let sp = match &stand.shaker.port {
                    PortSpec::Path(p) => p.clone(),
                    PortSpec::Sim | PortSpec::Can(_) => return Err(unbound("shaker")),
                };
                let s_io = open_serial(
                    &sp,
                    &SerialSettings {
                        baud: stand.shaker.baud,
                    },
                )
                .map_err(ShakerError::from)?;
                Box::new(ScpiShaker::new(
                    tapped(s_io, session),
                    ShakerOptions {
                        timeout: stand.shaker.timeout,
                        retries: stand.shaker.retries,
                    },
                ))
            }
        };
        let daq: Box<dyn Daq> = match &stand.daq.port {
            PortSpec::Sim => return Err(unbound("daq")),
            PortSpec::Path(dp) => {
                let d_io = open_serial(
                    dp,
                    &SerialSettings {
                        baud: stand.daq.baud,
                    },
                )
                .map_err(DaqError::from)?;
                Box::new(SerialDaq::new(
                    tapped(d_io, session),
                    DaqOptions {
                        command_timeout: stand.daq.timeout,
                        retries: stand.daq.retries,
                        ..DaqOptions::default()
                    },
                ))
            }
            PortSpec::Can(iface) if stand.daq.canopen.is_some() => {
                // A CANopen node (docs/canopen.md); every frame is tapped into the session.
                let settings = match stand.daq.canopen.as_ref().map(|c| c.settings()) {
                    Some(Ok(s)) => s,
                    Some(Err(e)) => {
                        let detail = format!("daq.canopen.eds: {e}");
                        return Err(crate::can::CanError::Config { detail }.into());
                    }
                    None => crate::canopen::CanOpenSettings::default(),
                };
                let d = crate::canopen::CanOpenDaq::open(iface, settings)?;
                Box::new(match session {
                    Some(s) => d.with_tap(Arc::new(s.clone()) as Arc<dyn ByteTap>),
                    None => d,
                })
            }
            PortSpec::Can(iface) => {
                let d = crate::can::CanDaq::open(iface, stand.daq.can.clone())?;
                Box::new(match session {
                    Some(s) => d.with_tap(Arc::new(s.clone()) as Arc<dyn ByteTap>),
                    None => d,
                })
            }
        };
        Rig::from_devices(stand, shaker, daq, session).await
    }

    /// Identifies both devices (checking the stand file's expected identities), resets the
    /// shaker (output off), configures the DAQ, and records stand, identities and stream.
    pub async fn from_devices(
        stand: &Stand,
        mut shaker: Box<dyn Shaker>,
        mut daq: Box<dyn Daq>,
        session: Option<&SessionHandle>,
    ) -> Result<Rig, RigError> {
        if let Some(s) = session {
            s.record(&StandRecord {
                name: stand.name.clone(),
                file: stand.file.clone(),
                text: stand.text.clone(),
                channels: stand.channels.clone(),
                geometry: stand.geometry.clone(),
            })?;
        }
        let shaker_identity = shaker.identify().await?;
        if !shaker_identity.matches(&stand.shaker.identity) {
            return Err(ShakerError::WrongIdentity {
                port: shaker.port().to_string(),
                got: shaker_identity.to_idn(),
                expected: stand.shaker.identity.clone(),
            }
            .into());
        }
        let daq_identity = daq.identify().await?;
        if !daq_identity.matches(&stand.daq.identity) {
            return Err(DaqError::WrongIdentity {
                port: daq.port().to_string(),
                got: daq_identity.to_idn(),
                expected: stand.daq.identity.clone(),
            }
            .into());
        }
        if let Some(s) = session {
            for (role, port, id) in [
                (Role::Shaker, shaker.port(), &shaker_identity),
                (Role::Daq, daq.port(), &daq_identity),
            ] {
                s.record(&DeviceIdentityRecord {
                    role,
                    port: port.to_string(),
                    manufacturer: id.manufacturer.clone(),
                    model: id.model.clone(),
                    serial: id.serial.clone(),
                    firmware: id.firmware.clone(),
                })?;
            }
        }
        // The DAQ's inputs are checked (the stream configured) before the exciter is prepared,
        // so that a wrong channel number stops the run before anything drives the structure.
        let stream = daq
            .configure(&stand.daq_config())
            .await
            .map_err(|e| channels_refused(stand, &daq_identity, e))?;
        shaker.reset().await?;
        if let Some(s) = session {
            s.record(&DaqStreamRecord {
                port: daq.port().to_string(),
                sample_rate_hz: stream.sample_rate_hz,
                samples_per_block: stream.samples_per_block,
                channels: stream.channels.clone(),
                names: Some(stand.channels.iter().map(|c| c.name.clone()).collect()),
            })?;
        }
        Ok(Rig {
            stand: stand.clone(),
            shaker,
            daq,
            stream,
            shaker_identity,
            daq_identity,
        })
    }
}
