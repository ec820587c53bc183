//! Dijkstra on the value function over the reversed moves: exact for deterministic moves, and
//! the warm start of policy iteration.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use super::*;

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

/// Values, the minimising action of each state and the settling order (increasing value).
pub(super) type ShortestPaths<A> = (Vec<f64>, Vec<A>, Vec<usize>);

/// Dijkstra on the value function from the target states: `into(j)` lists the moves
/// `(source i, cost, action)` that end in state j; targets are never relaxed. `before_settling`
/// runs with the number of states settled so far (the deadline check). Returns the values, the
/// minimising action of each state (`no_action` where none) and the settling order.
pub(super) fn dijkstra<A, I>(
    target: &[bool],
    no_action: A,
    mut before_settling: impl FnMut(usize) -> Result<(), PlanError>,
    into: impl Fn(usize) -> I,
) -> Result<ShortestPaths<A>, PlanError>
where
    A: Copy,
    I: Iterator<Item = (usize, f64, A)>,
{
    let n = target.len();
    let mut value = vec![f64::INFINITY; n];
    let mut policy = vec![no_action; n];
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
        before_settling(order.len())?;
        order.push(j);
        for (i, cost, action) in into(j) {
            if target[i] {
                continue;
            }
            let candidate = key + cost;
            if candidate < value[i] {
                value[i] = candidate;
                policy[i] = action;
                heap.push(HeapEntry {
                    key: candidate,
                    state: i,
                });
            }
        }
    }
    Ok((value, policy, order))
}
