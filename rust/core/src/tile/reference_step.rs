//! Reference-only models (ESIM's), whose state is a pixel's reference alone: `GROUP` listed pixels
//! at a time, the responses to their ramps' ends together, then each reference moved along its
//! ramp (an event at each threshold it crosses), then the quiet bands around the new ones.

use super::emit::{FuseCount, PixelEvents};
use super::prefetch::prefetch_bytes;
use super::{Frame, Tile};
use crate::pixel::{PixelModel, GROUP, RAMP_VALUES};
use crate::state_block::LANES;

impl Tile {
    /// The listed pixels of a reference-only model, `GROUP` at a time: their ramps' ends (and
    /// first references) together, then each one's reference along its ramp, then their bands
    /// around the new ones together. Such a pixel never wakes: it is listed because its input
    /// changed (or, in tests, because the sensor never skips: a flat ramp, which stays between
    /// its thresholds).
    pub(super) fn step_references(
        &mut self,
        model: &PixelModel,
        busy: &[u32],
        frame: &Frame,
        count: &mut FuseCount,
    ) -> bool {
        let mut groups = busy.chunks(GROUP).peekable();
        while let Some(group) = groups.next() {
            // The next group's references and first values: far apart, and read by no scan.
            for &j in groups.peek().copied().unwrap_or_default() {
                prefetch_bytes(self.references.as_ptr().wrapping_add(j as usize), 8);
                prefetch_bytes(self.first_values().as_ptr().wrapping_add(j as usize), 4);
            }
            let (u, first) = self.ramp_ends(model, group, frame.values);
            let mut references = [0.0; GROUP];
            for (k, &j) in group.iter().enumerate() {
                let j = j as usize;
                let reference = if first >> k & 1 != 0 {
                    self.made[j / LANES] |= 1 << (j % LANES);
                    u[k]
                } else {
                    self.references[j]
                };
                let mut out =
                    PixelEvents::open(&mut self.events, frame.clock, self.first_pixel + j);
                references[k] = model.cross_reference(
                    reference,
                    (frame.t0_s, u[GROUP + k]),
                    (frame.t1_s, u[2 * GROUP + k]),
                    &mut |e| out.push(e),
                );
                out.close();
                self.references[j] = references[k];
                if !self.report_if_due(frame.fuse, count) {
                    return false;
                }
            }
            let (lo, hi) = model.reference_bands_of_group(&references);
            for (k, &j) in group.iter().enumerate() {
                (self.lo[j as usize], self.hi[j as usize]) = (lo[k], hi[k]);
            }
        }
        true
    }

    /// The responses a group of listed reference-only pixels steps with: the first frame's
    /// (lanes 0..GROUP, for those without a reference yet: bit k of the mask), the last frame's
    /// and this one's (the next two rows). Padding lanes take 1.
    fn ramp_ends(
        &self,
        model: &PixelModel,
        group: &[u32],
        values: &[f32],
    ) -> ([f64; RAMP_VALUES], u32) {
        let mut ends = [1.0; RAMP_VALUES];
        let mut first = 0;
        for (k, &j) in group.iter().enumerate() {
            let j = j as usize;
            if !self.has_state(j) {
                ends[k] = self.first_values()[j];
                first |= 1 << k;
            }
            ends[GROUP + k] = self.last[j];
            ends[2 * GROUP + k] = values[j];
        }
        (model.responses_to_group(&ends), first)
    }
}
