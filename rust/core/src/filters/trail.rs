//! TRAIL: keep the first event of each burst (burst as defined in `event_trail.rs`).
//!
//! "Trail retains the first event of a burst after a polarity transition and cancels events of
//! the same polarity that are generated within the Trail threshold period"
//! (docs.prophesee.ai/stable/hw/manuals/esp.html); "TRAIL: filters out trailing events from
//! event bursts, keeping only the first event" (OpenEB `i_event_trail_filter_module.h`). The
//! Metavision SDK's `TrailFilterAlgorithm` states the same rule event by event: an event passes
//! when the pixel's last event had the other polarity, or came at least the threshold before it.
//! So a same-polarity event exactly the threshold after the previous one starts a new burst and
//! passes; one 1 us sooner is trail and is dropped.

/// Whether TRAIL keeps the event at `position` in its burst (1 = first).
#[inline]
pub(crate) fn keeps(position: u8) -> bool {
    position == 1
}
