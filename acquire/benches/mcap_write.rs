//! MCAP session write throughput with zstd compression, against the baseline of the same messages
//! written by a bare `mcap::Writer` without compression (same run).
//!
//! Run: `cargo bench -p acquire --bench mcap_write`.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::time::Duration;

use acquire::record::BlockRecord;
use acquire::session::{Session, SessionOptions};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

fn blocks(n: usize) -> Vec<BlockRecord> {
    (0..n)
        .map(|k| {
            let volts: Vec<Vec<f32>> = (0..8)
                .map(|c| {
                    (0..64)
                        .map(|i| {
                            (((k * 64 + i) as f32) * 0.01 * (c + 1) as f32).sin() * 0.5
                                + 1e-4 * ((i * 7 + c) % 13) as f32
                        })
                        .collect()
                })
                .collect();
            BlockRecord {
                seq: k as u64,
                first_sample: (k * 64) as u64,
                sample_rate_hz: Some(5120.0),
                volts,
            }
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let msgs = blocks(500);
    let encoded: Vec<Vec<u8>> = msgs
        .iter()
        .map(|m| serde_json::to_vec(m).unwrap())
        .collect();
    let bytes: usize = encoded.iter().map(|e| e.len()).sum();
    let dir = tempfile::tempdir().unwrap();
    let mut g = c.benchmark_group("mcap_write");
    g.throughput(Throughput::Bytes(bytes as u64));
    g.sample_size(10);
    let mut i = 0;
    g.bench_function("baseline_uncompressed_writer", |b| {
        b.iter(|| {
            i += 1;
            let f = std::fs::File::create(dir.path().join(format!("raw{i}.mcap"))).unwrap();
            let mut w = mcap::WriteOptions::new()
                .compression(None)
                .create(std::io::BufWriter::new(f))
                .unwrap();
            let ch = w
                .add_channel(0, "/daq/block", "json", &BTreeMap::new())
                .unwrap();
            for (s, e) in encoded.iter().enumerate() {
                w.write_to_known_channel(
                    &mcap::records::MessageHeader {
                        channel_id: ch,
                        sequence: s as u32,
                        log_time: s as u64,
                        publish_time: s as u64,
                    },
                    e,
                )
                .unwrap();
            }
            w.finish().unwrap();
        })
    });
    g.bench_function("session_zstd_with_json_encoding", |b| {
        b.iter(|| {
            i += 1;
            let s = Session::create(
                &dir.path().join(format!("s{i}.mcap")),
                SessionOptions {
                    flush_interval: Duration::from_millis(500),
                    ..Default::default()
                },
            )
            .unwrap();
            let h = s.handle();
            for m in &msgs {
                h.record(m).unwrap();
            }
            s.finish().unwrap();
        })
    });
    g.finish();
    let sizes: Vec<u64> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with('s'))
        .map(|e| e.metadata().unwrap().len())
        .collect();
    if let Some(s) = sizes.first() {
        println!(
            "session file {} bytes for {} bytes of JSON: compression ratio {:.2}",
            s,
            bytes,
            bytes as f64 / *s as f64
        );
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
