//! The tile's first bands, worked out lazily around the states already made, against a state
//! for every changed pixel.

use super::*;
use crate::events::Event;
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
fn tile_events(model: &PixelModel, frames: &[Vec<f32>], eager: bool) -> (Vec<Vec<Event>>, usize) {
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
