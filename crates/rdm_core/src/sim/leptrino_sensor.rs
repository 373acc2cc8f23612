//! The Leptrino sensor's stream state (the sensor end of its serial link,
//! jsk-wire-protocols.md sec. 5): the wrench it measures (clipped to what its int16 counts can
//! say), whether it streams, its temperature and sensor number, the sample frame of all three,
//! the frames encoded but not yet written to its UART (each with its tick time), and its
//! counters. One owner: the Python node `rdm.nodes.leptrino_sensor.LeptrinoSensorNode` (host
//! commands, UART writes) and the lockstep kernel's streaming tick both call this state.
//!
//! ASSUMPTION: the pending frames are bounded by the caller: the kernel writes them to the
//! UART before any Python code runs and at the end of each run, so they hold one run's
//! stream at most (`Vec` growth amortised; the first `PENDING_CAPACITY` bytes need none).

use super::leptrino_stream::{encode_force_frame, ForceFrame, ForceFrameError, RAW_AT_RATED};

/// Highest raw count the sensor outputs (int16).
pub const MAX_RAW: f64 = 32767.0;
/// Highest sensor number a sensor answers to (255 is the broadcast address).
pub const MAX_SENSOR_NO: i64 = 0xFE;
/// Pending bytes reserved at construction (about 90 frames).
pub const PENDING_CAPACITY: usize = 4096;

/// What [`LeptrinoStream::set_wrench`] did with a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WrenchInput {
    /// Inside the limits: taken as it is.
    Taken,
    /// Finite but outside the limits: clipped to them, counted as saturated.
    Clipped,
    /// Not six values, or one not finite: refused (the previous wrench stays), counted.
    Refused,
}

/// The state of one simulated Leptrino sensor's sample stream (see the module doc).
#[derive(Debug, Clone)]
pub struct LeptrinoStream {
    rated: [f64; 6],
    limits: [f64; 6],
    temperature: i16,
    sensor_no: u8,
    streaming: bool,
    wrench: [f64; 6],
    /// The frame of (wrench, temperature, sensor number); None: encode at the next use.
    frame: Option<ForceFrame>,
    pending: Vec<u8>,
    /// Per pending frame: (tick time s, end offset in `pending`).
    marks: Vec<(f64, usize)>,
    saturated_samples: u64,
    bad_wrench: u64,
    frames_sent: u64,
    bytes_dropped: u64,
    tx_short: u64,
}

/// A value outside the range a field takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FieldRange {
    /// Temperature outside int16.
    Temperature,
    /// Sensor number outside 0..=254.
    SensorNo,
}

impl LeptrinoStream {
    /// A sensor of `rated` capacity (N, N m per axis) at `temperature` (raw int16, 0.1 degC)
    /// answering to `sensor_no`, not streaming, measuring zero.
    pub fn new(rated: [f64; 6], temperature: i64, sensor_no: i64) -> Result<Self, FieldRange> {
        let mut s = LeptrinoStream {
            rated,
            limits: rated.map(|r| MAX_RAW * r / RAW_AT_RATED),
            temperature: 0,
            sensor_no: 0,
            streaming: false,
            wrench: [0.0; 6],
            frame: None,
            pending: Vec::with_capacity(PENDING_CAPACITY),
            marks: Vec::with_capacity(PENDING_CAPACITY / 32),
            saturated_samples: 0,
            bad_wrench: 0,
            frames_sent: 0,
            bytes_dropped: 0,
            tx_short: 0,
        };
        s.set_temperature(temperature)?;
        s.set_sensor_no(sensor_no)?;
        Ok(s)
    }

    /// Rated capacity per axis.
    pub fn rated(&self) -> [f64; 6] {
        self.rated
    }

    /// Highest magnitude per axis the counts can say (`32767 * rated / 10000`).
    pub fn limits(&self) -> [f64; 6] {
        self.limits
    }

    /// The wrench the sensor measures now.
    pub fn wrench(&self) -> [f64; 6] {
        self.wrench
    }

    pub fn streaming(&self) -> bool {
        self.streaming
    }

