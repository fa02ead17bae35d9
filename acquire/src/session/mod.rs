//! MCAP session files (docs/mcap-session.md): one file per session, every channel registered with
//! a JSON Schema, zstd-compressed chunks flushed at a fixed interval so a killed process loses at
//! most that interval, an explicit [`Session::finish`] whose errors are returned, and
//! [`recover`] for files whose writer died.
//!
//! Writing happens on a dedicated thread; [`SessionHandle`]s (cheap clones) serialize messages in
//! the caller and queue them without blocking. A message is never dropped silently: a failed
//! writer makes every later `SessionHandle::log` return an error, and bytes the
//! [`ByteTap`] could not queue are counted and reported.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use base64::Engine;
use serde::Serialize;

use crate::record::{self, Direction, Topic, TopicRecord};
use crate::transport::ByteTap;

/// Session-file errors. Each names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SessionError {
    /// Creating or writing the file failed.
    #[error(
        "session file {path}: {detail}; check free disk space and permissions of the directory"
    )]
    Write {
        /// File.
        path: String,
        /// What failed.
        detail: String,
    },
    /// The writer stopped (after an error or after finish); the message was not written.
    #[error("session file {path}: writer is closed ({detail}); this message was NOT recorded")]
    Closed {
        /// File.
        path: String,
        /// Why.
        detail: String,
    },
    /// The file is not an MCAP file at all (empty, or another format).
    #[error("{path} is not an MCAP file ({detail}); give a session file written by `ident sweep` (*.mcap)")]
    NotMcap {
        /// File.
        path: String,
        /// What it starts with.
        detail: String,
    },
    /// A truncated file holds no complete chunk: there is nothing to recover.
    #[error("session file {path}: no message can be recovered ({detail}); the recording was cut before its first chunk was written")]
    NothingToRecover {
        /// File.
        path: String,
        /// Why reading stopped.
        detail: String,
    },
    /// A record does not have its topic's shape.
    #[error("session file {path}: {topic} record {index}: {detail}; the file was not written by this version of ident, or is damaged")]
    Malformed {
        /// File.
        path: String,
        /// Topic name.
        topic: &'static str,
        /// 0-based index among that topic's records.
        index: usize,
        /// What does not fit (serde's message names the field).
        detail: String,
    },
    /// Reading a session file failed.
    #[error("session file {path}: {detail}")]
    Read {
        /// File.
        path: String,
        /// What failed.
        detail: String,
    },
}

/// Options of a session file.
#[derive(Debug, Clone)]
pub struct SessionOptions {
    /// Chunks are closed, compressed and written at least this often.
    pub flush_interval: Duration,
    /// Chunk size target (bytes, uncompressed).
    pub chunk_size: u64,
    /// zstd level.
    pub zstd_level: u32,
}

impl Default for SessionOptions {
    fn default() -> Self {
        SessionOptions {
            flush_interval: Duration::from_millis(500),
            chunk_size: 1 << 20,
            zstd_level: 3,
        }
    }
}

/// What the writer did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SessionSummary {
    /// File.
    pub path: String,
    /// Messages written per topic name.
    pub messages: BTreeMap<String, u64>,
    /// Flushes (chunk boundaries forced by the interval or on request).
    pub flushes: u64,
}

impl SessionSummary {
    /// Total messages.
    pub fn total(&self) -> u64 {
        self.messages.values().sum()
    }
}

enum Cmd {
    Msg {
        topic: Topic,
        log_time: u64,
        data: Vec<u8>,
    },
    Flush(mpsc::Sender<()>),
    Finish,
}

struct Shared {
    path: String,
    failed: AtomicBool,
    failure: std::sync::Mutex<Option<String>>,
    tap_lost: AtomicU64,
    sequence: AtomicU64,
}

/// An open session file being written.
pub struct Session {
    handle: SessionHandle,
    thread: Option<std::thread::JoinHandle<Result<SessionSummary, SessionError>>>,
}

/// A cheap, cloneable, thread-safe way to add messages to a session.
#[derive(Clone)]
pub struct SessionHandle {
    tx: mpsc::Sender<Cmd>,
    shared: Arc<Shared>,
}

