//! Dijkstra on the value function over the reversed moves: exact for deterministic moves, and
//! the warm start of policy iteration.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use super::*;

#[derive(Copy, Clone, PartialEq)]
pub(super) struct HeapEntry {
    pub(super) key: f64,
    pub(super) state: usize,
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
pub(super) fn dijkstra(
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
