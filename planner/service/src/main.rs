//! `pf-planner-service`: plans on request over LCM until SIGINT or SIGTERM.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use clap::Parser;
use lcm_transport::Lcm;
use pf_planner::traversability::TraversabilityParams;
use pf_planner_service::{ServiceConfig, DEFAULT_CHANNEL_PREFIX};
use tracing_subscriber::EnvFilter;

/// The P-F planner as an LCM service.
///
/// Channels: <prefix> followed by the names of `[planner]` in lcm_types/channels.toml (maps and
/// requests in; replies, feedback fields and status out).
/// Logs go to stderr; set RUST_LOG (e.g. RUST_LOG=debug) for more.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Args {
    /// LCM URL [default: $LCM_DEFAULT_URL, else the stack's default bus, lcm_types/channels.toml].
    #[arg(long)]
    lcm_url: Option<String>,
    /// Prefix of the five channel names.
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
    /// The traversability (cost) model as JSON, fields as in the planner's
    /// `TraversabilityParams` (height_weight, slope_weight, roughness_weight, slope_ref_deg,
    /// roughness_ref_m, p_floor, h_max, footprint_radius_m, max_slope_deg,
    /// height_confidence_sigmas, slope_fit_radius_m); fields left out keep
    /// their defaults (the paper's p = h/h_max), unknown fields are refused.
    #[arg(long)]
    traversability: Option<String>,
    /// Robot footprint radius in metres: each cell costs the largest traversability p within
    /// it, so paths keep that far from steep ground (default 0 = the paper's point robot;
    /// overrides `footprint_radius_m` of --traversability).
    #[arg(long)]
    footprint_radius: Option<f64>,
    /// Steepest walkable slope in degrees: known cells steeper than this are hard obstacles
    /// (unset: no limit, the paper's cost-only model; overrides `max_slope_deg` of
    /// --traversability).
    #[arg(long)]
    max_slope_deg: Option<f64>,
}

/// The traversability model of --traversability with --footprint-radius and --max-slope-deg
/// applied on top, validated.
fn cost_model(args: &Args) -> anyhow::Result<TraversabilityParams> {
    let mut params = match &args.traversability {
        Some(json) => serde_json::from_str::<TraversabilityParams>(json)
            .with_context(|| format!("--traversability {json}"))?,
        None => TraversabilityParams::default(),
    };
    if let Some(radius) = args.footprint_radius {
        anyhow::ensure!(
            radius.is_finite() && radius >= 0.0,
            "--footprint-radius (traversability.footprint_radius_m) must be finite and >= 0, got {radius}"
        );
        params.footprint_radius_m = radius;
    }
    if args.max_slope_deg.is_some() {
        params.max_slope_deg = args.max_slope_deg;
    }
    params
        .validate()
        .context("--traversability / --max-slope-deg / --footprint-radius")?;
    Ok(params)
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        // Colour codes only on a terminal: logs redirected to files, and the error messages
        // quoting their tails, stay plain text.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
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
    let mut config = ServiceConfig::with_prefix(&args.channel_prefix)?;
    config.max_map_cells = args.max_map_cells;
    config.workers = args.workers;
    config.queue_capacity = args.queue_capacity;
    config.max_queued_bytes = args.max_queued_bytes;
    config.cache_capacity = args.cache;
    config.stored_maps = args.stored_maps;
    config.status_period = Duration::from_secs_f64(args.status_period);
    config.defaults.max_solve_time = args.max_solve_time;
    config.traversability = cost_model(&args)?;

    let url = args
        .lcm_url
        .unwrap_or_else(|| lcm_transport::url_from_env_or(lcm_types::channels::DEFAULT_URL));
    let lcm = Arc::new(Lcm::open(&url).with_context(|| format!("opening LCM at {url}"))?);

    let shutdown = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&shutdown))
            .with_context(|| format!("installing the handler of signal {signal}"))?;
    }
    pf_planner_service::run(lcm, config, shutdown)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(flags: &[&str]) -> anyhow::Result<TraversabilityParams> {
        let args = Args::try_parse_from(
            std::iter::once("pf-planner-service").chain(flags.iter().copied()),
        )?;
        cost_model(&args)
    }

    #[test]
    fn cost_model_from_json_and_flags() {
        assert_eq!(model(&[]).unwrap(), TraversabilityParams::default());
        let weighted = model(&[
            r#"--traversability={"slope_weight": 1.5, "slope_ref_deg": 25, "footprint_radius_m": 0.3}"#,
        ])
        .unwrap();
        assert_eq!(weighted.slope_weight, 1.5);
        assert_eq!(weighted.slope_ref_deg, 25.0);
        assert_eq!(weighted.footprint_radius_m, 0.3);
        assert_eq!(
            weighted.height_weight, 1.0,
            "fields left out keep their defaults"
        );
        let overridden = model(&[
            r#"--traversability={"footprint_radius_m": 0.3, "max_slope_deg": 30}"#,
            "--footprint-radius=0.25",
            "--max-slope-deg=20",
        ])
        .unwrap();
        assert_eq!(overridden.footprint_radius_m, 0.25);
        assert_eq!(overridden.max_slope_deg, Some(20.0));
    }

    #[test]
    fn bad_cost_models_are_refused_with_the_reason() {
        for (flags, reason) in [
            (
                vec![r#"--traversability={"slope_wieght": 1}"#],
                "unknown field",
            ),
            (
                vec![r#"--traversability={"slope_weight": -1}"#],
                "slope_weight",
            ),
            (vec!["--traversability=not json"], "--traversability"),
            (vec!["--footprint-radius=NaN"], "footprint"),
            (vec!["--max-slope-deg=95"], "max_slope_deg"),
        ] {
            let error = model(&flags).expect_err(flags[0]);
            assert!(
                format!("{error:#}").contains(reason),
                "{flags:?}: {error:#}"
            );
        }
    }
}
