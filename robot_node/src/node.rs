//! The node: an LCM thread fills the inbox; the control loop runs once per period-long slot,
//! started by the arrival of a fresh state or by the slot's end (the watchdog, an absolute
//! deadline; see `schedule`), takes the newest state and navigator command, asks the safety
//! monitor, steps the controller (or damps), sends low_cmd_t, and every status period sends
//! robot_status_t.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use lcm_transport::Lcm;
use lcm_types::pfnav::{Header, LowCmd, RobotEstimate, RobotStatus};
use lcm_types::Message;

use crate::clock::{self, RealtimeSettings};
use crate::controller::{Estimate, HostedController};
use crate::inbox::{Counters, Inbox};
use crate::safety::{Mode, SafetyConfig, SafetyMonitor};
use crate::schedule::{SlotSchedule, Trigger};
use crate::stats::LoopTiming;

/// A cycle is missed when its period exceeds this many nominal periods (Cheetah-Software's
/// PeriodicTask criterion).
pub const MISS_FACTOR: f64 = 1.3;

/// SCHED_FIFO priority of liblcm's receive thread (see `run`), declared with the bus in
/// `lcm_types/channels.toml`.
pub use lcm_types::channels::RECEIVE_THREAD_PRIORITY;

/// The default deadline margin, a fraction of the period: room for the states' delivery
/// jitter before the cycle that uses them.
pub const DEFAULT_DEADLINE_MARGIN: f64 = 0.25;

/// The most periods one controller step spans when states were lost in between (the FMU runs
/// that many control ticks on the newest state): 20 ms at 1 kHz, the default state timeout.
/// A longer gap (a seq jump) steps this many; the cycle's work stays bounded.
pub const MAX_CATCH_UP_PERIODS: u32 = 20;

/// Periods of body time between the state the controller last stepped on (`last_seq`) and a
/// fresh one (`seq`): the body sends one state per tick and numbers them, so a gap in the
/// numbers is ticks whose states were lost, and the controller's clock must cover them too. A
/// number at or below the last (a restarted body) or no last step counts one period.
pub fn periods_since(last_seq: Option<i64>, seq: i64) -> u32 {
    match last_seq {
        Some(last) if seq > last => u32::try_from(seq.saturating_sub(last))
            .map_or(MAX_CATCH_UP_PERIODS, |gap| gap.min(MAX_CATCH_UP_PERIODS)),
        _ => 1,
    }
}

/// The node's channels: `<prefix>` + the names of `[robot]` in channels.toml.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RobotChannels {
    pub low_state: String,
    pub low_cmd: String,
    pub nav_cmd: String,
    pub status: String,
    pub estimate: String,
}

impl RobotChannels {
    pub fn with_prefix(prefix: &str) -> anyhow::Result<Self> {
        use lcm_types::channels::robot;
        let channels = Self {
            low_state: format!("{prefix}{}", robot::LOW_STATE),
            low_cmd: format!("{prefix}{}", robot::LOW_CMD),
            nav_cmd: format!("{prefix}{}", robot::NAV_CMD),
            status: format!("{prefix}{}", robot::ROBOT_STATUS),
            estimate: format!("{prefix}{}", robot::ROBOT_ESTIMATE),
        };
        let plain = prefix
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '/');
        anyhow::ensure!(
            plain,
            "channel prefix {prefix:?} may only contain ASCII letters, digits, '_', '-' and '/' (subscriptions are regular expressions)"
        );
        for name in [
            &channels.low_state,
            &channels.low_cmd,
            &channels.nav_cmd,
            &channels.status,
            &channels.estimate,
        ] {
            anyhow::ensure!(
                name.len() <= lcm_transport::MAX_CHANNEL_LEN,
                "channel {name:?} is longer than LCM's {} bytes",
                lcm_transport::MAX_CHANNEL_LEN
            );
        }
        Ok(channels)
    }
}

