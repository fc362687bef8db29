//! The readout: how the events the pixels made leave the chip, after the pixel solve.
//!
//! Stages, a file each, in the order events pass them:
//! - `arbiter`: the row arbiter, a queue of row requests (M/D/1 under load) that hands a granted
//!   row's waiting events to the bus together, and what happens when its queue is full (the
//!   events wait, or are dropped);
//! - `bus`: one grant and one event at a time, `T_row` per grant and `1 / R` per event;
//! - `quantise`: the time an event left, floored to the sensor's timestamp step;
//! - then the event rate controller the preset enables (`crate::filters`, Prophesee's ERC),
//!   last, as on the chip.
//!
//! Each event's readout delay (the microsecond it left minus the one it was made in) is kept,
//! and every event is accounted for: `events_in = events_out + dropped + erc_dropped + held`.
//! The readout runs on the sensor's sorted events in one sequential pass, with its state carried
//! from one feed to the next (an event may leave after the frame it was made in; it is held and
//! given by a later call or `flush`), so its events are the same on any thread count.
//!
//! With every stage off the readout is not built at all; below its limits (every event out in
//! the microsecond it was made) it changes no event.

mod arbiter;
mod bus;
mod quantise;
#[cfg(test)]
mod tests;

use std::collections::VecDeque;
use std::fmt;
use std::str::FromStr;

use crate::events::{Event, EventColumns};
use crate::filters::{ErcSettings, EventRateController, ERC_DEFAULT_PERIOD_US};
use crate::params::ParamError;
use arbiter::RowArbiter;
use bus::{Bus, PS_PER_US};
use quantise::{floor_us, stamp};

/// What the sensor does with events that find the readout's queue full.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ReadoutOverflow {
    /// They wait (the pixels hold their requests): nothing is lost, timestamps fall behind.
    #[default]
    Queue,
    /// Past `queue_depth` waiting events, an arriving event is dropped.
    Drop,
}

impl FromStr for ReadoutOverflow {
    type Err = ParamError;
    fn from_str(s: &str) -> Result<Self, ParamError> {
        match s {
            "queue" => Ok(Self::Queue),
            "drop" => Ok(Self::Drop),
            _ => Err(ParamError::new(
                "readout_overflow",
                format!("must be 'queue' or 'drop', got {s:?}"),
            )),
        }
    }
}

impl fmt::Display for ReadoutOverflow {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Queue => "queue",
            Self::Drop => "drop",
        })
    }
}

/// The readout's parameters; 0 switches a stage off (all off by default).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReadoutSettings {
    /// The arbiter's service time per row grant (ns); 0 = no row arbiter.
    pub row_service_ns: f64,
    /// Events per second the bus carries (millions); 0 = no limit.
    pub bus_rate_meps: f64,
    pub overflow: ReadoutOverflow,
    /// Events that may wait before `Drop` drops (0 with `Queue`: no bound).
    pub queue_depth: u64,
    /// Timestamp step (us); 0 or 1 = the 1 us clock.
    pub timestamp_step_us: u64,
    /// The event rate controller's rate (events/s, 200 us periods); 0 = off.
    pub erc_rate_hz: f64,
}

/// Longest service time of a row grant (1 ms), largest bus rate (1e11 events/s), deepest
/// queue and coarsest timestamp step: beyond these no sensor.
pub const MAX_ROW_SERVICE_NS: f64 = 1e6;
pub const MAX_BUS_RATE_MEPS: f64 = 1e5;
pub const MAX_QUEUE_DEPTH: u64 = 1 << 32;
pub const MAX_TIMESTAMP_STEP_US: u64 = 1_000_000;

impl ReadoutSettings {
    /// Whether any stage is on.
    pub fn is_on(&self) -> bool {
        self.row_service_ns > 0.0
            || self.bus_rate_meps > 0.0
            || self.timestamp_step_us > 1
            || self.erc_rate_hz > 0.0
    }

    fn erc(&self) -> Option<ErcSettings> {
        (self.erc_rate_hz > 0.0).then_some(ErcSettings {
            rate_hz: self.erc_rate_hz,
            period_us: ERC_DEFAULT_PERIOD_US,
        })
    }

