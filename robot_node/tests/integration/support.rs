//! A node on a memq bus with a fake body that sends a rigid standing low_state_t, either in
//! answer to every low_cmd_t (lockstep) or on its own clock, a fake navigator, and recorders
//! of commands and status messages.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use lcm_transport::Lcm;
use lcm_types::pfnav::{Header, LowCmd, LowState, NavCmd, RobotEstimate, RobotStatus};
use lcm_types::Message;
use pfnav_robot::clock::now_ns;
use pfnav_robot::fmu_host::UnpackedFmu;
use pfnav_robot::model_description::ScalarKind;
use pfnav_robot::{NodeConfig, RobotChannels, RunReport};

/// The controller FMU users validate: `$PFNAV_FMU_OUT`, else `$CARGO_TARGET_DIR/fmu/…`, else
/// the repo's `target/fmu/QuadController.fmu` (built by scripts/build_fmu_portable.sh).
pub fn fmu_path() -> PathBuf {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let candidates = [
        std::env::var_os("PFNAV_FMU_OUT").map(PathBuf::from),
        std::env::var_os("CARGO_TARGET_DIR")
            .map(|d| PathBuf::from(d).join("fmu/QuadController.fmu")),
        Some(repo.join("target/fmu/QuadController.fmu")),
    ];
    candidates
        .into_iter()
        .flatten()
        .find(|p| p.is_file())
        .expect("no QuadController.fmu: run scripts/build_fmu_portable.sh or set PFNAV_FMU_OUT")
}

/// What the fake body does with the next command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Body {
    /// Answer with the standing state, seq + 1.
    Answer,
    /// Answer nothing (a dead body or link).
    Silent,
    /// Answer once with a NaN joint velocity, then go back to `Answer`.
    NanOnce,
    /// Answer once with a seq 5 below the last, then go back to `Answer`.
    OutOfOrderOnce,
    /// Answer with garbage bytes instead of a state.
    Garbage,
    /// Skip every n-th tick: no state and no seq for it (a simulated body that overran its
    /// tick: its time did not move).
    StallEvery(i64),
    /// Lose every n-th state: its seq is used, the packet never arrives (a lossy link: the
    /// body's time moved).
    LoseEvery(i64),
}

/// One command as the body received it.
#[derive(Debug, Clone, Copy)]
pub struct Received {
    pub at_ns: u64,
    pub damping: bool,
    pub finite: bool,
    /// The seq of the state the command answers.
    pub state_seq: i64,
}

impl Received {
    /// A torque command (not damping) that answers a state.
    pub fn answers_a_state(&self) -> bool {
        !self.damping && self.state_seq >= 0
    }
}

pub struct Rig {
    pub lcm: Arc<Lcm>,
    pub channels: RobotChannels,
    pub body: Arc<Mutex<Body>>,
    pub commands: Arc<Mutex<Vec<Received>>>,
    pub statuses: Arc<Mutex<Vec<RobotStatus>>>,
    pub estimates: Arc<Mutex<Vec<RobotEstimate>>>,
    /// CLOCK_MONOTONIC ns of the body's last answer with a valid state.
    pub last_state_ns: Arc<Mutex<u64>>,
    pub navigator_on: Arc<AtomicBool>,
    shutdown: Arc<AtomicBool>,
    node: Option<JoinHandle<anyhow::Result<RunReport>>>,
    navigator: Option<JoinHandle<()>>,
    body_clock: Option<JoinHandle<()>>,
    _alone: MutexGuard<'static, ()>,
}

/// One rig at a time: each test measures how the node's cycles meet its body, which another
/// rig's node, body and navigator threads beside it would disturb on a small machine.
static RIGS: Mutex<()> = Mutex::new(());

fn standing_state(fmu: &std::path::Path) -> LowState {
    let unpacked = UnpackedFmu::open(fmu).expect("FMU unpacks");
    let start = |name: String| -> f32 {
        unpacked
            .description
            .variable(&name, ScalarKind::Real, "input")
            .ok()
            .and_then(|v| v.start.as_deref()?.parse().ok())
            .unwrap_or_else(|| panic!("{name} has a numeric start value"))
    };
    LowState {
        header: Header {
            frame_id: "body".to_owned(),
            ..Header::default()
        },
        imu_quaternion: [1.0, 0.0, 0.0, 0.0],
        imu_accelerometer: [0.0, 0.0, 9.81],
        q: std::array::from_fn(|j| start(format!("joint.q[{}]", j + 1))),
        foot_force: [30.0; 4],
        foot_contact: [1; 4],
        ..LowState::default()
    }
}

/// How the fake body times its states.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pacing {
    /// Answer every command at once (a body in lockstep with the node).
    Lockstep,
    /// Send a state every period on the body's own absolute deadlines, whatever the node does
    /// (a body with its own clock: a robot's motor boards, or pfnav-sim in real time).
    Clock(Duration),
}

