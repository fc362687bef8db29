//! The row arbiter: pixels that fired wait in their row until the arbiter grants the row; a
//! grant hands the bus every event waiting in that row (a row burst), as the AER readout of a
//! DVS does (row request, row acknowledge, then the row's columns). Rows are served oldest
//! request first (a request is raised when a row's first waiting event arrives; ties by the
//! lower row), so under light load events leave in the order they came, (t, y, x).
//!
//! Queueing: with one grant at a time of service time T_row and arrivals at rate lambda, this is
//! the M/D/1 queue of an arbiter tree's root (Gorni and Deptuch, arXiv 2511.03705): the mean
//! wait is `rho T / (2 (1 - rho))` with `rho = lambda T`, and above `rho = 1` the queue grows
//! without bound. Above it, what the sensor does is its firmware's: the events wait (the
//! pixels hold their requests: Prophesee's "backpressure", timestamps then fall behind real
//! time), or, with a queue of `depth` events, an event that finds the queue full is dropped
//! (libcaer's `DROP_DVS_ON_TRANSFER_STALL`, on by default on the DAVIS).
//!
//! Without a row service time (a bus limit only) a grant carries one event: a plain FIFO.

use std::collections::VecDeque;

use super::bus::PS_PER_US;
use crate::events::Event;

/// Events waiting in their rows, and the rows' requests.
///
/// Events arrive in (t, y, x) order, so rows raise their requests in (time, row) order: the
/// oldest request is always the first still waiting, and a FIFO of requests is the priority
/// queue of the arbiter.
#[derive(Debug, Default)]
pub(super) struct RowArbiter {
    /// Waiting events of each row (indexed by y), in arrival order (a row arbiter).
    rows: Vec<VecDeque<Event>>,
    /// Rows with waiting events: (request time in ps, row), oldest first.
    requests: VecDeque<(i128, u16)>,
    /// Waiting events in arrival order (a bus alone: a grant takes one event).
    fifo: VecDeque<Event>,
    /// Events waiting in all rows.
    waiting: usize,
    /// A grant drains the whole row (a row arbiter) or takes one event (a FIFO).
    whole_rows: bool,
    /// Most events that may wait; 0 = no bound (they wait, however long).
    depth: usize,
}

impl RowArbiter {
    pub(super) fn new(whole_rows: bool, depth: usize) -> Self {
        Self {
            whole_rows,
            depth,
            ..Self::default()
        }
    }

    pub(super) fn waiting(&self) -> usize {
        self.waiting
    }

    /// The earliest request, if any event waits.
    #[inline]
    pub(super) fn next_request_ps(&self) -> Option<i128> {
        if self.whole_rows {
            self.requests.front().map(|&(t_ps, _)| t_ps)
        } else {
            self.fifo.front().map(|e| i128::from(e.t_us) * PS_PER_US)
        }
    }

    /// An event arrives at `t_ps` (events arrive in (t, y, x) order); false when the queue is
    /// full and it is dropped.
    #[inline]
    pub(super) fn arrive(&mut self, e: Event, t_ps: i128) -> bool {
        if self.depth > 0 && self.waiting >= self.depth {
            return false;
        }
        self.waiting += 1;
        if !self.whole_rows {
            self.fifo.push_back(e);
            return true;
        }
        let y = usize::from(e.y);
        if y >= self.rows.len() {
            self.rows.resize_with(y + 1, VecDeque::new);
        }
        let row = &mut self.rows[y];
        if row.is_empty() {
            self.requests.push_back((t_ps, e.y));
        }
        row.push_back(e);
        true
    }

    /// Grant the earliest request: the events it hands to the bus, in their row's order, into
    /// `burst` (cleared first).
    pub(super) fn grant(&mut self, burst: &mut Vec<Event>) {
        burst.clear();
        if !self.whole_rows {
            burst.extend(self.fifo.pop_front());
        } else if let Some((_, y)) = self.requests.pop_front() {
            burst.extend(self.rows[usize::from(y)].drain(..));
        }
        self.waiting -= burst.len();
    }
}
