//! Shared helpers of the planner's integration tests: seeded random terrains and the graph value
//! an optimal P-F solution must reproduce.
#![allow(dead_code)]

use pf_planner::graph::{distances_to_targets, Connectivity};
use pf_planner::grid::PlanningGrid;
use pf_planner::lp::{LpSettings, LpSolver};
use pf_planner::pf::{PfGenerators, PfSolution};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Σᵢ tᵢ ∫φᵢ × dist(cell of i): the graph value the LP must reproduce.
pub fn graph_value(
    gens: &PfGenerators,
    grid: &PlanningGrid,
    sol: &PfSolution,
    directions: usize,
) -> f64 {
    let basis = &gens.generators().basis;
    let targets: Vec<usize> = (0..basis.len())
        .filter(|&i| sol.targets[i])
        .map(|i| basis.cell(i))
        .collect();
    let conn = Connectivity::from_directions(directions).expect("4 or 8");
    let dist = distances_to_targets(grid, &targets, conn);
    let mut value = 0.0;
    for (i, &t) in sol.start_coefficients.iter().enumerate() {
        if t > 0.0 {
            let d = dist[basis.cell(i)];
            assert!(d.is_finite(), "start mass on a cell the graph cannot route");
            value += t * gens.mass_integrals()[i] * d;
        }
    }
    value
}

/// Random terrain: p in [0.05, 1] with some smooth structure, ~12 % blocked cells.
pub fn random_grid(rng: &mut ChaCha8Rng) -> PlanningGrid {
    let width = rng.random_range(12..=20);
    let height = rng.random_range(12..=20);
    let cell_size = rng.random_range(0.1..0.6);
    let (fx, fy, phase) = (
        rng.random_range(0.1..0.8),
        rng.random_range(0.1..0.8),
        rng.random_range(0.0..6.0),
    );
    let mut cost = Vec::with_capacity(width * height);
    let mut blocked = Vec::with_capacity(width * height);
    for iy in 0..height {
        for ix in 0..width {
            let smooth = 0.5 + 0.4 * (fx * ix as f64 + phase).sin() * (fy * iy as f64).cos();
            let noise: f64 = rng.random_range(-0.1..0.1);
            cost.push((smooth + noise).clamp(0.05, 1.0));
            blocked.push(rng.random_bool(0.12));
        }
    }
    PlanningGrid::from_parts([-1.0, 2.0], cell_size, width, height, cost, blocked)
        .expect("valid random grid")
}

/// A free cell centre (and its index), drawn at random.
pub fn random_free_point(rng: &mut ChaCha8Rng, grid: &PlanningGrid) -> [f64; 2] {
    loop {
        let c = rng.random_range(0..grid.len());
        if !grid.blocked[c] {
            return grid.center_of_index(c);
        }
    }
}

/// The default LP settings with the given solver.
pub fn settings(solver: LpSolver) -> LpSettings {
    LpSettings {
        solver,
        ..LpSettings::default()
    }
}
