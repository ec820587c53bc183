//! Dijkstra and A* against an independent Bellman-Ford reference on seeded random terrains.

use pf_planner::graph::{astar_path, dijkstra_path, distances_to_targets, Connectivity};
use pf_planner::grid::{GoalRegion, PlanningGrid};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random_grid(seed: u64) -> PlanningGrid {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (w, h) = (rng.random_range(6..14), rng.random_range(5..12));
    let cost = (0..w * h).map(|_| rng.random_range(0.05..1.0)).collect();
    let mut blocked: Vec<bool> = (0..w * h).map(|_| rng.random_bool(0.2)).collect();
    blocked[0] = false;
    blocked[w * h - 1] = false;
    PlanningGrid::from_parts([-1.0, 2.0], 0.5, w, h, cost, blocked).expect("grid")
}

/// Cost-to-go by plain Bellman-Ford sweeps over an explicit edge list (no heap, no shared code).
fn bellman_ford(grid: &PlanningGrid, target: usize, eight: bool) -> Vec<f64> {
    let (w, h) = (grid.width as i64, grid.height as i64);
    let mut edges = Vec::new();
    for iy in 0..h {
        for ix in 0..w {
            let u = (iy * w + ix) as usize;
            for dy in -1..=1i64 {
                for dx in -1..=1i64 {
                    let diagonal = dx != 0 && dy != 0;
                    if (dx == 0 && dy == 0) || (diagonal && !eight) {
                        continue;
                    }
                    let (nx, ny) = (ix + dx, iy + dy);
                    if nx < 0 || ny < 0 || nx >= w || ny >= h {
                        continue;
                    }
                    let v = (ny * w + nx) as usize;
                    let corner_free = !diagonal
                        || (!grid.blocked[(iy * w + nx) as usize]
                            && !grid.blocked[(ny * w + ix) as usize]);
                    if !grid.blocked[u] && !grid.blocked[v] && corner_free {
                        let step = if diagonal { 2f64.sqrt() } else { 1.0 } * grid.cell_size;
                        edges.push((u, v, grid.cost[u] * step));
                    }
                }
            }
        }
    }
    let mut d = vec![f64::INFINITY; grid.len()];
    d[target] = 0.0;
    for _ in 0..grid.len() {
        let mut changed = false;
        for &(u, v, c) in &edges {
            if d[v] + c < d[u] {
                d[u] = d[v] + c;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    d
}

#[test]
fn distances_and_dijkstra_match_bellman_ford_on_random_terrains() {
    for seed in 0..25 {
        let grid = random_grid(seed);
        let target = grid.len() - 1;
        let goal = GoalRegion {
            center: grid.center_of_index(target),
            radius: 0.0,
        };
        let start = grid.center_of_index(0);
        for (conn, eight) in [(Connectivity::Four, false), (Connectivity::Eight, true)] {
            let reference = bellman_ford(&grid, target, eight);
            let d = distances_to_targets(&grid, &[target], conn);
            for (a, b) in d.iter().zip(&reference) {
                assert!(
                    (a.is_infinite() && b.is_infinite()) || (a - b).abs() <= 1e-12 * b.max(1.0),
                    "seed {seed}: {a} vs {b}"
                );
            }
            match dijkstra_path(&grid, start, &goal, conn) {
                Ok(path) => {
                    assert!((path.cost - reference[0]).abs() < 1e-12, "seed {seed}");
                    let astar = astar_path(&grid, start, &goal, conn)
                        .expect("A* finds a path when Dijkstra does");
                    assert!(
                        astar.cost >= path.cost - 1e-12,
                        "seed {seed}: A* beat the optimum"
                    );
                    // Recomputing the cost along the returned cells gives the reported cost.
                    let mut along = 0.0;
                    for pair in path.cells.windows(2) {
                        let (a, b) = (grid.center_of_index(pair[0]), grid.center_of_index(pair[1]));
                        along += grid.cost[pair[0]] * (b[0] - a[0]).hypot(b[1] - a[1]);
                    }
                    assert!((along - path.cost).abs() < 1e-9);
                }
                Err(_) => assert!(
                    reference[0].is_infinite(),
                    "seed {seed}: Dijkstra missed a path"
                ),
            }
        }
    }
}

#[test]
fn euclidean_heuristic_astar_is_greedy_when_p_is_small() {
    // Cheap detour around an expensive (not blocked) wall: the optimum walks around it, A* with
    // the inadmissible Euclidean heuristic walks straight through.
    let (w, h) = (21, 15);
    let mut cost = vec![0.05; w * h];
    for iy in 2..13 {
        cost[iy * w + 10] = 1.0;
    }
    let grid =
        PlanningGrid::from_parts([0.0, 0.0], 1.0, w, h, cost, vec![false; w * h]).expect("grid");
    let start = grid.cell_center(2, 7);
    let goal = GoalRegion {
        center: grid.cell_center(18, 7),
        radius: 0.0,
    };
    let d = dijkstra_path(&grid, start, &goal, Connectivity::Eight).expect("path");
    let a = astar_path(&grid, start, &goal, Connectivity::Eight).expect("path");
    assert!(a.cells.contains(&(7 * w + 10)), "A* should cross the wall");
    assert!(
        !d.cells.iter().any(|&c| grid.cost[c] > 0.5),
        "Dijkstra should go around"
    );
    assert!(d.cost < 0.8 * a.cost, "{} vs {}", d.cost, a.cost);
    assert!(a.expanded < d.expanded);
}
