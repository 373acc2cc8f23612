//! rosserial v2 frame scanning on the Spinal UART (`jsk-wire-protocols.md`, rosserial
//! section): `FF FE len_lo len_hi len_chk topic_lo topic_hi payload[len] msg_chk`.
//!
//! [`next_candidate`] classifies what starts at one position of a receive buffer: bytes
//! outside any frame, a frame candidate that needs more bytes, a good frame, or a rejected
//! candidate with its reason. The caller owns the buffer, the stream offset, the frame timer
//! and the re-scan policy. Pure slice arithmetic: it allocates nothing and never panics.
//!
//! The sending side: [`seal_frame`] writes a frame's header and checksums around a payload
//! already in place, [`client_stamp`] is the rosserial client's ROS time at a tick
//! (`rdm.protocol.rosserial.timesync.ClientClock.now`), and [`imu_frame`] builds the Spinal
//! mirror's 200 Hz `spinal/Imu` frame in one go, byte for byte what the Python codec
//! (`MessageCodec.encode` of the generated flat layout, then `framing.encode_frame`) sends.
//! They decline (`None`) whatever the Python path would pack differently or refuse
//! (non-finite values, float32 overflow, a stamp past `u32`): the caller then runs that path.

/// First byte of every frame.
pub const SYNC: u8 = 0xFF;
/// Second byte: rosserial protocol v2 ("hydro+").
pub const PROTOCOL_VERSION: u8 = 0xFE;
/// Bytes of a frame besides its payload.
pub const FRAME_OVERHEAD: usize = 8;

/// Why a frame candidate was rejected (the Python parser's `BadFrame.reason`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BadReason {
    /// 0xFF not followed by 0xFE.
    Version,
    /// `len_lo + len_hi + len_chk` is not 255 modulo 256.
    LengthChecksum,
    /// The length field is above the receiver's buffer.
    Oversize,
    /// `topic_lo + topic_hi + sum(payload) + msg_chk` is not 255 modulo 256.
    MessageChecksum,
}

impl BadReason {
    /// The reason's name as the Python parser counts it.
    pub fn name(self) -> &'static str {
        match self {
            BadReason::Version => "version",
            BadReason::LengthChecksum => "length_checksum",
            BadReason::Oversize => "oversize",
            BadReason::MessageChecksum => "message_checksum",
        }
    }
}

/// What starts at a buffer position.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// Bytes `pos..stop` are not a frame candidate (no 0xFF among them).
    Skip {
        /// First 0xFF after `pos`, or the buffer end.
        stop: usize,
    },
    /// A candidate starts at `pos` but is not complete yet.
    NeedMore,
    /// A good frame: `topic`, payload at `payload_start..payload_start + len`.
    Good {
        /// Topic id.
        topic: u16,
        /// Buffer index of the first payload byte.
        payload_start: usize,
        /// Payload length.
        len: usize,
    },
    /// A rejected candidate; `used` bytes examined (the reference's `data` length).
    Bad {
        /// Why it was rejected.
        reason: BadReason,
        /// Bytes of the candidate the reason covers.
        used: usize,
    },
}

