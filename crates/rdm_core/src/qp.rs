//! A small dense QP on Clarabel for loop-time use:
//!
//! minimise ½ xᵀPx + qᵀx  subject to  A_eq x = b_eq,  G x ≤ h.
//!
//! The sparsity pattern is fully dense and fixed at setup (built with `CscMatrix::new` and
//! explicit zeros, because `CscMatrix::from` drops zeros and later updates would be refused).
//! Presolve and equilibration are off: presolve would block data updates, and Clarabel's
//! equilibration is computed once from the setup data (dummy zeros here) and merely
//! re-applied on update. Instead each inequality row is normalised by its Euclidean norm
//! before it is handed over, which keeps rows of different physical units comparable.
//! After `new`, `solve` allocates nothing (checked in `tests/qp_alloc.rs`).

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT,
    SolverStatus, SupportedConeT, ZeroConeT,
};

/// Right-hand sides larger than this (after row normalisation) are clipped to it: Clarabel
/// handles huge finite bounds badly (scaling), and infinite ones would need presolve.
pub const QP_LOOSE_BOUND: f64 = 1e6;

/// Outcome of one solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QpStatus {
    /// Optimal to the requested tolerances.
    Solved,
    /// Optimal to Clarabel's reduced tolerances.
    AlmostSolved,
    /// The constraints admit no point.
    PrimalInfeasible,
    /// The objective is unbounded below.
    DualInfeasible,
    /// The iteration cap was reached.
    MaxIterations,
    /// Numerical trouble or insufficient progress.
    NumericalError,
}

impl QpStatus {
    /// Whether `solution()` holds a usable minimiser.
    pub fn is_ok(self) -> bool {
        matches!(self, QpStatus::Solved | QpStatus::AlmostSolved)
    }
}

/// Bad use of the solver (the QP itself is never an error: see [`QpStatus`]).
#[derive(Clone, Debug, PartialEq)]
pub enum QpError {
    /// An argument has the wrong length.
    WrongLength {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    /// An argument holds NaN or ±inf where that is not allowed.
    NonFinite(&'static str),
    /// Clarabel refused the setup or an update.
    Solver(String),
}

impl std::fmt::Display for QpError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            QpError::WrongLength {
                what,
                expected,
                got,
            } => write!(f, "{what}: expected {expected} values, got {got}"),
            QpError::NonFinite(what) => write!(f, "{what}: NaN or infinite value"),
            QpError::Solver(m) => write!(f, "QP solver: {m}"),
        }
    }
}

impl std::error::Error for QpError {}

/// Settings fixed at setup.
#[derive(Clone, Copy, Debug)]
pub struct QpSettings {
    /// Interior-point iteration cap.
    pub max_iter: u32,
    /// Absolute/relative gap and feasibility tolerance.
    pub tolerance: f64,
}

impl Default for QpSettings {
    fn default() -> Self {
        Self {
            max_iter: 50,
            tolerance: 1e-8,
        }
    }
}

/// A dense QP of fixed size with in-place data updates.
pub struct DenseQp {
    n: usize,
    n_eq: usize,
    n_ineq: usize,
    solver: DefaultSolver<f64>,
    p_values: Vec<f64>,
    a_values: Vec<f64>,
    q: Vec<f64>,
    b: Vec<f64>,
    x: Vec<f64>,
    iterations: u32,
}

impl std::fmt::Debug for DenseQp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DenseQp")
            .field("n", &self.n)
            .field("n_eq", &self.n_eq)
            .field("n_ineq", &self.n_ineq)
            .finish()
    }
}

fn dense_upper_pattern(n: usize) -> CscMatrix<f64> {
    let mut colptr = Vec::with_capacity(n + 1);
    let mut rowval = Vec::with_capacity(n * (n + 1) / 2);
    colptr.push(0);
    for j in 0..n {
        rowval.extend(0..=j);
        colptr.push(rowval.len());
    }
    let nnz = rowval.len();
    // Identity values at setup so the setup problem is well posed; overwritten per solve.
    let mut nzval = vec![0.0; nnz];
    for j in 0..n {
        nzval[colptr[j + 1] - 1] = 1.0;
    }
    CscMatrix::new(n, n, colptr, rowval, nzval)
}

