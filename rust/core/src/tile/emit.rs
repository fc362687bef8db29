//! A tile's events as they come out: a pixel's event at t_s seconds since the first frame becomes
//! one at t_us = max(origin_us + round(1e6 t_s), floor_us), x = pixel % width, y = pixel / width;
//! they are counted on the call's fuse every `REPORT_EVERY_EVENTS`, one compare a pixel.

use super::Tile;
use crate::events::{Event, EventRun};
use crate::fuse::{EventFuse, REPORT_EVERY_EVENTS};
use crate::pixel::PixelEvent;

/// Turns a pixel's event (seconds since the first frame) into an output event.
pub struct Clock {
    pub origin_us: i64,
    /// Events of this frame come after the previous frame's time, even when rounding says not.
    pub floor_us: i64,
    pub width: usize,
}

impl Clock {
    #[inline]
    fn address(&self, pixel: usize) -> (u16, u16) {
        ((pixel % self.width) as u16, (pixel / self.width) as u16)
    }

    #[inline]
    fn event(&self, (x, y): (u16, u16), e: PixelEvent) -> Event {
        Event {
            // Rounded half up by adding 0.5 and truncating, exact for the t_s >= 0 of events
            // (f64::round is a library call on baseline x86-64).
            t_us: (self.origin_us + (e.t_s * 1e6 + 0.5) as i64).max(self.floor_us),
            x,
            y,
            p: e.on as i8,
            label: e.cause as u8,
        }
    }
}

/// One pixel's events of a frame as the pixel model emits them, into the tile's run.
pub(super) struct PixelEvents<'a> {
    run: &'a mut EventRun,
    clock: &'a Clock,
    pixel: usize,
    /// The address costs a division: worked out only once the pixel has an event.
    address: Option<(u16, u16)>,
    mark: usize,
}

impl<'a> PixelEvents<'a> {
    #[inline(always)]
    pub(super) fn open(run: &'a mut EventRun, clock: &'a Clock, pixel: usize) -> Self {
        let mark = run.mark();
        Self {
            run,
            clock,
            pixel,
            address: None,
            mark,
        }
    }

    #[inline(always)]
    pub(super) fn push(&mut self, e: PixelEvent) {
        let (clock, pixel) = (self.clock, self.pixel);
        let address = *self.address.get_or_insert_with(|| clock.address(pixel));
        self.run.push(clock.event(address, e));
    }

    /// The pixel's events are all in (see `EventRun::close_pixel`).
    #[inline(always)]
    pub(super) fn close(self) {
        self.run.close_pixel(self.mark);
    }
}

/// The tile's events counted on the fuse so far, and the count at which to report again: one
/// compare a pixel (a pixel's events are bounded by its log range over theta_min).
pub(super) struct FuseCount {
    pub(super) reported: usize,
    pub(super) report_at: usize,
}

impl Tile {
    /// `report` once this frame's events reach `count.report_at` (one compare a pixel); returns
    /// whether to go on.
    #[inline(always)]
    pub(super) fn report_if_due(&mut self, fuse: &EventFuse, count: &mut FuseCount) -> bool {
        if self.events.len() < count.report_at {
            return true;
        }
        let go_on = self.report(fuse, &mut count.reported);
        count.report_at = count.reported + REPORT_EVERY_EVENTS;
        go_on
    }

    /// Count the events since the last report on the fuse and make room for the next ones, and
    /// for a pixel's that pass the next report (a growth that fails blows the fuse instead of
    /// aborting); returns whether to go on.
    #[cold]
    fn report(&mut self, fuse: &EventFuse, reported: &mut usize) -> bool {
        let count = self.events.len();
        let go_on = fuse.add(count - *reported);
        *reported = count;
        if go_on && !self.events.try_reserve(2 * REPORT_EVERY_EVENTS) {
            fuse.out_of_memory();
            return false;
        }
        go_on
    }
}
