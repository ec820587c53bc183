//! `pfnav-robot`: runs the controller FMU as a real-time LCM node until SIGINT or SIGTERM.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use clap::Parser;
use lcm_transport::Lcm;
use pfnav_robot::{platform, LoopTrigger, NodeConfig, RobotChannels, DEFAULT_DEADLINE_MARGIN};
use tracing_subscriber::EnvFilter;

/// The controller FMU as a real-time LCM node: low_state_t in, low_cmd_t out every period on
/// absolute deadlines, damping on faults, robot_status_t with timing statistics.
///
/// Channels: <prefix> followed by the names of `[robot]` in lcm_types/channels.toml.
/// Logs go to stderr; set RUST_LOG (e.g. RUST_LOG=debug) for more.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Args {
    /// The controller FMU [default: $PFNAV_FMU_OUT, else target/fmu/QuadController.fmu].
    #[arg(long)]
    fmu: Option<PathBuf>,
    /// LCM URL [default: $LCM_DEFAULT_URL, else the stack's default bus, lcm_types/channels.toml].
    #[arg(long)]
    lcm_url: Option<String>,
    /// Prefix of the channel names.
    #[arg(long, default_value = lcm_types::channels::DEFAULT_PREFIX)]
    channel_prefix: String,
    /// Control rate, Hz: 1000 or 500.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u32).range(500..=1000))]
    rate: u32,
    /// Damping after this long without a low_state_t, ms.
    #[arg(long, default_value_t = 20.0)]
    state_timeout_ms: f64,
    /// Damping while the states arrive later than this by the body's clock (`low_state_t.tick`,
    /// ms; it must count the body's milliseconds, as a robot's does), ms; default: not checked.
    #[arg(long)]
    max_state_delay_ms: Option<f64>,
    /// Damping after this long without a nav_cmd_t, ms.
    #[arg(long, default_value_t = 500.0)]
    nav_timeout_ms: f64,
    /// Fault-free cycles in a row before damping ends.
    #[arg(long, default_value_t = 20)]
    recover_cycles: u32,
    /// Velocity gain of the damping command, N m s/rad.
    #[arg(long, default_value_t = 2.0)]
    damping_kd: f32,
    /// Seconds between two robot_status_t messages.
    #[arg(long, default_value_t = 0.5)]
    status_period: f64,
    /// Control cycles between two robot_estimate_t messages (10: 100 Hz at 1 kHz).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    estimate_every: u32,
    /// SCHED_FIFO priority of the control thread (1..=99); 0 keeps ordinary scheduling and
    /// does not lock memory.
    #[arg(long, default_value_t = 80)]
    priority: i32,
    /// Stop after this many seconds (default: run until SIGINT/SIGTERM).
    #[arg(long)]
    duration: Option<f64>,
    /// What starts a control cycle: `deadline` = a fixed point of one-period slots
    /// phase-locked to the low_state_t stream, `--deadline-margin` after the states' arrival
    /// (the node's clock sets the period); `state` = the arrival of a fresh low_state_t (the
    /// slot's end as the watchdog; the stream's delivery sets the period); `clock` = fixed
    /// deadlines whatever the states do.
    #[arg(long, value_enum, default_value_t = TriggerArg::Deadline)]
    trigger: TriggerArg,
    /// With `--trigger deadline`: how long after the states' arrival phase a cycle starts, as a
    /// fraction of the period (0 < margin < 0.5); the room for the delivery's jitter.
    #[arg(long, default_value_t = DEFAULT_DEADLINE_MARGIN)]
    deadline_margin: f64,
    /// The trunk's position X Y Z when the node starts, in the frame the controller should
    /// estimate in (e.g. the world frame of a map); default: the FMU's start values, a frame
    /// that starts where the robot stands.
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true)]
    initial_position: Option<Vec<f64>>,
    /// At exit, write the whole run's timing and counters to this JSON file.
    #[arg(long)]
    report_json: Option<PathBuf>,
    /// Instead of the node, run a bare loop with the same period, priority and sleep for
    /// `--duration` seconds (no FMU, no bus): the machine's own floor for period jitter and
    /// misses (as cyclictest measures it).
    #[arg(long, requires = "duration")]
    measure_floor: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum TriggerArg {
    Deadline,
    State,
    Clock,
}

