//! Dijkstra and A* (8-connected) on the c_shape scenario resampled to 32², 64² and 128² cells —
//! the same maps the P-F benchmarks use.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use pf_planner::graph::{astar_path, dijkstra_path, Connectivity};
use pf_planner::grid::PlanningGrid;
use pf_planner::scenarios::by_name;

fn graph_search(c: &mut Criterion) {
    let scenario = by_name("c_shape").expect("built-in scenario");
    let mut group = c.benchmark_group("graph_search_c_shape");
    for n in [32usize, 64, 128] {
        let grid =
            PlanningGrid::from_map(&scenario.map, &scenario.traversability, n).expect("grid");
        group.bench_with_input(BenchmarkId::new("dijkstra", n), &grid, |b, grid| {
            b.iter(|| {
                dijkstra_path(grid, scenario.start, &scenario.goal, Connectivity::Eight)
                    .expect("path")
            })
        });
        group.bench_with_input(BenchmarkId::new("astar", n), &grid, |b, grid| {
            b.iter(|| {
                astar_path(grid, scenario.start, &scenario.goal, Connectivity::Eight).expect("path")
            })
        });
    }
    group.finish();
}

criterion_group!(benches, graph_search);
criterion_main!(benches);
