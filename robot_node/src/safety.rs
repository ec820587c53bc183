//! The safety monitor: decides every cycle whether the controller's torques may go to the
//! motors or the motors are damped, and why. Faults: no state for the state timeout, states
//! arriving later than the delay limit by the body's clock (when set), a state with a
//! non-finite value, an out-of-order or repeated state seq, no navigator command for the
//! navigator timeout, a failed controller step. Damping ends after `recover_cycles` cycles in a
//! row without a fault (a flapping link does not toggle the motors every cycle); a controller
//! failure is final (the FMU instance is in its error state).

use crate::inbox::Snapshot;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SafetyConfig {
    pub state_timeout_ns: u64,
    /// Damping when the newest state arrived later than this by the body's clock (`delay`);
    /// None: not checked (a body whose `tick` is not a clock, e.g. one in lockstep).
    pub max_state_delay_ns: Option<u64>,
    pub nav_timeout_ns: u64,
    pub recover_cycles: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    Torque,
    Damping,
}

impl Mode {
    /// The mode as the messages' `safety` field says it (`robot_status_t.SAFETY_*`).
    pub fn safety_code(self) -> i8 {
        match self {
            Mode::Torque => lcm_types::pfnav::RobotStatus::SAFETY_OK,
            Mode::Damping => lcm_types::pfnav::RobotStatus::SAFETY_DAMPING,
        }
    }
}

/// A fault and what its reason says (the ages and values when it was seen). While a fault of
/// one kind persists the reason it began with is kept (the age of the last state when damping
/// began, not a growing one); a fault of another kind replaces it. Plain data: the control loop
/// formats a reason only when the kind changes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Fault {
    Controller,
    NoStateYet,
    StateTimeout { age_ns: u64 },
    StateDelayed { delay_ns: u64 },
    NonFiniteState,
    OutOfOrderState { seq: i64, last: i64 },
    NoNavYet,
    NavTimeout { age_ns: u64 },
}

#[derive(Debug)]
pub struct SafetyMonitor {
    config: SafetyConfig,
    mode: Mode,
    reason: String,
    /// The fault the reason describes (None in torque mode and after recovery).
    fault: Option<Fault>,
    /// CLOCK_MONOTONIC ns of the last change of mode (0: never changed).
    since_ns: u64,
    damping_entries: i64,
    good_cycles: u32,
    controller_failure: Option<String>,
}

impl SafetyMonitor {
    /// Starts in damping: nothing has been heard from the body or the navigator yet.
    pub fn new(config: SafetyConfig) -> Self {
        Self {
            config,
            mode: Mode::Damping,
            reason: "starting: no low_state_t and nav_cmd_t yet".to_owned(),
            fault: None,
            since_ns: 0,
            damping_entries: 0,
            good_cycles: 0,
            controller_failure: None,
        }
    }

    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Why the motors are damped; empty in torque mode.
    pub fn reason(&self) -> &str {
        &self.reason
    }

    pub fn since_ns(&self) -> u64 {
        self.since_ns
    }

    pub fn damping_entries(&self) -> i64 {
        self.damping_entries
    }

    /// The controller failed: damping from now on, with `reason`.
    pub fn controller_failed(&mut self, reason: String, now_ns: u64) {
        self.controller_failure = Some(format!("controller failed: {reason}"));
        self.enter_damping(Fault::Controller, now_ns);
    }

    fn fault(&self, snapshot: &Snapshot, now_ns: u64) -> Option<Fault> {
        if self.controller_failure.is_some() {
            return Some(Fault::Controller);
        }
        match snapshot.state {
            None => return Some(Fault::NoStateYet),
            Some((_, at)) if now_ns.saturating_sub(at) > self.config.state_timeout_ns => {
                return Some(Fault::StateTimeout {
                    age_ns: now_ns.saturating_sub(at),
                })
            }
            Some(_) => {}
        }
        if let Some(limit) = self.config.max_state_delay_ns {
            if snapshot.state_delay_ns > limit {
                return Some(Fault::StateDelayed {
                    delay_ns: snapshot.state_delay_ns,
                });
            }
        }
        if snapshot.non_finite_state {
            return Some(Fault::NonFiniteState);
        }
        if let Some((seq, last)) = snapshot.out_of_order {
            return Some(Fault::OutOfOrderState { seq, last });
        }
        match snapshot.nav {
            None => Some(Fault::NoNavYet),
            Some((_, at)) if now_ns.saturating_sub(at) > self.config.nav_timeout_ns => {
                Some(Fault::NavTimeout {
                    age_ns: now_ns.saturating_sub(at),
                })
            }
            Some(_) => None,
        }
    }

