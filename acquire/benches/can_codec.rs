//! Host-side cost of the DAQ-over-CAN codec per frame (no socket): segmenting a block into frames
//! and reassembling + decoding it, for classic and FD frames. The baseline in the same run is a
//! plain `memcpy` of the same bytes, so the ratio says what the protocol costs over moving bytes.
//! The socket path is measured by `throughput_benchmark` in acquire/tests/vcan.rs (inside the VM).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;

use acquire::can::codec::{Message, Reassembler, SampleFormat, Segmenter, WireBlock};
use acquire::can::{CanId, FrameKind};

fn block() -> WireBlock {
    let counts = (0..64 * 4)
        .map(|i| (i * 7919 % 16_000_000) - 8_000_000)
        .collect();
    WireBlock {
        seq: 1,
        format: SampleFormat::I24,
        channel_count: 4,
        counts,
    }
}

fn codec(c: &mut Criterion) {
    let mut body = Vec::new();
    Message::Block(block()).encode(&mut body).expect("encode");
    for kind in [FrameKind::Classic, FrameKind::Fd] {
        let mut seg = Segmenter::new(CanId::Standard(0x102), kind);
        let mut frames = Vec::new();
        seg.segment(&body, &mut frames).expect("segment");
        let n = frames.len() as u64;
        let mut g = c.benchmark_group(format!("can_codec_{kind:?}"));
        g.throughput(Throughput::Elements(n));
        g.bench_function("baseline_memcpy", |b| {
            let mut out = vec![0u8; body.len()];
            b.iter(|| out.copy_from_slice(black_box(&body)))
        });
        g.bench_function("encode_and_segment", |b| {
            let blk = Message::Block(block());
            let mut buf = Vec::new();
            let mut out = Vec::with_capacity(n as usize);
            b.iter(|| {
                out.clear();
                blk.encode(&mut buf).expect("encode");
                seg.segment(black_box(&buf), &mut out).expect("segment");
            })
        });
        g.bench_function("segment_reassemble_decode", |b| {
            let mut r = Reassembler::new();
            // Counters must continue from frame to frame: re-segment each round.
            let mut s = Segmenter::new(CanId::Standard(0x102), kind);
            let mut out = Vec::with_capacity(n as usize);
            b.iter(|| {
                out.clear();
                s.segment(&body, &mut out).expect("segment");
                for f in &out {
                    if let Some(m) = r.push(f.data()).message {
                        black_box(Message::decode(m).expect("decode"));
                    }
                }
            })
        });
        g.finish();
    }
}

criterion_group!(benches, codec);
criterion_main!(benches);