/// Classify what starts at `buf[pos]` (see the module doc). `pos >= buf.len()` gives
/// `NeedMore`.
pub fn next_candidate(buf: &[u8], pos: usize, max_payload: usize) -> Step {
    let rest = buf.get(pos..).unwrap_or(&[]);
    let Some(&first) = rest.first() else {
        return Step::NeedMore;
    };
    if first != SYNC {
        let stop = rest
            .iter()
            .position(|&b| b == SYNC)
            .map_or(buf.len(), |k| pos + k);
        return Step::Skip { stop };
    }
    let Some(&version) = rest.get(1) else {
        return Step::NeedMore;
    };
    if version != PROTOCOL_VERSION {
        return Step::Bad {
            reason: BadReason::Version,
            used: 2,
        };
    }
    let (Some(&lo), Some(&hi), Some(&len_chk), Some(&t_lo), Some(&t_hi)) = (
        rest.get(2),
        rest.get(3),
        rest.get(4),
        rest.get(5),
        rest.get(6),
    ) else {
        return Step::NeedMore;
    };
    if (u32::from(lo) + u32::from(hi) + u32::from(len_chk)) % 256 != 255 {
        return Step::Bad {
            reason: BadReason::LengthChecksum,
            used: 5,
        };
    }
    let len = usize::from(lo) | (usize::from(hi) << 8);
    if len > max_payload {
        return Step::Bad {
            reason: BadReason::Oversize,
            used: 5,
        };
    }
    let (Some(payload), Some(&msg_chk)) = (rest.get(7..7 + len), rest.get(7 + len)) else {
        return Step::NeedMore;
    };
    let sum = payload.iter().fold(
        u32::from(t_lo) + u32::from(t_hi) + u32::from(msg_chk),
        |acc, &b| acc.wrapping_add(u32::from(b)),
    );
    if sum % 256 == 255 {
        Step::Good {
            topic: u16::from(t_lo) | (u16::from(t_hi) << 8),
            payload_start: pos + 7,
            len,
        }
    } else {
        Step::Bad {
            reason: BadReason::MessageChecksum,
            used: len + FRAME_OVERHEAD,
        }
    }
}

/// Payload bytes of a `spinal/Imu` message: `time stamp` (two `u32`), then `acc`, `gyro`,
/// `mag` (three `float32` each) and `quaternion` (four `float32`), little-endian.
pub const IMU_PAYLOAD_LEN: usize = 60;
/// Bytes of a whole `spinal/Imu` frame.
pub const IMU_FRAME_LEN: usize = IMU_PAYLOAD_LEN + FRAME_OVERHEAD;

/// Writes the header (sync, version, length, length checksum, topic id) and the message
/// checksum of a frame whose payload already fills `frame[7..frame.len() - 1]`, as
/// `framing.encode_frame` computes them. False (nothing written) when `frame` is shorter
/// than [`FRAME_OVERHEAD`] or the payload does not fit the `u16` length field.
pub fn seal_frame(topic: u16, frame: &mut [u8]) -> bool {
    let Some(n) = frame.len().checked_sub(FRAME_OVERHEAD) else {
        return false;
    };
    let Ok(n16) = u16::try_from(n) else {
        return false;
    };
    let [len_lo, len_hi] = n16.to_le_bytes();
    let [t_lo, t_hi] = topic.to_le_bytes();
    let sum = frame
        .get(7..7 + n)
        .unwrap_or(&[])
        .iter()
        .fold(u32::from(t_lo) + u32::from(t_hi), |acc, &b| {
            acc.wrapping_add(u32::from(b))
        });
    let len_chk = 255 - ((u32::from(len_lo) + u32::from(len_hi)) % 256) as u8;
    let msg_chk = 255 - (sum % 256) as u8;
    if let Some(head) = frame.get_mut(..7) {
        head.copy_from_slice(&[SYNC, PROTOCOL_VERSION, len_lo, len_hi, len_chk, t_lo, t_hi]);
    }
    if let Some(last) = frame.last_mut() {
        *last = msg_chk;
    }
    true
}

/// `x` as `struct.pack("<f", x)` stores a Python float (`PyFloat_Pack4`: rounded to the
/// nearest float32); None for a non-finite `x` or one that overflows float32 (the Python
/// path packs infinities and NaN itself and raises on the overflow).
pub fn float32_of(x: f64) -> Option<f32> {
    if !x.is_finite() {
        return None;
    }
    #[allow(clippy::cast_possible_truncation)] // the rounding is the point
    let y = x as f32;
    if y.is_finite() {
        Some(y)
    } else {
        None
    }
}

