//! The paper's ANSDMD generators on its three scenarios (32² RBF centres, 8 directions): the
//! generators are not Markov (negative transition mass, raw rows that do not conserve mass), so
//! the LP is solved by Clarabel even when the exact solver is asked for; the trajectory reaches
//! the goal without entering an obstacle, and its ∫p ds is within 10 % of the indicator optimum
//! (P-F indicator 64², which equals Dijkstra's) on `c_shape` and `mountain_pass`. On `pits` it is
//! not, and the test pins the measured reason: the RBF basis leaves out every centre next to an
//! obstacle, which closes the gaps between pits at 32², and ANSDMD is within 10 % of the optimum
//! on that domain (Dijkstra on the 32² grid with every blocked cell grown by one cell).

use pf_planner::basis::BasisKind;
use pf_planner::graph::{dijkstra_path, Connectivity};
use pf_planner::grid::PlanningGrid;
use pf_planner::io::MapScenario;
use pf_planner::lp::SolverUsed;
use pf_planner::metrics::evaluate_path;
use pf_planner::pf::{self, PfGenerators, PfOptions};
use pf_planner::scenarios;
use pf_planner::ssp::{structure, Structure};
use pf_planner::traversability::TraversabilityField;

const RBF_GRID: usize = 32;
const INDICATOR_GRID: usize = 64;

/// ∫p ds on the map of the P-F trajectory with `basis` on a `size`² grid, checked to reach the
/// goal without entering an obstacle; the solver that ran is returned too.
fn pf_cost(scenario: &MapScenario, basis: BasisKind, size: usize) -> (f64, SolverUsed) {
    let grid = PlanningGrid::from_map(&scenario.map, &scenario.traversability, size).expect("grid");
    let gens = PfGenerators::build(&grid, &basis, 8).expect("generators");
    let options = PfOptions::default();
    let prepared = pf::prepare(
        &gens,
        &grid,
        scenario.start,
        &scenario.goal,
        options.start_density,
    )
    .expect("prepare");
    if matches!(
        basis,
        BasisKind::Rbf {
            generators: pf_planner::basis::RbfGenerators::Ansdmd,
            ..
        }
    ) {
        let stats = &gens.generators().stats;
        assert!(
            stats.negative_entries > 0 && stats.max_row_sum_error > 1e-3,
            "{}: {stats:?}",
            scenario.name
        );
        assert!(
            matches!(
                structure(&prepared.problem(&gens, options.u_max)),
                Structure::General { .. }
            ),
            "{}: ANSDMD generators read as Markov",
            scenario.name
        );
    }
    let solution =
        pf::solve(&gens, &grid, scenario.start, &scenario.goal, &options).expect("P-F solve");
    assert!(
        solution.outcome.reached_goal(),
        "{}: {:?}",
        scenario.name,
        solution.outcome
    );
    let field =
        TraversabilityField::from_map(&scenario.map, &scenario.traversability).expect("field");
    let metrics = evaluate_path(&scenario.map, &field, &solution.path);
    assert_eq!(metrics.length_in_obstacles, 0.0, "{}", scenario.name);
    (metrics.cost_integral, solution.lp.solver)
}

fn check(name: &str) -> (f64, f64) {
    let scenario = scenarios::by_name(name).expect("scenario");
    let (ansdmd, solver) = pf_cost(&scenario, BasisKind::ANSDMD_RBF, RBF_GRID);
    assert_eq!(solver, SolverUsed::Clarabel, "{name}");
    let (optimum, _) = pf_cost(&scenario, BasisKind::Indicator, INDICATOR_GRID);
    println!("{name}: ANSDMD ∫p ds {ansdmd:.4}, indicator optimum {optimum:.4}");
    (ansdmd, optimum)
}

#[test]
fn c_shape_ansdmd_is_within_ten_percent_of_the_indicator_optimum() {
    let (ansdmd, optimum) = check("c_shape");
    assert!(ansdmd <= 1.1 * optimum, "{ansdmd} vs {optimum}");
}

#[test]
fn mountain_pass_ansdmd_is_within_ten_percent_of_the_indicator_optimum() {
    let (ansdmd, optimum) = check("mountain_pass");
    assert!(ansdmd <= 1.1 * optimum, "{ansdmd} vs {optimum}");
}

#[test]
fn pits_ansdmd_is_within_ten_percent_of_the_optimum_on_the_rbf_domain() {
    let (ansdmd, optimum) = check("pits");
    let scenario = scenarios::by_name("pits").expect("scenario");
    let grid =
        PlanningGrid::from_map(&scenario.map, &scenario.traversability, RBF_GRID).expect("grid");
    // The RBF domain: a centre is active only when its cell and its 8 neighbours are free.
    let mut grown = grid.blocked.clone();
    for iy in 0..grid.height {
        for ix in 0..grid.width {
            if grid.blocked[grid.index(ix, iy)] {
                for y in iy.saturating_sub(1)..=(iy + 1).min(grid.height - 1) {
                    for x in ix.saturating_sub(1)..=(ix + 1).min(grid.width - 1) {
                        grown[grid.index(x, y)] = true;
                    }
                }
            }
        }
    }
    let domain = PlanningGrid::from_parts(
        grid.origin,
        grid.cell_size,
        grid.width,
        grid.height,
        grid.cost.clone(),
        grown,
    )
    .expect("domain grid");
    let path = dijkstra_path(&domain, scenario.start, &scenario.goal, Connectivity::Eight)
        .expect("a path on the RBF domain");
    let field =
        TraversabilityField::from_map(&scenario.map, &scenario.traversability).expect("field");
    let on_domain = evaluate_path(&scenario.map, &field, &path.points).cost_integral;
    println!("pits: Dijkstra on the RBF domain {on_domain:.4}");
    // The detour is the domain's, not ANSDMD's: the gaps between pits are closed at 32².
    assert!(on_domain > 1.1 * optimum, "{on_domain} vs {optimum}");
    assert!(ansdmd <= 1.1 * on_domain, "{ansdmd} vs {on_domain}");
}
