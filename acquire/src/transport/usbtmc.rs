//! USBTMC instruments through the Linux `usbtmc` kernel driver (`/dev/usbtmc0`): the driver
//! turns each `write()` into one USBTMC message (bulk-out, end-of-message set) and each `read()`
//! into a request for one answer message (bulk-in). A `read()` with no query outstanding does
//! not wait for data like a serial port: the instrument has nothing to send and the driver gives
//! up after its own timeout (`ETIMEDOUT`, 5 s by default).
//!
//! [`UsbtmcTransport`] keeps those semantics behind the byte-stream [`Transport`] the SCPI
//! drivers use: the bytes written up to a flush are one message per line (one `write()` each),
//! and the device is read only after a message holding a query (`?`), until the answer line is
//! complete. The device file is blocking, so a worker thread owns it; the async side exchanges
//! messages with it over channels. The host's answer timeout governs: a flush does not wait for
//! the worker (which may sit in the read of an unanswered query until the driver's timeout), a
//! failed `write()` surfaces at the next flush or read, and a late `ETIMEDOUT` is logged and
//! dropped. Reconnecting means opening the
//! path again (the generator driver's reconnect does so).
//!
//! What the tests use instead of the kernel driver: an in-memory device with the driver's
//! message semantics (one write per message, read only after a query, `ETIMEDOUT` otherwise),
//! and the simulated generator's pseudo-terminal, which has byte-stream semantics (the worker
//! reads until the answer line ends, so it works over either). The USB framing itself
//! (bulk-in/out headers, `bTag`, the driver's ioctls) is not exercised.

use std::future::Future;
use std::io::{Read, Write};
use std::pin::Pin;
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::sync::{mpsc, oneshot};

use super::{Transport, TransportError};

/// Largest answer read in one `read()` (the driver splits longer messages over several reads).
const READ_CHUNK: usize = 64 * 1024;

/// What the worker thread answers: a chunk of an answer message, or the device's error.
type Chunk = std::io::Result<Vec<u8>>;

/// One message for the worker, and where it confirms the `write()`.
type Outgoing = (Vec<u8>, oneshot::Sender<std::io::Result<()>>);

/// An open USBTMC device (see the module docs).
pub struct UsbtmcTransport {
    name: String,
    /// Bytes written since the last flush.
    out: Vec<u8>,
    /// Messages to the worker thread.
    to_device: std::sync::mpsc::Sender<Outgoing>,
    /// Confirmations of the messages flushed and not yet confirmed.
    acks: std::collections::VecDeque<oneshot::Receiver<std::io::Result<()>>>,
    /// Answer bytes from the worker thread.
    from_device: mpsc::UnboundedReceiver<Chunk>,
    /// Answer bytes received and not yet read.
    unread: Vec<u8>,
}

impl std::fmt::Debug for UsbtmcTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UsbtmcTransport")
            .field("port", &self.name)
            .finish()
    }
}

/// Opens the `usbtmc` driver's device at `path` (`/dev/usbtmc0`), named `usbtmc:PATH`.
///
/// Missing device, permission denied and "not a character device" each become a
/// [`TransportError`] that says what to do (module loaded, udev rule and group, the path).
pub fn open_usbtmc(path: &str) -> Result<UsbtmcTransport, TransportError> {
    use std::os::unix::fs::FileTypeExt;
    let name = format!("usbtmc:{path}");
    let meta = std::fs::metadata(path).map_err(|e| open_error(&name, &e))?;
    if !meta.file_type().is_char_device() {
        return Err(TransportError::NotUsbtmc {
            port: name,
            detail: if meta.is_dir() {
                "it is a directory".into()
            } else {
                "it is not a character device".into()
            },
        });
    }
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .map_err(|e| open_error(&name, &e))?;
    Ok(UsbtmcTransport::over(&name, file))
}

fn open_error(port: &str, e: &std::io::Error) -> TransportError {
    use std::io::ErrorKind as K;
    let port = port.to_string();
    match e.kind() {
        K::NotFound => TransportError::UsbtmcNotFound { port },
        K::PermissionDenied => TransportError::UsbtmcPermission { port },
        _ => TransportError::Open {
            port,
            detail: e.to_string(),
        },
    }
}

