//! A simulated DAQ on a CAN interface: answers DAQ-over-CAN commands and streams sample blocks
//! from a signal function, with injectable faults: dropped, duplicated, corrupted data frames
//! (every n-th frame, or seeded per block as a stand file's `[faults]` asks), delayed blocks,
//! lost answers, and a DAQ that falls silent.

use std::time::Duration;

use rand::{Rng, SeedableRng};

use crate::can::codec::{
    kind, Message, Reassembler, SampleFormat, Segmenter, WireBlock, WireChannel,
};
use crate::can::{BusEvent, CanBus, CanError, CanId, FrameKind, WireFrame};
use crate::device::DeviceIdentity;

/// Faults the simulator injects: into its data frames (counted over all data frames sent), and
/// into its answers.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SimFaults {
    /// Skip every n-th data frame.
    pub drop_every: Option<u64>,
    /// Send every n-th data frame twice.
    pub duplicate_every: Option<u64>,
    /// Flip a payload bit in every n-th data frame (the frame counter stays intact).
    pub corrupt_every: Option<u64>,
    /// Commands (type bytes, `codec::kind`) whose answer is lost once each: the command takes
    /// effect, its answer never reaches the bus.
    pub lose_answers: Vec<u8>,
    /// A stand file's DAQ faults, drawn per block from its seed: `drop` loses one data frame of
    /// the block, `corrupt` flips a bit in one, `duplicate` sends one twice, `delay` holds the
    /// block back `delay_time`; after `daq_silent_after_blocks` (or `cable_pull_after_blocks`:
    /// on CAN the DAQ's frames simply stop) blocks it neither streams nor answers. The shaker
    /// fields do not apply here.
    pub per_block: Option<crate::faults::Faults>,
}

/// Told of each per-block fault injected: kind (`drop`, `corrupt`, `duplicate`, `delay`,
/// `daq_silent`, `cable_pull`) and block number since START.
pub type FaultNote = Box<dyn FnMut(&'static str, u64) + Send>;

/// What a per-block fault does to one block.
#[derive(Debug, Clone, Copy, PartialEq)]
enum BlockFault {
    None,
    /// One of its data frames is not sent.
    Drop,
    /// One of its data frames has a payload bit flipped.
    Corrupt,
    /// One of its data frames is sent twice.
    Duplicate,
    /// The block is held back.
    Delay,
}

impl BlockFault {
    /// The name injected faults are recorded under (`None` for no fault).
    fn name(self) -> Option<&'static str> {
        match self {
            BlockFault::None => None,
            BlockFault::Drop => Some("drop"),
            BlockFault::Corrupt => Some("corrupt"),
            BlockFault::Duplicate => Some("duplicate"),
            BlockFault::Delay => Some("delay"),
        }
    }
}

/// How the simulated DAQ behaves.
#[derive(Debug, Clone)]
pub struct SimCanDaqSettings {
    /// Identifier it listens to for commands.
    pub command_id: CanId,
    /// Identifier of its answers.
    pub status_id: CanId,
    /// Identifier of its sample blocks.
    pub data_id: CanId,
    /// Frames it sends (classic or FD).
    pub frames: FrameKind,
    /// Who it says it is.
    pub identity: DeviceIdentity,
    /// Sample encoding.
    pub format: SampleFormat,
    /// Volts per ADC count it announces for every channel (V).
    pub volts_per_count: f32,
    /// Number of device channels (0..count are valid in CONFIGURE).
    pub channel_count: u16,
    /// Highest sample rate it accepts (Hz).
    pub max_sample_rate_hz: f64,
    /// Send blocks at the configured sample rate (true) or as fast as the bus takes them (false).
    pub real_time: bool,
    /// With `real_time`: simulated time per wall-clock time (1 = real time; 4 = four times faster).
    pub speed: f64,
    /// Injected faults.
    pub faults: SimFaults,
}

impl Default for SimCanDaqSettings {
    fn default() -> Self {
        SimCanDaqSettings {
            command_id: CanId::Standard(0x100),
            status_id: CanId::Standard(0x101),
            data_id: CanId::Standard(0x102),
            frames: FrameKind::Classic,
            identity: DeviceIdentity {
                manufacturer: "IDENT-SIM".into(),
                model: "CANDAQ-8".into(),
                serial: "0001".into(),
                firmware: "1.0".into(),
            },
            format: SampleFormat::I24,
            volts_per_count: 10.0 / 8_388_608.0,
            channel_count: 8,
            max_sample_rate_hz: 1.0e6,
            real_time: true,
            speed: 1.0,
            faults: SimFaults::default(),
        }
    }
}

