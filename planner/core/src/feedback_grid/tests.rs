use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::basis::BasisKind;
use crate::graph::{distances_to_targets, Connectivity};
use crate::lp::{LpSettings, LpSolver};
use crate::pf::{self, PfGenerators, PfOptions, StartDensity};

fn solve(
    grid: &PlanningGrid,
    start: Point,
    goal: &GoalRegion,
    directions: usize,
    density: StartDensity,
    solver: LpSolver,
) -> (pf::PfSolution, PfGenerators) {
    let gens = PfGenerators::build(grid, &BasisKind::Indicator, directions).expect("generators");
    let opts = PfOptions {
        u_max: 0.8,
        start_density: density,
        lp: LpSettings {
            solver,
            ..LpSettings::default()
        },
        ..PfOptions::default()
    };
    let sol = pf::solve(&gens, grid, start, goal, &opts).expect("solved");
    (sol, gens)
}

/// The exact solver's field (8 directions, uniform start density) for a point goal at a cell centre.
fn exact_field(grid: &PlanningGrid, start: Point, goal_cell: (usize, usize)) -> FeedbackGrid {
    let goal = GoalRegion {
        center: grid.cell_center(goal_cell.0, goal_cell.1),
        radius: 0.0,
    };
    let (sol, _) = solve(
        grid,
        start,
        &goal,
        8,
        StartDensity::UniformFree,
        LpSolver::Exact,
    );
    sol.feedback_grid.expect("field")
}

/// Random terrain with ~12 % blocked cells (the optimality tests' kind).
fn random_grid(rng: &mut ChaCha8Rng) -> PlanningGrid {
    let width = rng.random_range(10..=18);
    let height = rng.random_range(10..=18);
    let cell_size = rng.random_range(0.1..0.6);
    let mut cost = Vec::with_capacity(width * height);
    let mut blocked = Vec::with_capacity(width * height);
    for iy in 0..height {
        for ix in 0..width {
            let smooth = 0.5 + 0.4 * (0.4 * ix as f64).sin() * (0.3 * iy as f64).cos();
            cost.push((smooth + rng.random_range(-0.1..0.1)).clamp(0.05, 1.0));
            blocked.push(rng.random_bool(0.12));
        }
    }
    PlanningGrid::from_parts([-1.0, 2.0], cell_size, width, height, cost, blocked).expect("grid")
}

fn free_point(rng: &mut ChaCha8Rng, grid: &PlanningGrid) -> Point {
    loop {
        let c = rng.random_range(0..grid.len());
        if !grid.blocked[c] {
            return grid.center_of_index(c);
        }
    }
}

#[test]
fn cost_to_go_is_the_dijkstra_distance_for_the_indicator_basis() {
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    let mut checked = 0;
    while checked < 12 {
        let grid = random_grid(&mut rng);
        let start = free_point(&mut rng, &grid);
        let goal = GoalRegion {
            center: free_point(&mut rng, &grid),
            radius: rng.random_range(0.0..2.0) * grid.cell_size,
        };
        for directions in [4, 8] {
            let gens = PfGenerators::build(&grid, &BasisKind::Indicator, directions).expect("gens");
            let opts = PfOptions {
                u_max: 0.8,
                ..PfOptions::default()
            };
            // Start and goal may be walled apart on a random map: nothing to compare then.
            let Ok(sol) = pf::solve(&gens, &grid, start, &goal, &opts) else {
                continue;
            };
            let field = sol.feedback_grid.expect("exact solver gives a field");
            let targets = grid.goal_cells(&goal);
            let conn = Connectivity::from_directions(directions).expect("4 or 8");
            let dist = distances_to_targets(&grid, &targets, conn);
            for (cell, &graph) in dist.iter().enumerate() {
                let got = field.cost_to_go[cell];
                if grid.blocked[cell] || graph.is_infinite() {
                    assert_eq!(got, UNREACHABLE, "cell {cell}: graph says unreachable");
                    assert_eq!((field.dir_x[cell], field.dir_y[cell]), (0.0, 0.0));
                    assert_eq!(field.speed[cell], 0.0);
                } else {
                    let tolerance = 1e-9 * graph.max(1e-12);
                    assert!(
                        (got - graph).abs() <= tolerance,
                        "cell {cell}: field {got} vs Dijkstra {graph}"
                    );
                }
            }
            for &cell in &targets {
                assert_eq!(field.cost_to_go[cell], 0.0);
                assert_eq!((field.dir_x[cell], field.dir_y[cell]), (0.0, 0.0));
            }
            checked += 1;
        }
    }
}

