//! Real-time planning through the service (memq://): the exact solver and Clarabel answer the
//! same optimum with a certificate, a new map of the same geometry reuses the cached generators,
//! and requests that could not be answered within the limits are refused before any work.

use crate::common;

use std::time::{Duration, Instant};

use common::{config, flat_map, inline_request, TestService};
use lcm_types::pfnav::{PlanMetrics, PlanOptions, PlanReply, PlanRequest};
use pf_planner::scenarios;

const WAIT: Duration = Duration::from_secs(60);

fn c_shape_pf(id: i64, grid_size: i32) -> PlanRequest {
    let scenario = scenarios::by_name("c_shape").expect("scenario");
    let mut request = inline_request(
        id,
        PlanRequest::METHOD_PF,
        &scenario.map,
        scenario.start,
        scenario.goal.center,
    );
    request.goal_radius = scenario.goal.radius;
    request.options.grid_size = grid_size;
    request
}

#[test]
fn exact_and_clarabel_replies_agree_and_both_are_certified() {
    let service = TestService::start(config("RT1_"));
    let exact = c_shape_pf(1, 48);
    let mut clarabel = c_shape_pf(2, 48);
    clarabel.options.solver = PlanOptions::SOLVER_CLARABEL;
    service.publish_request(&exact);
    service.publish_request(&clarabel);
    let (a, b) = (service.reply_to(1, WAIT), service.reply_to(2, WAIT));
    for reply in [&a, &b] {
        assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
        assert_eq!(reply.metrics.lp_status, PlanMetrics::LP_SOLVED);
        assert!(reply.metrics.certified, "{:?}", reply.metrics);
        assert!(reply.metrics.duality_gap <= reply.metrics.certificate_tolerance);
        assert!(reply.metrics.primal_residual <= reply.metrics.certificate_tolerance);
        assert!(reply.metrics.dual_residual <= reply.metrics.certificate_tolerance);
    }
    assert_eq!(a.metrics.lp_solver, PlanMetrics::SOLVER_DIJKSTRA);
    assert_eq!(b.metrics.lp_solver, PlanMetrics::SOLVER_CLARABEL);
    let (va, vb) = (a.metrics.objective, b.metrics.objective);
    assert!((va - vb).abs() <= 1e-6 * va, "exact {va} vs Clarabel {vb}");
    service.stop();
}

#[test]
fn a_new_map_of_the_same_geometry_is_a_generator_cache_hit() {
    let service = TestService::start(config("RT2_"));
    let first = c_shape_pf(1, 64);
    service.publish_request(&first);
    let reply = service.reply_to(1, WAIT);
    assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
    assert!(!reply.metrics.cache_hit);
    assert!(reply.metrics.generator_time > 0.0);
    // New heights (so new traversability), same geometry: only a new solve is needed.
    let mut second = c_shape_pf(2, 64);
    for h in &mut second.inline_map[0].heights {
        *h = 0.7 * *h + 0.05;
    }
    second.start_x += 0.5;
    service.publish_request(&second);
    let again = service.reply_to(2, WAIT);
    assert_eq!(again.status, PlanReply::STATUS_OK, "{}", again.error);
    assert!(again.metrics.cache_hit, "{:?}", again.metrics);
    assert_eq!(again.metrics.generator_time, 0.0);
    assert!(again.metrics.certified);
    assert_ne!(again.metrics.objective, reply.metrics.objective);
    service.stop();
}

#[test]
fn requests_beyond_the_limits_are_refused_at_once_with_the_limit_named() {
    let service = TestService::start(config("RT3_"));
    let map = flat_map(40, &[]);
    let mut tiny_speed = inline_request(1, PlanRequest::METHOD_ASTAR, &map, [0.5, 0.5], [9.0, 9.0]);
    tiny_speed.options.speed = 1e-18;
    let mut too_fast = inline_request(2, PlanRequest::METHOD_PF, &map, [0.5, 0.5], [9.0, 9.0]);
    too_fast.options.speed = 1e6;
    let mut big_clarabel = c_shape_pf(3, 256);
    big_clarabel.options.solver = PlanOptions::SOLVER_CLARABEL;
    let mut unknown_solver = c_shape_pf(4, 32);
    unknown_solver.options.solver = 9;
    let started = Instant::now();
    for request in [&tiny_speed, &too_fast, &big_clarabel, &unknown_solver] {
        service.publish_request(request);
    }
    for (id, words) in [(1, "samples"), (2, "speed"), (3, "clarabel"), (4, "solver")] {
        let reply = service.reply_to(id, WAIT);
        assert_eq!(
            reply.status,
            PlanReply::STATUS_INVALID_REQUEST,
            "{id}: {}",
            reply.error
        );
        assert!(reply.error.contains(words), "{id}: {}", reply.error);
    }
    assert!(
        started.elapsed() < Duration::from_secs(5),
        "refusals must not wait for planning: {:?}",
        started.elapsed()
    );
    service.stop();
}

/// max_solve_time bounds the P-F computation, generator build included: a 512² plan (about
/// 0.4 s on the 2-core development machine) with a 0.02 s limit is answered SOLVER_TIMEOUT within
/// the limit plus 10 % and 50 ms (plus a margin for a loaded test machine), and the stopped build
/// is not cached: the same request without a limit then succeeds. (With a 0.1 s limit a fast
/// machine could finish the build and stop in the LP solve instead, and the finished build is
/// rightly reused.)
#[test]
fn max_solve_time_is_kept_and_a_stopped_build_is_not_reused() {
    let service = TestService::start(config("RT4_"));
    let limit = 0.02;
    let mut limited = c_shape_pf(1, 512);
    limited.options.max_solve_time = limit;
    let started = Instant::now();
    service.publish_request(&limited);
    let reply = service.reply_to(1, WAIT);
    let elapsed = started.elapsed().as_secs_f64();
    assert_eq!(
        reply.status,
        PlanReply::STATUS_SOLVER_TIMEOUT,
        "{}",
        reply.error
    );
    assert!(
        reply
            .error
            .contains("time limit of 0.02 s reached during the generator build"),
        "{}",
        reply.error
    );
    assert!(
        elapsed <= limit * 1.1 + 0.05 + 0.25,
        "reply after {elapsed:.3} s for a {limit} s limit"
    );
    let mut unlimited = c_shape_pf(2, 512);
    unlimited.options.max_solve_time = 0.0;
    service.publish_request(&unlimited);
    let reply = service.reply_to(2, WAIT);
    assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
    assert!(!reply.metrics.cache_hit);
    service.stop();
}