/// Nanoseconds since the Unix epoch, now.
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// The MCAP writer of a session file, for recording and for recovery alike: `path` created new
/// (an existing file is never overwritten), zstd chunks of `opts.chunk_size` bytes at
/// `opts.zstd_level`, no profile, `library` naming the writing software.
fn create_writer(
    path: &Path,
    opts: &SessionOptions,
    library: &str,
) -> Result<mcap::Writer<BufWriter<File>>, SessionError> {
    let werr = |detail: String| SessionError::Write {
        path: path.display().to_string(),
        detail,
    };
    let file = File::options()
        .write(true)
        .create_new(true)
        .open(path)
        .map_err(|e| werr(format!("cannot create: {e}")))?;
    mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_level(opts.zstd_level)
        .chunk_size(Some(opts.chunk_size))
        .profile("")
        .library(library)
        .create(BufWriter::with_capacity(1 << 16, file))
        .map_err(|e| werr(e.to_string()))
}

impl Session {
    /// Creates `path` (refusing to overwrite an existing file) and starts the writer thread.
    pub fn create(path: &Path, opts: SessionOptions) -> Result<Session, SessionError> {
        let p = path.display().to_string();
        let werr = |detail: String| SessionError::Write {
            path: p.clone(),
            detail,
        };
        let mut writer = create_writer(
            path,
            &opts,
            concat!("ident-acquire/", env!("CARGO_PKG_VERSION")),
        )?;
        let mut ids = Vec::new();
        for t in record::ALL {
            let schema = serde_json::to_vec(&t.schema()).map_err(|e| werr(e.to_string()))?;
            let sid = writer
                .add_schema(t.schema_name(), "jsonschema", &schema)
                .map_err(|e| werr(e.to_string()))?;
            let cid = writer
                .add_channel(sid, t.name(), "json", &BTreeMap::new())
                .map_err(|e| werr(e.to_string()))?;
            ids.push(cid);
        }
        let shared = Arc::new(Shared {
            path: p.clone(),
            failed: AtomicBool::new(false),
            failure: std::sync::Mutex::new(None),
            tap_lost: AtomicU64::new(0),
            sequence: AtomicU64::new(0),
        });
        let (tx, rx) = mpsc::channel();
        let sh = shared.clone();
        let thread = std::thread::Builder::new()
            .name("mcap-session".into())
            .spawn(move || {
                let r = write_loop(&mut writer, &ids, rx, &opts, &sh.path);
                let r = match r {
                    Ok(summary) => writer.finish().map(|_| summary),
                    Err(e) => {
                        // Still try to leave a readable file.
                        let _ = writer.finish();
                        Err(e)
                    }
                };
                match r {
                    Ok(s) => Ok(s),
                    Err(e) => {
                        let detail = e.to_string();
                        sh.failed.store(true, Ordering::SeqCst);
                        if let Ok(mut f) = sh.failure.lock() {
                            *f = Some(detail.clone());
                        }
                        Err(SessionError::Write {
                            path: sh.path.clone(),
                            detail,
                        })
                    }
                }
            })
            .map_err(|e| werr(format!("cannot start the writer thread: {e}")))?;
        Ok(Session {
            handle: SessionHandle { tx, shared },
            thread: Some(thread),
        })
    }

    /// A handle for adding messages.
    pub fn handle(&self) -> SessionHandle {
        self.handle.clone()
    }

    /// Writes the summary and closes the file. Returns what was written, or the first error.
    /// Messages logged through handles after this returns fail with [`SessionError::Closed`].
    pub fn finish(mut self) -> Result<SessionSummary, SessionError> {
        self.finish_inner()
    }

