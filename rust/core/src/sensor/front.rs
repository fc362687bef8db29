//! A frame through every tile: the scan of all of them (validation and the pixels to step), and
//! only once the whole frame is valid, the step of all; their events then go through the latency
//! queue, and a call gives those in (t_prev, t], sorted by (t, y, x).

use rayon::prelude::*;

use super::parallel::for_each_tile;
use super::{EventSensor, FeedError};
use crate::block_flags::{all_valid, valid_value};
use crate::dense;
use crate::events::{EventColumns, OutOfMemory};
use crate::fuse::EventFuse;
use crate::pixel::PixelModel;
use crate::state_arena;
use crate::state_block::LANES;
use crate::tile::{round_up_f32, BlockStore, Clock, Tile, TILE};

impl EventSensor {
    pub(super) fn feed_here(
        &mut self,
        frame: &[f32],
        t_us: i64,
        parallel: bool,
    ) -> Result<EventColumns, FeedError> {
        let Some(origin_us) = self.origin_us else {
            if !frame.par_chunks(TILE).all(all_valid) {
                return Err(self.locate_bad_value(frame));
            }
            self.start(frame, t_us);
            return Ok(EventColumns::default());
        };
        let t0_s = (self.t_prev_us - origin_us) as f64 * 1e-6;
        let t1_s = (t_us - origin_us) as f64 * 1e-6;
        // Validation and the choice of pixels to step share one read of the frame; nothing is
        // changed before the whole frame is known to be valid.
        let t1_up = if self.never_skip {
            f32::INFINITY
        } else {
            round_up_f32(t1_s)
        };
        let all_valid = for_each_tile(&mut self.tiles, frame, parallel, |tile, values| {
            tile.scan(&self.model, values, t1_up)
        });
        if !all_valid {
            return Err(self.locate_bad_value(frame));
        }
        self.busy_last_frame = self.tiles.iter().map(Tile::busy_count).sum();
        let clock = Clock {
            origin_us,
            floor_us: self.t_prev_us + 1,
            width: self.model.params.width,
        };
        let model = &self.model;
        // The events held back count too: this call's output and what it holds back are merged
        // with them, and flush gives them all at once.
        let fuse = EventFuse::new(self.max_events, self.queue.held());
        for_each_tile(&mut self.tiles, frame, parallel, |tile, values| {
            tile.step(model, values, t0_s, t1_s, &clock, &fuse);
            true
        });
        if fuse.is_blown() {
            return Err(self.stop(t_us, fuse.count(), fuse.ran_out_of_memory()));
        }
        let frame_events = self.tiles.iter().map(|tile| &tile.events);
        match self.queue.push_and_take(frame_events, t_us) {
            Ok(events) => {
                self.t_prev_us = t_us;
                Ok(events)
            }
            Err(OutOfMemory { events }) => Err(self.stop(t_us, events, true)),
        }
    }

    /// Where the first invalid value is (the slow search runs only once a frame is refused).
    fn locate_bad_value(&self, frame: &[f32]) -> FeedError {
        let index = frame.iter().position(|v| !valid_value(*v)).unwrap_or(0);
        let (x, y) = (
            index % self.model.params.width,
            index / self.model.params.width,
        );
        let value = frame[index];
        if value.is_finite() {
            FeedError::Negative { x, y, value }
        } else {
            FeedError::NotFinite { x, y, value }
        }
    }

    fn start(&mut self, frame: &[f32], t_us: i64) {
        let model = &self.model;
        let stores = block_stores(model, frame);
        self.tiles = frame
            .par_chunks(TILE)
            .zip(stores)
            .enumerate()
            .map(|(i, (values, blocks))| Tile::start(model, i * TILE, values, blocks))
            .collect();
        self.busy_last_frame = self.tiles.iter().map(Tile::first_wakes_to_work_out).sum();
        self.origin_us = Some(t_us);
        self.t_prev_us = t_us;
        self.queue.clear();
    }
}

/// Room for the state blocks of each tile of `frame`: for the models the dense path steps, all
/// in one arena of huge pages (see `state_arena`), else reserved tile by tile.
fn block_stores(model: &PixelModel, frame: &[f32]) -> Vec<BlockStore> {
    let blocks: Vec<usize> = frame
        .chunks(TILE)
        .map(|values| values.len().div_ceil(LANES))
        .collect();
    let arena = dense::applies_to(model)
        .then(|| state_arena::stores_in_one_arena(&blocks))
        .flatten();
    arena.unwrap_or_else(|| {
        blocks
            .iter()
            .map(|&n| BlockStore::with_capacity(n))
            .collect()
    })
}
