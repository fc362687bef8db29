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

use crate::block_flags::{self, Avx2, BLOCK};
use crate::dense::{self, Inputs};
use crate::events::{Event, EventRun};
pub use crate::f32_bounds::round_up_f32;
use crate::f32_bounds::{band_inside_f32, round_down_f32};
use crate::first_band;
use crate::fuse::{EventFuse, REPORT_EVERY_EVENTS};
use crate::pixel::{PixelEvent, PixelModel, PixelState, Segment, GROUP, RAMP_VALUES};
pub use crate::state_arena::BlockStore;
use crate::state_block::{bits_of, StateBlock, LANES};

/// Pixels per tile: large enough to amortise scheduling, small enough to balance two or more
/// threads on a 346 x 260 sensor.
pub const TILE: usize = 4096;
// Pixels are tested together a block at a time (`block_flags::BLOCK`), as their states are
// stored together and their first bands worked out together; `used` masks are one bit per pixel
// of a block.
const _: () = assert!(first_band::BLOCK == BLOCK && BLOCK == LANES);

/// Turns a pixel's event (seconds since the first frame) into an output event.
pub struct Clock {
    pub origin_us: i64,
    /// Events of this frame come after the previous frame's time, even when rounding says not.
    pub floor_us: i64,
    pub width: usize,
}

impl Clock {
    #[inline]
    fn address(&self, pixel: usize) -> (u16, u16) {
        ((pixel % self.width) as u16, (pixel / self.width) as u16)
    }

    #[inline]
    fn event(&self, (x, y): (u16, u16), e: PixelEvent) -> Event {
        Event {
            // Rounded half up by adding 0.5 and truncating, exact for the t_s >= 0 of events
            // (f64::round is a library call on baseline x86-64).
            t_us: (self.origin_us + (e.t_s * 1e6 + 0.5) as i64).max(self.floor_us),
            x,
            y,
            p: e.on as i8,
            label: e.cause as u8,
        }
    }
}

/// One pixel's events of a frame as the pixel model emits them, into the tile's run.
struct PixelEvents<'a> {
    run: &'a mut EventRun,
    clock: &'a Clock,
    pixel: usize,
    /// The address costs a division: worked out only once the pixel has an event.
    address: Option<(u16, u16)>,
    mark: usize,
}

impl<'a> PixelEvents<'a> {
    #[inline(always)]
    fn open(run: &'a mut EventRun, clock: &'a Clock, pixel: usize) -> Self {
        let mark = run.mark();
        Self {
            run,
            clock,
            pixel,
            address: None,
            mark,
        }
    }

    #[inline(always)]
    fn push(&mut self, e: PixelEvent) {
        let (clock, pixel) = (self.clock, self.pixel);
        let address = *self.address.get_or_insert_with(|| clock.address(pixel));
        self.run.push(clock.event(address, e));
    }

