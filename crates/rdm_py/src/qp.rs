//! Binding of `rdm_core::qp::DenseQp`: `QpSolver(n, n_eq, n_ineq)`.

use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::create_exception;
use pyo3::prelude::*;

use rdm_core::qp::{DenseQp, QpSettings, QpStatus};

use crate::errors::RdmError;

create_exception!(
    _rdm,
    QpInputError,
    RdmError,
    "Bad QP data (wrong shape, NaN); the message names the argument."
);

fn status_name(s: QpStatus) -> &'static str {
    match s {
        QpStatus::Solved => "solved",
        QpStatus::AlmostSolved => "almost_solved",
        QpStatus::PrimalInfeasible => "primal_infeasible",
        QpStatus::DualInfeasible => "dual_infeasible",
        QpStatus::MaxIterations => "max_iterations",
        QpStatus::NumericalError => "numerical_error",
    }
}

fn flat2(a: &PyReadonlyArray2<'_, f64>, what: &str) -> PyResult<Vec<f64>> {
    let _ = what;
    Ok(a.as_array().iter().copied().collect::<Vec<_>>())
}

/// Dense QP: min ½xᵀPx + qᵀx s.t. A_eq x = b_eq, G x ≤ h (Clarabel, fixed pattern).
#[pyclass(module = "rdm._rdm", unsendable)]
pub struct QpSolver {
    inner: DenseQp,
}

#[pymethods]
impl QpSolver {
    #[new]
    #[pyo3(signature = (n, n_eq, n_ineq, max_iter = 50, tolerance = 1e-8))]
    fn new(n: usize, n_eq: usize, n_ineq: usize, max_iter: u32, tolerance: f64) -> PyResult<Self> {
        let inner = DenseQp::new(
            n,
            n_eq,
            n_ineq,
            QpSettings {
                max_iter,
                tolerance,
            },
        )
        .map_err(|e| QpInputError::new_err(e.to_string()))?;
        Ok(Self { inner })
    }

    /// Solve; returns (status, x). x is zeros unless status is solved/almost_solved.
    #[allow(clippy::too_many_arguments)]
    fn solve<'py>(
        &mut self,
        py: Python<'py>,
        p: PyReadonlyArray2<'py, f64>,
        q: PyReadonlyArray1<'py, f64>,
        a_eq: PyReadonlyArray2<'py, f64>,
        b_eq: PyReadonlyArray1<'py, f64>,
        g: PyReadonlyArray2<'py, f64>,
        h: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<(&'static str, Bound<'py, PyAny>)> {
        let (n, ne, ni) = (self.inner.n(), self.inner.n_eq(), self.inner.n_ineq());
        for (what, shape, rows) in [
            ("P", p.as_array().dim(), n),
            ("A_eq", a_eq.as_array().dim(), ne),
            ("G", g.as_array().dim(), ni),
        ] {
            if shape.0 != rows || (rows > 0 && shape.1 != n) {
                return Err(QpInputError::new_err(format!(
                    "{what}: expected shape ({rows}, {n}), got {shape:?}"
                )));
            }
        }
        let p = flat2(&p, "P")?;
        let a = flat2(&a_eq, "A_eq")?;
        let gm = flat2(&g, "G")?;
        let q: Vec<f64> = q.as_array().to_vec();
        let b: Vec<f64> = b_eq.as_array().to_vec();
        let hv: Vec<f64> = h.as_array().to_vec();
        let inner = &mut self.inner;
        let status = py
            .detach(move || inner.solve(&p, &q, &a, &b, &gm, &hv))
            .map_err(|e| QpInputError::new_err(e.to_string()))?;
        let x = self.inner.solution().to_vec().into_pyarray(py).into_any();
        Ok((status_name(status), x))
    }

    /// Interior-point iterations of the last solve.
    #[getter]
    fn iterations(&self) -> u32 {
        self.inner.iterations()
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<QpSolver>()?;
    m.add("QpInputError", m.py().get_type::<QpInputError>())?;
    Ok(())
}
