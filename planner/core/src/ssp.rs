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

use std::cmp::Ordering;
use std::collections::{BinaryHeap, VecDeque};
use std::time::Instant;

use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::Col;
use tracing::debug;

use crate::deadline::Deadline;
use crate::error::PlanError;
use crate::generators::SparseColumns;
use crate::lp_problem::LpProblem;
use crate::solve_status::{LpStatus, SolverUsed};

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

/// The SSP form of one LP: states are active functions, actions the non-wall fluxes.
struct Model {
    /// Actions of state i: `action_ptr[i]..action_ptr[i + 1]`.
    action_ptr: Vec<usize>,
    /// Direction of each action.
    action_dir: Vec<usize>,
    /// Cost c·Bᵢ·Δtₖ of each action.
    action_cost: Vec<f64>,
    /// Transitions of action a: `trans_ptr[a]..trans_ptr[a + 1]` into `trans_to`/`trans_prob`
    /// (self-loops included, targets included).
    trans_ptr: Vec<usize>,
    trans_to: Vec<usize>,
    trans_prob: Vec<f64>,
    structure: Structure,
}

impl Model {
    fn build(problem: &LpProblem<'_>) -> Model {
        let gens = problem.generators;
        let n = gens.basis.len();
        let c = 1.0 + 1.0 / problem.u_max;
        let nnz: usize = gens.generators.iter().map(|l| l.nnz()).sum();
        let actions = n * gens.generators.len();
        let mut trans_ptr = Vec::with_capacity(actions + 1);
        trans_ptr.push(0);
        let mut model = Model {
            action_ptr: Vec::with_capacity(n + 1),
            action_dir: Vec::with_capacity(actions),
            action_cost: Vec::with_capacity(actions),
            trans_ptr,
            trans_to: Vec::with_capacity(nnz),
            trans_prob: Vec::with_capacity(nnz),
            structure: Structure::Deterministic,
        };
        model.action_ptr.push(0);
        for i in 0..n {
            if !problem.target[i] {
                for (k, l) in gens.generators.iter().enumerate() {
                    let step = gens.directions[k].step;
                    let mut any = false;
                    let mut stay = 1.0;
                    let mut sum = 0.0;
                    let first = model.trans_to.len();
                    for (j, value) in l.column(i) {
                        any = true;
                        if j == i {
                            stay += step * value;
                        } else {
                            let prob = step * value;
                            if prob < -TRANSITION_EPS {
                                model.mark_general(format!(
                                    "direction {k}, function {i}: transition mass {prob:.3e} to {j} is negative"
                                ));
                            }
                            if prob > TRANSITION_EPS {
                                model.trans_to.push(j);
                                model.trans_prob.push(prob);
                                sum += prob;
                            }
                        }
                    }
                    if !any {
                        // A wall: the flux moves nothing and only costs, so it is no action.
                        continue;
                    }
                    if stay < -TRANSITION_EPS {
                        model.mark_general(format!(
                            "direction {k}, function {i}: negative probability {stay:.3e} of staying"
                        ));
                    }
                    if stay > TRANSITION_EPS {
                        model.trans_to.push(i);
                        model.trans_prob.push(stay);
                        sum += stay;
                    }
                    if (sum - 1.0).abs() > ROW_SUM_TOLERANCE {
                        model.mark_general(format!(
                            "direction {k}, function {i}: transition mass sums to {sum:.12}"
                        ));
                    }
                    let moves = model.trans_to.len() - first;
                    if moves == 0 || (moves == 1 && model.trans_to[first] == i) {
                        // Only staying: the flux costs and moves nothing (a wall in effect).
                        model.trans_to.truncate(first);
                        model.trans_prob.truncate(first);
                        continue;
                    }
                    if moves == 1 && model.trans_to[first] != i {
                        // Read back from 1/Δt · Δt: exactly one by construction.
                        model.trans_prob[first] = 1.0;
                    } else if model.structure == Structure::Deterministic {
                        model.structure = Structure::Stochastic;
                    }
                    model.trans_ptr.push(model.trans_to.len());
                    model.action_dir.push(k);
                    model.action_cost.push(c * problem.cost[i] * step);
                }
            }
            model.action_ptr.push(model.action_dir.len());
        }
        model
    }

    fn mark_general(&mut self, reason: String) {
        if !matches!(self.structure, Structure::General { .. }) {
            self.structure = Structure::General { reason };
        }
    }

    fn actions(&self, i: usize) -> std::ops::Range<usize> {
        self.action_ptr[i]..self.action_ptr[i + 1]
    }

    fn transitions(&self, a: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let range = self.trans_ptr[a]..self.trans_ptr[a + 1];
        self.trans_to[range.clone()]
            .iter()
            .copied()
            .zip(self.trans_prob[range].iter().copied())
    }