fn milliseconds(value: f64, flag: &str) -> anyhow::Result<u64> {
    anyhow::ensure!(
        value.is_finite() && value > 0.0 && value <= 60_000.0,
        "{flag} must be in (0, 60000] ms"
    );
    Ok((value * 1e6) as u64)
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
    let fmu = args.fmu.clone().unwrap_or_else(|| {
        std::env::var_os("PFNAV_FMU_OUT")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from("target/fmu/QuadController.fmu"))
    });
    let mut config = NodeConfig::new(fmu, RobotChannels::with_prefix(&args.channel_prefix)?);
    anyhow::ensure!(
        args.rate == 1000 || args.rate == 500,
        "--rate must be 1000 or 500 (the controller ticks every 1 ms: a period of whole ticks)"
    );
    config.period = Duration::from_secs_f64(1.0 / f64::from(args.rate));
    config.safety.state_timeout_ns = milliseconds(args.state_timeout_ms, "--state-timeout-ms")?;
    config.safety.nav_timeout_ns = milliseconds(args.nav_timeout_ms, "--nav-timeout-ms")?;
    config.safety.max_state_delay_ns = args
        .max_state_delay_ms
        .map(|ms| milliseconds(ms, "--max-state-delay-ms"))
        .transpose()?;
    config.safety.recover_cycles = args.recover_cycles;
    config.damping_kd = args.damping_kd;
    anyhow::ensure!(
        args.status_period.is_finite() && args.status_period > 0.0 && args.status_period <= 3600.0,
        "--status-period must be in (0, 3600] s"
    );
    config.status_period = Duration::from_secs_f64(args.status_period);
    config.estimate_every = args.estimate_every;
    anyhow::ensure!(
        (0..=99).contains(&args.priority),
        "--priority must be 0 (ordinary scheduling) or 1..=99"
    );
    config.realtime_priority = (args.priority > 0).then_some(args.priority);
    if let Some(seconds) = args.duration {
        anyhow::ensure!(
            seconds.is_finite() && seconds > 0.0 && seconds < 1e7,
            "--duration must be a positive number of seconds"
        );
        config.duration = Some(Duration::from_secs_f64(seconds));
    }

    anyhow::ensure!(
        args.deadline_margin > 0.0 && args.deadline_margin < 0.5,
        "--deadline-margin must be a fraction of the period in (0, 0.5)"
    );
    config.trigger = match args.trigger {
        TriggerArg::Deadline => LoopTrigger::deadline(config.period, args.deadline_margin),
        TriggerArg::State => LoopTrigger::StateArrival,
        TriggerArg::Clock => LoopTrigger::Clock,
    };
    if let Some(position) = &args.initial_position {
        anyhow::ensure!(
            position.len() == 3 && position.iter().all(|v| v.is_finite()),
            "--initial-position takes three finite numbers X Y Z"
        );
        config.initial_position = Some([position[0], position[1], position[2]]);
    }

    let shutdown = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&shutdown))
            .with_context(|| format!("installing the handler of signal {signal}"))?;
    }
    if args.measure_floor {
        let duration = config
            .duration
            .context("--measure-floor needs --duration")?;
        let report =
            platform::measure_floor(config.period, duration, config.realtime_priority, &shutdown);
        tracing::info!(
            cycles = report.cycles,
            misses = report.timing.misses,
            jitter_p99_us = report.timing.jitter.percentile_ns(0.99) as f64 * 1e-3,
            lateness_max_us = report.lateness.max_ns() as f64 * 1e-3,
            "bare loop stopped"
        );
        return write_report(
            args.report_json.as_deref(),
            &report.to_json(config_period_s(args.rate)),
        );
    }

    let url = args
        .lcm_url
        .unwrap_or_else(|| lcm_transport::url_from_env_or(lcm_types::channels::DEFAULT_URL));
    let lcm = Arc::new(Lcm::open(&url).with_context(|| format!("opening LCM at {url}"))?);
    let report = pfnav_robot::run(lcm, config, shutdown)?;
    let timing = &report.timing;
    tracing::info!(
        cycles = report.cycles,
        misses = timing.misses,
        period_p99_us = timing.period.percentile_ns(0.99) as f64 * 1e-3,
        period_max_us = timing.period.max_ns() as f64 * 1e-3,
        latency_p99_us = timing.latency.percentile_ns(0.99) as f64 * 1e-3,
        damping_entries = report.damping_entries,
        "stopped"
    );
    write_report(
        args.report_json.as_deref(),
        &report.to_json(config_period_s(args.rate)),
    )
}

/// Writes a run's JSON report to `path` (nothing without one).
fn write_report(path: Option<&std::path::Path>, report: &serde_json::Value) -> anyhow::Result<()> {
    let Some(path) = path else {
        return Ok(());
    };
    let text = serde_json::to_string_pretty(report).context("encoding the run report")?;
    std::fs::write(path, text + "\n")
        .with_context(|| format!("writing the run report {}", path.display()))
}

fn config_period_s(rate: u32) -> f64 {
    1.0 / f64::from(rate)
}
