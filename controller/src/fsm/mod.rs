//! Gait state machine in the style of MIT Cheetah-Software's `ControlFSM`: one state per file,
//! each with `enter` (entry actions), `run` (per-tick behaviour, producing an [`Actuation`]) and
//! `check_transition` (exit conditions, evaluated before `run`). Passive → stand-up → stand ↔
//! locomotion; any balancing state drops to damping on a fault (tilt, joint limit), and damping
//! is left only through an explicit request for passive.

mod damping;
mod locomotion;
mod passive;
mod stand;
mod stand_up;

use crate::api::{FsmState, Leg, ModeRequest, Reference, LEG_JOINT_NAMES, NUM_JOINTS, NUM_LEGS};
use crate::config::ControllerConfig;
use crate::estimate::Estimate;
use crate::estimator::StancePlan;
use crate::footholds::FootholdPlanner;
use crate::gait::Gait;
use crate::leg_control::LegControl;
use crate::model::RobotModel;
use crate::mpc_schedule::MpcScheduler;
use serde::{Deserialize, Serialize};

use damping::Damping;
use locomotion::Locomotion;
use passive::Passive;
use stand::Stand;
use stand_up::StandUp;

/// The pipeline stages a state drives: footholds, MPC scheduling and the leg torque laws.
pub struct Stages {
    /// Foothold planner and terrain knowledge.
    pub footholds: FootholdPlanner,
    /// MPC scheduling and the forces it holds.
    pub mpc: MpcScheduler,
    /// Leg torque laws.
    pub legs: LegControl,
}

/// Output of a state's run step.
pub struct Actuation {
    /// Joint torques before the effort clamp, N·m.
    pub torques: [f64; NUM_JOINTS],
    /// Scheduled stance per leg.
    pub contacts: [bool; NUM_LEGS],
    /// Ground reaction forces on the robot, world frame, N.
    pub forces: [[f64; 3]; NUM_LEGS],
    /// Desired foot positions, world frame, m.
    pub feet: [[f64; 3]; NUM_LEGS],
}

impl Actuation {
    /// Every foot in stance where it is, carrying `forces`.
    fn all_stance(
        torques: [f64; NUM_JOINTS],
        forces: [[f64; 3]; NUM_LEGS],
        estimate: &Estimate,
    ) -> Self {
        Actuation {
            torques,
            contacts: [true; NUM_LEGS],
            forces,
            feet: measured_feet(estimate),
        }
    }
}

/// What a state's run step reads this tick.
#[derive(Clone, Copy)]
pub struct Tick<'a> {
    /// The robot.
    pub model: &'a RobotModel,
    /// State estimate of this tick.
    pub estimate: &'a Estimate,
    /// The master's reference.
    pub reference: &'a Reference,
    /// Tick length, s.
    pub dt: f64,
    /// Time since the current state was entered, s.
    pub state_time: f64,
}

/// The exit of a balancing state: damping on a fault (logged with its reason), else the state
/// the mode asks for when that is not `current`.
fn balancing_transition(
    fault: Option<&str>,
    mode: ModeRequest,
    current: FsmState,
) -> Option<FsmState> {
    if let Some(reason) = fault {
        tracing::warn!(%reason, state = ?current, "fault: entering damping");
        return Some(FsmState::Damping);
    }
    let requested = match mode {
        ModeRequest::Passive => FsmState::Passive,
        ModeRequest::Stand => FsmState::Stand,
        ModeRequest::Locomotion => FsmState::Locomotion,
    };
    (requested != current).then_some(requested)
}

/// A change of state, with the fault that caused it when it is a drop to damping.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FsmTransition {
    /// State left.
    pub from: FsmState,
    /// State entered.
    pub to: FsmState,
    /// Which check failed with which value, for a transition caused by a fault.
    pub reason: Option<String>,
}

/// Tilt and joint-limit fault detection shared by the balancing states.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct FaultMonitor {
    max_tilt: f64,
    joint_limit_margin: f64,
}

impl FaultMonitor {
    /// Tilt or joint-limit fault, with a reason for the log.
    fn check(&self, estimate: &Estimate, legs: &LegControl) -> Option<String> {
        let tilt = estimate.rotation[(2, 2)].clamp(-1.0, 1.0).acos();
        if tilt > self.max_tilt {
            return Some(format!(
                "tilt check: base tilted {tilt:.3} rad, more than max.tilt {:.3} rad",
                self.max_tilt
            ));
        }
        let margin = self.joint_limit_margin;
        let (lower, upper) = legs.joint_limits();
        for leg in Leg::ALL {
            for j in 0..LEG_JOINT_NAMES.len() {
                let i = 3 * leg.index() + j;
                let q = estimate.q[leg.index()][j];
                if q < lower[i] - margin || q > upper[i] + margin {
                    return Some(format!(
                        "joint-limit check: joint {i} ({}) at {q:.3} rad beyond its limits [{:.3}, {:.3}] rad by more than the margin {margin:.3} rad",
                        leg.joint_label(j),
                        lower[i],
                        upper[i]
                    ));
                }
            }
        }
        None
    }
}

