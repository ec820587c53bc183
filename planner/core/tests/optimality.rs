//! The planner's strongest check: with the indicator basis and one-cell shifts the P-F LP is a
//! shortest-path problem, so LP optimum / (1 + 1/u_max) = Σ start mass × Dijkstra distance to the
//! goal on the 4- or 8-connected grid graph with edge weight p(source cell) × step. Equality to
//! 1e-6 (relative) proves the convex program was solved to global optimality.

use pf_planner::basis::BasisKind;
use pf_planner::graph::{distances_to_targets, Connectivity};
use pf_planner::grid::{GoalRegion, PlanningGrid};
use pf_planner::lp::{LpForm, LpSettings};
use pf_planner::pf::{self, PfGenerators, PfOptions, PfSolution, StartDensity};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const TOLERANCE: f64 = 1e-6;

/// Σᵢ tᵢ ∫φᵢ × dist(cell of i): the graph value the LP must reproduce.
fn graph_value(
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
fn random_grid(rng: &mut ChaCha8Rng) -> PlanningGrid {
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
fn random_free_point(rng: &mut ChaCha8Rng, grid: &PlanningGrid) -> [f64; 2] {
    loop {
        let c = rng.random_range(0..grid.len());
        if !grid.blocked[c] {
            return grid.center_of_index(c);
        }
    }
}

struct Case {
    relative_error: f64,
    lp_value: f64,
    graph_value: f64,
}

fn check(
    grid: &PlanningGrid,
    start: [f64; 2],
    goal: &GoalRegion,
    directions: usize,
    density: StartDensity,
    u_max: f64,
) -> Option<Case> {
    check_form(
        grid,
        start,
        goal,
        directions,
        density,
        u_max,
        LpForm::default(),
    )
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
    let gens = PfGenerators::build(grid, &BasisKind::Indicator, directions).expect("generators");
    let opts = PfOptions {
        u_max,
        start_density: density,
        lp: LpSettings {
            form,
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
        Err(e) => panic!("P-F failed: {e}"),
    };
    assert_eq!(sol.lp.status, "Solved", "{:?}", sol.lp);
    assert!(sol.lp.mass_balance_residual < 1e-7, "{:?}", sol.lp);
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
    // The benchmark's largest case (128² cells, 8 directions, uniform start density): the
    // reduced dual LP must still reproduce the graph value.
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