#[derive(Debug, Clone)]
pub struct NodeConfig {
    pub channels: RobotChannels,
    /// The controller FMU (`QuadController.fmu`).
    pub fmu: std::path::PathBuf,
    /// Control period (1 ms at 1 kHz, 2 ms at 500 Hz); also the FMU's step.
    pub period: Duration,
    pub safety: SafetyConfig,
    /// Velocity gain of the damping command, N m s/rad.
    pub damping_kd: f32,
    pub status_period: Duration,
    /// Cycles between two robot_estimate_t messages (10: 100 Hz at 1 kHz).
    pub estimate_every: u32,
    /// Try SCHED_FIFO at this priority and mlockall (None: ordinary scheduling).
    pub realtime_priority: Option<i32>,
    /// Stop after this long (None: until the shutdown flag is set).
    pub duration: Option<Duration>,
    /// The trunk's position when the node starts, in the frame the controller should work in
    /// (None: the FMU's start values, a frame starting where the robot stands).
    pub initial_position: Option<[f64; 3]>,
    /// What starts a cycle (`schedule`).
    pub trigger: LoopTrigger,
}

/// What starts the control cycles (see `schedule` for the slots they run in).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoopTrigger {
    /// The arrival of a fresh state (phase-locked slots, the slot's end as the watchdog): the
    /// least latency; the period follows the stream's delivery.
    StateArrival,
    /// A deadline `margin` after the centre of a slot phase-locked to the state stream: the
    /// period keeps the node's clock, the states arrive about `margin` before their cycle.
    Deadline { margin: Duration },
    /// Fixed deadlines, the slot centres, whatever the states do.
    Clock,
}

impl LoopTrigger {
    /// The phase-locked deadline `margin_fraction` of `period` after the states' arrival.
    pub fn deadline(period: Duration, margin_fraction: f64) -> Self {
        LoopTrigger::Deadline {
            margin: period.mul_f64(margin_fraction),
        }
    }
}

impl NodeConfig {
    /// The documented defaults: 1 kHz, 20 ms state timeout, 500 ms navigator timeout,
    /// 20 good cycles to recover, damping kd 2 N m s/rad, status every 0.5 s, SCHED_FIFO 80,
    /// cycles on the phase-locked deadline a quarter period after the states' arrival.
    pub fn new(fmu: std::path::PathBuf, channels: RobotChannels) -> Self {
        let period = Duration::from_millis(1);
        Self {
            channels,
            fmu,
            period,
            safety: SafetyConfig {
                state_timeout_ns: 20_000_000,
                max_state_delay_ns: None,
                nav_timeout_ns: 500_000_000,
                recover_cycles: 20,
            },
            damping_kd: 2.0,
            status_period: Duration::from_millis(500),
            estimate_every: 10,
            realtime_priority: Some(80),
            duration: None,
            trigger: LoopTrigger::deadline(period, DEFAULT_DEADLINE_MARGIN),
            initial_position: None,
        }
    }

    fn check(&self) -> anyhow::Result<()> {
        let period = self.period.as_secs_f64();
        anyhow::ensure!(
            (1e-4..=0.1).contains(&period),
            "period {period} s is outside 0.1 ms ..= 100 ms"
        );
        anyhow::ensure!(
            self.damping_kd.is_finite() && self.damping_kd >= 0.0,
            "damping kd must be finite and >= 0"
        );
        anyhow::ensure!(!self.status_period.is_zero(), "status period must be > 0");
        if let LoopTrigger::Deadline { margin } = self.trigger {
            anyhow::ensure!(
                margin < self.period / 2,
                "the deadline margin {margin:?} must be below half the period {:?}",
                self.period
            );
        }
        anyhow::ensure!(
            self.estimate_every > 0,
            "estimate interval must be > 0 cycles"
        );
        anyhow::ensure!(
            self.safety.state_timeout_ns > 0 && self.safety.nav_timeout_ns > 0,
            "timeouts must be > 0"
        );
        Ok(())
    }
}

/// How a run went (the whole run's timing, for the benchmark and the log at exit).
#[derive(Debug, Clone)]
pub struct RunReport {
    pub timing: LoopTiming,
    pub cycles: u64,
    /// Periods the controller was stepped in all (its clock; the body's ticks it has seen).
    pub controller_periods: u64,
    pub damping_entries: i64,
    pub counters: Counters,
    pub realtime: RealtimeSettings,
    pub final_mode: Mode,
    pub final_reason: String,
}

