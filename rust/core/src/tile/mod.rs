//! A tile of consecutive pixels (row-major): their states, the gates that let a frame skip the
//! quiet ones, and the events they emitted this frame. Tiles are the unit of parallel work, and
//! each owns its arrays so a frame touches memory in long runs.
//!
//! A frame goes through a tile in two passes. `scan` validates the values and lists the pixels
//! to step, testing 32 at a time with vector compares; it changes nothing a refused frame could
//! leave behind (it only works out the first quiet bands of the blocks that changed, and the
//! first wake-ups of the pixels without a state, which depend on the first frame alone, and may
//! copy the values into a spare buffer that only the step makes the last frame's). `step` then
//! runs the pixel model on the listed pixels alone and keeps the frame as the next ramps' start.
//!
//! The parts, a file each: the first pass (`scan`); the pixels' states, made only when needed
//! (`states`); the second pass's steps, one pixel at a time (`one_pixel_step`), a block at a time
//! (`dense_step`) and of reference-only models (`reference_step`); the events they emit (`emit`);
//! the wake-up times that gate them (`wake`); and the cache hints both passes give (`prefetch`).
//! Here: the tile, its start and `step`.

mod dense_step;
mod emit;
mod one_pixel_step;
mod prefetch;
mod reference_step;
mod scan;
mod states;
#[cfg(test)]
mod tests;
mod wake;
use crate::block_flags::BLOCK;
use crate::dense;
use crate::events::EventRun;
use crate::f32_bounds::round_down_f32;
pub use crate::f32_bounds::round_up_f32;
use crate::first_band;
use crate::fuse::{EventFuse, REPORT_EVERY_EVENTS};
use crate::pixel::PixelModel;
#[cfg(test)]
use crate::pixel::PixelState;
pub use crate::state_arena::BlockStore;
use crate::state_block::LANES;
pub use emit::Clock;
use emit::FuseCount;
use scan::all_bits;
use wake::{min_f32, WAKE_UNKNOWN_S};

/// Pixels per tile: large enough to amortise scheduling, small enough to balance two or more
/// threads on a 346 x 260 sensor.
pub const TILE: usize = 4096;

// Pixels are tested together a block at a time (`block_flags::BLOCK`), as their states are
// stored together and their first bands worked out together; `used` masks are one bit per pixel
// of a block.
const _: () = assert!(first_band::BLOCK == BLOCK && BLOCK == LANES);

/// Marks a block whose states are not made yet.
const NO_STATE: u32 = u32::MAX;

