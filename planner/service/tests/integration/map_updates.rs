//! The walking robot's loop over the service: a P-F plan comes with its feedback field (sent just
//! before the reply), map updates reveal cells under increasing seqs (an older or rewritten map
//! is rejected as stale, with the reason given to requests that name it), and an update that
//! changes only heights and known cells reuses the cached generators. memq only.

use crate::common;

use std::time::Duration;

use common::{config, flat_map, inline_request, map_message, TestService};
use lcm_types::pfnav::{PlanReply, PlanRequest};
use pf_planner::map::{GridMap, MapKnowledge};
use pf_planner_service::convert::partial_map_to_message;

const WAIT: Duration = Duration::from_secs(60);

fn naming(id: i64, seq: i64, method: i8) -> PlanRequest {
    PlanRequest {
        request_id: id,
        map_seq: seq,
        start_x: 0.4,
        start_y: 0.4,
        goal_x: 3.4,
        goal_y: 3.4,
        goal_radius: 0.3,
        method,
        ..PlanRequest::default()
    }
}

#[test]
fn a_pf_plan_sends_its_feedback_field_just_before_the_reply() {
    let service = TestService::start(config("FIELD_"));
    // 16 x 16 cells of 0.25 m, a short wall in the middle.
    let wall: Vec<(usize, usize)> = (4..12).map(|iy| (8, iy)).collect();
    let map = flat_map(16, &wall);
    service.publish_map(&map_message(&map, 3));
    service.publish_request(&naming(7, 3, PlanRequest::METHOD_PF));
    let reply = service.reply_to(7, WAIT);
    assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
    // The field was handled before the reply (published first, delivered in order).
    let field = service
        .fields
        .try_recv()
        .expect("the field arrives before its reply");
    assert_eq!(field.request_id, 7);
    assert_eq!(field.map_seq, 3);
    assert_eq!(
        field.header.seq, reply.header.seq,
        "field and reply share the reply counter"
    );
    assert_eq!(field.header.frame_id, "world");
    assert_eq!((field.width, field.height, field.num_cells), (16, 16, 256));
    assert_eq!(
        (field.origin_x, field.origin_y, field.resolution),
        (0.0, 0.0, 0.25)
    );
    assert_eq!(
        (field.goal_x, field.goal_y, field.goal_radius),
        (3.4, 3.4, 0.3)
    );
    let cell = |x: f64, y: f64| ((y / 0.25) as usize) * 16 + (x / 0.25) as usize;
    assert_eq!(field.cost_to_go[cell(3.4, 3.4)], 0.0, "target cell");
    for &(ix, iy) in &wall {
        let c = iy * 16 + ix;
        assert_eq!(field.cost_to_go[c], -1.0, "wall cell ({ix}, {iy})");
        assert_eq!(
            (field.dir_x[c], field.dir_y[c], field.speed[c]),
            (0.0, 0.0, 0.0)
        );
    }
    let start = cell(0.4, 0.4);
    assert!(field.cost_to_go[start] > 0.0);
    assert_eq!(field.speed[start], 0.5, "the request's default speed");
    let norm = f32::hypot(field.dir_x[start], field.dir_y[start]);
    assert!((norm - 1.0).abs() < 1e-6);
    // The reference leaves the start along the field's direction.
    let (a, b) = (
        &reply.samples[0],
        reply
            .samples
            .iter()
            .find(|s| (s.x - reply.samples[0].x).hypot(s.y - reply.samples[0].y) > 0.2)
            .expect("the reference moves"),
    );
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let along = f64::from(field.dir_x[start]) * dx + f64::from(field.dir_y[start]) * dy;
    assert!(
        along > 0.7 * dx.hypot(dy),
        "direction {:?} vs reference move ({dx}, {dy})",
        (field.dir_x[start], field.dir_y[start])
    );

    // Graph methods have no field.
    service.publish_request(&naming(8, 3, PlanRequest::METHOD_DIJKSTRA));
    let reply = service.reply_to(8, WAIT);
    assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
    assert!(service.fields.try_recv().is_err(), "no field for Dijkstra");
    service.stop();
}

/// The same 16² flat map with `bump` added to the heights of the cells in rows `rows`.
fn with_bump(rows: std::ops::Range<usize>, bump: f64) -> GridMap {
    let mut map = flat_map(16, &[]);
    for iy in rows {
        for ix in 0..16 {
            map.heights[iy * 16 + ix] += bump;
        }
    }
    map
}

