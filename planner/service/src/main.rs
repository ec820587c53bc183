//! `pf-planner-service`: plans on request over LCM until SIGINT or SIGTERM.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use clap::Parser;
use lcm_transport::Lcm;
use pf_planner_service::{ServiceConfig, DEFAULT_CHANNEL_PREFIX};
use tracing_subscriber::EnvFilter;

/// The P-F planner as an LCM service.
///
/// Channels: <prefix>MAP (terrain_map_t in), <prefix>PLAN_REQUEST (plan_request_t in),
/// <prefix>PLAN_REPLY (plan_reply_t out, one per request, request_id echoed),
/// <prefix>SERVICE_STATUS (service_status_t out, every status period).
/// Logs go to stderr; set RUST_LOG (e.g. RUST_LOG=debug) for more.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Args {
    /// LCM URL; default: $LCM_DEFAULT_URL, else udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304.
    #[arg(long)]
    lcm_url: Option<String>,
    /// Prefix of the four channel names.
    #[arg(long, default_value = DEFAULT_CHANNEL_PREFIX)]
    channel_prefix: String,
    /// Largest map accepted (width x height), checked on the raw size fields before decoding.
    #[arg(long, default_value_t = 512 * 512)]
    max_map_cells: usize,
    /// Planner worker threads.
    #[arg(long, default_value_t = 2)]
    workers: usize,
    /// Requests that may wait for a worker; further ones get a STATUS_BUSY reply.
    #[arg(long = "queue", default_value_t = 2048)]
    queue_capacity: usize,
    /// Bytes of request packets (inline maps) that may wait together; further ones get a
    /// STATUS_BUSY reply.
    #[arg(long, default_value_t = 128 << 20)]
    max_queued_bytes: usize,
    /// P-F generator sets (map + settings) kept for reuse (least recently used evicted).
    #[arg(long, default_value_t = 4)]
    cache: usize,
    /// Maps from the map channel kept for requests that name them by seq.
    #[arg(long, default_value_t = 8)]
    stored_maps: usize,
    /// Seconds between two status messages.
    #[arg(long, default_value_t = 1.0)]
    status_period: f64,
    /// Default solve-time limit in seconds for requests that leave options.max_solve_time at 0.
    #[arg(long, default_value_t = 30.0)]
    max_solve_time: f64,
    /// Robot footprint radius in metres: each cell costs the largest traversability p within
    /// it, so paths keep that far from steep ground (0 = the paper's point robot).
    #[arg(long, default_value_t = 0.0)]
    footprint_radius: f64,
    /// Steepest walkable slope in degrees: known cells steeper than this are hard obstacles
    /// (unset: no limit, the paper's cost-only model).
    #[arg(long)]
    max_slope_deg: Option<f64>,
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    let args = Args::parse();
    anyhow::ensure!(
        args.status_period.is_finite() && args.status_period > 0.0,
        "--status-period must be finite and > 0"
    );
    anyhow::ensure!(
        args.max_solve_time.is_finite() && args.max_solve_time > 0.0,
        "--max-solve-time must be finite and > 0"
    );
    anyhow::ensure!(
        args.footprint_radius.is_finite() && args.footprint_radius >= 0.0,
        "--footprint-radius (traversability.footprint_radius_m) must be finite and >= 0, got {}",
        args.footprint_radius
    );
    let mut config = ServiceConfig::with_prefix(&args.channel_prefix)?;
    config.max_map_cells = args.max_map_cells;
    config.workers = args.workers;
    config.queue_capacity = args.queue_capacity;
    config.max_queued_bytes = args.max_queued_bytes;
    config.cache_capacity = args.cache;
    config.stored_maps = args.stored_maps;
    config.status_period = Duration::from_secs_f64(args.status_period);
    config.defaults.max_solve_time = args.max_solve_time;
    config.traversability.footprint_radius_m = args.footprint_radius;
    config.traversability.max_slope_deg = args.max_slope_deg;
    config
        .traversability
        .validate()
        .context("--max-slope-deg / --footprint-radius")?;

    let url = args.lcm_url.unwrap_or_else(lcm_transport::default_url);
    let lcm = Arc::new(Lcm::open(&url).with_context(|| format!("opening LCM at {url}"))?);

    let shutdown = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&shutdown))
            .with_context(|| format!("installing the handler of signal {signal}"))?;
    }
    pf_planner_service::run(lcm, config, shutdown)?;
    Ok(())
}
