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

use quad_controller::{Command, FsmState, Reference, RobotState, NUM_JOINTS, NUM_LEGS};

#[cfg(doc)]
use quad_controller::ControllerConfig;

mod enums;
mod exchange;
mod table;
mod types;

pub use enums::{
    enum_type, enum_types, EnumItem, EnumType, FSM_STATE_TYPE, GAIT_KIND_TYPE, MODE_REQUEST_TYPE,
};
pub use exchange::{
    check_parameters, check_value, read_input, read_output, read_parameter, write_input,
    write_parameter,
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
    /// `Command::joint_torques[i]`.
    JointTorque(usize),
    /// `Command::contacts[leg]`.
    Contact(usize),
    /// `Command::fsm_state`.
    FsmState,
    /// `Command::desired_forces[leg][axis]`.
    DesiredForce(usize, usize),
    /// `Command::mpc_solve_time_s`.
    MpcSolveTime,
    /// `Command::mpc_solved`.
    MpcSolved,
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
    /// Inclusive lower bound checked by `fmi2Set*`.
    pub min: Option<f64>,
    /// Inclusive upper bound checked by `fmi2Set*`.
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
    }
}

/// The inputs of a fresh instance (also the XML `start` values): the controller crate's defaults.
pub fn initial_inputs() -> (RobotState, Reference) {
    (RobotState::default(), Reference::default())
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