    /// Reversed moves as CSR over the destination: `(source state, action)` per entry.
    /// With `most_likely_only`, each action contributes its most likely transition only.
    fn reversed(&self, n: usize, most_likely_only: bool) -> (Vec<usize>, Vec<(usize, usize)>) {
        // Two passes over the moves (count, then fill) instead of an intermediate edge list.
        let mut ptr = vec![0usize; n + 1];
        self.for_each_move(n, most_likely_only, |j, _, _| ptr[j + 1] += 1);
        for j in 0..n {
            ptr[j + 1] += ptr[j];
        }
        let mut next = ptr[..n].to_vec();
        let mut entries = vec![(0usize, 0usize); ptr[n]];
        self.for_each_move(n, most_likely_only, |j, i, a| {
            entries[next[j]] = (i, a);
            next[j] += 1;
        });
        (ptr, entries)
    }

    /// Calls `visit(destination, source, action)` for every move to another state.
    fn for_each_move(
        &self,
        n: usize,
        most_likely_only: bool,
        mut visit: impl FnMut(usize, usize, usize),
    ) {
        for i in 0..n {
            for a in self.actions(i) {
                if most_likely_only {
                    let best = self
                        .transitions(a)
                        .filter(|&(j, _)| j != i)
                        .max_by(|x, y| x.1.total_cmp(&y.1).then(y.0.cmp(&x.0)));
                    if let Some((j, _)) = best {
                        visit(j, i, a);
                    }
                } else {
                    for (j, _) in self.transitions(a).filter(|&(j, _)| j != i) {
                        visit(j, i, a);
                    }
                }
            }
        }
    }
}

#[derive(Copy, Clone, PartialEq)]
struct HeapEntry {
    key: f64,
    state: usize,
}

impl Eq for HeapEntry {}

impl Ord for HeapEntry {
    fn cmp(&self, other: &Self) -> Ordering {
        // Min-heap on the key; ties broken by the state index so runs are deterministic.
        other
            .key
            .total_cmp(&self.key)
            .then_with(|| other.state.cmp(&self.state))
    }
}