/// The rosserial client's ROS time `(sec, nsec)` at MCU tick `now_ms`
/// (`ClientClock.now`): unsynchronised (`sync` None) the tick's own uint32 milliseconds;
/// else `sync = (sync_tick, sync_ns)` plus the signed, wrap-safe tick difference, clamped
/// at zero. None when `sec` does not fit the `u32` of a ROS `time`.
pub fn client_stamp(now_ms: i64, sync: Option<(i64, i64)>) -> Option<(u32, u32)> {
    const MASK: i128 = 0xFFFF_FFFF;
    const NS: i128 = 1_000_000_000;
    let ns: i128 = match sync {
        None => (i128::from(now_ms) & MASK) * 1_000_000,
        Some((tick, sync_ns)) => {
            let elapsed = ((i128::from(now_ms) - i128::from(tick) + (1 << 31)) & MASK) - (1 << 31);
            let ns = i128::from(sync_ns) + elapsed * 1_000_000;
            if ns > 0 {
                ns
            } else {
                0
            }
        }
    };
    let sec = u32::try_from(ns / NS).ok()?;
    let nsec = u32::try_from(ns % NS).ok()?;
    Some((sec, nsec))
}

/// The values of one `spinal/Imu` message besides its stamp.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ImuValues {
    /// m/s^2.
    pub acc: [f64; 3],
    /// rad/s.
    pub gyro: [f64; 3],
    /// Magnetometer, about uT.
    pub mag: [f64; 3],
    /// Attitude x, y, z, w.
    pub quaternion: [f64; 4],
}

/// The whole `spinal/Imu` frame on `topic` with `stamp = (sec, nsec)`; None when a value is
/// not finite or overflows float32 (see [`float32_of`]).
pub fn imu_frame(topic: u16, stamp: (u32, u32), values: &ImuValues) -> Option<[u8; IMU_FRAME_LEN]> {
    let mut frame = [0u8; IMU_FRAME_LEN];
    let mut words = frame.get_mut(7..7 + IMU_PAYLOAD_LEN)?.chunks_exact_mut(4);
    for w in [stamp.0, stamp.1] {
        words.next()?.copy_from_slice(&w.to_le_bytes());
    }
    let floats = values
        .acc
        .iter()
        .chain(&values.gyro)
        .chain(&values.mag)
        .chain(&values.quaternion);
    for &x in floats {
        words.next()?.copy_from_slice(&float32_of(x)?.to_le_bytes());
    }
    seal_frame(topic, &mut frame).then_some(frame)
}

/// One `spinal/ServoState` of a `spinal/ServoStates` report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ServoStateValues {
    /// The servo's position in the mirror's servo table.
    pub index: u8,
    /// Present position, raw ticks.
    pub angle: i16,
    /// Temperature.
    pub temp: u8,
    /// Present current ("load").
    pub load: i16,
    /// Hardware error bits.
    pub error: u8,
}

/// Payload bytes of one `spinal/ServoState` (`uint8 index, int16 angle, uint8 temp,
/// int16 load, uint8 error`).
pub const SERVO_STATE_LEN: usize = 7;

/// Bytes of a whole `spinal/ServoStates` frame with `n` servos (`time stamp`, the `uint32`
/// count, the servos).
pub fn servo_states_frame_len(n: usize) -> usize {
    FRAME_OVERHEAD + 12 + SERVO_STATE_LEN * n
}