pub struct Tile {
    first_pixel: usize,
    /// The states made so far, a block of 32 neighbouring pixels together (stored field by
    /// field, for the dense path), blocks in the order they first needed one; for each block,
    /// where its states are (`NO_STATE`: none yet) and which of its pixels have one (bit k:
    /// pixel k). A pixel needs its state only once its input first changes or it first wakes
    /// (it starts settled at the first frame's value, which stays its last value until then),
    /// so a mostly static scene never makes most states. Reference-only models keep none here
    /// (`references`).
    blocks: BlockStore,
    block_slot: Vec<u32>,
    made: Vec<u32>,
    /// For each block: until when its states' gates can matter (`dense::Inputs::gates`), the
    /// latest `refractory_mark_s` of its states, or +inf once one may be a hot pixel's
    /// (`hot_next_s` finite). In a frame from a later time the dense path leaves those two
    /// fields of its states unread.
    block_gates_until_s: Vec<f64>,
    /// Reference-only models (`PixelModel::is_reference_only`, ESIM's): a pixel's whole state,
    /// its reference, in place of `blocks` (valid where `made` has its bit).
    references: Vec<f64>,
    /// Time-invariant models only: the input band in which each pixel cannot cross a threshold
    /// (the others are quiet only while their input is unchanged, and keep these empty). A pixel
    /// without a state has the band of the state it would start with, once its block has its
    /// first bands (with `origin`), else an empty one (lo > hi): any change then steps it.
    lo: Vec<f32>,
    hi: Vec<f32>,
    /// Bit b of word w: block 64 w + b has yet to have its first bands, which `scan` works out
    /// the first time most of its values change at once (empty without `origin`, and once
    /// every block has them). Where every pixel changes (grain, sensor noise) that is at the
    /// first changed frame; on a moving edge few do, and most of those fire: a band worked out
    /// for every pixel of the block would be wasted.
    first_bands_due: Vec<u64>,
    /// A lower bound on when each pixel next needs attention with constant input (seconds since
    /// the first frame), or `WAKE_UNKNOWN_S` (after a dense step, or before the first changed
    /// frame); the earliest of each block of 32 and of the tile: a frame reads only the wake-up
    /// times of blocks with one due.
    wake_s: Vec<f32>,
    block_wake_s: Vec<f32>,
    wake_min_s: f32,
    /// The time by which the last scan listed the pixels with a wake-up due (rounded up).
    due_by_s: f32,
    /// Whether the first wake-ups of the pixels without a state are yet to be worked out:
    /// `scan` does so at the first frame after the start, for those whose input stayed (the
    /// others get a state), rather than the start for all (where every pixel changes, none is
    /// needed). False where the start works them out.
    first_wakes_due: bool,
    /// The last frame's values: the start of each pixel's next ramp.
    last: Vec<f32>,
    /// Reference-only models, where most blocks changed in the last frame (grain, noise): the
    /// scan copies every value into `next` as it reads it, and `next` becomes `last` after the
    /// step, one read of the frame rather than a second one to copy the changed blocks
    /// (`keep_changed_blocks`) once the scan of every tile has pushed it out of the cache. Not
    /// for whole states: their step finds the frame in the cache again, and at 1280 x 720 the
    /// copy's writes in the scan cost the full model's update 8-15 % (README). Empty until a
    /// tile first needs it; `copy_in_scan` says whether the scan does it (set after a step, for
    /// the next frame; a refused frame leaves it).
    next: Vec<f32>,
    copy_in_scan: bool,
    /// Time-invariant models that never wake: the first frame's values, where a pixel's state
    /// starts. Such a pixel has its first state's band before it has a state
    /// (`first_bands_due`), so a change that stays in it passes the scan, and its `last` moves
    /// on without a state.
    origin: Vec<f32>,
    /// This frame: the pixels to step (indices in the tile), and the blocks of 32 in which a
    /// value changed (their bits), the only ones `last` must take.
    busy: Vec<u32>,
    changed_blocks: Vec<u64>,
    /// Dense frames: the listed pixels the quiet step left, in pixel order, and their threshold
    /// crossings where found together (`dense_step`); kept for their memory.
    others: Vec<u32>,
    outcomes: Vec<dense_step::Outcome>,
    finished: Vec<dense::SingleEvent>,
    /// The dense step's differences of the block it stepped last (`dense::Differences`), and
    /// whether this frame's step leaves them (see `dense_step`).
    differences: Box<dense::Differences>,
    finds_crossings: bool,
    /// This frame's events, in pixel order and each pixel's in time order.
    pub events: EventRun,
    /// Whether busy frames may take the dense path: the model suits it (`dense::applies_to`),
    /// and tests may turn it off (to compare it with the one-pixel path); and how many pixels it
    /// stepped.
    dense_path: bool,
    #[cfg(test)]
    pub dense_steps: usize,
    /// Blocks the dense path stepped without reading their gates, and reading them.
    #[cfg(test)]
    pub gated_blocks: [usize; 2],
    /// Pixels the dense path stepped that were held in reset at the frame's start.
    #[cfg(test)]
    pub dense_held_steps: usize,
    /// Pixels of dense frames stepped one at a time whose wake-up bound was left unknown
    /// (`Frame::wake_when_still`).
    #[cfg(test)]
    pub wakes_left_unknown: usize,
    /// Pixels of dense frames whose threshold crossings were found together.
    #[cfg(test)]
    pub crossings_found: usize,
    /// Pixels of dense frames whose single event was finished together.
    #[cfg(test)]
    pub events_finished: usize,
}

