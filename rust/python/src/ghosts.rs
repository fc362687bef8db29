//! Bindings of the lens-ghost tracer (pecs_core::ghost): numpy arrays in and out.

use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyUntypedArrayMethods,
};
use pecs_core::ghost::{self, Rays, Steps, Surfaces};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::detached::detached;

fn slice<'a, T: numpy::Element>(array: &'a PyReadonlyArray1<T>, name: &str) -> PyResult<&'a [T]> {
    array
        .as_slice()
        .map_err(|_| PyValueError::new_err(format!("ghost trace: {name} is not C-contiguous")))
}

/// A C-contiguous 2-D array's values and its column count.
fn table<'a, T: numpy::Element>(
    array: &'a PyReadonlyArray2<T>,
    name: &str,
) -> PyResult<(&'a [T], usize)> {
    let columns = array.shape()[1];
    let values = array
        .as_slice()
        .map_err(|_| PyValueError::new_err(format!("ghost trace: {name} is not C-contiguous")))?;
    Ok((values, columns))
}

type Traced<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<bool>>,
);

/// (film xy (N, 2) mm, weight (N, B), alive (N,)) of ghost rays: origin and direction (N, 3),
/// path and geometry band per ray (N,), weight bands (N, B); the paths' step tables (paths,
/// steps); per surface z, radius, semi-aperture^2, fixed reflectance (< 0: the film's), film
/// index and thickness (nm); media (surfaces + 1, bands), wavelengths (bands,), film z.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn ghost_trace<'py>(
    py: Python<'py>,
    origin_mm: PyReadonlyArray2<'py, f64>,
    direction: PyReadonlyArray2<'py, f64>,
    path: PyReadonlyArray1<'py, i64>,
    band: PyReadonlyArray1<'py, i64>,
    weight_band: PyReadonlyArray2<'py, i64>,
    step_surface: PyReadonlyArray2<'py, i64>,
    step_reflect: PyReadonlyArray2<'py, bool>,
    step_forward: PyReadonlyArray2<'py, bool>,
    vertex_z_mm: PyReadonlyArray1<'py, f64>,
    radius_mm: PyReadonlyArray1<'py, f64>,
    semi_aperture2_mm2: PyReadonlyArray1<'py, f64>,
    fixed_reflectance: PyReadonlyArray1<'py, f64>,
    film_index: PyReadonlyArray1<'py, f64>,
    film_thickness_nm: PyReadonlyArray1<'py, f64>,
    media: PyReadonlyArray2<'py, f64>,
    wavelength_nm: PyReadonlyArray1<'py, f64>,
    film_z_mm: f64,
) -> PyResult<Traced<'py>> {
    let (weight_band, bands_per_ray) = table(&weight_band, "weight_band")?;
    let (surface, steps) = table(&step_surface, "step_surface")?;
    let surfaces = Surfaces {
        vertex_z_mm: slice(&vertex_z_mm, "vertex_z_mm")?,
        radius_mm: slice(&radius_mm, "radius_mm")?,
        semi_aperture2_mm2: slice(&semi_aperture2_mm2, "semi_aperture2_mm2")?,
        fixed_reflectance: slice(&fixed_reflectance, "fixed_reflectance")?,
        film_index: slice(&film_index, "film_index")?,
        film_thickness_nm: slice(&film_thickness_nm, "film_thickness_nm")?,
        media: table(&media, "media")?.0,
        wavelength_nm: slice(&wavelength_nm, "wavelength_nm")?,
        film_z_mm,
    };
    let steps = Steps {
        surface,
        reflect: table(&step_reflect, "step_reflect")?.0,
        forward: table(&step_forward, "step_forward")?.0,
        steps,
    };
    let rays = Rays {
        origin_mm: table(&origin_mm, "origin_mm")?.0,
        direction: table(&direction, "direction")?.0,
        path: slice(&path, "path")?,
        band: slice(&band, "band")?,
        weight_band,
        bands_per_ray,
    };
    let n = rays.path.len();
    let traced = detached(py, "ghost tracer", || {
        ghost::trace(&surfaces, &steps, &rays)
    })?;
    Ok((
        traced.film_mm.into_pyarray(py).reshape([n, 2])?,
        traced.weight.into_pyarray(py).reshape([n, bands_per_ray])?,
        traced.alive.into_pyarray(py),
    ))
}

type SAndP<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);

/// (R_s, R_p) of single films, element by element over 1-D float64 arrays of one length.
#[pyfunction]
fn ghost_film_reflectance<'py>(
    py: Python<'py>,
    n0: PyReadonlyArray1<'py, f64>,
    n1: PyReadonlyArray1<'py, f64>,
    n2: PyReadonlyArray1<'py, f64>,
    thickness_nm: PyReadonlyArray1<'py, f64>,
    wavelength_nm: PyReadonlyArray1<'py, f64>,
    cos_theta0: PyReadonlyArray1<'py, f64>,
) -> PyResult<SAndP<'py>> {
    let columns = [
        slice(&n0, "n0")?,
        slice(&n1, "n1")?,
        slice(&n2, "n2")?,
        slice(&thickness_nm, "thickness_nm")?,
        slice(&wavelength_nm, "wavelength_nm")?,
        slice(&cos_theta0, "cos_theta0")?,
    ];
    let n = columns[0].len();
    if columns.iter().any(|c| c.len() != n) {
        return Err(PyValueError::new_err(
            "ghost_film_reflectance: the arrays differ in length",
        ));
    }
    let (rs, rp): (Vec<f64>, Vec<f64>) = (0..n)
        .map(|i| {
            let [a, b, c, d, e, f] = columns.map(|column| column[i]);
            ghost::thin_film::film_reflectance(a, b, c, d, e, f)
        })
        .unzip();
    Ok((rs.into_pyarray(py), rp.into_pyarray(py)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(ghost_trace, m)?)?;
    m.add_function(wrap_pyfunction!(ghost_film_reflectance, m)?)?;
    Ok(())
}