    /// Start (DATA_START) or stop (DATA_STOP) the stream.
    pub fn set_streaming(&mut self, on: bool) {
        self.streaming = on;
    }

    pub fn temperature(&self) -> i64 {
        i64::from(self.temperature)
    }

    /// The temperature every later frame carries (int16).
    pub fn set_temperature(&mut self, t: i64) -> Result<(), FieldRange> {
        self.temperature = i16::try_from(t).map_err(|_| FieldRange::Temperature)?;
        self.frame = None;
        Ok(())
    }

    pub fn sensor_no(&self) -> i64 {
        i64::from(self.sensor_no)
    }

    /// The sensor number every later frame carries (0..=254).
    pub fn set_sensor_no(&mut self, n: i64) -> Result<(), FieldRange> {
        match u8::try_from(n) {
            Ok(b) if n <= MAX_SENSOR_NO => self.sensor_no = b,
            _ => return Err(FieldRange::SensorNo),
        }
        self.frame = None;
        Ok(())
    }

    /// The wrench the sensor measures from now on (Fx, Fy, Fz, Mx, My, Mz): a sample outside
    /// the limits is clipped to them and counted; one not finite, or not six values, is
    /// refused and counted.
    pub fn set_wrench(&mut self, w: &[f64]) -> WrenchInput {
        let Ok(w) = <[f64; 6]>::try_from(w) else {
            self.bad_wrench += 1;
            return WrenchInput::Refused;
        };
        // NaN fails both comparisons: not inside.
        let inside = w
            .iter()
            .zip(self.limits.iter())
            .all(|(v, l)| -l <= *v && *v <= *l);
        self.frame = None;
        if inside {
            self.wrench = w;
            return WrenchInput::Taken;
        }
        if !w.iter().all(|v| v.is_finite()) {
            self.bad_wrench += 1;
            return WrenchInput::Refused;
        }
        for ((out, v), m) in self.wrench.iter_mut().zip(w).zip(self.limits) {
            *out = v.clamp(-m, m);
        }
        self.saturated_samples += 1;
        WrenchInput::Clipped
    }

    /// The sample frame of the present wrench, temperature and sensor number (encoded once
    /// per change of any of them).
    pub fn sample_frame(&mut self) -> Result<&[u8], ForceFrameError> {
        if self.frame.is_none() {
            self.frame = Some(encode_force_frame(
                &self.wrench,
                &self.rated,
                i64::from(self.temperature),
                0,
                i64::from(self.sensor_no),
                0,
            )?);
        }
        Ok(self.frame.as_ref().map_or(&[][..], |f| f.as_bytes()))
    }

    /// One streaming tick at `now` (s) with no host command waiting: while streaming, the
    /// sample frame is appended to the pending bytes (true); not streaming: nothing (false).
    pub fn stream_tick(&mut self, now: f64) -> Result<bool, ForceFrameError> {
        if !self.streaming {
            return Ok(false);
        }
        self.sample_frame()?;
        if let Some(f) = &self.frame {
            self.pending.extend_from_slice(f.as_bytes());
            self.marks.push((now, self.pending.len()));
        }
        Ok(true)
    }

    /// The frames of [`Self::stream_tick`] not yet written, and each one's (tick time s,
    /// end offset in them).
    pub fn pending(&self) -> (&[u8], &[(f64, usize)]) {
        (&self.pending, &self.marks)
    }

    /// The pending frames went to the UART: `written` of their bytes were taken.
    pub fn pending_written(&mut self, written: usize) {
        let frames = self.marks.len() as u64;
        self.count_write(self.pending.len(), written, frames);
        self.pending.clear();
        self.marks.clear();
    }

    /// A write of `len` bytes holding `frames` frames, of which the UART took `written`: all
    /// taken, the frames count as sent; fewer, the lost bytes and the short write are counted.
    pub fn count_write(&mut self, len: usize, written: usize, frames: u64) {
        if written < len {
            self.bytes_dropped += (len - written) as u64;
            self.tx_short += 1;
        } else {
            self.frames_sent += frames;
        }
    }

    /// Samples clipped to the limits.
    pub fn saturated_samples(&self) -> u64 {
        self.saturated_samples
    }