    fn finish_inner(&mut self) -> Result<SessionSummary, SessionError> {
        let _ = self.handle.tx.send(Cmd::Finish);
        let closed = |detail: &str| SessionError::Closed {
            path: self.handle.shared.path.clone(),
            detail: detail.into(),
        };
        let t = self
            .thread
            .take()
            .ok_or_else(|| closed("finish called twice"))?;
        let summary = t
            .join()
            .map_err(|_| closed("the writer thread panicked"))??;
        let lost = self.handle.shared.tap_lost.load(Ordering::SeqCst);
        if lost > 0 {
            return Err(closed(&format!(
                "{lost} raw byte records could not be queued"
            )));
        }
        Ok(summary)
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        if self.thread.is_some() {
            // Not finished explicitly: finish now so the file is valid, and say so loudly.
            if let Err(e) = self.finish_inner() {
                tracing::error!("session dropped without finish(): {e}");
            } else {
                tracing::warn!(
                    "session {} dropped without finish(); finished it",
                    self.handle.shared.path
                );
            }
        }
    }
}

fn write_loop(
    writer: &mut mcap::Writer<BufWriter<File>>,
    ids: &[u16],
    rx: mpsc::Receiver<Cmd>,
    opts: &SessionOptions,
    path: &str,
) -> Result<SessionSummary, mcap::McapError> {
    let mut counts = vec![0u64; ids.len()];
    let mut seq = vec![0u32; ids.len()];
    let mut last_flush = Instant::now();
    let mut flushes = 0;
    let mut dirty = false;
    loop {
        let wait = opts.flush_interval.saturating_sub(last_flush.elapsed());
        match rx.recv_timeout(wait) {
            Ok(Cmd::Msg {
                topic,
                log_time,
                data,
            }) => {
                let i = topic.index();
                let header = mcap::records::MessageHeader {
                    channel_id: ids[i],
                    sequence: seq[i],
                    log_time,
                    publish_time: log_time,
                };
                writer.write_to_known_channel(&header, &data)?;
                seq[i] = seq[i].wrapping_add(1);
                counts[i] += 1;
                dirty = true;
            }
            Ok(Cmd::Flush(done)) => {
                writer.flush()?;
                flushes += 1;
                dirty = false;
                last_flush = Instant::now();
                let _ = done.send(());
            }
            Ok(Cmd::Finish) | Err(mpsc::RecvTimeoutError::Disconnected) => break,
            Err(mpsc::RecvTimeoutError::Timeout) => {}
        }
        if last_flush.elapsed() >= opts.flush_interval {
            if dirty {
                writer.flush()?;
                flushes += 1;
                dirty = false;
            }
            last_flush = Instant::now();
        }
    }
    let messages = record::ALL
        .iter()
        .zip(counts)
        .map(|(t, c)| (t.name().to_string(), c))
        .collect();
    Ok(SessionSummary {
        path: path.to_string(),
        messages,
        flushes,
    })
}

impl SessionHandle {
    /// Queues a message on `topic` with the current time.
    pub(crate) fn log<T: Serialize + ?Sized>(
        &self,
        topic: Topic,
        msg: &T,
    ) -> Result<(), SessionError> {
        self.log_at(topic, now_ns(), msg)
    }

    /// Queues a record on its topic, stamped with the current time.
    pub fn record<R: TopicRecord>(&self, record: &R) -> Result<(), SessionError> {
        self.log(R::TOPIC, record)
    }

    /// Queues a message with an explicit log time (ns since the Unix epoch).
    pub fn log_at<T: Serialize + ?Sized>(
        &self,
        topic: Topic,
        log_time: u64,
        msg: &T,
    ) -> Result<(), SessionError> {
        let data = serde_json::to_vec(msg).map_err(|e| SessionError::Write {
            path: self.shared.path.clone(),
            detail: format!("cannot encode a {} message: {e}", topic.name()),
        })?;
        self.send(Cmd::Msg {
            topic,
            log_time,
            data,
        })
    }

    fn send(&self, cmd: Cmd) -> Result<(), SessionError> {
        self.check()?;
        self.shared.sequence.fetch_add(1, Ordering::Relaxed);
        self.tx.send(cmd).map_err(|_| SessionError::Closed {
            path: self.shared.path.clone(),
            detail: "the writer has finished".into(),
        })
    }

