//! The planner's strongest check: with the indicator basis and one-cell shifts the P-F LP is a
//! shortest-path problem, so LP optimum / (1 + 1/u_max) = Σ start mass × Dijkstra distance to the
//! goal on the 4- or 8-connected grid graph with edge weight p(source cell) × step. Equality to
//! 1e-6 (relative) proves the convex program was solved to global optimality. Every case runs
//! both the exact SSP solver (the default) and Clarabel, and both must carry a duality
//! certificate that holds.

use crate::support;

use pf_planner::basis::BasisKind;
use pf_planner::graph::{distances_to_targets, Connectivity};
use pf_planner::grid::{GoalRegion, PlanningGrid};
use pf_planner::lp::{LpForm, LpSettings, LpSolver, LpStatus};
use pf_planner::pf::{self, PfGenerators, PfOptions, StartDensity};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use support::{graph_value, random_free_point, random_grid};

const TOLERANCE: f64 = 1e-6;

struct Case {
    relative_error: f64,
    lp_value: f64,
    graph_value: f64,
}

/// Runs the exact solver and Clarabel (dual form); both must match the graph. Returns the
/// exact solver's case.
fn check(
    grid: &PlanningGrid,
    start: [f64; 2],
    goal: &GoalRegion,
    directions: usize,
    density: StartDensity,
    u_max: f64,
) -> Option<Case> {
    let clarabel = check_with(
        grid,
        start,
        goal,
        directions,
        density,
        u_max,
        LpSolver::Clarabel,
        LpForm::default(),
    );
    let exact = check_with(
        grid,
        start,
        goal,
        directions,
        density,
        u_max,
        LpSolver::Exact,
        LpForm::default(),
    );
    assert_eq!(clarabel.is_some(), exact.is_some());
    if let (Some(c), Some(e)) = (&clarabel, &exact) {
        assert!(
            c.relative_error < TOLERANCE,
            "Clarabel: {} vs Dijkstra {} (rel {:.2e})",
            c.lp_value,
            c.graph_value,
            c.relative_error
        );
        assert!(
            (c.lp_value - e.lp_value).abs() <= TOLERANCE * e.lp_value.abs().max(1e-12),
            "Clarabel {} vs exact {}",
            c.lp_value,
            e.lp_value
        );
    }
    exact
}

fn check_form(
    grid: &PlanningGrid,
    start: [f64; 2],
    goal: &GoalRegion,
    directions: usize,
    density: StartDensity,
    u_max: f64,
    form: LpForm,
) -> Option<Case> {
    check_with(
        grid,
        start,
        goal,
        directions,
        density,
        u_max,
        LpSolver::Clarabel,
        form,
    )
}

#[allow(clippy::too_many_arguments)]
fn check_with(
    grid: &PlanningGrid,
    start: [f64; 2],
    goal: &GoalRegion,
    directions: usize,
    density: StartDensity,
    u_max: f64,
    solver: LpSolver,
    form: LpForm,
) -> Option<Case> {
    let gens = PfGenerators::build(grid, &BasisKind::Indicator, directions).expect("generators");
    let opts = PfOptions {
        u_max,
        start_density: density,
        lp: LpSettings {
            form,
            solver,
            ..LpSettings::default()
        },
        ..PfOptions::default()
    };
    let sol = match pf::solve(&gens, grid, start, goal, &opts) {
        Ok(sol) => sol,
        // A random start walled off from the goal: the graph must agree it is unreachable.
        Err(pf_planner::error::PlanError::Unreachable { .. }) => {
            let conn = Connectivity::from_directions(directions).expect("4 or 8");
            let dist = distances_to_targets(grid, &grid.goal_cells(goal), conn);
            let (sx, sy) = grid.cell_of(start).expect("on grid");
            assert!(
                dist[grid.index(sx, sy)].is_infinite(),
                "P-F called a reachable start unreachable"
            );
            return None;
        }
        Err(e) => panic!("P-F ({solver}) failed: {e}"),
    };
    assert_eq!(sol.lp.status, LpStatus::Solved, "{solver}: {:?}", sol.lp);
    assert!(
        sol.lp.mass_balance_residual < 1e-7,
        "{solver}: {:?}",
        sol.lp
    );
    assert!(
        sol.lp.certificate.holds(),
        "{solver}: certificate {:?}",
        sol.lp.certificate
    );
    let reference = graph_value(&gens, grid, &sol, directions);
    Some(Case {
        relative_error: (sol.weighted_length - reference).abs() / reference,
        lp_value: sol.weighted_length,
        graph_value: reference,
    })
}

