//! DAQ stream over a pseudo-terminal: sustained bytes/s with zero loss, and the CPU the host
//! side uses. Baseline (same run): copying the same bytes through a pty without decoding.
//!
//! Run: `cargo bench -p acquire --bench pty_stream`. Before criterion, a paced run at the
//! 3 Mbaud line rate (300 kB/s) prints the receiving thread's CPU share of one core.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use acquire::daq::frame::{FrameDecoder, Message};
use acquire::transport::{open_serial, pty_pair, SerialSettings};
use criterion::{criterion_group, Criterion, Throughput};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

const CHANNELS: usize = 8;
const SPB: usize = 64;

fn frames(n: usize) -> Vec<u8> {
    let (mut a, mut b, mut out) = (Vec::new(), Vec::new(), Vec::new());
    for seq in 0..n {
        let counts: Vec<i32> = (0..CHANNELS * SPB)
            .map(|i| ((i * 7919 + seq * 31) % 16_000_000) as i32 - 8_000_000)
            .collect();
        Message::Data(counts).encode(seq as u32, &mut a, &mut b, &mut out);
    }
    out
}

/// CPU ticks (user + system) of the calling thread, from /proc.
fn thread_cpu() -> Duration {
    let s = std::fs::read_to_string("/proc/thread-self/stat").unwrap_or_default();
    let rest = s.rsplit(')').next().unwrap_or("");
    // After the command name: state ppid pgrp session tty_nr tpgid flags minflt cminflt majflt
    // cmajflt utime stime … (clock ticks, 100 per second on Linux).
    let f: Vec<&str> = rest.split_whitespace().collect();
    let num = |i: usize| f.get(i).and_then(|x| x.parse::<u64>().ok()).unwrap_or(0);
    let ticks = num(11) + num(12);
    Duration::from_millis(ticks * 10)
}

/// Sends `data` through a pty (optionally paced to `bytes_per_s`) and decodes it on the other
/// side in a thread of its own. Returns (blocks decoded, faults, receiver CPU, wall time).
fn transfer(data: &[u8], decode: bool, bytes_per_s: Option<f64>) -> (u64, u64, Duration, Duration) {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let pty = rt.block_on(async { pty_pair("daq").unwrap() });
    let path = pty.path.clone();
    let expect = data.len();
    let (opened_tx, opened_rx) = std::sync::mpsc::channel::<()>();
    let recv = std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async move {
            let mut io = open_serial(&path, &SerialSettings { baud: 3_000_000 }).unwrap();
            let _ = opened_tx.send(());
            let mut dec = FrameDecoder::new();
            let mut buf = vec![0u8; 65536];
            let (mut got, mut blocks, mut faults, mut next) = (0usize, 0u64, 0u64, 0u32);
            let cpu0 = thread_cpu();
            let t0 = Instant::now();
            while got < expect {
                let n = match tokio::time::timeout(Duration::from_secs(5), io.read(&mut buf)).await
                {
                    Ok(Ok(n)) if n > 0 => n,
                    _ => break,
                };
                got += n;
                if decode {
                    dec.feed(&buf[..n], |f| match f {
                        Ok(f) if f.seq == next => {
                            blocks += 1;
                            next += 1;
                        }
                        _ => faults += 1,
                    });
                }
            }
            (blocks, faults, thread_cpu() - cpu0, t0.elapsed())
        })
    });
    rt.block_on(async {
        opened_rx
            .recv_timeout(Duration::from_secs(5))
            .expect("receiver opened the port");
        let mut dev = pty.device;
        let chunk = 4096;
        let t0 = Instant::now();
        for (i, c) in data.chunks(chunk).enumerate() {
            if let Some(r) = bytes_per_s {
                let due = t0 + Duration::from_secs_f64((i * chunk) as f64 / r);
                tokio::time::sleep_until(due.into()).await;
            }
            dev.write_all(c).await.unwrap();
        }
        dev.flush().await.unwrap();
        let r = recv.join().unwrap();
        drop(dev);
        r
    })
}

fn paced_report() {
    let n = 300;
    let data = frames(n);
    let rate = 300_000.0; // 3 Mbaud, 10 bits per byte
    let (blocks, faults, cpu, wall) = transfer(&data, true, Some(rate));
    println!(
        "paced 3 Mbaud: {} bytes in {:.2} s = {:.0} B/s, {blocks}/{n} blocks, {faults} faults, receiver CPU {:.1} % of a core",
        data.len(),
        wall.as_secs_f64(),
        data.len() as f64 / wall.as_secs_f64(),
        100.0 * cpu.as_secs_f64() / wall.as_secs_f64()
    );
    let (blocks, faults, cpu, wall) = transfer(&frames(3000), true, None);
    println!(
        "unpaced: {:.1} MB/s with {blocks}/3000 blocks, {faults} faults, receiver CPU {:.0} % of a core",
        frames(3000).len() as f64 / wall.as_secs_f64() / 1e6,
        100.0 * cpu.as_secs_f64() / wall.as_secs_f64()
    );
}

fn bench(c: &mut Criterion) {
    let data = frames(200);
    let mut g = c.benchmark_group("pty_stream");
    g.throughput(Throughput::Bytes(data.len() as u64));
    g.sample_size(10);
    g.bench_function("baseline_raw_copy", |b| {
        b.iter(|| transfer(&data, false, None))
    });
    g.bench_function("daq_frames_decoded", |b| {
        b.iter(|| {
            let (blocks, faults, _, _) = transfer(&data, true, None);
            assert_eq!((blocks, faults), (200, 0), "loss on the pty");
        })
    });
    g.finish();
}

criterion_group!(benches, bench);

fn main() {
    paced_report();
    benches();
    Criterion::default().configure_from_args().final_summary();
}
