//! The bus: one event at a time leaves the chip, each taking `1 / rate` (a rate of R Meps is
//! a slot of 1e6 / R ps), and one row grant at a time takes the arbiter's service time T_row.
//!
//! A grant at time g of a row holding n events keeps the bus busy until
//! `g + T_row + n / R`; the k-th event (from 1) of the burst has left at `g + T_row + k / R`,
//! and that is the time it is stamped with. The bus is free again at the end of the burst, so
//! the next grant is at `max(free, its request)`: a single server whose throughput is
//! `n / (T_row + n / R)` events per grant time, which tends to R when rows are full and to
//! 1 / T_row when each grant carries one event (the saturation of an arbiter tree at 1 / T,
//! Gorni and Deptuch, arXiv 2511.03705).
//!
//! Times are integer picoseconds in i128, exact for any i64 microsecond time: a slot of a rate
//! that is not a whole number of ps is rounded to the nearest ps (12 Meps: 83,333 ps, a rate
//! 4e-6 off).

/// Picoseconds in a microsecond: events arrive at whole microseconds.
pub(super) const PS_PER_US: i128 = 1_000_000;

#[derive(Clone, Debug)]
pub(super) struct Bus {
    /// Row grant (the arbiter's handshake with a row), ps.
    row_ps: i128,
    /// One event on the bus, ps.
    slot_ps: i128,
    /// When the bus is next free; i128::MIN before any event.
    free_ps: i128,
}

impl Bus {
    pub(super) fn new(row_service_ns: f64, rate_meps: f64) -> Self {
        let slot_ps = if rate_meps > 0.0 {
            (1e6 / rate_meps).round() as i128
        } else {
            0
        };
        Self {
            row_ps: (row_service_ns * 1e3).round() as i128,
            slot_ps,
            free_ps: i128::MIN,
        }
    }

    /// Whether events take any time at all here.
    pub(super) fn takes_time(&self) -> bool {
        self.row_ps > 0 || self.slot_ps > 0
    }

    pub(super) fn free_ps(&self) -> i128 {
        self.free_ps
    }

    /// A burst of `n` events granted at `grant_ps`: calls `leave(k, t_ps)` with each event's
    /// time of leaving (k from 0), and keeps the bus busy until the last has left.
    #[inline]
    pub(super) fn carry(&mut self, grant_ps: i128, n: usize, mut leave: impl FnMut(usize, i128)) {
        let mut t_ps = grant_ps + self.row_ps;
        for k in 0..n {
            t_ps += self.slot_ps;
            leave(k, t_ps);
        }
        self.free_ps = t_ps;
    }
}
