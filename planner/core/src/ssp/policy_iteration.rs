//! Stochastic moves (RBF): policy iteration with Gauss-Seidel evaluation and a sparse-LU
//! fallback, warm-started from Dijkstra values.

use std::collections::VecDeque;

use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::Col;
use tracing::debug;

use crate::deadline::Deadline;
use crate::error::PlanError;
use crate::lp_problem::LpProblem;
use crate::solve_status::{LpStatus, SolverUsed};

use super::deterministic::check_reachable;
use super::dijkstra::dijkstra;
use super::model::Model;
use super::*;

/// Q-value of action a under the values V.
pub(super) fn q_value(model: &Model, target: &[bool], value: &[f64], a: usize) -> f64 {
    let mut q = model.action_cost[a];
    for (j, p) in model.transitions(a) {
        if !target[j] {
            q += p * value[j];
        }
    }
    q
}

pub(super) fn policy_iteration(
    problem: &LpProblem<'_>,
    model: &Model,
    deadline: Deadline,
) -> Result<SspSolution, PlanError> {
    let target = problem.target;
    let n = target.len();
    // States that can reach the target at all (support graph), and a proper fallback action of
    // each: one with positive probability of moving one BFS layer closer.
    let support = model.reversed(n, false);
    let mut layer = vec![usize::MAX; n];
    let mut descend = vec![usize::MAX; n];
    let mut queue: VecDeque<usize> = (0..n).filter(|&j| target[j]).collect();
    for &j in &queue {
        layer[j] = 0;
    }
    while let Some(j) = queue.pop_front() {
        for &(i, a) in &support.1[support.0[j]..support.0[j + 1]] {
            if layer[i] == usize::MAX {
                layer[i] = layer[j] + 1;
                descend[i] = a;
                queue.push_back(i);
            }
        }
    }
    let reachable: Vec<bool> = layer.iter().map(|&l| l != usize::MAX).collect();
    // Warm start: greedy for the Dijkstra values of the most-likely-move graph.
    let (ptr, entries) = model.reversed(n, true);
    let (guess, _, _) = dijkstra(
        target,
        usize::MAX,
        |_| Ok(()),
        |j| {
            entries[ptr[j]..ptr[j + 1]]
                .iter()
                .map(|&(i, a)| (i, model.action_cost[a], a))
        },
    )?;
    let mut policy = vec![usize::MAX; n];
    for i in (0..n).filter(|&i| reachable[i] && !target[i]) {
        let mut best = (f64::INFINITY, usize::MAX);
        for a in model.actions(i) {
            let proper = model.transitions(a).all(|(j, _)| reachable[j]);
            if !proper {
                continue;
            }
            let mut q = model.action_cost[a];
            for (j, p) in model.transitions(a) {
                if !target[j] {
                    q += p * guess[j];
                }
            }
            if q < best.0 {
                best = (q, a);
            }
        }
        policy[i] = if best.1 == usize::MAX {
            descend[i]
        } else {
            best.1
        };
    }
    make_proper(model, target, &reachable, &descend, &mut policy);

    // Dense index of the states whose values are unknown.
    let states: Vec<usize> = (0..n).filter(|&i| reachable[i] && !target[i]).collect();
    let mut index = vec![usize::MAX; n];
    for (s, &i) in states.iter().enumerate() {
        index[i] = s;
    }
    let mut value = vec![f64::INFINITY; n];
    for (j, _) in target.iter().enumerate().filter(|(_, &t)| t) {
        value[j] = 0.0;
    }
    // Gauss-Seidel starts from the warm-start values, downstream (small values) first.
    for &i in &states {
        value[i] = if guess[i].is_finite() { guess[i] } else { 0.0 };
    }
    let mut order = states.clone();
    order.sort_by(|&a, &b| guess[a].total_cmp(&guess[b]));
    let mut iterations = 0u32;
    loop {
        iterations += 1;
        if !evaluate_by_sweeps(model, target, &order, &policy, &mut value) {
            let lu = factor(model, &states, &index, &policy)?;
            let mut rhs =
                Col::<f64>::from_fn(states.len(), |s| model.action_cost[policy[states[s]]]);
            lu.solve_in_place(rhs.as_mat_mut());
            for (s, &i) in states.iter().enumerate() {
                value[i] = rhs[s];
            }
        }
        let mut changed = 0usize;
        for &i in &states {
            let current = q_value(model, target, &value, policy[i]);
            let mut best = (current, policy[i]);
            for a in model.actions(i) {
                if a == policy[i] || !model.transitions(a).all(|(j, _)| reachable[j]) {
                    continue;
                }
                let q = q_value(model, target, &value, a);
                if q < best.0 - IMPROVEMENT_EPS * best.0.abs().max(1e-300) {
                    best = (q, a);
                }
            }
            if best.1 != policy[i] {
                policy[i] = best.1;
                changed += 1;
            }
        }
        debug!(iterations, changed, "policy iteration");
        if changed == 0 {
            check_reachable(problem, &value)?;
            // Upstream (large values) first for the occupation measure.
            order.sort_by(|&a, &b| value[b].total_cmp(&value[a]));
            let q = match occupation_by_sweeps(model, problem, &states, &index, &order, &policy) {
                Some(q) => q,
                None => {
                    let lu = factor(model, &states, &index, &policy)?;
                    let mut q = Col::<f64>::from_fn(states.len(), |s| problem.start[states[s]]);
                    lu.solve_transpose_in_place(q.as_mat_mut());
                    (0..states.len()).map(|s| q[s]).collect()
                }
            };
            let k_count = problem.generators.directions.len();
            let mut flux = vec![vec![0.0; n]; k_count];
            for (s, &i) in states.iter().enumerate() {
                let k = model.action_dir[policy[i]];
                flux[k][i] = problem.generators.directions[k].step * q[s].max(0.0);
            }
            return Ok(SspSolution {
                flux,
                potential: value,
                method: SolverUsed::PolicyIteration,
                iterations,
            });
        }
        if iterations as usize >= MAX_POLICY_ITERATIONS {
            return Err(PlanError::LpFailed {
                status: LpStatus::MaxIterations,
                reason: format!(
                    "policy iteration did not settle after {iterations} evaluations ({changed} states still switching)"
                ),
            });
        }
        deadline.check("the LP solve (policy iteration)")?;
    }
}

