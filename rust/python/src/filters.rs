//! `pecs._core.FilterChain`: the core's on-chip event filters (pecs_core::filters), numpy
//! columns in, a numpy bool verdict per decided event out, run without the GIL.

use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1};
use pecs_core::filters::{
    AfkMode, AfkSettings, ErcSettings, FilterChain, FilterSettings, TrailMode, TrailSettings,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::detached::detached;

/// (low_hz, high_hz, mode "band-stop" | "band-pass", start_threshold, stop_threshold).
type Afk<'a> = (u32, u32, &'a str, u8, u8);
/// (mode "trail" | "stc-cut-trail" | "stc-keep-trail", threshold_ms).
type Trail<'a> = (&'a str, u32);
/// (rate_hz, period_us).
type Erc = (f64, u32);

#[pyclass(name = "FilterChain", module = "pecs._core")]
pub struct PyFilterChain {
    inner: FilterChain,
}

#[pymethods]
impl PyFilterChain {
    /// `width`, `height`: the sensor's size where known (0 otherwise), a hint for the state.
    #[new]
    #[pyo3(signature = (afk = None, trail = None, erc = None, width = 0, height = 0))]
    fn new(
        afk: Option<Afk>,
        trail: Option<Trail>,
        erc: Option<Erc>,
        width: usize,
        height: usize,
    ) -> PyResult<Self> {
        let settings = FilterSettings {
            afk: afk.map(afk_settings).transpose()?,
            trail: trail.map(trail_settings).transpose()?,
            erc: erc.map(|(rate_hz, period_us)| ErcSettings { rate_hz, period_us }),
        };
        let inner = FilterChain::new(&settings, width, height)
            .map_err(|error| PyValueError::new_err(error.message))?;
        Ok(Self { inner })
    }

    /// Verdicts (bool) for the events decided now: those held from before, then these.
    fn push<'py>(
        &mut self,
        py: Python<'py>,
        t: PyReadonlyArray1<'_, i64>,
        x: PyReadonlyArray1<'_, u16>,
        y: PyReadonlyArray1<'_, u16>,
        p: PyReadonlyArray1<'_, i8>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let (t, x, y, p) = (t.as_slice()?, x.as_slice()?, y.as_slice()?, p.as_slice()?);
        let chain = &mut self.inner;
        let verdicts = detached(py, "on-chip filters", || chain.push(t, x, y, p))?;
        Ok(verdicts.into_pyarray(py))
    }

    /// Verdicts for the events still held: the stream ended.
    fn finish<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let chain = &mut self.inner;
        let verdicts = detached(py, "on-chip filters", || {
            Ok::<_, std::convert::Infallible>(chain.finish())
        })?;
        Ok(verdicts.into_pyarray(py))
    }

    /// Events pushed whose verdict waits for the end of their rate-controller period.
    #[getter]
    fn held(&self) -> usize {
        self.inner.held()
    }

    /// Events in, dropped by each filter, and passed, so far.
    fn counts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let counts = self.inner.counts();
        let dict = PyDict::new(py);
        dict.set_item("events_in", counts.events_in)?;
        dict.set_item("afk_dropped", counts.afk_dropped)?;
        dict.set_item("trail_dropped", counts.trail_dropped)?;
        dict.set_item("erc_dropped", counts.erc_dropped)?;
        dict.set_item("events_out", counts.events_out)?;
        Ok(dict)
    }
}

fn afk_settings((low_hz, high_hz, mode, start, stop): Afk) -> PyResult<AfkSettings> {
    let mode = match mode {
        "band-stop" => AfkMode::BandStop,
        "band-pass" => AfkMode::BandPass,
        other => {
            return Err(PyValueError::new_err(format!(
                "anti-flicker mode {other:?}: choose band-stop or band-pass"
            )))
        }
    };
    Ok(AfkSettings {
        low_hz,
        high_hz,
        mode,
        start_threshold: start,
        stop_threshold: stop,
    })
}

fn trail_settings((mode, threshold_ms): Trail) -> PyResult<TrailSettings> {
    let mode = match mode {
        "trail" => TrailMode::Trail,
        "stc-cut-trail" => TrailMode::StcCutTrail,
        "stc-keep-trail" => TrailMode::StcKeepTrail,
        other => {
            return Err(PyValueError::new_err(format!(
                "event trail mode {other:?}: choose trail, stc-cut-trail or stc-keep-trail"
            )))
        }
    };
    Ok(TrailSettings { mode, threshold_ms })
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyFilterChain>()
}
