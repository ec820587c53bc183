//! Paths never cut through obstacles: a maze of one-cell walls whose only openings are diagonal
//! gaps (two wall cells touching at a corner) must be solved with zero length inside obstacles,
//! for the integrated path and for the re-timed reference samples alike.

use pf_planner::basis::BasisKind;
use pf_planner::grid::GoalRegion;
use pf_planner::map::GridMap;
use pf_planner::metrics::evaluate_path;
use pf_planner::plan::{Method, Planner, PlannerOptions};
use pf_planner::traversability::TraversabilityParams;

/// 33 × 33 cells of 0.25 m: vertical one-cell walls every fourth column with an opening that
/// alternates between the top and the bottom, and diagonal one-cell wall fragments next to the
/// openings, so the cheapest routes squeeze past obstacle corners.
fn maze() -> GridMap {
    let n = 33;
    let mut obstacles = vec![false; n * n];
    let mut heights = vec![0.2; n * n];
    for (k, wx) in (4..n - 2).step_by(4).enumerate() {
        let gap_at_top = k % 2 == 0;
        for iy in 0..n {
            let in_gap = if gap_at_top { iy >= n - 3 } else { iy < 3 };
            if !in_gap {
                obstacles[iy * n + wx] = true;
            }
        }
        // A diagonal fragment in front of the gap: wall cells touching only at a corner.
        let (y0, dir) = if gap_at_top {
            (n - 5, 1i64)
        } else {
            (4, -1i64)
        };
        for d in 0..2i64 {
            let (x, y) = (wx as i64 - 1 - d, y0 as i64 + dir * d);
            obstacles[(y as usize) * n + x as usize] = true;
        }
    }
    for (i, h) in heights.iter_mut().enumerate() {
        *h += 0.05 * ((i % 7) as f64);
    }
    GridMap::new([0.0, 0.0], 0.25, n, n, heights, Some(obstacles)).expect("maze")
}

#[test]
fn pf_paths_and_reference_samples_stay_out_of_a_maze_with_diagonal_gaps() {
    let map = maze();
    let start = map.cell_center(1, 1);
    let goal = GoalRegion {
        center: map.cell_center(31, 31),
        radius: 0.3,
    };
    let mut checked = 0;
    for directions in [4, 8] {
        for basis in [BasisKind::Indicator] {
            let options = PlannerOptions {
                grid_size: 33,
                directions,
                basis,
                ..PlannerOptions::default()
            };
            let mut planner =
                Planner::new(map.clone(), TraversabilityParams::default(), 33).expect("planner");
            for method in [Method::Pf, Method::Dijkstra, Method::AStar] {
                let plan = planner
                    .plan(start, 0.0, &goal, method, &options)
                    .unwrap_or_else(|e| panic!("{method} {directions}: {e}"));
                assert_eq!(
                    plan.metrics.length_in_obstacles, 0.0,
                    "{method}, {directions} directions: path in obstacles"
                );
                let samples: Vec<[f64; 2]> = plan.trajectory.iter().map(|s| [s.x, s.y]).collect();
                let on_samples = evaluate_path(&map, planner.field(), &samples);
                assert_eq!(
                    on_samples.length_in_obstacles, 0.0,
                    "{method}, {directions} directions: reference samples in obstacles"
                );
                assert!(plan.metrics.length > 20.0, "the maze forces a long detour");
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 6);
}
