//! The lockstep loop's schedule: which node ticks at which base tick.
//!
//! Time advances in base ticks of `dt`. Node `i` has a period that is a whole number
//! `every[i]` of base ticks and an offset `offset[i]` in `0..every[i]`; it ticks at the base
//! ticks `k` with `k % every[i] == offset[i]`, in the order the nodes were given. The
//! schedule holds the periods and one buffer of node indices sized at setup: selecting the
//! nodes due at a tick allocates nothing and takes one remainder per node.

use std::fmt;

/// A configuration the schedule refuses.
#[derive(Clone, Debug, PartialEq)]
pub enum ScheduleError {
    /// `dt` is not a positive finite number.
    BadDt(f64),
    /// Node `index`'s period is not a positive finite number.
    BadPeriod { index: usize, period: f64 },
    /// Node `index`'s period is not a whole multiple of `dt`.
    NotMultiple { index: usize, period: f64, dt: f64 },
    /// Node `index`'s offset is not in `0..every`.
    BadOffset {
        index: usize,
        offset: u64,
        every: u64,
    },
    /// One offset per node is needed.
    Lengths { periods: usize, offsets: usize },
}

impl fmt::Display for ScheduleError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ScheduleError::BadDt(dt) => write!(f, "dt {dt} must be a positive finite number"),
            ScheduleError::BadPeriod { period, .. } => {
                write!(f, "period {period} must be a positive finite number")
            }
            ScheduleError::NotMultiple { period, dt, .. } => {
                write!(f, "period {period} s is not a whole multiple of dt {dt} s")
            }
            ScheduleError::BadOffset { offset, every, .. } => {
                write!(f, "offset {offset} not in 0..{}", every - 1)
            }
            ScheduleError::Lengths { periods, offsets } => {
                write!(f, "{periods} periods but {offsets} offsets")
            }
        }
    }
}

impl ScheduleError {
    /// The node the error is about (None: the whole schedule).
    pub fn index(&self) -> Option<usize> {
        match self {
            ScheduleError::BadPeriod { index, .. }
            | ScheduleError::NotMultiple { index, .. }
            | ScheduleError::BadOffset { index, .. } => Some(*index),
            ScheduleError::BadDt(_) | ScheduleError::Lengths { .. } => None,
        }
    }
}

/// Base ticks between a node's ticks, from its period: `round(period / dt)`, refused when
/// below 1 or when `every * dt` differs from `period` by more than `1e-9 * max(1, period)`.
///
/// ASSUMPTION: a period within `1e-9` (relative, at least absolute below 1 s) of a whole
/// multiple of `dt` is that multiple (periods written as `1 / hz` are not exact in binary).
pub fn ticks_between(index: usize, period: f64, dt: f64) -> Result<u64, ScheduleError> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(ScheduleError::BadDt(dt));
    }
    if !(period.is_finite() && period > 0.0) {
        return Err(ScheduleError::BadPeriod { index, period });
    }
    let every = (period / dt).round_ties_even();
    if !(1.0..=1e15).contains(&every) || (every * dt - period).abs() > 1e-9 * period.max(1.0) {
        return Err(ScheduleError::NotMultiple { index, period, dt });
    }
    Ok(every as u64)
}

/// The nodes' periods in base ticks and offsets, and the nodes due at the selected tick.
#[derive(Clone, Debug)]
pub struct TickSchedule {
    every: Vec<u64>,
    offset: Vec<u64>,
    due: Vec<usize>,
    len: usize,
}

impl TickSchedule {
    /// The schedule of nodes with `periods` [s] and `offsets` [base ticks] at base tick `dt`.
    pub fn new(dt: f64, periods: &[f64], offsets: &[u64]) -> Result<Self, ScheduleError> {
        if periods.len() != offsets.len() {
            return Err(ScheduleError::Lengths {
                periods: periods.len(),
                offsets: offsets.len(),
            });
        }
        if !(dt.is_finite() && dt > 0.0) {
            return Err(ScheduleError::BadDt(dt));
        }
        let mut every = Vec::with_capacity(periods.len());
        for (index, (&period, &offset)) in periods.iter().zip(offsets).enumerate() {
            let e = ticks_between(index, period, dt)?;
            if offset >= e {
                return Err(ScheduleError::BadOffset {
                    index,
                    offset,
                    every: e,
                });
            }
            every.push(e);
        }
        Ok(TickSchedule {
            every,
            offset: offsets.to_vec(),
            due: vec![0; periods.len()],
            len: 0,
        })
    }