    /// The reason a fault gives in the status message.
    fn describe(&self, fault: Fault) -> String {
        let ms = |ns: u64| ns as f64 * 1e-6;
        match fault {
            Fault::Controller => self.controller_failure.clone().unwrap_or_default(),
            Fault::NoStateYet => "no low_state_t received yet".to_owned(),
            Fault::StateTimeout { age_ns } => format!(
                "no low_state_t for {:.1} ms (timeout {:.1} ms)",
                ms(age_ns),
                ms(self.config.state_timeout_ns)
            ),
            Fault::StateDelayed { delay_ns } => format!(
                "low_state_t delayed by {:.1} ms (limit {:.1} ms)",
                ms(delay_ns),
                ms(self.config.max_state_delay_ns.unwrap_or_default())
            ),
            Fault::NonFiniteState => "non-finite value in low_state_t".to_owned(),
            Fault::OutOfOrderState { seq, last } => {
                format!("out-of-order low_state_t seq {seq} after {last}")
            }
            Fault::NoNavYet => "no nav_cmd_t received yet".to_owned(),
            Fault::NavTimeout { age_ns } => format!(
                "no nav_cmd_t for {:.1} ms (timeout {:.1} ms)",
                ms(age_ns),
                ms(self.config.nav_timeout_ns)
            ),
        }
    }

    fn enter_damping(&mut self, fault: Fault, now_ns: u64) {
        self.good_cycles = 0;
        let same_kind = self
            .fault
            .is_some_and(|kept| std::mem::discriminant(&kept) == std::mem::discriminant(&fault));
        if !same_kind {
            self.fault = Some(fault);
            self.reason = self.describe(fault);
        }
        if self.mode == Mode::Torque {
            self.mode = Mode::Damping;
            self.since_ns = now_ns;
            self.damping_entries += 1;
            tracing::warn!(reason = %self.reason, "damping");
        }
    }