impl RunReport {
    /// The whole run's figures (seconds, counts) as JSON, for benchmarks.
    pub fn to_json(&self, period_s: f64) -> serde_json::Value {
        let t = &self.timing;
        serde_json::json!({
            "period_nominal": period_s,
            "cycles": self.cycles,
            "controller_periods": self.controller_periods,
            "misses": t.misses,
            "overruns": t.overruns,
            "period": t.period.to_json(),
            "jitter": t.jitter.to_json(),
            "runtime": t.runtime.to_json(),
            "latency": t.latency.to_json(),
            "cycles_state_arrived": t.state_arrived,
            "cycles_state_waiting": t.state_waiting,
            "cycles_watchdog": t.watchdog,
            "skipped_slots": t.skipped_slots,
            "cycles_held": t.held_cycles,
            "damping_entries": self.damping_entries,
            "states_received": self.counters.states_received,
            "states_out_of_order": self.counters.states_out_of_order,
            "states_non_finite": self.counters.states_non_finite,
            "nav_cmds_received": self.counters.nav_cmds_received,
            "malformed_messages": self.counters.malformed_messages,
            "realtime_priority": self.realtime.fifo_priority,
            "memory_locked": self.realtime.memory_locked,
            "final_safety": match self.final_mode {
                Mode::Torque => "torque",
                Mode::Damping => "damping",
            },
            "final_reason": self.final_reason,
        })
    }
}

fn wall_utime() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_micros()).unwrap_or(i64::MAX))
}

fn header(seq: i64) -> Header {
    Header {
        utime: wall_utime(),
        seq,
        frame_id: "body".to_owned(),
    }
}

/// Encodes `message` into `bytes` (reusing its allocation) and publishes it on `channel`; a
/// failure is logged, never fatal to the loop.
fn send<M: Message>(lcm: &Lcm, channel: &str, message: &M, bytes: &mut Vec<u8>) {
    match message.encode_into(bytes) {
        Ok(()) => {
            if let Err(error) = lcm.publish(channel, bytes) {
                tracing::error!(%error, channel, "could not send {}", M::TYPE_NAME);
            }
        }
        Err(error) => tracing::error!(%error, channel, "could not encode {}", M::TYPE_NAME),
    }
}

