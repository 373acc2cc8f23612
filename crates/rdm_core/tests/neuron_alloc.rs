//! Proves that a Neuron bank tick allocates nothing after setup: a counting global allocator
//! wraps the system allocator while the bank handles a flight-like frame stream plus bad
//! frames, configuration bursts, reboots and the watchdog; the plant bridge's coupling
//! (`BankBridge` snapshot / push / couple) runs beside it every millisecond.

use std::alloc::System;

use rdm_core::firmware::bank_bridge::{BankBridge, ServoEntry};
use rdm_core::firmware::neuron_bank::NeuronBank;
use rdm_core::firmware::neuron_board::BoardSettings;
use rdm_core::firmware::neuron_frame::RxError;
use rdm_core::firmware::neuron_servo::ServoConfig;
use rdm_core::firmware::neuron_tx::{RxFrame, FLAG_EXTENDED};
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

fn bank() -> NeuronBank {
    let settings: Vec<BoardSettings> = (1..=4u8)
        .map(|s| {
            let mut b = BoardSettings::new(s);
            b.servo_count = (s as usize) % 3 + 1;
            b.servos = [ServoConfig::default(); 4];
            b.imu = s == 1;
            b.plant_driven = s % 2 == 0;
            b
        })
        .collect();
    NeuronBank::new(&settings, 1024).expect("valid settings")
}

fn bank_joints(bank: &NeuronBank) -> usize {
    bank.boards().iter().map(|b| b.servos().len()).sum()
}

/// The frames Spinal would send at millisecond `k` (plus junk and configuration).
fn frames(k: usize, out: &mut [RxFrame; 8]) -> usize {
    let mut n = 0;
    let mut put = |f: RxFrame| {
        if let Some(slot) = out.get_mut(n) {
            *slot = f;
            n += 1;
        }
    };
    if k.is_multiple_of(2) {
        let v = (k % 1000) as u64;
        let word = v | v << 10 | v << 20 | v << 32 | v << 42 | v << 52;
        put(RxFrame::new(0x00F, 0, &word.to_le_bytes()));
    } else {
        for s in 1..=4u32 {
            let count = (s as usize) % 3 + 1;
            let words = [0x8000u16 | (2000 + (k % 50) as u16); 4];
            let mut data = [0u8; 8];
            for (i, w) in words.iter().take(count).enumerate() {
                data[2 * i..2 * i + 2].copy_from_slice(&w.to_le_bytes());
            }
            put(RxFrame::new(0x200 | s, 0, &data[..2 * count]));
        }
    }
    match k % 97 {
        0 => put(RxFrame::new(0x70F, 0, &[])), // enum request
        1 => put(RxFrame::new(0x711, 0, &[])), // config request
        2 => put(RxFrame::new(0x721, 0, &[3, 0, 1, 0, 2, 0, 3, 0])), // PID gains
        3 => put(RxFrame::new(0x212, 0, &[0xFF, 0xFF, 0x01])), // wrong DLC
        4 => put(RxFrame::new(0x1ABC_DEF0, FLAG_EXTENDED, &[1])),
        5 => put(RxFrame::new(0x713, 0, &[])), // config request to board 3
        6 => put(RxFrame::new(0x213, 0, &[0x00, 0x80, 0x00, 0x80])), // currents, torque on
        7 => put(RxFrame::new(0x724, 0, &[7])), // reboot board 4
        _ => {}
    }
    n
}

/// Every servo of `bank()` on its own joint (qpos address 7 + joint), a rotor per board.
fn bridge(bank: &NeuronBank) -> BankBridge {
    let mut servos = Vec::new();
    for (k, b) in bank.boards().iter().enumerate() {
        for i in 0..b.servos().len() {
            let joint = servos.len();
            servos.push(ServoEntry {
                board: k,
                servo: i,
                joint,
            });
        }
    }
    let n = servos.len();
    let qadr: Vec<usize> = (7..7 + n).collect();
    let scale = vec![4096.0 / std::f64::consts::TAU; n];
    let rotors: Vec<(usize, usize)> = (0..4).map(|r| (r, r)).collect();
    BankBridge::new(bank, 2048, &qadr, &scale, &servos, &rotors, &[0, 1, 2, 3])
        .expect("valid bridge")
}

fn main() {
    let mut bank = bank();
    let mut coupling = bridge(&bank);
    let mut qpos = [0.0f64; 32];
    let mut targets = [0.0f64; 12];
    let mut duties = [0.5f64; 4];
    let mut coupled = 0usize;
    let mut buf = [RxFrame::default(); 8];
    // Warm up outside the region.
    for k in 0..200 {
        let n = frames(k, &mut buf);
        bank.tick(k as f64 * 0.001, &buf[..n]).expect("finite time");
    }
    let region = Region::new(GLOBAL);
    let mut sent = 0usize;
    for k in 200..20_000 {
        // A 150 ms silence trips the watchdog once.
        let n = if (5000..5150).contains(&k) {
            0
        } else {
            frames(k, &mut buf)
        };
        if let Some(q) = qpos.get_mut(7 + k % 5) {
            *q = (k % 13) as f64 * 0.01;
        }
        coupling.snapshot(&qpos).expect("qpos covers qadr");
        coupling.push_positions(&mut bank).expect("finite joints");
        let c = coupling
            .couple(&bank, &mut targets[..bank_joints(&bank)], &mut duties)
            .expect("sized outputs");
        coupled += usize::from(c.targets || c.duties);
        let _ = bank.set_position(1, 0, 2048.0 + (k % 7) as f64);
        let _ = bank.set_imu_raw(0, 0, [k as i16, 0, 1]);
        sent += bank
            .tick(k as f64 * 0.001, &buf[..n])
            .expect("finite time")
            .len();
    }
    let stats = region.change();
    assert_eq!(
        (
            stats.allocations,
            stats.reallocations,
            stats.bytes_allocated
        ),
        (0, 0, 0),
        "NeuronBank::tick / BankBridge allocated: {stats:?}"
    );
    assert!(
        coupled > 100,
        "goals and duties reach the bridge, {coupled} changes"
    );
    assert!(
        sent > 10_000,
        "the stream should make the boards answer, sent {sent}"
    );
    let b = bank.board(3).expect("board 3");
    assert!(b.counters.reboots > 0, "reboot path exercised");
    let dlc = bank.board(1).expect("board 1").counters.rx_errors[RxError::Dlc.index()];
    assert!(dlc > 0, "the wrong-DLC frame to slave 2 is counted");
    println!("neuron_alloc: ok ({sent} frames sent, no allocation)");
}
