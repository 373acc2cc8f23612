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

/// Result code of a successful response.
pub const RESULT_OK: u8 = 0x00;

/// The leading run of whole OK-sample frames of a byte chunk (host side, see
/// [`ok_sample_run`]): how far it reaches and the newest sample of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OkSampleRun {
    /// Bytes of the chunk the run covers (0: the chunk does not start with such a frame).
    pub end: usize,
    /// Frames in the run.
    pub count: usize,
    /// Offset in the chunk of the newest frame's first byte (its `DLE`).
    pub last_start: usize,
    /// Unstuffed payload of the newest frame (all zero when `count` is 0).
    pub last_payload: [u8; FORCE_PAYLOAD_LEN],
}

/// One whole frame at the start of `data` that is an OK sample: `DLE STX`, a stuffed payload
/// of exactly [`FORCE_PAYLOAD_LEN`] bytes with header (len, *, [`DATA_START`], [`RESULT_OK`]),
/// `DLE ETX`, a matching BCC. Returns the frame length and the payload, else None.
fn ok_sample_frame(data: &[u8]) -> Option<(usize, [u8; FORCE_PAYLOAD_LEN])> {
    if data.first() != Some(&DLE) || data.get(1) != Some(&STX) {
        return None;
    }
    let mut payload = [0u8; FORCE_PAYLOAD_LEN];
    let mut n = 0;
    let mut i = 2;
    let mut bcc = ETX;
    loop {
        let b = *data.get(i)?;
        let byte = if b == DLE {
            match *data.get(i + 1)? {
                DLE => {
                    i += 2;
                    DLE
                }
                ETX => break,
                _ => return None, // DLE STX restart or a bad escape: not a plain whole frame
            }
        } else {
            i += 1;
            b
        };
        *payload.get_mut(n)? = byte; // longer than a sample: not one
        n += 1;
        bcc ^= byte;
    }
    let check = *data.get(i + 2)?;
    let is_sample = n == FORCE_PAYLOAD_LEN
        && usize::from(payload[0]) == FORCE_PAYLOAD_LEN
        && payload[2] == DATA_START
        && payload[3] == RESULT_OK
        && check == bcc;
    is_sample.then_some((i + 3, payload))
}

/// Host-side fast scan of a Leptrino byte chunk read while the de-framer is idle: the
/// longest prefix made of back-to-back whole frames that each carry an OK sample (the frames
/// `rdm.protocol.leptrino.LeptrinoStreamParser` would return, one by one, as well-formed
/// payloads that parse to an OK `ForceData`). Stops at the first byte that starts anything
/// else, which the caller de-frames the plain way. Allocates nothing, never panics.
pub fn ok_sample_run(data: &[u8]) -> OkSampleRun {
    let mut run = OkSampleRun {
        end: 0,
        count: 0,
        last_start: 0,
        last_payload: [0u8; FORCE_PAYLOAD_LEN],
    };
    while let Some((len, payload)) = data.get(run.end..).and_then(ok_sample_frame) {
        run.last_start = run.end;
        run.last_payload = payload;
        run.end += len;
        run.count += 1;
    }
    run
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

    #[test]
    fn ok_sample_run_stops_at_anything_else() {
        let a = encode_force_frame(&[0.1; 6], &[1.0; 6], 250, 0, 0, 0).unwrap();
        // a count of 0x10 in a low byte forces DLE stuffing
        let b = encode_force_frame(&[16.0 / 10000.0; 6], &[1.0; 6], 16, 0, 0, 0).unwrap();
        let err = encode_force_frame(&[0.1; 6], &[1.0; 6], 250, 0, 0, 1).unwrap();
        let mut data = Vec::new();
        data.extend_from_slice(a.as_bytes());
        data.extend_from_slice(b.as_bytes());
        let two = data.len();
        data.extend_from_slice(err.as_bytes());
        data.extend_from_slice(a.as_bytes());
        let run = ok_sample_run(&data);
        assert_eq!(
            (run.end, run.count, run.last_start),
            (two, 2, a.as_bytes().len())
        );
        assert_eq!(run.last_payload[4], 16);
        // a truncated frame or a bad BCC ends the run too
        assert_eq!(ok_sample_run(&data[..two - 1]).count, 1);
        let mut bad = a.as_bytes().to_vec();
        if let Some(last) = bad.last_mut() {
            *last ^= 1;
        }
        assert_eq!(ok_sample_run(&bad).end, 0);
        assert_eq!(ok_sample_run(&[]).count, 0);
    }
}
