//! One object per constraint of Sec. V, each writing its own rows `G delta <= h` over the
//! free variables (in the manner of pink's limits/barriers). `Context` carries the
//! quantity values and their Jacobian at the current step.

use super::config::PlannerConfig;
use super::damper::{allowed_approach, state_step_bound};
use super::quantities::QuantityLayout;

/// Everything a constraint needs to write its rows.
pub struct Context<'a> {
    pub cfg: &'a PlannerConfig,
    pub layout: &'a QuantityLayout,
    /// Full state zeta = [p, eta, q].
    pub zeta: &'a [f64],
    /// zeta indices of the QP variables.
    pub free: &'a [usize],
    /// Quantity vector and its Jacobian (row-major, len x free.len()).
    pub values: &'a [f64],
    pub jac: &'a [f64],
    /// Joint limits (q order).
    pub limits: &'a [(f64, f64)],
    /// Stall torques (q order).
    pub stall: &'a [f64],
    /// Lower thrust limits.
    pub thrust_min: &'a [f64],
}

impl Context<'_> {
    fn jac_row(&self, r: usize) -> &[f64] {
        let nf = self.free.len();
        self.jac.get(r * nf..(r + 1) * nf).unwrap_or(&[])
    }
}

/// Write `sign * jac_row(r)` into `g` and `bound` into `h`.
fn row(ctx: &Context<'_>, r: usize, sign: f64, g: &mut [f64], h: &mut f64, bound: f64) {
    for (gi, ji) in g.iter_mut().zip(ctx.jac_row(r)) {
        *gi = sign * ji;
    }
    *h = bound;
}

/// A constraint family: a fixed number of rows and how to fill them.
pub trait Constraint: Send + Sync {
    /// Short name used in reports ("joint_limit", "joint_torque", ...).
    fn name(&self) -> &'static str;
    /// Rows this constraint writes (fixed at setup).
    fn n_rows(&self, layout: &QuantityLayout, n_free: usize) -> usize;
    /// Fill `g` (n_rows x n_free, row-major) and `h`.
    fn write(&self, ctx: &Context<'_>, g: &mut [f64], h: &mut [f64]);
}

/// State limits with the velocity damper of eqs. (58)-(60): joint limits from the
/// description, base roll/pitch within +-`base_tilt_limit`, plus the step limit on every
/// variable.
pub struct StateLimits;

impl Constraint for StateLimits {
    fn name(&self) -> &'static str {
        "joint_limit"
    }
    fn n_rows(&self, _: &QuantityLayout, n_free: usize) -> usize {
        2 * n_free
    }
    fn write(&self, ctx: &Context<'_>, g: &mut [f64], h: &mut [f64]) {
        let nf = ctx.free.len();
        g.fill(0.0);
        let cfg = ctx.cfg;
        for (c, &k) in ctx.free.iter().enumerate() {
            let x = ctx.zeta[k];
            let (step, lo, hi) = match k {
                0..=2 => (cfg.step_position, f64::NEG_INFINITY, f64::INFINITY),
                3 | 4 => (cfg.step_angle, -cfg.base_tilt_limit, cfg.base_tilt_limit),
                5 => (cfg.step_angle, f64::NEG_INFINITY, f64::INFINITY),
                _ => {
                    let (lo, hi) = ctx.limits.get(k - 6).copied().unwrap_or((-1e3, 1e3));
                    (cfg.step_angle, lo, hi)
                }
            };
            let up = state_step_bound(hi - x, step, &cfg.state);
            let down = state_step_bound(x - lo, step, &cfg.state);
            g[(2 * c) * nf + c] = 1.0;
            h[2 * c] = up;
            g[(2 * c + 1) * nf + c] = -1.0;
            h[2 * c + 1] = down;
        }
    }
}

/// Joint torque limits of eqs. (61)-(62): |tau_i| <= stall torque, damped.
pub struct JointTorque;

impl Constraint for JointTorque {
    fn name(&self) -> &'static str {
        "joint_torque"
    }
    fn n_rows(&self, l: &QuantityLayout, _: usize) -> usize {
        2 * l.n_q
    }
    fn write(&self, ctx: &Context<'_>, g: &mut [f64], h: &mut [f64]) {
        let nf = ctx.free.len();
        let l = ctx.layout;
        for i in 0..l.n_q {
            let r = l.torque() + i;
            let tau = ctx.values[r];
            let stall = ctx.stall.get(i).copied().unwrap_or(0.0);
            let p = &ctx.cfg.torque;
            let (a, b) = g.split_at_mut((2 * i + 1) * nf);
            let up = &mut a[2 * i * nf..];
            row(
                ctx,
                r,
                1.0,
                up,
                &mut h[2 * i],
                allowed_approach(stall - tau, p),
            );
            row(
                ctx,
                r,
                -1.0,
                &mut b[..nf],
                &mut h[2 * i + 1],
                allowed_approach(tau + stall, p),
            );
        }
    }
}

