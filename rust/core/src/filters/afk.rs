//! AFK, the anti-flicker filter: drops (band-stop) or keeps only (band-pass) the events of 4 x 4
//! pixel regions that flicker at a frequency inside a band of 50-520 Hz.
//!
//! What Prophesee documents, and this model takes as it is:
//! - "The anti-flicker function detects and cancels flicker events in 4x4 divided pixel regions"
//!   (docs.prophesee.ai/stable/hw/manuals/esp.html).
//! - The band: 50 <= low < high <= 520 Hz (OpenEB `antiflicker_filter.cpp`,
//!   `get_min/max_supported_frequency`), given to the chip as periods in 128 us units:
//!   `period = (1e6 / f) >> 7` (`freq_to_period`); the longest period in the band is that of
//!   the low frequency (`max_cutoff_period`), the shortest that of the high one
//!   (`min_cutoff_period`). 50-520 Hz is 156 and 15 units: periods of 1920-20095 us.
//! - BAND_STOP removes the events of flickering regions; BAND_PASS "removes all events outside
//!   of the band" (OpenEB `i_antiflicker_module.h`), i.e. keeps only those.
//! - A hysteresis of two counters, a start and a stop threshold of 0-7 (OpenEB `counter_high`
//!   and `counter_low`; 6 and 4 are the values Prophesee's tools start from).
//!
//! How the chip measures a region's frequency is not published; this model measures it as the
//! Metavision SDK's software `AntiFlickerAlgorithm` (which Prophesee calls "mostly equivalent" to
//! the hardware filter) does for one pixel: a flickering light makes runs of ON events and runs
//! of OFF events, and the time from the start of one ON run to the start of the next (likewise
//! OFF) is the light's period. Per region:
//! 1. An event whose polarity differs from the region's previous event (or its first event)
//!    starts a run of that polarity. If the region had a run of that polarity before, the time
//!    since that run started is one period measurement: `units = period_us >> 7`.
//! 2. A measurement in the band (`min_cutoff <= units <= max_cutoff`) raises the region's
//!    counter by one (at most 7); one outside lowers it by one (at least 0). At `counter >=
//!    start` the region is flickering; at `counter <= stop` it no longer is (in between it stays
//!    as it was).
//! 3. A region with no new run for longer than the longest period in the band cannot be
//!    flickering inside it: its counter returns to 0 and it is not flickering (the chip has an
//!    invalidation timeout computed from `max_cutoff_period`, OpenEB `compute_invalidation`).
//! 4. The event passes, in band-stop, when its region is not flickering (after 1-3 with this
//!    event); in band-pass, when it is.
//!
//! Not modelled: the duty-cycle setting (1/16 steps), whose effect inside a period is not
//! documented; every event of a flickering region counts as flicker.

use super::pixel_map::PixelMap;
use super::FilterError;

/// The least and greatest band frequencies the chip takes (Hz).
pub const AFK_MIN_HZ: u32 = 50;
pub const AFK_MAX_HZ: u32 = 520;
/// The hysteresis counter's greatest value (3 bits).
pub const AFK_MAX_THRESHOLD: u8 = 7;
/// The chip's unit of period (us): periods are counted in 128 us steps.
const PERIOD_UNIT_BITS: u32 = 7;
/// Side of a region, in pixels.
const REGION_BITS: u32 = 2;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AfkMode {
    /// Drop the events of flickering regions.
    BandStop,
    /// Keep only the events of flickering regions.
    BandPass,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AfkSettings {
    pub low_hz: u32,
    pub high_hz: u32,
    pub mode: AfkMode,
    /// The counter at which a region becomes flickering.
    pub start_threshold: u8,
    /// The counter at which a flickering region stops being so.
    pub stop_threshold: u8,
}

impl AfkSettings {
    pub fn validate(&self) -> Result<(), FilterError> {
        let (low, high) = (self.low_hz, self.high_hz);
        if !(AFK_MIN_HZ <= low && low < high && high <= AFK_MAX_HZ) {
            return Err(FilterError::new(format!(
                "anti-flicker band {low}-{high} Hz: needs {AFK_MIN_HZ} <= low < high <= \
                 {AFK_MAX_HZ} Hz"
            )));
        }
        let (start, stop) = (self.start_threshold, self.stop_threshold);
        if !(stop < start && start <= AFK_MAX_THRESHOLD) {
            return Err(FilterError::new(format!(
                "anti-flicker thresholds start {start}, stop {stop}: needs 0 <= stop < start <= \
                 {AFK_MAX_THRESHOLD}"
            )));
        }
        Ok(())
    }

    /// The band as periods in 128 us units, (shortest, longest), as OpenEB's `freq_to_period`.
    pub fn period_units(&self) -> (i64, i64) {
        let units = |hz: u32| i64::from(1_000_000 / hz) >> PERIOD_UNIT_BITS;
        (units(self.high_hz), units(self.low_hz))
    }
}

#[derive(Clone, Copy, Default)]
struct Region {
    /// Start of the latest run of each polarity (OFF, ON), valid where `has_run` says.
    run_start_us: [i64; 2],
    has_run: [bool; 2],
    /// Polarity of the region's previous event, valid once `seen`.
    last_on: bool,
    seen: bool,
    /// When the latest run (of either polarity) started.
    last_run_start_us: i64,
    counter: u8,
    flickering: bool,
}

pub(crate) struct AntiFlicker {
    min_units: i64,
    max_units: i64,
    /// The longest period that measures inside the band (us).
    longest_period_us: i64,
    band_pass: bool,
    start: u8,
    stop: u8,
    regions: PixelMap<Region>,
}

impl AntiFlicker {
    /// `settings` must have passed `validate`.
    pub(crate) fn new(settings: &AfkSettings, width: usize, height: usize) -> Self {
        let (min_units, max_units) = settings.period_units();
        Self {
            min_units,
            max_units,
            longest_period_us: ((max_units + 1) << PERIOD_UNIT_BITS) - 1,
            band_pass: settings.mode == AfkMode::BandPass,
            start: settings.start_threshold,
            stop: settings.stop_threshold,
            regions: PixelMap::new(width.div_ceil(4), height.div_ceil(4)),
        }
    }

    /// Whether the filter passes this event (events come in time order).
    #[inline]
    pub(crate) fn keeps(&mut self, t_us: i64, x: u16, y: u16, on: bool) -> bool {
        let (min_units, max_units) = (self.min_units, self.max_units);
        let (start, stop, longest) = (self.start, self.stop, self.longest_period_us);
        let region = self.regions.get_mut(x >> REGION_BITS, y >> REGION_BITS);
        if region.seen && t_us.saturating_sub(region.last_run_start_us) > longest {
            region.counter = 0;
            region.flickering = false;
        }
        if !region.seen || region.last_on != on {
            let polarity = usize::from(on);
            if region.has_run[polarity] {
                let units = t_us.saturating_sub(region.run_start_us[polarity]) >> PERIOD_UNIT_BITS;
                region.counter = if (min_units..=max_units).contains(&units) {
                    (region.counter + 1).min(AFK_MAX_THRESHOLD)
                } else {
                    region.counter.saturating_sub(1)
                };
                if region.counter >= start {
                    region.flickering = true;
                } else if region.counter <= stop {
                    region.flickering = false;
                }
            }
            region.run_start_us[polarity] = t_us;
            region.has_run[polarity] = true;
            region.last_run_start_us = t_us;
        }
        region.last_on = on;
        region.seen = true;
        region.flickering == self.band_pass
    }
}