/// Gauss-Seidel sweeps before an evaluation falls back to the sparse LU.
pub(super) const MAX_SWEEPS: usize = 2000;
/// A sweep whose largest change is below this times the largest value ends the iteration
/// (a few ulps: the result is the LU's to round-off).
pub(super) const SWEEP_TOLERANCE: f64 = 1e-14;

/// Evaluates `policy` in place: `V(i) = c(π(i)) + Σⱼ U_π(i, j) V(j)` (V = 0 on targets) by
/// Gauss-Seidel sweeps over `order` (downstream first). `I − U_π` of a proper policy is a
/// nonsingular M-matrix, so the sweeps converge from any start; with the transfer mostly
/// pointing downstream they converge in a few dozen sweeps, where a sparse LU of an RBF policy
/// matrix costs about a second at 128². `false` when `MAX_SWEEPS` did not suffice (the caller
/// then factorises).
pub(super) fn evaluate_by_sweeps(
    model: &Model,
    target: &[bool],
    order: &[usize],
    policy: &[usize],
    value: &mut [f64],
) -> bool {
    for _ in 0..MAX_SWEEPS {
        let (mut change, mut scale) = (0.0f64, 0.0f64);
        for &i in order {
            let a = policy[i];
            let (mut sum, mut stay) = (model.action_cost[a], 0.0);
            for (j, p) in model.transitions(a) {
                if j == i {
                    stay += p;
                } else if !target[j] {
                    sum += p * value[j];
                }
            }
            let v = sum / (1.0 - stay);
            change = change.max((v - value[i]).abs());
            scale = scale.max(v.abs());
            value[i] = v;
        }
        if !(change.is_finite() && scale.is_finite()) {
            return false;
        }
        if change <= SWEEP_TOLERANCE * scale {
            return true;
        }
    }
    false
}

