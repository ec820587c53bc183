//! The one table of FMU variables. `modelDescription.xml`, the HTML documentation and every
//! `fmi2Get*`/`fmi2Set*` call are driven by it; there is no second list to keep in sync.
//!
//! Value references are the table index (unique across types), so the `index` attribute used in
//! `<ModelStructure>` is always `value_reference + 1`.
//!
//! This module holds what a row is ([`Variable`], [`Binding`]) and how to look rows up; the
//! submodules hold the FMI types, the enumerations, the table's declarations and the value
//! exchange with the controller, all re-exported here so callers see one `variables` path.

use std::sync::OnceLock;

use quad_controller::{
    Command, Controller, ControllerConfig, EstimateReport, FsmState, Reference, RobotModel,
    RobotState, NUM_JOINTS, NUM_LEGS,
};

mod enums;
mod exchange;
mod table;
mod types;

pub use enums::{
    enum_type, enum_types, EnumItem, EnumType, ESTIMATOR_KIND_TYPE, FSM_STATE_TYPE, GAIT_KIND_TYPE,
    MODE_REQUEST_TYPE,
};
pub use exchange::{
    check_parameters, check_value, read_input, read_output, read_parameter, write_input,
    write_parameter, Inputs,
};
pub use types::{Causality, ScalarType, Unit, Value, Variability};

/// What a variable is connected to inside the FMU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Binding {
    /// `RobotState::base_position[i]`.
    BasePosition(usize),
    /// `RobotState::base_orientation[i]` (w, x, y, z).
    BaseOrientation(usize),
    /// `RobotState::base_linear_velocity[i]`.
    BaseLinearVelocity(usize),
    /// `RobotState::base_angular_velocity[i]`.
    BaseAngularVelocity(usize),
    /// `RobotState::joint_positions[i]`.
    JointPosition(usize),
    /// `RobotState::joint_velocities[i]`.
    JointVelocity(usize),
    /// `Reference::x`.
    RefX,
    /// `Reference::y`.
    RefY,
    /// `Reference::terrain.height` (the reference sample's z).
    RefZ,
    /// `Reference::yaw`.
    RefYaw,
    /// `Reference::vx`.
    RefVx,
    /// `Reference::vy`.
    RefVy,
    /// `Reference::yaw_rate`.
    RefYawRate,
    /// `Reference::body_height`.
    RefBodyHeight,
    /// `Reference::terrain.slope_x`.
    TerrainSlopeX,
    /// `Reference::terrain.slope_y`.
    TerrainSlopeY,
    /// `HeightMap::origin[i]`.
    HeightMapOrigin(usize),
    /// `HeightMap::spacing`.
    HeightMapSpacing,
    /// `HeightMap::heights[i]`.
    HeightMapHeight(usize),
    /// `Reference::mode`.
    ModeRequest,
    /// `SensorReadings::imu.gyro[i]`.
    ImuGyro(usize),
    /// `SensorReadings::imu.acc[i]`.
    ImuAcc(usize),
    /// `SensorReadings::contacts[leg]` (its integer code).
    ContactSensor(usize),
    /// `SensorReadings::fix.position[i]`.
    FixPosition(usize),
    /// `SensorReadings::fix.valid`.
    FixValid,
    /// `Command::joint_torques[i]`.
    JointTorque(usize),
    /// `Command::contacts[leg]` (the scheduled stance).
    ScheduledStance(usize),
    /// `Command::fsm_state`.
    FsmState,
    /// `Command::desired_forces[leg][axis]`.
    DesiredForce(usize, usize),
    /// `Command::mpc_solve_time_s`.
    MpcSolveTime,
    /// `Command::mpc_solved`.
    MpcSolved,
    /// `Command::estimate.position[i]`.
    EstimatedPosition(usize),
    /// `Command::estimate.velocity[i]`.
    EstimatedVelocity(usize),
    /// `Command::estimate.rpy[i]`.
    EstimatedRpy(usize),
    /// `Command::estimate.status`.
    EstimatorStatus,
    /// Element `element` of the field `field` (index into [`ControllerConfig::FIELDS`]).
    Parameter {
        /// Index into [`ControllerConfig::FIELDS`].
        field: usize,
        /// Element of an array field (0 for scalars).
        element: usize,
    },
}

/// One row of the table.
#[derive(Clone, Debug)]
pub struct Variable {
    /// Structured FMI name, e.g. `joint.q[1]`.
    pub name: String,
    /// Value reference (= position in the table).
    pub value_reference: u32,
    /// Causality.
    pub causality: Causality,
    /// Variability.
    pub variability: Variability,
    /// Start value; its variant gives the variable's type.
    pub start: Value,
    /// Human description.
    pub description: String,
    /// Unit, if dimensional.
    pub unit: Option<Unit>,
    /// Enumeration type (an [`EnumType`] name) of an Integer variable, if it has one.
    pub declared_type: Option<&'static str>,
    /// Inclusive lower bound (`min` in the XML), checked by `fmi2Set*` unless
    /// [`Variable::range_is_enforced`] says it only documents the operating region.
    pub min: Option<f64>,
    /// Inclusive upper bound (`max` in the XML), checked like `min`.
    pub max: Option<f64>,
    /// Where the value lives.
    pub binding: Binding,
}