/// Writes the `spinal/ServoStates` frame of `servos` on `topic` with `stamp = (sec, nsec)`
/// into `frame`, which must be exactly [`servo_states_frame_len`] of the number of servos
/// long: the bytes of the Python codec's `encode` and `framing.encode_frame`. False when
/// the lengths disagree or the payload does not fit the frame's length field (`frame` then
/// holds no frame).
pub fn write_servo_states_frame(
    topic: u16,
    stamp: (u32, u32),
    servos: impl IntoIterator<Item = ServoStateValues>,
    frame: &mut [u8],
) -> bool {
    let Some(body) = frame.len().checked_sub(FRAME_OVERHEAD + 12) else {
        return false;
    };
    if body % SERVO_STATE_LEN != 0 {
        return false;
    }
    let n = body / SERVO_STATE_LEN;
    let Ok(count) = u32::try_from(n) else {
        return false;
    };
    let Some(payload) = frame.get_mut(7..frame.len() - 1) else {
        return false;
    };
    let (head, mut rest) = payload.split_at_mut(12);
    head[..4].copy_from_slice(&stamp.0.to_le_bytes());
    head[4..8].copy_from_slice(&stamp.1.to_le_bytes());
    head[8..].copy_from_slice(&count.to_le_bytes());
    let mut written = 0usize;
    for s in servos {
        if rest.len() < SERVO_STATE_LEN {
            return false; // more servos than the frame holds
        }
        let (item, tail) = rest.split_at_mut(SERVO_STATE_LEN);
        let [a0, a1] = s.angle.to_le_bytes();
        let [l0, l1] = s.load.to_le_bytes();
        item.copy_from_slice(&[s.index, a0, a1, s.temp, l0, l1, s.error]);
        rest = tail;
        written += 1;
    }
    written == n && seal_frame(topic, frame)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(topic: u16, payload: &[u8]) -> Vec<u8> {
        let n = payload.len();
        let (lo, hi) = ((n & 0xFF) as u8, (n >> 8) as u8);
        let mut out = vec![SYNC, PROTOCOL_VERSION, lo, hi, 255 - lo.wrapping_add(hi)];
        out.extend_from_slice(&topic.to_le_bytes());
        out.extend_from_slice(payload);
        let sum: u32 = topic
            .to_le_bytes()
            .iter()
            .chain(payload)
            .map(|&b| u32::from(b))
            .sum();
        out.push(255 - (sum % 256) as u8);
        out
    }

    #[test]
    fn good_frame_and_every_reject_reason() {
        let f = frame(153, &[1, 2, 3, 250]);
        assert_eq!(
            next_candidate(&f, 0, 512),
            Step::Good {
                topic: 153,
                payload_start: 7,
                len: 4
            }
        );
        for cut in 0..f.len() {
            assert_eq!(
                next_candidate(&f[..cut], 0, 512),
                Step::NeedMore,
                "cut {cut}"
            );
        }
        let mut bad = f.clone();
        bad[1] = 0xFF;
        assert_eq!(
            next_candidate(&bad, 0, 512),
            Step::Bad {
                reason: BadReason::Version,
                used: 2
            }
        );
        let mut bad = f.clone();
        bad[4] ^= 1;
        assert_eq!(
            next_candidate(&bad, 0, 512),
            Step::Bad {
                reason: BadReason::LengthChecksum,
                used: 5
            }
        );
        assert_eq!(
            next_candidate(&f, 0, 3),
            Step::Bad {
                reason: BadReason::Oversize,
                used: 5
            }
        );
        let mut bad = f.clone();
        bad[8] ^= 0x10;
        assert_eq!(
            next_candidate(&bad, 0, 512),
            Step::Bad {
                reason: BadReason::MessageChecksum,
                used: 12
            }
        );
    }

    #[test]
    fn skips_to_the_next_sync_and_handles_any_position() {
        let mut s = vec![1, 2, 3];
        s.extend(frame(7, &[]));
        assert_eq!(next_candidate(&s, 0, 512), Step::Skip { stop: 3 });
        assert_eq!(next_candidate(&s, 1, 512), Step::Skip { stop: 3 });
        assert_eq!(next_candidate(&[0, 0], 0, 512), Step::Skip { stop: 2 });
        assert_eq!(next_candidate(&s, 99, 512), Step::NeedMore);
        assert_eq!(
            next_candidate(&s, 3, 512),
            Step::Good {
                topic: 7,
                payload_start: 10,
                len: 0
            }
        );
        let big = frame(100, &[0xAB; 1022]);
        assert!(matches!(
            next_candidate(&big, 0, 1022),
            Step::Good { len: 1022, .. }
        ));
    }

    #[test]
    fn sealed_frames_scan_back() {
        for n in [0usize, 1, 60, 300] {
            let mut f = vec![0u8; n + FRAME_OVERHEAD];
            for (i, b) in f[7..7 + n].iter_mut().enumerate() {
                *b = (i * 37 + n) as u8;
            }
            assert!(seal_frame(0x1234, &mut f));
            assert_eq!(f, frame(0x1234, &f[7..7 + n]));
        }
        assert!(!seal_frame(1, &mut [0u8; 7]));
    }

    #[test]
    fn float32_rounding_and_refusals() {
        assert_eq!(float32_of(0.1), Some(0.1f32));
        assert_eq!(float32_of(-1.5e-40), Some(-1.5e-40f32));
        assert_eq!(float32_of(f64::from(f32::MAX)), Some(f32::MAX));
        assert_eq!(float32_of(1e39), None);
        assert_eq!(float32_of(f64::NAN), None);
        assert_eq!(float32_of(f64::INFINITY), None);
    }

    #[test]
    fn client_stamp_as_the_python_clock() {
        assert_eq!(client_stamp(1500, None), Some((1, 500_000_000)));
        assert_eq!(client_stamp(-1, None), Some((4_294_967, 295_000_000)));
        assert_eq!(client_stamp(10, Some((20, 5_000_000))), Some((0, 0)));
        assert_eq!(
            client_stamp(1_005, Some((1_000, 7_000_000_000))),
            Some((7, 5_000_000))
        );
        // a tick after a wrap counts forward
        assert_eq!(
            client_stamp(3, Some((0xFFFF_FFFE, 0))),
            Some((0, 5_000_000))
        );
        assert_eq!(client_stamp(0, Some((0, 5_000_000_000_000_000_000))), None);
    }

    #[test]
    fn imu_frame_layout() {
        let v = ImuValues {
            acc: [0.0, 0.5, 9.81],
            gyro: [-0.25, 1e-3, 2.0],
            mag: [30.0, 0.0, -40.0],
            quaternion: [0.0, 0.0, 0.0, 1.0],
        };
        let f = imu_frame(153, (12, 34), &v).unwrap();
        let mut payload = Vec::new();
        payload.extend_from_slice(&12u32.to_le_bytes());
        payload.extend_from_slice(&34u32.to_le_bytes());
        for x in v
            .acc
            .iter()
            .chain(&v.gyro)
            .chain(&v.mag)
            .chain(&v.quaternion)
        {
            payload.extend_from_slice(&(*x as f32).to_le_bytes());
        }
        assert_eq!(f.to_vec(), frame(153, &payload));
        let mut bad = v;
        bad.quaternion[3] = f64::NAN;
        assert_eq!(imu_frame(153, (0, 0), &bad), None);
    }

    #[test]
    fn servo_states_frame_layout() {
        let servos = [
            ServoStateValues {
                index: 0,
                angle: -2,
                temp: 40,
                load: 300,
                error: 0,
            },
            ServoStateValues {
                index: 3,
                angle: 2048,
                temp: 255,
                load: -32768,
                error: 8,
            },
        ];
        let mut f = vec![0u8; servo_states_frame_len(2)];
        assert!(write_servo_states_frame(160, (7, 9), servos, &mut f));
        let mut payload = vec![7, 0, 0, 0, 9, 0, 0, 0, 2, 0, 0, 0];
        payload.extend_from_slice(&[0, 0xFE, 0xFF, 40, 0x2C, 0x01, 0]);
        payload.extend_from_slice(&[3, 0x00, 0x08, 255, 0x00, 0x80, 8]);
        assert_eq!(f, frame(160, &payload));
        // too few or too many servos for the buffer
        assert!(!write_servo_states_frame(
            160,
            (7, 9),
            servos,
            &mut vec![0u8; servo_states_frame_len(3)]
        ));
        assert!(!write_servo_states_frame(
            160,
            (7, 9),
            servos,
            &mut vec![0u8; servo_states_frame_len(1)]
        ));
        assert!(!write_servo_states_frame(
            160,
            (7, 9),
            servos,
            &mut [0u8; 19]
        ));
        let mut empty = vec![0u8; servo_states_frame_len(0)];
        assert!(write_servo_states_frame(160, (1, 2), [], &mut empty));
        assert_eq!(empty, frame(160, &[1, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0]));
    }
}
