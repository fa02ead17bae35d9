//! A line-oriented conversation with an instrument over any [`Transport`]: commands out with a
//! terminator, answer lines in before a deadline, late answers of a timed-out attempt drained.
//! The SCPI shaker controller and the SCPI signal generator drivers both talk through it and name
//! their device in the errors they make of [`LinkError`]. The framing itself, [`LineBuffer`], is
//! I/O free and also serves the simulated instruments.

use std::collections::VecDeque;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;

use super::Transport;

/// How long [`LineLink::drain`] waits for more late bytes before it considers the line quiet.
const QUIET: Duration = Duration::from_millis(5);

/// Why the link failed, before a driver names its device.
#[derive(Debug)]
pub enum LinkError {
    /// The operating system's error.
    Io(std::io::Error),
    /// The other end closed the stream (end of file).
    Closed,
}

impl LinkError {
    /// This failure as the driver's error, naming its device `device`.
    pub fn on<E: LinkFailure>(self, device: &str) -> E {
        match self {
            LinkError::Io(e) => E::io(device, e),
            LinkError::Closed => E::closed(device),
        }
    }
}

/// A driver's error type, as it names the failures of its device's link.
pub trait LinkFailure {
    /// The operating system's error `e` on the link to `device`.
    fn io(device: &str, e: std::io::Error) -> Self;
    /// `device` closed the stream (end of file).
    fn closed(device: &str) -> Self;
}

/// What a query got back.
#[derive(Debug, Clone, PartialEq)]
pub enum Answer {
    /// An answer line.
    Text(String),
    /// A line that is not text (the bytes lossily decoded).
    Garbage(String),
    /// No line after every attempt; `pending`: what the last attempt to receive any bytes
    /// received without a line end (a wrong baud rate or terminator shows here).
    Silent {
        /// Bytes without a line end, lossily decoded.
        pending: Option<String>,
    },
}

/// A transport with its receive buffer and the lines framed but not yet read.
pub struct LineLink<T> {
    io: T,
    lines: LineBuffer,
    ready: VecDeque<Line>,
    rx: Vec<u8>,
}

impl<T: Transport> LineLink<T> {
    /// A link over `io`; nothing is sent or read yet.
    pub fn new(io: T) -> Self {
        LineLink {
            io,
            lines: LineBuffer::new(),
            ready: VecDeque::new(),
            rx: vec![0; 1024],
        }
    }

    /// What was received after the last complete line, lossily decoded (for messages).
    pub fn pending(&self) -> String {
        self.lines.pending()
    }

    /// Continues over a new connection (after a reconnect); what the old one held is dropped.
    pub fn replace(&mut self, io: T) {
        self.io = io;
        self.clear();
    }

    fn clear(&mut self) {
        self.ready.clear();
        self.lines.clear();
    }

    /// Sends `line` followed by `terminator` and flushes.
    pub async fn send(&mut self, line: &str, terminator: &str) -> Result<(), std::io::Error> {
        let mut bytes = Vec::with_capacity(line.len() + terminator.len());
        bytes.extend_from_slice(line.as_bytes());
        bytes.extend_from_slice(terminator.as_bytes());
        self.io.write_all(&bytes).await?;
        self.io.flush().await
    }

    /// Sends raw `bytes` (a command carrying a binary block) followed by `terminator`, and
    /// flushes.
    pub async fn send_bytes(
        &mut self,
        bytes: &[u8],
        terminator: &str,
    ) -> Result<(), std::io::Error> {
        let mut all = Vec::with_capacity(bytes.len() + terminator.len());
        all.extend_from_slice(bytes);
        all.extend_from_slice(terminator.as_bytes());
        self.io.write_all(&all).await?;
        self.io.flush().await
    }