/// A signal source: the ADC count of `device_channel` at sample `index` (since START).
pub type Signal = Box<dyn FnMut(u16, u64) -> i32 + Send>;

/// What the simulator did (to compare with what the host detected).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SimStats {
    /// Blocks produced.
    pub blocks: u64,
    /// Data frames produced (before fault injection).
    pub data_frames: u64,
    /// Data frames skipped.
    pub dropped: u64,
    /// Data frames sent twice.
    pub duplicated: u64,
    /// Data frames corrupted.
    pub corrupted: u64,
    /// Commands received.
    pub commands: u64,
    /// Answers not sent (`SimFaults::lose_answers`).
    pub answers_lost: u64,
}

struct Stream {
    channels: Vec<u16>,
    samples_per_block: u16,
    sample_rate_hz: f64,
}

/// A simulated DAQ bound to its interface (listening for commands), ready to [`serve`](Self::serve).
pub struct SimCanDaq {
    bus: CanBus,
    settings: SimCanDaqSettings,
    note: Option<FaultNote>,
}

impl SimCanDaq {
    /// Opens `interface` and starts listening for commands (call inside a tokio runtime). Commands
    /// sent after this returns are received.
    pub fn bind(interface: &str, settings: SimCanDaqSettings) -> Result<SimCanDaq, CanError> {
        let bus = CanBus::open_filtered(interface, &[settings.command_id])?;
        Ok(SimCanDaq {
            bus,
            settings,
            note: None,
        })
    }

    /// Calls `note` for each per-block fault injected ([`SimFaults::per_block`]).
    pub fn on_fault(mut self, note: FaultNote) -> SimCanDaq {
        self.note = Some(note);
        self
    }

    /// Serves the DAQ-over-CAN protocol until `stop` resolves (or `max_blocks` blocks were sent,
    /// if given). Returns what it did.
    pub async fn serve(
        self,
        signal: Signal,
        max_blocks: Option<u64>,
        stop: tokio::sync::oneshot::Receiver<()>,
    ) -> Result<SimStats, CanError> {
        serve_on(self.bus, self.settings, signal, max_blocks, stop, self.note).await
    }
}