    /// Base ticks between node `i`'s ticks.
    pub fn every(&self, i: usize) -> u64 {
        self.every[i]
    }

    /// Whether node `i` ticks at base tick `k`.
    pub fn is_due(&self, i: usize, k: u64) -> bool {
        k % self.every[i] == self.offset[i]
    }

    /// Select base tick `k`: the nodes due at it, in node order, become [`due`](Self::due)'s
    /// `0..` (returns how many).
    pub fn select(&mut self, k: u64) -> usize {
        let mut n = 0;
        for i in 0..self.every.len() {
            if k % self.every[i] == self.offset[i] {
                self.due[n] = i;
                n += 1;
            }
        }
        self.len = n;
        n
    }

    /// The `j`-th node due at the selected tick (`j` below what [`select`](Self::select)
    /// returned).
    pub fn due(&self, j: usize) -> usize {
        self.due[..self.len][j]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn periods_of_one_over_hz_become_whole_tick_counts() {
        let periods = [1.0 / 40.0, 1.0 / 200.0, 0.001, 1.0 / 500.0, 1.0];
        let s = TickSchedule::new(0.001, &periods, &[0; 5]).unwrap();
        let every: Vec<u64> = (0..5).map(|i| s.every(i)).collect();
        assert_eq!(every, [25, 5, 1, 2, 1000]);
    }

    #[test]
    fn selected_nodes_are_those_with_the_offset_remainder_in_node_order() {
        // Independent count: node i ticks at offset[i], offset[i] + every[i], ...
        let periods = [0.001, 0.005, 0.025, 0.005];
        let offsets = [0, 2, 7, 0];
        let mut s = TickSchedule::new(0.001, &periods, &offsets).unwrap();
        let every = [1u64, 5, 25, 5];
        let mut expected: Vec<Vec<usize>> = vec![Vec::new(); 200];
        for i in 0..4 {
            let mut k = offsets[i];
            while k < 200 {
                expected[k as usize].push(i);
                k += every[i];
            }
        }
        for (k, want) in expected.iter().enumerate() {
            let n = s.select(k as u64);
            let got: Vec<usize> = (0..n).map(|j| s.due(j)).collect();
            assert_eq!(&got, want, "tick {k}");
            for i in 0..4 {
                assert_eq!(s.is_due(i, k as u64), want.contains(&i));
            }
        }
    }

    #[test]
    fn bad_configurations_are_refused_with_the_node_index() {
        let e = TickSchedule::new(0.001, &[0.001, 0.0015], &[0, 0]).unwrap_err();
        assert!(matches!(e, ScheduleError::NotMultiple { index: 1, .. }));
        assert_eq!(e.index(), Some(1));
        let e = TickSchedule::new(0.001, &[f64::NAN], &[0]).unwrap_err();
        assert!(matches!(e, ScheduleError::BadPeriod { index: 0, .. }));
        let e = TickSchedule::new(0.001, &[0.002], &[2]).unwrap_err();
        assert_eq!(e.to_string(), "offset 2 not in 0..1");
        assert!(matches!(
            TickSchedule::new(0.0, &[0.001], &[0]),
            Err(ScheduleError::BadDt(_))
        ));
        assert!(matches!(
            TickSchedule::new(0.001, &[0.001], &[]),
            Err(ScheduleError::Lengths { .. })
        ));
        assert!(matches!(
            TickSchedule::new(0.001, &[0.0004], &[0]),
            Err(ScheduleError::NotMultiple { .. })
        ));
    }
}