    /// The mode of this cycle, given the inbox's snapshot at `now_ns`.
    pub fn update(&mut self, snapshot: &Snapshot, now_ns: u64) -> Mode {
        match self.fault(snapshot, now_ns) {
            Some(fault) => self.enter_damping(fault, now_ns),
            None if self.mode == Mode::Damping => {
                self.good_cycles += 1;
                if self.good_cycles >= self.config.recover_cycles {
                    tracing::info!(after = %self.reason, "torque control");
                    self.mode = Mode::Torque;
                    self.since_ns = now_ns;
                    self.reason.clear();
                    self.fault = None;
                }
            }
            None => {}
        }
        self.mode
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inbox::{BodyState, NavReference};

    const MS: u64 = 1_000_000;

    /// A fault's expected reason and the snapshot that shows it at a time.
    type FaultCase = (&'static str, Box<dyn Fn(u64) -> Snapshot>);

    fn config() -> SafetyConfig {
        SafetyConfig {
            state_timeout_ns: 20 * MS,
            max_state_delay_ns: Some(30 * MS),
            nav_timeout_ns: 500 * MS,
            recover_cycles: 3,
        }
    }

    fn healthy(now: u64) -> Snapshot {
        Snapshot {
            state: Some((BodyState::default(), now)),
            nav: Some((NavReference::default(), now)),
            ..Snapshot::default()
        }
    }

    fn run_healthy(monitor: &mut SafetyMonitor, from: u64, cycles: u64) -> Mode {
        let mut mode = monitor.mode();
        for k in 0..cycles {
            mode = monitor.update(&healthy(from + k * MS), from + k * MS);
        }
        mode
    }

    #[test]
    fn starts_damped_and_enters_torque_after_the_recovery_cycles() {
        let mut monitor = SafetyMonitor::new(config());
        assert_eq!(monitor.update(&Snapshot::default(), 0), Mode::Damping);
        assert!(
            monitor.reason().contains("no low_state_t"),
            "{}",
            monitor.reason()
        );
        assert_eq!(run_healthy(&mut monitor, MS, 2), Mode::Damping);
        assert_eq!(run_healthy(&mut monitor, 3 * MS, 1), Mode::Torque);
        assert_eq!(monitor.reason(), "");
        assert_eq!(monitor.damping_entries(), 0, "the start is no entry");
    }

    #[test]
    fn each_fault_damps_with_its_reason_and_clears() {
        let faults: Vec<FaultCase> = vec![
            (
                "no low_state_t for 21.0 ms",
                Box::new(|now| Snapshot {
                    state: Some((BodyState::default(), now - 21 * MS)),
                    ..healthy(now)
                }),
            ),
            (
                "low_state_t delayed by 31.5 ms (limit 30.0 ms)",
                Box::new(|now| Snapshot {
                    state_delay_ns: 31_500_000,
                    ..healthy(now)
                }),
            ),
            (
                "non-finite value",
                Box::new(|now| Snapshot {
                    non_finite_state: true,
                    ..healthy(now)
                }),
            ),
            (
                "out-of-order low_state_t seq 3 after 9",
                Box::new(|now| Snapshot {
                    out_of_order: Some((3, 9)),
                    ..healthy(now)
                }),
            ),
            (
                "no nav_cmd_t for 501.0 ms",
                Box::new(|now| Snapshot {
                    nav: Some((NavReference::default(), now - 501 * MS)),
                    ..healthy(now)
                }),
            ),
        ];
        let mut monitor = SafetyMonitor::new(config());
        let mut now = 1_000 * MS;
        assert_eq!(run_healthy(&mut monitor, now, 3), Mode::Torque);
        for (entries, (reason, snapshot)) in faults.iter().enumerate() {
            now += 10 * MS;
            assert_eq!(
                monitor.update(&snapshot(now), now),
                Mode::Damping,
                "{reason}"
            );
            assert!(
                monitor.reason().contains(reason),
                "{reason} vs {}",
                monitor.reason()
            );
            assert_eq!(monitor.since_ns(), now);
            assert_eq!(monitor.damping_entries(), entries as i64 + 1);
            // A fault in the middle of the recovery restarts the count.
            assert_eq!(run_healthy(&mut monitor, now + MS, 2), Mode::Damping);
            assert_eq!(
                monitor.update(&snapshot(now + 3 * MS), now + 3 * MS),
                Mode::Damping
            );
            assert_eq!(run_healthy(&mut monitor, now + 4 * MS, 2), Mode::Damping);
            assert_eq!(run_healthy(&mut monitor, now + 6 * MS, 1), Mode::Torque);
            now += 10 * MS;
        }
    }

    #[test]
    fn a_persisting_fault_keeps_the_reason_it_began_with() {
        let mut monitor = SafetyMonitor::new(config());
        assert_eq!(run_healthy(&mut monitor, 0, 3), Mode::Torque);
        let last_state = 2 * MS;
        let stale = |now: u64| Snapshot {
            state: Some((BodyState::default(), last_state)),
            ..healthy(now)
        };
        monitor.update(&stale(last_state + 21 * MS), last_state + 21 * MS);
        monitor.update(&stale(last_state + 90 * MS), last_state + 90 * MS);
        assert_eq!(
            monitor.reason(),
            "no low_state_t for 21.0 ms (timeout 20.0 ms)",
            "the age when damping began"
        );
        let nan = Snapshot {
            non_finite_state: true,
            ..healthy(last_state + 91 * MS)
        };
        monitor.update(&nan, last_state + 91 * MS);
        assert_eq!(monitor.reason(), "non-finite value in low_state_t");
        assert_eq!(monitor.damping_entries(), 1);
    }

    #[test]
    fn a_controller_failure_is_final() {
        let mut monitor = SafetyMonitor::new(config());
        assert_eq!(run_healthy(&mut monitor, 0, 3), Mode::Torque);
        monitor.controller_failed("fmi2DoStep returned fmi2Error".to_owned(), 5 * MS);
        assert_eq!(run_healthy(&mut monitor, 6 * MS, 100), Mode::Damping);
        assert!(monitor.reason().contains("fmi2DoStep"));
    }
}
