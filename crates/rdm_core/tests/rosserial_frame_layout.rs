//! The rosserial v2 frame scan and sealer against frames written out here from the protocol's
//! layout (`FF FE len_lo len_hi len_chk topic_lo topic_hi payload msg_chk`, each checksum
//! `255 - sum mod 256`), with topic ids and lengths whose high bytes are not zero: a scan that
//! reads the high byte wrong, or leaves it out of a checksum, fails here.

use rdm_core::firmware::rosserial_frame::{next_candidate, seal_frame, BadReason, Step};

fn frame(topic: u16, payload: &[u8]) -> Vec<u8> {
    let len = payload.len() as u16;
    let [len_lo, len_hi] = len.to_le_bytes();
    let [t_lo, t_hi] = topic.to_le_bytes();
    let len_chk = 255 - ((u32::from(len_lo) + u32::from(len_hi)) % 256) as u8;
    let body: u32 =
        u32::from(t_lo) + u32::from(t_hi) + payload.iter().map(|&b| u32::from(b)).sum::<u32>();
    let msg_chk = 255 - (body % 256) as u8;
    let mut out = vec![0xFF, 0xFE, len_lo, len_hi, len_chk, t_lo, t_hi];
    out.extend_from_slice(payload);
    out.push(msg_chk);
    out
}

#[test]
fn frames_with_high_topic_and_length_bytes_are_found_whole() {
    for (topic, n) in [
        (0x0000u16, 0usize),
        (0x0064, 5),
        (0x1234, 300),
        (0xFFFF, 513),
    ] {
        let payload: Vec<u8> = (0..n).map(|k| (k * 37 + 11) as u8).collect();
        let bytes = frame(topic, &payload);
        let mut stream = vec![0x00, 0x42];
        stream.extend_from_slice(&bytes);
        assert_eq!(next_candidate(&stream, 0, 1024), Step::Skip { stop: 2 });
        assert_eq!(
            next_candidate(&stream, 2, 1024),
            Step::Good {
                topic,
                payload_start: 9,
                len: n
            },
            "topic {topic:#x} len {n}"
        );
        // the sealer writes the same header and checksum around the payload
        let mut sealed = vec![0u8; n + 8];
        sealed[7..7 + n].copy_from_slice(&payload);
        assert!(seal_frame(topic, &mut sealed));
        assert_eq!(sealed, bytes);
        // one byte short: more is needed
        assert_eq!(
            next_candidate(&bytes[..bytes.len() - 1], 0, 1024),
            Step::NeedMore
        );
    }
}

#[test]
fn a_changed_high_byte_breaks_the_checksum_it_is_part_of() {
    let payload = [1u8, 2, 3, 4, 250, 251];
    let good = frame(0x0302, &payload);
    let mut topic_hi = good.clone();
    topic_hi[6] ^= 0x10;
    assert_eq!(
        next_candidate(&topic_hi, 0, 1024),
        Step::Bad {
            reason: BadReason::MessageChecksum,
            used: payload.len() + 8
        }
    );
    let mut len_hi = good.clone();
    len_hi[3] ^= 0x01;
    assert_eq!(
        next_candidate(&len_hi, 0, 1024),
        Step::Bad {
            reason: BadReason::LengthChecksum,
            used: 5
        }
    );
    let long = frame(7, &[0u8; 600]);
    assert_eq!(
        next_candidate(&long, 0, 512),
        Step::Bad {
            reason: BadReason::Oversize,
            used: 5
        }
    );
}
