//! The on-chip event filters of Prophesee's sensors (the Event Signal Processing block of the
//! Gen4.1 / IMX636, the EVK4's sensor; docs.prophesee.ai/stable/hw/manuals/esp.html), for
//! events from any source: the anti-flicker filter (`afk`), the event trail filter in its TRAIL
//! and STC types (`event_trail`, `trail`, `stc`) and the event rate controller (`erc`). Each file
//! states its rule and the sources it comes from.
//!
//! A `FilterChain` runs the filters that are on, in the order the ESP documentation lists them
//! (AFK, event trail, ERC; the ERC last, so that it holds the rate of what leaves the chip), on
//! a stream of events in time order given in batches of any size. State is kept per pixel or
//! region across batches, and the only decisions that wait are the ERC's on its current period,
//! so a stream filtered whole or batch by batch gives the same events. Everything is sequential
//! and integer (time in whole microseconds): the result does not depend on threads or machine.

mod afk;
mod erc;
mod event_trail;
mod pixel_map;
mod stc;
#[cfg(test)]
mod tests;
mod trail;

use std::fmt;

pub use afk::{AfkMode, AfkSettings, AFK_MAX_HZ, AFK_MAX_THRESHOLD, AFK_MIN_HZ};
pub use erc::{ErcSettings, ERC_DEFAULT_PERIOD_US};
pub use event_trail::TrailMode;

use afk::AntiFlicker;
// The sensor's readout runs the rate controller alone, on events it has already ordered.
pub(crate) use erc::EventRateController;
use event_trail::EventTrailFilter;

/// The event trail filter's threshold range (whole milliseconds).
pub const TRAIL_MIN_MS: u32 = 1;
pub const TRAIL_MAX_MS: u32 = 100;

/// Bad settings or bad input; the message is one line meant for the user.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FilterError {
    pub message: String,
}

impl FilterError {
    fn new(message: String) -> Self {
        Self { message }
    }
}

impl fmt::Display for FilterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for FilterError {}

/// The event trail filter's type and threshold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TrailSettings {
    pub mode: TrailMode,
    pub threshold_ms: u32,
}

impl TrailSettings {
    pub fn validate(&self) -> Result<(), FilterError> {
        let ms = self.threshold_ms;
        if !(TRAIL_MIN_MS..=TRAIL_MAX_MS).contains(&ms) {
            return Err(FilterError::new(format!(
                "event trail threshold {ms} ms: needs {TRAIL_MIN_MS}-{TRAIL_MAX_MS} whole ms"
            )));
        }
        Ok(())
    }
}

/// Which filters are on, and their settings; a filter left None is off.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FilterSettings {
    pub afk: Option<AfkSettings>,
    pub trail: Option<TrailSettings>,
    pub erc: Option<ErcSettings>,
}

impl FilterSettings {
    pub fn validate(&self) -> Result<(), FilterError> {
        self.afk.as_ref().map_or(Ok(()), AfkSettings::validate)?;
        self.trail
            .as_ref()
            .map_or(Ok(()), TrailSettings::validate)?;
        self.erc.as_ref().map_or(Ok(()), ErcSettings::validate)
    }
}

/// Events in, and dropped by each filter, since the chain was made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FilterCounts {
    pub events_in: u64,
    pub afk_dropped: u64,
    pub trail_dropped: u64,
    pub erc_dropped: u64,
    /// Events decided and passed (held events are in none of the counts but `events_in`).
    pub events_out: u64,
}

/// The filters that are on, with their state, over one stream of events in time order.
pub struct FilterChain {
    afk: Option<AntiFlicker>,
    trail: Option<EventTrailFilter>,
    erc: Option<EventRateController>,
    last_t_us: Option<i64>,
    counts: FilterCounts,
}