#[test]
fn directions_are_unit_vectors_that_point_downhill_in_the_cost_to_go() {
    // Open, smoothly varying terrain: from every cell the lattice move closest to the field's
    // direction lowers the cost-to-go.
    let (w, h) = (20, 16);
    let cost = (0..w * h)
        .map(|c| {
            let (ix, iy) = ((c % w) as f64, (c / w) as f64);
            0.3 + 0.25 * (0.5 * ix).sin() * (0.35 * iy).cos() + 0.02 * ix
        })
        .collect();
    let grid =
        PlanningGrid::from_parts([0.0, 0.0], 0.25, w, h, cost, vec![false; w * h]).expect("grid");
    let goal = GoalRegion {
        center: grid.cell_center(15, 11),
        radius: 0.3,
    };
    let (sol, _) = solve(
        &grid,
        grid.cell_center(1, 1),
        &goal,
        8,
        StartDensity::UniformFree,
        LpSolver::Exact,
    );
    let field = sol.feedback_grid.expect("field");
    let shifts = [
        (1, 0),
        (1, 1),
        (0, 1),
        (-1, 1),
        (-1, 0),
        (-1, -1),
        (0, -1),
        (1, -1),
    ];
    let mut with_direction = 0;
    for iy in 0..h {
        for ix in 0..w {
            let cell = field.index(ix, iy);
            let d = [field.dir_x[cell], field.dir_y[cell]];
            if field.cost_to_go[cell] == 0.0 {
                assert_eq!(d, [0.0, 0.0], "target cell ({ix}, {iy})");
                continue;
            }
            assert!(
                (d[0].hypot(d[1]) - 1.0).abs() < 1e-12,
                "({ix}, {iy}): {d:?}"
            );
            assert_eq!(
                field.speed[cell], 0.8,
                "speed = u_max before the plan sets it"
            );
            with_direction += 1;
            let next = shifts
                .iter()
                .filter_map(|&(sx, sy)| {
                    let (nx, ny) = (ix as i64 + sx, iy as i64 + sy);
                    let inside = nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64;
                    inside.then(|| {
                        let norm = ((sx * sx + sy * sy) as f64).sqrt();
                        let dot = (d[0] * sx as f64 + d[1] * sy as f64) / norm;
                        (dot, field.index(nx as usize, ny as usize))
                    })
                })
                .max_by(|a, b| a.0.total_cmp(&b.0))
                .map(|(_, next)| next)
                .expect("an interior neighbour");
            assert!(
                field.cost_to_go[next] < field.cost_to_go[cell],
                "({ix}, {iy}): moving along {d:?} goes from {} to {}",
                field.cost_to_go[cell],
                field.cost_to_go[next]
            );
        }
    }
    assert!(with_direction > w * h / 2);
}