impl PartialOrd for HeapEntry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// Dijkstra from the targets over reversed moves: (values, chosen action, pop order).
fn dijkstra(
    model: &Model,
    target: &[bool],
    reversed: &(Vec<usize>, Vec<(usize, usize)>),
) -> (Vec<f64>, Vec<usize>, Vec<usize>) {
    let n = target.len();
    let (ptr, entries) = reversed;
    let mut value = vec![f64::INFINITY; n];
    let mut policy = vec![usize::MAX; n];
    let mut order = Vec::with_capacity(n);
    let mut heap = BinaryHeap::new();
    for (j, _) in target.iter().enumerate().filter(|(_, &t)| t) {
        value[j] = 0.0;
        heap.push(HeapEntry { key: 0.0, state: j });
    }
    while let Some(HeapEntry { key, state: j }) = heap.pop() {
        if key > value[j] {
            continue;
        }
        order.push(j);
        for &(i, a) in &entries[ptr[j]..ptr[j + 1]] {
            if target[i] {
                continue;
            }
            let candidate = key + model.action_cost[a];
            if candidate < value[i] {
                value[i] = candidate;
                policy[i] = a;
                heap.push(HeapEntry {
                    key: candidate,
                    state: i,
                });
            }
        }
    }
    (value, policy, order)
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

/// States settled by Dijkstra between two deadline checks (about 0.1 ms of work).
const STATES_PER_DEADLINE_CHECK: usize = 4096;

/// No move (a wall, or a target state).
const NO_MOVE: u32 = u32::MAX;

/// The destination of every (direction, state) move, `dest[k·n + i]`, when every generator column
/// is a wall or one deterministic move (Ulam's method); `None` otherwise.
fn deterministic_moves(problem: &LpProblem<'_>) -> Option<Vec<u32>> {
    let gens = problem.generators;
    let n = gens.basis.len();
    if u32::try_from(n).is_err() {
        return None;
    }
    let mut dest = vec![NO_MOVE; n * gens.generators.len()];
    for (k, l) in gens.generators.iter().enumerate() {
        let step = gens.directions[k].step;
        for i in (0..n).filter(|&i| !problem.target[i]) {
            let range = l.colptr[i]..l.colptr[i + 1];
            match range.len() {
                0 => {}
                2 => {
                    let (mut stay, mut to) = (f64::NAN, (usize::MAX, f64::NAN));
                    for e in range {
                        let (j, v) = (l.rowval[e], l.nzval[e]);
                        if j == i {
                            stay = 1.0 + step * v;
                        } else {
                            to = (j, step * v);
                        }
                    }
                    let exact = |x: f64, want: f64| (x - want).abs() <= TRANSITION_EPS;
                    if to.0 == usize::MAX || !exact(stay, 0.0) || !exact(to.1, 1.0) {
                        return None;
                    }
                    dest[k * n + i] = to.0 as u32;
                }
                _ => return None,
            }
        }
    }
    Some(dest)
}

/// Dijkstra from the targets over the reversed moves, then the flux in one pass over the
/// shortest-path tree in decreasing value.
fn solve_deterministic(
    problem: &LpProblem<'_>,
    dest: &[u32],
    deadline: Deadline,
) -> Result<SspSolution, PlanError> {
    let gens = problem.generators;
    let n = gens.basis.len();
    let k_count = gens.directions.len();
    let c = 1.0 + 1.0 / problem.u_max;
    // Reversed moves as CSR over the destination: (source, direction) per entry.
    let mut ptr = vec![0u32; n + 1];
    for &j in dest.iter().filter(|&&j| j != NO_MOVE) {
        ptr[j as usize + 1] += 1;
    }
    for j in 0..n {
        ptr[j + 1] += ptr[j];
    }
    let mut next: Vec<u32> = ptr[..n].to_vec();
    let mut from = vec![(0u32, 0u8); ptr[n] as usize];
    for (slot, &j) in dest.iter().enumerate() {
        if j != NO_MOVE {
            let (k, i) = (slot / n, slot % n);
            from[next[j as usize] as usize] = (i as u32, k as u8);
            next[j as usize] += 1;
        }
    }
    let step_cost: Vec<f64> = gens.directions.iter().map(|d| c * d.step).collect();
    let mut value = vec![f64::INFINITY; n];
    let mut policy = vec![u8::MAX; n];
    let mut order = Vec::with_capacity(n);
    let mut heap = BinaryHeap::new();
    for (j, _) in problem.target.iter().enumerate().filter(|(_, &t)| t) {
        value[j] = 0.0;
        heap.push(HeapEntry { key: 0.0, state: j });
    }
    while let Some(HeapEntry { key, state: j }) = heap.pop() {
        if key > value[j] {
            continue;
        }
        if order.len() % STATES_PER_DEADLINE_CHECK == 0 {
            deadline.check("the LP solve (Dijkstra)")?;
        }
        order.push(j);
        for &(i, k) in &from[ptr[j] as usize..ptr[j + 1] as usize] {
            let i = i as usize;
            let candidate = key + problem.cost[i] * step_cost[k as usize];
            if candidate < value[i] {
                value[i] = candidate;
                policy[i] = k;
                heap.push(HeapEntry {
                    key: candidate,
                    state: i,
                });
            }
        }
    }
    check_reachable(problem, &value)?;
    let mut q = problem.start.to_vec();
    let mut flux = vec![vec![0.0; n]; k_count];
    // Decreasing value: every state's inflow is complete before it is passed on.
    for &i in order.iter().rev() {
        if problem.target[i] || q[i] == 0.0 {
            continue;
        }
        let k = policy[i] as usize;
        flux[k][i] = gens.directions[k].step * q[i];
        let j = dest[k * n + i] as usize;
        if !problem.target[j] {
            q[j] += q[i];
        }
    }
    Ok(SspSolution {
        flux,
        potential: value,
        method: SolverUsed::Dijkstra,
        iterations: 0,
    })
}

fn check_reachable(problem: &LpProblem<'_>, value: &[f64]) -> Result<(), PlanError> {
    if let Some(i) = (0..value.len())
        .find(|&i| !problem.target[i] && problem.start[i] > 0.0 && value[i].is_infinite())
    {
        return Err(PlanError::Infeasible {
            reason: format!(
                "start mass on basis function {i}, from which no sequence of moves reaches the goal region"
            ),
        });
    }
    Ok(())
}

/// Q-value of action a under the values V.
fn q_value(model: &Model, target: &[bool], value: &[f64], a: usize) -> f64 {
    let mut q = model.action_cost[a];
    for (j, p) in model.transitions(a) {
        if !target[j] {
            q += p * value[j];
        }
    }
    q
}

fn policy_iteration(
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
    let (guess, _, _) = dijkstra(model, target, &model.reversed(n, true));
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
const MAX_SWEEPS: usize = 2000;
/// A sweep whose largest change is below this times the largest value ends the iteration
/// (a few ulps: the result is the LU's to round-off).
const SWEEP_TOLERANCE: f64 = 1e-14;

/// Evaluates `policy` in place: `V(i) = c(π(i)) + Σⱼ U_π(i, j) V(j)` (V = 0 on targets) by
/// Gauss-Seidel sweeps over `order` (downstream first). `I − U_π` of a proper policy is a
/// nonsingular M-matrix, so the sweeps converge from any start; with the transfer mostly
/// pointing downstream they converge in a few dozen sweeps, where a sparse LU of an RBF policy
/// matrix costs about a second at 128². `false` when `MAX_SWEEPS` did not suffice (the caller
/// then factorises).
fn evaluate_by_sweeps(
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
fn occupation_by_sweeps(
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
fn make_proper(
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
fn factor(
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
