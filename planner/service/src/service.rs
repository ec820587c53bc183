//! The service loop: LCM handlers validate and enqueue, a worker pool plans, a status thread
//! reports once a period. The LCM handler thread never plans: it decodes, validates, and either
//! enqueues the job or answers at once (invalid request, busy).

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use crossbeam_channel::{Receiver, Sender, TrySendError};
use lcm_transport::Lcm;
use lcm_types::pfnav::{
    FeedbackField, Header, PlanMetrics, PlanReply, PlanRequest, ServiceStatus, TerrainMap,
};
use lcm_types::{DecodeLimits, Message};
use pf_planner::traversability::TraversabilityParams;
use tracing::{debug, error, info, warn};

use crate::convert::{self, MapSource, OptionDefaults, ReceivedMap, Rejection, ValidatedRequest};
use crate::planning::{self, GeneratorCache, PlanOutcome};
use crate::preflight;

/// Channel names of one service instance: `<prefix>MAP`, `<prefix>PLAN_REQUEST`,
/// `<prefix>PLAN_REPLY`, `<prefix>FEEDBACK_FIELD`, `<prefix>SERVICE_STATUS`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Channels {
    pub map: String,
    pub request: String,
    pub reply: String,
    /// `feedback_field_t` of every successful P-F plan, sent just before its reply.
    pub feedback_field: String,
    pub status: String,
}

/// Default channel prefix.
pub const DEFAULT_CHANNEL_PREFIX: &str = lcm_types::channels::DEFAULT_PREFIX;

impl Channels {
    /// The five channels under `prefix`; every name must fit LCM's 63-byte limit and be a
    /// plain name (the subscription side treats names as regular expressions).
    pub fn with_prefix(prefix: &str) -> anyhow::Result<Self> {
        let plain = prefix
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '/');
        anyhow::ensure!(
            plain,
            "channel prefix {prefix:?} may only contain ASCII letters, digits, '_', '-' and '/'"
        );
        use lcm_types::channels::planner;
        let channels = Self {
            map: format!("{prefix}{}", planner::MAP),
            request: format!("{prefix}{}", planner::PLAN_REQUEST),
            reply: format!("{prefix}{}", planner::PLAN_REPLY),
            feedback_field: format!("{prefix}{}", planner::FEEDBACK_FIELD),
            status: format!("{prefix}{}", planner::SERVICE_STATUS),
        };
        let longest = [
            &channels.map,
            &channels.request,
            &channels.reply,
            &channels.feedback_field,
            &channels.status,
        ]
        .into_iter()
        .max_by_key(|name| name.len())
        .unwrap_or(&channels.status);
        anyhow::ensure!(
            longest.len() <= lcm_transport::MAX_CHANNEL_LEN,
            "channel prefix {prefix:?} is too long: {longest:?} has {} bytes, LCM allows {}",
            longest.len(),
            lcm_transport::MAX_CHANNEL_LEN
        );
        Ok(channels)
    }
}

/// Everything the service is configured with.
#[derive(Debug, Clone)]
pub struct ServiceConfig {
    pub channels: Channels,
    /// Largest map (cells) accepted, inline or on the map channel.
    pub max_map_cells: usize,
    /// Planner threads.
    pub workers: usize,
    /// Requests that may wait for a worker; more are answered with STATUS_BUSY.
    pub queue_capacity: usize,
    /// Bytes of request packets (inline maps) that may wait for a worker together; a request
    /// that would exceed it is answered with STATUS_BUSY. Bounds the queue's memory whatever
    /// `queue_capacity` is.
    pub max_queued_bytes: usize,
    /// Generator sets (map + settings) kept for reuse.
    pub cache_capacity: usize,
    /// Maps from the map channel kept for requests that refer to them by seq.
    pub stored_maps: usize,
    /// Period of the status message.
    pub status_period: Duration,
    /// Defaults for request options left at 0.
    pub defaults: OptionDefaults,
    /// Traversability model of every plan (the wire contract has no field for it): the paper's
    /// p = h/h_max by default; `--footprint-radius` sets the robot's footprint.
    pub traversability: TraversabilityParams,
}

