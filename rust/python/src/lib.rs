//! Thin pyo3 bindings of pecs-core: argument conversion only, no physics.

use pyo3::prelude::*;

mod arrow_export;
mod detached;
mod evt3;
mod exr;
mod filters;
mod ghosts;
mod metrics;
mod sensor;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    join_thread_pool();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<sensor::PyEventSensor>()?;
    m.add_function(wrap_pyfunction!(sensor::check_sensor_params, m)?)?;
    m.add_class::<arrow_export::ExportedBatch>()?;
    m.add_function(wrap_pyfunction!(exr::read_exr, m)?)?;
    metrics::register(m)?;
    evt3::register(m)?;
    filters::register(m)?;
    ghosts::register(m)?;
    Ok(())
}

/// The importing thread (Python's main thread, as a rule) becomes one of rayon's workers: a
/// frame's parallel work then starts on the thread that calls `feed`, instead of waking a pool
/// thread and putting the caller to sleep until it is done, which cost tens of microseconds a
/// frame. Only with two threads or more: the pool's own threads must still run work handed in
/// from other threads while this one is busy in Python.
fn join_thread_pool() {
    let threads = std::env::var("RAYON_NUM_THREADS")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    if threads >= 2 {
        // An error means the pool exists already; it then works as it is.
        let _ = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .use_current_thread()
            .build_global();
    }
}
