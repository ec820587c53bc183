//! The service end to end on `memq://` (in-process LCM, no network): replies against independent
//! library computations, every invalid request answered, busy replies, status counters. (Bursts and
//! garbage packets go to the service binary over real UDP: `hostile_packets`.)

use crate::common;

use std::collections::HashSet;
use std::time::Duration;

use common::{config, flat_map, inline_request, map_message, TestService};
use lcm_types::pfnav::{PlanOptions, PlanReply, PlanRequest};
use pf_planner::graph::{self, Connectivity};
use pf_planner::grid::PlanningGrid;
use pf_planner::metrics::evaluate_path;
use pf_planner::plan::walk_into_goal;
use pf_planner::scenarios;
use pf_planner::traversability::{TraversabilityField, TraversabilityParams};

const WAIT: Duration = Duration::from_secs(60);

fn c_shape_request(
    id: i64,
    method: i8,
    grid_size: i32,
    directions: i8,
) -> (PlanRequest, pf_planner::io::MapScenario) {
    let scenario = scenarios::by_name("c_shape").unwrap();
    let mut request = inline_request(
        id,
        method,
        &scenario.map,
        scenario.start,
        scenario.goal.center,
    );
    request.goal_radius = scenario.goal.radius;
    request.start_yaw = scenario.start_yaw;
    request.options.grid_size = grid_size;
    request.options.directions = directions;
    (request, scenario)
}

#[test]
fn admissible_astar_over_the_wire_returns_the_dijkstra_optimum() {
    let service = TestService::start(config("T1A_"));
    let (request, scenario) = c_shape_request(12, PlanRequest::METHOD_ASTAR_ADMISSIBLE, 64, 8);
    service.publish_request(&request);
    let reply = service.reply_to(12, WAIT);
    assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
    assert_eq!(reply.method, PlanRequest::METHOD_ASTAR_ADMISSIBLE);
    let field =
        TraversabilityField::from_map(&scenario.map, &TraversabilityParams::default()).unwrap();
    let grid = PlanningGrid::from_field(&scenario.map, &field, 64).unwrap();
    let optimum =
        graph::dijkstra_path(&grid, scenario.start, &scenario.goal, Connectivity::Eight).unwrap();
    assert!(
        (reply.metrics.objective - optimum.cost).abs() <= 1e-9 * optimum.cost,
        "admissible A* {} vs Dijkstra {}",
        reply.metrics.objective,
        optimum.cost
    );
    // Fewer nodes than Dijkstra expands (measured 2389 against 3676).
    assert!((reply.metrics.expanded_nodes as usize) < optimum.expanded);
    service.stop();
}

#[test]
fn c_shape_dijkstra_reply_equals_the_library_path_cost() {
    let service = TestService::start(config("T1_"));
    let (request, scenario) = c_shape_request(11, PlanRequest::METHOD_DIJKSTRA, 64, 8);
    service.publish_request(&request);
    let reply = service.reply_to(11, WAIT);
    assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
    assert_eq!(
        (reply.method, reply.map_seq),
        (PlanRequest::METHOD_DIJKSTRA, 1)
    );

    // Independent reference: the library's graph search and metric on the same inputs.
    let field =
        TraversabilityField::from_map(&scenario.map, &TraversabilityParams::default()).unwrap();
    let grid = PlanningGrid::from_field(&scenario.map, &field, 64).unwrap();
    let path =
        graph::dijkstra_path(&grid, scenario.start, &scenario.goal, Connectivity::Eight).unwrap();
    // Every plan walks on from the goal region's rim to its centre.
    let mut points = path.points.clone();
    walk_into_goal(&grid, &mut points, &scenario.goal);
    let metrics = evaluate_path(&scenario.map, &field, &points);
    assert_eq!(reply.metrics.cost, metrics.cost_integral);
    assert_eq!(reply.metrics.length, metrics.length);
    assert_eq!(reply.metrics.objective, path.cost);
    assert!(reply.metrics.reached_goal);
    let first = &reply.samples[0];
    let last = reply.samples.last().unwrap();
    assert_eq!(reply.num_samples as usize, reply.samples.len());
    assert!((first.x - scenario.start[0]).hypot(first.y - scenario.start[1]) < grid.cell_size);
    assert!(scenario.goal.contains([last.x, last.y]));
    // At the default 0.5 m/s the walk takes at least length / speed.
    assert!(last.t >= metrics.length / 0.5 - 1e-9);
    service.stop();
}