    /// Errors if the writer has failed or raw bytes were lost.
    pub fn check(&self) -> Result<(), SessionError> {
        if self.shared.failed.load(Ordering::SeqCst) {
            let detail = self
                .shared
                .failure
                .lock()
                .ok()
                .and_then(|f| f.clone())
                .unwrap_or_default();
            return Err(SessionError::Closed {
                path: self.shared.path.clone(),
                detail,
            });
        }
        let lost = self.shared.tap_lost.load(Ordering::SeqCst);
        if lost > 0 {
            return Err(SessionError::Closed {
                path: self.shared.path.clone(),
                detail: format!("{lost} raw byte records could not be queued"),
            });
        }
        Ok(())
    }

    /// Forces a chunk boundary and waits (up to `timeout`) until it is written to the OS.
    pub fn flush(&self, timeout: Duration) -> Result<(), SessionError> {
        let (tx, rx) = mpsc::channel();
        self.send(Cmd::Flush(tx))?;
        rx.recv_timeout(timeout).map_err(|_| SessionError::Closed {
            path: self.shared.path.clone(),
            detail: format!("flush not confirmed within {timeout:?}"),
        })
    }

    /// The file being written.
    pub fn path(&self) -> &str {
        &self.shared.path
    }
}

impl ByteTap for SessionHandle {
    fn bytes(&self, port: &str, direction: Direction, data: &[u8]) {
        let rec = record::RawBytes {
            port: port.to_string(),
            direction,
            data: base64::engine::general_purpose::STANDARD.encode(data),
        };
        if self.record(&rec).is_err() {
            self.shared.tap_lost.fetch_add(1, Ordering::SeqCst);
        }
    }
}

/// One message read back from a session file.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Topic name.
    pub topic: String,
    /// Log time (ns since the Unix epoch).
    pub log_time: u64,
    /// Decoded JSON.
    pub value: serde_json::Value,
}

impl Record {
    /// True for a record of `R`'s topic.
    pub fn is<R: TopicRecord>(&self) -> bool {
        self.topic == R::TOPIC.name()
    }

    /// This record as `R` (serde's error names the field that does not fit).
    pub fn decode<R: TopicRecord>(&self) -> Result<R, serde_json::Error> {
        R::deserialize(&self.value)
    }
}

/// What [`read`] or [`recover`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadReport {
    /// The file read.
    pub path: String,
    /// Messages, in file order.
    pub records: Vec<Record>,
    /// `None` if the file is complete; otherwise where and why reading stopped.
    pub truncated: Option<String>,
}

impl ReadReport {
    /// Every record of `R`'s topic, decoded, in file order.
    pub fn all<R: TopicRecord>(&self) -> Result<Vec<R>, SessionError> {
        self.records
            .iter()
            .filter(|r| r.is::<R>())
            .enumerate()
            .map(|(index, r)| r.decode().map_err(|e| self.malformed::<R>(index, e)))
            .collect()
    }

    /// The first record of `R`'s topic, decoded, if there is one.
    pub fn first<R: TopicRecord>(&self) -> Result<Option<R>, SessionError> {
        self.records
            .iter()
            .find(|r| r.is::<R>())
            .map(|r| r.decode().map_err(|e| self.malformed::<R>(0, e)))
            .transpose()
    }

    /// The error for record `index` of `R`'s topic.
    pub fn malformed<R: TopicRecord>(&self, index: usize, e: serde_json::Error) -> SessionError {
        SessionError::Malformed {
            path: self.path.clone(),
            topic: R::TOPIC.name(),
            index,
            detail: e.to_string(),
        }
    }
}