    /// Each field in its range, and fields that only make sense together.
    pub fn validate(&self) -> Result<(), ParamError> {
        let bad = |field: &'static str, message: String| Err(ParamError::new(field, message));
        for (field, value, least, most) in [
            (
                "readout_row_service_ns",
                self.row_service_ns,
                1e-3,
                MAX_ROW_SERVICE_NS,
            ),
            (
                "readout_bus_rate_meps",
                self.bus_rate_meps,
                1e-3,
                MAX_BUS_RATE_MEPS,
            ),
        ] {
            if !(value == 0.0 || (least..=most).contains(&value)) {
                return bad(
                    field,
                    format!("must be 0 (off) or in [{least:?}, {most:?}], got {value:?}"),
                );
            }
        }
        if self.queue_depth > MAX_QUEUE_DEPTH {
            let message = format!(
                "must be at most {MAX_QUEUE_DEPTH}, got {}",
                self.queue_depth
            );
            return bad("readout_queue_depth", message);
        }
        if self.timestamp_step_us > MAX_TIMESTAMP_STEP_US {
            let message = format!(
                "must be 0 (1 us) to {MAX_TIMESTAMP_STEP_US}, got {}",
                self.timestamp_step_us
            );
            return bad("timestamp_step_us", message);
        }
        let timed = self.row_service_ns > 0.0 || self.bus_rate_meps > 0.0;
        match self.overflow {
            ReadoutOverflow::Drop if !timed => bad(
                "readout_overflow",
                "'drop' drops events waiting for the bus; it needs readout_bus_rate_meps or \
                 readout_row_service_ns"
                    .to_string(),
            ),
            ReadoutOverflow::Drop if self.queue_depth == 0 => bad(
                "readout_queue_depth",
                "readout_overflow 'drop' needs the events that may wait (1 or more)".to_string(),
            ),
            ReadoutOverflow::Queue if self.queue_depth > 0 => bad(
                "readout_queue_depth",
                format!(
                    "{} is only used with readout_overflow 'drop' (with 'queue' events wait \
                     without bound); set it to 0 or drop",
                    self.queue_depth
                ),
            ),
            _ => Ok(()),
        }?;
        if let Some(erc) = self.erc() {
            if erc.validate().is_err() {
                let message = format!(
                    "must be 0 (off) or from 5000 (one event per 200 us period) to 1e15, got {:?}",
                    self.erc_rate_hz
                );
                return bad("erc_rate_hz", message);
            }
        }
        Ok(())
    }
}

/// Every event the readout took, by what became of it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadoutCounts {
    pub events_in: u64,
    /// Given out (after the rate controller).
    pub events_out: u64,
    /// Dropped by a full readout queue.
    pub dropped: u64,
    /// Dropped by the event rate controller.
    pub erc_dropped: u64,
    /// Still inside: waiting for the bus, left after the last call's time, or in an open rate
    /// controller period.
    pub held: u64,
    /// Events out whose stamp is a later microsecond than the one they were made in, and the
    /// sum and largest of their delays (us, before the timestamp step).
    pub delayed: u64,
    pub delay_total_us: u64,
    pub delay_max_us: u64,
    /// Events out stamped with the same time as the event before them.
    pub same_timestamp: u64,
}

/// An event that has left the bus: stamped with the microsecond it left (before the step).
#[derive(Clone, Copy, Debug)]
struct Left {
    event: Event,
    t_left_us: i64,
}

/// Events a call gives out, and each one's readout delay (us).
#[derive(Debug, Default)]
pub struct ReadoutBatch {
    pub events: EventColumns,
    pub delay_us: Vec<i64>,
}

impl ReadoutBatch {
    /// Room for `n` events, with the label column where `labels`.
    fn with_capacity(n: usize, labels: bool) -> Self {
        let events = EventColumns {
            t_us: Vec::with_capacity(n),
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            p: Vec::with_capacity(n),
            label: Vec::with_capacity(if labels { n } else { 0 }),
        };
        Self {
            events,
            delay_us: Vec::with_capacity(n),
        }
    }

