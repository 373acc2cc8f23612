//! Standard normals of one generator handed out a few at a time (9 per IMU sample, 6 per
//! wrench sample) and drawn a chunk at a time: the sensor noise models' stream. The
//! generator is the caller's (`refill` appends one chunk); the stream owns it from its
//! construction on and runs up to one chunk ahead of what was taken.
//!
//! ASSUMPTION: a chunk drawn in one call equals the same number drawn one call after another
//! (true of numpy's `Generator.normal`: element by element, no state carried between calls;
//! `tests/test_plant_sensors_and_bridge.py` checks it), so how the draws are cut into chunks
//! does not change the stream.

/// The stream (see the module doc).
#[derive(Debug, Clone)]
pub struct NormalStream {
    buf: Vec<f64>,
    pos: usize,
    chunk: usize,
    taken: u64,
}

impl NormalStream {
    /// An empty stream drawing `chunk` (at least 1) values per refill; takes of up to
    /// `max_take` values allocate nothing after the first refill.
    pub fn new(chunk: usize, max_take: usize) -> Self {
        let chunk = chunk.max(1);
        NormalStream {
            buf: Vec::with_capacity(chunk + max_take),
            pos: 0,
            chunk,
            taken: 0,
        }
    }

    /// Values drawn per refill.
    pub fn chunk(&self) -> usize {
        self.chunk
    }

    /// Values taken so far.
    pub fn taken(&self) -> u64 {
        self.taken
    }

    /// Fill `out` with the next values; when fewer are left, the taken ones are dropped and
    /// `refill(buf, chunk)` appends `chunk` more (as often as `out` needs: at most
    /// `out.len() / chunk + 1` times). A refill that appends nothing is an error.
    pub fn take<E>(
        &mut self,
        out: &mut [f64],
        mut refill: impl FnMut(&mut Vec<f64>, usize) -> Result<(), E>,
        empty: impl Fn() -> E,
    ) -> Result<(), E> {
        let n = out.len();
        if self.pos + n > self.buf.len() {
            self.buf.drain(..self.pos);
            self.pos = 0;
            while self.buf.len() < n {
                let before = self.buf.len();
                refill(&mut self.buf, self.chunk)?;
                if self.buf.len() == before {
                    return Err(empty());
                }
            }
        }
        out.copy_from_slice(&self.buf[self.pos..self.pos + n]);
        self.pos += n;
        self.taken += n as u64;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A "generator" counting 0, 1, 2, ...: the stream must hand out that sequence.
    fn counter() -> impl FnMut(&mut Vec<f64>, usize) -> Result<(), ()> {
        let mut next = 0.0;
        move |buf, chunk| {
            for _ in 0..chunk {
                buf.push(next);
                next += 1.0;
            }
            Ok(())
        }
    }

    #[test]
    fn takes_across_chunks_are_the_sequence() {
        let mut s = NormalStream::new(7, 9);
        let mut refill = counter();
        let mut want = 0.0;
        for k in [1usize, 9, 6, 7, 3, 9, 9, 2, 6, 1, 9] {
            let mut out = [f64::NAN; 9];
            s.take(&mut out[..k], &mut refill, || ()).unwrap();
            for v in &out[..k] {
                assert_eq!(*v, want);
                want += 1.0;
            }
        }
        assert_eq!(s.taken(), want as u64);
    }

    #[test]
    fn a_take_longer_than_a_chunk_refills_several_times() {
        let mut s = NormalStream::new(4, 9);
        let mut out = [0.0; 11];
        s.take(&mut out, counter(), || ()).unwrap();
        assert_eq!(
            out,
            [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0]
        );
    }

    #[test]
    fn a_refill_that_appends_nothing_is_an_error() {
        let mut s = NormalStream::new(4, 6);
        let mut out = [0.0; 6];
        assert_eq!(s.take(&mut out, |_, _| Ok::<(), u8>(()), || 7), Err(7));
        assert_eq!(s.taken(), 0);
    }
}
