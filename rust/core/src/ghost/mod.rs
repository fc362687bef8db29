//! Lens ghosts, traced: rays that reflect twice inside a lens on their way to the film (Hullin,
//! Eisemann, Seidel and Lee, "Physically-based real-time lens flare rendering", SIGGRAPH 2011).
//!
//! One concept a file: a ray meeting one spherical (or flat) surface, where it lands and where
//! it goes next (`interface`); the reflectance of a surface bare or under a single-layer coating
//! (`thin_film`); and a ray following its path's steps from the entrance plane to the film,
//! its weight the product of the reflectances and transmittances it met (`path_trace`). The
//! Python side (pecs.lens.ghosts) builds the paths, the rays and the films, and splats the
//! result; lens space as there: z along the axis from the first vertex, light towards +z, mm.

pub mod interface;
pub mod path_trace;
pub mod thin_film;

pub use path_trace::{trace, GhostError, Rays, Steps, Surfaces, Traced};