impl ServiceConfig {
    /// The documented defaults with the given channel prefix.
    pub fn with_prefix(prefix: &str) -> anyhow::Result<Self> {
        Ok(Self {
            channels: Channels::with_prefix(prefix)?,
            max_map_cells: 512 * 512,
            workers: 2,
            queue_capacity: 2048,
            max_queued_bytes: 128 << 20,
            cache_capacity: 4,
            stored_maps: 8,
            status_period: Duration::from_secs(1),
            defaults: OptionDefaults::default(),
            traversability: TraversabilityParams::default(),
        })
    }

    fn check(&self) -> anyhow::Result<()> {
        anyhow::ensure!(self.workers >= 1, "--workers must be at least 1");
        anyhow::ensure!(self.queue_capacity >= 1, "--queue must be at least 1");
        anyhow::ensure!(
            self.max_map_cells >= 1,
            "--max-map-cells must be at least 1"
        );
        anyhow::ensure!(!self.status_period.is_zero(), "status period must be > 0");
        self.traversability
            .validate()
            .map_err(|e| anyhow::anyhow!("traversability model: {e}"))?;
        Ok(())
    }
}

/// Counters reported in `service_status_t`.
#[derive(Debug)]
struct Stats {
    started: Instant,
    requests_received: AtomicI64,
    requests_served: AtomicI64,
    requests_failed: AtomicI64,
    requests_busy: AtomicI64,
    malformed: AtomicI64,
    maps_received: AtomicI64,
    latest_map_seq: AtomicI64,
    last_solve_time_bits: AtomicU64,
    queue_depth: AtomicUsize,
    queued_bytes: AtomicUsize,
    status_seq: AtomicI64,
    reply_seq: AtomicI64,
}

impl Stats {
    fn new() -> Self {
        Self {
            started: Instant::now(),
            requests_received: AtomicI64::new(0),
            requests_served: AtomicI64::new(0),
            requests_failed: AtomicI64::new(0),
            requests_busy: AtomicI64::new(0),
            malformed: AtomicI64::new(0),
            maps_received: AtomicI64::new(0),
            latest_map_seq: AtomicI64::new(-1),
            last_solve_time_bits: AtomicU64::new(0f64.to_bits()),
            queue_depth: AtomicUsize::new(0),
            queued_bytes: AtomicUsize::new(0),
            status_seq: AtomicI64::new(0),
            reply_seq: AtomicI64::new(0),
        }
    }
}

/// Counters at the end of a run (also useful to tests).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ServiceReport {
    pub requests_received: i64,
    pub requests_served: i64,
    pub requests_failed: i64,
    pub requests_rejected_busy: i64,
    pub malformed_messages: i64,
    pub maps_received: i64,
}

/// Maps received on the map channel, newest first.
#[derive(Debug)]
struct MapStore {
    capacity: usize,
    held: Mutex<HeldMaps>,
    /// The most recent rejections (seq, reason), newest first, at most [`REJECTIONS_KEPT`].
    rejected: Mutex<VecDeque<(i64, String)>>,
}

#[derive(Debug, Default)]
struct HeldMaps {
    /// Newest (highest seq) first.
    maps: VecDeque<(i64, Arc<ReceivedMap>)>,
    /// Highest seq ever accepted: the map updates are ordered by it.
    highest_seq: Option<i64>,
}

/// What became of a valid map published on the map channel.
#[derive(Debug, Clone, PartialEq, Eq)]
enum MapUpdate {
    /// A new map under a new, highest seq.
    Stored,
    /// The identical map under a seq already held (a client republishing after loss).
    Republished,
    /// An older seq, or an accepted seq with other content: refused with this reason.
    Stale(String),
}

/// Rejected maps whose reason is remembered.
const REJECTIONS_KEPT: usize = 64;
/// Longest remembered rejection reason, bytes (keeps the store's memory bounded).
const REJECTION_REASON_MAX: usize = 512;

impl MapStore {
    fn new(capacity: usize) -> Self {
        Self {
            capacity,
            held: Mutex::new(HeldMaps::default()),
            rejected: Mutex::new(VecDeque::new()),
        }
    }

