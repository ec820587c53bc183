//! The walkable-slope limit: a ridge whose cost alone makes crossing it the cheapest route is
//! walked around once its flanks are steeper than `max_slope_deg`.

use pf_planner::grid::GoalRegion;
use pf_planner::map::GridMap;
use pf_planner::metrics::evaluate_path;
use pf_planner::plan::{plan, Method, PlanRequest, PlannerOptions};
use pf_planner::traversability::{block_steep_cells, TraversabilityField, TraversabilityParams};

/// 32 × 32 cells of 0.25 m, flat at 0.1 m, with a sharp 1 m ridge across x = 4 m from y = 0 to
/// y = 6.5 m: going around its end is much longer than stepping over it.
fn ridge_map() -> GridMap {
    let (w, h, res) = (32, 32, 0.25);
    let heights = (0..w * h)
        .map(|i| {
            let (ix, iy) = (i % w, i / w);
            let (x, y) = ((ix as f64 + 0.5) * res, (iy as f64 + 0.5) * res);
            if (x - 4.0).abs() < 0.3 && y < 6.5 {
                1.1
            } else {
                0.1
            }
        })
        .collect();
    GridMap::new([0.0, 0.0], res, w, h, heights, None).expect("valid map")
}

fn request(params: TraversabilityParams) -> PlanRequest {
    PlanRequest {
        map: ridge_map(),
        start: [1.0, 1.0],
        start_yaw: 0.0,
        goal: GoalRegion {
            center: [7.0, 1.0],
            radius: 0.4,
        },
        method: Method::Pf,
        options: PlannerOptions {
            grid_size: 32,
            traversability: params,
            ..Default::default()
        },
    }
}

#[test]
fn steep_ridge_is_crossed_by_cost_alone_and_walked_around_with_a_slope_limit() {
    let costly = plan(&request(TraversabilityParams::default())).expect("plan");
    let limited_params = TraversabilityParams {
        max_slope_deg: Some(30.0),
        ..Default::default()
    };
    let limited = plan(&request(limited_params)).expect("plan");

    // Measured on the map with the steep cells blocked: the cost-only path steps over the ridge,
    // the limited one never touches a steep cell and goes round the ridge's end (y > 6.5 m).
    let map = ridge_map();
    let blocked = block_steep_cells(&map, None, &limited_params);
    let field = TraversabilityField::from_map(&blocked, &limited_params).expect("field");
    let over = evaluate_path(&blocked, &field, &costly.path);
    let around = evaluate_path(&blocked, &field, &limited.path);
    assert!(over.length_in_obstacles > 0.2, "{over:?}");
    assert_eq!(around.length_in_obstacles, 0.0, "{around:?}");
    assert!(limited.path.iter().any(|p| p[1] > 6.5));
    assert!(around.length > 2.0 * over.length);
}
