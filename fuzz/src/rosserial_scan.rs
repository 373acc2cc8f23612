//! rosserial v2 frame scan (`rdm_core::firmware::rosserial_frame::next_candidate`), driven
//! the way `rdm.protocol.rosserial.framing.FrameParser` drives it over a receive buffer.
//!
//! Input: one selector byte (bits 0-1: the receiver's buffer, 64 / 512 / 1022 / 65535
//! bytes; bit 2: re-scan after a rejected candidate), then the received bytes.
//!
//! Checks, each against the frame format recomputed here from the bytes (fact sheet
//! sec. 1.2), never against the scanner's own arithmetic:
//! * a `Good` frame starts `FF FE`, its length checksum and message checksum hold, its
//!   length is within the buffer, and `seal_frame` rebuilds exactly its bytes;
//! * a `Bad` candidate breaks the rule its reason names, and only the first one broken;
//! * `Skip` covers only non-0xFF bytes and stops at a 0xFF or the end;
//! * `NeedMore` is answered only for a candidate cut short by the end of the buffer;
//! * every step advances (the scan of a finite buffer ends).

use rdm_core::firmware::rosserial_frame::{next_candidate, seal_frame, BadReason, Step};

const BUFFERS: [usize; 4] = [64, 512, 1022, 65535];

/// The reason an independent reading of the frame format gives for the candidate at
/// `buf[pos]` (a 0xFF): `Ok(Some(r))` rejected, `Ok(None)` good, `Err(())` incomplete.
fn expected(buf: &[u8], pos: usize, max_payload: usize) -> Result<Option<BadReason>, ()> {
    let rest = &buf[pos..];
    if rest.len() < 2 {
        return Err(());
    }
    if rest[1] != 0xFE {
        return Ok(Some(BadReason::Version));
    }
    if rest.len() < 7 {
        return Err(());
    }
    if (u32::from(rest[2]) + u32::from(rest[3]) + u32::from(rest[4])) % 256 != 255 {
        return Ok(Some(BadReason::LengthChecksum));
    }
    let n = usize::from(rest[2]) + 256 * usize::from(rest[3]);
    if n > max_payload {
        return Ok(Some(BadReason::Oversize));
    }
    if rest.len() < n + 8 {
        return Err(());
    }
    let sum: u32 = rest[5..n + 8].iter().map(|&b| u32::from(b)).sum();
    if sum % 256 != 255 {
        return Ok(Some(BadReason::MessageChecksum));
    }
    Ok(None)
}

/// Run the scan over `data` (see the module doc); panics on a broken rule.
pub fn check(data: &[u8]) {
    let Some((&selector, buf)) = data.split_first() else {
        return;
    };
    let max_payload = BUFFERS[usize::from(selector & 3)];
    let rescan = selector & 4 != 0;
    let mut pos = 0;
    while pos < buf.len() {
        match next_candidate(buf, pos, max_payload) {
            Step::Skip { stop } => {
                assert!(
                    stop > pos && stop <= buf.len(),
                    "crash: skip to {stop} from {pos}"
                );
                assert!(
                    !buf[pos..stop].contains(&0xFF),
                    "wrong rejection: skipped a 0xFF in {pos}..{stop}"
                );
                assert!(
                    stop == buf.len() || buf[stop] == 0xFF,
                    "wrong rejection: skip stopped at a non-sync byte {stop}"
                );
                pos = stop;
            }
            Step::NeedMore => {
                assert!(
                    expected(buf, pos, max_payload).is_err(),
                    "wrong rejection: NeedMore for a complete candidate at {pos}"
                );
                break;
            }
            Step::Good {
                topic,
                payload_start,
                len,
            } => {
                assert_eq!(
                    expected(buf, pos, max_payload),
                    Ok(None),
                    "bad frame accepted at {pos}"
                );
                let frame = &buf[pos..pos + len + 8];
                assert_eq!(payload_start, pos + 7, "bad frame accepted: payload offset");
                assert_eq!(
                    u16::from_le_bytes([frame[5], frame[6]]),
                    topic,
                    "bad frame accepted: topic id"
                );
                let mut rebuilt = frame.to_vec();
                rebuilt[..7].fill(0);
                rebuilt[len + 7] = 0;
                assert!(
                    seal_frame(topic, &mut rebuilt),
                    "not canonical: seal refused"
                );
                assert_eq!(
                    rebuilt, frame,
                    "not canonical: frame at {pos} re-encodes differently"
                );
                pos += len + 8;
            }
            Step::Bad { reason, used } => {
                assert_eq!(
                    expected(buf, pos, max_payload),
                    Ok(Some(reason)),
                    "wrong rejection at {pos}"
                );
                let want = match reason {
                    BadReason::Version => 2,
                    BadReason::LengthChecksum | BadReason::Oversize => 5,
                    BadReason::MessageChecksum => {
                        usize::from(buf[pos + 2]) + 256 * usize::from(buf[pos + 3]) + 8
                    }
                };
                assert_eq!(used, want, "wrong rejection: {used} bytes used at {pos}");
                pos += if rescan { 1 } else { used };
            }
        }
    }
}
