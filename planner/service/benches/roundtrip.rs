//! Round-trip latency (request published → reply received) through the service on a 64 x 64
//! map, next to the bare planner call on the same request. The transport is `memq://`
//! (in-process; udpm adds the kernel's loopback multicast on top), so the difference is the
//! service's own cost: encode, decode, validation, queue hand-off, reply.
//!
//! `cargo bench -p pf-planner-service --bench roundtrip -- --warm-up-time 1 --measurement-time 3`

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use lcm_transport::Lcm;
use lcm_types::pfnav::{Header, PlanReply, PlanRequest, TerrainMap};
use lcm_types::Message;
use pf_planner::traversability::TraversabilityParams;
use pf_planner_service::convert::{validate_request, MapSource, OptionDefaults};
use pf_planner_service::planning::{self, GeneratorCache};
use pf_planner_service::ServiceConfig;

const SIDE: usize = 64;

fn request(id: i64, method: i8) -> PlanRequest {
    let n = SIDE * SIDE;
    // Gentle deterministic relief so that costs vary across the map.
    let heights = (0..n)
        .map(|i| {
            let (x, y) = ((i % SIDE) as f64, (i / SIDE) as f64);
            0.2 + 0.1 * (0.2 * x).sin() * (0.15 * y).cos()
        })
        .collect();
    let map = TerrainMap {
        header: Header {
            utime: 0,
            seq: 1,
            frame_id: "world".into(),
        },
        origin_x: 0.0,
        origin_y: 0.0,
        resolution: 0.25,
        width: SIDE as i32,
        height: SIDE as i32,
        num_cells: n as i32,
        heights,
        num_obstacle_cells: 0,
        obstacle_mask: Vec::new(),
    };
    PlanRequest {
        request_id: id,
        num_inline_maps: 1,
        inline_map: vec![map],
        start_x: 0.5,
        start_y: 0.5,
        goal_x: 15.0,
        goal_y: 14.0,
        goal_radius: 0.5,
        method,
        ..PlanRequest::default()
    }
}

struct NoMaps;
impl MapSource for NoMaps {
    fn map_by_seq(&self, _: i64) -> Option<(i64, Arc<pf_planner::map::GridMap>)> {
        None
    }
}

fn bench(c: &mut Criterion) {
    let lcm = Arc::new(Lcm::open("memq://").expect("memq"));
    let config = ServiceConfig::with_prefix("BENCH_").expect("prefix");
    let (tx, replies) = mpsc::channel::<PlanReply>();
    let _sub = lcm
        .subscribe(&config.channels.reply, move |_, bytes| {
            let _ = tx.send(PlanReply::decode(bytes).expect("valid reply"));
        })
        .expect("subscribe");
    let shutdown = Arc::new(AtomicBool::new(false));
    let service = {
        let (lcm, config, shutdown) = (Arc::clone(&lcm), config.clone(), Arc::clone(&shutdown));
        std::thread::spawn(move || pf_planner_service::run(lcm, config, shutdown))
    };
    let cache = GeneratorCache::new(4);
    let mut group = c.benchmark_group("plan_64x64");
    for (name, method) in [
        ("dijkstra", PlanRequest::METHOD_DIJKSTRA),
        ("pf", PlanRequest::METHOD_PF),
    ] {
        let msg = request(1, method);
        let validated =
            validate_request(&msg, &NoMaps, 1 << 20, &OptionDefaults::default()).expect("valid");
        group.bench_function(format!("{name}/bare_planner"), |b| {
            b.iter(|| {
                planning::plan(&validated, &cache, &TraversabilityParams::default()).expect("plans")
            })
        });
        let mut id = 0;
        group.bench_function(format!("{name}/service_roundtrip_memq"), |b| {
            b.iter(|| {
                id += 1;
                let mut m = msg.clone();
                m.request_id = id;
                lcm.publish(&config.channels.request, &m.encode().expect("encodes"))
                    .expect("publish");
                loop {
                    let reply = replies
                        .recv_timeout(Duration::from_secs(60))
                        .expect("reply");
                    if reply.request_id == id {
                        assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
                        break reply;
                    }
                }
            })
        });
    }
    group.finish();
    shutdown.store(true, Ordering::SeqCst);
    let _ = service.join();
}

criterion_group!(benches, bench);
criterion_main!(benches);