    /// The next answer line before `deadline`; `Ok(None)` on timeout.
    pub async fn read_line(&mut self, deadline: Instant) -> Result<Option<Line>, LinkError> {
        loop {
            if let Some(l) = self.ready.pop_front() {
                return Ok(Some(l));
            }
            let n = match tokio::time::timeout_at(deadline, self.io.read(&mut self.rx)).await {
                Err(_) => return Ok(None),
                Ok(Err(e)) => return Err(LinkError::Io(e)),
                Ok(Ok(0)) => return Err(LinkError::Closed),
                Ok(Ok(n)) => n,
            };
            let ready = &mut self.ready;
            self.lines.feed(&self.rx[..n], |l| ready.push_back(l));
        }
    }

    /// Sends `line` with `terminator` and waits `timeout` for the answer line; after a timeout,
    /// drains late bytes and sends it again, `retries` times.
    pub async fn query(
        &mut self,
        line: &str,
        terminator: &str,
        timeout: Duration,
        retries: u32,
    ) -> Result<Answer, LinkError> {
        let mut pending = None;
        for attempt in 0..=retries {
            if attempt > 0 {
                self.drain().await?;
            }
            self.send(line, terminator).await.map_err(LinkError::Io)?;
            match self.read_line(Instant::now() + timeout).await? {
                Some(Line::Text(t)) => return Ok(Answer::Text(t)),
                Some(Line::Garbage(g)) => return Ok(Answer::Garbage(g)),
                None => {
                    let p = self.pending();
                    if !p.is_empty() {
                        pending = Some(p);
                    }
                }
            }
        }
        Ok(Answer::Silent { pending })
    }

    /// Discards everything received so far and whatever still arrives until the line is quiet
    /// (late answers to an attempt that timed out).
    pub async fn drain(&mut self) -> Result<(), LinkError> {
        self.clear();
        while let Ok(r) = tokio::time::timeout(QUIET, self.io.read(&mut self.rx)).await {
            match r {
                Ok(0) => return Err(LinkError::Closed),
                Ok(_) => continue,
                Err(e) => return Err(LinkError::Io(e)),
            }
        }
        Ok(())
    }
}

/// Maximum line length (bytes, without terminator) accepted in either direction.
pub const MAX_LINE: usize = 256;

/// Splits a byte stream into lines at `\n` (a preceding `\r` is dropped). I/O free.
#[derive(Debug, Default)]
pub struct LineBuffer {
    buf: Vec<u8>,
    overflow: bool,
}

/// One framed line, or a line that was too long or not text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Line {
    /// A complete line.
    Text(String),
    /// Bytes that are not a valid line (too long or not UTF-8), lossily decoded for messages.
    Garbage(String),
}

impl LineBuffer {
    /// An empty buffer.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds bytes; calls `sink` for every complete line.
    pub fn feed(&mut self, bytes: &[u8], mut sink: impl FnMut(Line)) {
        for &b in bytes {
            if b == b'\n' {
                if self.buf.last() == Some(&b'\r') {
                    self.buf.pop();
                }
                let line = if self.overflow {
                    Line::Garbage(format!(
                        "{}… (longer than {MAX_LINE} bytes)",
                        String::from_utf8_lossy(&self.buf)
                    ))
                } else {
                    match std::str::from_utf8(&self.buf) {
                        Ok(s) if !s.chars().any(|c| c.is_control() && c != '\t') => {
                            Line::Text(s.to_string())
                        }
                        _ => Line::Garbage(String::from_utf8_lossy(&self.buf).into_owned()),
                    }
                };
                self.buf.clear();
                self.overflow = false;
                sink(line);
            } else if self.buf.len() < MAX_LINE {
                self.buf.push(b);
            } else {
                self.overflow = true;
            }
        }
    }

    /// Bytes of an unfinished line, lossily decoded.
    pub fn pending(&self) -> String {
        String::from_utf8_lossy(&self.buf).into_owned()
    }

    /// Discards an unfinished line.
    pub fn clear(&mut self) {
        self.buf.clear();
        self.overflow = false;
    }
}