fn dense_pattern(m: usize, n: usize) -> CscMatrix<f64> {
    let colptr = (0..=n).map(|j| j * m).collect();
    let rowval = (0..n).flat_map(|_| 0..m).collect();
    CscMatrix::new(m, n, colptr, rowval, vec![0.0; m * n])
}

fn check(what: &'static str, v: &[f64], len: usize) -> Result<(), QpError> {
    if v.len() != len {
        return Err(QpError::WrongLength {
            what,
            expected: len,
            got: v.len(),
        });
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(QpError::NonFinite(what));
    }
    Ok(())
}

impl DenseQp {
    /// A solver for `n` variables, `n_eq` equality rows and `n_ineq` inequality rows.
    pub fn new(
        n: usize,
        n_eq: usize,
        n_ineq: usize,
        settings: QpSettings,
    ) -> Result<Self, QpError> {
        if n == 0 {
            return Err(QpError::WrongLength {
                what: "n",
                expected: 1,
                got: 0,
            });
        }
        let m = n_eq + n_ineq;
        let p = dense_upper_pattern(n);
        let a = dense_pattern(m, n);
        let q = vec![0.0; n];
        let b = vec![0.0; m];
        let mut cones: Vec<SupportedConeT<f64>> = Vec::with_capacity(2);
        if n_eq > 0 {
            cones.push(ZeroConeT(n_eq));
        }
        if n_ineq > 0 {
            cones.push(NonnegativeConeT(n_ineq));
        }
        let s: DefaultSettings<f64> = DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .equilibrate_enable(false)
            .max_iter(settings.max_iter)
            .tol_gap_abs(settings.tolerance)
            .tol_gap_rel(settings.tolerance)
            .tol_feas(settings.tolerance)
            .direct_solve_method("qdldl".to_string())
            .build()
            .map_err(|e| QpError::Solver(e.to_string()))?;
        let solver = DefaultSolver::new(&p, &q, &a, &b, &cones, s)
            .map_err(|e| QpError::Solver(e.to_string()))?;
        Ok(Self {
            n,
            n_eq,
            n_ineq,
            solver,
            p_values: p.nzval.clone(),
            a_values: a.nzval.clone(),
            q,
            b,
            x: vec![0.0; n],
            iterations: 0,
        })
    }

    /// Number of variables.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Number of equality rows.
    pub fn n_eq(&self) -> usize {
        self.n_eq
    }

    /// Number of inequality rows.
    pub fn n_ineq(&self) -> usize {
        self.n_ineq
    }