/// The fake body's states: the standing state with seq + 1 each, or what `Body` says instead.
struct FakeBody {
    template: LowState,
    behaviour: Arc<Mutex<Body>>,
    last_state_ns: Arc<Mutex<u64>>,
    seq: i64,
    /// Ticks the body has had (sent or not).
    ticks: i64,
    garbage_seed: u64,
}

impl FakeBody {
    /// The next packet to send on the state channel (None: the body is silent).
    fn next_payload(&mut self) -> Option<Vec<u8>> {
        let mut behaviour = self.behaviour.lock().unwrap();
        self.ticks += 1;
        if matches!(*behaviour, Body::StallEvery(n) if self.ticks % n == 0) {
            return None;
        }
        let mut state = self.template.clone();
        self.seq += 1;
        state.header.seq = self.seq;
        state.tick = self.seq;
        let payload = match *behaviour {
            Body::Silent => return None,
            Body::LoseEvery(n) if self.seq % n == 0 => return None,
            Body::Answer | Body::StallEvery(_) | Body::LoseEvery(_) => {
                state.encode().expect("state encodes")
            }
            Body::NanOnce => {
                *behaviour = Body::Answer;
                state.dq[4] = f32::NAN;
                state.encode().expect("state encodes")
            }
            Body::OutOfOrderOnce => {
                *behaviour = Body::Answer;
                state.header.seq = self.seq - 5;
                state.encode().expect("state encodes")
            }
            Body::Garbage => {
                // xorshift: random lengths and bytes, every third packet behind the right
                // fingerprint so the decoder gets past the first check.
                let seed = &mut self.garbage_seed;
                *seed ^= *seed << 13;
                *seed ^= *seed >> 7;
                *seed ^= *seed << 17;
                let len = (*seed % 400) as usize;
                let mut bytes: Vec<u8> = (0..len).map(|i| (*seed >> (i % 56)) as u8).collect();
                if *seed % 3 == 0 && bytes.len() >= 8 {
                    bytes[..8].copy_from_slice(&LowState::FINGERPRINT.to_be_bytes());
                }
                bytes
            }
        };
        if matches!(
            *behaviour,
            Body::Answer | Body::StallEvery(_) | Body::LoseEvery(_)
        ) {
            *self.last_state_ns.lock().unwrap() = now_ns();
        }
        Some(payload)
    }
}

impl Rig {
    /// Starts a node with `prefix` channels, the fake body answering every command, the
    /// navigator sending Stand every 20 ms, status every 100 ms; `adjust` changes the node's
    /// configuration.
    pub fn start(prefix: &str, adjust: impl FnOnce(&mut NodeConfig)) -> Self {
        Self::start_paced(prefix, Pacing::Lockstep, adjust)
    }