fn seconds(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

/// Runs the node on `lcm` until `shutdown` is set (or the configured duration has passed).
/// The calling thread becomes the control thread; an LCM thread is started beside it.
pub fn run(
    lcm: Arc<Lcm>,
    config: NodeConfig,
    shutdown: Arc<AtomicBool>,
) -> anyhow::Result<RunReport> {
    config.check()?;
    let period_ns = u64::try_from(config.period.as_nanos()).unwrap_or(u64::MAX);
    let mut controller = HostedController::load(
        &config.fmu,
        config.period.as_secs_f64(),
        config.initial_position,
    )
    .with_context(|| format!("loading the controller FMU {}", config.fmu.display()))?;

    // liblcm starts its receive thread at the first subscription, with this thread's
    // scheduling. Under ordinary scheduling every busy ordinary process could hold the states
    // back (a body's tick once waited 24 ms for its command); at the loop's own priority it
    // preempted the loops for every packet on the bus (more misses). So it gets the lowest
    // SCHED_FIFO priority: above every ordinary process, below the loops.
    if config.realtime_priority.is_some() {
        let rc = clock::set_thread_fifo(RECEIVE_THREAD_PRIORITY);
        if rc != 0 {
            tracing::warn!(
                error = %std::io::Error::from_raw_os_error(rc),
                "SCHED_FIFO refused for liblcm's receive thread"
            );
        }
    }
    let inbox = Arc::new(Inbox::new(config.safety.state_timeout_ns));
    let state_inbox = Arc::clone(&inbox);
    let _state_sub = lcm.subscribe(&config.channels.low_state, move |_, bytes| {
        state_inbox.on_low_state(bytes, clock::now_ns());
    })?;
    let nav_inbox = Arc::clone(&inbox);
    let _nav_sub = lcm.subscribe(&config.channels.nav_cmd, move |_, bytes| {
        nav_inbox.on_nav_cmd(bytes, clock::now_ns());
    })?;

    let receiver_stop = AtomicBool::new(false);
    std::thread::scope(|scope| {
        let receiver = std::thread::Builder::new()
            .name("pfnav-robot-lcm".to_owned())
            .spawn_scoped(scope, || {
                // The receiving thread stamps the states' arrival and wakes the control loop:
                // under load a normally scheduled thread would hand the states over in bursts.
                // Same priority as the control thread; its work per packet is a decode and a
                // copy.
                if let Some(priority) = config.realtime_priority {
                    let rc = clock::set_thread_fifo(priority);
                    if rc != 0 {
                        tracing::warn!(
                            priority,
                            error = %std::io::Error::from_raw_os_error(rc),
                            "SCHED_FIFO refused for the LCM thread"
                        );
                    }
                }
                while !receiver_stop.load(Ordering::Relaxed) {
                    if let Err(error) = lcm.handle_timeout(Duration::from_millis(10)) {
                        tracing::error!(%error, "LCM receive failed");
                        // Bounded retry rate while the bus is broken.
                        std::thread::sleep(Duration::from_millis(10));
                    }
                }
            })
            .context("starting the LCM thread")?;
        let report = control_loop(&lcm, &config, period_ns, &mut controller, &inbox, &shutdown);
        receiver_stop.store(true, Ordering::Relaxed);
        if receiver.join().is_err() {
            tracing::error!("the LCM thread panicked");
        }
        report
    })
}

fn control_loop(
    lcm: &Lcm,
    config: &NodeConfig,
    period_ns: u64,
    controller: &mut HostedController,
    inbox: &Inbox,
    shutdown: &AtomicBool,
) -> anyhow::Result<RunReport> {
    let realtime = match config.realtime_priority {
        Some(priority) => clock::apply_realtime(priority),
        None => RealtimeSettings::default(),
    };
    let mut safety = SafetyMonitor::new(config.safety);
    let miss_ns = (period_ns as f64 * MISS_FACTOR) as u64;
    let status_ns = u64::try_from(config.status_period.as_nanos()).unwrap_or(u64::MAX);
    let end_ns = config
        .duration
        .map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));

    let mut window = LoopTiming::default();
    let mut total = LoopTiming::default();
    let mut window_cycles = 0i64;
    let mut cycles = 0u64;
    let mut controller_periods = 0u64;
    let mut warned_slow_states = false;
    let mut command_seq = 0i64;
    // The command's bytes, reused every cycle: the loop allocates nothing once it has run.
    let mut command_bytes = Vec::new();
    let mut status_seq = 0i64;
    let mut fsm_state = -1i8;
    // The controller's newest estimate and the state seq it came from (None before its first
    // step), sent every `estimate_every` cycles in `estimate` (its bytes reused like the
    // command's).
    let mut latest_estimate: Option<(i64, Estimate)> = None;
    let mut estimate = RobotEstimate {
        header: Header {
            frame_id: "controller".to_owned(),
            ..Header::default()
        },
        state_seq: -1,
        fsm_state: -1,
        safety: RobotStatus::SAFETY_DAMPING,
        ..RobotEstimate::default()
    };
    let mut estimate_bytes = Vec::new();
    let mut status_bytes = Vec::new();
    let mut estimate_seq = 0i64;
    let mut last_used_state_seq: Option<i64> = None;
    let mut counters = Counters::default();
    let mut command = LowCmd {
        header: header(0),
        state_seq: -1,
        mode: [LowCmd::MODE_SERVO; 12],
        ..LowCmd::default()
    };

    let start_ns = clock::now_ns();
    let mut schedule = SlotSchedule::new(period_ns, start_ns);
    // Accepted states in all at the previous cycle: a larger count in the inbox is a fresh one.
    let mut states_seen = 0i64;
    let mut next_status = start_ns + status_ns;
    let mut previous_cycle_start: Option<u64> = None;
    tracing::info!(
        period_ms = config.period.as_secs_f64() * 1e3,
        low_state = %config.channels.low_state,
        low_cmd = %config.channels.low_cmd,
        "control loop started"
    );

    while !shutdown.load(Ordering::Relaxed) {
        let trigger = match config.trigger {
            LoopTrigger::Deadline { margin } => {
                let margin_ns = u64::try_from(margin.as_nanos()).unwrap_or(u64::MAX);
                clock::sleep_until_ns(schedule.deadline_ns(margin_ns));
                Trigger::Deadline(inbox.fresh_state_arrival(states_seen))
            }
            LoopTrigger::StateArrival => {
                let open = schedule.open_ns();
                clock::sleep_until_ns(open);
                match inbox.wait_for_state(states_seen, schedule.close_ns()) {
                    Some(arrival) if arrival > open => Trigger::StateArrived(arrival),
                    Some(arrival) => Trigger::StateWaiting(arrival),
                    None => Trigger::Watchdog,
                }
            }
            LoopTrigger::Clock => {
                clock::sleep_until_ns(schedule.centre_ns());
                Trigger::Clock
            }
        };
        let cycle_start = clock::now_ns();
        if end_ns.is_some_and(|end| cycle_start - start_ns >= end) {
            break;
        }
        if let Some(previous) = previous_cycle_start {
            let period = cycle_start.saturating_sub(previous);
            window.period.record(period);
            total.period.record(period);
            let jitter = period.abs_diff(period_ns);
            window.jitter.record(jitter);
            total.jitter.record(jitter);
            if period > miss_ns {
                window.misses += 1;
                total.misses += 1;
            }
        }
        previous_cycle_start = Some(cycle_start);
        tracing::trace!(
            cycle_start,
            centre = schedule.centre_ns(),
            ?trigger,
            "cycle"
        );
        window.count_trigger(trigger);
        total.count_trigger(trigger);

        let snapshot = inbox.take();
        counters = snapshot.counters;
        states_seen = counters.states_received;
        let mut mode = safety.update(&snapshot, cycle_start);
        let mut fresh_state_arrival = None;
        if mode == Mode::Torque {
            // The monitor's torque mode implies both are present.
            if let (Some((state, arrived)), Some((nav, _))) = (snapshot.state, snapshot.nav) {
                if last_used_state_seq == Some(state.seq) {
                    // No state since the last step: the body's clock has not been seen to move
                    // (a simulated body that overran its tick, a late packet), so the
                    // controller's does not either; the command it answered is sent again.
                    window.held_cycles += 1;
                    total.held_cycles += 1;
                } else {
                    let periods = periods_since(last_used_state_seq, state.seq);
                    let result = controller.step(&state, &nav, periods);
                    if result.is_ok() {
                        controller_periods += u64::from(periods);
                    }
                    match result {
                        Ok(output) if output.torques.iter().all(|t| t.is_finite()) => {
                            for (slot, torque) in command.tau.iter_mut().zip(output.torques) {
                                *slot = torque as f32;
                            }
                            command.kd = [0.0; 12];
                            fsm_state = i8::try_from(output.fsm_state).unwrap_or(-1);
                            command.state_seq = state.seq;
                            latest_estimate = Some((state.seq, output.estimate));
                            fresh_state_arrival = Some(arrived);
                            last_used_state_seq = Some(state.seq);
                        }
                        Ok(output) => {
                            safety.controller_failed(
                                format!("non-finite torque {:?}", output.torques),
                                cycle_start,
                            );
                            mode = Mode::Damping;
                        }
                        Err(error) => {
                            safety.controller_failed(format!("{error:#}"), cycle_start);
                            mode = Mode::Damping;
                        }
                    }
                }
            }
        }
        if mode == Mode::Damping {
            // The controller's clock restarts with the next torque cycle's state.
            last_used_state_seq = None;
            command.tau = [0.0; 12];
            command.kd = [config.damping_kd; 12];
            command.state_seq = snapshot.state.map_or(-1, |(s, _)| s.seq);
        }
        command.header.seq = command_seq;
        command.header.utime = wall_utime();
        command_seq += 1;
        send(lcm, &config.channels.low_cmd, &command, &mut command_bytes);
        let sent = clock::now_ns();
        let runtime = sent.saturating_sub(cycle_start);
        window.runtime.record(runtime);
        total.runtime.record(runtime);
        if runtime > period_ns {
            window.overruns += 1;
            total.overruns += 1;
        }
        if let Some(arrived) = fresh_state_arrival {
            let latency = sent.saturating_sub(arrived);
            window.latency.record(latency);
            total.latency.record(latency);
        }
        window_cycles += 1;
        cycles += 1;

        if let Some((state_seq, e)) =
            latest_estimate.filter(|_| cycles % u64::from(config.estimate_every) == 0)
        {
            estimate.header.seq = estimate_seq;
            estimate.header.utime = wall_utime();
            estimate.state_seq = state_seq;
            estimate.position = e.position;
            estimate.velocity = e.velocity;
            estimate.rpy = e.rpy;
            estimate.position_variance = e.position_variance;
            estimate.estimator_status = e.status;
            estimate.fsm_state = fsm_state;
            estimate.safety = mode.safety_code();
            estimate_seq += 1;
            send(
                lcm,
                &config.channels.estimate,
                &estimate,
                &mut estimate_bytes,
            );
        }

        if sent >= next_status {
            let window_total = window_cycles.unsigned_abs();
            if !warned_slow_states && window_total >= 100 && window.held_cycles * 4 > window_total {
                // The controller's clock counts the body's states: a body sending fewer than one
                // per period (a slower rate than `--rate`) would slow it down.
                warned_slow_states = true;
                tracing::warn!(
                    held = window.held_cycles,
                    cycles = window_cycles,
                    "over a quarter of the cycles found no fresh state (states lost or late, or a body slower than --rate): the controller's clock follows the states it gets"
                );
            }
            let status = RobotStatus {
                header: header(status_seq),
                uptime: seconds(sent - start_ns),
                period: config.period.as_secs_f64(),
                window_cycles,
                total_cycles: i64::try_from(cycles).unwrap_or(i64::MAX),
                window_misses: i64::try_from(window.misses).unwrap_or(i64::MAX),
                total_misses: i64::try_from(total.misses).unwrap_or(i64::MAX),
                period_p50: seconds(window.period.percentile_ns(0.5)),
                period_p99: seconds(window.period.percentile_ns(0.99)),
                period_max: seconds(window.period.max_ns()),
                runtime_p50: seconds(window.runtime.percentile_ns(0.5)),
                runtime_p99: seconds(window.runtime.percentile_ns(0.99)),
                runtime_max: seconds(window.runtime.max_ns()),
                latency_p99: seconds(window.latency.percentile_ns(0.99)),
                latency_max: seconds(window.latency.max_ns()),
                safety: safety.mode().safety_code(),
                safety_since: seconds(safety.since_ns().saturating_sub(start_ns)),
                reason: safety.reason().to_owned(),
                damping_entries: safety.damping_entries(),
                fsm_state,
                states_received: counters.states_received,
                states_out_of_order: counters.states_out_of_order,
                states_non_finite: counters.states_non_finite,
                nav_cmds_received: counters.nav_cmds_received,
                malformed_messages: counters.malformed_messages,
                realtime_priority: realtime.fifo_priority,
                memory_locked: realtime.memory_locked,
                jitter_p99: seconds(window.jitter.percentile_ns(0.99)),
                jitter_max: seconds(window.jitter.max_ns()),
                latency_p50: seconds(window.latency.percentile_ns(0.5)),
                window_overruns: i64::try_from(window.overruns).unwrap_or(i64::MAX),
                total_overruns: i64::try_from(total.overruns).unwrap_or(i64::MAX),
            };
            status_seq += 1;
            send(lcm, &config.channels.status, &status, &mut status_bytes);
            window.clear();
            window_cycles = 0;
            next_status += status_ns;
            if next_status <= sent {
                next_status = sent + status_ns;
            }
        }

        let skipped = schedule.advance(trigger, clock::now_ns());
        window.skipped_slots += skipped;
        total.skipped_slots += skipped;
    }
    Ok(RunReport {
        timing: total,
        cycles,
        controller_periods,
        damping_entries: safety.damping_entries(),
        counters,
        realtime,
        final_mode: safety.mode(),
        final_reason: safety.reason().to_owned(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_controller_steps_one_period_per_body_tick() {
        assert_eq!(periods_since(None, 7), 1);
        assert_eq!(periods_since(Some(6), 7), 1);
        // Two states lost in between: the body lived three ticks.
        assert_eq!(periods_since(Some(4), 7), 3);
        assert_eq!(periods_since(Some(0), 25), MAX_CATCH_UP_PERIODS);
        assert_eq!(periods_since(Some(0), i64::MAX), MAX_CATCH_UP_PERIODS);
        assert_eq!(
            periods_since(Some(i64::MIN), i64::MAX),
            MAX_CATCH_UP_PERIODS
        );
        // A restarted body numbers from the start again.
        assert_eq!(periods_since(Some(900), 1), 1);
        assert_eq!(periods_since(Some(7), 7), 1);
    }
}