    #[inline]
    fn push(&mut self, e: &Event, delay_us: i64, labels: bool) {
        let c = &mut self.events;
        c.t_us.push(e.t_us);
        c.x.push(e.x);
        c.y.push(e.y);
        c.p.push(e.p);
        if labels {
            c.label.push(e.label);
        }
        self.delay_us.push(delay_us);
    }

    fn append(&mut self, other: Self) {
        let (c, o) = (&mut self.events, other.events);
        c.t_us.extend(o.t_us);
        c.x.extend(o.x);
        c.y.extend(o.y);
        c.p.extend(o.p);
        c.label.extend(o.label);
        self.delay_us.extend(other.delay_us);
    }
}

/// The counts of events given out, carried from one call to the next.
#[derive(Debug, Default)]
struct Giving {
    counts: ReadoutCounts,
    last_stamp_us: Option<i64>,
    labels: bool,
}

impl Giving {
    /// `events` (stamped, with their delays) as a batch, counted.
    fn give(&mut self, events: impl ExactSizeIterator<Item = (Event, i64)>) -> ReadoutBatch {
        let mut batch = ReadoutBatch::with_capacity(events.len(), self.labels);
        let c = &mut self.counts;
        for (event, delay_us) in events {
            if delay_us > 0 {
                c.delayed += 1;
                c.delay_total_us += delay_us as u64;
                c.delay_max_us = c.delay_max_us.max(delay_us as u64);
            }
            c.same_timestamp += u64::from(self.last_stamp_us == Some(event.t_us));
            self.last_stamp_us = Some(event.t_us);
            batch.push(&event, delay_us, self.labels);
        }
        c.events_out += batch.delay_us.len() as u64;
        batch
    }
}

/// The readout of one sensor, with its state across calls.
pub struct Readout {
    arbiter: RowArbiter,
    bus: Bus,
    step_us: i64,
    /// Events that have left but after the last call's time, in order.
    left: VecDeque<Left>,
    erc: Option<EventRateController>,
    /// The events in the rate controller's open period, in order (its verdicts wait).
    erc_held: Vec<(Event, i64)>,
    /// Scratch: the rate controller's verdicts.
    verdicts: Vec<bool>,
    /// Scratch: a grant's burst.
    burst: Vec<Event>,
    giving: Giving,
    settings: ReadoutSettings,
}

impl Readout {
    /// The readout of these settings (validated), or None when every stage is off.
    pub fn new(settings: &ReadoutSettings) -> Option<Self> {
        if !settings.is_on() {
            return None;
        }
        let depth = match settings.overflow {
            ReadoutOverflow::Drop => settings.queue_depth as usize,
            ReadoutOverflow::Queue => 0,
        };
        Some(Self {
            arbiter: RowArbiter::new(settings.row_service_ns > 0.0, depth),
            bus: Bus::new(settings.row_service_ns, settings.bus_rate_meps),
            step_us: settings.timestamp_step_us.max(1) as i64,
            left: VecDeque::new(),
            erc: settings.erc().as_ref().map(EventRateController::new),
            erc_held: Vec::new(),
            verdicts: Vec::new(),
            burst: Vec::new(),
            giving: Giving {
                labels: true,
                ..Giving::default()
            },
            settings: settings.clone(),
        })
    }

    /// With or without the label column in the output (on by default).
    pub fn with_labels(mut self, labels: bool) -> Self {
        self.giving.labels = labels;
        self
    }

    /// Start over, as a new readout (counts too).
    pub fn reset(&mut self) {
        if let Some(fresh) = Self::new(&self.settings) {
            *self = fresh.with_labels(self.giving.labels);
        }
    }

    pub fn counts(&self) -> ReadoutCounts {
        let held = self.arbiter.waiting() + self.left.len() + self.erc_held.len();
        ReadoutCounts {
            held: held as u64,
            ..self.giving.counts
        }
    }

