//! The generator build of the RBF basis at 32² centres, 8 directions: the paper's ANSDMD (least
//! squares `G U = A` with row normalisation, [`pf_planner::generators::ansdmd`]) beside the
//! Shepard transfer ([`pf_planner::generators::rbf`]) for the same basis, in one run. Target:
//! ANSDMD ≤ 1 s.
//!
//! `cargo bench -p pf-planner --bench ansdmd` (about a minute). Criterion drives the
//! measurements; a summary table with the medians and the spread of the samples is printed at the
//! end. `PF_BENCH_SCENARIOS=c_shape,pits` chooses the scenarios (default: c_shape and pits; the
//! mountain pass has the same geometry as c_shape: no hard obstacles).

use std::cell::RefCell;
use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::Criterion;
use pf_planner::basis::BasisKind;
use pf_planner::generators::Generators;
use pf_planner::grid::PlanningGrid;
use pf_planner::scenarios;

/// RBF centres along the map's longer side.
const CENTRES: usize = 32;
/// Move directions (the planner's default).
const DIRECTIONS: usize = 8;

/// Per-iteration times of the samples of the last measurement, seconds.
struct Recorder(RefCell<Vec<f64>>);

impl Recorder {
    /// Benchmarks `routine` under `name`; returns (minimum, median, maximum) of the samples.
    fn measure(&self, c: &mut Criterion, name: &str, mut routine: impl FnMut()) -> [f64; 3] {
        self.0.borrow_mut().clear();
        c.bench_function(name, |b| {
            b.iter_custom(|iters| {
                let started = Instant::now();
                for _ in 0..iters {
                    routine();
                }
                let elapsed = started.elapsed();
                self.0
                    .borrow_mut()
                    .push(elapsed.as_secs_f64() / iters as f64);
                elapsed
            })
        });
        let mut times = self.0.borrow().clone();
        times.sort_by(f64::total_cmp);
        match (times.first(), times.get(times.len() / 2), times.last()) {
            (Some(&lo), Some(&mid), Some(&hi)) => [lo, mid, hi],
            _ => [f64::NAN; 3],
        }
    }
}

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
    let rec = Recorder(RefCell::new(Vec::new()));
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
