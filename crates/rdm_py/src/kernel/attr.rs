//! Typed reads and writes of Python attributes with interned names: the kernel keeps the
//! nodes' Python-visible state in their own attributes (read when a plan is loaded, written
//! back before any Python code runs).

use pyo3::prelude::*;
use pyo3::types::{PyString, PyTuple};

/// An attribute name interned once (cheap repeated lookups).
pub(crate) struct Name(Py<PyString>);

impl Name {
    pub(crate) fn new(py: Python<'_>, name: &str) -> Self {
        Name(PyString::intern(py, name).unbind())
    }

    /// The interned string (e.g. as a dict key).
    pub(crate) fn key<'py>(&self, py: Python<'py>) -> &Bound<'py, PyString> {
        self.0.bind(py)
    }

    pub(crate) fn get<'py>(&self, obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        obj.getattr(self.0.bind(obj.py()))
    }

    pub(crate) fn set<'py, V: IntoPyObject<'py>>(
        &self,
        obj: &Bound<'py, PyAny>,
        value: V,
    ) -> PyResult<()> {
        obj.setattr(self.0.bind(obj.py()), value)
    }

    pub(crate) fn i64(&self, obj: &Bound<'_, PyAny>) -> PyResult<i64> {
        self.get(obj)?.extract()
    }

    /// Python truthiness (`bool(obj.name)`).
    pub(crate) fn truthy(&self, obj: &Bound<'_, PyAny>) -> PyResult<bool> {
        self.get(obj)?.is_truthy()
    }
}

/// `node.kernel_plan()`: the plan tuple of the node's fast path, or None when it has none now.
pub(crate) fn read_plan<'py>(node: &Bound<'py, PyAny>) -> PyResult<Option<Bound<'py, PyTuple>>> {
    let plan = node.call_method0(pyo3::intern!(node.py(), "kernel_plan"))?;
    if plan.is_none() {
        Ok(None)
    } else {
        Ok(Some(plan.cast_into::<PyTuple>()?))
    }
}
