//! The P-F planner on the paper's three scenarios, with both bases: the feedback-law trajectory
//! reaches the goal and never enters an obstacle (RBF on `pits`: see the known-limitation test); on `c_shape` its ∫p ds beats the paper's A*
//! baseline (Euclidean heuristic, inadmissible for p < 1) by at least 20 % and is within 5 % of
//! the optimal graph path (Dijkstra).

use pf_planner::basis::BasisKind;
use pf_planner::graph::{astar_path, dijkstra_path, Connectivity};
use pf_planner::grid::PlanningGrid;
use pf_planner::io::MapScenario;
use pf_planner::map::Point;
use pf_planner::metrics::{evaluate_path, PathMetrics};
use pf_planner::pf::{self, PfGenerators, PfOptions, PfSolution};
use pf_planner::scenarios;
use pf_planner::traversability::TraversabilityField;

/// Planning cells along the longer side: moderate sizes keep the suite fast.
const INDICATOR_GRID: usize = 64;
const RBF_GRID: usize = 32;

struct Run {
    solution: PfSolution,
    metrics: PathMetrics,
    grid: PlanningGrid,
}

fn run(scenario: &MapScenario, basis: BasisKind, grid_size: usize) -> Run {
    let grid =
        PlanningGrid::from_map(&scenario.map, &scenario.traversability, grid_size).expect("grid");
    let gens = PfGenerators::build(&grid, &basis, 8).expect("generators");
    let solution = pf::solve(
        &gens,
        &grid,
        scenario.start,
        &scenario.goal,
        &PfOptions::default(),
    )
    .expect("P-F solve");
    let field =
        TraversabilityField::from_map(&scenario.map, &scenario.traversability).expect("field");
    let metrics = evaluate_path(&scenario.map, &field, &solution.path);
    Run {
        solution,
        metrics,
        grid,
    }
}

fn assert_reaches_goal_without_obstacles(
    name: &str,
    basis: &str,
    scenario: &MapScenario,
    run: &Run,
) {
    let sol = &run.solution;
    assert!(
        sol.outcome.reached_goal(),
        "{name}/{basis}: {:?} after {} points (LP {:?})",
        sol.outcome,
        sol.path.len(),
        sol.lp
    );
    let end = *sol.path.last().expect("non-empty path");
    // The integration stops in a goal cell; the final straight move enters the disc when it is free.
    let slack = run.grid.cell_size * std::f64::consts::SQRT_2;
    let to_goal = (end[0] - scenario.goal.center[0]).hypot(end[1] - scenario.goal.center[1]);
    assert!(
        to_goal <= scenario.goal.radius + slack,
        "{name}/{basis}: ends {to_goal} m from the goal centre"
    );
    assert_eq!(
        run.metrics.length_in_obstacles, 0.0,
        "{name}/{basis}: path enters an obstacle"
    );
    for p in &sol.path {
        assert!(
            !scenario.map.is_obstacle_at(*p),
            "{name}/{basis}: point {p:?} inside an obstacle"
        );
        assert!(
            scenario.map.contains(*p),
            "{name}/{basis}: point {p:?} off the map"
        );
    }
    println!(
        "{name}/{basis}: ∫p ds = {:.4}, length {:.2} m, clearance {:.3} m, LP {} in {:.3} s ({} vars), generators {:.3} s",
        run.metrics.cost_integral,
        run.metrics.length,
        run.metrics.min_clearance,
        sol.lp.status,
        sol.lp.solve_time_s,
        sol.lp.variables,
        sol.lp.generator_time_s
    );
}

#[test]
fn every_scenario_is_solved_with_the_indicator_basis() {
    for name in scenarios::SCENARIO_NAMES {
        let scenario = scenarios::by_name(name).expect("scenario");
        let run = run(&scenario, BasisKind::Indicator, INDICATOR_GRID);
        assert_reaches_goal_without_obstacles(name, "indicator", &scenario, &run);
    }
}

#[test]
fn open_scenarios_are_solved_with_the_rbf_basis() {
    for name in ["mountain_pass", "c_shape"] {
        let scenario = scenarios::by_name(name).expect("scenario");
        let run = run(&scenario, BasisKind::DEFAULT_RBF, RBF_GRID);
        assert_reaches_goal_without_obstacles(name, "rbf", &scenario, &run);
    }
}

/// Known limitation: on `pits` the RBF field (32² centres, centres within one spacing of a pit
/// dropped) stalls next to a pit. The trajectory must still never enter an obstacle, and the
/// failure must be reported as an outcome, not hidden.
#[test]
fn pits_with_the_rbf_basis_never_enters_a_pit() {
    let scenario = scenarios::by_name("pits").expect("scenario");
    let run = run(&scenario, BasisKind::DEFAULT_RBF, RBF_GRID);
    assert_eq!(run.metrics.length_in_obstacles, 0.0, "path enters a pit");
    for p in &run.solution.path {
        assert!(!scenario.map.is_obstacle_at(*p), "point {p:?} inside a pit");
    }
    println!(
        "pits/rbf: outcome {:?}, {} points",
        run.solution.outcome,
        run.solution.path.len()
    );
}

fn cost_of(scenario: &MapScenario, points: &[Point]) -> f64 {
    let field =
        TraversabilityField::from_map(&scenario.map, &scenario.traversability).expect("field");
    evaluate_path(&scenario.map, &field, points).cost_integral
}

#[test]
fn c_shape_pf_beats_astar_and_matches_dijkstra() {
    let scenario = scenarios::by_name("c_shape").expect("scenario");
    let run = run(&scenario, BasisKind::Indicator, INDICATOR_GRID);
    assert!(
        run.solution.outcome.reached_goal(),
        "{:?}",
        run.solution.outcome
    );
    let pf_cost = run.metrics.cost_integral;
    let astar = astar_path(
        &run.grid,
        scenario.start,
        &scenario.goal,
        Connectivity::Eight,
    )
    .expect("A*");
    let dijkstra = dijkstra_path(
        &run.grid,
        scenario.start,
        &scenario.goal,
        Connectivity::Eight,
    )
    .expect("Dijkstra");
    let astar_cost = cost_of(&scenario, &astar.points);
    let dijkstra_cost = cost_of(&scenario, &dijkstra.points);
    println!(
        "c_shape ∫p ds: P-F {pf_cost:.4}, A* {astar_cost:.4}, Dijkstra {dijkstra_cost:.4}; P-F/A* = {:.3}, P-F/Dijkstra = {:.3}",
        pf_cost / astar_cost,
        pf_cost / dijkstra_cost
    );
    assert!(
        pf_cost <= 0.80 * astar_cost,
        "P-F {pf_cost} vs A* {astar_cost}"
    );
    assert!(
        (pf_cost - dijkstra_cost).abs() <= 0.05 * dijkstra_cost,
        "P-F {pf_cost} vs Dijkstra {dijkstra_cost}"
    );
}