    /// Samples refused (not six values, or not finite).
    pub fn bad_wrench(&self) -> u64 {
        self.bad_wrench
    }

    /// Frames the UART took whole.
    pub fn frames_sent(&self) -> u64 {
        self.frames_sent
    }

    /// Bytes the UART did not take.
    pub fn bytes_dropped(&self) -> u64 {
        self.bytes_dropped
    }

    /// Writes the UART cut short.
    pub fn tx_short(&self) -> u64 {
        self.tx_short
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RATED: [f64; 6] = [200.0, 200.0, 400.0, 4.0, 4.0, 4.0];

    #[test]
    fn limits_are_the_int16_counts() {
        let s = LeptrinoStream::new(RATED, 250, 0).unwrap();
        // 32767 counts of 10000 per rated value, written out.
        assert_eq!(s.limits()[0], 655.34);
        assert_eq!(s.limits()[2], 1310.68);
        assert_eq!(s.limits()[3], 13.1068);
    }

    #[test]
    fn wrench_is_clipped_or_refused_and_counted() {
        let mut s = LeptrinoStream::new(RATED, 250, 0).unwrap();
        let w = [1.0, -2.0, 3.0, 0.5, -0.5, 0.0];
        assert_eq!(s.set_wrench(&w), WrenchInput::Taken);
        assert_eq!(s.wrench(), w);
        let big = [1e6, -1e6, 3.0, 0.5, -0.5, -0.0];
        assert_eq!(s.set_wrench(&big), WrenchInput::Clipped);
        assert_eq!(s.wrench(), [655.34, -655.34, 3.0, 0.5, -0.5, -0.0]);
        assert!(s.wrench()[5].is_sign_negative());
        assert_eq!(
            s.set_wrench(&[f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0]),
            WrenchInput::Refused
        );
        assert_eq!(
            s.set_wrench(&[f64::INFINITY, 0.0, 0.0, 0.0, 0.0, 0.0]),
            WrenchInput::Refused
        );
        assert_eq!(s.set_wrench(&[0.0; 5]), WrenchInput::Refused);
        assert_eq!(s.wrench()[0], 655.34);
        assert_eq!((s.saturated_samples(), s.bad_wrench()), (1, 3));
    }

    #[test]
    fn fields_outside_their_range_are_refused() {
        let mut s = LeptrinoStream::new(RATED, 250, 0).unwrap();
        assert_eq!(s.set_temperature(40000), Err(FieldRange::Temperature));
        assert_eq!(s.set_sensor_no(255), Err(FieldRange::SensorNo));
        assert_eq!(s.set_sensor_no(-1), Err(FieldRange::SensorNo));
        assert_eq!((s.temperature(), s.sensor_no()), (250, 0));
        assert!(LeptrinoStream::new(RATED, 0, 300).is_err());
    }

    #[test]
    fn stream_ticks_queue_marked_frames_until_written() {
        let mut s = LeptrinoStream::new([1.0; 6], 50, 0).unwrap();
        assert_eq!(s.stream_tick(0.0), Ok(false));
        s.set_streaming(true);
        s.set_wrench(&[1e-4, 2e-4, 3e-4, 4e-4, 5e-4, 6e-4]);
        assert_eq!(s.stream_tick(0.001), Ok(true));
        s.set_temperature(51).unwrap();
        assert_eq!(s.stream_tick(0.002), Ok(true));
        let n = s.pending().0.len();
        let first = s.pending().1[0].1;
        assert_eq!(s.pending().1, &[(0.001, first), (0.002, n)]);
        assert_ne!(s.pending().0[..first], s.pending().0[first..]);
        s.pending_written(n - 3);
        assert_eq!(
            (s.frames_sent(), s.bytes_dropped(), s.tx_short()),
            (0, 3, 1)
        );
        assert!(s.pending().0.is_empty() && s.pending().1.is_empty());
        s.stream_tick(0.003).unwrap();
        let n = s.pending().0.len();
        s.pending_written(n);
        assert_eq!(s.frames_sent(), 1);
    }
}
