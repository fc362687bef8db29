//! Spatiotemporal distances between two event streams, as defined by PECS (ECCV 2024, supplement):
//! the chamfer distance and the Gaussian distance over events seen as points (x, y, p, t) of a
//! normalised 4-D space, with exact nearest neighbours found over a BVH.
//!
//! - `normalize`: events to points (per-stream min-max, the PECS default, or by sensor size).
//! - `nearest`: exact nearest-neighbour distances (a BVH of 3-D points per polarity).
//! - `bvh`, `block`, `morton`: that BVH, its blocks of points, their Morton order.
//! - `chamfer`, `gaussian`: the two metrics from the per-event nearest distances.

pub mod block;
pub mod bvh;
pub mod chamfer;
pub mod gaussian;
pub mod morton;
pub mod nearest;
pub mod normalize;

use std::fmt;

pub use bvh::PointBvh;
pub use chamfer::chamfer_distance;
pub use gaussian::{gaussian_distance, PECS_SIGMA};
pub use nearest::{nearest_distances, PolarityMatching};
pub use normalize::{normalize, Cloud, Normalization};

/// Events as parallel columns: time (µs), pixel column and row, polarity (1 ON, 0 OFF).
#[derive(Clone, Copy, Debug)]
pub struct Events<'a> {
    pub t_us: &'a [i64],
    pub x: &'a [u16],
    pub y: &'a [u16],
    pub p: &'a [i8],
}

impl Events<'_> {
    pub fn len(&self) -> usize {
        self.t_us.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t_us.is_empty()
    }

    /// Checks that the columns have one length and every polarity is 0 or 1.
    pub fn validate(&self, stream: &'static str) -> Result<(), MetricsError> {
        let n = self.t_us.len();
        if self.x.len() != n || self.y.len() != n || self.p.len() != n {
            return Err(MetricsError::LengthMismatch {
                stream,
                t: n,
                x: self.x.len(),
                y: self.y.len(),
                p: self.p.len(),
            });
        }
        if n > u32::MAX as usize {
            return Err(MetricsError::Parameter(format!(
                "stream {stream}: {n} events is more than the {} a comparison supports",
                u32::MAX
            )));
        }
        if let Some(index) = self.p.iter().position(|&p| p != 0 && p != 1) {
            let value = self.p[index];
            return Err(MetricsError::Polarity {
                stream,
                index,
                value,
            });
        }
        Ok(())
    }
}

/// Why two streams cannot be compared.
#[derive(Clone, Debug, PartialEq)]
pub enum MetricsError {
    /// The columns of a stream differ in length.
    LengthMismatch {
        stream: &'static str,
        t: usize,
        x: usize,
        y: usize,
        p: usize,
    },
    /// A polarity other than 0 (OFF) or 1 (ON).
    Polarity {
        stream: &'static str,
        index: usize,
        value: i8,
    },
    /// A stream with no events where the metric needs at least one.
    Empty { stream: &'static str },
    /// A normalisation or metric parameter out of range.
    Parameter(String),
}

impl fmt::Display for MetricsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::LengthMismatch { stream, t, x, y, p } => write!(
                f,
                "stream {stream}: columns differ in length (t {t}, x {x}, y {y}, p {p})"
            ),
            Self::Polarity {
                stream,
                index,
                value,
            } => write!(
                f,
                "stream {stream}: polarity at event {index} is {value}, expected 0 (OFF) or 1 (ON)"
            ),
            Self::Empty { stream } => write!(f, "stream {stream} has no events"),
            Self::Parameter(message) => f.write_str(message),
        }
    }
}

impl std::error::Error for MetricsError {}

/// Both PECS metrics of a pair of streams, from one nearest-neighbour pass in each direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Comparison {
    pub chamfer: f64,
    pub gaussian: f64,
}

/// The per-event nearest distances of `a` to `b` and of `b` to `a`, in the normalised space.
pub fn nearest_distances_both_ways(
    a: &Events,
    b: &Events,
    normalization: &Normalization,
    polarity: PolarityMatching,
) -> Result<(Vec<f64>, Vec<f64>), MetricsError> {
    a.validate("a")?;
    b.validate("b")?;
    for (events, stream) in [(a, "a"), (b, "b")] {
        if events.is_empty() {
            return Err(MetricsError::Empty { stream });
        }
    }
    // Each stream on its own, both at once; then both directions at once, so one direction's
    // serial steps overlap the other's parallel work.
    let index = |events: &Events| -> Result<_, MetricsError> {
        Ok(nearest::PolarityIndex::build(&normalize(
            events,
            normalization,
        )?))
    };
    let (index_a, index_b) = rayon::join(|| index(a), || index(b));
    let (index_a, index_b) = (index_a?, index_b?);
    Ok(rayon::join(
        || index_b.nearest_distances(&index_a, polarity),
        || index_a.nearest_distances(&index_b, polarity),
    ))
}

/// The per-event nearest distances of `a` to `b` (`a` may be empty, `b` may not).
pub fn nearest_distances_between(
    a: &Events,
    b: &Events,
    normalization: &Normalization,
    polarity: PolarityMatching,
) -> Result<Vec<f64>, MetricsError> {
    a.validate("a")?;
    b.validate("b")?;
    if b.is_empty() {
        return Err(MetricsError::Empty { stream: "b" });
    }
    if a.is_empty() {
        return Ok(Vec::new());
    }
    let cloud_a = normalize(a, normalization)?;
    let cloud_b = normalize(b, normalization)?;
    Ok(nearest_distances(&cloud_a, &cloud_b, polarity))
}

/// The chamfer and Gaussian distances between `a` and `b` (both must have events).
pub fn compare(
    a: &Events,
    b: &Events,
    normalization: &Normalization,
    polarity: PolarityMatching,
    sigma: f64,
) -> Result<Comparison, MetricsError> {
    gaussian::check_sigma(sigma)?;
    let (a_to_b, b_to_a) = nearest_distances_both_ways(a, b, normalization, polarity)?;
    Ok(Comparison {
        chamfer: chamfer_distance(&a_to_b, &b_to_a),
        gaussian: gaussian_distance(&a_to_b, &b_to_a, sigma),
    })
}
