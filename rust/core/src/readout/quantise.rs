//! Timestamp quantisation: the time an event left the chip, floored to the sensor's clock.
//!
//! `t = floor(t_leave / 1 us)`, then `t_stamp = floor(t / step) x step` (floor towards minus
//! infinity, so times before 0 floor the same way). Prophesee and DAVIS stamp at 1 us; Samsung's
//! Gen3 (the DVXplorer's) stamps at about 100 us, so at 6 Mev/s some 600 events share one
//! timestamp (better-flow/evimo#32). Flooring keeps the stream's order: times never decrease.

use super::bus::PS_PER_US;

/// Whole microseconds of a time in ps, floored.
#[inline]
pub(super) fn floor_us(t_ps: i128) -> i64 {
    // In i64 where it fits (times within 106 days of 0): a 128-bit division is a library call
    // that cost more than the rest of an event's readout.
    match i64::try_from(t_ps) {
        Ok(t) => t.div_euclid(PS_PER_US as i64),
        Err(_) => t_ps.div_euclid(PS_PER_US) as i64,
    }
}

/// `t_us` floored to a multiple of `step_us` (1 leaves it as it is).
#[inline]
pub(super) fn stamp(t_us: i64, step_us: i64) -> i64 {
    if step_us <= 1 {
        t_us
    } else {
        t_us.div_euclid(step_us) * step_us
    }
}
