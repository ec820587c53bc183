//! The controller: one tick of [`Controller::step`] is the pipeline
//! estimate → gait state machine → footholds → MPC scheduling → leg control laws → torques,
//! each stage its own module with its own state:
//!
//! - `estimator` + `estimate`: the state the stages use (rotation, feet, gravity), from the
//!   measured base state (ground truth) or from the IMU/leg-kinematics filters.
//! - `fsm`: passive / stand-up / stand / locomotion / damping, one state per file;
//!   the locomotion state runs the gait schedule and drives the next three stages.
//! - `footholds`: Raibert footholds at the terrain height (height map or plane),
//!   swing apex, the ground under the stance and the friction normal.
//! - `mpc_schedule`: when to re-solve the convex MPC and with which reference, feet and
//!   contact schedule; the forces held in between.
//! - `leg_control`: stance `τ = Jᵀ Rᵀ(−f) + h`, swing inverse dynamics + PD, stand-up
//!   and damping laws, the effort clamp.
//!
//! Frames: `R` rotates base-frame vectors into the world frame (the state's quaternion); MPC
//! forces `f` are ground reaction forces acting ON the robot at the foot, world frame.
//!
//! Terrain awareness (the paper's "particle → rigid body" step): the reference carries a local
//! terrain plane. The base height reference is `body_height` above that plane at the predicted
//! base position, the pitch reference follows the plane's slope along the heading (clamped to
//! `max_terrain_pitch`), footholds are placed at the plane's height (plus the foot radius), and
//! the MPC's friction pyramid is built about the plane's normal. A local [`HeightMap`]
//! (`Controller::set_height_map`) refines all of these (see `footholds`).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::api::{
    Command, ControllerError, FsmState, HeightMap, Leg, Reference, RobotState, SensorReadings,
    NUM_JOINTS, NUM_LEGS,
};
use crate::config::{ControllerConfig, RobotScale};
use crate::estimator::StateEstimator;
use crate::footholds::FootholdPlanner;
pub use crate::footholds::FOOTHOLD_SEARCH_RADIUS;
use crate::fsm::{Fsm, FsmTransition, Stages};
use crate::leg_control::LegControl;
use crate::model::RobotModel;
use crate::mpc_schedule::{MpcMemory, MpcScheduler};
pub use crate::validation::validate_config;
use crate::validation::{validate_reference, validate_state};

/// Everything a controller carries from one tick to the next. Restored into a controller built
/// from the same model and configuration, the controller continues bit for bit as the one it
/// was taken from (an FMU state is this plus the FMU's own variables).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ControllerState {
    estimator: StateEstimator,
    fsm: Fsm,
    footholds: FootholdPlanner,
    mpc: MpcMemory,
    legs: LegControl,
    last_transition: Option<FsmTransition>,
}

/// The quadruped controller (see the crate docs for the API contract).
pub struct Controller {
    model: RobotModel,
    config: ControllerConfig,
    com_offset_body: Vector3<f64>,
    estimator: StateEstimator,
    fsm: Fsm,
    stages: Stages,
    last_transition: Option<FsmTransition>,
}

impl Controller {
    /// Build a controller; fails on an invalid config or when the standing pose is unreachable.
    pub fn new(model: RobotModel, config: ControllerConfig) -> Result<Self, ControllerError> {
        validate_config(&config, RobotScale::of(&model))?;
        let stand_joint_positions = model.stand_joint_positions(config.body_height)?;
        let nominal_feet_body =
            Leg::ALL.map(|leg| Vector3::from(model.nominal_foot_position(leg, config.body_height)));
        let (inertia, com) = model.composite_inertia(&stand_joint_positions);
        let com_offset_body = Vector3::from(com);
        let stages = Stages {
            footholds: FootholdPlanner::new(&config, nominal_feet_body, model.foot_radius()),
            mpc: MpcScheduler::new(&config, model.total_mass(), inertia, com_offset_body)?,
            legs: LegControl::new(&model, &config, stand_joint_positions, com_offset_body),
        };
        Ok(Controller {
            estimator: StateEstimator::new(&model, &config),
            fsm: Fsm::new(&config),
            last_transition: None,
            stages,
            com_offset_body,
            model,
            config,
        })
    }

    /// A copy of the controller's state between ticks.
    pub fn save_state(&self) -> ControllerState {
        ControllerState {
            estimator: self.estimator.clone(),
            fsm: self.fsm.clone(),
            footholds: self.stages.footholds.clone(),
            mpc: self.stages.mpc.memory(),
            legs: self.stages.legs.clone(),
            last_transition: self.last_transition.clone(),
        }
    }

    /// Continues from `state`, saved by a controller of the same model and configuration. A
    /// state that does not fit (another MPC horizon, a non-finite height map) is refused and
    /// changes nothing.
    pub fn restore_state(&mut self, state: ControllerState) -> Result<(), ControllerError> {
        let ControllerState {
            estimator,
            fsm,
            footholds,
            mpc,
            legs,
            last_transition,
        } = state;
        footholds
            .height_map()
            .validate()
            .map_err(ControllerError::InvalidState)?;
        self.stages
            .mpc
            .restore(mpc)
            .map_err(ControllerError::InvalidState)?;
        self.estimator = estimator;
        self.fsm = fsm;
        self.stages.footholds = footholds;
        self.stages.legs = legs;
        self.last_transition = last_transition;
        Ok(())
    }