impl Tile {
    /// Pixels settled at the first frame's values (`values` starts at pixel `first_pixel`), at
    /// time 0 s. No state is made yet: only when a pixel first wakes (leak, shot noise, a hot
    /// pixel) or its input first changes.
    pub fn start(
        model: &PixelModel,
        first_pixel: usize,
        values: &[f32],
        blocks: BlockStore,
    ) -> Self {
        let n = values.len();
        let time_invariant = model.is_time_invariant();
        let (lo, hi) = if time_invariant {
            (vec![f32::INFINITY; n], vec![f32::NEG_INFINITY; n])
        } else {
            (Vec::new(), Vec::new())
        };
        let keeps_origin = time_invariant && !model.can_wake();
        let mut tile = Self {
            first_pixel,
            blocks,
            block_slot: vec![NO_STATE; n.div_ceil(LANES)],
            made: vec![0; n.div_ceil(LANES)],
            block_gates_until_s: vec![f64::NEG_INFINITY; n.div_ceil(LANES)],
            references: if model.is_reference_only() {
                vec![0.0; n]
            } else {
                Vec::new()
            },
            lo,
            hi,
            first_bands_due: if keeps_origin {
                all_bits(n.div_ceil(BLOCK))
            } else {
                Vec::new()
            },
            wake_s: if !model.acts_with_constant_input() {
                vec![f32::INFINITY; n]
            } else if time_invariant {
                // A change inside a pixel's band passes the scan, so the band's pixels cannot
                // be listed for an unknown wake-up alone (see `step_one`): worked out now.
                (first_pixel..)
                    .zip(values)
                    .map(|(pixel, &v)| round_down_f32(model.first_wake_s(pixel as u64, v as f64)))
                    .collect()
            } else {
                // Worked out only for the pixels whose input then stays the same: where every
                // pixel changes at the next frame, none is needed.
                vec![WAKE_UNKNOWN_S; n]
            },
            block_wake_s: Vec::new(),
            wake_min_s: f32::INFINITY,
            due_by_s: f32::NEG_INFINITY,
            first_wakes_due: model.acts_with_constant_input() && !time_invariant,
            last: values.to_vec(),
            next: Vec::new(),
            copy_in_scan: false,
            origin: if keeps_origin {
                values.to_vec()
            } else {
                Vec::new()
            },
            busy: Vec::new(),
            changed_blocks: vec![0; n.div_ceil(BLOCK * 64)],
            others: Vec::new(),
            outcomes: Vec::new(),
            finished: Vec::new(),
            differences: Box::default(),
            finds_crossings: false,
            events: EventRun::default(),
            dense_path: dense::applies_to(model),
            #[cfg(test)]
            dense_steps: 0,
            #[cfg(test)]
            gated_blocks: [0; 2],
            #[cfg(test)]
            dense_held_steps: 0,
            #[cfg(test)]
            wakes_left_unknown: 0,
            #[cfg(test)]
            crossings_found: 0,
            #[cfg(test)]
            events_finished: 0,
        };
        tile.block_wake_s = tile.wake_s.chunks(BLOCK).map(min_f32).collect();
        tile.wake_min_s = min_f32(&tile.block_wake_s);
        tile
    }

    /// How many pixels the next scan works out the first wake-ups of (see `first_wakes_due`).
    pub fn first_wakes_to_work_out(&self) -> usize {
        if self.first_wakes_due {
            self.last.len()
        } else {
            0
        }
    }

    /// How many pixels `scan` listed.
    pub fn busy_count(&self) -> usize {
        self.busy.len()
    }

    /// How many pixels have a state.
    #[cfg(test)]
    pub fn state_count(&self) -> usize {
        self.made.iter().map(|m| m.count_ones() as usize).sum()
    }

    /// The states made so far, in pixel order (none where the tile keeps references alone).
    #[cfg(test)]
    pub fn states(&self) -> Vec<PixelState> {
        (0..self.last.len())
            .filter(|&j| self.has_state(j) && self.references.is_empty())
            .map(|j| self.blocks[self.block_slot[j / LANES] as usize].get(j % LANES))
            .collect()
    }

    /// Whole states for a reference-only model (tests: the reference the references are
    /// checked against); before any pixel has one.
    #[cfg(test)]
    pub fn with_whole_states(&mut self) {
        assert!(self.made.iter().all(|&m| m == 0));
        self.references = Vec::new();
    }

    /// Whether the next scan copies the values it reads (see `next`).
    #[cfg(test)]
    pub fn copies_in_scan(&self) -> bool {
        self.copy_in_scan
    }

    /// Every pixel one at a time from now on.
    #[cfg(test)]
    pub fn without_dense_path(&mut self) {
        self.dense_path = false;
    }

