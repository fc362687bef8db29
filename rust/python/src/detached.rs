//! Rust work run without the GIL, its failures as Python exceptions.

use std::fmt::Display;
use std::panic::{catch_unwind, AssertUnwindSafe};

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

/// Runs `work` with the GIL released. Its error (bad input) becomes a ValueError with the
/// error's message; a panic (a bug in pecs) becomes a RuntimeError naming `component`, never
/// an abort or a PanicException, which `except Exception` would not catch.
pub fn detached<T: Send, E: Display + Send>(
    py: Python<'_>,
    component: &str,
    work: impl FnOnce() -> Result<T, E> + Send,
) -> PyResult<T> {
    match py.detach(|| catch_unwind(AssertUnwindSafe(work))) {
        Ok(Ok(value)) => Ok(value),
        Ok(Err(error)) => Err(PyValueError::new_err(error.to_string())),
        Err(_) => Err(PyRuntimeError::new_err(format!(
            "internal error in the {component} (a bug in pecs)"
        ))),
    }
}