    /// Accepts `map` under `seq` when seq is above every accepted one, or when it repeats a
    /// held map exactly; anything else is a stale update (maps are revealed as the robot walks,
    /// so an older or rewritten map must not replace what planning already saw).
    fn update(&self, seq: i64, map: ReceivedMap) -> MapUpdate {
        let mut held = self.held.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(highest) = held.highest_seq.filter(|&h| seq <= h) {
            let same = held.maps.iter().any(|(s, m)| *s == seq && **m == map);
            return if same {
                MapUpdate::Republished
            } else if seq < highest {
                MapUpdate::Stale(format!("stale map update: seq {seq} < latest {highest}"))
            } else {
                MapUpdate::Stale(format!(
                    "stale map update: seq {seq} was already accepted with different content (publish changes under a higher seq)"
                ))
            };
        }
        held.highest_seq = Some(seq);
        held.maps.push_front((seq, Arc::new(map)));
        held.maps.truncate(self.capacity.max(1));
        drop(held);
        let mut rejected = self.rejected.lock().unwrap_or_else(PoisonError::into_inner);
        rejected.retain(|(s, _)| *s != seq);
        MapUpdate::Stored
    }

    fn reject(&self, seq: i64, reason: &str) {
        let mut reason = reason.to_owned();
        if reason.len() > REJECTION_REASON_MAX {
            let mut end = REJECTION_REASON_MAX;
            while !reason.is_char_boundary(end) {
                end -= 1;
            }
            reason.truncate(end);
            reason.push('…');
        }
        let mut rejected = self.rejected.lock().unwrap_or_else(PoisonError::into_inner);
        rejected.retain(|(s, _)| *s != seq);
        rejected.push_front((seq, reason));
        rejected.truncate(REJECTIONS_KEPT);
    }

    /// Why the map with `seq` was rejected, if it is one of the last [`REJECTIONS_KEPT`]
    /// rejections and no valid map with that seq arrived since.
    fn rejection(&self, seq: i64) -> Option<String> {
        let rejected = self.rejected.lock().unwrap_or_else(PoisonError::into_inner);
        rejected
            .iter()
            .find(|(s, _)| *s == seq)
            .map(|(_, reason)| reason.clone())
    }

    /// A request that names a stored-map seq the store does not hold gets the reason that map
    /// was rejected, when it was one of the recent rejections.
    fn explain_missing_map(&self, msg: &PlanRequest, rejection: Rejection) -> Rejection {
        let names_stored_map = msg.num_inline_maps == 0 && msg.map_seq != -1;
        if rejection.status != PlanReply::STATUS_INVALID_MAP
            || !names_stored_map
            || self.map_by_seq(msg.map_seq).is_some()
        {
            return rejection;
        }
        match self.rejection(msg.map_seq) {
            Some(reason) => Rejection::new(
                PlanReply::STATUS_INVALID_MAP,
                format!(
                    "map seq {} was rejected when it was published: {reason}",
                    msg.map_seq
                ),
            ),
            None => rejection,
        }
    }
}

impl MapSource for MapStore {
    fn map_by_seq(&self, seq: i64) -> Option<(i64, Arc<ReceivedMap>)> {
        let held = self.held.lock().unwrap_or_else(PoisonError::into_inner);
        if seq == -1 {
            held.maps.front().cloned()
        } else {
            held.maps.iter().find(|(s, _)| *s == seq).cloned()
        }
    }
}

/// State shared by the handlers, the workers and the status thread.
struct Shared {
    lcm: Arc<Lcm>,
    config: ServiceConfig,
    stats: Stats,
    maps: MapStore,
    cache: GeneratorCache,
    shutdown: Arc<AtomicBool>,
}

struct Job {
    request: ValidatedRequest,
    received: Instant,
    /// Charged against `max_queued_bytes` while the job waits: the packet's size, twice (the
    /// decoded inline map holds about as much again as its wire form).
    queued_bytes: usize,
}

fn now_utime() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_micros()).unwrap_or(i64::MAX))
}

fn header(seq: i64) -> Header {
    Header {
        utime: now_utime(),
        seq,
        frame_id: "world".to_owned(),
    }
}

impl Shared {
    fn publish_reply(&self, reply: PlanReply) {
        self.publish_reply_after_field(reply, None);
    }

