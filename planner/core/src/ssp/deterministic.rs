//! Deterministic moves (Ulam's one-cell shifts): V* by Dijkstra, the flux by one pass over the
//! shortest-path tree.

use crate::deadline::Deadline;
use crate::error::PlanError;
use crate::lp_problem::LpProblem;
use crate::solve_status::SolverUsed;

use super::dijkstra::dijkstra;
use super::*;

/// States settled by Dijkstra between two deadline checks (about 0.1 ms of work).
pub(super) const STATES_PER_DEADLINE_CHECK: usize = 4096;

/// No move (a wall, or a target state).
pub(super) const NO_MOVE: u32 = u32::MAX;

/// The destination of every (direction, state) move, `dest[k·n + i]`, when every generator column
/// is a wall or one deterministic move (Ulam's method); `None` otherwise.
pub(super) fn deterministic_moves(problem: &LpProblem<'_>) -> Option<Vec<u32>> {
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
pub(super) fn solve_deterministic(
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
    let (value, policy, order) = dijkstra(
        problem.target,
        u8::MAX,
        |settled| {
            if settled % STATES_PER_DEADLINE_CHECK == 0 {
                deadline.check("the LP solve (Dijkstra)")?;
            }
            Ok(())
        },
        |j| {
            from[ptr[j] as usize..ptr[j + 1] as usize]
                .iter()
                .map(|&(i, k)| {
                    let i = i as usize;
                    (i, problem.cost[i] * step_cost[k as usize], k)
                })
        },
    )?;
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

pub(super) fn check_reachable(problem: &LpProblem<'_>, value: &[f64]) -> Result<(), PlanError> {
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