/// The state machine: the current state, how long it has run, and each state's own data.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Fsm {
    current: FsmState,
    /// Time since the current state was entered, s.
    state_time: f64,
    faults: FaultMonitor,
    passive: Passive,
    stand_up: StandUp,
    stand: Stand,
    locomotion: Locomotion,
    damping: Damping,
}

impl Fsm {
    /// The state machine of `config`, starting passive.
    pub fn new(config: &ControllerConfig) -> Self {
        Fsm {
            current: FsmState::Passive,
            state_time: 0.0,
            faults: FaultMonitor {
                max_tilt: config.max_tilt,
                joint_limit_margin: config.joint_limit_margin,
            },
            passive: Passive,
            stand_up: StandUp::new(config.stand_up_duration),
            stand: Stand::new(),
            locomotion: Locomotion::new(Gait::new(config.gait, config.gait_period), config),
            damping: Damping,
        }
    }

    /// Current state.
    pub fn state(&self) -> FsmState {
        self.current
    }

    /// Which legs this tick's state plans in stance: the gait schedule in locomotion, all four
    /// (mid-stance) otherwise: standing, standing up, and resting or damping on the ground.
    pub fn stance_plan(&self) -> StancePlan {
        match self.current {
            FsmState::Locomotion => self.locomotion.stance_plan(),
            _ => [Some(0.5); NUM_LEGS],
        }
    }

    /// The state the current one hands over to this tick, if any, with the fault that caused
    /// it (a drop to damping).
    pub fn check_transition(
        &self,
        stages: &Stages,
        estimate: &Estimate,
        reference: &Reference,
    ) -> Option<FsmTransition> {
        // Only the balancing states watch for faults.
        let fault = match self.current {
            FsmState::Passive | FsmState::Damping => None,
            FsmState::StandUp | FsmState::Stand | FsmState::Locomotion => {
                self.faults.check(estimate, &stages.legs)
            }
        };
        let mode = reference.mode;
        let next = match self.current {
            FsmState::Passive => self.passive.check_transition(mode),
            FsmState::StandUp => {
                self.stand_up
                    .check_transition(fault.as_deref(), mode, self.state_time)
            }
            FsmState::Stand => self.stand.check_transition(fault.as_deref(), mode),
            FsmState::Locomotion => self.locomotion.check_transition(fault.as_deref(), mode),
            FsmState::Damping => self.damping.check_transition(mode),
        }?;
        let reason = fault.filter(|_| next == FsmState::Damping);
        Some(FsmTransition {
            from: self.current,
            to: next,
            reason,
        })
    }

    /// Enters `next`: resets the state time, makes the MPC solve on the next balancing tick and
    /// runs the state's entry actions.
    pub fn enter(&mut self, next: FsmState, stages: &mut Stages, estimate: &Estimate) {
        tracing::debug!(from = ?self.current, to = ?next, "FSM transition");
        self.current = next;
        self.state_time = 0.0;
        stages.mpc.solve_on_next_update();
        match next {
            FsmState::Passive => self.passive.enter(stages),
            FsmState::StandUp => self.stand_up.enter(estimate),
            FsmState::Stand => self.stand.enter(estimate),
            FsmState::Locomotion => self.locomotion.enter(estimate),
            FsmState::Damping => self.damping.enter(stages),
        }
    }

    /// Runs the current state for one tick of `dt` seconds.
    pub fn run(
        &mut self,
        model: &RobotModel,
        stages: &mut Stages,
        estimate: &Estimate,
        reference: &Reference,
        dt: f64,
    ) -> Actuation {
        let tick = Tick {
            model,
            estimate,
            reference,
            dt,
            state_time: self.state_time,
        };
        let actuation = match self.current {
            FsmState::Passive => self.passive.run(),
            FsmState::StandUp => self.stand_up.run(stages, &tick),
            FsmState::Stand => self.stand.run(stages, &tick),
            FsmState::Locomotion => self.locomotion.run(stages, &tick),
            FsmState::Damping => self.damping.run(stages, &tick),
        };
        self.state_time += dt;
        actuation
    }
}

/// Feet reported while no foot is planned: where they are.
fn measured_feet(estimate: &Estimate) -> [[f64; 3]; NUM_LEGS] {
    estimate.feet_world.map(|f| [f.x, f.y, f.z])
}
