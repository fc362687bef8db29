//! The bound on the events one call may give, enforced while the call's tiles run: the light
//! can ask for any number of crossings (a frame at 3e38 after a dark one, thresholds at 0.01,
//! is about 9,600 events a pixel), and the events of a call are all held in memory at once.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Most events one call may give. A call returns its events at once, and simulating one takes
/// about 62 bytes at its peak (the pixel's event, the frame's sorted copy, the merge with
/// held-back events, the output columns) and about 0.4 us on one core: 5e7 events are about
/// 3 GB and tens of seconds, what a workstation can give one call. Longer gaps are simulated
/// by feeding frames in between, whose events then stream out in batches. Noise expected over a
/// gap is checked against it before any work (`EventSensor::feed` refuses the gap and changes
/// nothing); the light's crossings can only be counted as they are made, by this fuse.
pub const MAX_EVENTS_PER_FEED: usize = 50_000_000;

/// Events a tile gathers between two reports to the fuse: a report is an atomic add, rare next
/// to the events it covers, and the memory a tile may hold unreported stays small (1 MiB).
pub const REPORT_EVERY_EVENTS: usize = 1 << 16;

/// The events a call has given so far, shared by its tiles; it blows once they pass the limit
/// or memory for them cannot be had, and then every tile stops at its next report.
#[derive(Debug)]
pub struct EventFuse {
    limit: usize,
    count: AtomicUsize,
    out_of_memory: AtomicBool,
}

impl EventFuse {
    /// A fuse for one call, with `held` events already counted (those held back by latency
    /// from earlier calls, which this call's output merges with).
    pub fn new(limit: usize, held: usize) -> Self {
        Self {
            limit,
            count: AtomicUsize::new(held),
            out_of_memory: AtomicBool::new(false),
        }
    }

    /// Count `events` more; returns whether the work may go on.
    #[inline]
    pub fn add(&self, events: usize) -> bool {
        let total = self.count.fetch_add(events, Ordering::Relaxed) + events;
        total <= self.limit && !self.out_of_memory.load(Ordering::Relaxed)
    }

    /// Memory for more events could not be had: the work stops.
    pub fn out_of_memory(&self) {
        self.out_of_memory.store(true, Ordering::Relaxed);
    }

    pub fn is_blown(&self) -> bool {
        self.count() > self.limit || self.out_of_memory.load(Ordering::Relaxed)
    }

    /// Events counted so far (those of the tiles that stopped early included).
    pub fn count(&self) -> usize {
        self.count.load(Ordering::Relaxed)
    }

    pub fn limit(&self) -> usize {
        self.limit
    }

    pub fn ran_out_of_memory(&self) -> bool {
        self.out_of_memory.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blows_once_the_count_passes_the_limit_or_memory_runs_out() {
        let fuse = EventFuse::new(10, 4);
        assert!(fuse.add(6) && !fuse.is_blown()); // 10 = the limit, still allowed
        assert!(!fuse.add(1) && fuse.is_blown());
        assert_eq!(fuse.count(), 11);
        let fuse = EventFuse::new(10, 0);
        fuse.out_of_memory();
        assert!(!fuse.add(0) && fuse.is_blown() && fuse.ran_out_of_memory());
    }
}
