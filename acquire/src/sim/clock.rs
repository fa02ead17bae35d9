//! The simulated stand's clock: the samples its DAQ has produced since START.
//!
//! The simulated stand has no time of its own. Its DAQ produces blocks at `speed` times real time
//! while it can. A starved simulator (a busy machine, a host that reads slowly) produces fewer,
//! and its simulated time runs slower. A drive change reaches the simulated exciter between two
//! blocks, so the first sample taken after it is the count of samples produced so far.
//!
//! A host in the same process reads that count as the DAQ's sample clock
//! ([`crate::daq::Daq::sample_clock`], through [`SimClockedDaq`]). Reckoning from wall-clock
//! time instead overestimates it whenever the simulator runs behind its speed: the sweep then
//! waits for seconds of stream that hold nothing new. On a loaded machine that turned a
//! ten-second sweep into minutes and the devices' timeouts into failures.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use async_trait::async_trait;

use crate::daq::{Daq, DaqConfig, DaqError, DaqEvent, StreamInfo};
use crate::device::DeviceIdentity;

/// Samples the simulated DAQ has produced since the last START (shared by the simulator and
/// the host).
#[derive(Debug, Clone, Default)]
pub struct SimClock(Arc<AtomicU64>);

impl SimClock {
    /// The index of the next sample the simulated DAQ will take.
    pub fn now(&self) -> u64 {
        self.0.load(Ordering::SeqCst)
    }

    /// Counts a produced block of `samples`. Called while the excitation it is generated with
    /// is read, under the same lock, so that a drive change is either in the block or after it.
    pub(crate) fn advance(&self, samples: u64) {
        self.0.fetch_add(samples, Ordering::SeqCst);
    }

    /// Back to sample 0 (START).
    pub(crate) fn restart(&self) {
        self.0.store(0, Ordering::SeqCst);
    }
}

/// A host's DAQ driver for the simulated DAQ, with the simulator's [`SimClock`] as its sample
/// clock. Everything else goes to the driver.
pub struct SimClockedDaq {
    inner: Box<dyn Daq>,
    clock: SimClock,
}

impl SimClockedDaq {
    /// `inner` (the driver connected to the simulated DAQ) reading `clock`.
    pub fn new(inner: Box<dyn Daq>, clock: SimClock) -> SimClockedDaq {
        SimClockedDaq { inner, clock }
    }
}

#[async_trait]
impl Daq for SimClockedDaq {
    fn port(&self) -> &str {
        self.inner.port()
    }

    async fn identify(&mut self) -> Result<DeviceIdentity, DaqError> {
        self.inner.identify().await
    }

    async fn configure(&mut self, config: &DaqConfig) -> Result<StreamInfo, DaqError> {
        self.inner.configure(config).await
    }

    async fn start(&mut self) -> Result<(), DaqError> {
        self.inner.start().await
    }

    async fn next_event(&mut self) -> Result<DaqEvent, DaqError> {
        self.inner.next_event().await
    }

    async fn stop(&mut self) -> Result<(), DaqError> {
        self.inner.stop().await
    }

    fn sample_clock(&self) -> Option<u64> {
        Some(self.clock.now())
    }
}
