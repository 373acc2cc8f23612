//! Proves that scanning a rosserial receive buffer allocates nothing: a counting global
//! allocator wraps the system allocator while `next_candidate` walks a stream of good frames,
//! line noise and every kind of rejected candidate, as the Python binding's loop does.

use std::alloc::System;

use rdm_core::firmware::rosserial_frame::{
    client_stamp, imu_frame, next_candidate, seal_frame, servo_states_frame_len,
    write_servo_states_frame, ImuValues, ServoStateValues, Step, IMU_FRAME_LEN,
};
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
    // the sending side: the 200 Hz Imu frame (stamp, packing, checksums), a sealed frame
    // and the 50 Hz ServoStates frame
    let mut sealed = [0u8; 64];
    let mut servo_buf = [0u8; 128];
    let (mut imu_sum, mut declined) = (0u32, 0u32);
    for k in 0..2000i64 {
        let sync = (k % 3 != 0).then_some((k / 2, 5_000_000_000 + k));
        let x = k as f64 * 1e-3;
        let values = ImuValues {
            acc: [x, -x, 9.8],
            gyro: [0.1 * x, 0.0, -0.2],
            mag: [30.0, 0.0, if k % 500 == 7 { f64::NAN } else { -40.0 }],
            quaternion: [0.0, 0.0, x.sin(), x.cos()],
        };
        match client_stamp(k, sync).and_then(|stamp| imu_frame(150, stamp, &values)) {
            Some(f) => imu_sum = imu_sum.wrapping_add(u32::from(f[IMU_FRAME_LEN - 1])),
            None => declined += 1,
        }
        sealed[7] = k as u8;
        assert!(seal_frame(7, &mut sealed));
        let n = (k % 9) as usize;
        let servos = (0..n).map(|i| ServoStateValues {
            index: i as u8,
            angle: (k as i16).wrapping_mul(7),
            temp: 40,
            load: -(i as i16),
            error: 0,
        });
        let frame = &mut servo_buf[..servo_states_frame_len(n)];
        assert!(write_servo_states_frame(160, (k as u32, 0), servos, frame));
    }
    let stats = region.change();
    assert_eq!(
        stats.allocations + stats.reallocations,
        0,
        "scan allocated: {stats:?}"
    );
    assert_eq!(declined, 4, "NaN samples declined");
    println!("rosserial_frame_alloc: imu frames checksum sum {imu_sum}");
    assert!(good >= 2000, "good frames found: {good}");
    assert!(bad > 500 && skipped > 200, "rejects {bad}, skips {skipped}");
    println!("rosserial_frame_alloc: {good} frames, {bad} rejects, {skipped} skips, 0 allocations");
}
