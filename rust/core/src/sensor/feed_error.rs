//! Why a call was refused, in the words a user reads. The sensor is unchanged after any refusal
//! but `TooManyEvents` (a call stopped mid-way) and `Stopped` (every call after it).

use std::fmt;

use super::noise_gap::NoiseWork;

/// Why a frame or time was refused. The sensor is unchanged after any of these but
/// `TooManyEvents`, which stops it mid-call, and `Stopped`, its refusal of every call after.
#[derive(Clone, Debug, PartialEq)]
pub enum FeedError {
    Shape {
        expected: usize,
        got: usize,
    },
    NotFinite {
        x: usize,
        y: usize,
        value: f32,
    },
    Negative {
        x: usize,
        y: usize,
        value: f32,
    },
    Time {
        t_us: i64,
        t_prev_us: i64,
    },
    TimeRange {
        t_us: i64,
    },
    /// Refused before any work: the noise expected over the gap passes the limit.
    TooMuchNoise(NoiseWork),
    /// Stopped while working: the events so far passed the limit, or memory for them ran out.
    TooManyEvents(Overflow),
    /// A call after `TooManyEvents`, before `reset`: the pixels were left partly stepped.
    Stopped {
        cause: String,
    },
}

/// A call that stopped mid-way, its pixels partly stepped.
#[derive(Clone, Debug, PartialEq)]
pub struct Overflow {
    pub t_us: i64,
    pub t_prev_us: i64,
    /// Events counted when it stopped (those held back from earlier calls included).
    pub events: usize,
    pub limit: usize,
    /// Memory ran out before the limit was reached.
    pub out_of_memory: bool,
}

impl Overflow {
    /// What stopped the call, in a few words (the refusal of later calls repeats it).
    pub(super) fn cause(&self) -> String {
        if self.out_of_memory {
            format!(
                "memory ran out for {} events at t_us = {}",
                self.events, self.t_us
            )
        } else {
            format!(
                "{} events at t_us = {}, more than the {:.0e} one call may give",
                self.events, self.t_us, self.limit as f64
            )
        }
    }
}

impl fmt::Display for Overflow {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the light changed by more than the thresholds can follow in one call (t_us = {} to \
             {}): {}; feed frames closer in time, or lower the light range, or raise the \
             thresholds. The sensor stopped mid-call: call reset() to start over",
            self.t_prev_us,
            self.t_us,
            self.cause()
        )
    }
}

impl fmt::Display for FeedError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Shape { expected, got } => {
                write!(f, "frame has {got} pixels, the sensor has {expected}")
            }
            Self::NotFinite { x, y, value } => {
                write!(f, "frame has a non-finite value ({value}) at x={x}, y={y}")
            }
            Self::Negative { x, y, value } => {
                write!(
                    f,
                    "frame has a negative photocurrent ({value}) at x={x}, y={y}"
                )
            }
            Self::Time { t_us, t_prev_us } => {
                write!(
                    f,
                    "t_us must increase from frame to frame: got {t_us} after {t_prev_us}"
                )
            }
            Self::TimeRange { t_us } => {
                write!(f, "t_us must be within +-2^53 us (285 years), got {t_us}")
            }
            Self::TooMuchNoise(work) => work.fmt(f),
            Self::TooManyEvents(overflow) => overflow.fmt(f),
            Self::Stopped { cause } => write!(
                f,
                "the sensor stopped mid-call after {cause} and its pixels are partly stepped; \
                 call reset() to start over"
            ),
        }
    }
}

impl std::error::Error for FeedError {}