    /// Publishes `field` (if any) on the feedback-field channel, then `reply`: a client that
    /// has the reply already holds the field of the same request. Both carry the same
    /// `header.seq` (the reply counter).
    fn publish_reply_after_field(&self, mut reply: PlanReply, field: Option<FeedbackField>) {
        let seq = self.stats.reply_seq.fetch_add(1, Ordering::SeqCst);
        if let Some(mut field) = field {
            field.header = header(seq);
            field.request_id = reply.request_id;
            field.map_seq = reply.map_seq;
            match field.encode() {
                Ok(bytes) => {
                    if let Err(e) = self
                        .lcm
                        .publish(&self.config.channels.feedback_field, &bytes)
                    {
                        error!(request_id = reply.request_id, error = %e, "could not publish the feedback field");
                    }
                }
                Err(e) => {
                    error!(request_id = reply.request_id, error = %e, "could not encode the feedback field")
                }
            }
        }
        reply.header = header(seq);
        if reply.status == PlanReply::STATUS_OK {
            self.stats.requests_served.fetch_add(1, Ordering::SeqCst);
        } else {
            self.stats.requests_failed.fetch_add(1, Ordering::SeqCst);
            if reply.status == PlanReply::STATUS_BUSY {
                self.stats.requests_busy.fetch_add(1, Ordering::SeqCst);
            }
        }
        let encoded = reply.encode();
        match encoded {
            Ok(bytes) => {
                if let Err(e) = self.lcm.publish(&self.config.channels.reply, &bytes) {
                    error!(request_id = reply.request_id, error = %e, "could not publish the reply");
                }
            }
            Err(e) => {
                error!(request_id = reply.request_id, error = %e, "could not encode the reply")
            }
        }
    }

    fn reject(
        &self,
        request_id: i64,
        method: i8,
        map_seq: i64,
        rejection: Rejection,
        solve_time: f64,
    ) {
        debug!(request_id, status = rejection.status, reason = %rejection.reason, "request rejected");
        self.publish_reply(PlanReply {
            request_id,
            status: rejection.status,
            error: rejection.reason,
            method,
            map_seq,
            metrics: PlanMetrics {
                solve_time,
                objective: f64::NAN,
                ..PlanMetrics::default()
            },
            ..PlanReply::default()
        });
    }

    fn status_message(&self) -> ServiceStatus {
        let s = &self.stats;
        let clamp = |n: usize| i32::try_from(n).unwrap_or(i32::MAX);
        ServiceStatus {
            header: header(s.status_seq.fetch_add(1, Ordering::SeqCst)),
            uptime: s.started.elapsed().as_secs_f64(),
            requests_received: s.requests_received.load(Ordering::SeqCst),
            requests_served: s.requests_served.load(Ordering::SeqCst),
            requests_failed: s.requests_failed.load(Ordering::SeqCst),
            requests_rejected_busy: s.requests_busy.load(Ordering::SeqCst),
            malformed_messages: s.malformed.load(Ordering::SeqCst),
            maps_received: s.maps_received.load(Ordering::SeqCst),
            latest_map_seq: s.latest_map_seq.load(Ordering::SeqCst),
            last_solve_time: f64::from_bits(s.last_solve_time_bits.load(Ordering::SeqCst)),
            queue_depth: clamp(s.queue_depth.load(Ordering::SeqCst)),
            queue_capacity: clamp(self.config.queue_capacity),
            cached_generators: clamp(self.cache.len()),
        }
    }

    fn publish_status(&self) {
        match self.status_message().encode() {
            Ok(bytes) => {
                if let Err(e) = self.lcm.publish(&self.config.channels.status, &bytes) {
                    warn!(error = %e, "could not publish the service status");
                }
            }
            Err(e) => error!(error = %e, "could not encode the service status"),
        }
    }

    fn report(&self) -> ServiceReport {
        let s = &self.stats;
        ServiceReport {
            requests_received: s.requests_received.load(Ordering::SeqCst),
            requests_served: s.requests_served.load(Ordering::SeqCst),
            requests_failed: s.requests_failed.load(Ordering::SeqCst),
            requests_rejected_busy: s.requests_busy.load(Ordering::SeqCst),
            malformed_messages: s.malformed.load(Ordering::SeqCst),
            maps_received: s.maps_received.load(Ordering::SeqCst),
        }
    }

    fn decode_limits(&self) -> DecodeLimits {
        DecodeLimits {
            max_array_len: self.config.max_map_cells,
            ..DecodeLimits::default()
        }
    }