impl UsbtmcTransport {
    /// A transport over `device`, which has the `usbtmc` driver's message semantics (each
    /// `write()` one message, each `read()` one answer or part of it). Spawns the worker thread
    /// that owns it; the thread ends when the transport is dropped and the device's pending
    /// call (if any) returns.
    pub fn over(name: &str, device: impl Read + Write + Send + 'static) -> UsbtmcTransport {
        let (to_device, requests) = std::sync::mpsc::channel::<Outgoing>();
        let (answers, from_device) = mpsc::unbounded_channel();
        let thread_name = format!("usbtmc {name}");
        let port = name.to_string();
        let worker = move || serve(&port, device, &requests, &answers);
        if let Err(e) = std::thread::Builder::new().name(thread_name).spawn(worker) {
            // No thread: every message fails with this error (reported on the first flush).
            tracing::error!("{name}: cannot start the USBTMC worker thread: {e}");
        }
        UsbtmcTransport {
            name: name.to_string(),
            out: Vec::new(),
            to_device,
            acks: std::collections::VecDeque::new(),
            from_device,
            unread: Vec::new(),
        }
    }
}

/// Whether a message asks for an answer (a SCPI query: `*IDN?`, `VOLT?`, `*OPC?;SYST:ERR?`).
fn is_query(message: &[u8]) -> bool {
    message.contains(&b'?')
}

/// The device gone (unplugged, powered off) reads as a lost connection.
fn device_error(e: std::io::Error) -> std::io::Error {
    // ENODEV (19) and ESHUTDOWN (108): the usbtmc driver's "device disconnected".
    match e.raw_os_error() {
        Some(19) | Some(108) => std::io::Error::new(
            std::io::ErrorKind::NotConnected,
            format!(
                "USBTMC device disconnected ({e}); check the USB cable and the generator's power"
            ),
        ),
        _ => e,
    }
}

/// The worker: writes each message with one `write()`, then reads the answer of a query.
fn serve(
    port: &str,
    mut device: impl Read + Write,
    requests: &std::sync::mpsc::Receiver<Outgoing>,
    answers: &mpsc::UnboundedSender<Chunk>,
) {
    let mut buf = vec![0u8; READ_CHUNK];
    while let Ok((message, ack)) = requests.recv() {
        let written = match device.write(&message) {
            Ok(n) if n == message.len() => Ok(()),
            Ok(n) => Err(std::io::Error::new(
                std::io::ErrorKind::WriteZero,
                format!(
                    "the device took {n} of the message's {} bytes",
                    message.len()
                ),
            )),
            Err(e) => Err(device_error(e)),
        };
        let ok = written.is_ok();
        // The transport may be gone (dropped mid-flush): nothing to tell then.
        let _ = ack.send(written);
        if !ok || !is_query(&message) {
            continue;
        }
        // Read until the answer line is complete (the driver returns the whole message, or
        // parts of it when longer than the buffer; a pseudo-terminal returns what is there).
        loop {
            match device.read(&mut buf) {
                Ok(0) => {
                    let _ = answers.send(Ok(Vec::new()));
                    return;
                }
                Ok(n) => {
                    let done = buf[n - 1] == b'\n';
                    if answers.send(Ok(buf[..n].to_vec())).is_err() {
                        return;
                    }
                    if done {
                        break;
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {
                    // The driver's timeout: no answer. The host has timed out by now too.
                    tracing::warn!(
                        "{port}: no answer to {:?} (driver timeout)",
                        String::from_utf8_lossy(&message).trim_end()
                    );
                    break;
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    let _ = answers.send(Err(device_error(e)));
                    break;
                }
            }
        }
    }
}

fn worker_gone() -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::NotConnected,
        "the USBTMC worker thread has ended",
    )
}

impl UsbtmcTransport {
    /// Collects the `write()` confirmations that are in; the first failure, if any.
    fn written(&mut self, cx: &mut Context<'_>) -> std::io::Result<()> {
        while let Some(ack) = self.acks.front_mut() {
            match Pin::new(ack).poll(cx) {
                Poll::Pending => return Ok(()),
                Poll::Ready(r) => {
                    self.acks.pop_front();
                    match r {
                        Ok(Ok(())) => {}
                        Ok(Err(e)) => return Err(e),
                        Err(_) => return Err(worker_gone()),
                    }
                }
            }
        }
        Ok(())
    }
}

impl Transport for UsbtmcTransport {
    fn port(&self) -> &str {
        &self.name
    }
}

