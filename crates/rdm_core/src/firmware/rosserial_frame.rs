//! rosserial v2 frame scanning on the Spinal UART (`jsk-wire-protocols.md`, rosserial
//! section): `FF FE len_lo len_hi len_chk topic_lo topic_hi payload[len] msg_chk`.
//!
//! [`next_candidate`] classifies what starts at one position of a receive buffer exactly as
//! the Python reference parser (`rdm.protocol.rosserial.framing.PlainFrameParser`) does,
//! step by step: bytes outside any frame, a frame candidate that needs more bytes, a good
//! frame, or a rejected candidate with its reason. The caller owns the buffer, the stream
//! offset, the frame timer and the re-scan policy. Pure slice arithmetic: it allocates
//! nothing and never panics.

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
}
