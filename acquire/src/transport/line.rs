//! A line-oriented conversation with an instrument over any [`Transport`]: commands out with a
//! terminator, answer lines in before a deadline, late answers of a timed-out attempt drained.
//! The SCPI shaker controller and the SCPI signal generator drivers both talk through it and name
//! their device in the errors they make of [`LinkError`].

use std::collections::VecDeque;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;

use super::Transport;
use crate::shaker::scpi::{Line, LineBuffer};

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