    /// Handler of the map channel: size check on the raw claims, decode, validate, store.
    fn on_map(&self, bytes: &[u8]) {
        let Some(claim) = preflight::peek_map(bytes) else {
            self.stats.malformed.fetch_add(1, Ordering::Relaxed);
            debug!(
                len = bytes.len(),
                "map channel: not a terrain_map_t (fingerprint or length)"
            );
            return;
        };
        if let Err(rejection) = convert::check_map_size(
            claim.width,
            claim.height,
            claim.num_cells,
            self.config.max_map_cells,
        ) {
            self.stats.malformed.fetch_add(1, Ordering::Relaxed);
            warn!(seq = claim.seq, reason = %rejection.reason, "map rejected before decoding");
            self.maps.reject(claim.seq, &rejection.reason);
            return;
        }
        let map = TerrainMap::decode_with_limits(bytes, &self.decode_limits())
            .map_err(|e| Rejection::new(PlanReply::STATUS_INVALID_MAP, e.to_string()))
            .and_then(|msg| {
                convert::map_from_message(&msg, self.config.max_map_cells)
                    .map(|map| (msg.header.seq, map))
            });
        match map {
            Ok((seq, map)) => {
                let (width, height) = (map.map.width, map.map.height);
                let known = map.knowledge.as_ref().map(|k| k.known_count());
                match self.maps.update(seq, map) {
                    MapUpdate::Stored => {
                        self.stats.maps_received.fetch_add(1, Ordering::SeqCst);
                        self.stats.latest_map_seq.store(seq, Ordering::SeqCst);
                        info!(seq, width, height, ?known, "map stored");
                    }
                    MapUpdate::Republished => {
                        self.stats.maps_received.fetch_add(1, Ordering::SeqCst);
                        debug!(seq, "map republished unchanged");
                    }
                    MapUpdate::Stale(reason) => {
                        warn!(seq, %reason, "map rejected");
                        self.maps.reject(seq, &reason);
                    }
                }
            }
            Err(rejection) => {
                self.stats.malformed.fetch_add(1, Ordering::Relaxed);
                warn!(seq = claim.seq, reason = %rejection.reason, "map rejected");
                self.maps.reject(claim.seq, &rejection.reason);
            }
        }
    }

    /// Handler of the request channel: never plans; answers at once or enqueues.
    fn on_request(&self, bytes: &[u8], queue: &Sender<Job>) {
        let received = Instant::now();
        let Some(peek) = preflight::peek_request(bytes) else {
            self.stats.malformed.fetch_add(1, Ordering::Relaxed);
            debug!(len = bytes.len(), "request channel: not a plan_request_t");
            return;
        };
        // An undecodable packet whose id cannot be read (or is not a valid id) gets no reply:
        // there is nobody to address it to.
        let id_for_reply = peek.request_id.filter(|&id| id > 0);
        if let Some(claim) = peek.inline_map {
            if let Err(rejection) = convert::check_map_size(
                claim.width,
                claim.height,
                claim.num_cells,
                self.config.max_map_cells,
            ) {
                if rejection.status == PlanReply::STATUS_MAP_TOO_LARGE {
                    self.stats.requests_received.fetch_add(1, Ordering::SeqCst);
                    warn!(request_id = ?peek.request_id, reason = %rejection.reason, "inline map refused before decoding");
                    self.reject(peek.request_id.unwrap_or(0), -1, claim.seq, rejection, 0.0);
                    return;
                }
            }
        }
        let msg = match PlanRequest::decode_with_limits(bytes, &self.decode_limits()) {
            Ok(msg) => msg,
            Err(e) => {
                self.stats.malformed.fetch_add(1, Ordering::Relaxed);
                if let Some(id) = id_for_reply {
                    self.stats.requests_received.fetch_add(1, Ordering::SeqCst);
                    let rejection = Rejection::new(
                        PlanReply::STATUS_INVALID_REQUEST,
                        format!("could not decode the plan_request_t: {e}"),
                    );
                    self.reject(id, -1, -1, rejection, 0.0);
                }
                return;
            }
        };
        self.stats.requests_received.fetch_add(1, Ordering::SeqCst);
        let request = match convert::validate_request(
            &msg,
            &self.maps,
            self.config.max_map_cells,
            &self.config.defaults,
        ) {
            Ok(request) => request,
            Err(rejection) => {
                let rejection = self.maps.explain_missing_map(&msg, rejection);
                self.reject(msg.request_id, msg.method, msg.map_seq, rejection, 0.0);
                return;
            }
        };
        if self.shutdown.load(Ordering::SeqCst) {
            self.reject_shutting_down(&request);
            return;
        }
        let queued_bytes = bytes.len().saturating_mul(2);
        let waiting = self
            .stats
            .queued_bytes
            .fetch_add(queued_bytes, Ordering::SeqCst);
        if waiting.saturating_add(queued_bytes) > self.config.max_queued_bytes && waiting > 0 {
            self.stats
                .queued_bytes
                .fetch_sub(queued_bytes, Ordering::SeqCst);
            let rejection = Rejection::new(
                PlanReply::STATUS_BUSY,
                format!(
                    "busy: {waiting} bytes of requests are already waiting (limit {}); retry later",
                    self.config.max_queued_bytes
                ),
            );
            let r = &request;
            self.reject(r.request_id, r.method_code, r.map_seq, rejection, 0.0);
            return;
        }
        self.stats.queue_depth.fetch_add(1, Ordering::SeqCst);
        match queue.try_send(Job {
            request,
            received,
            queued_bytes,
        }) {
            Ok(()) => {}
            Err(TrySendError::Full(job) | TrySendError::Disconnected(job)) => {
                self.stats.queue_depth.fetch_sub(1, Ordering::SeqCst);
                self.stats
                    .queued_bytes
                    .fetch_sub(job.queued_bytes, Ordering::SeqCst);
                let rejection = Rejection::new(
                    PlanReply::STATUS_BUSY,
                    format!(
                        "busy: {} requests are already waiting (queue capacity); retry later",
                        self.config.queue_capacity
                    ),
                );
                let r = &job.request;
                self.reject(r.request_id, r.method_code, r.map_seq, rejection, 0.0);
            }
        }
    }

