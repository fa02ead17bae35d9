//! A scripted instrument for the driver's tests, over a memory transport: it answers each
//! expected command with its lines and falls silent on an unexpected one.

use crate::transport::{MemoryTransport, Transport};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::task::JoinHandle;

/// Spawns the instrument of `script`: `frame` turns the bytes it receives into commands (`C`);
/// `answer` gives the lines (with their line ends) an exchange (`E`) answers to a command, or
/// `None` when the command is not the one the exchange expects — the instrument then falls
/// silent. The task returns every command received.
pub(super) fn instrument<C, E>(
    script: Vec<E>,
    mut frame: impl FnMut(&[u8], &mut Vec<C>) + Send + 'static,
    answer: fn(&E, &C) -> Option<Vec<String>>,
) -> (Box<dyn Transport>, JoinHandle<Vec<C>>)
where
    C: Clone + Send + 'static,
    E: Send + 'static,
{
    let (host, mut dev) = MemoryTransport::pair("gen", "gen-dev", 1 << 16);
    let task = tokio::spawn(async move {
        let mut got = Vec::new();
        let mut buf = vec![0u8; 4096];
        let mut next = 0usize;
        let mut silent = false;
        loop {
            let n = match dev.read(&mut buf).await {
                Ok(0) | Err(_) => return got,
                Ok(n) => n,
            };
            let mut received = Vec::new();
            frame(&buf[..n], &mut received);
            for c in received {
                got.push(c.clone());
                if silent {
                    continue;
                }
                match script.get(next).and_then(|e| answer(e, &c)) {
                    Some(lines) => {
                        next += 1;
                        for l in lines {
                            let _ = dev.write_all(l.as_bytes()).await;
                        }
                    }
                    None => silent = true,
                }
            }
        }
    });
    (Box::new(host), task)
}