async fn serve_on(
    bus: CanBus,
    mut settings: SimCanDaqSettings,
    mut signal: Signal,
    max_blocks: Option<u64>,
    stop: tokio::sync::oneshot::Receiver<()>,
    mut note: Option<FaultNote>,
) -> Result<SimStats, CanError> {
    let mut note = |kind: &'static str, seq: u64| {
        if let Some(n) = note.as_mut() {
            n(kind, seq)
        }
    };
    let per_block = settings.faults.per_block.clone();
    let mut rng = rand::rngs::StdRng::seed_from_u64(per_block.as_ref().map_or(0, |f| f.seed));
    let mut silent = false;
    let interface = bus.interface();
    let mut rx = Reassembler::new();
    let mut tx_status = Segmenter::new(settings.status_id, settings.frames);
    let mut tx_data = Segmenter::new(settings.data_id, settings.frames);
    let mut stats = SimStats::default();
    let mut stream: Option<Stream> = None;
    let mut streaming = false;
    let mut block_seq: u32 = 0;
    let mut frames: Vec<WireFrame> = Vec::new();
    let (mut body, mut counts) = (Vec::new(), Vec::<i32>::new());
    let mut ticker = tokio::time::interval(Duration::from_millis(10));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Burst);
    tokio::pin!(stop);

    loop {
        if max_blocks.is_some_and(|m| stats.blocks >= m) {
            streaming = false;
        }
        tokio::select! {
            _ = &mut stop => return Ok(stats),
            ev = bus.recv() => {
                let BusEvent::Frame(f) = ev? else { continue };
                if silent {
                    continue;
                }
                let p = rx.push(f.data());
                let Some(body_in) = p.message else { continue };
                stats.commands += 1;
                let (answer, started) = answer(&settings, &mut stream, &mut streaming, body_in);
                if let Some(period) = started {
                    block_seq = 0;
                    ticker = tokio::time::interval(period.max(Duration::from_micros(1)));
                    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Burst);
                }
                let command = body_in.first().copied().unwrap_or(0);
                if let Some(i) = settings.faults.lose_answers.iter().position(|&k| k == command) {
                    settings.faults.lose_answers.remove(i);
                    stats.answers_lost += 1;
                    continue;
                }
                encode_frames(&answer, &mut tx_status, (&mut body, &mut frames), (interface, "answer"))?;
                for f in &frames {
                    bus.send(f).await?;
                }
            }
            // Real time: one block per period. Otherwise flat out, yielding so commands still get in.
            _ = async {
                if settings.real_time { ticker.tick().await; } else { tokio::task::yield_now().await; }
            }, if streaming => {
                let Some(s) = &stream else { continue };
                let first = block_seq as u64 * s.samples_per_block as u64;
                fill_counts(&mut signal, s, first, settings.format, &mut counts);
                let this = block_seq as u64;
                let fault = match block_fault(per_block.as_ref(), stats.blocks, &mut rng) {
                    Ok(fault) => fault,
                    Err(gone) => {
                        silent = true;
                        streaming = false;
                        note(gone, this);
                        continue;
                    }
                };
                let block = Message::Block(WireBlock { seq: block_seq, format: settings.format, channel_count: s.channels.len() as u8, counts: std::mem::take(&mut counts) });
                encode_frames(&block, &mut tx_data, (&mut body, &mut frames), (interface, "block"))?;
                if let Message::Block(b) = block { counts = b.counts; }
                // The frame a per-block fault hits.
                let target = match fault {
                    BlockFault::Drop | BlockFault::Corrupt | BlockFault::Duplicate => Some(rng.random_range(0..frames.len())),
                    BlockFault::None | BlockFault::Delay => None,
                };
                if let Some(kind) = fault.name() {
                    note(kind, this);
                }
                if let (BlockFault::Delay, Some(f)) = (fault, &per_block) {
                    tokio::time::sleep(f.delay_time).await;
                }
                send_block(&bus, &frames, (fault, target), &settings.faults, &mut stats).await?;
                stats.blocks += 1;
                block_seq = block_seq.wrapping_add(1);
            }
        }
    }
}

/// The answer to one command, and (for START) the block period the ticker must take.
fn answer(
    settings: &SimCanDaqSettings,
    stream: &mut Option<Stream>,
    streaming: &mut bool,
    body_in: &[u8],
) -> (Message, Option<Duration>) {
    let mut started = None;
    let answer = match Message::decode(body_in) {
        Ok(Message::Identify) => Message::Identity(settings.identity.to_idn()),
        Ok(Message::Configure {
            sample_rate_mhz,
            samples_per_block,
            channels,
        }) => {
            let rate = sample_rate_mhz as f64 / 1000.0;
            if let Some(bad) = channels.iter().find(|&&c| c >= settings.channel_count) {
                Message::Nak {
                    command: kind::CONFIGURE,
                    code: 2,
                    message: format!("no channel {bad} (device has {})", settings.channel_count),
                }
            } else if rate <= 0.0
                || rate > settings.max_sample_rate_hz
                || samples_per_block == 0
                || channels.is_empty()
            {
                Message::Nak {
                    command: kind::CONFIGURE,
                    code: 3,
                    message: format!("rate {rate} Hz / block {samples_per_block} not supported"),
                }
            } else {
                *streaming = false;
                let announce = Message::Announce {
                    sample_rate_mhz,
                    samples_per_block,
                    channels: channels
                        .iter()
                        .map(|&c| WireChannel {
                            device_channel: c,
                            volts_per_count: settings.volts_per_count,
                        })
                        .collect(),
                };
                *stream = Some(Stream {
                    channels,
                    samples_per_block,
                    sample_rate_hz: rate,
                });
                announce
            }
        }
        Ok(Message::Start) => match stream {
            None => Message::Nak {
                command: kind::START,
                code: 1,
                message: "not configured".into(),
            },
            Some(s) => {
                *streaming = true;
                started = Some(Duration::from_secs_f64(
                    s.samples_per_block as f64 / s.sample_rate_hz / settings.speed.max(1e-6),
                ));
                Message::Ack {
                    command: kind::START,
                }
            }
        },
        Ok(Message::Stop) => {
            *streaming = false;
            Message::Ack {
                command: kind::STOP,
            }
        }
        Ok(other) => Message::Nak {
            command: 0,
            code: 4,
            message: format!("unexpected {}", other.name()),
        },
        Err(e) => Message::Nak {
            command: body_in.first().copied().unwrap_or(0),
            code: 5,
            message: e.to_string(),
        },
    };
    (answer, started)
}

