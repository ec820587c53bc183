//! Criterion benchmarks of the P-F pipeline on the `c_shape` scenario, generator build and LP
//! solve measured separately:
//! - indicator basis, 8 directions, grids 32², 64², 128² (target: 128² LP ≤ 5 s);
//! - Gaussian RBFs (σ = 0.5 h, 16 samples per function), 8 directions, 16², 24², 32² centres
//!   (target: 32² generator + LP ≤ 2 s).
//!
//! Run briefly: `cargo bench -p pf-planner --bench pf -- --warm-up-time 1 --measurement-time 3`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use pf_planner::basis::BasisKind;
use pf_planner::grid::PlanningGrid;
use pf_planner::lp::{self, LpSettings};
use pf_planner::pf::{prepare, PfGenerators, StartDensity};
use pf_planner::scenarios;

const U_MAX: f64 = 1.0;

fn bench_basis(c: &mut Criterion, label: &str, basis: BasisKind, sizes: &[usize]) {
    let scenario = scenarios::by_name("c_shape").expect("built-in scenario");
    let mut group = c.benchmark_group(label);
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    for &size in sizes {
        let grid =
            PlanningGrid::from_map(&scenario.map, &scenario.traversability, size).expect("grid");
        group.bench_with_input(BenchmarkId::new("generators", size), &grid, |b, grid| {
            b.iter(|| PfGenerators::build(black_box(grid), &basis, 8).expect("generators"))
        });
        let gens = PfGenerators::build(&grid, &basis, 8).expect("generators");
        let prepared = prepare(
            &gens,
            &grid,
            scenario.start,
            &scenario.goal,
            StartDensity::UniformFree,
        )
        .expect("prepared");
        let settings = LpSettings::default();
        let once = lp::solve(&prepared.problem(&gens, U_MAX), &settings).expect("lp");
        println!(
            "{label} {size}: {} functions, generator nnz {}, LP {} variables x {} constraints, {} iterations, status {}",
            gens.generators().basis.len(),
            gens.generators().stats.nnz,
            once.report.variables,
            once.report.constraints,
            once.report.iterations,
            once.report.status
        );
        group.bench_with_input(BenchmarkId::new("lp", size), &prepared, |b, prepared| {
            b.iter(|| lp::solve(black_box(&prepared.problem(&gens, U_MAX)), &settings).expect("lp"))
        });
    }
    group.finish();
}

fn indicator(c: &mut Criterion) {
    bench_basis(c, "pf_indicator_8dir", BasisKind::Indicator, &[32, 64, 128]);
}

fn rbf(c: &mut Criterion) {
    bench_basis(c, "pf_rbf_8dir", BasisKind::DEFAULT_RBF, &[16, 24, 32]);
}

criterion_group!(benches, indicator, rbf);
criterion_main!(benches);
