//! The exact, structure-exploiting solver of the P-F LP (the default).
//!
//! When every generator is Markov, Lₖ = (Uₖᵀ − I)/Δtₖ with every row of Uₖ non-negative and
//! summing to one (Ulam's indicator generators always; RBF generators built positivity-preserving),
//! the dual of the LP is the Bellman inequality of a stochastic shortest path (SSP):
//!
//! `V(i) ≤ c·Bᵢ·Δtₖ + Σⱼ Uₖ(i, j)·V(j)` for every state i and action k, V = 0 on the target,
//!
//! with c = 1 + 1/u_max (see [`crate::certificate`]). Its largest solution is the optimal
//! cost-to-go V*, an optimal dual; the primal flux is the occupation measure of the optimal policy,
//! `(I − U_πᵀ) q = t`, `z_{π(i)}(i) = Δt_{π(i)}·q(i)`. Two exact methods, chosen by structure:
//!
//! - **Deterministic moves** (every Uₖ row a unit vector: Ulam's method with one-cell shifts):
//!   Dijkstra from the target over the reversed moves gives V* exactly, and the flux is one pass
//!   over the shortest-path tree in decreasing V. O(nK log n); measured a few times the cost of
//!   the graph Dijkstra (`cargo bench -p pf-planner --bench pf`).
//! - **Stochastic moves** (RBF): policy iteration. Each evaluation is one sparse LU solve of
//!   `(I − U_π) V = c_π` (faer); the improvement step picks each state's best action. It starts
//!   from the policy that is greedy for the Dijkstra values of the moves' support graph with every
//!   transition replaced by its most likely one, made proper where needed, so on near-lattice
//!   generators it ends after a few evaluations. The flux reuses the last factorisation
//!   (a transposed solve).
//!
//! Why not network simplex or a general interior point: the deterministic case *is* a shortest
//! path, so Dijkstra is optimal in complexity and exact in floating point (no tolerance), and the
//! stochastic case is an SSP whose policy iteration converges in a handful of solves; Clarabel
//! (`LpSolver::Clarabel`) stays available as the independent cross-check.
//!
//! A generator that is not Markov (negative transition mass, rows that do not sum to one) is
//! reported as [`Structure::General`] and the caller falls back to Clarabel.

mod deterministic;
mod dijkstra;
mod model;
mod policy_iteration;

use std::time::Instant;

use tracing::debug;

use crate::deadline::Deadline;
use crate::error::PlanError;
use crate::lp_problem::LpProblem;
use crate::solve_status::SolverUsed;

use deterministic::{deterministic_moves, solve_deterministic};
use model::Model;
use policy_iteration::policy_iteration;

/// Transition mass below this (in absolute value) is treated as zero when reading Uₖ back from Lₖ.
const TRANSITION_EPS: f64 = 1e-12;

/// Largest accepted deviation of a row sum of Uₖ from one for the SSP structure.
const ROW_SUM_TOLERANCE: f64 = 1e-9;

/// Policy-iteration limit; SSP policy iteration ends in far fewer on every measured map.
pub const MAX_POLICY_ITERATIONS: usize = 200;

/// An action switches only when it improves the state's value by more than this relative
/// amount: exact ties must not make policy iteration cycle.
const IMPROVEMENT_EPS: f64 = 1e-12;

/// What kind of generator set this is.
#[derive(Debug, Clone, PartialEq)]
pub enum Structure {
    /// Markov generators whose moves are all deterministic.
    Deterministic,
    /// Markov generators with stochastic moves.
    Stochastic,
    /// Not Markov (the reason names the first offending entry): the SSP solver does not apply.
    General { reason: String },
}

/// An optimal primal-dual pair of the LP.
pub struct SspSolution {
    /// zₖ per direction, per active function.
    pub flux: Vec<Vec<f64>>,
    /// The optimal cost-to-go V* (0 on targets, +∞ where the target cannot be reached).
    pub potential: Vec<f64>,
    /// Which method ran: Dijkstra or policy iteration.
    pub method: SolverUsed,
    /// Policy evaluations (0 for Dijkstra).
    pub iterations: u32,
}

/// Reads the SSP structure of the LP's generators.
pub fn structure(problem: &LpProblem<'_>) -> Structure {
    if deterministic_moves(problem).is_some() {
        return Structure::Deterministic;
    }
    Model::build(problem).structure
}

/// Solves the LP exactly; `Ok(None)` when the generators are not Markov (use Clarabel).
pub fn solve(
    problem: &LpProblem<'_>,
    deadline: Deadline,
) -> Result<Option<SspSolution>, PlanError> {
    let started = Instant::now();
    let n = problem.target.len();
    if let Some(moves) = deterministic_moves(problem) {
        let moves_s = started.elapsed().as_secs_f64();
        let solution = solve_deterministic(problem, &moves, deadline)?;
        debug!(
            moves_s,
            solved_s = started.elapsed().as_secs_f64(),
            "SSP solved by Dijkstra"
        );
        return Ok(Some(solution));
    }
    let model = Model::build(problem);
    match &model.structure {
        Structure::General { reason } => {
            debug!(
                reason,
                "generators are not Markov; the SSP solver does not apply"
            );
            Ok(None)
        }
        // Not reached for Markov generators whose moves are all deterministic (handled above).
        Structure::Deterministic | Structure::Stochastic => {
            debug_assert!(n == model.action_ptr.len() - 1);
            policy_iteration(problem, &model, deadline).map(Some)
        }
    }
}
