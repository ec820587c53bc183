//! Round-trip latency (request published → reply received) through the service, next to the
//! bare planner call on the same request: a 64 x 64 map sent inline, and the `c_shape` scenario
//! published once on the map channel and named by its seq in every request (the real-time case:
//! P-F on a 128² grid with cached generators, and Dijkstra on the same grid as the baseline).
//! The transport is `memq://` (in-process; udpm adds the kernel's loopback multicast on top), so
//! the difference is the service's own cost: encode, decode, validation, queue hand-off, reply.
//! A table of medians is printed at the end.
//!
//! The last case is the walking robot's replan: a new version of the c_shape map (a sensor has
//! revealed more cells: known mask grown, heights of the revealed cells changed, same blocked
//! cells) is published under the next seq, then a P-F request names it; the time from publishing
//! the map to receiving the reply (the feedback field arrives just before it) is measured per
//! update, and its p50/p99 printed (target p50 ≤ 100 ms, p99 ≤ 200 ms).
//!
//! `cargo bench -p pf-planner-service --bench roundtrip -- --warm-up-time 1 --measurement-time 3`

use std::cell::RefCell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::Criterion;
use lcm_transport::Lcm;
use lcm_types::pfnav::{FeedbackField, Header, PlanReply, PlanRequest, TerrainMap};
use lcm_types::Message;
use pf_planner::map::MapKnowledge;
use pf_planner::scenarios;
use pf_planner::traversability::TraversabilityParams;
use pf_planner_service::convert::{
    map_to_message, partial_map_to_message, validate_request, MapSource, OptionDefaults,
    ReceivedMap,
};
use pf_planner_service::planning::{self, GeneratorCache};
use pf_planner_service::ServiceConfig;

const SIDE: usize = 64;
/// Seq under which the c_shape map is published.
const PUBLISHED_SEQ: i64 = 7;
/// P-F planning grid of the published-map case.
const PUBLISHED_GRID: i32 = 128;

/// Medians of criterion's samples, by benchmark name.
struct Recorder(RefCell<Vec<(String, f64)>>);

impl Recorder {
    /// Benchmarks `routine` under `name` and records its median time.
    fn measure(&self, c: &mut Criterion, name: &str, mut routine: impl FnMut()) {
        let samples = RefCell::new(Vec::new());
        c.bench_function(name, |b| {
            b.iter_custom(|iters| {
                let started = Instant::now();
                for _ in 0..iters {
                    routine();
                }
                let elapsed = started.elapsed();
                samples
                    .borrow_mut()
                    .push(elapsed.as_secs_f64() / iters as f64);
                elapsed
            })
        });
        let mut times = samples.into_inner();
        times.sort_by(f64::total_cmp);
        let median = times.get(times.len() / 2).copied().unwrap_or(f64::NAN);
        self.0.borrow_mut().push((name.to_owned(), median));
    }
}

/// A request naming the published c_shape map.
fn published_request(id: i64, method: i8) -> PlanRequest {
    let scenario = scenarios::by_name("c_shape").expect("scenario");
    let mut request = PlanRequest {
        request_id: id,
        map_seq: PUBLISHED_SEQ,
        start_x: scenario.start[0],
        start_y: scenario.start[1],
        goal_x: scenario.goal.center[0],
        goal_y: scenario.goal.center[1],
        goal_radius: scenario.goal.radius,
        method,
        ..PlanRequest::default()
    };
    request.options.grid_size = PUBLISHED_GRID;
    request
}

/// The published map, for the bare planner calls.
struct PublishedMap(Arc<ReceivedMap>);
impl MapSource for PublishedMap {
    fn map_by_seq(&self, seq: i64) -> Option<(i64, Arc<ReceivedMap>)> {
        (seq == PUBLISHED_SEQ).then(|| (seq, Arc::clone(&self.0)))
    }
}

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
        ..TerrainMap::default()
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
    fn map_by_seq(&self, _: i64) -> Option<(i64, Arc<ReceivedMap>)> {
        None
    }
}

/// Publishes `msg` with a fresh id and waits for its reply.
fn round_trip(
    lcm: &Lcm,
    channel: &str,
    replies: &mpsc::Receiver<PlanReply>,
    msg: &PlanRequest,
    id: i64,
) -> PlanReply {
    let mut m = msg.clone();
    m.request_id = id;
    lcm.publish(channel, &m.encode().expect("encodes"))
        .expect("publish");
    loop {
        let reply = replies
            .recv_timeout(Duration::from_secs(60))
            .expect("reply");
        if reply.request_id == id {
            assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
            return reply;
        }
    }
}

