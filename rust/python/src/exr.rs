//! `pecs._core.read_exr`: one channel of an EXR image as a float32 numpy array.

use std::path::PathBuf;

use numpy::{IntoPyArray, PyArray2, PyArrayMethods};
use pecs_core::exr_frame::read_exr_frame;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// Returns (frame of shape (height, width), name of the channel used).
#[pyfunction]
#[pyo3(signature = (path, channel=None))]
pub fn read_exr<'py>(
    py: Python<'py>,
    path: PathBuf,
    channel: Option<String>,
) -> PyResult<(Bound<'py, PyArray2<f32>>, String)> {
    let frame = py
        .detach(|| read_exr_frame(&path, channel.as_deref()))
        .map_err(|e| PyValueError::new_err(format!("{}: {e}", path.display())))?;
    let array = frame
        .values
        .into_pyarray(py)
        .reshape([frame.height, frame.width])?;
    Ok((array, frame.channel))
}