impl FilterChain {
    /// A chain for a sensor of about `width` x `height` pixels (a size hint only: any 16-bit
    /// address is taken; 0 x 0 when it is not known).
    pub fn new(
        settings: &FilterSettings,
        width: usize,
        height: usize,
    ) -> Result<Self, FilterError> {
        settings.validate()?;
        Ok(Self {
            afk: settings
                .afk
                .map(|afk| AntiFlicker::new(&afk, width, height)),
            trail: settings
                .trail
                .map(|trail| EventTrailFilter::new(trail.mode, trail.threshold_ms, width, height)),
            erc: settings.erc.map(|erc| EventRateController::new(&erc)),
            last_t_us: None,
            counts: FilterCounts::default(),
        })
    }

    /// Filters the next events of the stream (columns of equal length, t non-decreasing and not
    /// before the last event pushed; polarity ON where p > 0). Returns a verdict (pass or not)
    /// for each event decided now: the events held from earlier calls first, then these, in
    /// order; the last `held()` events after the call wait for a later call or `finish`. Bad
    /// input is refused before any state changes.
    pub fn push(
        &mut self,
        t: &[i64],
        x: &[u16],
        y: &[u16],
        p: &[i8],
    ) -> Result<Vec<bool>, FilterError> {
        self.check(t, x, y, p)?;
        let mut verdicts = Vec::with_capacity(self.held() + t.len());
        for i in 0..t.len() {
            let (t_us, on) = (t[i], p[i] > 0);
            let mut passed = true;
            if let Some(afk) = &mut self.afk {
                passed = afk.keeps(t_us, x[i], y[i], on);
                self.counts.afk_dropped += u64::from(!passed);
            }
            if let Some(trail) = &mut self.trail {
                // The trail filter sees only what the anti-flicker filter let through.
                if passed {
                    passed = trail.keeps(t_us, x[i], y[i], on);
                    self.counts.trail_dropped += u64::from(!passed);
                }
            }
            match &mut self.erc {
                Some(erc) => self.counts.erc_dropped += erc.push(t_us, passed, &mut verdicts),
                None => verdicts.push(passed),
            }
        }
        self.counts.events_in += t.len() as u64;
        if let Some(&last) = t.last() {
            self.last_t_us = Some(last);
        }
        self.count_out(&verdicts);
        Ok(verdicts)
    }

    /// Ends the stream: verdicts for the held events. The chain can go on afterwards (a new
    /// ERC period starts with the next event).
    pub fn finish(&mut self) -> Vec<bool> {
        let mut verdicts = Vec::with_capacity(self.held());
        if let Some(erc) = &mut self.erc {
            self.counts.erc_dropped += erc.close(&mut verdicts);
        }
        self.count_out(&verdicts);
        verdicts
    }

    /// Events pushed whose verdict waits for the end of their ERC period.
    pub fn held(&self) -> usize {
        self.erc.as_ref().map_or(0, EventRateController::held)
    }

    pub fn counts(&self) -> FilterCounts {
        self.counts
    }

    fn count_out(&mut self, verdicts: &[bool]) {
        self.counts.events_out += verdicts.iter().filter(|&&kept| kept).count() as u64;
    }

    /// Columns of one length, times in order from the last event pushed on.
    fn check(&self, t: &[i64], x: &[u16], y: &[u16], p: &[i8]) -> Result<(), FilterError> {
        let n = t.len();
        if x.len() != n || y.len() != n || p.len() != n {
            return Err(FilterError::new(format!(
                "event columns differ in length: t {n}, x {}, y {}, p {}",
                x.len(),
                y.len(),
                p.len()
            )));
        }
        let mut previous = self.last_t_us.unwrap_or(i64::MIN);
        for &t_us in t {
            if t_us < previous {
                return Err(FilterError::new(format!(
                    "events out of time order: t = {t_us} us comes after t = {previous} us; the \
                     on-chip filters take events sorted by t"
                )));
            }
            previous = t_us;
        }
        Ok(())
    }
}
