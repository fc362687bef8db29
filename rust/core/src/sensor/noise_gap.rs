//! The noise a gap between frames would give, at most (pixels (leak + shot) + hot pixels hot rate)
//! gap_s expected events, which `EventSensor::feed` bounds by the limit of a call before any work.

use std::fmt;

use crate::fuse::MAX_EVENTS_PER_FEED;
use crate::params::SensorParams;

/// Noise a gap between frames would give, when it is too much for one call.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseWork {
    pub t_us: i64,
    pub t_prev_us: i64,
    pub expected_events: f64,
    pub rates: NoiseRates,
}

/// Expected noise event rates of a whole sensor, from its parameters alone.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseRates {
    pub pixels: usize,
    /// Leak plus shot noise of one pixel, shot noise at its largest (in the dark).
    pub per_pixel_hz: f64,
    pub hot_pixels: f64,
    pub hot_pixel_rate_hz: f64,
}

impl NoiseRates {
    /// Leak rates average `leak_rate_hz` over pixels (log-normal around it); shot noise is at
    /// most `shot_rate_hz` (its rate falls with light); a fraction of pixels is hot.
    pub fn of(p: &SensorParams) -> Self {
        let pixels = p.width * p.height;
        let hot = p.hot_pixel_fraction > 0.0 && p.hot_pixel_rate_hz > 0.0;
        Self {
            pixels,
            per_pixel_hz: p.leak_rate_hz + p.shot_rate_hz,
            hot_pixels: if hot {
                p.hot_pixel_fraction * pixels as f64
            } else {
                0.0
            },
            hot_pixel_rate_hz: p.hot_pixel_rate_hz,
        }
    }

    /// Expected events per second over the whole sensor, at most.
    pub fn total_hz(&self) -> f64 {
        self.pixels as f64 * self.per_pixel_hz + self.hot_pixels * self.hot_pixel_rate_hz
    }

    /// Expected events over a gap, at most.
    pub fn expected_events(&self, gap_us: i64) -> f64 {
        self.total_hz() * gap_us as f64 * 1e-6
    }
}

impl fmt::Display for NoiseWork {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let r = &self.rates;
        let gap_s = (self.t_us - self.t_prev_us) as f64 * 1e-6;
        let max_gap_s = MAX_EVENTS_PER_FEED as f64 / r.total_hz();
        write!(
            f,
            "t_us = {}: a gap of {} after {} would give about {:.2e} noise events \
             ({} pixels at up to {} Hz of leak and shot noise each, {:.0} hot pixels at {} Hz), \
             more than the {:.0e} one call may give (about 3 GB of \
             memory while they are simulated); feed frames at most {} apart",
            self.t_us,
            duration(gap_s, 1),
            self.t_prev_us,
            self.expected_events,
            r.pixels,
            r.per_pixel_hz,
            r.hot_pixels,
            r.hot_pixel_rate_hz,
            MAX_EVENTS_PER_FEED as f64,
            duration(max_gap_s, 3),
        )
    }
}

/// A duration in the unit that shows it: seconds from 1 s, else milliseconds from 1 ms, else
/// microseconds, with `decimals` places (a 1 ms gap in seconds to one place read "0.0 s").
pub(super) fn duration(seconds: f64, decimals: usize) -> String {
    if seconds >= 1.0 {
        format!("{seconds:.decimals$} s")
    } else if seconds >= 1e-3 {
        format!("{:.decimals$} ms", seconds * 1e3)
    } else {
        format!("{:.decimals$} us", seconds * 1e6)
    }
}
