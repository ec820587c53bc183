//! An in-process service on `memq://` (or, inside the test network namespace, a `udpm://` URL)
//! and a client on the same LCM instance (memq delivers only within one instance).

#![allow(dead_code)] // each test binary uses a different part of this helper

use std::cell::Cell;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use lcm_transport::Lcm;
use lcm_types::pfnav::{FeedbackField, PlanReply, PlanRequest, ServiceStatus, TerrainMap};
use lcm_types::Message;
use pf_planner::map::GridMap;
use pf_planner_service::{ServiceConfig, ServiceReport};

thread_local! {
    /// On the thread that runs a service's LCM handlers: that service's `handler_id` (0 on every
    /// other thread). The tests of one binary run at once, so an allocation counter must tell its
    /// own service's thread from the others' (see `MaxAllocation`).
    pub static HANDLER_ID: Cell<u64> = const { Cell::new(0) };
}

/// The next `TestService::handler_id`.
static NEXT_HANDLER_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

pub struct TestService {
    pub lcm: &'static Lcm,
    pub config: ServiceConfig,
    shutdown: Arc<AtomicBool>,
    thread: Option<JoinHandle<anyhow::Result<ServiceReport>>>,
    pub replies: Receiver<PlanReply>,
    /// The value of `HANDLER_ID` on this service's handler thread.
    pub handler_id: u64,
    pub statuses: Receiver<ServiceStatus>,
    /// `feedback_field_t` messages, in the order the service sent them.
    pub fields: Receiver<FeedbackField>,
}

impl TestService {
    /// Starts the service with `config` on a fresh memq instance.
    pub fn start(config: ServiceConfig) -> Self {
        Self::start_on("memq://", config)
    }

    /// The service and the client on one LCM instance opened with `url` (a `udpm://` URL only
    /// inside the test network namespace).
    pub fn start_on(url: &str, config: ServiceConfig) -> Self {
        // Service logs in the test output (RUST_LOG=debug for more); once per test binary.
        let _ = tracing_subscriber::fmt()
            .with_env_filter(
                tracing_subscriber::EnvFilter::try_from_default_env()
                    .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
            )
            .with_test_writer()
            .try_init();
        // 'static so that the client subscriptions can live next to the service; one small
        // leaked instance per test.
        let lcm_arc = Arc::new(Lcm::open(url).expect("LCM URL opens"));
        let lcm: &'static Lcm = Box::leak(Box::new(Arc::clone(&lcm_arc)));
        let (reply_tx, replies) = mpsc::channel();
        let reply_sub = lcm
            .subscribe(&config.channels.reply, move |_, bytes| {
                let reply = PlanReply::decode(bytes).expect("the service publishes valid replies");
                let _ = reply_tx.send(reply);
            })
            .unwrap();
        reply_sub.set_queue_capacity(1_000_000).unwrap();
        std::mem::forget(reply_sub);
        let (status_tx, statuses) = mpsc::channel();
        let status_sub = lcm
            .subscribe(&config.channels.status, move |_, bytes| {
                let status = ServiceStatus::decode(bytes).expect("valid status");
                let _ = status_tx.send(status);
            })
            .unwrap();
        std::mem::forget(status_sub);
        let (field_tx, fields) = mpsc::channel();
        let field_sub = lcm
            .subscribe(&config.channels.feedback_field, move |_, bytes| {
                let field = FeedbackField::decode(bytes).expect("valid feedback field");
                let _ = field_tx.send(field);
            })
            .unwrap();
        field_sub.set_queue_capacity(1_000_000).unwrap();
        std::mem::forget(field_sub);
        let shutdown = Arc::new(AtomicBool::new(false));
        let handler_id = NEXT_HANDLER_ID.fetch_add(1, Ordering::SeqCst);
        let thread = {
            let (config, shutdown) = (config.clone(), Arc::clone(&shutdown));
            std::thread::Builder::new()
                .name("service".into())
                .spawn(move || {
                    HANDLER_ID.with(|t| t.set(handler_id));
                    pf_planner_service::run(lcm_arc, config, shutdown)
                })
                .unwrap()
        };
        // The first status means the service has subscribed (memq drops unheard messages).
        let first = statuses.recv_timeout(Duration::from_secs(30));
        assert!(first.is_ok(), "the service published no status within 30 s");
        Self {
            lcm,
            config,
            shutdown,
            thread: Some(thread),
            replies,
            handler_id,
            statuses,
            fields,
        }
    }