    /// The pixel's events are all in (see `EventRun::close_pixel`).
    #[inline(always)]
    fn close(self) {
        self.run.close_pixel(self.mark);
    }
}

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
    /// Pixels of dense frames stepped one at a time whose wake-up bound was left unknown
    /// (`Frame::wake_when_still`).
    #[cfg(test)]
    pub wakes_left_unknown: usize,
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
            events: EventRun::default(),
            dense_path: dense::applies_to(model),
            #[cfg(test)]
            dense_steps: 0,
            #[cfg(test)]
            gated_blocks: [0; 2],
            #[cfg(test)]
            wakes_left_unknown: 0,
        };
        tile.block_wake_s = tile.wake_s.chunks(BLOCK).map(min_f32).collect();
        tile.wake_min_s = min_f32(&tile.block_wake_s);
        tile
    }

    /// The first-frame values of the pixels without a state: `origin` where kept, else `last`
    /// (such a pixel has then had no change).
    fn first_values(&self) -> &[f32] {
        if self.origin.is_empty() {
            &self.last
        } else {
            &self.origin
        }
    }

    /// Whether pixel `j` has a state.
    #[inline(always)]
    fn has_state(&self, j: usize) -> bool {
        self.made[j / LANES] & (1 << (j % LANES)) != 0
    }

    /// Pixel `j`'s state, settled at time 0 s at its first-frame value (its block made first
    /// where it has none); returns where it is (block slot, lane).
    #[cold]
    fn make_state(&mut self, model: &PixelModel, j: usize) -> (usize, usize) {
        let (b, k) = (j / LANES, j % LANES);
        let slot = self.block_made(b);
        let pixel = (self.first_pixel + j) as u64;
        let state = model.init(pixel, self.first_values()[j] as f64, 0.0);
        self.blocks[slot].set(k, &state);
        self.note_gates(b, state.hot_next_s, state.refractory_mark_s);
        self.made[b] |= 1 << k;
        (slot, k)
    }

    /// A state of block `b` with these gates was made or stepped (see `block_gates_until_s`):
    /// kept only for the dense path.
    #[inline]
    fn note_gates(&mut self, b: usize, hot_next_s: f64, refractory_mark_s: f64) {
        if !self.dense_path {
            return;
        }
        let until_s = if hot_next_s < f64::INFINITY {
            f64::INFINITY
        } else {
            refractory_mark_s
        };
        self.block_gates_until_s[b] = self.block_gates_until_s[b].max(until_s);
    }

    /// Whether the dense path must read the gates of block `b`'s states in a frame from `t0_s`
    /// (see `dense::Inputs::gates`).
    #[inline(always)]
    fn reads_gates(&self, b: usize, t0_s: f64) -> bool {
        self.block_gates_until_s[b] > t0_s
    }

    /// `make_state` of the pixels of block `b` in `pixels` (bit k: pixel k; none has a state):
    /// where every pixel changes, the first changed frame makes every state, a block at once.
    fn make_states(&mut self, model: &PixelModel, b: usize, pixels: u32) {
        if pixels.count_ones() < BLOCK_INIT_MIN_PIXELS {
            let mut rest = pixels;
            while rest != 0 {
                self.make_state(model, b * LANES + rest.trailing_zeros() as usize);
                rest &= rest - 1;
            }
            return;
        }
        let slot = self.block_made(b);
        let start = b * LANES;
        let first_values = lanes_from(self.first_values(), start);
        let first_pixel = (self.first_pixel + start) as u64;
        model.init_block(
            first_pixel,
            &first_values,
            0.0,
            pixels,
            &mut self.blocks[slot],
        );
        let mut rest = pixels;
        while rest != 0 {
            let k = rest.trailing_zeros() as usize;
            let block = &self.blocks[slot];
            self.note_gates(b, block.hot_next_s[k], block.refractory_mark_s[k]);
            rest &= rest - 1;
        }
        self.made[b] |= pixels;
    }

    /// Where block `b`'s states are (its slot), made empty first where it has none.
    fn block_made(&mut self, b: usize) -> usize {
        if self.block_slot[b] == NO_STATE {
            self.block_slot[b] = self.blocks.push(StateBlock::empty()) as u32;
        }
        self.block_slot[b] as usize
    }

    /// Pixels that need stepping to `t1_up` (rounded up), listed for `step`; returns whether
    /// every value is a usable photocurrent. Changes nothing else but the first bands of the
    /// blocks that changed (see the module's note).
    pub fn scan(&mut self, model: &PixelModel, values: &[f32], t1_up: f32) -> bool {
        // The scan is most of a static frame's cost, and 8-wide compares halve it: compiled
        // twice, the AVX2 copy is chosen at run time so the wheel still runs on any x86-64.
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = Avx2::detect() {
            // SAFETY: the CPU supports AVX2 (an `Avx2` says so).
            return unsafe { self.scan_avx2(model, values, t1_up, avx2) };
        }
        self.scan_portable(model, values, t1_up, None)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn scan_avx2(
        &mut self,
        model: &PixelModel,
        values: &[f32],
        t1_up: f32,
        avx2: Avx2,
    ) -> bool {
        self.scan_portable(model, values, t1_up, Some(avx2))
    }

    #[inline(always)]
    fn scan_portable(
        &mut self,
        model: &PixelModel,
        values: &[f32],
        t1_up: f32,
        avx2: Option<Avx2>,
    ) -> bool {
        self.busy.clear();
        self.due_by_s = t1_up;
        if self.first_wakes_due {
            self.set_first_wakes(model, values);
        }
        // Most frames come before every pixel's wake-up time: then no block is due.
        let due_by = (t1_up >= self.wake_min_s).then_some(t1_up);
        let mut scan = Scan::new(
            std::mem::take(&mut self.busy),
            std::mem::take(&mut self.changed_blocks),
            avx2,
        );
        let full = values.len() / BLOCK * BLOCK;
        if self.copy_in_scan {
            self.next.resize(values.len(), 0.0);
        }
        match (due_by, self.copy_in_scan) {
            (None, false) => self.scan_whole_blocks::<false, false>(model, values, 0.0, &mut scan),
            (None, true) => self.scan_whole_blocks::<false, true>(model, values, 0.0, &mut scan),
            (Some(t1), false) => {
                self.scan_whole_blocks::<true, false>(model, values, t1, &mut scan)
            }
            (Some(t1), true) => self.scan_whole_blocks::<true, true>(model, values, t1, &mut scan),
        }
        if full < values.len() {
            self.scan_tail(model, values, full, due_by, &mut scan);
        }
        self.busy = scan.busy;
        self.changed_blocks = scan.changed_blocks;
        scan.valid
    }

    /// The whole blocks of `scan`, by iterators (no index checks); with `DUE`, a block whose
    /// earliest wake-up is by `t1_up` is looked at closely. Only a block with something
    /// noteworthy (a changed value, a wake-up due) goes further: its first bands where still
    /// due, then its flags. With `COPY`, every value goes into `next` too.
    #[inline(always)]
    fn scan_whole_blocks<const DUE: bool, const COPY: bool>(
        &mut self,
        model: &PixelModel,
        values: &[f32],
        t1_up: f32,
        scan: &mut Scan,
    ) {
        let blocks = values
            .chunks_exact(BLOCK)
            .zip(self.last.chunks_exact(BLOCK))
            .zip(self.wake_s.chunks_exact(BLOCK))
            .zip(&self.block_wake_s);
        // Once every block has its first bands (or without them), the loop skips the test.
        let first_bands_left = !self.first_bands_due.is_empty();
        for (b, (((value, last), wake_s), &block_wake_s)) in blocks.enumerate() {
            let start = b * BLOCK;
            let (value, last) = (block_of(value), block_of(last));
            prefetch_bytes(value.as_ptr().wrapping_add(SCAN_PREFETCH_AHEAD), BLOCK * 4);
            if COPY {
                *block_of_mut(&mut self.next[start..start + BLOCK]) = *value;
            }
            let due_by = (DUE && t1_up >= block_wake_s).then_some(t1_up);
            let changed = any_changed(value, last);
            if !changed && due_by.is_none() {
                continue;
            }
            let first_bands = changed
                && first_bands_left
                && take_bit_if(&mut self.first_bands_due, b, || most_changed(value, last));
            if first_bands {
                let range = start..start + BLOCK;
                set_first_bands(
                    model,
                    self.first_pixel + start,
                    &self.origin[range.clone()],
                    self.made[b],
                    &mut self.lo[range.clone()],
                    &mut self.hi[range],
                );
                forget_if_none(&mut self.first_bands_due);
            }
            let range = start..start + BLOCK;
            let inputs = block_flags::Inputs {
                value,
                last,
                band: (!self.lo.is_empty())
                    .then(|| (block_of(&self.lo[range.clone()]), block_of(&self.hi[range]))),
                wake_s: block_of(wake_s),
            };
            scan.block(start, &inputs, changed, due_by, u32::MAX);
        }
    }

    /// The last, shorter block of `scan`, from pixel `full` on, as `scan_whole_blocks` takes a
    /// whole one.
    fn scan_tail(
        &mut self,
        model: &PixelModel,
        values: &[f32],
        full: usize,
        due_by: Option<f32>,
        scan: &mut Scan,
    ) {
        if self.copy_in_scan {
            self.next[full..].copy_from_slice(&values[full..]);
        }
        let (value, last) = (&values[full..], &self.last[full..]);
        let changed_count = value.iter().zip(last).filter(|(v, l)| v != l).count();
        let most_changed = || 2 * changed_count >= value.len();
        let changed = changed_count > 0;
        if changed && take_bit_if(&mut self.first_bands_due, full / BLOCK, most_changed) {
            self.set_first_bands(model, full..values.len());
        }
        let tail = Padded::new(self, values, full);
        let used = (1u32 << (values.len() - full)) - 1;
        let block_wake_s = self.block_wake_s[full / BLOCK];
        let due = due_by.filter(|&t| t >= block_wake_s);
        if changed || due.is_some() {
            scan.block(full, &tail.inputs(!self.lo.is_empty()), changed, due, used);
        }
    }

    /// The first wake-ups of the pixels without a state whose input has stayed at the first
    /// frame's (the others get a state this frame), and the earliest of the tile again. They
    /// depend on the first frame alone, so a frame the scan refuses may leave them.
    #[cold]
    fn set_first_wakes(&mut self, model: &PixelModel, values: &[f32]) {
        for (j, &value) in values.iter().enumerate() {
            if value == self.last[j] {
                self.settle_wake(model, j);
            }
        }
        for (block_wake_s, wake_s) in self.block_wake_s.iter_mut().zip(self.wake_s.chunks(BLOCK)) {
            *block_wake_s = min_f32(wake_s);
        }
        self.wake_min_s = min_f32(&self.block_wake_s);
        self.first_wakes_due = false;
    }

    /// The first bands of the pixels `range` (one block or less), for those without a state.
    fn set_first_bands(&mut self, model: &PixelModel, range: std::ops::Range<usize>) {
        set_first_bands(
            model,
            self.first_pixel + range.start,
            &self.origin[range.clone()],
            self.made[range.start / BLOCK],
            &mut self.lo[range.clone()],
            &mut self.hi[range],
        );
        forget_if_none(&mut self.first_bands_due);
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

    /// The listed pixels one at a time; returns false where the fuse stopped it.
    fn step_sparse(
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

    /// The listed pixels of a reference-only model, `GROUP` at a time: their ramps' ends (and
    /// first references) together, then each one's reference along its ramp, then their bands
    /// around the new ones together. Such a pixel never wakes: it is listed because its input
    /// changed (or, in tests, because the sensor never skips: a flat ramp, which stays between
    /// its thresholds).
    fn step_references(
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

    /// The listed pixels a block at a time: the quiet ones of a block stepped together, the
    /// others (an event, a reset to release, ...) one at a time after, in pixel order, so the
    /// events come in the same order. Returns false where the fuse stopped it.
    fn step_dense(
        &mut self,
        model: &PixelModel,
        busy: &[u32],
        frame: &Frame,
        count: &mut FuseCount,
    ) -> bool {
        let mut rest = busy;
        while let Some((b, listed, after)) = first_block(rest) {
            rest = after;
            let mask = if listed.len() == LANES {
                u32::MAX
            } else {
                listed
                    .iter()
                    .fold(0, |mask, &j| mask | 1 << (j as usize % LANES))
            };
            // The block after next (its fields the step reads): asked for now, it is in the
            // cache by then, where the hardware's prefetcher stops at each page.
            if let Some(&ahead) = after.get(DENSE_PREFETCH_AHEAD) {
                self.prefetch_block(ahead as usize / LANES, frame.t0_s);
            }
            if let Some(&next) = after.first() {
                self.prefetch_block_to_l1(next as usize / LANES);
            }
            let went_on = if listed.len() >= DENSE_MIN_LISTED {
                self.step_block(model, b, mask, frame, count)
            } else {
                listed
                    .iter()
                    .all(|&j| self.step_one(model, j as usize, frame, count))
            };
            if !went_on {
                return false;
            }
        }
        true
    }

    /// The listed pixels of block `b` (bit k of `mask`: pixel k of the block) through the
    /// dense path (see `step_dense`).
    fn step_block(
        &mut self,
        model: &PixelModel,
        b: usize,
        mask: u32,
        frame: &Frame,
        count: &mut FuseCount,
    ) -> bool {
        let start = b * LANES;
        let value = lanes_from(frame.values, start);
        let last = lanes_from(&self.last, start);
        // The listed pixels whose input changed: the only ones the dense step may take (the
        // others are listed for a wake-up, and need a state only if it is due).
        let changed = mask & changed_bits(&value, &last);
        let without_state = changed & !self.made[b];
        if without_state != 0 {
            self.make_states(model, b, without_state);
        }
        let inputs = Inputs {
            value,
            last,
            listed: mask,
            // Once the block's new states are made: they may be hot.
            gates: self.reads_gates(b, frame.t0_s),
        };
        let stepped = if changed == 0 {
            [false; LANES]
        } else {
            let slot = self.block_slot[b] as usize;
            dense::step_quiet(
                model,
                &mut self.blocks[slot],
                &inputs,
                frame.t0_s,
                frame.t1_s,
            )
        };
        let end = (start + LANES).min(self.last.len());
        for (wake_s, &stepped) in self.wake_s[start..end].iter_mut().zip(&stepped) {
            *wake_s = if stepped { WAKE_UNKNOWN_S } else { *wake_s };
        }
        let stepped = bits_of(&stepped);
        #[cfg(test)]
        {
            self.dense_steps += stepped.count_ones() as usize;
            self.gated_blocks[inputs.gates as usize] += (stepped != 0) as usize;
        }
        // The others one at a time, in pixel order.
        let mut others = mask & !stepped;
        // Their whole states, all asked for at once: the fields the dense step did not read are
        // in no cache, and asked for one pixel at a time each pixel's misses would wait for the
        // last pixel's step.
        let mut ahead = others;
        while ahead != 0 {
            self.prefetch_state((start + ahead.trailing_zeros() as usize) as u32);
            ahead &= ahead - 1;
        }
        while others != 0 {
            let j = start + others.trailing_zeros() as usize;
            if !self.step_one(model, j, frame, count) {
                return false;
            }
            others &= others - 1;
        }
        true
    }

    /// Ask for pixel `j`'s state to be brought into the cache (none: nothing to fetch): one
    /// cache line from each field's array.
    #[inline(always)]
    fn prefetch_state(&self, j: u32) {
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

    /// Ask for the fields of block `b`'s states that the dense path reads in a frame from
    /// `t0_s`, into the second-level cache: its 40 or 48 lines a block would fill the first
    /// level's few outstanding-miss slots, and the loads waiting for them stall (a 1280 x 720
    /// sensor, whose states come from memory: 14 against 17-18 ns a pixel update,
    /// `dense --once davis346 30 0.01 1280x720`).
    #[inline(always)]
    fn prefetch_block(&self, b: usize, t0_s: f64) {
        if let Some(block) = self.blocks.get(self.block_slot[b] as usize) {
            let fields = if self.reads_gates(b, t0_s) {
                DENSE_FIELDS + GATE_FIELDS
            } else {
                DENSE_FIELDS
            };
            prefetch_bytes_to_l2(std::ptr::from_ref(block), fields * LANES * 8);
        }
    }

    /// Ask for the fields of block `b`'s states that the dense path always reads, from the
    /// second-level cache (`prefetch_block`) into the first, a block ahead: the step's loads
    /// otherwise wait on them (1280 x 720, every pixel changing: about 5 % of a frame).
    #[inline(always)]
    fn prefetch_block_to_l1(&self, b: usize) {
        if let Some(block) = self.blocks.get(self.block_slot[b] as usize) {
            prefetch_bytes(std::ptr::from_ref(block), DENSE_FIELDS * LANES * 8);
        }
    }

    /// Where pixel `j`'s state is (block slot, lane), made now if it has none yet.
    #[inline]
    fn state_slot(&mut self, model: &PixelModel, j: usize) -> (usize, usize) {
        if self.has_state(j) {
            (self.block_slot[j / LANES] as usize, j % LANES)
        } else {
            self.make_state(model, j)
        }
    }

    /// One pixel through the pixel model, its events collected and its gates renewed; returns
    /// false where the fuse stops the tile.
    #[inline]
    fn step_one(
        &mut self,
        model: &PixelModel,
        j: usize,
        frame: &Frame,
        count: &mut FuseCount,
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

    /// Every pixel with a change gets a state and a step (tests: the reference for the first
    /// bands, which let a pixel's changes pass without a state).
    #[cfg(test)]
    pub fn without_lazy_bands(&mut self) {
        self.origin.clear();
        self.first_bands_due.clear();
    }

    /// Pixel `j`'s wake-up bound worked out where it is unknown (`WAKE_UNKNOWN_S`); returns
    /// whether it was, and comes after the time by which the scan listed the pixels due.
    fn settle_wake(&mut self, model: &PixelModel, j: usize) -> bool {
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

    /// `report` once this frame's events reach `count.report_at` (one compare a pixel); returns
    /// whether to go on.
    #[inline(always)]
    fn report_if_due(&mut self, fuse: &EventFuse, count: &mut FuseCount) -> bool {
        if self.events.len() < count.report_at {
            return true;
        }
        let go_on = self.report(fuse, &mut count.reported);
        count.report_at = count.reported + REPORT_EVERY_EVENTS;
        go_on
    }

    /// Count the events since the last report on the fuse and make room for the next ones, and
    /// for a pixel's that pass the next report (a growth that fails blows the fuse instead of
    /// aborting); returns whether to go on.
    #[cold]
    fn report(&mut self, fuse: &EventFuse, reported: &mut usize) -> bool {
        let count = self.events.len();
        let go_on = fuse.add(count - *reported);
        *reported = count;
        if go_on && !self.events.try_reserve(2 * REPORT_EVERY_EVENTS) {
            fuse.out_of_memory();
            return false;
        }
        go_on
    }

    /// The earliest wake-up times again, of the blocks with a stepped pixel and of the tile.
    fn update_wake_minima(&mut self) {
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

    /// The pixel's wake-up time (left infinite when no pixel can wake) and quiet band again.
    fn update_gate(&mut self, model: &PixelModel, j: usize, st: &PixelState, can_wake: bool) {
        if can_wake {
            self.wake_s[j] = round_down_f32(model.wake_s(st));
        }
        if !self.lo.is_empty() {
            (self.lo[j], self.hi[j]) = band_inside_f32(model.quiet_band(st));
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

/// The tile's events counted on the fuse so far, and the count at which to report again: one
/// compare a pixel (a pixel's events are bounded by its log range over theta_min).
struct FuseCount {
    reported: usize,
    report_at: usize,
}

/// The wake-up time of a pixel whose bound is yet to be worked out (after a dense step, see the
/// module `dense`, or before its first state): before any frame, so the next scan lists the
/// pixel, and `step_one` works the bound out where its input did not change.
const WAKE_UNKNOWN_S: f32 = f32::NEG_INFINITY;

/// How many listed pixels ahead the dense path asks for a block's states (in a busy tile about
/// two blocks).
const DENSE_PREFETCH_AHEAD: usize = 2 * LANES;

/// Fewer pixels of a block than this get their first states one at a time (`init`), more all
/// at once (`init_block`, whose lanes cost about as many instructions as 12 pixels one at a
/// time: 6,800 a block on the AVX2 path, callgrind).
const BLOCK_INIT_MIN_PIXELS: u32 = 12;

/// A block with fewer listed pixels than this has them stepped one at a time.
const DENSE_MIN_LISTED: usize = 8;

/// The fields of a `StateBlock`; the first of them, which the dense path reads; and the two after
/// those, which it reads only where a block's gates can matter (`Tile::reads_gates`).
const STATE_FIELDS: usize = 16;
const DENSE_FIELDS: usize = 10;
const GATE_FIELDS: usize = 2;

/// A tile takes the dense path when at least 1 / this of its pixels are to be stepped.
const DENSE_MIN_BUSY_FRACTION: usize = 4;

/// What `Tile::scan` gathers block by block.
struct Scan {
    /// The pixels to step, as indices in the tile.
    busy: Vec<u32>,
    valid: bool,
    /// Bit b of word w: a value changed in block 64 w + b.
    changed_blocks: Vec<u64>,
    /// The flags' AVX2 copy, where the CPU has it.
    avx2: Option<Avx2>,
}

impl Scan {
    fn new(busy: Vec<u32>, mut changed_blocks: Vec<u64>, avx2: Option<Avx2>) -> Self {
        changed_blocks.fill(0);
        Self {
            busy,
            valid: true,
            changed_blocks,
            avx2,
        }
    }

    /// One block with a changed value (`changed`, from `any_changed`) or a wake-up due: the
    /// flags of all its pixels at once (vector compares), then the set ones alone.
    #[inline(always)]
    fn block(
        &mut self,
        start: usize,
        inputs: &block_flags::Inputs,
        changed: bool,
        due_by: Option<f32>,
        used: u32,
    ) {
        let flags = block_flags::flags(inputs, due_by, self.avx2);
        self.valid &= flags.invalid & used == 0;
        if changed {
            let block_index = start / BLOCK;
            self.changed_blocks[block_index / 64] |= 1 << (block_index % 64);
        }
        let mut busy = flags.busy & used;
        if busy == u32::MAX {
            // Every pixel of the block (every pixel changes): a run, without a test a pixel.
            self.busy.extend(start as u32..(start + BLOCK) as u32);
            return;
        }
        while busy != 0 {
            self.busy
                .push((start + busy.trailing_zeros() as usize) as u32);
            busy &= busy - 1;
        }
    }
}

/// Bit k set where `value[k]` differs from `last[k]`.
#[inline(always)]
fn changed_bits(value: &[f32; LANES], last: &[f32; LANES]) -> u32 {
    let mut bits = 0;
    for k in 0..LANES {
        bits |= ((value[k] != last[k]) as u32) << k;
    }
    bits
}

/// The block of the first listed pixel (`busy` is in pixel order), that block's listed pixels,
/// and the pixels after them; None for an empty list.
#[inline(always)]
fn first_block(busy: &[u32]) -> Option<(usize, &[u32], &[u32])> {
    let block = *busy.first()? as usize / BLOCK;
    let next = ((block + 1) * BLOCK) as u32;
    // A block has at most BLOCK listed pixels: the search looks at those alone. Where every
    // pixel changes, the block's last pixel is the BLOCK-th listed (the list has no repeats):
    // the whole block, without the search.
    let in_block = if busy.get(BLOCK - 1) == Some(&(next - 1)) {
        BLOCK
    } else {
        busy[..busy.len().min(BLOCK)].partition_point(|&j| j < next)
    };
    let (listed, after) = busy.split_at(in_block);
    Some((block, listed, after))
}

/// Whether any value of a block differs from the last frame's: a branch-free test of all its
/// pixels at once (vector compares). The last frame's values are valid, so a value equal to one
/// is too (NaN equals nothing): validity is left to the flags.
#[inline(always)]
fn any_changed(value: &[f32; BLOCK], last: &[f32; BLOCK]) -> bool {
    let mut any = false;
    for k in 0..BLOCK {
        any |= value[k] != last[k];
    }
    any
}

/// Whether most values of a block differ from the last frame's (see `first_bands_due`).
#[inline(always)]
fn most_changed(value: &[f32; BLOCK], last: &[f32; BLOCK]) -> bool {
    let mut count = 0;
    for k in 0..BLOCK {
        count += (value[k] != last[k]) as u32;
    }
    2 * count as usize >= BLOCK
}

/// Clears bit `b` where it is set (absent: clear) and `also` holds (asked only then); returns
/// whether it did.
#[inline(always)]
fn take_bit_if(bits: &mut [u64], b: usize, also: impl FnOnce() -> bool) -> bool {
    match bits.get_mut(b / 64) {
        Some(word) if *word >> (b % 64) & 1 != 0 && also() => {
            *word &= !(1 << (b % 64));
            true
        }
        _ => false,
    }
}

/// Drops `bits` once none is set, so that a test of a bit in it is one of its length.
fn forget_if_none(bits: &mut Vec<u64>) {
    if bits.iter().all(|&word| word == 0) {
        *bits = Vec::new();
    }
}

/// `n` bits, all set.
fn all_bits(n: usize) -> Vec<u64> {
    let mut bits = vec![u64::MAX; n.div_ceil(64)];
    if !n.is_multiple_of(64) {
        bits[n / 64] = (1 << (n % 64)) - 1;
    }
    bits
}

/// The first bands of the pixels from `first_pixel` on (one block or less, with first-frame
/// values `origin`) but those of `has_state`; worked out once a block, the first time it
/// changes.
#[cold]
#[inline(never)]
fn set_first_bands(
    model: &PixelModel,
    first_pixel: usize,
    origin: &[f32],
    has_state: u32,
    lo: &mut [f32],
    hi: &mut [f32],
) {
    first_band::set_first_bands(model, first_pixel as u64, origin, has_state, lo, hi);
}

#[inline(always)]
fn block_of(values: &[f32]) -> &[f32; BLOCK] {
    values.try_into().expect("a whole block")
}

#[inline(always)]
fn block_of_mut(values: &mut [f32]) -> &mut [f32; BLOCK] {
    values.try_into().expect("a whole block")
}

/// The last, shorter block of a tile, padded to a whole one (the padding is masked out).
struct Padded {
    value: [f32; BLOCK],
    last: [f32; BLOCK],
    lo: [f32; BLOCK],
    hi: [f32; BLOCK],
    wake_s: [f32; BLOCK],
}

impl Padded {
    fn new(tile: &Tile, values: &[f32], start: usize) -> Self {
        let fill = |from: &[f32]| {
            let mut block = [0.0; BLOCK];
            if !from.is_empty() {
                block[..from.len() - start].copy_from_slice(&from[start..]);
            }
            block
        };
        Self {
            value: fill(values),
            last: fill(&tile.last),
            lo: fill(&tile.lo),
            hi: fill(&tile.hi),
            wake_s: fill(&tile.wake_s),
        }
    }

    fn inputs(&self, with_band: bool) -> block_flags::Inputs<'_> {
        block_flags::Inputs {
            value: &self.value,
            last: &self.last,
            band: with_band.then_some((&self.lo, &self.hi)),
            wake_s: &self.wake_s,
        }
    }
}

/// Pixels looked up this far ahead of their use in `Tile::step` (their states), and twice as
/// far (their indices and values).
const PREFETCH_AHEAD: usize = 4;

/// Values asked for this far ahead of the scan (4 KiB): the frame comes from memory, not the
/// cache, and the hardware prefetcher stops at each 4 KiB page; asking ahead keeps the loads
/// of the next pages under way while a block is tested.
const SCAN_PREFETCH_AHEAD: usize = 1024;

/// The block of `LANES` values from `start` (the last, shorter one padded with zeros).
#[inline(always)]
fn lanes_from(values: &[f32], start: usize) -> [f32; LANES] {
    match values.get(start..start + LANES) {
        Some(whole) => whole.try_into().expect("a whole block"),
        None => {
            let mut padded = [0.0; LANES];
            padded[..values.len() - start].copy_from_slice(&values[start..]);
            padded
        }
    }
}

/// A hint to load `bytes` bytes from `start` into the cache; it never faults, so any address
/// will do (those past the end of an array are simply wasted).
#[inline(always)]
fn prefetch_bytes<T>(start: *const T, bytes: usize) {
    prefetch_lines::<TO_L1, T>(start, bytes);
}

/// `prefetch_bytes` into the second-level cache (and those beyond it), not the first.
#[inline(always)]
fn prefetch_bytes_to_l2<T>(start: *const T, bytes: usize) {
    prefetch_lines::<TO_L2, T>(start, bytes);
}

/// x86's prefetch hints (`_MM_HINT_T0`, `_MM_HINT_T1`): into every cache level, or from the
/// second level on.
const TO_L1: i32 = 3;
const TO_L2: i32 = 2;

#[inline(always)]
fn prefetch_lines<const HINT: i32, T>(start: *const T, bytes: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        let start = start.cast::<i8>();
        for offset in (0..bytes).step_by(64) {
            // SAFETY: a prefetch is only a hint to the cache and cannot fault.
            unsafe { std::arch::x86_64::_mm_prefetch::<HINT>(start.wrapping_add(offset)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (start, bytes);
}

/// The smallest value (wake-up times are never NaN), eight lanes at a time so it vectorises.
fn min_f32(values: &[f32]) -> f32 {
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

/// One pixel over (t0, t1]: held at its last input since its state's time, then the ramp (linear
/// in log) from the last frame's value to this one's.
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
    model.run(st, pixel, &ramp, events);
}
#[cfg(all(test, target_arch = "x86_64"))]
const _: () =
    assert!(TO_L1 == std::arch::x86_64::_MM_HINT_T0 && TO_L2 == std::arch::x86_64::_MM_HINT_T1);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{ReferenceReset, SensorParams};
    use crate::rng::{Draw, Stream};

    /// A moving edge over `n` pixels (frames 1 to 4: a few pixels of each block jump to five
    /// times their value and get states, too few for the block's first bands), then grain on
    /// every pixel with a jump here and there (frames 5 on: the first bands, around those states).
    fn edge_then_grain(n: usize) -> Vec<Vec<f32>> {
        let draw = |j: usize, k: usize| Draw::new(11, j as u64, k as u64).uniform(Stream::Jitter);
        let texture: Vec<f32> = (0..n).map(|j| (0.05 + draw(j, 0)) as f32).collect();
        let mut frames = vec![texture.clone()];
        for k in 1..16 {
            let frame = (0..n).map(|j| {
                let value = texture[j] as f64;
                if k < 5 {
                    let edge = j % BLOCK < 2 * k;
                    (if edge { 5.0 * value } else { value }) as f32
                } else if draw(j, k) < 0.03 {
                    (0.05 + draw(j, k + 100)) as f32
                } else {
                    (value * (1.0 + 0.02 * (draw(j, k + 200) - 0.5))) as f32
                }
            });
            frames.push(frame.collect());
        }
        frames
    }

    /// Each frame's events of a tile of `frames[0].len()` pixels fed `frames` 1 ms apart, and
    /// how many states it made; `eager` gives every changed pixel a state (no first bands).
    fn tile_events(
        model: &PixelModel,
        frames: &[Vec<f32>],
        eager: bool,
    ) -> (Vec<Vec<Event>>, usize) {
        let blocks = BlockStore::with_capacity(frames[0].len().div_ceil(LANES));
        let mut tile = Tile::start(model, 0, &frames[0], blocks);
        if eager {
            tile.without_lazy_bands();
        }
        let fuse = EventFuse::new(usize::MAX, 0);
        let mut events = Vec::new();
        for (k, frame) in frames.iter().enumerate().skip(1) {
            let (t0_s, t1_s) = ((k - 1) as f64 * 1e-3, k as f64 * 1e-3);
            assert!(tile.scan(model, frame, round_up_f32(t1_s)));
            let floor_us = (t0_s * 1e6) as i64 + 1;
            let clock = Clock {
                origin_us: 0,
                floor_us,
                width: 16,
            };
            tile.step(model, frame, t0_s, t1_s, &clock, &fuse);
            events.push(tile.events.as_slice().to_vec());
        }
        (events, tile.state_count())
    }

    #[test]
    fn first_bands_around_existing_states_give_the_events_of_a_state_for_every_change() {
        // ESIM's reset and mismatched thresholds (first bands one pixel at a time); 300 pixels
        // end with a short block.
        let mut esim = SensorParams::ideal(300, 1);
        esim.reference_reset = ReferenceReset::Event;
        let mut mismatched = SensorParams::ideal(300, 1);
        mismatched.theta_sigma = 0.03;
        let frames = edge_then_grain(300);
        for params in [esim, mismatched] {
            let model = PixelModel::new(params);
            let (eager, eager_states) = tile_events(&model, &frames, true);
            let (lazy, lazy_states) = tile_events(&model, &frames, false);
            let count: usize = eager.iter().map(Vec::len).sum();
            assert!(count > 500, "{count} events");
            assert!(eager == lazy, "events differ");
            // The edge's 8 pixels a block have states; of the rest, jumps made some.
            assert!(
                lazy_states >= 8 * 9 + 4 && 2 * lazy_states < eager_states,
                "{lazy_states}"
            );
        }
    }
}
