//! The lockstep loop's schedule: which node ticks at which base tick.
//!
//! Time advances in base ticks of `dt`. Node `i` has a period that is a whole number
//! `every[i]` of base ticks and an offset `offset[i]` in `0..every[i]`; it ticks at the base
//! ticks `k` with `k % every[i] == offset[i]`, in the order the nodes were given. At setup the
//! schedule lists the nodes due at each residue of `k` modulo the least common multiple of
//! the `every`s (one remainder per tick then); when that cycle is longer than
//! [`MAX_CYCLE`] ticks it tests every node at every tick instead (one remainder per node)
//! into a buffer sized at setup. Selecting the nodes of a tick allocates nothing.

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

/// Longest cycle (base ticks) listed at setup.
pub const MAX_CYCLE: u64 = 100_000;

/// The nodes' periods in base ticks and offsets, and the nodes due at the selected tick.
#[derive(Clone, Debug)]
pub struct TickSchedule {
    every: Vec<u64>,
    offset: Vec<u64>,
    /// Length of the listed cycle (0: none, every node tested at every tick).
    cycle: u64,
    /// The nodes due at residue `r` are `table[starts[r]..starts[r + 1]]`.
    starts: Vec<usize>,
    table: Vec<usize>,
    /// Without a listed cycle: the nodes due at the selected tick.
    scanned: Vec<usize>,
    from: usize,
    len: usize,
}

/// The least common multiple of `every`, or None when it exceeds [`MAX_CYCLE`].
fn cycle_of(every: &[u64]) -> Option<u64> {
    let mut cycle: u64 = 1;
    for &e in every {
        let (mut a, mut b) = (cycle, e);
        while b != 0 {
            (a, b) = (b, a % b);
        }
        cycle = (cycle / a).checked_mul(e).filter(|&c| c <= MAX_CYCLE)?;
    }
    Some(cycle)
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
        let mut s = TickSchedule {
            cycle: 0,
            starts: Vec::new(),
            table: Vec::new(),
            scanned: vec![0; every.len()],
            every,
            offset: offsets.to_vec(),
            from: 0,
            len: 0,
        };
        if let Some(cycle) = cycle_of(&s.every) {
            let (every, offset) = (&s.every, &s.offset);
            s.starts.reserve(cycle as usize + 1);
            s.starts.push(0);
            for r in 0..cycle {
                s.table
                    .extend((0..every.len()).filter(|&i| r % every[i] == offset[i]));
                s.starts.push(s.table.len());
            }
            s.cycle = cycle;
        }
        Ok(s)
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
        if self.cycle > 0 {
            let r = (k % self.cycle) as usize;
            self.from = self.starts[r];
            self.len = self.starts[r + 1] - self.from;
            return self.len;
        }
        let mut n = 0;
        for i in 0..self.every.len() {
            if k % self.every[i] == self.offset[i] {
                self.scanned[n] = i;
                n += 1;
            }
        }
        self.len = n;
        n
    }

    /// The `j`-th node due at the selected tick (`j` below what [`select`](Self::select)
    /// returned).
    pub fn due(&self, j: usize) -> usize {
        if self.cycle > 0 {
            self.table[self.from..self.from + self.len][j]
        } else {
            self.scanned[..self.len][j]
        }
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

    /// The nodes due at each of `ticks` ticks, counted independently: node i ticks at
    /// offset[i], offset[i] + every[i], ...
    fn expected(every: &[u64], offsets: &[u64], ticks: usize) -> Vec<Vec<usize>> {
        let mut out: Vec<Vec<usize>> = vec![Vec::new(); ticks];
        for i in 0..every.len() {
            let mut k = offsets[i];
            while k < ticks as u64 {
                out[k as usize].push(i);
                k += every[i];
            }
        }
        out
    }

    fn check(s: &mut TickSchedule, want: &[Vec<usize>], from: u64) {
        for (k, want) in (from..).zip(want) {
            let n = s.select(k);
            let got: Vec<usize> = (0..n).map(|j| s.due(j)).collect();
            assert_eq!(&got, want, "tick {k}");
            for i in 0..s.every.len() {
                assert_eq!(s.is_due(i, k), want.contains(&i));
            }
        }
    }

    #[test]
    fn selected_nodes_are_those_with_the_offset_remainder_in_node_order() {
        let periods = [0.001, 0.005, 0.025, 0.005];
        let offsets = [0, 2, 7, 0];
        let mut s = TickSchedule::new(0.001, &periods, &offsets).unwrap();
        assert_eq!(s.cycle, 25);
        check(&mut s, &expected(&[1, 5, 25, 5], &offsets, 200), 0);
    }

    #[test]
    fn a_cycle_too_long_to_list_tests_every_node_at_every_tick() {
        // lcm(997, 991) = 988_027 ticks: no table, the same nodes selected.
        let offsets = [3, 990, 0];
        let mut s = TickSchedule::new(1.0, &[997.0, 991.0, 2.0], &offsets).unwrap();
        assert_eq!(s.cycle, 0);
        let want = expected(&[997, 991, 2], &offsets, 3000);
        check(&mut s, &want, 0);
        let listed_offsets = [3, 90, 1];
        let mut listed = TickSchedule::new(1.0, &[97.0, 91.0, 2.0], &listed_offsets).unwrap();
        assert_eq!(listed.cycle, 97 * 91 * 2);
        check(
            &mut listed,
            &expected(&[97, 91, 2], &listed_offsets, 20_000),
            0,
        );
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
