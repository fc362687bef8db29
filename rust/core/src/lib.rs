//! pecs-core: the physics and numerics of pecs, with no Python and no files.
//!
//! One physical concept per module: the DVS pixel (`pixel`), its noise processes (`noise`),
//! counter-based random numbers (`rng`), the streaming sensor that runs pixels in parallel
//! (`sensor`).

pub mod metrics;
