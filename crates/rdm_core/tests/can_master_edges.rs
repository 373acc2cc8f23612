//! Bad input to the CAN master: extreme times, non-finite duties, oversize frames and a full
//! board-config queue give typed errors or defined behaviour, never a panic.

use rdm_core::firmware::can_master::{CanMaster, MasterError, MasterState, BOARD_QUEUE};
use rdm_core::firmware::neuron_frame::enum_response;
use rdm_core::firmware::neuron_tx::RxFrame;

#[test]
fn extreme_times_and_bad_commands() {
    let mut m = CanMaster::new(0, 0);
    let _ = m.tick_ms(0, &[]);
    let heard = [
        RxFrame::from_sent(&enum_response(1)),
        RxFrame::new(0x701, 0, &[0; 12]),
    ];
    let _ = m.tick_ms(1, &heard);
    assert_eq!(m.rx_count, 2);
    assert_eq!(
        m.rx_errors.get(4),
        1,
        "a 12-byte classic frame is a DLC error"
    );
    // Jump to the end of time: the last 10 ms replay (enumeration ends, the first config
    // wait of 200 ms never does); a repeated and an older time only receive.
    let _ = m.tick_ms(i64::MAX, &[]);
    let _ = m.tick_ms(i64::MAX, &[]);
    let _ = m.tick_ms(i64::MIN, &[]);
    assert_eq!(m.state, MasterState::Configuring);
    assert_eq!(m.neurons().len(), 1);
    let mut m = CanMaster::new(0, 0);
    for t in 0..700 {
        let _ = m.tick_ms(t, if t == 1 { &heard[..1] } else { &[] });
    }
    assert_eq!(m.state, MasterState::Running);
    assert_eq!(m.set_motor_duties(&[f64::NAN]), Err(MasterError::Duty(0)));
    assert_eq!(
        m.set_motor_duties(&[0.5, 0.5]),
        Err(MasterError::DutyCount(2))
    );
    assert_eq!(m.set_servo_target(1, 0, 5), Err(MasterError::NoServo(1, 0)));
    assert_eq!(
        m.configure_board(0x721, &[0; 9], None),
        Err(MasterError::BadFrame)
    );
    for _ in 0..BOARD_QUEUE {
        assert_eq!(m.configure_board(0x721, &[7], Some(1)), Ok(()));
    }
    assert_eq!(
        m.configure_board(0x721, &[7], Some(1)),
        Err(MasterError::BoardQueueFull)
    );
    let mut fresh = CanMaster::new(i64::MAX, i64::MAX);
    let _ = fresh.tick_ms(i64::MAX, &[]);
    assert_eq!(fresh.state, MasterState::Booting); // start + delay lies past the end of time
}
