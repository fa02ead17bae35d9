//! Serial ports (`tokio-serial`, built on `serialport` without libudev) and pseudo-terminal pairs
//! for the simulated stand.

use tokio_serial::{SerialPort, SerialPortBuilderExt, SerialStream};

use super::TransportError;

/// Line settings of a serial port. Pseudo-terminals ignore the baud rate.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialSettings {
    /// Baud rate (bit/s), 8 data bits, no parity, 1 stop bit, no flow control.
    pub baud: u32,
}

impl Default for SerialSettings {
    fn default() -> Self {
        SerialSettings { baud: 115_200 }
    }
}

/// An open serial port (or the host end of a pseudo-terminal).
pub struct SerialTransport {
    name: String,
    inner: SerialStream,
}

impl std::fmt::Debug for SerialTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialTransport")
            .field("port", &self.name)
            .finish()
    }
}

/// Opens `port` exclusively (an `flock` plus `TIOCEXCL`, so a second program gets
/// [`TransportError::Busy`]). Must be called inside a tokio runtime.
pub fn open_serial(
    port: &str,
    settings: &SerialSettings,
) -> Result<SerialTransport, TransportError> {
    let path = std::path::Path::new(port);
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(TransportError::NotFound {
                port: port.to_string(),
            })
        }
        Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied => {
            return Err(TransportError::PermissionDenied {
                port: port.to_string(),
            })
        }
        Ok(m) if m.is_dir() => {
            return Err(TransportError::NotSerial {
                port: port.to_string(),
                detail: "it is a directory".into(),
            })
        }
        _ => {}
    }
    let stream = tokio_serial::new(port, settings.baud)
        .data_bits(tokio_serial::DataBits::Eight)
        .parity(tokio_serial::Parity::None)
        .stop_bits(tokio_serial::StopBits::One)
        .flow_control(tokio_serial::FlowControl::None)
        .open_native_async()
        .map_err(|e| classify_open_error(port, &e))?;
    Ok(SerialTransport {
        name: port.to_string(),
        inner: stream,
    })
}

/// Maps a `serialport` error to a [`TransportError`] that says what to check.
pub(crate) fn classify_open_error(port: &str, e: &tokio_serial::Error) -> TransportError {
    use tokio_serial::ErrorKind;
    let port = port.to_string();
    let detail = e.description.clone();
    match e.kind {
        ErrorKind::Io(std::io::ErrorKind::NotFound) => TransportError::NotFound { port },
        ErrorKind::Io(std::io::ErrorKind::PermissionDenied) => {
            TransportError::PermissionDenied { port }
        }
        ErrorKind::NoDevice if detail.contains("lock") || detail.contains("busy") => {
            TransportError::Busy { port }
        }
        ErrorKind::Io(std::io::ErrorKind::ResourceBusy) => TransportError::Busy { port },
        _ if detail.contains("Permission denied") => TransportError::PermissionDenied { port },
        _ if detail.contains("Device or resource busy") => TransportError::Busy { port },
        _ if detail.contains("Inappropriate ioctl") || detail.contains("Not a typewriter") => {
            TransportError::NotSerial { port, detail }
        }
        _ => TransportError::Open { port, detail },
    }
}

stream_transport!(SerialTransport);

/// A pseudo-terminal: the device side (served by a simulator) and the path a host program opens
/// like a real serial port. Dropping the device end closes the port ("cable pulled").
pub struct PtyDevice {
    /// The simulator's end (the pty master).
    pub device: SerialTransport,
    /// Path of the host end (`/dev/pts/N`), to put in a stand file or pass to [`open_serial`].
    pub path: String,
}

/// Creates a pseudo-terminal pair for a simulated `role` ("shaker", "daq"). Must be called inside a
/// tokio runtime.
///
/// The host end is closed again at once: the host program opens it by path, exclusively, like a
/// real port. While no host program has it open, reads of the device end fail with `EIO`; device
/// simulators treat that as "nobody connected" and retry.
pub fn pty_pair(role: &str) -> Result<PtyDevice, TransportError> {
    let err = |e: tokio_serial::Error| TransportError::Pty {
        role: role.to_string(),
        detail: e.description,
    };
    let (master, slave) = SerialStream::pair().map_err(err)?;
    let path = slave.name().ok_or_else(|| TransportError::Pty {
        role: role.to_string(),
        detail: "the pseudo-terminal has no name".into(),
    })?;
    drop(slave);
    Ok(PtyDevice {
        device: SerialTransport {
            name: format!("sim-{role}:{path}"),
            inner: master,
        },
        path,
    })
}