/// The occupation measure q of `policy` from the start density, `(I − U_πᵀ) q = t` over
/// `states`, by Gauss-Seidel sweeps over `order` (upstream first); `None` when `MAX_SWEEPS` did
/// not suffice.
pub(super) fn occupation_by_sweeps(
    model: &Model,
    problem: &LpProblem<'_>,
    states: &[usize],
    index: &[usize],
    order: &[usize],
    policy: &[usize],
) -> Option<Vec<f64>> {
    let m = states.len();
    // Incoming transitions of the policy, CSR over the dense state index.
    let mut ptr = vec![0usize; m + 1];
    let mut stay = vec![0.0; m];
    for (s, &i) in states.iter().enumerate() {
        for (j, p) in model.transitions(policy[i]) {
            if j == i {
                stay[s] += p;
            } else if index[j] != usize::MAX {
                ptr[index[j] + 1] += 1;
            }
        }
    }
    for s in 0..m {
        ptr[s + 1] += ptr[s];
    }
    let mut fill = ptr[..m].to_vec();
    let mut incoming = vec![(0usize, 0.0); ptr[m]];
    for (s, &i) in states.iter().enumerate() {
        for (j, p) in model.transitions(policy[i]) {
            if j != i && index[j] != usize::MAX {
                incoming[fill[index[j]]] = (s, p);
                fill[index[j]] += 1;
            }
        }
    }
    let mut q = vec![0.0; m];
    for _ in 0..MAX_SWEEPS {
        let (mut change, mut scale) = (0.0f64, 0.0f64);
        for &i in order {
            let s = index[i];
            let mut sum = problem.start[i];
            for &(from, p) in &incoming[ptr[s]..ptr[s + 1]] {
                sum += p * q[from];
            }
            let v = sum / (1.0 - stay[s]);
            change = change.max((v - q[s]).abs());
            scale = scale.max(v.abs());
            q[s] = v;
        }
        if !(change.is_finite() && scale.is_finite()) {
            return None;
        }
        if change <= SWEEP_TOLERANCE * scale {
            return Some(q);
        }
    }
    None
}

/// Replaces the action of every state that cannot reach the target under `policy` by its
/// layer-descending action, so the policy is proper (reaches the target with probability one).
pub(super) fn make_proper(
    model: &Model,
    target: &[bool],
    reachable: &[bool],
    descend: &[usize],
    policy: &mut [usize],
) {
    let n = target.len();
    let mut ptr = vec![0usize; n + 1];
    for i in (0..n).filter(|&i| policy[i] != usize::MAX) {
        for (j, _) in model.transitions(policy[i]) {
            ptr[j + 1] += 1;
        }
    }
    for j in 0..n {
        ptr[j + 1] += ptr[j];
    }
    let mut next = ptr.clone();
    let mut from = vec![0usize; ptr[n]];
    for i in (0..n).filter(|&i| policy[i] != usize::MAX) {
        for (j, _) in model.transitions(policy[i]) {
            from[next[j]] = i;
            next[j] += 1;
        }
    }
    let mut reaches = target.to_vec();
    let mut queue: VecDeque<usize> = (0..n).filter(|&j| target[j]).collect();
    while let Some(j) = queue.pop_front() {
        for &i in &from[ptr[j]..ptr[j + 1]] {
            if !reaches[i] {
                reaches[i] = true;
                queue.push_back(i);
            }
        }
    }
    for i in 0..n {
        if reachable[i] && !target[i] && !reaches[i] {
            policy[i] = descend[i];
        }
    }
}

/// LU factors of `I − U_π` over the non-target reachable states.
pub(super) fn factor(
    model: &Model,
    states: &[usize],
    index: &[usize],
    policy: &[usize],
) -> Result<faer::sparse::linalg::solvers::Lu<usize, f64>, PlanError> {
    let mut triplets = Vec::with_capacity(states.len() * 3);
    for (s, &i) in states.iter().enumerate() {
        triplets.push(Triplet::new(s, s, 1.0));
        for (j, p) in model.transitions(policy[i]) {
            if index[j] != usize::MAX {
                triplets.push(Triplet::new(s, index[j], -p));
            }
        }
    }
    let failed = |reason: String| PlanError::LpFailed {
        status: LpStatus::NumericalError,
        reason,
    };
    let matrix =
        SparseColMat::<usize, f64>::try_new_from_triplets(states.len(), states.len(), &triplets)
            .map_err(|e| failed(format!("policy matrix: {e:?}")))?;
    matrix
        .sp_lu()
        .map_err(|e| failed(format!("policy evaluation (sparse LU): {e:?}")))
}
