//! A transport wrapper that copies every byte sent and received to a [`ByteTap`] (the session log).

use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

use super::Transport;
pub use crate::record::Direction;

/// Receives a copy of every byte a [`Tapped`] transport moves. Must not block and must not lose
/// data (the session implementation queues to its writer thread).
pub trait ByteTap: Send + Sync {
    /// `data` went over `port` in `direction`.
    fn bytes(&self, port: &str, direction: Direction, data: &[u8]);
}

/// A transport whose traffic is copied to a tap.
pub struct Tapped<T> {
    inner: T,
    tap: Arc<dyn ByteTap>,
}

impl<T: Transport> Tapped<T> {
    /// Wraps `inner`; every byte read or written is reported to `tap`.
    pub fn new(inner: T, tap: Arc<dyn ByteTap>) -> Self {
        Tapped { inner, tap }
    }
}

impl<T: Transport> Transport for Tapped<T> {
    fn port(&self) -> &str {
        self.inner.port()
    }
}

impl<T: Transport> AsyncRead for Tapped<T> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let before = buf.filled().len();
        let r = Pin::new(&mut self.inner).poll_read(cx, buf);
        if let Poll::Ready(Ok(())) = &r {
            let new = &buf.filled()[before..];
            if !new.is_empty() {
                self.tap.bytes(self.inner.port(), Direction::Rx, new);
            }
        }
        r
    }
}

impl<T: Transport> AsyncWrite for Tapped<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write(cx, buf);
        if let Poll::Ready(Ok(n)) = &r {
            if *n > 0 {
                self.tap.bytes(self.inner.port(), Direction::Tx, &buf[..*n]);
            }
        }
        r
    }
    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }
    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}
