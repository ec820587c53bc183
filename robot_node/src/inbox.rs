//! The receiving side of the node: decodes `low_state_t` and `nav_cmd_t` packets on the LCM
//! thread, checks them, and keeps the newest good one of each for the control loop, which
//! takes a copy once per cycle. Bad packets are counted, never stored, and never panic.

use std::sync::{Condvar, Mutex, PoisonError};
use std::time::Duration;

use lcm_types::pfnav::{LowState, NavCmd};
use lcm_types::Message;

use crate::delay::DelayTracker;

/// A `low_state_t` as the controller uses it (no heap: the control loop copies it).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BodyState {
    pub seq: i64,
    pub imu_quaternion: [f32; 4],
    pub imu_gyroscope: [f32; 3],
    pub imu_accelerometer: [f32; 3],
    pub q: [f32; 12],
    pub dq: [f32; 12],
    pub foot_contact: [i8; 4],
}

impl BodyState {
    fn from_message(m: &LowState) -> Self {
        Self {
            seq: m.header.seq,
            imu_quaternion: m.imu_quaternion,
            imu_gyroscope: m.imu_gyroscope,
            imu_accelerometer: m.imu_accelerometer,
            q: m.q,
            dq: m.dq,
            foot_contact: m.foot_contact,
        }
    }
}

/// Every float of the message is finite (the controller reads all but tau_est and foot_force,
/// but a NaN anywhere means the sender is broken).
fn low_state_is_finite(m: &LowState) -> bool {
    m.imu_quaternion
        .iter()
        .chain(&m.imu_gyroscope)
        .chain(&m.imu_accelerometer)
        .chain(&m.q)
        .chain(&m.dq)
        .chain(&m.tau_est)
        .chain(&m.foot_force)
        .all(|v| v.is_finite())
}

/// A `nav_cmd_t` as the controller uses it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NavReference {
    pub mode: i8,
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub yaw: f64,
    pub vx: f64,
    pub vy: f64,
    pub yaw_rate: f64,
    pub body_height: f64,
    pub terrain_dzdx: f64,
    pub terrain_dzdy: f64,
}

impl NavReference {
    fn from_message(m: &NavCmd) -> Option<Self> {
        let values = [
            m.x,
            m.y,
            m.z,
            m.yaw,
            m.vx,
            m.vy,
            m.yaw_rate,
            m.body_height,
            m.terrain_dzdx,
            m.terrain_dzdy,
        ];
        let known_mode = [
            NavCmd::MODE_PASSIVE,
            NavCmd::MODE_STAND,
            NavCmd::MODE_LOCOMOTION,
        ]
        .contains(&m.mode);
        (known_mode && values.iter().all(|v| v.is_finite())).then_some(Self {
            mode: m.mode,
            x: m.x,
            y: m.y,
            z: m.z,
            yaw: m.yaw,
            vx: m.vx,
            vy: m.vy,
            yaw_rate: m.yaw_rate,
            body_height: m.body_height,
            terrain_dzdx: m.terrain_dzdx,
            terrain_dzdy: m.terrain_dzdy,
        })
    }
}

/// Message counters since start (reported in robot_status_t).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    pub states_received: i64,
    pub states_out_of_order: i64,
    pub states_non_finite: i64,
    pub nav_cmds_received: i64,
    pub malformed_messages: i64,
}

/// What the control loop takes each cycle.
#[derive(Debug, Clone, Copy, Default)]
pub struct Snapshot {
    /// The newest accepted state and its arrival time (CLOCK_MONOTONIC ns).
    pub state: Option<(BodyState, u64)>,
    /// The newest valid navigator command and its arrival time.
    pub nav: Option<(NavReference, u64)>,
    /// A state with a non-finite value arrived since the previous snapshot.
    pub non_finite_state: bool,
    /// A state with a seq at or below the last accepted one arrived since the previous
    /// snapshot: (its seq, the last accepted seq).
    pub out_of_order: Option<(i64, i64)>,
    /// How late the newest accepted state arrived by the body's clock (`delay`), ns.
    pub state_delay_ns: u64,
    pub counters: Counters,
}

#[derive(Debug, Default)]
struct Held {
    snapshot: Snapshot,
    delay: DelayTracker,
}