    fn reject_shutting_down(&self, request: &ValidatedRequest) {
        let rejection = Rejection::new(
            PlanReply::STATUS_BUSY,
            "busy: the service is shutting down; retry later",
        );
        self.reject(
            request.request_id,
            request.method_code,
            request.map_seq,
            rejection,
            0.0,
        );
    }

    fn worker(&self, jobs: &Receiver<Job>) {
        for job in jobs.iter() {
            self.stats.queue_depth.fetch_sub(1, Ordering::SeqCst);
            self.stats
                .queued_bytes
                .fetch_sub(job.queued_bytes, Ordering::SeqCst);
            let request = &job.request;
            if self.shutdown.load(Ordering::SeqCst) {
                self.reject_shutting_down(request);
                continue;
            }
            let started = Instant::now();
            let outcome = planning::plan(request, &self.cache, &self.config.traversability);
            let solve_time = started.elapsed().as_secs_f64();
            self.stats
                .last_solve_time_bits
                .store(solve_time.to_bits(), Ordering::SeqCst);
            match outcome {
                Ok(PlanOutcome {
                    samples,
                    mut metrics,
                    cache_hit,
                    feedback_field,
                }) => {
                    metrics.solve_time = solve_time;
                    info!(
                        request_id = request.request_id,
                        method = ?request.method,
                        cost = metrics.cost,
                        samples = samples.len(),
                        solve_time,
                        cache_hit,
                        waited_s = (started - job.received).as_secs_f64(),
                        "planned"
                    );
                    let reply = PlanReply {
                        request_id: request.request_id,
                        status: PlanReply::STATUS_OK,
                        error: String::new(),
                        method: request.method_code,
                        map_seq: request.map_seq,
                        num_samples: i32::try_from(samples.len()).unwrap_or(i32::MAX),
                        samples,
                        metrics,
                        ..PlanReply::default()
                    };
                    self.publish_reply_after_field(reply, feedback_field);
                }
                Err(rejection) => {
                    info!(request_id = request.request_id, reason = %rejection.reason, "planning failed");
                    self.reject(
                        request.request_id,
                        request.method_code,
                        request.map_seq,
                        rejection,
                        solve_time,
                    );
                }
            }
        }
    }

