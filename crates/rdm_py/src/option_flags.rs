//! `model.opt.disableflags` as the plant's step reads and writes it (lazy sensors):
//! the int itself when `rdm.plant.option_flags` found its address, else the bindings'
//! property (three attribute accesses a step, ~2k instructions).

use pyo3::prelude::*;
use pyo3::types::PyString;

pub(crate) enum OptionFlags {
    /// `Plant._flags_address`: the int32 inside the model the link keeps alive.
    Raw(*mut i32),
    /// `model.opt` and the interned `disableflags`.
    Attr(Py<PyAny>, Py<PyString>),
}

impl OptionFlags {
    /// From `Plant._flags_address` (None: the property of `opt`). The address is used only
    /// where the probe could have found it: aligned, inside the first `searched` bytes
    /// (`rdm.plant.option_flags.SEARCH_BYTES`) of the model the step core holds (`model._address`),
    /// so a plant whose model was swapped after the probe falls back to the property
    /// instead of writing into freed memory.
    pub(crate) fn new(
        py: Python<'_>,
        address: Option<usize>,
        model_address: Option<usize>,
        searched: usize,
        opt: Py<PyAny>,
    ) -> Self {
        match (address, model_address) {
            (Some(a), Some(base))
                if a % std::mem::align_of::<i32>() == 0
                    && a >= base
                    && a + std::mem::size_of::<i32>() <= base + searched =>
            {
                OptionFlags::Raw(a as *mut i32)
            }
            _ => OptionFlags::Attr(opt, PyString::intern(py, "disableflags").unbind()),
        }
    }

    pub(crate) fn get(&self, py: Python<'_>) -> PyResult<i64> {
        match self {
            // SAFETY: the address was probed inside the live model (option_flags.py), which
            // the step core holds; no MuJoCo call runs while the GIL is held here.
            OptionFlags::Raw(p) => Ok(i64::from(unsafe { p.read() })),
            OptionFlags::Attr(opt, name) => opt.bind(py).getattr(name.bind(py))?.extract(),
        }
    }

    pub(crate) fn set(&self, py: Python<'_>, flags: i64) -> PyResult<()> {
        match self {
            OptionFlags::Raw(p) => {
                let v = i32::try_from(flags).map_err(|_| {
                    pyo3::exceptions::PyOverflowError::new_err("disableflags: out of int32")
                })?;
                // SAFETY: as in `get`.
                unsafe { p.write(v) };
                Ok(())
            }
            OptionFlags::Attr(opt, name) => opt.bind(py).setattr(name.bind(py), flags),
        }
    }
}
