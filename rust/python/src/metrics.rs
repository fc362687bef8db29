//! Bindings of the event-stream metrics (pecs_core::metrics): numpy columns in, floats out.

use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1};
use pecs_core::metrics::{self, Events, Normalization, PolarityMatching};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::detached::detached;

/// A stream as contiguous numpy columns (t int64 µs, x uint16, y uint16, p int8).
type Columns<'py> = (
    PyReadonlyArray1<'py, i64>,
    PyReadonlyArray1<'py, u16>,
    PyReadonlyArray1<'py, u16>,
    PyReadonlyArray1<'py, i8>,
);

/// (width, height, t_origin_us, t_span_us) of the sensor normalisation.
type Sensor = (u32, u32, i64, i64);

fn events<'a>(columns: &'a Columns, stream: &str) -> PyResult<Events<'a>> {
    Ok(Events {
        t_us: slice(&columns.0, stream, "t")?,
        x: slice(&columns.1, stream, "x")?,
        y: slice(&columns.2, stream, "y")?,
        p: slice(&columns.3, stream, "p")?,
    })
}

fn slice<'a, T: numpy::Element>(
    array: &'a PyReadonlyArray1<T>,
    stream: &str,
    column: &str,
) -> PyResult<&'a [T]> {
    array.as_slice().map_err(|_| {
        PyValueError::new_err(format!(
            "stream {stream}: column {column} is not contiguous"
        ))
    })
}

fn normalization(normalize: &str, sensor: Option<Sensor>) -> PyResult<Normalization> {
    match (normalize, sensor) {
        ("pecs", _) => Ok(Normalization::Pecs),
        ("sensor", Some((width, height, t_origin_us, t_span_us))) => Ok(Normalization::Sensor {
            width,
            height,
            t_origin_us,
            t_span_us,
        }),
        ("sensor", None) => Err(PyValueError::new_err(
            "normalize='sensor' needs sensor=(width, height, t_origin_us, t_span_us)",
        )),
        (other, _) => Err(PyValueError::new_err(format!(
            "normalize must be 'pecs' or 'sensor', got {other:?}"
        ))),
    }
}

fn matching(polarity: &str) -> PyResult<PolarityMatching> {
    match polarity {
        "coordinate" => Ok(PolarityMatching::Coordinate),
        "separate" => Ok(PolarityMatching::Separate),
        other => Err(PyValueError::new_err(format!(
            "polarity must be 'coordinate' or 'separate', got {other:?}"
        ))),
    }
}

/// (chamfer, gaussian) between streams a and b; both need events.
#[pyfunction]
#[pyo3(signature = (a, b, normalize = "pecs", polarity = "coordinate", sensor = None, sigma = 0.4))]
fn event_metrics(
    py: Python<'_>,
    a: Columns,
    b: Columns,
    normalize: &str,
    polarity: &str,
    sensor: Option<Sensor>,
    sigma: f64,
) -> PyResult<(f64, f64)> {
    let (a, b) = (events(&a, "a")?, events(&b, "b")?);
    let (normalization, polarity) = (normalization(normalize, sensor)?, matching(polarity)?);
    let comparison = detached(py, "event metrics", || {
        metrics::compare(&a, &b, &normalization, polarity, sigma)
    })?;
    Ok((comparison.chamfer, comparison.gaussian))
}

/// Distance of every event of a to its nearest event of b (b needs events), as float64.
#[pyfunction]
#[pyo3(signature = (a, b, normalize = "pecs", polarity = "coordinate", sensor = None))]
fn event_nearest_distances<'py>(
    py: Python<'py>,
    a: Columns,
    b: Columns,
    normalize: &str,
    polarity: &str,
    sensor: Option<Sensor>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (a, b) = (events(&a, "a")?, events(&b, "b")?);
    let (normalization, polarity) = (normalization(normalize, sensor)?, matching(polarity)?);
    let distances = detached(py, "event metrics", || {
        metrics::nearest_distances_between(&a, &b, &normalization, polarity)
    })?;
    Ok(distances.into_pyarray(py))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(event_metrics, m)?)?;
    m.add_function(wrap_pyfunction!(event_nearest_distances, m)?)?;
    Ok(())
}