    /// As `start`, with the body timed by `pacing`.
    pub fn start_paced(prefix: &str, pacing: Pacing, adjust: impl FnOnce(&mut NodeConfig)) -> Self {
        // A test that failed with its rig held leaves the lock poisoned, not the next rig.
        let alone = RIGS.lock().unwrap_or_else(PoisonError::into_inner);
        let lcm = Arc::new(Lcm::open("memq://").expect("memq bus"));
        let channels = RobotChannels::with_prefix(prefix).expect("channels");
        let fmu = fmu_path();
        let mut config = NodeConfig::new(fmu.clone(), channels.clone());
        config.status_period = Duration::from_millis(100);
        // Tests share the machine: no SCHED_FIFO, no mlockall of the test process.
        config.realtime_priority = None;
        adjust(&mut config);

        let body = Arc::new(Mutex::new(Body::Answer));
        let commands = Arc::new(Mutex::new(Vec::new()));
        let statuses = Arc::new(Mutex::new(Vec::new()));
        let last_state_ns = Arc::new(Mutex::new(0u64));
        let shutdown = Arc::new(AtomicBool::new(false));
        let fake_body = Arc::new(Mutex::new(FakeBody {
            template: standing_state(&fmu),
            behaviour: body.clone(),
            last_state_ns: last_state_ns.clone(),
            seq: 0,
            ticks: 0,
            garbage_seed: 0x9e37_79b9_7f4a_7c15,
        }));
        {
            let commands = commands.clone();
            let (bus, state_channel) = (Arc::clone(&lcm), channels.low_state.clone());
            let fake_body = fake_body.clone();
            let subscription = lcm
                .subscribe(&channels.low_cmd, move |_, bytes| {
                    let at_ns = now_ns();
                    let Ok(command) = LowCmd::decode(bytes) else {
                        return;
                    };
                    commands.lock().unwrap().push(Received {
                        at_ns,
                        damping: command.kd.iter().any(|&kd| kd > 0.0),
                        finite: command.tau.iter().chain(&command.kd).all(|v| v.is_finite()),
                        state_seq: command.state_seq,
                    });
                    if pacing == Pacing::Lockstep {
                        if let Some(payload) = fake_body.lock().unwrap().next_payload() {
                            let _ = bus.publish(&state_channel, &payload);
                        }
                    }
                })
                .expect("subscribe low_cmd");
            // Subscriptions borrow the bus; the rig keeps the bus for the whole test, so the
            // subscription may live as long (dropping it would unsubscribe the body).
            std::mem::forget(subscription);
        }
        let body_clock = match pacing {
            Pacing::Lockstep => None,
            Pacing::Clock(period) => {
                let (bus, state_channel) = (Arc::clone(&lcm), channels.low_state.clone());
                let shutdown = shutdown.clone();
                let period_ns = period.as_nanos() as u64;
                Some(std::thread::spawn(move || {
                    let mut deadline = now_ns();
                    while !shutdown.load(Ordering::Relaxed) {
                        deadline += period_ns;
                        pfnav_robot::clock::sleep_until_ns(deadline);
                        if let Some(payload) = fake_body.lock().unwrap().next_payload() {
                            let _ = bus.publish(&state_channel, &payload);
                        }
                    }
                }))
            }
        };
        let estimates = Arc::new(Mutex::new(Vec::new()));
        {
            let estimates = estimates.clone();
            let subscription = lcm
                .subscribe(&channels.estimate, move |_, bytes| {
                    if let Ok(estimate) = RobotEstimate::decode(bytes) {
                        estimates.lock().unwrap().push(estimate);
                    }
                })
                .expect("subscribe estimate");
            std::mem::forget(subscription);
        }
        {
            let statuses = statuses.clone();
            let subscription = lcm
                .subscribe(&channels.status, move |_, bytes| {
                    if let Ok(status) = RobotStatus::decode(bytes) {
                        statuses.lock().unwrap().push(status);
                    }
                })
                .expect("subscribe status");
            std::mem::forget(subscription);
        }

        let navigator_on = Arc::new(AtomicBool::new(true));
        let navigator = {
            let (bus, channel) = (Arc::clone(&lcm), channels.nav_cmd.clone());
            let (shutdown, navigator_on) = (shutdown.clone(), navigator_on.clone());
            std::thread::spawn(move || {
                let mut seq = 0;
                while !shutdown.load(Ordering::Relaxed) {
                    if navigator_on.load(Ordering::Relaxed) {
                        let command = NavCmd {
                            header: Header {
                                seq,
                                ..Header::default()
                            },
                            mode: NavCmd::MODE_STAND,
                            ..NavCmd::default()
                        };
                        seq += 1;
                        let _ = bus.publish(&channel, &command.encode().expect("encodes"));
                    }
                    std::thread::sleep(Duration::from_millis(20));
                }
            })
        };
        let node = {
            let (bus, shutdown) = (Arc::clone(&lcm), shutdown.clone());
            std::thread::spawn(move || pfnav_robot::run(bus, config, shutdown))
        };
        Self {
            lcm,
            channels,
            body,
            commands,
            statuses,
            estimates,
            last_state_ns,
            navigator_on,
            shutdown,
            node: Some(node),
            navigator: Some(navigator),
            body_clock,
            _alone: alone,
        }
    }

    pub fn set_body(&self, behaviour: Body) {
        *self.body.lock().unwrap() = behaviour;
    }

    /// Waits (up to `timeout`) for a status message newer than `after_seq` that satisfies
    /// `predicate`; returns it, or panics naming `what` and the last status.
    pub fn wait_status(
        &self,
        what: &str,
        after_seq: i64,
        timeout: Duration,
        predicate: impl Fn(&RobotStatus) -> bool,
    ) -> RobotStatus {
        let start = Instant::now();
        loop {
            {
                let statuses = self.statuses.lock().unwrap();
                if let Some(found) = statuses
                    .iter()
                    .find(|s| s.header.seq > after_seq && predicate(s))
                {
                    return found.clone();
                }
                assert!(
                    start.elapsed() < timeout,
                    "{what}: not within {timeout:?}; last status {:?}",
                    statuses.last()
                );
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Waits (up to `timeout`) until `count` torque commands answering a state have come in;
    /// panics with the number that did. A body starved by a loaded machine takes longer, not
    /// fewer commands.
    pub fn wait_answered_commands(&self, count: usize, timeout: Duration) {
        let start = Instant::now();
        loop {
            let answered = self
                .commands
                .lock()
                .unwrap()
                .iter()
                .filter(|c| c.answers_a_state())
                .count();
            if answered >= count {
                return;
            }
            assert!(
                start.elapsed() < timeout,
                "{answered} of {count} torque commands within {timeout:?}"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Stops the node and returns its report.
    pub fn stop(mut self) -> RunReport {
        self.shutdown.store(true, Ordering::Relaxed);
        if let Some(navigator) = self.navigator.take() {
            navigator.join().expect("navigator thread");
        }
        if let Some(body_clock) = self.body_clock.take() {
            body_clock.join().expect("body clock thread");
        }
        self.node
            .take()
            .expect("running")
            .join()
            .expect("node thread does not panic")
            .expect("node runs without error")
    }
}
