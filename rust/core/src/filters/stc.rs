//! STC (spatio-temporal contrast): keep the second event of each burst, so an isolated event
//! (a burst of one) never passes (burst as defined in `event_trail.rs`).
//!
//! "Spatio-Temporal-Contrast (STC) retains the second event of a burst. Hence, STC filters out
//! isolated events" (docs.prophesee.ai/stable/hw/manuals/esp.html). Its two types (OpenEB
//! `i_event_trail_filter_module.h`):
//! - STC_CUT_TRAIL "filters out the first event of a burst as well as trailing events after the
//!   second event, keeping only the second event from the burst. Single events are filtered
//!   out": position 2 only.
//! - STC_KEEP_TRAIL "filters out the first event of burst, keeping all the trailing events from
//!   the burst. Single events are filtered out": positions 2 and later.
//!
//! Every burst is judged on its own, as the documentation and Prophesee's patent (US 11,689,824
//! B2: an event passes when it is part of "a previously unaccepted event trail") describe: a
//! new burst of the same polarity after a gap of at least the threshold has its second event
//! kept. (The Metavision SDK's software `SpatioTemporalContrastAlgorithm` with cut_trail instead
//! cuts every event up to the next polarity change, a difference its own comment notes.)
//! A second event exactly the threshold after the first starts a new burst (the patent's
//! "shorter than"), as in TRAIL; the SDK's software STC counts it inside, a 1 us difference
//! below the chip's time tick.

/// Whether STC keeps the event at `position` in its burst (1 = first); `cut_trail` for
/// STC_CUT_TRAIL, else STC_KEEP_TRAIL.
#[inline]
pub(crate) fn keeps(position: u8, cut_trail: bool) -> bool {
    if cut_trail {
        position == 2
    } else {
        position >= 2
    }
}