impl AsyncRead for UsbtmcTransport {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        if let Err(e) = self.written(cx) {
            return Poll::Ready(Err(e));
        }
        if self.unread.is_empty() {
            match self.from_device.poll_recv(cx) {
                Poll::Pending => return Poll::Pending,
                // Worker gone, or the device's end of file: end of stream.
                Poll::Ready(None) => return Poll::Ready(Ok(())),
                Poll::Ready(Some(Err(e))) => return Poll::Ready(Err(e)),
                Poll::Ready(Some(Ok(bytes))) if bytes.is_empty() => return Poll::Ready(Ok(())),
                Poll::Ready(Some(Ok(bytes))) => self.unread = bytes,
            }
        }
        let n = self.unread.len().min(buf.remaining());
        buf.put_slice(&self.unread[..n]);
        self.unread.drain(..n);
        Poll::Ready(Ok(()))
    }
}

impl AsyncWrite for UsbtmcTransport {
    fn poll_write(
        mut self: Pin<&mut Self>,
        _cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        self.out.extend_from_slice(buf);
        Poll::Ready(Ok(buf.len()))
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        // Each line of what was written is one message (SCPI's message terminator is the newline).
        while !self.out.is_empty() {
            let end = match self.out.iter().position(|b| *b == b'\n') {
                Some(i) => i + 1,
                None => self.out.len(),
            };
            let message: Vec<u8> = self.out.drain(..end).collect();
            let (tx, rx) = oneshot::channel();
            if self.to_device.send((message, tx)).is_err() {
                return Poll::Ready(Err(worker_gone()));
            }
            self.acks.push_back(rx);
        }
        // Confirmations already in: a failed write() fails this flush. Those still pending are
        // not waited for: the worker may be blocked in the read of an earlier query the device
        // never answers (until the driver's timeout), and the host's answer timeout must govern.
        // Their errors surface at the next flush or read.
        Poll::Ready(self.written(cx))
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        self.poll_flush(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::VecDeque;
    use std::sync::{Arc, Mutex};
    use std::time::Duration;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    /// An in-memory device with the `usbtmc` driver's message semantics: every `write()` is one
    /// message (recorded), a query queues its answer, a `read()` returns at most `chunk` bytes of
    /// the queued answer and fails with `ETIMEDOUT` when none is queued.
    struct FakeDriver {
        messages: Messages,
        answers: VecDeque<u8>,
        chunk: usize,
        unanswered_reads: Arc<Mutex<u32>>,
    }

    impl Write for FakeDriver {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.messages
                .lock()
                .map_err(|_| std::io::Error::other("poisoned"))?
                .push(buf.to_vec());
            let text = String::from_utf8_lossy(buf);
            if text.trim() == "*IDN?" {
                self.answers
                    .extend(b"Keysight Technologies,33512B,MY00000001,5.03-3.15-2.00-58-00\n");
            } else if text.trim() == "DATA?" {
                // A long answer, read in several chunks.
                self.answers.extend(vec![b'7'; 300]);
                self.answers.push_back(b'\n');
            } else if text.trim() == "SILENT?" {
                // No answer queued: the read times out like the driver's.
            }
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Read for FakeDriver {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            if self.answers.is_empty() {
                *self
                    .unanswered_reads
                    .lock()
                    .map_err(|_| std::io::Error::other("poisoned"))? += 1;
                return Err(std::io::Error::from_raw_os_error(110)); // ETIMEDOUT
            }
            let n = self.answers.len().min(buf.len()).min(self.chunk);
            for b in buf.iter_mut().take(n) {
                *b = self.answers.pop_front().unwrap_or(b'\n');
            }
            Ok(n)
        }
    }

    /// The messages the fake device received.
    type Messages = Arc<Mutex<Vec<Vec<u8>>>>;

    fn fake() -> (UsbtmcTransport, Messages, Arc<Mutex<u32>>) {
        let messages = Arc::new(Mutex::new(Vec::new()));
        let timeouts = Arc::new(Mutex::new(0));
        let dev = FakeDriver {
            messages: messages.clone(),
            answers: VecDeque::new(),
            chunk: 128,
            unanswered_reads: timeouts.clone(),
        };
        (
            UsbtmcTransport::over("usbtmc:fake", dev),
            messages,
            timeouts,
        )
    }

    async fn line(t: &mut UsbtmcTransport) -> String {
        let mut got = Vec::new();
        let mut b = [0u8; 64];
        while !got.ends_with(b"\n") {
            let n = tokio::time::timeout(Duration::from_secs(5), t.read(&mut b))
                .await
                .expect("answer in time")
                .expect("read");
            assert!(n > 0, "end of stream before the answer ended");
            got.extend_from_slice(&b[..n]);
        }
        String::from_utf8(got).expect("utf-8")
    }

    #[tokio::test]
    async fn each_line_is_one_message_and_only_queries_are_read() {
        let (mut t, messages, timeouts) = fake();
        // Two settings and a query written at once, flushed once: three messages.
        t.write_all(b"FREQ 100\nVOLT 0.5\n*IDN?\n").await.unwrap();
        t.flush().await.unwrap();
        assert!(line(&mut t)
            .await
            .starts_with("Keysight Technologies,33512B,"));
        // A long answer arrives in chunks and is reassembled up to its newline.
        t.write_all(b"DATA?\n").await.unwrap();
        t.flush().await.unwrap();
        let data = line(&mut t).await;
        assert_eq!(data.len(), 301, "{data:?}");
        assert_eq!(
            *messages.lock().unwrap(),
            vec![
                b"FREQ 100\n".to_vec(),
                b"VOLT 0.5\n".to_vec(),
                b"*IDN?\n".to_vec(),
                b"DATA?\n".to_vec()
            ]
        );
        // The settings were never followed by a read (which the driver would time out).
        assert_eq!(*timeouts.lock().unwrap(), 0);
        assert_eq!(t.port(), "usbtmc:fake");
    }

    #[tokio::test]
    async fn a_query_without_answer_times_out_on_the_host_and_the_next_one_works() {
        let (mut t, _messages, timeouts) = fake();
        t.write_all(b"SILENT?\n").await.unwrap();
        t.flush().await.unwrap();
        let mut b = [0u8; 16];
        let r = tokio::time::timeout(Duration::from_millis(200), t.read(&mut b)).await;
        assert!(
            r.is_err(),
            "no answer must read as nothing, not as data or end of stream"
        );
        assert_eq!(*timeouts.lock().unwrap(), 1);
        t.write_all(b"*IDN?\n").await.unwrap();
        t.flush().await.unwrap();
        assert!(line(&mut t).await.contains("33512B"));
    }

    /// A device whose `write()` fails as an unplugged instrument's does (`ENODEV`).
    struct Unplugged;

    impl Write for Unplugged {
        fn write(&mut self, _: &[u8]) -> std::io::Result<usize> {
            Err(std::io::Error::from_raw_os_error(19))
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Read for Unplugged {
        fn read(&mut self, _: &mut [u8]) -> std::io::Result<usize> {
            Err(std::io::Error::from_raw_os_error(19))
        }
    }

    #[tokio::test]
    async fn a_failed_write_surfaces_as_a_lost_connection() {
        let mut t = UsbtmcTransport::over("usbtmc:gone", Unplugged);
        t.write_all(b"*IDN?\n").await.unwrap();
        // The flush may return before the worker's confirmation; the error then comes with the
        // next flush or read, within the host's own timeout.
        let r = match t.flush().await {
            Err(e) => Err(e),
            Ok(()) => {
                let mut b = [0u8; 8];
                tokio::time::timeout(Duration::from_secs(5), t.read(&mut b))
                    .await
                    .expect("the error arrives")
                    .map(|_| ())
            }
        };
        let e = r.unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::NotConnected, "{e}");
        assert!(e.to_string().contains("USB cable"), "{e}");
    }

    #[test]
    fn missing_device_and_plain_files_say_what_to_do() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("usbtmc7");
        let e = open_usbtmc(missing.to_str().unwrap()).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("usbtmc:") && msg.contains("usbtmc7"), "{msg}");
        assert!(msg.contains("modprobe usbtmc"), "{msg}");
        let plain = dir.path().join("not-a-device");
        std::fs::write(&plain, b"").unwrap();
        let msg = open_usbtmc(plain.to_str().unwrap())
            .unwrap_err()
            .to_string();
        assert!(msg.contains("not a character device"), "{msg}");
        let msg = open_error(
            "usbtmc:/dev/usbtmc0",
            &std::io::Error::from_raw_os_error(13),
        )
        .to_string();
        assert!(msg.contains("udev") && msg.contains("usbtmc*"), "{msg}");
    }

    #[test]
    fn an_unplugged_device_reads_as_a_lost_connection() {
        let e = device_error(std::io::Error::from_raw_os_error(19));
        assert_eq!(e.kind(), std::io::ErrorKind::NotConnected);
        assert!(e.to_string().contains("USB cable"));
        assert!(is_query(b"*OPC?;SYST:ERR?\n") && !is_query(b"OUTP ON\n"));
    }
}