#[test]
fn a_uniform_map_gives_straight_directions_not_a_zig_zag() {
    let n = 21;
    let grid =
        PlanningGrid::from_parts([0.0, 0.0], 0.5, n, n, vec![0.4; n * n], vec![false; n * n])
            .expect("grid");
    let (gx, gy) = (10usize, 10usize);
    let field = exact_field(&grid, grid.cell_center(0, 3), (gx, gy));
    let s = std::f64::consts::FRAC_1_SQRT_2;
    // The mean of the axial and the diagonal step (both optimal off the axes and diagonals).
    let between = {
        let (x, y) = (1.0 + s, s);
        let norm = f64::hypot(x, y);
        [x / norm, y / norm]
    };
    for iy in 0..n {
        for ix in 0..n {
            let cell = field.index(ix, iy);
            if (ix, iy) == (gx, gy) {
                assert_eq!(field.cost_to_go[cell], 0.0);
                continue;
            }
            let (dx, dy) = (gx as f64 - ix as f64, gy as f64 - iy as f64);
            let d = [field.dir_x[cell], field.dir_y[cell]];
            // Within the lattice's resolution of the straight line to the goal...
            let cos = (d[0] * dx + d[1] * dy) / dx.hypot(dy);
            assert!(
                cos >= (22.5f64 + 1e-6).to_radians().cos(),
                "({ix}, {iy}): {d:?} vs the goal direction ({dx}, {dy})"
            );
            // ...and the same direction over a whole octant: exact on the axes and diagonals,
            // the axial/diagonal mean strictly inside the first octant.
            if dy == 0.0 && dx > 0.0 {
                assert_eq!(d, [1.0, 0.0], "({ix}, {iy})");
            } else if dx == dy && dx > 0.0 {
                assert!((d[0] - s).abs() < 1e-12 && (d[1] - s).abs() < 1e-12);
            } else if dx > dy && dy > 0.0 {
                assert!(
                    (d[0] - between[0]).abs() < 1e-12 && (d[1] - between[1]).abs() < 1e-12,
                    "({ix}, {iy}): {d:?}, expected {between:?}"
                );
            }
        }
    }
}

#[test]
fn obstacles_and_cut_off_cells_read_unreachable() {
    // 7 x 5, a full wall at ix = 3 except nothing: the right side is cut off from the goal.
    let (w, h) = (7, 5);
    let blocked: Vec<bool> = (0..w * h).map(|c| c % w == 3).collect();
    let grid =
        PlanningGrid::from_parts([0.0, 0.0], 1.0, w, h, vec![0.5; w * h], blocked).expect("grid");
    let field = exact_field(&grid, grid.cell_center(2, 4), (0, 2));
    for iy in 0..h {
        for ix in 0..w {
            let cell = field.index(ix, iy);
            if ix >= 3 {
                assert_eq!(field.cost_to_go[cell], UNREACHABLE, "({ix}, {iy})");
                assert_eq!(
                    (field.dir_x[cell], field.dir_y[cell], field.speed[cell]),
                    (0.0, 0.0, 0.0)
                );
            } else {
                assert!(field.cost_to_go[cell] >= 0.0, "({ix}, {iy})");
            }
        }
    }
}

#[test]
fn clarabel_gives_the_field_for_a_uniform_start_and_refuses_a_point_start() {
    let (w, h) = (9, 7);
    let mut blocked = vec![false; w * h];
    blocked[3 * w + 4] = true;
    blocked[2 * w + 4] = true;
    let cost = (0..w * h).map(|c| 0.2 + 0.05 * (c % 5) as f64).collect();
    let grid = PlanningGrid::from_parts([0.0, 0.0], 0.5, w, h, cost, blocked).expect("grid");
    let goal = GoalRegion {
        center: grid.cell_center(8, 3),
        radius: 0.5,
    };
    let start = grid.cell_center(0, 3);
    let (exact, _) = solve(
        &grid,
        start,
        &goal,
        8,
        StartDensity::UniformFree,
        LpSolver::Exact,
    );
    let (clarabel, _) = solve(
        &grid,
        start,
        &goal,
        8,
        StartDensity::UniformFree,
        LpSolver::Clarabel,
    );
    let (exact, clarabel) = (
        exact.feedback_grid.expect("exact field"),
        clarabel.feedback_grid.expect("Clarabel field"),
    );
    for cell in 0..grid.len() {
        let (a, b) = (exact.cost_to_go[cell], clarabel.cost_to_go[cell]);
        assert!(
            (a - b).abs() <= 1e-6 * a.abs().max(1.0),
            "cell {cell}: {a} vs {b}"
        );
    }
    let (point, _) = solve(
        &grid,
        start,
        &goal,
        8,
        StartDensity::PointMass,
        LpSolver::Clarabel,
    );
    assert_eq!(point.feedback_grid, Err(FieldUnavailable::DualNotCostToGo));
}

