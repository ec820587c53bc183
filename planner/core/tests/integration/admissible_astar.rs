//! A* with the admissible heuristic p_min × distance ([`astar_admissible_path`]) against Dijkstra:
//! the same optimal cost (1e-9 relative) with no more expanded nodes, on the three paper scenarios
//! and on seeded random maps with 4- and 8-connectivity; its heuristic is consistent edge by edge;
//! and the paper's Euclidean-heuristic A* is not optimal on the scenarios.

use pf_planner::graph::{
    astar_admissible_path, astar_path, dijkstra_path, neighbours, AdmissibleHeuristic,
    Connectivity, GraphPath,
};
use pf_planner::grid::{GoalRegion, PlanningGrid};
use pf_planner::plan::{Method, Planner, PlannerOptions};
use pf_planner::scenarios::{by_name, SCENARIO_NAMES};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const RELATIVE_TOLERANCE: f64 = 1e-9;
const CONNECTIVITIES: [Connectivity; 2] = [Connectivity::Four, Connectivity::Eight];

/// Random map: 20–48 cells a side, p in [0.05, 1] (smooth plus noise), 15 % blocked cells.
fn random_grid(rng: &mut ChaCha8Rng) -> PlanningGrid {
    let (width, height) = (rng.random_range(20..=48), rng.random_range(20..=48));
    let cell_size = rng.random_range(0.1..0.5);
    let (fx, fy) = (rng.random_range(0.05..0.5), rng.random_range(0.05..0.5));
    let mut cost = Vec::with_capacity(width * height);
    let mut blocked = Vec::with_capacity(width * height);
    for iy in 0..height {
        for ix in 0..width {
            let smooth = 0.5 + 0.45 * (fx * ix as f64).sin() * (fy * iy as f64).cos();
            cost.push((smooth + rng.random_range(-0.1..0.1)).clamp(0.05, 1.0));
            blocked.push(rng.random_bool(0.15));
        }
    }
    PlanningGrid::from_parts([-3.0, 1.0], cell_size, width, height, cost, blocked).expect("grid")
}

/// A point anywhere inside a random free cell (not only its centre).
fn random_free_point(rng: &mut ChaCha8Rng, grid: &PlanningGrid) -> [f64; 2] {
    loop {
        let cell = rng.random_range(0..grid.len());
        if !grid.blocked[cell] {
            let c = grid.center_of_index(cell);
            let half = 0.49 * grid.cell_size;
            return [
                c[0] + rng.random_range(-half..half),
                c[1] + rng.random_range(-half..half),
            ];
        }
    }
}

fn relative_error(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(f64::MIN_POSITIVE)
}

/// Asserts the admissible A* path has Dijkstra's cost and expands no more nodes.
fn assert_optimal(case: &str, admissible: &GraphPath, dijkstra: &GraphPath) {
    let error = relative_error(admissible.cost, dijkstra.cost);
    assert!(
        error <= RELATIVE_TOLERANCE,
        "{case}: admissible A* {} vs Dijkstra {} (rel {error:.2e})",
        admissible.cost,
        dijkstra.cost
    );
    assert!(
        admissible.expanded <= dijkstra.expanded,
        "{case}: admissible A* expanded {} nodes, Dijkstra {}",
        admissible.expanded,
        dijkstra.expanded
    );
}

/// h(u) ≤ p(u)·step(u, v) + h(v) on every edge and h = 0 on every goal cell.
fn assert_consistent(case: &str, grid: &PlanningGrid, goal: &GoalRegion, conn: Connectivity) {
    let targets = grid.goal_cells(goal);
    let h = AdmissibleHeuristic::from_targets(grid, goal.center, &targets);
    for &t in &targets {
        assert_eq!(
            h.at(grid.center_of_index(t)),
            0.0,
            "{case}: h > 0 on goal cell {t}"
        );
    }
    for u in (0..grid.len()).filter(|&u| !grid.blocked[u]) {
        let hu = h.at(grid.center_of_index(u));
        for (v, step) in neighbours(grid, u, conn) {
            let bound = grid.cost[u] * step + h.at(grid.center_of_index(v));
            assert!(
                hu <= bound + 1e-12 * bound.max(1.0),
                "{case}: h({u}) = {hu} > p·step + h({v}) = {bound}"
            );
        }
    }
}