#[test]
fn c_shape_pf_optimum_equals_the_shortest_path_and_generators_are_cached() {
    let service = TestService::start(config("T2_"));
    let (mut request, scenario) = c_shape_request(21, PlanRequest::METHOD_PF, 32, 4);
    request.options.basis = PlanOptions::BASIS_INDICATOR;
    request.options.start_density = PlanOptions::START_DENSITY_POINT;
    service.publish_request(&request);
    let first = service.reply_to(21, WAIT);
    assert_eq!(first.status, PlanReply::STATUS_OK, "{}", first.error);
    assert_eq!(
        first.metrics.lp_status,
        lcm_types::pfnav::PlanMetrics::LP_SOLVED
    );

    // With the indicator basis the LP optimum / (1 + 1/u_max) is the 4-connected graph distance
    // from the start cell to the goal cells (the planner's optimality identity).
    let field =
        TraversabilityField::from_map(&scenario.map, &TraversabilityParams::default()).unwrap();
    let grid = PlanningGrid::from_field(&scenario.map, &field, 32).unwrap();
    let targets = grid.goal_cells(&scenario.goal);
    let distances = graph::distances_to_targets(&grid, &targets, Connectivity::Four);
    let (sx, sy) = grid.cell_of(scenario.start).unwrap();
    let expected = distances[grid.index(sx, sy)];
    let weighted = first.metrics.objective / 2.0;
    assert!(
        (weighted - expected).abs() <= 1e-6 * expected,
        "LP {weighted} vs graph {expected}"
    );

    // Same map and settings, other goal: generators come from the cache, same LP size.
    request.request_id = 22;
    request.goal_x -= 1.0;
    service.publish_request(&request);
    let second = service.reply_to(22, WAIT);
    assert_eq!(second.status, PlanReply::STATUS_OK, "{}", second.error);
    // A status published after both replies: one generator set, built once.
    let status = loop {
        let status = service
            .statuses
            .recv_timeout(Duration::from_secs(3))
            .unwrap();
        if status.requests_served == 2 {
            break status;
        }
    };
    assert_eq!(status.cached_generators, 1);
    service.stop();
}

