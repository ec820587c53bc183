//! A terrain map the service rejects on the map channel (NaN heights, too many cells) and that a
//! request then names by seq: the reply carries the reason of the rejection instead of only "no
//! map with seq N". The service remembers the last 64 rejections (bounded memory); a valid map
//! published later under the same seq replaces the rejection. memq only.

use crate::common;

use std::time::Duration;

use common::{config, flat_map, map_message, TestService};
use lcm_types::pfnav::{PlanReply, PlanRequest};

const WAIT: Duration = Duration::from_secs(60);

fn naming(id: i64, seq: i64) -> PlanRequest {
    PlanRequest {
        request_id: id,
        map_seq: seq,
        start_x: 0.5,
        start_y: 0.5,
        goal_x: 3.0,
        goal_y: 3.0,
        goal_radius: 0.3,
        method: PlanRequest::METHOD_DIJKSTRA,
        ..PlanRequest::default()
    }
}

/// A map rejected on the map channel (NaN heights, too many cells) and then named in a request:
/// the reply carries the rejection's reason, not only "no map with seq N"; a valid map
/// published later under the same seq replaces the rejection.
#[test]
fn regression_a_request_naming_a_rejected_map_gets_the_reason() {
    let mut cfg = config("REJ_");
    cfg.max_map_cells = 64 * 64;
    let service = TestService::start(cfg);
    let mut nan = map_message(&flat_map(16, &[]), 42);
    nan.heights[5] = f64::NAN;
    service.publish_map(&nan);
    let oversize = map_message(&flat_map(80, &[]), 43);
    service.publish_map(&oversize);
    let named = naming;
    // The map handler runs before the request handler for messages published in this order.
    service.publish_request(&named(1, 42));
    service.publish_request(&named(2, 43));
    service.publish_request(&named(3, 44));
    for (id, words) in [
        (
            1,
            ["map seq 42 was rejected when it was published: ", "finite"],
        ),
        (
            2,
            ["map seq 43 was rejected when it was published: ", "6400"],
        ),
        (3, ["holds no map with seq 44", "holds no map with seq 44"]),
    ] {
        let reply = service.reply_to(id, WAIT);
        assert_eq!(reply.status, PlanReply::STATUS_INVALID_MAP, "{id}");
        for w in words {
            assert!(
                reply.error.contains(w),
                "{id}: {w:?} not in {}",
                reply.error
            );
        }
    }
    service.publish_map(&map_message(&flat_map(16, &[]), 42));
    service.publish_request(&named(4, 42));
    let reply = service.reply_to(4, WAIT);
    assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
    service.stop();
}

/// Only the last 64 rejections are remembered: after 70 rejected maps the oldest six are
/// "no map with seq N" again, the newest still carry their reason.
#[test]
fn rejection_reasons_are_bounded_to_the_last_64() {
    let service = TestService::start(config("REJ64_"));
    for seq in 100..170 {
        let mut nan = map_message(&flat_map(8, &[]), seq);
        nan.heights[3] = f64::NAN;
        service.publish_map(&nan);
        if seq % 10 == 9 {
            // A round trip every ten maps: liblcm's per-subscription queue (30 by default)
            // never overflows, and every map was handled before the requests below.
            let id = 1000 + seq;
            service.publish_request(&naming(id, seq));
            let reply = service.reply_to(id, WAIT);
            assert!(
                reply.error.contains("was rejected"),
                "{seq}: {}",
                reply.error
            );
        }
    }
    service.publish_request(&naming(1, 100));
    service.publish_request(&naming(2, 105));
    service.publish_request(&naming(3, 106));
    service.publish_request(&naming(4, 169));
    for (id, words) in [
        (1, "holds no map with seq 100"),
        (2, "holds no map with seq 105"),
        (3, "map seq 106 was rejected when it was published: "),
        (4, "map seq 169 was rejected when it was published: "),
    ] {
        let reply = service.reply_to(id, WAIT);
        assert_eq!(reply.status, PlanReply::STATUS_INVALID_MAP, "{id}");
        assert!(reply.error.contains(words), "{id}: {}", reply.error);
    }
    service.stop();
}