    fn status_loop(&self) {
        let tick = Duration::from_millis(20).min(self.config.status_period);
        let mut next = Instant::now();
        while !self.shutdown.load(Ordering::SeqCst) {
            if Instant::now() >= next {
                self.publish_status();
                next += self.config.status_period;
            }
            std::thread::sleep(tick);
        }
    }
}

/// Runs the service on `lcm` until `shutdown` becomes true (set it from a signal handler or a
/// test). Returns the final counters; a final status message is published before returning.
pub fn run(
    lcm: Arc<Lcm>,
    config: ServiceConfig,
    shutdown: Arc<AtomicBool>,
) -> anyhow::Result<ServiceReport> {
    config.check()?;
    let (queue, jobs) = crossbeam_channel::bounded::<Job>(config.queue_capacity);
    let shared = Arc::new(Shared {
        cache: GeneratorCache::new(config.cache_capacity),
        maps: MapStore::new(config.stored_maps),
        stats: Stats::new(),
        lcm: Arc::clone(&lcm),
        config,
        shutdown,
    });
    let channels = shared.config.channels.clone();
    info!(
        url = lcm.url(),
        map = %channels.map,
        request = %channels.request,
        reply = %channels.reply,
        feedback_field = %channels.feedback_field,
        status = %channels.status,
        workers = shared.config.workers,
        queue = shared.config.queue_capacity,
        max_map_cells = shared.config.max_map_cells,
        "pf-planner-service starting"
    );
    std::thread::scope(|scope| -> anyhow::Result<()> {
        for i in 0..shared.config.workers {
            let jobs = jobs.clone();
            let shared = &shared;
            std::thread::Builder::new()
                .name(format!("planner-{i}"))
                .spawn_scoped(scope, move || shared.worker(&jobs))
                .context("spawning a planner worker")?;
        }
        drop(jobs);
        // Subscribed before the first status goes out: a client that waits for a status
        // message can rely on its requests being heard (memq drops unheard messages).
        let subscriptions = subscribe(&lcm, &shared, queue)?;
        std::thread::Builder::new()
            .name("status".into())
            .spawn_scoped(scope, || shared.status_loop())
            .context("spawning the status thread")?;

        let result = handle_until_shutdown(&lcm, &shared);
        // Dropping the subscriptions drops the queue's sender: workers drain it and stop.
        drop(subscriptions);
        // Stop the status thread (and make workers answer what is left with "shutting down")
        // even when the handle loop failed.
        shared.shutdown.store(true, Ordering::SeqCst);
        result
    })?;
    shared.publish_status();
    let report = shared.report();
    info!(?report, "pf-planner-service stopped");
    Ok(report)
}

/// Subscribes the map and request handlers; the request handler owns the queue's sender.
fn subscribe<'l>(
    lcm: &'l Lcm,
    shared: &Arc<Shared>,
    queue: Sender<Job>,
) -> anyhow::Result<[lcm_transport::Subscription<'l>; 2]> {
    let map_shared = Arc::clone(shared);
    let map_sub = lcm
        .subscribe(&shared.config.channels.map, move |_, bytes| {
            map_shared.on_map(bytes)
        })
        .context("subscribing to the map channel")?;
    let request_shared = Arc::clone(shared);
    let request_sub = lcm
        .subscribe(&shared.config.channels.request, move |_, bytes| {
            request_shared.on_request(bytes, &queue)
        })
        .context("subscribing to the request channel")?;
    // liblcm drops packets beyond 30 per subscription by default; a burst of requests is
    // absorbed here and then answered (planned or busy) one by one.
    request_sub.set_queue_capacity(4096)?;
    Ok([map_sub, request_sub])
}

/// Handles LCM traffic until shutdown.
fn handle_until_shutdown(lcm: &Lcm, shared: &Shared) -> anyhow::Result<()> {
    let mut consecutive_errors = 0u32;
    while !shared.shutdown.load(Ordering::SeqCst) {
        match lcm.handle_timeout(Duration::from_millis(50)) {
            Ok(_) => consecutive_errors = 0,
            Err(e) => {
                consecutive_errors += 1;
                warn!(error = %e, consecutive_errors, "LCM handle failed");
                anyhow::ensure!(consecutive_errors < 100, "LCM keeps failing: {e}");
                std::thread::sleep(Duration::from_millis(10));
            }
        }
    }
    info!("shutdown requested");
    Ok(())
}