impl Variable {
    /// The variable's FMI type.
    pub fn scalar_type(&self) -> ScalarType {
        self.start.scalar_type()
    }

    /// The 1-based `index` used in `<ModelStructure>`.
    pub fn index(&self) -> usize {
        self.value_reference as usize + 1
    }

    /// Whether `fmi2Set*` refuses values outside `min`/`max`. Measured joint positions and
    /// velocities are not refused: their range is the URDF's (the region the controller is
    /// designed for), but a real or simulated robot can leave it, and the controller's own fault
    /// checks must see that (they drop to damping and log the joint and value).
    pub fn range_is_enforced(&self) -> bool {
        !matches!(
            self.binding,
            Binding::JointPosition(_) | Binding::JointVelocity(_)
        )
    }

    /// Whether `fmi2SetReal` accepts NaN/inf. Only the IMU inputs do: a glitching IMU sample is
    /// something the estimator must survive (it holds or skips the sample and reports it in
    /// `est.status`), so the master passes it on instead of being refused.
    pub fn accepts_non_finite(&self) -> bool {
        matches!(self.binding, Binding::ImuGyro(_) | Binding::ImuAcc(_))
    }

    /// Whether `fmi2Set*` may write it while the simulation runs (step complete).
    pub fn settable_while_running(&self) -> bool {
        self.causality == Causality::Input || self.variability == Variability::Tunable
    }
}

/// The outputs before the first doStep: no torque, no contact scheduled, FSM passive.
pub fn initial_command() -> Command {
    Command {
        joint_torques: [0.0; NUM_JOINTS],
        contacts: [false; NUM_LEGS],
        fsm_state: FsmState::Passive,
        desired_forces: [[0.0; 3]; NUM_LEGS],
        desired_foot_positions: [[0.0; 3]; NUM_LEGS],
        mpc_solve_time_s: 0.0,
        mpc_solved: false,
        estimate: initial_estimate(),
    }
}

/// The estimate outputs before the first doStep: the start pose of [`initial_inputs`] at rest.
fn initial_estimate() -> EstimateReport {
    let (state, _) = initial_inputs();
    EstimateReport {
        position: state.base_position,
        ..EstimateReport::default()
    }
}

/// The robot the variable table describes: `robot/quadruped.urdf`, compiled in. The bundle ships
/// the same file as `resources/quadruped.urdf`; the joint ranges and the standing start pose of
/// the table come from it.
pub fn robot_model() -> &'static RobotModel {
    static MODEL: OnceLock<RobotModel> = OnceLock::new();
    MODEL.get_or_init(|| {
        RobotModel::from_urdf_str(ROBOT_URDF)
            .unwrap_or_else(|e| panic!("the compiled-in robot/quadruped.urdf is invalid: {e}"))
    })
}

/// `robot/quadruped.urdf` as compiled into the FMU.
pub const ROBOT_URDF: &str = include_str!("../../../robot/quadruped.urdf");

/// The inputs of a fresh instance (also the XML `start` values): the robot standing still on
/// flat ground at z = 0 in its nominal stance, so that a run with no inputs set stands up and
/// holds the stand. Joint angles are the controller's standing pose (inverse kinematics of the
/// nominal feet at the default `stand.bodyHeight`), the base is at that height with identity
/// orientation, every velocity is zero; the reference is the controller's default (mode Stand,
/// flat terrain at z = 0, default body height).
pub fn initial_inputs() -> (RobotState, Reference) {
    static INPUTS: OnceLock<(RobotState, Reference)> = OnceLock::new();
    *INPUTS.get_or_init(|| {
        let config = ControllerConfig::default();
        let body_height = config.body_height;
        let controller = Controller::new(robot_model().clone(), config).unwrap_or_else(|e| {
            panic!("the default configuration cannot stand the compiled-in robot: {e}")
        });
        let state = RobotState {
            base_position: [0.0, 0.0, body_height],
            joint_positions: controller.stand_joint_positions(),
            ..RobotState::default()
        };
        (state, Reference::default())
    })
}

/// The table, built once.
pub fn table() -> &'static [Variable] {
    static TABLE: OnceLock<Vec<Variable>> = OnceLock::new();
    TABLE.get_or_init(table::build_table)
}

/// Finds a variable by name (linear; meant for tests and tools, not the hot path).
pub fn by_name(name: &str) -> Option<&'static Variable> {
    table().iter().find(|v| v.name == name)
}

#[cfg(test)]
mod tests;