    /// Every pixel with a change gets a state and a step (tests: the reference for the first
    /// bands, which let a pixel's changes pass without a state).
    #[cfg(test)]
    pub fn without_lazy_bands(&mut self) {
        self.origin.clear();
        self.first_bands_due.clear();
    }

    /// Step the listed pixels over (t0, t1] to this frame's `values`, collecting their events;
    /// then this frame becomes the next ramps' start. The events are counted on `fuse` as they
    /// come; once it has blown the tile stops where it is (then its pixels are partly stepped).
    /// Where most pixels are listed (every pixel changes), they go through the dense path first.
    pub fn step(
        &mut self,
        model: &PixelModel,
        values: &[f32],
        t0_s: f64,
        t1_s: f64,
        clock: &Clock,
        fuse: &EventFuse,
    ) {
        self.events.clear();
        if fuse.is_blown() {
            return;
        }
        // Most pixels listed: every pixel changes (grain, noise), most of them only a little.
        let most_busy = self.busy.len() * DENSE_MIN_BUSY_FRACTION >= values.len();
        let dt_s = t1_s - t0_s;
        let dense = self.dense_path && most_busy && dt_s > 0.0 && dt_s.is_finite();
        let can_wake = model.can_wake();
        let frame = Frame {
            values,
            t0_s,
            t1_s,
            clock,
            fuse,
            can_wake,
            wake_when_still: dense && can_wake && self.lo.is_empty(),
        };
        let mut count = FuseCount {
            reported: 0,
            report_at: REPORT_EVERY_EVENTS,
        };
        let busy = std::mem::take(&mut self.busy);
        let went_on = if !self.references.is_empty() {
            self.step_references(model, &busy, &frame, &mut count)
        } else if dense {
            self.step_dense(model, &busy, &frame, &mut count)
        } else {
            self.step_sparse(model, &busy, &frame, &mut count)
        };
        self.busy = busy;
        if !went_on {
            return;
        }
        fuse.add(self.events.len() - count.reported);
        if frame.can_wake {
            self.update_wake_minima();
        }
        self.keep_values(values);
    }

    /// This frame's values become `last`: `next` where the scan copied them, else the changed
    /// blocks copied now; and whether the next scan copies them (see `next`).
    fn keep_values(&mut self, values: &[f32]) {
        if self.copy_in_scan {
            std::mem::swap(&mut self.last, &mut self.next);
        } else {
            self.keep_changed_blocks(values);
        }
        let most_changed = || {
            let changed: u32 = self.changed_blocks.iter().map(|w| w.count_ones()).sum();
            2 * changed as usize >= self.last.len().div_ceil(BLOCK)
        };
        self.copy_in_scan = !self.references.is_empty() && most_changed();
    }

    /// This frame's values into `last`, in the blocks where one changed: a run of consecutive
    /// changed blocks (where every pixel changes, a whole word's) in one copy.
    fn keep_changed_blocks(&mut self, values: &[f32]) {
        for (word_index, &word) in self.changed_blocks.iter().enumerate() {
            let mut bits = word;
            while bits != 0 {
                let first = bits.trailing_zeros();
                let end_bit = first + (bits >> first).trailing_ones();
                let start = (word_index * 64 + first as usize) * BLOCK;
                let end = ((word_index * 64 + end_bit as usize) * BLOCK).min(values.len());
                self.last[start..end].copy_from_slice(&values[start..end]);
                bits &= u64::MAX.checked_shl(end_bit).unwrap_or(0);
            }
        }
    }
}

/// A frame as `Tile::step` takes it.
struct Frame<'a> {
    values: &'a [f32],
    t0_s: f64,
    t1_s: f64,
    clock: &'a Clock,
    fuse: &'a EventFuse,
    can_wake: bool,
    /// A dense frame of a model without quiet bands: a changed pixel's wake-up bound is left
    /// unknown (`WAKE_UNKNOWN_S`), to be worked out at the next frame only if its input then
    /// stays the same (`settle_wake`); where every pixel changes in every frame, none is.
    wake_when_still: bool,
}

/// A tile takes the dense path when at least 1 / this of its pixels are to be stepped.
const DENSE_MIN_BUSY_FRACTION: usize = 4;
