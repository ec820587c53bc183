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
use nalgebra::Vector3;
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

/// Angle between the body's z axis and the unit vector `normal`, rad.
fn tilt_from(estimate: &Estimate, normal: &Vector3<f64>) -> f64 {
    let body_z = estimate.rotation.column(2);
    body_z.dot(normal).clamp(-1.0, 1.0).acos()
}

impl FaultMonitor {
    /// Tilt or joint-limit fault, with a reason for the log. The base has tilted over when it
    /// is beyond `max_tilt` both from the ground's normal under the feet (`normal`, the MPC's
    /// friction normal) and from world vertical. From the normal alone, a body parallel to a
    /// 30° incline has not tilted, where from vertical it would have only 0.9 − 0.52 rad left
    /// for transients (docs/slopes.md, 3e). From vertical too, because the normal is a plane
    /// fitted under the feet and the body: a trunk pushed sideways towards a flank has it
    /// tilted 20–30° the other way while the trunk itself is still within 30° of upright, and
    /// damping it there made the fall (docs/push-recovery.md).
    fn check(
        &self,
        estimate: &Estimate,
        legs: &LegControl,
        normal: &Vector3<f64>,
    ) -> Option<String> {
        let from_normal = tilt_from(estimate, normal);
        let from_vertical = tilt_from(estimate, &Vector3::z());
        if from_normal.is_nan()
            || from_vertical.is_nan()
            || from_normal.min(from_vertical) > self.max_tilt
        {
            return Some(format!(
                "tilt check: base tilted {from_normal:.3} rad from the ground's normal and {from_vertical:.3} rad from vertical, more than max.tilt {:.3} rad",
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
                let normal =
                    stages
                        .footholds
                        .friction_normal(reference, estimate, [true; NUM_LEGS]);
                self.faults.check(estimate, &stages.legs, &normal)
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
    pub fn enter(
        &mut self,
        next: FsmState,
        model: &RobotModel,
        stages: &mut Stages,
        estimate: &Estimate,
        reference: &Reference,
    ) {
        tracing::debug!(from = ?self.current, to = ?next, "FSM transition");
        self.current = next;
        self.state_time = 0.0;
        stages.mpc.solve_on_next_update();
        match next {
            FsmState::Passive => self.passive.enter(stages),
            FsmState::StandUp => self.stand_up.enter(model, stages, estimate, reference),
            FsmState::Stand => self.stand.enter(stages, estimate),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::rpy_of;
    use nalgebra::Rotation3;

    fn estimate_with(rotation: Rotation3<f64>) -> Estimate {
        let rotation = *rotation.matrix();
        Estimate {
            rotation,
            rpy: rpy_of(&rotation),
            position: Vector3::zeros(),
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
            q: [[0.0; 3]; NUM_LEGS],
            dq: [[0.0; 3]; NUM_LEGS],
            feet_world: [Vector3::zeros(); NUM_LEGS],
            gravity_body: [0.0; 3],
        }
    }

    fn monitor() -> FaultMonitor {
        FaultMonitor {
            max_tilt: 0.9,
            joint_limit_margin: 0.15,
        }
    }

    fn legs() -> LegControl {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robot/quadruped.toml");
        let model =
            RobotModel::from_config_file(&path).expect("the repository's robot config loads");
        let config = ControllerConfig::default();
        LegControl::new(&model, &config, [0.0; NUM_JOINTS], Vector3::zeros())
    }

    /// `estimate` with every joint in the middle of its range (no joint-limit fault).
    fn within_limits(mut estimate: Estimate, legs: &LegControl) -> Estimate {
        let (lower, upper) = legs.joint_limits();
        for (l, q) in estimate.q.iter_mut().enumerate() {
            for (j, angle) in q.iter_mut().enumerate() {
                *angle = 0.5 * (lower[3 * l + j] + upper[3 * l + j]);
            }
        }
        estimate
    }

    #[test]
    fn the_tilt_is_measured_from_the_terrain_planes_normal() {
        let slope = 30f64.to_radians();
        // The plane rises along +x; a body parallel to it is pitched nose up (negative pitch).
        let normal = Vector3::new(-slope.tan(), 0.0, 1.0).normalize();
        let parallel = estimate_with(Rotation3::from_euler_angles(0.0, -slope, 0.0));
        assert!(tilt_from(&parallel, &normal) < 1e-12);
        let level = estimate_with(Rotation3::identity());
        assert!((tilt_from(&level, &normal) - slope).abs() < 1e-12);
    }

    #[test]
    fn on_a_30_degree_plane_the_tilt_check_allows_the_full_margin_from_the_plane() {
        let slope = 30f64.to_radians();
        let normal = Vector3::new(-slope.tan(), 0.0, 1.0).normalize();
        let (monitor, legs) = (monitor(), legs());
        // Rolled 0.6 rad on the plane: 0.6 rad from its normal, 0.86 rad from world vertical
        // (beyond the 0.9 − 0.52 rad a check from vertical alone would leave).
        let rolled = within_limits(
            estimate_with(Rotation3::from_euler_angles(0.6, -slope, 0.0)),
            &legs,
        );
        assert!(monitor.check(&rolled, &legs, &normal).is_none());
        // Rolled 1.0 rad on the plane: a fault.
        let over = within_limits(
            estimate_with(Rotation3::from_euler_angles(1.0, -slope, 0.0)),
            &legs,
        );
        let fault = monitor.check(&over, &legs, &normal);
        assert!(fault.is_some_and(|reason| reason.contains("tilt check")));
    }

    #[test]
    fn a_trunk_upright_over_a_tilted_ground_plane_has_not_tilted_over() {
        // Pushed towards a flank: the plane under the feet leans 30° one way, the trunk rolls
        // 0.45 rad the other. 0.97 rad from the plane's normal, within max.tilt of vertical.
        let slope = 30f64.to_radians();
        let normal = Vector3::new(0.0, slope.tan(), 1.0).normalize();
        let (monitor, legs) = (monitor(), legs());
        let rolled = within_limits(
            estimate_with(Rotation3::from_euler_angles(0.45, 0.0, 0.0)),
            &legs,
        );
        assert!(tilt_from(&rolled, &normal) > monitor.max_tilt);
        assert!(monitor.check(&rolled, &legs, &normal).is_none());
        // Rolled on over 0.9 rad from vertical too: a fault.
        let over = within_limits(
            estimate_with(Rotation3::from_euler_angles(0.95, 0.0, 0.0)),
            &legs,
        );
        let fault = monitor.check(&over, &legs, &normal);
        assert!(fault.is_some_and(|reason| reason.contains("tilt check")));
    }

    #[test]
    fn on_flat_ground_the_tilt_check_is_the_tilt_from_vertical() {
        let (monitor, legs) = (monitor(), legs());
        let vertical = Vector3::z();
        let rolled = within_limits(
            estimate_with(Rotation3::from_euler_angles(0.85, 0.0, 0.0)),
            &legs,
        );
        assert!(monitor.check(&rolled, &legs, &vertical).is_none());
        let fallen = within_limits(
            estimate_with(Rotation3::from_euler_angles(0.0, -0.95, 0.0)),
            &legs,
        );
        assert!(monitor.check(&fallen, &legs, &vertical).is_some());
    }
}