#[test]
fn every_invalid_request_is_answered_with_a_status_and_a_reason() {
    let service = TestService::start(config("T3_"));
    let open = flat_map(16, &[]);
    // A wall at ix = 8 with no gap: the right half is unreachable from the left.
    let wall: Vec<(usize, usize)> = (0..16).map(|iy| (8, iy)).collect();
    let walled = flat_map(16, &wall);
    let good = |id| {
        inline_request(
            id,
            PlanRequest::METHOD_DIJKSTRA,
            &open,
            [0.4, 0.4],
            [3.5, 3.5],
        )
    };
    let mut cases: Vec<(PlanRequest, i64, i8, &str)> = Vec::new();
    let mut bad_id = good(0);
    bad_id.request_id = -4;
    cases.push((bad_id, -4, PlanReply::STATUS_INVALID_REQUEST, "request_id"));
    let mut nan = good(31);
    nan.inline_map[0].heights[17] = f64::NAN;
    cases.push((nan, 31, PlanReply::STATUS_INVALID_MAP, "not finite"));
    // A start 1 m inside a 2 m square block: beyond the reach within which a start on a
    // blocked cell is led off it (footprint and margin plus a cell).
    let block: Vec<(usize, usize)> = (4..12)
        .flat_map(|ix| (4..12).map(move |iy| (ix, iy)))
        .collect();
    let obstacle_start = inline_request(
        32,
        PlanRequest::METHOD_DIJKSTRA,
        &flat_map(16, &block),
        [2.0, 2.0],
        [0.5, 0.5],
    );
    cases.push((
        obstacle_start,
        32,
        PlanReply::STATUS_START_INVALID,
        "obstacle",
    ));
    let unreachable = inline_request(
        33,
        PlanRequest::METHOD_DIJKSTRA,
        &walled,
        [0.5, 0.5],
        [3.5, 3.5],
    );
    cases.push((
        unreachable,
        33,
        PlanReply::STATUS_GOAL_UNREACHABLE,
        "unreachable",
    ));
    let mut pf_unreachable =
        inline_request(34, PlanRequest::METHOD_PF, &walled, [0.5, 0.5], [3.5, 3.5]);
    pf_unreachable.options.directions = 4;
    cases.push((
        pf_unreachable,
        34,
        PlanReply::STATUS_GOAL_UNREACHABLE,
        "unreachable",
    ));
    let mut method = good(35);
    method.method = 7;
    cases.push((
        method,
        35,
        PlanReply::STATUS_INVALID_REQUEST,
        "unknown method",
    ));
    let mut off_map = good(36);
    off_map.start_x = -3.0;
    cases.push((off_map, 36, PlanReply::STATUS_START_INVALID, "off the map"));
    let mut by_seq = good(37);
    by_seq.num_inline_maps = 0;
    by_seq.inline_map.clear();
    by_seq.map_seq = 99;
    cases.push((by_seq, 37, PlanReply::STATUS_INVALID_MAP, "seq 99"));
    for (request, _, _, _) in &cases {
        service.publish_request(request);
    }
    let ids: Vec<i64> = cases.iter().map(|c| c.1).collect();
    let replies = service.collect(&ids, WAIT);
    for (_, id, status, needle) in &cases {
        assert_eq!(replies[id].len(), 1, "request {id} answered once");
        let reply = &replies[id][0];
        assert_eq!(reply.status, *status, "request {id}: {}", reply.error);
        assert!(
            reply.error.to_lowercase().contains(&needle.to_lowercase()),
            "request {id}: {:?}",
            reply.error
        );
        assert!(reply.samples.is_empty());
    }
    // And a good one after all that.
    service.publish_request(&good(38));
    assert_eq!(service.reply_to(38, WAIT).status, PlanReply::STATUS_OK);
    let report = service.stop();
    assert_eq!(report.requests_served, 1);
    assert_eq!(report.requests_failed, cases.len() as i64);
}

#[test]
fn maps_by_seq_from_the_map_channel_are_used() {
    let service = TestService::start(config("T4_"));
    let map = flat_map(12, &[]);
    service.publish_map(&map_message(&map, 5));
    let mut request = inline_request(41, PlanRequest::METHOD_ASTAR, &map, [0.3, 0.3], [2.5, 2.0]);
    request.num_inline_maps = 0;
    request.inline_map.clear();
    request.map_seq = 5;
    service.publish_request(&request);
    let reply = service.reply_to(41, WAIT);
    assert_eq!(
        (reply.status, reply.map_seq),
        (PlanReply::STATUS_OK, 5),
        "{}",
        reply.error
    );
    request.request_id = 42;
    request.map_seq = -1; // the latest
    service.publish_request(&request);
    assert_eq!(service.reply_to(42, WAIT).map_seq, 5);
    service.stop();
}

#[test]
fn a_full_queue_answers_busy_and_every_request_still_gets_one_reply() {
    let mut cfg = config("T6_");
    cfg.workers = 1;
    cfg.queue_capacity = 2;
    let service = TestService::start(cfg);
    let scenario = scenarios::by_name("c_shape").unwrap();
    let ids: Vec<i64> = (1..=12).collect();
    for &id in &ids {
        let mut r = inline_request(
            id,
            PlanRequest::METHOD_PF,
            &scenario.map,
            scenario.start,
            scenario.goal.center,
        );
        r.options.grid_size = 32;
        r.options.directions = 4;
        r.goal_radius = scenario.goal.radius;
        service.publish_request(&r);
    }
    let replies = service.collect(&ids, Duration::from_secs(90));
    let mut busy = 0;
    for id in &ids {
        let for_id = &replies[id];
        assert_eq!(for_id.len(), 1);
        match for_id[0].status {
            PlanReply::STATUS_OK => {}
            PlanReply::STATUS_BUSY => {
                busy += 1;
                assert!(for_id[0].error.contains("busy"), "{}", for_id[0].error);
            }
            other => panic!("request {id}: status {other}: {}", for_id[0].error),
        }
    }
    // One solving, two queued: at least the rest of a fast burst must have been refused.
    assert!(
        busy >= 1,
        "no busy reply although 12 slow requests met a queue of 2"
    );
    let report = service.stop();
    assert_eq!(report.requests_rejected_busy, busy);
}