    pub fn publish_request(&self, request: &PlanRequest) {
        self.publish_raw(&self.config.channels.request, &request.encode().unwrap());
    }

    pub fn publish_map(&self, map: &TerrainMap) {
        self.publish_raw(&self.config.channels.map, &map.encode().unwrap());
    }

    pub fn publish_raw(&self, channel: &str, bytes: &[u8]) {
        self.lcm.publish(channel, bytes).unwrap();
    }

    /// Waits for the reply to `request_id`, skipping replies to other ids.
    pub fn reply_to(&self, request_id: i64, timeout: Duration) -> PlanReply {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.replies.recv_timeout(left) {
                Ok(reply) if reply.request_id == request_id => return reply,
                Ok(_) => continue,
                Err(_) => panic!("no reply to request {request_id} within {timeout:?}"),
            }
        }
    }

    /// Collects replies until `count` arrived for ids in `wanted` or the timeout passes;
    /// returns every reply received for those ids, grouped by id.
    pub fn collect(&self, wanted: &[i64], timeout: Duration) -> HashMap<i64, Vec<PlanReply>> {
        let mut by_id: HashMap<i64, Vec<PlanReply>> = HashMap::new();
        let deadline = Instant::now() + timeout;
        let mut answered = 0;
        while answered < wanted.len() {
            let left = deadline.saturating_duration_since(Instant::now());
            let Ok(reply) = self.replies.recv_timeout(left) else {
                break;
            };
            if wanted.contains(&reply.request_id) {
                let entry = by_id.entry(reply.request_id).or_default();
                if entry.is_empty() {
                    answered += 1;
                }
                entry.push(reply);
            }
        }
        // Late duplicates would show up here.
        while let Ok(reply) = self.replies.recv_timeout(Duration::from_millis(100)) {
            if wanted.contains(&reply.request_id) {
                by_id.entry(reply.request_id).or_default().push(reply);
            }
        }
        by_id
    }

    pub fn stop(mut self) -> ServiceReport {
        self.shutdown.store(true, Ordering::SeqCst);
        self.thread
            .take()
            .expect("stopped once")
            .join()
            .expect("service thread did not panic")
            .expect("service ran without error")
    }
}

impl Drop for TestService {
    fn drop(&mut self) {
        self.shutdown.store(true, Ordering::SeqCst);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// A config with a test-specific prefix.
pub fn config(prefix: &str) -> ServiceConfig {
    ServiceConfig::with_prefix(prefix).unwrap()
}

/// The wire form of a planner map.
pub fn map_message(map: &GridMap, seq: i64) -> TerrainMap {
    pf_planner_service::convert::map_to_message(map, seq)
}

/// A flat `n` x `n` map of 0.25 m cells at the origin, with optional obstacle cells.
pub fn flat_map(n: usize, obstacles: &[(usize, usize)]) -> GridMap {
    let mask = (!obstacles.is_empty()).then(|| {
        let mut mask = vec![false; n * n];
        for &(ix, iy) in obstacles {
            mask[iy * n + ix] = true;
        }
        mask
    });
    GridMap::new([0.0, 0.0], 0.25, n, n, vec![0.1; n * n], mask).unwrap()
}

/// A request to plan on `map` inline from `start` to a 0.3 m goal disc at `goal`.
pub fn inline_request(
    id: i64,
    method: i8,
    map: &GridMap,
    start: [f64; 2],
    goal: [f64; 2],
) -> PlanRequest {
    PlanRequest {
        request_id: id,
        num_inline_maps: 1,
        inline_map: vec![map_message(map, 1)],
        map_seq: -1,
        start_x: start[0],
        start_y: start[1],
        goal_x: goal[0],
        goal_y: goal[1],
        goal_radius: 0.3,
        method,
        ..PlanRequest::default()
    }
}
