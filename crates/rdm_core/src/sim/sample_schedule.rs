//! The plant bridge's sampling schedule: which sensor reading is due at which tick.
//!
//! The bridge ticks at a base period (1 ms); each reading (IMU, wrench, mocap, ground truth)
//! has a period that is a whole number of base ticks, or is off. Tick `n` (counted from 0)
//! takes a reading when `n % every == 0`: the first tick takes every reading that is on,
//! then every `every`-th tick. The schedule is a counter and four periods: no allocation,
//! constant time per tick.
//!
//! ASSUMPTION: the tick counter is a `u64` that wraps after 2^64 ticks (5.8e8 years at
//! 1 kHz); the schedule's phase after a wrap is not kept.

/// The readings the bridge samples, in the order it takes them within one tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reading {
    /// One noisy IMU sample (gyro, accelerometer, magnetometer).
    Imu = 0,
    /// One noisy sample per wrench sensor.
    Wrench = 1,
    /// The foot pose (motion capture).
    Mocap = 2,
    /// The ground-truth record.
    Truth = 3,
}

/// Number of readings a schedule holds.
pub const READINGS: usize = 4;

/// Which readings are due at one tick, indexed by [`Reading`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Due(pub [bool; READINGS]);

impl Due {
    /// Whether `reading` is due.
    pub fn has(self, reading: Reading) -> bool {
        self.0[reading as usize]
    }
}

/// Ticks between the samples of each reading (0: off) and the ticks taken so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SampleSchedule {
    every: [u64; READINGS],
    count: u64,
}

impl SampleSchedule {
    /// A schedule at tick 0; `every[r]` ticks between the samples of reading `r`, 0 = off.
    pub fn new(every: [u64; READINGS]) -> Self {
        SampleSchedule { every, count: 0 }
    }

    /// Ticks between the samples of each reading (0: off), indexed by [`Reading`].
    pub fn every(&self) -> [u64; READINGS] {
        self.every
    }

    /// Ticks taken so far (the index of the next tick).
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The readings due at the next tick, without taking it.
    pub fn peek(&self) -> Due {
        let n = self.count;
        Due(self.every.map(|e| e != 0 && n.is_multiple_of(e)))
    }

    /// Take the next tick: the readings due at it.
    pub fn advance(&mut self) -> Due {
        let due = self.peek();
        self.count = self.count.wrapping_add(1);
        due
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_tick_takes_every_reading_that_is_on() {
        let mut s = SampleSchedule::new([5, 1, 0, 10]);
        assert_eq!(s.advance(), Due([true, true, false, true]));
        assert_eq!(s.count(), 1);
    }

    #[test]
    fn due_ticks_are_the_multiples_of_each_period() {
        // An independent count: the due ticks of period e over 0..100 are 0, e, 2e, ...
        let every = [5, 1, 0, 10];
        let mut s = SampleSchedule::new(every);
        let mut seen = [[false; 100]; READINGS];
        for n in 0..100 {
            let mut copy = s;
            assert_eq!(s.peek(), copy.advance());
            let d = s.advance();
            for (row, due) in seen.iter_mut().zip(d.0) {
                row[n] = due;
            }
        }
        for (r, &e) in every.iter().enumerate() {
            let mut expected = [false; 100];
            if e > 0 {
                let mut k = 0;
                while k < 100 {
                    expected[k as usize] = true;
                    k += e;
                }
            }
            assert_eq!(seen[r], expected, "reading {r}, every {e}");
        }
        assert!(Due([false, false, true, false]).has(Reading::Mocap));
        assert!(!Due([false, false, true, false]).has(Reading::Truth));
    }

    #[test]
    fn counter_wraps_instead_of_panicking() {
        let mut s = SampleSchedule {
            every: [1, 0, 0, 0],
            count: u64::MAX,
        };
        assert!(s.advance().has(Reading::Imu));
        assert_eq!(s.count(), 0);
    }
}