    /// Sets the local terrain height map used from the next `step` on (a map with spacing ≤ 0
    /// clears it: the terrain plane of the reference is used alone). On an invalid map the
    /// previous one is kept and an error returned.
    pub fn set_height_map(&mut self, map: &HeightMap) -> Result<(), ControllerError> {
        map.validate().map_err(ControllerError::InvalidReference)?;
        self.stages.footholds.set_height_map(map);
        Ok(())
    }

    /// The height map in use.
    pub fn height_map(&self) -> &HeightMap {
        self.stages.footholds.height_map()
    }

    /// Current FSM state.
    pub fn fsm_state(&self) -> FsmState {
        self.fsm.state()
    }

    /// The last state change (made by the latest `step` when its `from` is not the state before
    /// that step), with the reason when a fault caused it.
    pub fn last_transition(&self) -> Option<&FsmTransition> {
        self.last_transition.as_ref()
    }

    /// Declares that each state given to [`Controller::step`] stays in force for `seconds` (a
    /// co-simulation master that exchanges data every `seconds` while the controller ticks
    /// faster; 0, the default, means a fresh state every tick). Joint PD gains are then capped at
    /// `k_d ≤ 1.0·M_ii/T` and `k_p ≤ 0.25·M_ii/T²` (M_ii the joint's inertia in its leg), which a
    /// held feedback needs to stay stable; at T = 1 ms no default gain reaches its cap.
    pub fn set_input_period(&mut self, seconds: f64) -> Result<(), ControllerError> {
        if !(seconds.is_finite() && seconds >= 0.0) {
            return Err(ControllerError::Config(format!(
                "input period {seconds} s must be finite and >= 0"
            )));
        }
        self.stages.legs.set_input_period(seconds);
        Ok(())
    }

    /// The robot model.
    pub fn model(&self) -> &RobotModel {
        &self.model
    }

    /// The configuration.
    pub fn config(&self) -> &ControllerConfig {
        &self.config
    }

    /// Joint angles of the standing pose, index 3·leg + j.
    pub fn stand_joint_positions(&self) -> [f64; NUM_JOINTS] {
        self.stages.legs.stand_joint_positions()
    }

    /// CoM offset from the base origin in the base frame at the standing pose, m.
    pub fn com_offset_body(&self) -> [f64; 3] {
        [
            self.com_offset_body.x,
            self.com_offset_body.y,
            self.com_offset_body.z,
        ]
    }

    /// Damping torques `−k_d q̇` (clamped; zero for non-finite velocities). Safe to apply while
    /// `step` reports an error.
    pub fn safe_command(&self, state: &RobotState) -> Command {
        Command {
            joint_torques: self.stages.legs.safe_damping_torques(&self.model, state),
            contacts: [false; NUM_LEGS],
            fsm_state: FsmState::Damping,
            desired_forces: [[0.0; 3]; NUM_LEGS],
            desired_foot_positions: [[0.0; 3]; NUM_LEGS],
            mpc_solve_time_s: 0.0,
            mpc_solved: false,
            estimate: self.estimator.report(),
        }
    }

    /// One control tick with the default sensor readings ([`SensorReadings::default`]: a level
    /// IMU at rest, contacts from the schedule, no fix). Meant for the ground-truth estimator;
    /// with the Kalman estimator use [`Controller::step_with_sensors`].
    pub fn step(
        &mut self,
        state: &RobotState,
        reference: &Reference,
        dt: f64,
    ) -> Result<Command, ControllerError> {
        self.step_with_sensors(state, &SensorReadings::default(), reference, dt)
    }

    /// One control tick. Deterministic: the same sequence of inputs gives bit-identical outputs.
    /// On invalid input (non-finite joints, or a bad base state when it is read: always in
    /// ground-truth mode, at the first tick in Kalman mode) the controller's internal state is
    /// left untouched and an error returned. Bad `sensors` are not an error: the estimator holds
    /// or skips them and reports it in [`Command::estimate`]'s status.
    pub fn step_with_sensors(
        &mut self,
        state: &RobotState,
        sensors: &SensorReadings,
        reference: &Reference,
        dt: f64,
    ) -> Result<Command, ControllerError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(ControllerError::InvalidDt(dt));
        }
        validate_state(state, self.estimator.reads_base_state())?;
        validate_reference(reference, self.config.mpc_dt)?;

        let plan = self.fsm.stance_plan();
        let estimate = self
            .estimator
            .update(&self.model, state, sensors, &plan, dt);
        if let Some(transition) = self
            .fsm
            .check_transition(&self.stages, &estimate, reference)
        {
            self.fsm.enter(
                transition.to,
                &self.model,
                &mut self.stages,
                &estimate,
                reference,
            );
            self.last_transition = Some(transition);
        }
        // The state runs the gait, footholds, MPC scheduling and leg laws it needs.
        let actuation = self
            .fsm
            .run(&self.model, &mut self.stages, &estimate, reference, dt);
        let joint_torques = self.stages.legs.clamp_to_effort_limits(actuation.torques);
        self.estimator.record_applied_torques(&joint_torques);

        Ok(Command {
            joint_torques,
            contacts: actuation.contacts,
            fsm_state: self.fsm.state(),
            desired_forces: actuation.forces,
            desired_foot_positions: actuation.feet,
            mpc_solve_time_s: self.stages.mpc.solve_time_s(),
            mpc_solved: self.stages.mpc.solved(),
            estimate: self.estimator.report(),
        })
    }
}