#[test]
fn admissible_astar_equals_dijkstra_on_24_random_maps() {
    let mut reachable = 0;
    let mut fewer_expansions = 0;
    for seed in 0..24 {
        let mut rng = ChaCha8Rng::seed_from_u64(1000 + seed);
        let grid = random_grid(&mut rng);
        let start = random_free_point(&mut rng, &grid);
        // Goals from a single cell (radius 0) to a disc of three cells radius.
        let goal = GoalRegion {
            center: random_free_point(&mut rng, &grid),
            radius: rng.random_range(0.0..3.0) * grid.cell_size,
        };
        for conn in CONNECTIVITIES {
            let case = format!("seed {seed}, {}-connected", conn.directions());
            assert_consistent(&case, &grid, &goal, conn);
            match dijkstra_path(&grid, start, &goal, conn) {
                Ok(dijkstra) => {
                    let admissible = astar_admissible_path(&grid, start, &goal, conn)
                        .unwrap_or_else(|e| panic!("{case}: Dijkstra found a path, A* {e}"));
                    assert_optimal(&case, &admissible, &dijkstra);
                    reachable += 1;
                    fewer_expansions += usize::from(admissible.expanded < dijkstra.expanded);
                }
                Err(_) => assert!(
                    astar_admissible_path(&grid, start, &goal, conn).is_err(),
                    "{case}: A* found a path Dijkstra did not"
                ),
            }
        }
    }
    println!("{reachable} of 48 cases reachable; admissible A* expanded fewer nodes in {fewer_expansions}");
    // The comparison must have been made on most maps, and the heuristic must do some work.
    assert!(reachable >= 36, "only {reachable} of 48 cases reachable");
    assert!(
        fewer_expansions * 2 >= reachable,
        "fewer expansions in only {fewer_expansions} of {reachable} cases"
    );
}

#[test]
fn admissible_astar_equals_dijkstra_on_the_paper_scenarios_and_the_paper_astar_does_not() {
    let options = PlannerOptions::default();
    for name in SCENARIO_NAMES {
        let scenario = by_name(name).expect("scenario");
        let mut planner = Planner::new(
            scenario.map.clone(),
            scenario.traversability,
            options.grid_size,
        )
        .expect("planner");
        let grid = planner.grid().clone();
        let mut paper_astar_excess = Vec::new();
        for conn in CONNECTIVITIES {
            let case = format!("{name}, {}-connected", conn.directions());
            assert_consistent(&case, &grid, &scenario.goal, conn);
            let dijkstra =
                dijkstra_path(&grid, scenario.start, &scenario.goal, conn).expect("Dijkstra");
            let admissible =
                astar_admissible_path(&grid, scenario.start, &scenario.goal, conn).expect("A*");
            let paper = astar_path(&grid, scenario.start, &scenario.goal, conn).expect("A*");
            println!(
                "{case}: Dijkstra {:.6} ({} expanded), admissible A* {:.6} ({}), paper A* {:.6} ({})",
                dijkstra.cost,
                dijkstra.expanded,
                admissible.cost,
                admissible.expanded,
                paper.cost,
                paper.expanded
            );
            assert_optimal(&case, &admissible, &dijkstra);
            paper_astar_excess.push(paper.cost / dijkstra.cost - 1.0);
        }
        // Through the planner's front door, by name, at the default 8 directions.
        let method: Method = "astar-admissible".parse().expect("method name");
        let plan = planner
            .plan(
                scenario.start,
                scenario.start_yaw,
                &scenario.goal,
                method,
                &options,
            )
            .expect("plan");
        let dijkstra = planner
            .plan(
                scenario.start,
                scenario.start_yaw,
                &scenario.goal,
                Method::Dijkstra,
                &options,
            )
            .expect("plan");
        assert_eq!(plan.method, Method::AStarAdmissible);
        assert!(relative_error(plan.planner_cost, dijkstra.planner_cost) <= RELATIVE_TOLERANCE);
        // The paper's inadmissible heuristic costs more than the optimum on every scenario
        // (pits by the least: measured +0.7 % at 8 directions).
        for excess in paper_astar_excess {
            assert!(
                excess > 1e-3,
                "{name}: the paper's A* is within {excess:.1e} of the optimum"
            );
        }
    }
}