#[test]
fn stale_map_updates_are_rejected_and_republication_is_accepted() {
    let service = TestService::start(config("STALE_"));
    let older = with_bump(0..0, 0.0);
    let newer = with_bump(2..4, 0.3);
    service.publish_map(&map_message(&older, 5));
    service.publish_map(&map_message(&newer, 7));
    // Seq 6 arrives late: below the latest accepted seq.
    service.publish_map(&map_message(&with_bump(5..6, 0.2), 6));
    // Seq 7 again with other content: an accepted seq is never rewritten...
    let mut rewritten = map_message(&newer, 7);
    rewritten.heights[0] = 2.0;
    service.publish_map(&rewritten);
    // ...but the identical map under its seq (a republication after loss) is fine.
    service.publish_map(&map_message(&newer, 7));
    // A stale seq with NaN heights keeps its own reason.
    let mut nan = map_message(&older, 4);
    nan.heights[3] = f64::NAN;
    service.publish_map(&nan);

    service.publish_request(&naming(1, 6, PlanRequest::METHOD_DIJKSTRA));
    let reply = service.reply_to(1, WAIT);
    assert_eq!(reply.status, PlanReply::STATUS_INVALID_MAP);
    assert!(
        reply.error.contains("stale map update: seq 6 < latest 7"),
        "{}",
        reply.error
    );
    service.publish_request(&naming(2, 4, PlanRequest::METHOD_DIJKSTRA));
    let reply = service.reply_to(2, WAIT);
    assert_eq!(reply.status, PlanReply::STATUS_INVALID_MAP);
    assert!(reply.error.contains("not finite"), "{}", reply.error);
    // Seq 7 (and "latest") is the first version: the rewrite did not replace it. Its cost
    // differs from the older map's, so the reply tells which one was planned on.
    let cost_on = |id: i64, seq: i64| {
        service.publish_request(&naming(id, seq, PlanRequest::METHOD_DIJKSTRA));
        let reply = service.reply_to(id, WAIT);
        assert_eq!(reply.status, PlanReply::STATUS_OK, "{id}: {}", reply.error);
        assert_eq!(reply.map_seq, if seq == -1 { 7 } else { seq });
        reply.metrics.cost
    };
    let on_5 = cost_on(3, 5);
    let on_7 = cost_on(4, 7);
    let on_latest = cost_on(5, -1);
    assert_eq!(on_7, on_latest);
    assert!(on_7 != on_5, "seq 7 is the bumped map");
    // A rewritten seq 7 would have a 2 m cell at the origin, next to the start (p there ≈ 1).
    let inline = inline_request(
        9,
        PlanRequest::METHOD_DIJKSTRA,
        &newer,
        [0.4, 0.4],
        [3.4, 3.4],
    );
    service.publish_request(&inline);
    let reply = service.reply_to(9, WAIT);
    assert_eq!(reply.metrics.cost, on_7);
    let report = service.stop();
    assert_eq!(report.maps_received, 3, "5, 7 and the republished 7");
}

#[test]
fn a_map_update_that_reveals_cells_reuses_the_generators_and_prices_unknown_cells() {
    let service = TestService::start(config("REVEAL_"));
    let wall: Vec<(usize, usize)> = (0..12).map(|iy| (8, iy)).collect();
    let map = flat_map(16, &wall);
    service.publish_map(&map_message(&map, 1));
    service.publish_request(&naming(1, 1, PlanRequest::METHOD_PF));
    let first = service.reply_to(1, WAIT);
    assert_eq!(first.status, PlanReply::STATUS_OK, "{}", first.error);
    assert!(!first.metrics.cache_hit);
    let first_field = service.fields.try_recv().expect("field");

    // The sensor has seen the left half (wall included); the right half is unknown, at p = 0.9.
    let mut revealed = map.clone();
    for h in revealed.heights.iter_mut().take(8 * 16) {
        *h = 0.05; // lower ground seen in the bottom rows
    }
    let known: Vec<bool> = (0..256).map(|c| c % 16 <= 8).collect();
    let knowledge = MapKnowledge::new(&revealed, known.clone(), 0.9).expect("knowledge");
    service.publish_map(&partial_map_to_message(&revealed, Some(&knowledge), 2));
    service.publish_request(&naming(2, 2, PlanRequest::METHOD_PF));
    let second = service.reply_to(2, WAIT);
    assert_eq!(second.status, PlanReply::STATUS_OK, "{}", second.error);
    assert!(
        second.metrics.cache_hit,
        "same blocked cells: cached generators"
    );
    let field = service.fields.try_recv().expect("field");
    assert_eq!(field.map_seq, 2);
    // Unknown cells cost the prior 0.9 per metre (h_max is the known 0.1 m, so known flat
    // ground costs 1 too, except the lower bottom rows): the goal's neighbourhood is unknown.
    // Cell (15, 13) is unknown, one cell east of the goal disc's cell (14, 13): the step
    // costs the prior, 0.9 × 0.25 m.
    let outside = 13 * 16 + 15;
    assert!(!known[outside]);
    assert_eq!(field.cost_to_go[13 * 16 + 14], 0.0, "in the goal disc");
    assert!(
        (field.cost_to_go[outside] - 0.9 * 0.25).abs() < 1e-6,
        "unknown neighbour of the goal: {}",
        field.cost_to_go[outside]
    );
    assert!(
        field.cost_to_go[0] != first_field.cost_to_go[0],
        "heights changed the costs"
    );

    // An obstacle flag on an unknown cell is ignored: a wall nobody has seen blocks nothing.
    let full_wall: Vec<(usize, usize)> = (0..16).map(|iy| (8, iy)).collect();
    let walled = flat_map(16, &full_wall);
    let mut blocked = inline_request(
        3,
        PlanRequest::METHOD_DIJKSTRA,
        &walled,
        [0.4, 0.4],
        [3.4, 3.4],
    );
    service.publish_request(&blocked);
    let reply = service.reply_to(3, WAIT);
    assert_eq!(
        reply.status,
        PlanReply::STATUS_GOAL_UNREACHABLE,
        "{}",
        reply.error
    );
    let unseen_wall =
        MapKnowledge::new(&walled, (0..256).map(|c| c % 16 != 8).collect(), 0.0 + 0.5)
            .expect("knowledge");
    blocked.request_id = 4;
    blocked.inline_map = vec![partial_map_to_message(&walled, Some(&unseen_wall), 1)];
    service.publish_request(&blocked);
    let reply = service.reply_to(4, WAIT);
    assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
    service.stop();
}
