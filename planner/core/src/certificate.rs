//! The duality certificate of a P-F LP solution: a check, independent of the solver that produced
//! it, that a flux z and a potential V are optimal for the LP in its original units.
//!
//! With the density eliminated (r = Σₖ zₖ / u_max, see [`crate::lp`]) the LP and its dual are
//! - primal: `min c·Bᵀ Σₖ zₖ` s.t. `−Σₖ Lₖ zₖ = t` (non-target rows), `z ≥ 0`, with c = 1 + 1/u_max;
//! - dual: `max tᵀV` s.t. `(−Lₖᵀ V)ᵢ ≤ c·Bᵢ` for every flux (k, i), V = 0 on the targets.
//!
//! For a Markov generator Lₖ = (Uₖᵀ − I)/Δtₖ the dual constraint reads
//! `V(i) ≤ c·Bᵢ·Δtₖ + Σⱼ Uₖ(i, j) V(j)`: the Bellman inequality of a stochastic shortest path,
//! whose largest solution is the cost-to-go. Primal feasibility, dual feasibility and a zero gap
//! together prove optimality (weak duality), whatever produced the pair.
//!
//! A potential of `+∞` marks a function that cannot reach the target: no start mass may sit
//! there, and a constraint that routes mass into such a function is satisfied by any finite
//! left-hand side (the move is never worth making).

use serde::Serialize;

use crate::generators::SparseColumns;
use crate::lp_problem::LpProblem;

/// Default bound of each relative residual and of the relative gap for a certified solution.
pub const CERTIFICATE_TOLERANCE: f64 = 1e-6;

/// Residuals and gap of one primal-dual pair, all relative (see the field docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Certificate {
    /// Largest violation of the mass balance or of z ≥ 0, relative to the largest start
    /// coefficient.
    pub primal_residual: f64,
    /// Largest violation of a Bellman inequality, relative to the largest `c·Bᵢ`.
    pub dual_residual: f64,
    /// |primal objective − dual objective| / max(|primal|, |dual|).
    pub duality_gap: f64,
    /// Primal objective `c·Bᵀ Σₖ zₖ` (= `Bᵀr + Σₖ Bᵀzₖ` at the eliminated density).
    pub primal_objective: f64,
    /// Dual objective tᵀV.
    pub dual_objective: f64,
    /// The bound the three relative figures are held to.
    pub tolerance: f64,
}

impl Certificate {
    /// Whether the pair is certified optimal within [`Certificate::tolerance`].
    pub fn holds(&self) -> bool {
        self.primal_residual <= self.tolerance
            && self.dual_residual <= self.tolerance
            && self.duality_gap <= self.tolerance
    }

    /// A certificate for the empty flow (all start mass already in the target).
    pub fn trivial() -> Self {
        Self {
            primal_residual: 0.0,
            dual_residual: 0.0,
            duality_gap: 0.0,
            primal_objective: 0.0,
            dual_objective: 0.0,
            tolerance: CERTIFICATE_TOLERANCE,
        }
    }
}

/// Checks `flux` (per direction, per active function) and `potential` (per active function,
/// 0 on targets, `+∞` where the target cannot be reached) against `problem`.
pub fn certify(problem: &LpProblem<'_>, flux: &[Vec<f64>], potential: &[f64]) -> Certificate {
    let gens = problem.generators;
    let n = gens.basis.len();
    let c = 1.0 + 1.0 / problem.u_max;
    let is_target = |i: usize| problem.target[i];
    let t_max = (0..n)
        .filter(|&i| !is_target(i))
        .map(|i| problem.start[i])
        .fold(0.0f64, f64::max);
    let cost_max = (0..n)
        .filter(|&i| !is_target(i))
        .map(|i| c * problem.cost[i])
        .fold(0.0f64, f64::max);

    let mut balance = vec![0.0; n];
    let mut negative = 0.0f64;
    let mut primal_objective = 0.0;
    let mut dual_violation = 0.0f64;
    for (l, z) in gens.generators.iter().zip(flux) {
        for i in (0..n).filter(|&i| !is_target(i)) {
            let zi = z[i];
            negative = negative.max(-zi);
            primal_objective += c * problem.cost[i] * zi;
            let mut lhs = 0.0;
            let mut moves = false;
            let mut into_unreachable = false;
            for (j, value) in l.column(i) {
                moves = true;
                if zi != 0.0 {
                    balance[j] -= value * zi;
                }
                if !is_target(j) {
                    if potential[j].is_infinite() && value > 0.0 {
                        into_unreachable = true;
                    } else {
                        lhs -= value * potential[j];
                    }
                }
            }
            if moves && !into_unreachable && potential[i].is_finite() {
                dual_violation = dual_violation.max(lhs - c * problem.cost[i]);
            }
        }
    }
    let mut balance_error = 0.0f64;
    let mut dual_objective = 0.0;
    for i in (0..n).filter(|&i| !is_target(i)) {
        balance_error = balance_error.max((balance[i] - problem.start[i]).abs());
        if problem.start[i] > 0.0 {
            dual_objective += problem.start[i] * potential[i];
        }
    }
    let relative = |value: f64, scale: f64| if scale > 0.0 { value / scale } else { value };
    let scale = primal_objective.abs().max(dual_objective.abs());
    let duality_gap = if dual_objective.is_finite() {
        relative((primal_objective - dual_objective).abs(), scale)
    } else {
        f64::INFINITY
    };
    Certificate {
        primal_residual: relative(balance_error.max(negative), t_max),
        dual_residual: relative(dual_violation.max(0.0), cost_max),
        duality_gap,
        primal_objective,
        dual_objective,
        tolerance: CERTIFICATE_TOLERANCE,
    }
}