    /// The next events from the pixels (sorted by (t, y, x), all later than the last call's
    /// time), and the time up to which the stream is complete: gives every event stamped up to
    /// `t_us` that the rate controller has decided on.
    pub fn push(&mut self, events: &EventColumns, t_us: i64) -> ReadoutBatch {
        let arrivals = (0..events.len()).map(|i| Event {
            t_us: events.t_us[i],
            x: events.x[i],
            y: events.y[i],
            p: events.p[i],
            label: events.label.get(i).copied().unwrap_or(0),
        });
        self.giving.counts.events_in += events.len() as u64;
        // Events made up to t_us are all here; later ones arrive at t_us + 1 or after, so every
        // grant before then can be decided now.
        self.read_out(arrivals, (i128::from(t_us) + 1) * PS_PER_US);
        let due = self.left.partition_point(|l| l.t_left_us <= t_us);
        self.rate_controlled(due, false)
    }

    /// The stream ended: everything still inside, out or dropped.
    pub fn finish(&mut self, events: &EventColumns) -> ReadoutBatch {
        let mut batch = self.push(events, i64::MAX - 1);
        self.read_out(std::iter::empty(), i128::MAX);
        let rest = self.rate_controlled(self.left.len(), true);
        batch.append(rest);
        batch
    }

    /// The arrivals through the arbiter and the bus, grants decided before `horizon_ps`.
    fn read_out(&mut self, arrivals: impl Iterator<Item = Event>, horizon_ps: i128) {
        if !self.bus.takes_time() {
            // Time quantisation or the rate controller alone: each event leaves as it came.
            self.left.extend(arrivals.map(|event| Left {
                event,
                t_left_us: event.t_us,
            }));
            return;
        }
        let mut arrivals = arrivals.peekable();
        loop {
            let arrival_ps = arrivals.peek().map(|e| i128::from(e.t_us) * PS_PER_US);
            let grant_ps = self
                .arbiter
                .next_request_ps()
                .map(|request| request.max(self.bus.free_ps()));
            match (arrival_ps, grant_ps) {
                // An arrival at a grant's time is in time for it.
                (Some(a), g) if !matches!(g, Some(g) if g < a) => {
                    let e = arrivals.next().expect("peeked");
                    if !self.arbiter.arrive(e, a) {
                        self.giving.counts.dropped += 1;
                    }
                }
                (_, Some(g)) if g < horizon_ps => self.grant(g),
                _ => break,
            }
        }
    }

    fn grant(&mut self, grant_ps: i128) {
        let mut burst = std::mem::take(&mut self.burst);
        self.arbiter.grant(&mut burst);
        let left = &mut self.left;
        self.bus.carry(grant_ps, burst.len(), |k, t_ps| {
            left.push_back(Left {
                event: burst[k],
                t_left_us: floor_us(t_ps),
            });
        });
        self.burst = burst;
    }

    /// The first `due` events that left, stamped, through the rate controller where it is on;
    /// `end`: the stream ended, decide its open period.
    fn rate_controlled(&mut self, due: usize, end: bool) -> ReadoutBatch {
        let step_us = self.step_us;
        let stamped = self.left.drain(..due).map(|l| {
            let mut event = l.event;
            event.t_us = stamp(l.t_left_us, step_us);
            (event, l.t_left_us - l.event.t_us)
        });
        let Some(erc) = &mut self.erc else {
            return self.giving.give(stamped);
        };
        // Verdicts come in order, the held events' first; those of the open period wait.
        let mut pending = std::mem::take(&mut self.erc_held);
        let verdicts = &mut self.verdicts;
        verdicts.clear();
        let mut dropped = 0;
        for (event, delay_us) in stamped {
            dropped += erc.push(event.t_us, true, verdicts);
            pending.push((event, delay_us));
        }
        if end {
            dropped += erc.close(verdicts);
        }
        self.giving.counts.erc_dropped += dropped;
        self.erc_held = pending.split_off(verdicts.len());
        let kept: Vec<(Event, i64)> = pending
            .into_iter()
            .zip(verdicts.iter())
            .filter_map(|(event, &keep)| keep.then_some(event))
            .collect();
        self.giving.give(kept.into_iter())
    }
}