#[test]
fn a_start_inside_the_goal_still_gets_the_whole_field() {
    // Point start in the target: the LP is trivial (no flow, no dual); V* comes from the SSP.
    let n = 6;
    let grid =
        PlanningGrid::from_parts([0.0, 0.0], 1.0, n, n, vec![0.5; n * n], vec![false; n * n])
            .expect("grid");
    let goal = GoalRegion {
        center: grid.cell_center(2, 2),
        radius: 0.0,
    };
    let (sol, _) = solve(
        &grid,
        goal.center,
        &goal,
        4,
        StartDensity::PointMass,
        LpSolver::Exact,
    );
    let field = sol.feedback_grid.expect("field");
    // 4-connected, p = 0.5, 1 m cells: cost-to-go = 0.5 × Manhattan distance.
    for iy in 0..n {
        for ix in 0..n {
            let manhattan = (ix as f64 - 2.0).abs() + (iy as f64 - 2.0).abs();
            assert!((field.cost_to_go[field.index(ix, iy)] - 0.5 * manhattan).abs() < 1e-12);
        }
    }
}

#[test]
fn the_rbf_field_lives_on_the_planning_grid() {
    let n = 12;
    let grid =
        PlanningGrid::from_parts([0.0, 0.0], 0.5, n, n, vec![0.5; n * n], vec![false; n * n])
            .expect("grid");
    let gens = PfGenerators::build(&grid, &BasisKind::DEFAULT_RBF, 8).expect("generators");
    let goal = GoalRegion {
        center: grid.cell_center(9, 9),
        radius: 0.6,
    };
    let sol = pf::solve(
        &gens,
        &grid,
        grid.cell_center(2, 2),
        &goal,
        &PfOptions::default(),
    )
    .expect("solved");
    let field = sol.feedback_grid.expect("RBF field");
    assert_eq!((field.width, field.height, field.resolution), (n, n, 0.5));
    let start = field.index(2, 2);
    assert!(field.cost_to_go[start] > 0.0);
    // Up and to the right, towards the goal.
    assert!(
        field.dir_x[start] > 0.5 && field.dir_y[start] > 0.5,
        "{:?}",
        (field.dir_x[start], field.dir_y[start])
    );
    // Cost-to-go falls towards the goal along the diagonal.
    for k in 2..8 {
        assert!(field.cost_to_go[field.index(k + 1, k + 1)] < field.cost_to_go[field.index(k, k)]);
    }
}

