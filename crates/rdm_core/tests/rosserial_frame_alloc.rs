//! Proves that scanning a rosserial receive buffer allocates nothing: a counting global
//! allocator wraps the system allocator while `next_candidate` walks a stream of good frames,
//! line noise and every kind of rejected candidate, as the Python binding's loop does.

use std::alloc::System;

use rdm_core::firmware::rosserial_frame::{next_candidate, Step};
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

fn frame(topic: u16, payload: &[u8], out: &mut Vec<u8>) {
    let n = payload.len();
    let (lo, hi) = ((n & 0xFF) as u8, (n >> 8) as u8);
    out.extend_from_slice(&[0xFF, 0xFE, lo, hi, 255 - lo.wrapping_add(hi)]);
    out.extend_from_slice(&topic.to_le_bytes());
    out.extend_from_slice(payload);
    let sum: u32 = topic
        .to_le_bytes()
        .iter()
        .chain(payload)
        .map(|&b| u32::from(b))
        .sum();
    out.push(255 - (sum % 256) as u8);
}

fn main() {
    let mut stream = Vec::new();
    for k in 0..2000u32 {
        let payload: Vec<u8> = (0..(k % 90)).map(|i| (i * 7 + k) as u8).collect();
        frame(100 + (k % 60) as u16, &payload, &mut stream);
        match k % 7 {
            0 => stream.extend_from_slice(&[1, 2, 3]),    // noise
            1 => stream.extend_from_slice(&[0xFF, 0xFF]), // version
            2 => stream.extend_from_slice(&[0xFF, 0xFE, 0, 4, 0xFB]), // oversize (1024)
            3 => stream.extend_from_slice(&[0xFF, 0xFE, 1, 0, 0]), // length checksum
            _ => {}
        }
    }
    let region = Region::new(GLOBAL);
    let (mut pos, mut good, mut bad, mut skipped) = (0usize, 0u32, 0u32, 0u32);
    while pos < stream.len() {
        match next_candidate(&stream, pos, 512) {
            Step::Skip { stop } => {
                skipped += 1;
                pos = stop;
            }
            Step::NeedMore => break,
            Step::Good {
                payload_start, len, ..
            } => {
                good += 1;
                pos = payload_start + len + 1;
            }
            Step::Bad { .. } => {
                bad += 1;
                pos += 1; // re-scan after the 0xFF, as the parser's default
            }
        }
    }
    let stats = region.change();
    assert_eq!(
        stats.allocations + stats.reallocations,
        0,
        "scan allocated: {stats:?}"
    );
    assert!(good >= 2000, "good frames found: {good}");
    assert!(bad > 500 && skipped > 200, "rejects {bad}, skips {skipped}");
    println!("rosserial_frame_alloc: {good} frames, {bad} rejects, {skipped} skips, 0 allocations");
}
