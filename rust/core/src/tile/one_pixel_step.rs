//! The listed pixels one at a time through the pixel model over (t0, t1]: held at the last input
//! from the state's time to t0, then the ramp linear in log from the last frame's value to this
//! one's; then the pixel's wake-up time and quiet band again, the gates the next scans read.

use super::emit::{FuseCount, PixelEvents};
use super::prefetch::prefetch_bytes;
use super::states::STATE_FIELDS;
use super::{Frame, Tile, WAKE_UNKNOWN_S};
use crate::pixel::{FoundCrossings, PixelEvent, PixelModel, PixelState, Segment};
use crate::state_block::LANES;

impl Tile {
    /// The listed pixels one at a time; returns false where the fuse stopped it.
    pub(super) fn step_sparse(
        &mut self,
        model: &PixelModel,
        busy: &[u32],
        frame: &Frame,
        count: &mut FuseCount,
    ) -> bool {
        for k in 0..busy.len() {
            // The states of pixels along a moving edge are far apart in memory: ask for the
            // ones a few steps ahead so their cache misses overlap with this pixel's work (and
            // for the indices that find them, further ahead).
            if let Some(&further) = busy.get(k + 2 * PREFETCH_AHEAD) {
                let j = further as usize;
                prefetch_bytes(self.block_slot.as_ptr().wrapping_add(j / LANES), 4);
                prefetch_bytes(self.last.as_ptr().wrapping_add(j), 4);
                prefetch_bytes(frame.values.as_ptr().wrapping_add(j), 4);
            }
            if let Some(&ahead) = busy.get(k + PREFETCH_AHEAD) {
                self.prefetch_state(ahead);
            }
            if !self.step_one(model, busy[k] as usize, frame, count) {
                return false;
            }
        }
        true
    }

    /// Ask for pixel `j`'s state to be brought into the cache (none: nothing to fetch): one
    /// cache line from each field's array.
    #[inline(always)]
    pub(super) fn prefetch_state(&self, j: u32) {
        let j = j as usize;
        if let Some(block) = self.blocks.get(self.block_slot[j / LANES] as usize) {
            let lane = std::ptr::from_ref(block)
                .cast::<f64>()
                .wrapping_add(j % LANES);
            for field in 0..STATE_FIELDS {
                prefetch_bytes(lane.wrapping_add(field * LANES), 1);
            }
        }
    }

    /// One pixel through the pixel model, its events collected and its gates renewed; returns
    /// false where the fuse stops the tile.
    #[inline]
    pub(super) fn step_one(
        &mut self,
        model: &PixelModel,
        j: usize,
        frame: &Frame,
        count: &mut FuseCount,
    ) -> bool {
        self.step_one_found(model, j, frame, count, None)
    }

    /// `step_one`, with the threshold crossings of the frame's ramp already found where `found`
    /// is given (the dense path's, for a pixel whose state is at the frame's start).
    #[inline]
    pub(super) fn step_one_found(
        &mut self,
        model: &PixelModel,
        j: usize,
        frame: &Frame,
        count: &mut FuseCount,
        found: Option<FoundCrossings>,
    ) -> bool {
        if frame.values[j] == self.last[j] && self.settle_wake(model, j) {
            // Listed for its wake-up bound alone, which was unknown and is not due: the scan
            // would not have listed it with it.
            return true;
        }
        let (slot, k) = self.state_slot(model, j);
        let mut state = self.blocks[slot].get(k);
        let pixel = self.first_pixel + j;
        let mut out = PixelEvents::open(&mut self.events, frame.clock, pixel);
        step_pixel(
            model,
            !self.lo.is_empty(),
            &mut state,
            pixel as u64,
            self.last[j],
            frame.values[j],
            frame.t0_s,
            frame.t1_s,
            found,
            &mut |e| out.push(e),
        );
        out.close();
        self.blocks[slot].set(k, &state);
        self.note_gates(j / LANES, state.hot_next_s, state.refractory_mark_s);
        if frame.wake_when_still && frame.values[j] != self.last[j] {
            // As after a dense step: worked out only if the input then stays the same.
            self.wake_s[j] = WAKE_UNKNOWN_S;
            #[cfg(test)]
            {
                self.wakes_left_unknown += 1;
            }
        } else {
            self.update_gate(model, j, &state, frame.can_wake);
        }
        self.report_if_due(frame.fuse, count)
    }
}

/// Pixels looked up this far ahead of their use in `Tile::step` (their states), and twice as
/// far (their indices and values).
const PREFETCH_AHEAD: usize = 4;

/// One pixel over (t0, t1]: held at its last input since its state's time, then the ramp (linear
/// in log) from the last frame's value to this one's, whose first crossings `found` may hold.
#[allow(clippy::too_many_arguments)]
fn step_pixel(
    model: &PixelModel,
    time_invariant: bool,
    st: &mut PixelState,
    pixel: u64,
    last_value: f32,
    value: f32,
    t0_s: f64,
    t1_s: f64,
    found: Option<FoundCrossings>,
    events: &mut impl FnMut(PixelEvent),
) {
    let r = &model.receptor;
    if time_invariant {
        // Skipped frames moved the input inside the quiet band, which changes nothing else.
        let x = r.total_current(last_value as f64);
        if x != st.x {
            st.x = x;
            st.u = r.response(x);
            st.v = st.u;
        }
    }
    // Otherwise a pixel is skipped only while its input is unchanged, so its state already holds
    // the response to the last frame's value.
    if value == last_value {
        // Woken by its own dynamics with the input still held: one constant segment from the
        // state's time to the frame's, not one to the last frame and a flat ramp after it.
        let held = Segment::constant(st.t_s, t1_s, st.u, st.x);
        model.run(st, pixel, &held, events);
        return;
    }
    // Found for the ramp from the frame's start, with nothing held before it.
    debug_assert!(found.is_none() || (st.t_s == t0_s && !time_invariant));
    let (u0, x0) = (st.u, st.x);
    if st.t_s < t0_s {
        if time_invariant && model.holds_still_until(st, t0_s) {
            // Held inside its band with nothing due: running would only move its time.
            st.t_s = t0_s;
        } else {
            let held = Segment::constant(st.t_s, t0_s, st.u, st.x);
            model.run(st, pixel, &held, events);
        }
    }
    let x1 = r.total_current(value as f64);
    let ramp = Segment {
        t0_s,
        t1_s,
        u0,
        u1: r.response(x1),
        x0,
        x1,
    };
    model.run_found(st, pixel, &ramp, found, events);
}
