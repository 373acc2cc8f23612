//! Sensor side of a Leptrino continuous-output sample (command 0x32): wrench -> raw int16
//! counts -> payload -> `DLE STX stuffed(payload) DLE ETX BCC` (jsk-wire-protocols.md sec. 5),
//! the same bytes as `rdm.protocol.leptrino.encode_response(ForceData(from_wrench(...)))`.
//!
//! Raw count per axis: `round_ties_even(w * 10000 / rated)` (Python's `round`). Everything
//! that the Python form rejects (a non-finite wrench, a count outside int16, a temperature
//! outside int16, a status / term number / result outside u8) is an error here, so a caller
//! can fall back to the Python form and get its exact exception.

/// Frame delimiter / escape byte.
pub const DLE: u8 = 0x10;
/// Start of text.
pub const STX: u8 = 0x02;
/// End of text.
pub const ETX: u8 = 0x03;
/// Raw count at the rated capacity.
pub const RAW_AT_RATED: f64 = 10000.0;
/// Payload header: length, term number, command, result.
pub const HEADER_LEN: usize = 4;
/// Command byte of a continuous-output sample.
pub const DATA_START: u8 = 0x32;
/// Payload length of a sample: header + 6 int16 counts + int16 temperature + status + pad.
pub const FORCE_PAYLOAD_LEN: usize = HEADER_LEN + 16;
/// Longest frame of a sample: every payload byte a DLE (doubled) + 5 framing bytes.
pub const MAX_FORCE_FRAME_LEN: usize = 2 * FORCE_PAYLOAD_LEN + 5;

/// Why a sample cannot be encoded (the Python form raises for the same inputs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ForceFrameError {
    /// Wrench axis not finite.
    NonFinite(usize),
    /// Raw count of this axis outside int16 (or not finite: rated 0).
    RawRange(usize),
    /// Temperature outside int16.
    Temperature,
    /// Status, term number or result outside 0..255.
    Byte,
}

/// One encoded frame in a fixed buffer (no allocation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ForceFrame {
    bytes: [u8; MAX_FORCE_FRAME_LEN],
    len: usize,
}

impl ForceFrame {
    /// The frame's bytes.
    pub fn as_bytes(&self) -> &[u8] {
        self.bytes.get(..self.len).unwrap_or(&[])
    }
}

/// Raw int16 counts of a wrench (`round(w * 10000 / rated)`, ties to even).
pub fn raw_counts(wrench: &[f64; 6], rated: &[f64; 6]) -> Result<[i16; 6], ForceFrameError> {
    let mut raw = [0i16; 6];
    for k in 0..6 {
        if !wrench[k].is_finite() {
            return Err(ForceFrameError::NonFinite(k));
        }
        let r = (wrench[k] * RAW_AT_RATED / rated[k]).round_ties_even();
        // NaN fails both comparisons: out of range.
        if !(-32768.0..=32767.0).contains(&r) {
            return Err(ForceFrameError::RawRange(k));
        }
        raw[k] = r as i16;
    }
    Ok(raw)
}

/// Encode one sample frame: the wrench in `rated` units, temperature (int16), status,
/// term (sensor) number and result byte.
pub fn encode_force_frame(
    wrench: &[f64; 6],
    rated: &[f64; 6],
    temperature: i64,
    status: i64,
    term_no: i64,
    result: i64,
) -> Result<ForceFrame, ForceFrameError> {
    let byte = |v: i64| u8::try_from(v).map_err(|_| ForceFrameError::Byte);
    let (term_no, result) = (byte(term_no)?, byte(result)?);
    let raw = raw_counts(wrench, rated)?;
    let temperature = i16::try_from(temperature).map_err(|_| ForceFrameError::Temperature)?;
    let status = byte(status)?;
    let mut payload = [0u8; FORCE_PAYLOAD_LEN];
    payload[0] = FORCE_PAYLOAD_LEN as u8;
    payload[1] = term_no;
    payload[2] = DATA_START;
    payload[3] = result;
    for (k, r) in raw.iter().enumerate() {
        let [lo, hi] = r.to_le_bytes();
        payload[HEADER_LEN + 2 * k] = lo;
        payload[HEADER_LEN + 2 * k + 1] = hi;
    }
    let [lo, hi] = temperature.to_le_bytes();
    payload[HEADER_LEN + 12] = lo;
    payload[HEADER_LEN + 13] = hi;
    payload[HEADER_LEN + 14] = status;
    // payload[HEADER_LEN + 15]: pad byte, 0
    let mut frame = ForceFrame {
        bytes: [0u8; MAX_FORCE_FRAME_LEN],
        len: 0,
    };
    let mut n = 0;
    let mut push = |b: u8, frame: &mut ForceFrame| {
        if let Some(slot) = frame.bytes.get_mut(n) {
            *slot = b;
            n += 1;
        }
    };
    push(DLE, &mut frame);
    push(STX, &mut frame);
    let mut bcc = ETX;
    for &b in payload.iter() {
        bcc ^= b;
        push(b, &mut frame);
        if b == DLE {
            push(DLE, &mut frame);
        }
    }
    push(DLE, &mut frame);
    push(ETX, &mut frame);
    push(bcc, &mut frame);
    frame.len = n;
    Ok(frame)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_of_zero_wrench() {
        let f = encode_force_frame(&[0.0; 6], &[1.0; 6], 250, 0, 0, 0).unwrap();
        let b = f.as_bytes();
        assert_eq!(&b[..2], &[DLE, STX]);
        assert_eq!(b[2], 20);
        assert_eq!(b[4], DATA_START);
        assert_eq!(b.len(), 2 + 20 + 3);
    }

    #[test]
    fn rejects_what_python_rejects() {
        let rated = [1.0; 6];
        let mut w = [0.0; 6];
        w[2] = f64::NAN;
        assert_eq!(
            encode_force_frame(&w, &rated, 0, 0, 0, 0),
            Err(ForceFrameError::NonFinite(2))
        );
        w[2] = 3.3;
        assert_eq!(
            encode_force_frame(&w, &rated, 0, 0, 0, 0),
            Err(ForceFrameError::RawRange(2))
        );
        assert_eq!(
            encode_force_frame(&[0.0; 6], &rated, 40000, 0, 0, 0),
            Err(ForceFrameError::Temperature)
        );
        assert_eq!(
            encode_force_frame(&[0.0; 6], &rated, 0, 256, 0, 0),
            Err(ForceFrameError::Byte)
        );
    }
}