#[test]
fn lp_equals_dijkstra_on_random_terrains_for_4_and_8_directions() {
    let mut rng = ChaCha8Rng::seed_from_u64(20261123);
    let mut worst: f64 = 0.0;
    let mut checked = 0;
    for terrain in 0..24 {
        let grid = random_grid(&mut rng);
        let start = random_free_point(&mut rng, &grid);
        let goal = GoalRegion {
            center: random_free_point(&mut rng, &grid),
            radius: grid.cell_size * rng.random_range(0.0..2.0),
        };
        let u_max = rng.random_range(0.3..2.0);
        for directions in [4, 8] {
            // Alternate the start density so both the single tube and the all-cells flow are checked.
            let density = if terrain % 2 == 0 {
                StartDensity::PointMass
            } else {
                StartDensity::UniformFree
            };
            let Some(case) = check(&grid, start, &goal, directions, density, u_max) else {
                continue;
            };
            assert!(
                case.relative_error < TOLERANCE,
                "terrain {terrain}, {directions} directions, {density:?}: LP {} vs Dijkstra {} (rel {:.2e})",
                case.lp_value,
                case.graph_value,
                case.relative_error
            );
            worst = worst.max(case.relative_error);
            checked += 1;
        }
    }
    assert!(checked >= 40, "only {checked} reachable cases");
    println!("random terrains: {checked} LPs, worst relative error {worst:.3e}");
}

#[test]
fn an_obstacle_that_forces_a_detour_changes_both_values_identically() {
    // A wall with one gap: the 4- and 8-connected optima must both go through the gap.
    let (w, h) = (9, 9);
    let mut blocked = vec![false; w * h];
    for iy in 0..h - 2 {
        blocked[iy * w + 4] = true;
    }
    let grid =
        PlanningGrid::from_parts([0.0, 0.0], 1.0, w, h, vec![0.5; w * h], blocked).expect("grid");
    let goal = GoalRegion {
        center: grid.cell_center(8, 0),
        radius: 0.0,
    };
    for directions in [4, 8] {
        let case = check(
            &grid,
            grid.cell_center(0, 0),
            &goal,
            directions,
            StartDensity::PointMass,
            1.0,
        )
        .expect("reachable");
        assert!(
            case.relative_error < TOLERANCE,
            "{directions}: {} vs {}",
            case.lp_value,
            case.graph_value
        );
        // The straight line is 8 cells at p = 0.5; the gap at the top makes it much longer.
        assert!(
            case.graph_value > 0.5 * 14.0,
            "detour expected, got {}",
            case.graph_value
        );
    }
}

#[test]
fn lp_equals_dijkstra_on_the_three_scenarios() {
    for name in pf_planner::scenarios::SCENARIO_NAMES {
        let scenario = pf_planner::scenarios::by_name(name).expect("scenario");
        let grid =
            PlanningGrid::from_map(&scenario.map, &scenario.traversability, 32).expect("grid");
        for directions in [4, 8] {
            for density in [StartDensity::PointMass, StartDensity::UniformFree] {
                let case = check(
                    &grid,
                    scenario.start,
                    &scenario.goal,
                    directions,
                    density,
                    1.0,
                )
                .expect("reachable");
                println!(
                    "{name}, {directions} directions, {density:?}: LP {:.9} vs Dijkstra {:.9} (rel {:.2e})",
                    case.lp_value, case.graph_value, case.relative_error
                );
                assert!(
                    case.relative_error < TOLERANCE,
                    "{name}/{directions}/{density:?}: rel {:.2e}",
                    case.relative_error
                );
            }
        }
    }
}

#[test]
fn primal_and_dual_forms_reach_the_same_optimum() {
    // The default solves the dual of the reduced LP; the reduced primal must give the same value.
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut checked = 0;
    for _ in 0..8 {
        let grid = random_grid(&mut rng);
        let start = random_free_point(&mut rng, &grid);
        let goal = GoalRegion {
            center: random_free_point(&mut rng, &grid),
            radius: grid.cell_size,
        };
        for directions in [4, 8] {
            let mut values = Vec::new();
            for form in [LpForm::Primal, LpForm::Dual] {
                let Some(case) = check_form(
                    &grid,
                    start,
                    &goal,
                    directions,
                    StartDensity::UniformFree,
                    0.8,
                    form,
                ) else {
                    continue;
                };
                assert!(
                    case.relative_error < TOLERANCE,
                    "{form:?}, {directions} directions: LP {} vs Dijkstra {}",
                    case.lp_value,
                    case.graph_value
                );
                values.push(case.lp_value);
            }
            if let [primal, dual] = values[..] {
                assert!(
                    (primal - dual).abs() <= TOLERANCE * dual,
                    "{primal} vs {dual}"
                );
                checked += 1;
            }
        }
    }
    assert!(checked >= 8, "only {checked} reachable cases");
}

#[test]
fn lp_equals_dijkstra_on_the_full_resolution_c_shape() {
    // The benchmark's largest Clarabel case (128² cells, 8 directions, uniform start density):
    // the reduced dual LP and the exact solver must still reproduce the graph value.
    let scenario = pf_planner::scenarios::by_name("c_shape").expect("scenario");
    let grid = PlanningGrid::from_map(&scenario.map, &scenario.traversability, 128).expect("grid");
    let case = check(
        &grid,
        scenario.start,
        &scenario.goal,
        8,
        StartDensity::UniformFree,
        1.0,
    )
    .expect("reachable");
    println!(
        "c_shape 128²: LP {:.9} vs Dijkstra {:.9} (rel {:.2e})",
        case.lp_value, case.graph_value, case.relative_error
    );
    assert!(
        case.relative_error < TOLERANCE,
        "rel {:.2e}",
        case.relative_error
    );
}
