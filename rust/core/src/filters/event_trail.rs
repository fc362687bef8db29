//! The event trail filter of the Gen4.1 / IMX636 ESP: one block with three types, TRAIL,
//! STC_CUT_TRAIL and STC_KEEP_TRAIL (OpenEB `I_EventTrailFilterModule::Type`; Gen4.1 lacks
//! STC_KEEP_TRAIL), one of them on at a time, with one threshold of 1-100 whole milliseconds
//! (OpenEB `event_trail_filter.cpp` keeps `round(threshold_us / 1000)` ms, range [1000, 100000]
//! us). The rule of each type is in `trail.rs` and `stc.rs`; what they share, the burst, is here.
//!
//! **Burst.** "A burst is defined as events of the same polarity occurring within a threshold
//! period" (OpenEB `i_event_trail_filter_module.h`); the filter "considers successive events of
//! the same polarity generated in a short time as burst" (docs.prophesee.ai/stable/hw/manuals/
//! esp.html). Prophesee's patent on the filter (US 11,689,824 B2) states the interval exactly: an
//! event trail is "a plurality of successive events having a same polarity and separated by time
//! intervals each shorter than a time threshold". So, at one pixel, an event continues the burst
//! of the pixel's previous event when it has the same polarity and comes less than the threshold
//! after it (`t - t_prev < threshold`); otherwise (first event of the pixel, polarity changed, or
//! `t - t_prev >= threshold`) it starts a new burst. The interval is measured from the pixel's
//! previous event, kept or not: the IMX636 updates its last timestamp at every event (OpenEB
//! writes `enable_last_ts_update_at_every_event = 1` for it), and Prophesee's software filters
//! (Metavision SDK `TrailFilterAlgorithm`, `SpatioTemporalContrastAlgorithm`) do the same.
//!
//! The chip counts time in coarse ticks (a prescaler and multiplier per threshold, OpenEB's
//! `gen41_stc_threshold_params`), so its boundary is exact only to a tick; here time is whole
//! microseconds and the boundary exact.

use super::pixel_map::PixelMap;
use super::{stc, trail};

/// Which events of a burst the event trail filter keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrailMode {
    /// TRAIL: the first event of each burst.
    Trail,
    /// STC_CUT_TRAIL: the second event of each burst only.
    StcCutTrail,
    /// STC_KEEP_TRAIL: every event of a burst but its first.
    StcKeepTrail,
}

/// A pixel's last event, and where it stood in its burst.
#[derive(Clone, Copy, Default)]
struct PixelBurst {
    last_t_us: i64,
    last_on: bool,
    /// 0 before the pixel's first event; then 1, 2, and 3 for the third event and any later.
    position: u8,
}

/// Position of each event in its pixel's burst, and the mode's verdict on it.
pub(crate) struct EventTrailFilter {
    mode: TrailMode,
    threshold_us: i64,
    pixels: PixelMap<PixelBurst>,
}

impl EventTrailFilter {
    pub(crate) fn new(mode: TrailMode, threshold_ms: u32, width: usize, height: usize) -> Self {
        Self {
            mode,
            threshold_us: i64::from(threshold_ms) * 1000,
            pixels: PixelMap::new(width, height),
        }
    }

    /// Whether the filter passes this event (events come in time order).
    #[inline]
    pub(crate) fn keeps(&mut self, t_us: i64, x: u16, y: u16, on: bool) -> bool {
        let position = self.position(t_us, x, y, on);
        match self.mode {
            TrailMode::Trail => trail::keeps(position),
            TrailMode::StcCutTrail => stc::keeps(position, true),
            TrailMode::StcKeepTrail => stc::keeps(position, false),
        }
    }

    /// 1 for the first event of a burst, 2 for the second, 3 for the third and any later.
    #[inline]
    fn position(&mut self, t_us: i64, x: u16, y: u16, on: bool) -> u8 {
        let threshold_us = self.threshold_us;
        let pixel = self.pixels.get_mut(x, y);
        let continues = pixel.position > 0
            && pixel.last_on == on
            && t_us.saturating_sub(pixel.last_t_us) < threshold_us;
        pixel.position = if continues {
            (pixel.position + 1).min(3)
        } else {
            1
        };
        pixel.last_t_us = t_us;
        pixel.last_on = on;
        pixel.position
    }
}
