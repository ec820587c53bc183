//! The generator build of the RBF basis at 32² centres, 8 directions: the paper's ANSDMD (least
//! squares `G U = A` with row normalisation, [`pf_planner::generators::ansdmd`]) beside the
//! Shepard transfer ([`pf_planner::generators::rbf`]) for the same basis, in one run. Target:
//! ANSDMD ≤ 1 s.
//!
//! `cargo bench -p pf-planner --bench ansdmd` (about a minute). Criterion drives the
//! measurements; a summary table with the medians and the spread of the samples is printed at the
//! end. `PF_BENCH_SCENARIOS=c_shape,pits` chooses the scenarios (default: c_shape and pits; the
//! mountain pass has the same geometry as c_shape: no hard obstacles).

use std::hint::black_box;
use std::time::Duration;

use criterion::Criterion;
use pf_planner::basis::BasisKind;
use pf_planner::generators::Generators;
use pf_planner::grid::PlanningGrid;
use pf_planner::scenarios;

mod support;
use support::Recorder;

/// RBF centres along the map's longer side.
const CENTRES: usize = 32;
/// Move directions (the planner's default).
const DIRECTIONS: usize = 8;

fn ms(t: f64) -> String {
    format!("{:.0}", t * 1e3)
}

fn main() {
    let mut c = Criterion::default()
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(4))
        .configure_from_args();
    let names = std::env::var("PF_BENCH_SCENARIOS").unwrap_or_else(|_| "c_shape,pits".into());
    let rec = Recorder::default();
    let mut rows = Vec::new();
    for name in names.split(',').map(str::trim).filter(|n| !n.is_empty()) {
        let scenario = scenarios::by_name(name).expect("built-in scenario");
        let grid = PlanningGrid::from_map(&scenario.map, &scenario.traversability, CENTRES)
            .expect("planning grid");
        let ansdmd = Generators::build(&grid, BasisKind::ANSDMD_RBF, DIRECTIONS).expect("ansdmd");
        let transfer =
            Generators::build(&grid, BasisKind::DEFAULT_RBF, DIRECTIONS).expect("transfer");
        let ansdmd_t = rec.measure(&mut c, &format!("{name} RBF {CENTRES}²: ansdmd"), || {
            black_box(Generators::build(&grid, BasisKind::ANSDMD_RBF, DIRECTIONS).expect("ansdmd"));
        });
        let transfer_t = rec.measure(&mut c, &format!("{name} RBF {CENTRES}²: transfer"), || {
            black_box(
                Generators::build(&grid, BasisKind::DEFAULT_RBF, DIRECTIONS).expect("transfer"),
            );
        });
        rows.push(format!(
            "| {name} | {} | {} ({}–{}) | {} ({}–{}) | {:.1}× | {} / {} | {} |",
            ansdmd.basis.len(),
            ms(ansdmd_t[1]),
            ms(ansdmd_t[0]),
            ms(ansdmd_t[2]),
            ms(transfer_t[1]),
            ms(transfer_t[0]),
            ms(transfer_t[2]),
            ansdmd_t[1] / transfer_t[1],
            ansdmd.stats.nnz,
            transfer.stats.nnz,
            if ansdmd_t[1] <= 1.0 { "yes" } else { "no" },
        ));
    }
    c.final_summary();

    println!();
    println!(
        "RBF {CENTRES}² centres, {DIRECTIONS} directions, σ = 0.5 h, 16 samples per function; \
         median (min–max) of criterion's samples, ms"
    );
    println!(
        "| scenario | functions | ANSDMD build | transfer build | ANSDMD / transfer | non-zeros ANSDMD / transfer | ANSDMD ≤ 1 s |"
    );
    println!("|---|---:|---:|---:|---:|---:|---|");
    for row in &rows {
        println!("{row}");
    }
}
