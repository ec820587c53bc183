//! The SSP form of the LP read back from the generators: states, actions, transition
//! probabilities and costs, and whether the generators are Markov at all.

use crate::generators::SparseColumns;
use crate::lp_problem::LpProblem;

use super::*;

/// The SSP form of one LP: states are active functions, actions the non-wall fluxes.
pub(super) struct Model {
    /// Actions of state i: `action_ptr[i]..action_ptr[i + 1]`.
    pub(super) action_ptr: Vec<usize>,
    /// Direction of each action.
    pub(super) action_dir: Vec<usize>,
    /// Cost c·Bᵢ·Δtₖ of each action.
    pub(super) action_cost: Vec<f64>,
    /// Transitions of action a: `trans_ptr[a]..trans_ptr[a + 1]` into `trans_to`/`trans_prob`
    /// (self-loops included, targets included).
    pub(super) trans_ptr: Vec<usize>,
    pub(super) trans_to: Vec<usize>,
    pub(super) trans_prob: Vec<f64>,
    pub(super) structure: Structure,
}

impl Model {
    pub(super) fn build(problem: &LpProblem<'_>) -> Model {
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
                            sum += model.add_transition(k, i, j, step * value);
                        }
                    }
                    if !any {
                        // A wall: the flux moves nothing and only costs, so it is no action.
                        continue;
                    }
                    sum += model.add_transition(k, i, i, stay);
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

    /// Records the transition mass `prob` of (direction `k`, function `i`) to `j` (`j == i`:
    /// staying) and returns what it adds to the row sum: negative mass makes the generators
    /// general (not Markov); mass within the threshold of zero is no transition.
    pub(super) fn add_transition(&mut self, k: usize, i: usize, j: usize, prob: f64) -> f64 {
        if prob < -TRANSITION_EPS {
            self.mark_general(format!(
                "direction {k}, function {i}: negative transition mass {prob:.3e} to {j}"
            ));
        }
        if prob > TRANSITION_EPS {
            self.trans_to.push(j);
            self.trans_prob.push(prob);
            prob
        } else {
            0.0
        }
    }

    pub(super) fn mark_general(&mut self, reason: String) {
        if !matches!(self.structure, Structure::General { .. }) {
            self.structure = Structure::General { reason };
        }
    }

    pub(super) fn actions(&self, i: usize) -> std::ops::Range<usize> {
        self.action_ptr[i]..self.action_ptr[i + 1]
    }

    pub(super) fn transitions(&self, a: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let range = self.trans_ptr[a]..self.trans_ptr[a + 1];
        self.trans_to[range.clone()]
            .iter()
            .copied()
            .zip(self.trans_prob[range].iter().copied())
    }

    /// Reversed moves as CSR over the destination: `(source state, action)` per entry.
    /// With `most_likely_only`, each action contributes its most likely transition only.
    pub(super) fn reversed(
        &self,
        n: usize,
        most_likely_only: bool,
    ) -> (Vec<usize>, Vec<(usize, usize)>) {
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
    pub(super) fn for_each_move(
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
