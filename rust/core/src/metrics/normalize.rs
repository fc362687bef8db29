//! Events to points of the metric space: x, y and p scaled to [0, 100], t to [0, 1000].
//!
//! PECS (supplement) normalises each stream on its own by min-max per axis; `Sensor` is the
//! documented variant that uses the sensor size and the window length, shared by both streams,
//! so that global offsets and scale errors stay visible.

use rayon::prelude::*;

use super::{Events, MetricsError};

/// Added to every min-max range, as PECS does, so a constant axis maps to 0 instead of 0/0.
pub const EPS: f64 = 1e-8;
/// Scale of x, y and p after normalisation.
pub const SPACE_SCALE: f64 = 100.0;
/// Scale of t after normalisation.
pub const TIME_SCALE: f64 = 1000.0;

/// How events become points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Normalization {
    /// Per stream and per axis: v~ = scale (v - min v) / (max v - min v + 1e-8).
    Pecs,
    /// Shared by both streams: x~ = 100 x / width, y~ = 100 y / height, p~ = 100 p,
    /// t~ = 1000 (t - t_origin_us) / t_span_us.
    Sensor {
        width: u32,
        height: u32,
        t_origin_us: i64,
        t_span_us: i64,
    },
}

/// A stream as points: (x~, y~, t~) per event, its raw polarity, and the p~ of each polarity.
///
/// p~ takes one value per polarity in either normalisation, so a 4-D distance is a 3-D distance
/// plus a constant polarity offset in quadrature.
#[derive(Clone, Debug, PartialEq)]
pub struct Cloud {
    pub xyt: Vec<[f64; 3]>,
    pub on: Vec<bool>,
    /// p~ of OFF events and of ON events.
    pub p_coord: [f64; 2],
}

/// The points of `events` under `normalization`.
pub fn normalize(events: &Events, normalization: &Normalization) -> Result<Cloud, MetricsError> {
    match *normalization {
        Normalization::Pecs => Ok(min_max(events)),
        Normalization::Sensor {
            width,
            height,
            t_origin_us,
            t_span_us,
        } => {
            if width == 0 || height == 0 || t_span_us <= 0 {
                return Err(MetricsError::Parameter(format!(
                    "sensor normalisation needs a positive width, height and window length; got \
                     width {width}, height {height}, window {t_span_us} us"
                )));
            }
            Ok(by_sensor(events, width, height, t_origin_us, t_span_us))
        }
    }
}

/// PECS: v~ = scale (v - min v) / (max v - min v + eps), per axis, over this stream only.
fn min_max(events: &Events) -> Cloud {
    let (x0, x1) = range(events.x);
    let (y0, y1) = range(events.y);
    let (p0, p1) = range(events.p);
    let (t0, t1) = (
        events.t_us.par_iter().copied().min().unwrap_or(0),
        events.t_us.par_iter().copied().max().unwrap_or(0),
    );
    // Differences of integer times are taken in i64 (exact), then converted.
    let t_range = (t1 - t0) as f64 + EPS;
    let (x_range, y_range, p_range) = (x1 - x0 + EPS, y1 - y0 + EPS, p1 - p0 + EPS);
    let xyt = (0..events.len())
        .into_par_iter()
        .map(|i| {
            [
                SPACE_SCALE * (f64::from(events.x[i]) - x0) / x_range,
                SPACE_SCALE * (f64::from(events.y[i]) - y0) / y_range,
                TIME_SCALE * (events.t_us[i] - t0) as f64 / t_range,
            ]
        })
        .collect();
    Cloud {
        xyt,
        on: events.p.par_iter().map(|&p| p == 1).collect(),
        p_coord: [
            SPACE_SCALE * (0.0 - p0) / p_range,
            SPACE_SCALE * (1.0 - p0) / p_range,
        ],
    }
}

/// The variant: x, y by the sensor size, t by the window, p as is, the same for both streams.
fn by_sensor(events: &Events, width: u32, height: u32, t_origin_us: i64, t_span_us: i64) -> Cloud {
    let (w, h, span) = (f64::from(width), f64::from(height), t_span_us as f64);
    let xyt = (0..events.len())
        .into_par_iter()
        .map(|i| {
            [
                SPACE_SCALE * f64::from(events.x[i]) / w,
                SPACE_SCALE * f64::from(events.y[i]) / h,
                TIME_SCALE * (events.t_us[i] - t_origin_us) as f64 / span,
            ]
        })
        .collect();
    Cloud {
        xyt,
        on: events.p.par_iter().map(|&p| p == 1).collect(),
        p_coord: [0.0, SPACE_SCALE],
    }
}

/// (min, max) of the values as f64, (0, 0) when there are none.
fn range<T: Copy + Ord + Send + Sync + Into<f64>>(values: &[T]) -> (f64, f64) {
    match (values.par_iter().min(), values.par_iter().max()) {
        (Some(&lo), Some(&hi)) => (lo.into(), hi.into()),
        _ => (0.0, 0.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_max_maps_extremes_to_zero_and_scale() {
        let events = Events {
            t_us: &[10, 20, 30],
            x: &[5, 7, 9],
            y: &[1, 1, 3],
            p: &[0, 1, 1],
        };
        let cloud = normalize(&events, &Normalization::Pecs).unwrap();
        let almost = |a: f64, b: f64| (a - b).abs() < 1e-6;
        assert_eq!(cloud.xyt[0], [0.0, 0.0, 0.0]);
        assert!(almost(cloud.xyt[2][0], 100.0) && almost(cloud.xyt[2][1], 100.0));
        assert!(almost(cloud.xyt[2][2], 1000.0) && almost(cloud.xyt[1][2], 500.0));
        assert!(almost(cloud.xyt[1][1], 0.0) && almost(cloud.xyt[1][0], 50.0));
        assert_eq!(cloud.on, vec![false, true, true]);
        assert!(cloud.p_coord[0] == 0.0 && almost(cloud.p_coord[1], 100.0));
    }

    #[test]
    fn single_polarity_and_single_event_map_to_zero() {
        let events = Events {
            t_us: &[7],
            x: &[3],
            y: &[4],
            p: &[1],
        };
        let cloud = normalize(&events, &Normalization::Pecs).unwrap();
        assert_eq!(cloud.xyt, vec![[0.0, 0.0, 0.0]]);
        assert_eq!(cloud.p_coord[1], 0.0);
    }

    #[test]
    fn sensor_normalisation_uses_size_and_window() {
        let events = Events {
            t_us: &[150],
            x: &[173],
            y: &[65],
            p: &[1],
        };
        let sensor = Normalization::Sensor {
            width: 346,
            height: 260,
            t_origin_us: 100,
            t_span_us: 200,
        };
        let cloud = normalize(&events, &sensor).unwrap();
        assert_eq!(cloud.xyt[0], [50.0, 25.0, 250.0]);
        assert_eq!(cloud.p_coord, [0.0, 100.0]);
        let bad = Normalization::Sensor {
            width: 0,
            height: 1,
            t_origin_us: 0,
            t_span_us: 1,
        };
        assert!(normalize(&events, &bad).is_err());
    }
}
