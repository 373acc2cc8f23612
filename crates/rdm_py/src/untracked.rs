//! Slices of numpy arrays without rust-numpy's dynamic borrow checker.
//!
//! `PyReadonlyArray` / `PyReadwriteArray` register every borrow in a process-wide hash map
//! and remove it again when the guard drops. The lockstep loop takes ~15 such borrows per
//! simulated ms (the plant's MuJoCo views, the bridge's arrays); their bookkeeping was
//! ~10k of ~186k instructions per simulated ms (cachegrind, docs/sim.md "Speed").
//! The per-step paths read and write those arrays through these two functions instead.
//!
//! What the checker guarded, each caller keeps by hand (its `SAFETY` comment says how):
//! - the slice lives only inside one Rust call, the GIL held, and no Python code runs while
//!   it is alive (Python could resize, free or write the array);
//! - no two slices alive at the same time overlap where one of them is written (distinct
//!   MuJoCo fields, or distinct arrays the binding allocated itself).

use numpy::{Element, PyArray, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// numpy's `NPY_ARRAY_WRITEABLE` flag bit.
const WRITEABLE: i32 = 0x0400;

/// The elements of a C-contiguous array in row-major order.
///
/// # Safety
/// The caller keeps the contract of the module documentation for the slice's life.
pub(crate) unsafe fn read<'a, T: Element, D: numpy::ndarray::Dimension>(
    array: &'a Bound<'_, PyArray<T, D>>,
    what: &str,
) -> PyResult<&'a [T]> {
    c_contiguous(array, what)?;
    // SAFETY: forwarded to the caller (module contract).
    unsafe { array.as_slice() }.map_err(|_| not_c_contiguous(what))
}

/// The elements of a C-contiguous array for writing; refuses an array numpy marks
/// read-only, as the checked borrow does.
///
/// # Safety
/// The caller keeps the contract of the module documentation for the slice's life.
#[allow(clippy::mut_from_ref)] // the buffer is numpy's, not the Bound's
pub(crate) unsafe fn write<'a, T: Element, D: numpy::ndarray::Dimension>(
    array: &'a Bound<'_, PyArray<T, D>>,
    what: &str,
) -> PyResult<&'a mut [T]> {
    // SAFETY: the pointer is the live array object the Bound holds.
    let flags = unsafe { (*array.as_array_ptr()).flags };
    if flags & WRITEABLE == 0 {
        return Err(PyValueError::new_err(format!("{what}: not writeable")));
    }
    c_contiguous(array, what)?;
    // SAFETY: forwarded to the caller (module contract).
    unsafe { array.as_slice_mut() }.map_err(|_| not_c_contiguous(what))
}

/// Whether two arrays' buffers share no byte (a written slice must not alias a read one).
pub(crate) fn disjoint<
    T: Element,
    U: Element,
    D: numpy::ndarray::Dimension,
    E: numpy::ndarray::Dimension,
>(
    a: &Bound<'_, PyArray<T, D>>,
    b: &Bound<'_, PyArray<U, E>>,
) -> bool {
    let span = |p: *const u8, n: usize| (p as usize, p as usize + n);
    let (a0, a1) = span(a.data().cast(), a.len() * std::mem::size_of::<T>());
    let (b0, b1) = span(b.data().cast(), b.len() * std::mem::size_of::<U>());
    a1 <= b0 || b1 <= a0
}

fn c_contiguous<T: Element, D: numpy::ndarray::Dimension>(
    array: &Bound<'_, PyArray<T, D>>,
    what: &str,
) -> PyResult<()> {
    if array.is_c_contiguous() {
        Ok(())
    } else {
        Err(not_c_contiguous(what))
    }
}

fn not_c_contiguous(what: &str) -> PyErr {
    PyValueError::new_err(format!("{what}: must be C-contiguous"))
}