/// Rotor thrust limits of eqs. (63)-(64): lambda_min <= lambda <= lambda-bar+ (perching
/// upper limit when perched), damped.
pub struct RotorThrust;

impl Constraint for RotorThrust {
    fn name(&self) -> &'static str {
        "rotor_thrust"
    }
    fn n_rows(&self, l: &QuantityLayout, _: usize) -> usize {
        2 * l.n_rotors
    }
    fn write(&self, ctx: &Context<'_>, g: &mut [f64], h: &mut [f64]) {
        let nf = ctx.free.len();
        let l = ctx.layout;
        let p = &ctx.cfg.thrust;
        for i in 0..l.n_rotors {
            let lam = ctx.values[l.thrust() + i];
            let upper = ctx.values[l.thrust_upper() + i];
            let lower = ctx.thrust_min.get(i).copied().unwrap_or(0.0);
            let (ju, jl) = (
                ctx.jac_row(l.thrust_upper() + i),
                ctx.jac_row(l.thrust() + i),
            );
            let up = &mut g[2 * i * nf..(2 * i + 1) * nf];
            for (c, u) in up.iter_mut().enumerate() {
                *u = jl.get(c).unwrap_or(&0.0) - ju.get(c).unwrap_or(&0.0);
            }
            h[2 * i] = allowed_approach(upper - lam, p);
            let (_, rest) = g.split_at_mut((2 * i + 1) * nf);
            row(
                ctx,
                l.thrust() + i,
                -1.0,
                &mut rest[..nf],
                &mut h[2 * i + 1],
                allowed_approach(lam - lower, p),
            );
        }
    }
}

/// Flight stability of eqs. (65)-(66): rho stays above rho_F.
pub struct Stability;

impl Constraint for Stability {
    fn name(&self) -> &'static str {
        "stability"
    }
    fn n_rows(&self, _: &QuantityLayout, _: usize) -> usize {
        1
    }
    fn write(&self, ctx: &Context<'_>, g: &mut [f64], h: &mut [f64]) {
        let r = ctx.layout.rho();
        let bound = allowed_approach(ctx.values[r], &ctx.cfg.stability);
        row(ctx, r, -1.0, g, &mut h[0], bound);
    }
}

/// Collision avoidance of eq. (67) between shape pairs (and shapes vs the ceiling).
pub struct Collision;

impl Constraint for Collision {
    fn name(&self) -> &'static str {
        "collision"
    }
    fn n_rows(&self, l: &QuantityLayout, _: usize) -> usize {
        l.n_pairs
    }
    fn write(&self, ctx: &Context<'_>, g: &mut [f64], h: &mut [f64]) {
        let nf = ctx.free.len();
        let l = ctx.layout;
        for k in 0..l.n_pairs {
            let r = l.pairs() + k;
            let bound = allowed_approach(ctx.values[r], &ctx.cfg.collision);
            row(ctx, r, -1.0, &mut g[k * nf..(k + 1) * nf], &mut h[k], bound);
        }
    }
}

/// Rotor airflow interference of eq. (68): rotors of different units keep their
/// centres more than one diameter apart.
pub struct Airflow;

impl Constraint for Airflow {
    fn name(&self) -> &'static str {
        "airflow"
    }
    fn n_rows(&self, l: &QuantityLayout, _: usize) -> usize {
        l.airflow_pairs.len()
    }
    fn write(&self, ctx: &Context<'_>, g: &mut [f64], h: &mut [f64]) {
        let nf = ctx.free.len();
        let l = ctx.layout;
        for k in 0..l.airflow_pairs.len() {
            let r = l.airflow() + k;
            let bound = allowed_approach(ctx.values[r], &ctx.cfg.airflow);
            row(ctx, r, -1.0, &mut g[k * nf..(k + 1) * nf], &mut h[k], bound);
        }
    }
}

/// The full constraint set of eq. (70), in report order.
pub fn all_constraints() -> Vec<Box<dyn Constraint>> {
    vec![
        Box::new(StateLimits),
        Box::new(JointTorque),
        Box::new(RotorThrust),
        Box::new(Stability),
        Box::new(Collision),
        Box::new(Airflow),
    ]
}
