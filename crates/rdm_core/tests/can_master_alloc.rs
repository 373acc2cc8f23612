//! Proves that a CAN-master tick allocates nothing after setup: a counting global allocator
//! wraps the system allocator while the master boots (enumeration, config replies), runs
//! the schedule with servo states / IMU / bad frames, takes commands, board configs and a
//! reboot re-request, replays a late tick and logs a disconnect.

use std::alloc::System;

use rdm_core::firmware::can_master::{CanMaster, MasterState};
use rdm_core::firmware::neuron_frame::{
    enum_response, imu_frame, initial_config_0, initial_config_2, servo_state,
};
use rdm_core::firmware::neuron_tx::{RxFrame, FLAG_EXTENDED};
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// The Neuron frames heard at millisecond `t`.
fn frames(t: i64, out: &mut [RxFrame; 8]) -> usize {
    let mut n = 0;
    let mut put = |f: RxFrame| {
        if let Some(slot) = out.get_mut(n) {
            *slot = f;
            n += 1;
        }
    };
    let sent = |f| RxFrame::from_sent(&f);
    if (1..200).contains(&t) {
        put(sent(enum_response(1 + (t % 3) as u8)));
    }
    if (200..1200).contains(&t) && t % 50 == 0 {
        let slave = 1 + ((t / 50) % 3) as u8;
        put(sent(initial_config_0(slave, 2, slave == 1, false, 0)));
        put(sent(initial_config_2(slave, 0, 100, 1, 2, 1)));
        put(sent(initial_config_2(slave, 1, -100, 1, 2, 0)));
    }
    let silent = (3000..3300).contains(&t);
    if t >= 1200 && !silent {
        let slave = 1 + (t % 3) as u8;
        put(sent(servo_state(
            slave,
            (t % 2) as u8,
            42,
            30,
            4 * (t % 7 == 0) as u8,
            3,
            0,
        )));
        put(sent(imu_frame(1, (t % 3) as u8, [1, -2, 3])));
        if t % 11 == 0 {
            put(RxFrame::new(0x211, 0, &[0; 3])); // wrong DLC
            put(RxFrame::new(0x1234, FLAG_EXTENDED, &[1]));
            put(sent(servo_state(9, 0, 1, 1, 0, 0, 0))); // unknown slave
        }
    }
    n
}

// Runs as a plain `main` (harness = false, like the other *_alloc tests): the allocation
// counter is process-global, and libtest's own threads allocated while a tick was being
// counted (a CI run saw 4 such allocations).
fn main() {
    master_ticks_allocate_nothing();
    master_bank_and_wire_allocate_nothing();
    println!("can_master_alloc: ok");
}

fn master_ticks_allocate_nothing() {
    let mut m = CanMaster::new(0, 0);
    let mut buf = [RxFrame::default(); 8];
    let mut sent_total = 0usize;
    let region = Region::new(GLOBAL);
    let mut t = 0i64;
    while t < 9000 {
        let n = frames(t, &mut buf);
        if m.state == MasterState::Running {
            let _ = m.set_motor_duties(&[0.6, 0.7, 0.8]);
            let _ = m.set_servo_target(2, 0, (t % 1000) as i32);
            let _ = m.set_servo_torque(1, 1, t % 2 == 0);
            let _ = m.set_servo_current(3, 0, 5);
            if t == 4000 {
                let _ = m.configure_board(0x722, &[7], Some(2));
            }
            m.clear_events();
        }
        sent_total += m.tick_ms(t, buf.get(..n).unwrap_or(&[])).len();
        t += if t == 6000 { 40 } else { 1 };
    }
    let stats = region.change();
    assert_eq!(
        (stats.allocations, stats.reallocations),
        (0, 0),
        "master ticks allocated"
    );
    assert_eq!(m.state, MasterState::Running);
    assert_eq!(m.motor_number, 3);
    assert!(sent_total > 7000, "the schedule ran: {sent_total} frames");
    assert!(m.rx_error_total() > 100, "bad frames counted");
}

/// Master and a Neuron bank on a `CanWire`, with the capture log drained into a buffer
/// reserved at setup: the whole bus allocates nothing per tick.
fn master_bank_and_wire_allocate_nothing() {
    use rdm_core::firmware::can_wire::{CanWire, Sender};
    use rdm_core::firmware::neuron_bank::NeuronBank;
    use rdm_core::firmware::neuron_board::BoardSettings;
    use rdm_core::firmware::neuron_servo::ServoConfig;

    let settings: Vec<BoardSettings> = (1..=4u8)
        .map(|s| {
            let mut b = BoardSettings::new(s);
            b.servo_count = 2;
            b.servos = [ServoConfig::default(); 4];
            b.imu = s == 1;
            b
        })
        .collect();
    let mut bank = NeuronBank::new(&settings, 1024).expect("valid settings");
    let mut master = CanMaster::new(0, 0);
    let mut wire = CanWire::new(1024, 4096, true);
    let (mut rx_bank, mut rx_master) = (Vec::with_capacity(1024), Vec::with_capacity(1024));
    let mut text = String::with_capacity(4096 * 64);
    let region = Region::new(GLOBAL);
    let mut lines = 0usize;
    for t in 0..6000i64 {
        let stamp = t as f64 * 1e-3;
        wire.take_for_neurons(&mut rx_bank);
        if let Ok(out) = bank.tick(stamp, &rx_bank) {
            for e in out {
                wire.send(Sender::Neurons, stamp, e.frame);
            }
        }
        wire.take_for_master(&mut rx_master);
        if master.state == MasterState::Running {
            let _ = master.set_motor_duties(&[0.6, 0.7, 0.8, 0.9]);
            master.clear_events();
        }
        for f in master.tick_ms(t, &rx_master) {
            wire.send(Sender::Master, stamp, f.frame);
        }
        if wire.log_len() > 1000 {
            text.clear();
            wire.drain_log("rdm-sim", &mut text);
            lines += text.matches('\n').count();
        }
    }
    let stats = region.change();
    assert_eq!(
        (stats.allocations, stats.reallocations),
        (0, 0),
        "bus ticks allocated"
    );
    assert_eq!(master.state, MasterState::Running);
    assert_eq!(master.motor_number, 4);
    assert!(lines > 5000, "{lines} frames logged");
    assert_eq!((wire.queue_dropped, wire.log_dropped), (0, 0));
}