/// Shared between the LCM thread (writer) and the control loop (reader); each side holds the
/// lock for a copy of a few hundred bytes. The control loop can wait for the next accepted
/// state ([`Inbox::wait_for_state`]): the LCM thread wakes it as soon as one is stored.
#[derive(Debug)]
pub struct Inbox {
    held: Mutex<Held>,
    state_accepted: Condvar,
    /// After this long without an accepted state the link counts as lost, and the next state
    /// may start a new sequence (a restarted body counts from 0 again).
    sequence_restart_ns: u64,
}

impl Inbox {
    pub fn new(sequence_restart_ns: u64) -> Self {
        Self {
            held: Mutex::new(Held::default()),
            state_accepted: Condvar::new(),
            sequence_restart_ns,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Held> {
        // The critical sections only copy plain data; a poisoned lock still holds consistent data.
        self.held.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// A `low_state_t` packet received at `now_ns`.
    pub fn on_low_state(&self, bytes: &[u8], now_ns: u64) {
        let decoded = LowState::decode(bytes);
        let mut held = self.lock();
        let snapshot = &mut held.snapshot;
        let message = match decoded {
            Ok(message) => message,
            Err(error) => {
                snapshot.counters.malformed_messages += 1;
                tracing::debug!(%error, "malformed low_state_t");
                return;
            }
        };
        if !low_state_is_finite(&message) {
            snapshot.counters.states_non_finite += 1;
            snapshot.non_finite_state = true;
            return;
        }
        let seq = message.header.seq;
        if let Some((last, received)) = snapshot.state.map(|(s, at)| (s.seq, at)) {
            let link_alive = now_ns.saturating_sub(received) <= self.sequence_restart_ns;
            if link_alive && seq <= last {
                snapshot.counters.states_out_of_order += 1;
                snapshot.out_of_order = Some((seq, last));
                return;
            }
        }
        snapshot.counters.states_received += 1;
        snapshot.state = Some((BodyState::from_message(&message), now_ns));
        let delay_ns = held.delay.observe(message.tick, now_ns);
        held.snapshot.state_delay_ns = delay_ns;
        drop(held);
        self.state_accepted.notify_one();
    }

    /// Waits until more than `accepted` states have been accepted in all (compare
    /// `Counters::states_received` of the last snapshot) or CLOCK_MONOTONIC reaches `until_ns`,
    /// whichever comes first. Returns the arrival time of the newest state if one came, None
    /// at the deadline.
    pub fn wait_for_state(&self, accepted: i64, until_ns: u64) -> Option<u64> {
        let mut held = self.lock();
        loop {
            if held.snapshot.counters.states_received > accepted {
                return held.snapshot.state.map(|(_, at)| at);
            }
            let now = crate::clock::now_ns();
            if now >= until_ns {
                return None;
            }
            held = self
                .state_accepted
                .wait_timeout(held, Duration::from_nanos(until_ns - now))
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    /// The arrival time of the newest state if more than `accepted` states have been accepted
    /// in all (a fresh one since the snapshot that counted `accepted`), without waiting.
    pub fn fresh_state_arrival(&self, accepted: i64) -> Option<u64> {
        let held = self.lock();
        if held.snapshot.counters.states_received > accepted {
            held.snapshot.state.map(|(_, at)| at)
        } else {
            None
        }
    }

    /// A `nav_cmd_t` packet received at `now_ns`; one with an unknown mode or a non-finite
    /// value counts as malformed.
    pub fn on_nav_cmd(&self, bytes: &[u8], now_ns: u64) {
        let reference = NavCmd::decode(bytes)
            .ok()
            .and_then(|m| NavReference::from_message(&m));
        let mut held = self.lock();
        let snapshot = &mut held.snapshot;
        match reference {
            Some(reference) => {
                snapshot.counters.nav_cmds_received += 1;
                snapshot.nav = Some((reference, now_ns));
            }
            None => snapshot.counters.malformed_messages += 1,
        }
    }

    /// A packet on one of the node's channels that is not a message of that channel's type
    /// (counted as malformed).
    pub fn on_malformed(&self) {
        self.lock().snapshot.counters.malformed_messages += 1;
    }

    /// The newest messages and the events since the previous call (which are then cleared).
    pub fn take(&self) -> Snapshot {
        let mut held = self.lock();
        let snapshot = held.snapshot;
        held.snapshot.non_finite_state = false;
        held.snapshot.out_of_order = None;
        snapshot
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(seq: i64) -> LowState {
        LowState {
            header: lcm_types::pfnav::Header {
                seq,
                ..Default::default()
            },
            imu_quaternion: [1.0, 0.0, 0.0, 0.0],
            ..Default::default()
        }
    }

    fn bytes(m: &impl Message) -> Vec<u8> {
        m.encode().expect("consistent message")
    }

    #[test]
    fn newest_in_order_state_is_kept_and_bad_ones_are_counted() {
        let inbox = Inbox::new(20_000_000);
        inbox.on_low_state(&bytes(&state(5)), 1_000);
        inbox.on_low_state(&bytes(&state(6)), 2_000);
        let taken = inbox.take();
        assert_eq!(taken.state.map(|(s, at)| (s.seq, at)), Some((6, 2_000)));
        assert!(!taken.non_finite_state && taken.out_of_order.is_none());

        inbox.on_low_state(&bytes(&state(6)), 3_000);
        inbox.on_low_state(&bytes(&state(4)), 3_500);
        let mut nan = state(7);
        nan.dq[3] = f32::NAN;
        inbox.on_low_state(&bytes(&nan), 4_000);
        inbox.on_low_state(b"garbage", 5_000);
        let taken = inbox.take();
        assert_eq!(
            taken.state.map(|(s, _)| s.seq),
            Some(6),
            "nothing bad replaces the state"
        );
        assert_eq!(taken.out_of_order, Some((4, 6)));
        assert!(taken.non_finite_state);
        assert_eq!(
            taken.counters,
            Counters {
                states_received: 2,
                states_out_of_order: 2,
                states_non_finite: 1,
                malformed_messages: 1,
                ..Counters::default()
            }
        );
        let again = inbox.take();
        assert!(
            !again.non_finite_state && again.out_of_order.is_none(),
            "events are cleared"
        );
    }

    #[test]
    fn a_waiting_loop_is_woken_by_the_next_accepted_state_only() {
        let inbox = std::sync::Arc::new(Inbox::new(20_000_000));
        inbox.on_low_state(&bytes(&state(1)), 5);
        let accepted = inbox.take().counters.states_received;
        assert_eq!(
            inbox.wait_for_state(accepted - 1, 0),
            Some(5),
            "already there"
        );
        assert_eq!(
            inbox.wait_for_state(accepted, crate::clock::now_ns() + 1_000_000),
            None,
            "nothing new: the deadline ends the wait"
        );
        let writer = std::sync::Arc::clone(&inbox);
        let sender = std::thread::spawn(move || {
            writer.on_low_state(b"garbage", 10);
            writer.on_low_state(&bytes(&state(1)), 20);
            writer.on_low_state(&bytes(&state(2)), 30);
        });
        // Generous deadline: only a state the inbox accepts (seq 2) ends this wait early.
        let woke = inbox.wait_for_state(accepted, crate::clock::now_ns() + 60_000_000_000);
        sender.join().expect("sender");
        assert_eq!(woke, Some(30));
    }

    #[test]
    fn after_a_link_loss_a_restarted_sequence_is_accepted() {
        let inbox = Inbox::new(20_000_000);
        inbox.on_low_state(&bytes(&state(900)), 1_000_000);
        inbox.on_low_state(&bytes(&state(0)), 1_000_000 + 10_000_000);
        assert_eq!(
            inbox.take().state.map(|(s, _)| s.seq),
            Some(900),
            "within the timeout: out of order"
        );
        inbox.on_low_state(&bytes(&state(0)), 1_000_000 + 30_000_000);
        assert_eq!(
            inbox.take().state.map(|(s, _)| s.seq),
            Some(0),
            "after it: a new sequence"
        );
    }

    #[test]
    fn nav_commands_with_unknown_modes_or_non_finite_values_are_malformed() {
        let inbox = Inbox::new(20_000_000);
        let good = NavCmd {
            mode: NavCmd::MODE_LOCOMOTION,
            vx: 0.5,
            ..Default::default()
        };
        inbox.on_nav_cmd(&bytes(&good), 10);
        inbox.on_nav_cmd(
            &bytes(&NavCmd {
                mode: 9,
                ..good.clone()
            }),
            20,
        );
        inbox.on_nav_cmd(
            &bytes(&NavCmd {
                yaw: f64::INFINITY,
                ..good.clone()
            }),
            30,
        );
        inbox.on_nav_cmd(&bytes(&state(1)), 40);
        let taken = inbox.take();
        assert_eq!(taken.nav.map(|(n, at)| (n.vx, at)), Some((0.5, 10)));
        assert_eq!(taken.counters.nav_cmds_received, 1);
        assert_eq!(taken.counters.malformed_messages, 3);
    }
}
