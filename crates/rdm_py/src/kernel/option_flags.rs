//! `model.opt.disableflags` as the kernel reads and writes it around a step (lazy sensors):
//! the int itself when `rdm.plant.option_flags` found its address, else the bindings'
//! property (three attribute accesses a step, ~2k instructions).

use pyo3::prelude::*;

use super::attr::Name;

pub(crate) enum OptionFlags {
    /// `Plant._flags_address`: the int32 inside the model the link keeps alive.
    Raw(*mut i32),
    /// `model.opt` and the interned `disableflags`.
    Attr(Py<PyAny>, Name),
}

impl OptionFlags {
    /// From `Plant._flags_address` (None: the property of `opt`). The address is used only
    /// where the probe could have found it: aligned, inside the first `searched` bytes
    /// (`rdm.plant.option_flags.SEARCH_BYTES`) of the model the link holds (`model._address`),
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
            _ => OptionFlags::Attr(opt, Name::new(py, "disableflags")),
        }
    }

    pub(crate) fn get(&self, py: Python<'_>) -> PyResult<i64> {
        match self {
            // SAFETY: the address was probed inside the live model (option_flags.py), which
            // the plant link holds; no MuJoCo call runs while the GIL is held here.
            OptionFlags::Raw(p) => Ok(i64::from(unsafe { p.read() })),
            OptionFlags::Attr(opt, name) => name.i64(opt.bind(py)),
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
            OptionFlags::Attr(opt, name) => name.set(opt.bind(py), flags),
        }
    }
}