    /// Solve with new data. Matrices are row-major: `p` n×n (symmetrised as (P+Pᵀ)/2),
    /// `a_eq` n_eq×n, `g` n_ineq×n. `h` may hold +inf (row dropped in effect); every other
    /// entry must be finite. Allocation-free.
    #[allow(clippy::too_many_arguments)]
    pub fn solve(
        &mut self,
        p: &[f64],
        q: &[f64],
        a_eq: &[f64],
        b_eq: &[f64],
        g: &[f64],
        h: &[f64],
    ) -> Result<QpStatus, QpError> {
        let (n, n_eq, n_ineq) = (self.n, self.n_eq, self.n_ineq);
        check("P", p, n * n)?;
        check("q", q, n)?;
        check("A_eq", a_eq, n_eq * n)?;
        check("b_eq", b_eq, n_eq)?;
        check("G", g, n_ineq * n)?;
        if h.len() != n_ineq {
            return Err(QpError::WrongLength {
                what: "h",
                expected: n_ineq,
                got: h.len(),
            });
        }
        if h.iter().any(|v| v.is_nan() || *v == f64::NEG_INFINITY) {
            return Err(QpError::NonFinite("h"));
        }
        let mut k = 0;
        for j in 0..n {
            for i in 0..=j {
                self.p_values[k] = 0.5 * (p[i * n + j] + p[j * n + i]);
                k += 1;
            }
        }
        self.q.copy_from_slice(q);
        let m = n_eq + n_ineq;
        for i in 0..n_eq {
            for j in 0..n {
                self.a_values[j * m + i] = a_eq[i * n + j];
            }
            self.b[i] = b_eq[i];
        }
        for i in 0..n_ineq {
            let row = &g[i * n..(i + 1) * n];
            let norm = row.iter().map(|v| v * v).sum::<f64>().sqrt();
            let scale = if norm > 1e-12 { 1.0 / norm } else { 1.0 };
            for (j, v) in row.iter().enumerate() {
                self.a_values[j * m + n_eq + i] = v * scale;
            }
            self.b[n_eq + i] = (h[i] * scale).min(QP_LOOSE_BOUND);
        }
        self.solver
            .update_P(&self.p_values)
            .and_then(|_| self.solver.update_A(&self.a_values))
            .and_then(|_| self.solver.update_q(&self.q))
            .and_then(|_| self.solver.update_b(&self.b))
            .map_err(|e| QpError::Solver(e.to_string()))?;
        self.solver.solve();
        let solution = &self.solver.solution;
        self.iterations = solution.iterations;
        let status = match solution.status {
            SolverStatus::Solved => QpStatus::Solved,
            SolverStatus::AlmostSolved => QpStatus::AlmostSolved,
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                QpStatus::PrimalInfeasible
            }
            SolverStatus::DualInfeasible | SolverStatus::AlmostDualInfeasible => {
                QpStatus::DualInfeasible
            }
            SolverStatus::MaxIterations | SolverStatus::MaxTime => QpStatus::MaxIterations,
            _ => QpStatus::NumericalError,
        };
        if status.is_ok() {
            self.x.copy_from_slice(&solution.x);
        } else {
            self.x.fill(0.0);
        }
        Ok(status)
    }

    /// Minimiser of the last solve (zeros if it failed).
    pub fn solution(&self) -> &[f64] {
        &self.x
    }

    /// Dual variables of the inequality rows of the last solve (scaled by the row
    /// normalisation; only their sign pattern and magnitude ranking are meaningful).
    pub fn inequality_duals(&self) -> &[f64] {
        let z = &self.solver.solution.z;
        z.get(self.n_eq..).unwrap_or(&[])
    }

    /// Interior-point iterations of the last solve.
    pub fn iterations(&self) -> u32 {
        self.iterations
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_constrained_quadratic() {
        // min (x0-1)^2 + (x1-2)^2 s.t. x0 + x1 = 1, x1 <= 0.2
        let mut qp = DenseQp::new(2, 1, 1, QpSettings::default()).unwrap();
        let st = qp
            .solve(
                &[2.0, 0.0, 0.0, 2.0],
                &[-2.0, -4.0],
                &[1.0, 1.0],
                &[1.0],
                &[0.0, 1.0],
                &[0.2],
            )
            .unwrap();
        assert_eq!(st, QpStatus::Solved);
        let x = qp.solution();
        assert!(
            (x[0] - 0.8).abs() < 1e-6 && (x[1] - 0.2).abs() < 1e-6,
            "{x:?}"
        );
    }

    #[test]
    fn infeasible_and_bad_input() {
        let mut qp = DenseQp::new(1, 0, 2, QpSettings::default()).unwrap();
        let st = qp
            .solve(&[1.0], &[0.0], &[], &[], &[1.0, -1.0], &[-1.0, -1.0])
            .unwrap();
        assert_eq!(st, QpStatus::PrimalInfeasible);
        assert!(matches!(
            qp.solve(&[f64::NAN], &[0.0], &[], &[], &[1.0, -1.0], &[1.0, 1.0]),
            Err(QpError::NonFinite("P"))
        ));
        assert!(matches!(
            qp.solve(&[1.0], &[0.0], &[], &[], &[1.0], &[1.0, 1.0]),
            Err(QpError::WrongLength { what: "G", .. })
        ));
    }
}