/// The fault the next block gets (after `blocks` blocks); `Err` names why the DAQ goes silent
/// for good (`cable_pull`, `daq_silent`).
fn block_fault(
    f: Option<&crate::faults::Faults>,
    blocks: u64,
    rng: &mut rand::rngs::StdRng,
) -> Result<BlockFault, &'static str> {
    let Some(f) = f else {
        return Ok(BlockFault::None);
    };
    if f.cable_pull_after_blocks.is_some_and(|k| blocks >= k) {
        return Err("cable_pull");
    }
    if f.daq_silent_after_blocks.is_some_and(|k| blocks >= k) {
        return Err("daq_silent");
    }
    Ok(draw_block_fault(f, rng))
}

/// A random per-block fault, with the stand's probabilities.
fn draw_block_fault(f: &crate::faults::Faults, rng: &mut rand::rngs::StdRng) -> BlockFault {
    let u: f64 = rng.random();
    if u < f.drop {
        BlockFault::Drop
    } else if u < f.drop + f.corrupt {
        BlockFault::Corrupt
    } else if u < f.drop + f.corrupt + f.duplicate {
        BlockFault::Duplicate
    } else if u < f.drop + f.corrupt + f.duplicate + f.delay {
        BlockFault::Delay
    } else {
        BlockFault::None
    }
}

/// The block's ADC counts from sample `first` on, sample-major, clamped to the format's range.
fn fill_counts(
    signal: &mut Signal,
    s: &Stream,
    first: u64,
    format: SampleFormat,
    counts: &mut Vec<i32>,
) {
    counts.clear();
    let (lo, hi) = format.range();
    for i in 0..s.samples_per_block as u64 {
        for &c in &s.channels {
            counts.push(signal(c, first + i).clamp(lo, hi));
        }
    }
}

/// Sends a block's data frames, with the per-block fault (`fault`, on frame `target`) and the
/// periodic frame faults of `faults`; counts them in `stats`.
async fn send_block(
    bus: &CanBus,
    frames: &[WireFrame],
    (fault, target): (BlockFault, Option<usize>),
    faults: &SimFaults,
    stats: &mut SimStats,
) -> Result<(), CanError> {
    for (i, f) in frames.iter().enumerate() {
        let here = |kind: BlockFault| target == Some(i) && fault == kind;
        stats.data_frames += 1;
        let n = stats.data_frames;
        let hit = |every: Option<u64>| every.is_some_and(|e| e > 0 && n.is_multiple_of(e));
        if hit(faults.drop_every) || here(BlockFault::Drop) {
            stats.dropped += 1;
            continue;
        }
        let mut f = *f;
        let corrupt = hit(faults.corrupt_every) || here(BlockFault::Corrupt);
        if corrupt && f.data().len() > 1 {
            let mut d = f.data().to_vec();
            let last = d.len() - 1;
            d[1 + n as usize % last] ^= 0x10;
            f = WireFrame::from_parts(f.id(), f.kind(), &d);
            stats.corrupted += 1;
        }
        bus.send(&f).await?;
        if hit(faults.duplicate_every) || here(BlockFault::Duplicate) {
            bus.send(&f).await?;
            stats.duplicated += 1;
        }
    }
    Ok(())
}

/// Encodes `message` and cuts it into `frames` (cleared first); `body` is the encoding buffer.
fn encode_frames(
    message: &Message,
    segmenter: &mut Segmenter,
    (body, frames): (&mut Vec<u8>, &mut Vec<WireFrame>),
    (interface, what): (&str, &'static str),
) -> Result<(), CanError> {
    let err = |source| CanError::Encode {
        interface: interface.into(),
        message: what,
        source,
    };
    message.encode(body).map_err(err)?;
    frames.clear();
    segmenter.segment(body, frames).map_err(err)?;
    Ok(())
}
