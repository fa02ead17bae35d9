//! The link between a simulated device and the host: the state every simulated device shares (the
//! excitation driving the plant, the log of injected faults, the pulled cable) and the reads and
//! writes on a host connection. Below the devices (`sim`, `sim::generator`), importing none.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde::Serialize;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

use super::signal::Excitation;
use crate::transport::Transport;

/// A fault the simulator injected.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct InjectedFault {
    /// `drop`, `corrupt`, `duplicate`, `delay`, `daq_silent`, `shaker_silent`, `cable_pull`.
    pub kind: &'static str,
    /// DAQ block number (or shaker command count).
    pub seq: u64,
}

/// What the simulated devices share: the excitation the shaker or generator drives the plant
/// with, the faults injected so far, and whether the cable is pulled.
#[derive(Default)]
pub(super) struct Shared {
    pub(super) excitation: Excitation,
    pub(super) injected: Vec<InjectedFault>,
    pub(super) cable_pulled: bool,
}

pub(super) type SharedRef = Arc<Mutex<Shared>>;

/// The shared state, also after a device task panicked while holding it (the state stays
/// readable: a test then sees the faults logged so far).
pub(super) fn lock(s: &SharedRef) -> std::sync::MutexGuard<'_, Shared> {
    s.lock().unwrap_or_else(|p| p.into_inner())
}

/// Waits up to 20 ms for bytes from the host into `buf`: how many arrived (0: none yet). `None`
/// when the device stops serving this connection: its cable is pulled, or the host left a
/// connection that is not a pty (`pty == false`: a TCP client). On a pty, a port no host has open
/// (reads fail with EIO) is waited out.
pub(super) async fn read_host<T: Transport>(
    io: &mut T,
    buf: &mut [u8],
    shared: &SharedRef,
    pty: bool,
) -> Option<usize> {
    if lock(shared).cable_pulled {
        return None;
    }
    match tokio::time::timeout(Duration::from_millis(20), io.read(buf)).await {
        Err(_) => Some(0),
        Ok(Ok(0)) | Ok(Err(_)) if !pty => None,
        Ok(Ok(0)) | Ok(Err(_)) => {
            tokio::time::sleep(Duration::from_millis(10)).await;
            Some(0)
        }
        Ok(Ok(n)) => Some(n),
    }
}

/// Sends an answer line (when there is one); false when the host can no longer be written to.
pub(super) async fn send_answer<T: Transport>(io: &mut T, answer: Option<String>) -> bool {
    let Some(mut a) = answer else {
        return true;
    };
    a.push('\n');
    io.write_all(a.as_bytes()).await.is_ok()
}