/// One message read linearly: its channel, sequence, log time (ns) and payload.
type RawMessage = (Arc<mcap::Channel<'static>>, u32, u64, Vec<u8>);

/// Fails unless `path` starts with the MCAP magic bytes.
fn check_magic(path: &Path) -> Result<(), SessionError> {
    let mut head = Vec::with_capacity(mcap::MAGIC.len());
    File::open(path)
        .and_then(|f| f.take(mcap::MAGIC.len() as u64).read_to_end(&mut head))
        .map_err(|e| SessionError::Read {
            path: path.display().to_string(),
            detail: format!("cannot open: {e}"),
        })?;
    if head == mcap::MAGIC {
        return Ok(());
    }
    let detail = if head.is_empty() {
        "the file is empty".to_string()
    } else {
        format!("it starts with {head:02x?}, not the MCAP magic")
    };
    Err(SessionError::NotMcap {
        path: path.display().to_string(),
        detail,
    })
}

/// Every message of every complete chunk, and why reading stopped early (`None`: the file is
/// complete, footer and end magic included).
fn linear_messages(path: &Path) -> Result<(Vec<RawMessage>, Option<String>), SessionError> {
    check_magic(path)?;
    let file = File::open(path).map_err(|e| SessionError::Read {
        path: path.display().to_string(),
        detail: format!("cannot open: {e}"),
    })?;
    let opts = mcap::sans_io::LinearReaderOptions::default().with_skip_end_magic(true);
    let mut out = Vec::new();
    let mut stop = None;
    for m in mcap::io::MessageReader::new_with_options(BufReader::new(file), opts) {
        match m {
            Ok(m) => out.push((
                m.channel.clone(),
                m.sequence,
                m.log_time,
                m.data.into_owned(),
            )),
            Err(e) => {
                stop = Some(e.to_string());
                break;
            }
        }
    }
    if stop.is_none() {
        // The linear reader accepts files without end magic; say whether the summary is there.
        let bytes = std::fs::read(path).map_err(|e| SessionError::Read {
            path: path.display().to_string(),
            detail: e.to_string(),
        })?;
        if !bytes.ends_with(mcap::MAGIC) || bytes.len() < 2 * mcap::MAGIC.len() {
            stop = Some("file ends without the MCAP footer (writer did not finish)".into());
        }
    }
    Ok((out, stop))
}

/// Reads every message of a session file, complete or truncated (a truncated file yields the
/// messages of every complete chunk, and `truncated` says why it stopped).
pub fn read(path: &Path) -> Result<ReadReport, SessionError> {
    let (msgs, stop) = linear_messages(path)?;
    let records = msgs
        .into_iter()
        .map(|(c, _, t, d)| Record {
            topic: c.topic.clone(),
            log_time: t,
            value: serde_json::from_slice(&d).unwrap_or(serde_json::Value::Null),
        })
        .collect();
    Ok(ReadReport {
        path: path.display().to_string(),
        records,
        truncated: stop,
    })
}

/// What [`recover`] did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecoverReport {
    /// Input file.
    pub input: String,
    /// Output file.
    pub output: String,
    /// Messages copied.
    pub messages: u64,
    /// Why the input ended early (`None` if it was complete).
    pub truncated: Option<String>,
}

/// Rewrites a (possibly truncated) session file into a valid one with a summary: every message of
/// every complete chunk is copied with its channel and schema. Refuses to overwrite `output`.
pub fn recover(input: &Path, output: &Path) -> Result<RecoverReport, SessionError> {
    let (msgs, stop) = linear_messages(input)?;
    if let (true, Some(why)) = (msgs.is_empty(), &stop) {
        return Err(SessionError::NothingToRecover {
            path: input.display().to_string(),
            detail: why.clone(),
        });
    }
    let o = output.display().to_string();
    let werr = |detail: String| SessionError::Write {
        path: o.clone(),
        detail,
    };
    let mut w = create_writer(
        output,
        &SessionOptions::default(),
        concat!("ident-acquire-recover/", env!("CARGO_PKG_VERSION")),
    )?;
    let n = msgs.len() as u64;
    for (channel, sequence, log_time, data) in msgs {
        let m = mcap::Message {
            channel,
            sequence,
            log_time,
            publish_time: log_time,
            data: std::borrow::Cow::Owned(data),
        };
        w.write(&m).map_err(|e| werr(e.to_string()))?;
    }
    w.finish().map_err(|e| werr(e.to_string()))?;
    Ok(RecoverReport {
        input: input.display().to_string(),
        output: o,
        messages: n,
        truncated: stop,
    })
}

/// Default output path of [`recover`]: `<stem>.recovered.mcap` next to the input.
pub fn recovered_path(input: &Path) -> PathBuf {
    let stem = input
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "session".into());
    input.with_file_name(format!("{stem}.recovered.mcap"))
}

#[cfg(test)]
mod tests;