fn main() {
    let mut c = Criterion::default()
        .sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
        .configure_from_args();
    let rec = Recorder(RefCell::new(Vec::new()));
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
    let traversability = TraversabilityParams::default();
    let mut id = 0;
    for (name, method) in [
        ("dijkstra", PlanRequest::METHOD_DIJKSTRA),
        ("pf", PlanRequest::METHOD_PF),
    ] {
        let msg = request(1, method);
        let validated =
            validate_request(&msg, &NoMaps, 1 << 20, &OptionDefaults::default()).expect("valid");
        rec.measure(
            &mut c,
            &format!("64² inline map, {name}: bare planner"),
            || {
                planning::plan(&validated, &cache, &traversability).expect("plans");
            },
        );
        rec.measure(
            &mut c,
            &format!("64² inline map, {name}: service round trip"),
            || {
                id += 1;
                round_trip(&lcm, &config.channels.request, &replies, &msg, id);
            },
        );
    }

    let scenario = scenarios::by_name("c_shape").expect("scenario");
    let published = map_to_message(&scenario.map, PUBLISHED_SEQ);
    lcm.publish(&config.channels.map, &published.encode().expect("encodes"))
        .expect("publish map");
    let maps = PublishedMap(Arc::new(ReceivedMap::known(scenario.map.clone())));
    // The service stores the map asynchronously: the first request may race it.
    let first = published_request(0, PlanRequest::METHOD_PF);
    let stored = Instant::now();
    loop {
        id += 1;
        let mut m = first.clone();
        m.request_id = id;
        lcm.publish(&config.channels.request, &m.encode().expect("encodes"))
            .expect("publish");
        let reply = loop {
            let r = replies
                .recv_timeout(Duration::from_secs(60))
                .expect("reply");
            if r.request_id == id {
                break r;
            }
        };
        if reply.status == PlanReply::STATUS_OK {
            break;
        }
        assert!(
            stored.elapsed() < Duration::from_secs(10),
            "published map never stored: {}",
            reply.error
        );
    }
    for (name, method) in [
        ("dijkstra", PlanRequest::METHOD_DIJKSTRA),
        ("pf", PlanRequest::METHOD_PF),
    ] {
        let msg = published_request(1, method);
        let validated =
            validate_request(&msg, &maps, 1 << 20, &OptionDefaults::default()).expect("valid");
        rec.measure(
            &mut c,
            &format!("c_shape published, {PUBLISHED_GRID}² {name}: bare planner"),
            || {
                planning::plan(&validated, &cache, &traversability).expect("plans");
            },
        );
        rec.measure(
            &mut c,
            &format!("c_shape published, {PUBLISHED_GRID}² {name}: service round trip"),
            || {
                id += 1;
                round_trip(&lcm, &config.channels.request, &replies, &msg, id);
            },
        );
    }
    let (fields_tx, fields) = mpsc::channel::<FeedbackField>();
    let _field_sub = lcm
        .subscribe(&config.channels.feedback_field, move |_, bytes| {
            let _ = fields_tx.send(FeedbackField::decode(bytes).expect("valid field"));
        })
        .expect("subscribe");
    let updates = map_updates(&lcm, &config, &replies, &fields, &mut id);
    shutdown.store(true, Ordering::SeqCst);
    let _ = service.join();
    c.final_summary();

    println!();
    println!("medians of criterion's samples (memq://; target: 128² P-F round trip ≤ 100 ms)");
    println!("| case | median |");
    println!("|---|---:|");
    for (name, median) in rec.0.borrow().iter() {
        println!("| {name} | {:.2} ms |", median * 1e3);
    }
    let percentile = |q: f64| updates[((updates.len() - 1) as f64 * q).round() as usize] * 1e3;
    println!(
        "| map update → P-F reply with field, {PUBLISHED_GRID}², {} updates | p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms |",
        updates.len(),
        percentile(0.5),
        percentile(0.99),
        percentile(1.0)
    );
}

/// Map updates of the walking robot: the c_shape map revealed column band by column band
/// (known mask grows, revealed heights change, blocked cells stay), each published under the
/// next seq and planned on at once. Returns the sorted latencies (map published → reply), s.
fn map_updates(
    lcm: &Lcm,
    config: &ServiceConfig,
    replies: &mpsc::Receiver<PlanReply>,
    fields: &mpsc::Receiver<FeedbackField>,
    id: &mut i64,
) -> Vec<f64> {
    const UPDATES: usize = 200;
    let scenario = scenarios::by_name("c_shape").expect("scenario");
    let map = &scenario.map;
    let mut latencies = Vec::with_capacity(UPDATES);
    for update in 0..UPDATES {
        let seq = PUBLISHED_SEQ + 1 + update as i64;
        // Everything left of a sweeping column is known; the rest keeps the prior.
        let seen = (update * 7) % map.width + 1;
        let known: Vec<bool> = (0..map.len()).map(|c| c % map.width < seen).collect();
        let mut revealed = map.clone();
        for (h, &k) in revealed.heights.iter_mut().zip(&known) {
            if k {
                *h *= 1.0 + 0.01 * (update % 5) as f64;
            }
        }
        let knowledge = MapKnowledge::new(&revealed, known, 0.5).expect("knowledge");
        let message = partial_map_to_message(&revealed, Some(&knowledge), seq);
        let mut request = published_request(0, PlanRequest::METHOD_PF);
        request.map_seq = seq;
        *id += 1;
        request.request_id = *id;
        let started = Instant::now();
        lcm.publish(&config.channels.map, &message.encode().expect("encodes"))
            .expect("publish map");
        lcm.publish(
            &config.channels.request,
            &request.encode().expect("encodes"),
        )
        .expect("publish request");
        let reply = loop {
            let r = replies
                .recv_timeout(Duration::from_secs(60))
                .expect("reply");
            if r.request_id == *id {
                break r;
            }
        };
        latencies.push(started.elapsed().as_secs_f64());
        assert_eq!(reply.status, PlanReply::STATUS_OK, "{}", reply.error);
        assert!(
            reply.metrics.cache_hit,
            "a map update must reuse the generators"
        );
        let field = loop {
            let f = fields
                .recv_timeout(Duration::from_secs(1))
                .expect("the field arrives before the reply");
            if f.request_id == *id {
                break f;
            }
        };
        assert_eq!(field.map_seq, seq);
    }
    latencies.sort_by(f64::total_cmp);
    latencies
}
