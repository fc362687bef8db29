//! `pecs._core.Evt3Decoder` / `Evt3Encoder`: the core's EVT3 codec, numpy in, Arrow or numpy
//! out, run without the GIL; bad data raises `Evt3DataError(offset, problem)`.

use std::convert::Infallible;

use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1};
use pecs_core::evt3::{Evt3Decoder, Evt3Encoder};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::arrow_export::ExportedBatch;
use crate::detached::detached;

pyo3::create_exception!(
    _core,
    Evt3DataError,
    PyValueError,
    "Bad EVT3 data; args are (byte offset, problem)."
);

#[pyclass(name = "Evt3Decoder", module = "pecs._core")]
pub struct PyEvt3Decoder {
    inner: Evt3Decoder,
}

#[pymethods]
impl PyEvt3Decoder {
    /// `offset`: file offset of the first data byte, for the offsets in errors.
    #[new]
    fn new(width: u16, height: u16, offset: u64) -> PyResult<Self> {
        let inner = Evt3Decoder::new(width, height, offset).map_err(PyValueError::new_err)?;
        Ok(Self { inner })
    }

    /// Decodes from `chunk` (uint8) until the batch would pass `max_events`; returns the
    /// exported batch (t, x, y, p) and the bytes of `chunk` used.
    fn decode(
        &mut self,
        py: Python<'_>,
        chunk: PyReadonlyArray1<'_, u8>,
        max_events: usize,
    ) -> PyResult<(ExportedBatch, usize)> {
        let bytes = chunk.as_slice()?;
        let decoder = &mut self.inner;
        let decoded = detached(py, "EVT3 decoder", || {
            Ok::<_, Infallible>(decoder.decode(bytes, max_events))
        })?;
        let (events, used) = decoded.map_err(data_error)?;
        Ok((ExportedBatch::new(events, false), used))
    }

    /// Call after the last chunk: a word cut short raises Evt3DataError.
    fn finish(&self) -> PyResult<()> {
        self.inner.finish().map_err(data_error)
    }
}

fn data_error(error: pecs_core::evt3::Evt3Error) -> PyErr {
    Evt3DataError::new_err((error.offset, error.problem))
}

#[pyclass(name = "Evt3Encoder", module = "pecs._core")]
pub struct PyEvt3Encoder {
    inner: Evt3Encoder,
}

#[pymethods]
impl PyEvt3Encoder {
    #[new]
    fn new(width: u16, height: u16) -> PyResult<Self> {
        let inner = Evt3Encoder::new(width, height).map_err(PyValueError::new_err)?;
        Ok(Self { inner })
    }

    /// The EVT3 words (little-endian bytes, uint8) of one batch of events sorted by t.
    fn encode<'py>(
        &mut self,
        py: Python<'py>,
        t: PyReadonlyArray1<'_, i64>,
        x: PyReadonlyArray1<'_, u16>,
        y: PyReadonlyArray1<'_, u16>,
        p: PyReadonlyArray1<'_, i8>,
    ) -> PyResult<Bound<'py, PyArray1<u8>>> {
        let (t, x, y, p) = (t.as_slice()?, x.as_slice()?, y.as_slice()?, p.as_slice()?);
        let encoder = &mut self.inner;
        let bytes = detached(py, "EVT3 encoder", || encoder.encode(t, x, y, p))?;
        Ok(bytes.into_pyarray(py))
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyEvt3Decoder>()?;
    m.add_class::<PyEvt3Encoder>()?;
    m.add("Evt3DataError", m.py().get_type::<Evt3DataError>())?;
    Ok(())
}
