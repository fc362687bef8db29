//! Event columns handed to pyarrow through the Arrow C data interface
//! (arrow.apache.org/docs/format/CDataInterface.html): the column vectors move into the exported
//! array without a copy, and Python imports it against the schema it already holds, which costs
//! a few microseconds where wrapping five numpy arrays one by one cost fifteen.

use std::ffi::c_void;
use std::ptr;

use pecs_core::EventColumns;
use pyo3::prelude::*;

/// `struct ArrowArray` of the C data interface.
#[repr(C)]
struct ArrowArray {
    length: i64,
    null_count: i64,
    offset: i64,
    n_buffers: i64,
    n_children: i64,
    buffers: *mut *const c_void,
    children: *mut *mut ArrowArray,
    dictionary: *mut ArrowArray,
    release: Option<unsafe extern "C" fn(*mut ArrowArray)>,
    private_data: *mut c_void,
}

/// What one column's array owns: its values, and its buffer list (no validity bitmap, values).
struct ColumnData {
    _values: Box<dyn std::any::Any>,
    buffers: [*const c_void; 2],
}

/// What the struct array of a batch owns: its columns' arrays, and its buffer list (no validity).
struct BatchData {
    children: Vec<*mut ArrowArray>,
    buffers: [*const c_void; 1],
}

unsafe extern "C" fn release_column(array: *mut ArrowArray) {
    // SAFETY: called once by the consumer on an array `column` made, whose private data is a
    // leaked Box<ColumnData>.
    unsafe {
        drop(Box::from_raw((*array).private_data.cast::<ColumnData>()));
        (*array).release = None;
    }
}

unsafe extern "C" fn release_batch(array: *mut ArrowArray) {
    // SAFETY: called once by the consumer on an array `batch` made; its children are leaked
    // Boxes, each released here unless the consumer moved it out (then its release is null).
    unsafe {
        let data = Box::from_raw((*array).private_data.cast::<BatchData>());
        for &child in &data.children {
            if let Some(release) = (*child).release {
                release(child);
            }
            drop(Box::from_raw(child));
        }
        (*array).release = None;
    }
}

fn column<T: 'static>(values: Vec<T>) -> *mut ArrowArray {
    let length = values.len() as i64;
    let mut data = Box::new(ColumnData {
        buffers: [ptr::null(), values.as_ptr().cast()],
        _values: Box::new(values),
    });
    let array = ArrowArray {
        length,
        null_count: 0,
        offset: 0,
        n_buffers: 2,
        n_children: 0,
        buffers: data.buffers.as_mut_ptr(),
        children: ptr::null_mut(),
        dictionary: ptr::null_mut(),
        release: Some(release_column),
        private_data: Box::into_raw(data).cast(),
    };
    Box::into_raw(Box::new(array))
}

fn batch(length: usize, columns: Vec<*mut ArrowArray>) -> ArrowArray {
    let mut data = Box::new(BatchData {
        children: columns,
        buffers: [ptr::null()],
    });
    ArrowArray {
        length: length as i64,
        null_count: 0,
        offset: 0,
        n_buffers: 1,
        n_children: data.children.len() as i64,
        buffers: data.buffers.as_mut_ptr(),
        children: data.children.as_mut_ptr(),
        dictionary: ptr::null_mut(),
        release: Some(release_batch),
        private_data: Box::into_raw(data).cast(),
    }
}

/// A batch of events exported as a struct array (t, x, y, p[, label]), waiting to be imported
/// by `pyarrow.RecordBatch._import_from_c(batch.address, schema)` while this object is alive.
/// The import moves the array out (and nulls its `release`); one never imported is released
/// when this object goes.
#[pyclass(module = "pecs._core")]
pub struct ExportedBatch {
    /// Owned (from `Box::into_raw`); the importer writes to it through `address`.
    array: *mut ArrowArray,
}

// SAFETY: the array and everything it points to are owned heap data, not tied to a thread.
unsafe impl Send for ExportedBatch {}
// SAFETY: Rust only reads the pointer; the struct behind it is written by its one importer
// (pyarrow refuses an array already moved out), which pecs's own `_batch` does right away.
unsafe impl Sync for ExportedBatch {}

impl ExportedBatch {
    pub fn new(c: EventColumns, with_labels: bool) -> Self {
        let length = c.len();
        let mut columns = vec![column(c.t_us), column(c.x), column(c.y), column(c.p)];
        if with_labels {
            columns.push(column(c.label));
        }
        Self {
            array: Box::into_raw(Box::new(batch(length, columns))),
        }
    }
}

#[pymethods]
impl ExportedBatch {
    /// Address of the `struct ArrowArray`.
    #[getter]
    fn address(&self) -> usize {
        self.array as usize
    }
}

impl Drop for ExportedBatch {
    fn drop(&mut self) {
        // SAFETY: made by `Box::into_raw` in `new` and freed only here.
        let mut array = unsafe { Box::from_raw(self.array) };
        if let Some(release) = array.release {
            // SAFETY: still ours: an import would have moved it out and nulled `release`.
            unsafe { release(&mut *array) };
        }
    }
}
