//! `pecs._core.EventSensor`: numpy frames in, event batches out through the Arrow C data
//! interface (imported by pyarrow in Python).

use std::sync::{Mutex, MutexGuard};

use numpy::{IntoPyArray, PyArray1, PyReadonlyArray2};
use pecs_core::readout::{ReadoutOverflow, ReadoutSettings};
use pecs_core::{EventSensor, ReferenceReset, SensorParams};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrow_export::ExportedBatch;
use crate::detached::detached;

/// The sensor parameters as Python passes them: a dict with one entry per field.
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
struct ParamsArg {
    width: usize,
    height: usize,
    theta_on: f64,
    theta_off: f64,
    theta_sigma: f64,
    theta_noise: f64,
    theta_min: f64,
    refractory_us: f64,
    reference_reset: String,
    cutoff_hz: f64,
    cutoff_half_photocurrent: f64,
    dark_current: f64,
    white_lux: f64,
    lin_log_knee: f64,
    latency_us: f64,
    jitter_us: f64,
    leak_rate_hz: f64,
    leak_spread_decades: f64,
    leak_light_rate_hz: f64,
    shot_rate_hz: f64,
    shot_light_exponent: f64,
    hot_pixel_fraction: f64,
    hot_pixel_rate_hz: f64,
    seed: u64,
    readout_row_service_ns: f64,
    readout_bus_rate_meps: f64,
    readout_overflow: String,
    readout_queue_depth: u64,
    timestamp_step_us: u64,
    erc_rate_hz: f64,
}

impl ParamsArg {
    fn into_params(self) -> PyResult<SensorParams> {
        let reference_reset: ReferenceReset = self.reference_reset.parse().map_err(value_error)?;
        let overflow: ReadoutOverflow = self.readout_overflow.parse().map_err(value_error)?;
        Ok(SensorParams {
            width: self.width,
            height: self.height,
            theta_on: self.theta_on,
            theta_off: self.theta_off,
            theta_sigma: self.theta_sigma,
            theta_noise: self.theta_noise,
            theta_min: self.theta_min,
            refractory_us: self.refractory_us,
            reference_reset,
            cutoff_hz: self.cutoff_hz,
            cutoff_half_photocurrent: self.cutoff_half_photocurrent,
            dark_current: self.dark_current,
            white_lux: self.white_lux,
            lin_log_knee: self.lin_log_knee,
            latency_us: self.latency_us,
            jitter_us: self.jitter_us,
            leak_rate_hz: self.leak_rate_hz,
            leak_spread_decades: self.leak_spread_decades,
            leak_light_rate_hz: self.leak_light_rate_hz,
            shot_rate_hz: self.shot_rate_hz,
            shot_light_exponent: self.shot_light_exponent,
            hot_pixel_fraction: self.hot_pixel_fraction,
            hot_pixel_rate_hz: self.hot_pixel_rate_hz,
            seed: self.seed,
            readout: ReadoutSettings {
                row_service_ns: self.readout_row_service_ns,
                bus_rate_meps: self.readout_bus_rate_meps,
                overflow,
                queue_depth: self.readout_queue_depth,
                timestamp_step_us: self.timestamp_step_us,
                erc_rate_hz: self.erc_rate_hz,
            },
        })
    }
}

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// Check sensor parameters as the core would take them: a ValueError names the first bad field
/// and its range.
#[pyfunction]
pub fn check_sensor_params(params: &Bound<'_, PyDict>) -> PyResult<()> {
    let params = params.extract::<ParamsArg>()?.into_params()?;
    params.validate().map_err(value_error)
}

/// A sensor is one stream in time order; calls from several threads take turns on its lock.
#[pyclass(name = "EventSensor", module = "pecs._core")]
pub struct PyEventSensor {
    inner: Mutex<EventSensor>,
    /// Whether batches carry the `label` column.
    labels: bool,
}

/// The sensor, for one call. A panic while it was held is already raised as a RuntimeError;
/// the sensor is taken as it was left rather than refused forever after.
fn locked(inner: &Mutex<EventSensor>) -> MutexGuard<'_, EventSensor> {
    inner
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

#[pymethods]
impl PyEventSensor {
    #[new]
    #[pyo3(signature = (params, labels = false))]
    fn new(params: &Bound<'_, PyDict>, labels: bool) -> PyResult<Self> {
        let params = params.extract::<ParamsArg>()?.into_params()?;
        Ok(Self {
            inner: Mutex::new(
                EventSensor::new(params)
                    .map_err(value_error)?
                    .with_labels(labels),
            ),
            labels,
        })
    }

    /// Feed a C-contiguous float32 frame (height, width) at `t_us`; returns the events as a
    /// struct array (t, x, y, p[, label]) to import. The lock is taken with the GIL released,
    /// so a thread waiting for it lets the one holding it finish.
    fn feed(
        &self,
        py: Python<'_>,
        frame: PyReadonlyArray2<'_, f32>,
        t_us: i64,
    ) -> PyResult<ExportedBatch> {
        let values = frame
            .as_slice()
            .map_err(|_| value_error("frame must be C-contiguous"))?;
        let inner = &self.inner;
        let events = detached(py, "event sensor", || locked(inner).feed(values, t_us))?;
        Ok(ExportedBatch::new(events, self.labels))
    }

    fn flush(&self, py: Python<'_>) -> PyResult<ExportedBatch> {
        let inner = &self.inner;
        let events = detached(py, "event sensor", || locked(inner).flush())?;
        Ok(ExportedBatch::new(events, self.labels))
    }

    fn reset(&self, py: Python<'_>) {
        py.detach(|| locked(&self.inner).reset());
    }

    #[getter]
    fn last_time_us(&self, py: Python<'_>) -> Option<i64> {
        py.detach(|| locked(&self.inner).last_time_us())
    }

    /// The readout delay (us) of each event the last feed or flush gave; empty when the
    /// readout is off.
    fn delays_us<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        let delays = py.detach(|| locked(&self.inner).delays_us().to_vec());
        delays.into_pyarray(py)
    }

    /// What became of the events through the readout so far, or None when it is off.
    fn readout_counts<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(c) = py.detach(|| locked(&self.inner).readout_counts()) else {
            return Ok(None);
        };
        let dict = PyDict::new(py);
        for (key, value) in [
            ("events_in", c.events_in),
            ("events_out", c.events_out),
            ("dropped", c.dropped),
            ("erc_dropped", c.erc_dropped),
            ("held", c.held),
            ("delayed", c.delayed),
            ("delay_total_us", c.delay_total_us),
            ("delay_max_us", c.delay_max_us),
            ("same_timestamp", c.same_timestamp),
        ] {
            dict.set_item(key, value)?;
        }
        Ok(Some(dict))
    }
}
