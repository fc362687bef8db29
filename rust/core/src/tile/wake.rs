//! The pixels' wake-up times, the gate that lets a scan skip a pixel whose input stayed: a pixel
//! need not be stepped before t_wake, a lower bound of the time its state could emit with its
//! input held (leak, shot noise, the end of a reset), kept in f32 rounded down so a gate never
//! opens late; the earliest per block and per tile let whole blocks and tiles be skipped.

use super::dense_step::first_block;
use super::Tile;
use crate::block_flags::BLOCK;
use crate::f32_bounds::{band_inside_f32, round_down_f32};
use crate::pixel::{PixelModel, PixelState};
use crate::state_block::LANES;

/// The wake-up time of a pixel whose bound is yet to be worked out (after a dense step, see the
/// module `dense`, or before its first state): before any frame, so the next scan lists the
/// pixel, and `step_one` works the bound out where its input did not change.
pub(super) const WAKE_UNKNOWN_S: f32 = f32::NEG_INFINITY;

impl Tile {
    /// Pixel `j`'s wake-up bound worked out where it is unknown (`WAKE_UNKNOWN_S`); returns
    /// whether it was, and comes after the time by which the scan listed the pixels due.
    pub(super) fn settle_wake(&mut self, model: &PixelModel, j: usize) -> bool {
        if self.wake_s[j] != WAKE_UNKNOWN_S {
            return false;
        }
        let wake_s = round_down_f32(self.wake_bound_s(model, j));
        self.wake_s[j] = wake_s;
        self.due_by_s < wake_s
    }

    /// Pixel `j`'s wake-up bound: its state's, or for a pixel without one, that of the state it
    /// would start with (its first-frame input has stayed).
    #[inline]
    fn wake_bound_s(&self, model: &PixelModel, j: usize) -> f64 {
        if self.has_state(j) {
            let slot = self.block_slot[j / LANES] as usize;
            model.wake_s(&self.blocks[slot].get(j % LANES))
        } else {
            let pixel = (self.first_pixel + j) as u64;
            model.first_wake_s(pixel, self.first_values()[j] as f64)
        }
    }

    /// The pixel's wake-up time (left infinite when no pixel can wake) and quiet band again.
    pub(super) fn update_gate(
        &mut self,
        model: &PixelModel,
        j: usize,
        st: &PixelState,
        can_wake: bool,
    ) {
        if can_wake {
            self.wake_s[j] = round_down_f32(model.wake_s(st));
        }
        if !self.lo.is_empty() {
            (self.lo[j], self.hi[j]) = band_inside_f32(model.quiet_band(st));
        }
    }

    /// The earliest wake-up times again, of the blocks with a stepped pixel and of the tile.
    pub(super) fn update_wake_minima(&mut self) {
        let mut rest = &self.busy[..];
        while let Some((block, _, after)) = first_block(rest) {
            rest = after;
            let end = (block * BLOCK + BLOCK).min(self.wake_s.len());
            self.block_wake_s[block] = min_f32(&self.wake_s[block * BLOCK..end]);
        }
        if !self.busy.is_empty() {
            self.wake_min_s = min_f32(&self.block_wake_s);
        }
    }
}

/// The smallest value (wake-up times are never NaN), eight lanes at a time so it vectorises.
pub(super) fn min_f32(values: &[f32]) -> f32 {
    let mut lanes = [f32::INFINITY; 8];
    let chunks = values.chunks_exact(8);
    let rest = chunks.remainder();
    for chunk in chunks {
        for (lane, &v) in lanes.iter_mut().zip(chunk) {
            *lane = if v < *lane { v } else { *lane };
        }
    }
    lanes
        .iter()
        .chain(rest)
        .fold(f32::INFINITY, |m, &v| m.min(v))
}