#[test]
fn the_npz_archive_holds_every_array_with_its_shape() {
    let field = FeedbackGrid {
        origin: [1.0, -2.0],
        resolution: 0.25,
        width: 3,
        height: 2,
        dir_x: vec![1.0, 0.0, 0.0, 0.5, 0.0, -1.0],
        dir_y: vec![0.0; 6],
        speed: vec![0.5, 0.0, 0.0, 0.5, 0.0, 0.5],
        cost_to_go: vec![1.0, 0.0, -1.0, 2.0, 0.0, 3.0],
        goal: GoalRegion {
            center: [1.5, -1.5],
            radius: 0.3,
        },
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("field.npz");
    field.write_npz(&path).expect("written");
    let mut archive = zip::ZipArchive::new(std::fs::File::open(&path).expect("open")).expect("zip");
    let mut names: Vec<String> = archive.file_names().map(str::to_owned).collect();
    names.sort();
    assert_eq!(
        names,
        [
            "cost_to_go.npy",
            "dir_x.npy",
            "dir_y.npy",
            "goal.npy",
            "origin.npy",
            "resolution.npy",
            "speed.npy"
        ]
    );
    let mut read = |name: &str| {
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(&mut archive.by_name(name).expect("entry"), &mut bytes)
            .expect("read");
        bytes
    };
    let cost = read("cost_to_go.npy");
    let header = String::from_utf8_lossy(&cost[10..cost.len() - 48]).to_string();
    assert!(header.contains("'shape': (2, 3)"), "{header}");
    assert_eq!((cost.len() - 48) % 64, 0, "data starts 64-aligned");
    let values: Vec<f64> = cost[cost.len() - 48..]
        .chunks(8)
        .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
        .collect();
    assert_eq!(values, field.cost_to_go);
    let resolution = read("resolution.npy");
    assert!(String::from_utf8_lossy(&resolution).contains("'shape': ()"));
    let goal = read("goal.npy");
    assert!(String::from_utf8_lossy(&goal).contains("'shape': (3,)"));
}

#[test]
fn plans_carry_the_field_at_the_requested_speed_and_graph_plans_do_not() {
    use crate::map::GridMap;
    use crate::plan::{Method, Planner, PlannerOptions};
    use crate::traversability::TraversabilityParams;
    let n = 16;
    let heights = (0..n * n).map(|c| 0.1 + 0.01 * (c % n) as f64).collect();
    let map = GridMap::new([0.0, 0.0], 0.25, n, n, heights, None).expect("map");
    let options = PlannerOptions {
        grid_size: n,
        speed: 0.7,
        ..PlannerOptions::default()
    };
    let mut planner = Planner::new(map, TraversabilityParams::default(), n).expect("planner");
    let goal = GoalRegion {
        center: [3.5, 3.5],
        radius: 0.3,
    };
    let plan = planner
        .plan([0.3, 0.3], 0.0, &goal, Method::Pf, &options)
        .expect("P-F plan");
    let field = plan.feedback_field.expect("P-F plans carry a field");
    assert_eq!((field.width, field.height), (n, n));
    assert!(field
        .speed
        .iter()
        .zip(&field.cost_to_go)
        .all(|(&s, &c)| if c > 0.0 { s == 0.7 } else { s == 0.0 }));
    let graph = planner
        .plan([0.3, 0.3], 0.0, &goal, Method::Dijkstra, &options)
        .expect("Dijkstra plan");
    assert_eq!(
        graph.feedback_field,
        Err(FieldUnavailable::NotPf { method: "dijkstra" })
    );
}

#[test]
fn on_a_watershed_the_direction_follows_one_route_not_their_mean() {
    // A symmetric map: a block in the middle, the goal straight behind it. Cells on the axis
    // in front of the block have two equally good routes (north and south around it); the mean
    // of their first moves would point at the block, which is no optimal move. Every cell's
    // direction must be an optimal move, or the mean of two adjacent optimal moves: each
    // lattice move within 22.5° of it is tight in the Bellman equation (p = 0.5, 1 m cells).
    let (w, h) = (13, 11);
    let block = |ix: usize, iy: usize| (5..=7).contains(&ix) && (3..=7).contains(&iy);
    let blocked: Vec<bool> = (0..w * h).map(|c| block(c % w, c / w)).collect();
    let grid =
        PlanningGrid::from_parts([0.0, 0.0], 1.0, w, h, vec![0.5; w * h], blocked).expect("grid");
    let field = exact_field(&grid, grid.cell_center(1, 5), (11, 5));
    let moves: [(i64, i64); 8] = [
        (1, 0),
        (1, 1),
        (0, 1),
        (-1, 1),
        (-1, 0),
        (-1, -1),
        (0, -1),
        (1, -1),
    ];
    for iy in 0..h {
        for ix in 0..w {
            let cell = field.index(ix, iy);
            if field.cost_to_go[cell] <= 0.0 {
                continue;
            }
            let d = [field.dir_x[cell], field.dir_y[cell]];
            let near: Vec<(i64, i64)> = moves
                .iter()
                .copied()
                .filter(|&(sx, sy)| {
                    let len = ((sx * sx + sy * sy) as f64).sqrt();
                    (d[0] * sx as f64 + d[1] * sy as f64) / len
                        >= (22.5f64.to_radians()).cos() - 1e-9
                })
                .collect();
            assert!(!near.is_empty() && near.len() <= 2, "({ix}, {iy}): {d:?}");
            for (sx, sy) in near {
                let (nx, ny) = (ix as i64 + sx, iy as i64 + sy);
                assert!(nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64);
                let next = field.index(nx as usize, ny as usize);
                let step = 0.5 * ((sx * sx + sy * sy) as f64).sqrt();
                assert!(
                    field.cost_to_go[next] >= 0.0
                        && (field.cost_to_go[next] + step - field.cost_to_go[cell]).abs() < 1e-9,
                    "({ix}, {iy}): direction {d:?} includes the move to ({nx}, {ny}), which is not optimal ({} + {step} vs {})",
                    field.cost_to_go[next],
                    field.cost_to_go[cell]
                );
            }
        }
    }
}
