//! pecs-core: the physics and numerics of pecs, with no Python and no files.
//!
//! One physical concept per module: counter-based random numbers (`rng`), sensor parameters
//! (`params`), the photoreceptor (`photoreceptor`), exact crossing times (`crossing`), background
//! noise (`noise`), one pixel (`pixel`), the streaming sensor (`sensor`: a frame's passes through
//! the tiles, on threads or not, the bound on a gap's noise, the errors) and its tiles of pixels
//! (`tile`: the scan, the states made when needed, the one-pixel, dense and reference-only steps,
//! their events) with the flags their scan finds a block at a time (`block_flags`),
//! the dense path that steps a tile's pixels several at a time (`dense`) straight from states stored
//! field by field (`state_block`), the quiet bands of pixels' first states a block at a time
//! (`first_band`), f32 bounds of the gates (`f32_bounds`), its events (`events`) and the bound on
//! them per call (`fuse`); the EVT3 event encoding
//! (`evt3`); the on-chip event filters of Prophesee's sensors, for events from any source
//! (`filters`); how events leave the chip, its arbiter, bus and timestamp clock (`readout`);
//! and the exponential the pixel model evaluates most (`exp`).

mod block_flags;
mod cpu_dispatch;
pub mod crossing;
mod dense;
pub mod events;
pub mod evt3;
pub mod exp;
pub mod exr_frame;
mod f32_bounds;
pub mod filters;
mod first_band;
pub mod fuse;
pub mod ghost;
pub mod metrics;
pub mod noise;
pub mod params;
pub mod photoreceptor;
pub mod pixel;
pub mod readout;
pub mod rng;
pub mod sensor;
mod state_arena;
mod state_block;
pub mod tile;

pub use events::{Event, EventColumns};
pub use params::{ParamError, ReferenceReset, SensorParams};
pub use sensor::{EventSensor, FeedError};