#[test]
fn status_is_published_every_period_with_counters() {
    let mut cfg = config("T8_");
    cfg.status_period = Duration::from_millis(200);
    let service = TestService::start(cfg);
    let map = flat_map(8, &[]);
    service.publish_request(&inline_request(
        81,
        PlanRequest::METHOD_DIJKSTRA,
        &map,
        [0.2, 0.2],
        [1.7, 1.7],
    ));
    assert_eq!(service.reply_to(81, WAIT).status, PlanReply::STATUS_OK);
    let mut seen = HashSet::new();
    let mut last = None;
    while seen.len() < 3 {
        let status = service
            .statuses
            .recv_timeout(Duration::from_secs(5))
            .expect("status every 200 ms");
        seen.insert(status.header.seq);
        last = Some(status);
    }
    let status = last.unwrap();
    assert!(status.uptime > 0.0);
    assert_eq!((status.requests_received, status.requests_served), (1, 1));
    assert_eq!(status.queue_capacity, 2048); // ServiceConfig default: holds a burst
    assert!(status.last_solve_time > 0.0);
    service.stop();
}

/// Distance from (x, y) to the nearest cell centre of `map` whose inclination exceeds 30°.
fn distance_to_steep_ground(map: &pf_planner::map::GridMap, x: f64, y: f64) -> f64 {
    let mut nearest = f64::INFINITY;
    for iy in 0..map.height {
        for ix in 0..map.width {
            if pf_planner::traversability::slope_deg(map, ix, iy) > 30.0 {
                let c = map.cell_center(ix, iy);
                nearest = nearest.min((c[0] - x).hypot(c[1] - y));
            }
        }
    }
    nearest
}

#[test]
fn a_footprint_radius_keeps_the_mountain_pass_plan_off_the_flanks() {
    let scenario = scenarios::by_name("mountain_pass").unwrap();
    let mut clearance = Vec::new();
    for (id, radius) in [(61, 0.0), (62, 0.25)] {
        let mut cfg = config(&format!("T6{id}_"));
        cfg.traversability.footprint_radius_m = radius;
        let service = TestService::start(cfg);
        let mut request = inline_request(
            id,
            PlanRequest::METHOD_DIJKSTRA,
            &scenario.map,
            scenario.start,
            scenario.goal.center,
        );
        request.goal_radius = scenario.goal.radius;
        service.publish_request(&request);
        let reply = service.reply_to(id, WAIT);
        assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
        // The reply is the library's plan on the footprint field.
        let params = TraversabilityParams {
            footprint_radius_m: radius,
            ..Default::default()
        };
        let field = TraversabilityField::from_map(&scenario.map, &params).unwrap();
        let grid = PlanningGrid::from_field(&scenario.map, &field, scenario.map.width).unwrap();
        let path = graph::dijkstra_path(&grid, scenario.start, &scenario.goal, Connectivity::Eight)
            .unwrap();
        assert_eq!(reply.metrics.objective, path.cost);
        clearance.push(
            reply
                .samples
                .iter()
                .map(|s| distance_to_steep_ground(&scenario.map, s.x, s.y))
                .fold(f64::INFINITY, f64::min),
        );
        service.stop();
    }
    // The point robot's path touches the flank; with the footprint it keeps its radius off it
    // (less half a cell diagonal: distances are to cell centres).
    eprintln!("clearance of the plan from ground steeper than 30°: {clearance:?}");
    assert!(
        clearance[0] < 0.15,
        "point-robot clearance {}",
        clearance[0]
    );
    assert!(
        clearance[1] >= 0.25 - 0.09,
        "footprint clearance {}",
        clearance[1]
    );
}
