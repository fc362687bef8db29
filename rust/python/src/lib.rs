//! Thin pyo3 bindings of pecs-core: argument conversion only, no physics.

use pyo3::prelude::*;

mod arrow_export;
mod exr;
mod metrics;
mod sensor;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<sensor::PyEventSensor>()?;
    m.add_class::<arrow_export::ExportedBatch>()?;
    m.add_function(wrap_pyfunction!(exr::read_exr, m)?)?;
    metrics::register(m)?;
    Ok(())
}
