//! The one table of FMU variables. `modelDescription.xml`, the HTML documentation and every
//! `fmi2Get*`/`fmi2Set*` call are driven by it; there is no second list to keep in sync. It is
//! declared once (`table.rs`) and built for the robot an FMU carries ([`VariableTable`]).
//!
//! Value references are the table index (unique across types), so the `index` attribute used in
//! `<ModelStructure>` is always `value_reference + 1`.
//!
//! This module holds what a row is ([`Variable`], [`Binding`]) and how to look rows up; the
//! submodules hold the FMI types, the enumerations, the table's declarations and the value
//! exchange with the controller, all re-exported here so callers see one `variables` path.

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

use crate::FmuError;

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
    /// `Command::estimate.position_variance[i]`.
    EstimatedPositionVariance(usize),
    /// `Command::estimate.attitude_variance[i]`.
    EstimatedAttitudeVariance(usize),
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

/// The variable table of one robot: the rows (names, value references and types are the same for
/// every robot; joint ranges, effort limits and start values are the robot's) and the inputs of a
/// fresh instance. `modelDescription.xml` is written from it by `bundle-fmu`, and an instance
/// rebuilds it at `fmi2Instantiate` from the robot and `controller.json` in its resources, so
/// the two cannot disagree.
#[derive(Clone, Debug)]
pub struct VariableTable {
    robot_name: String,
    rows: Vec<Variable>,
    initial_state: RobotState,
}

impl VariableTable {
    /// The table of `model` with `config` as the parameters' start values. The start inputs are
    /// the robot standing still on flat ground at z = 0 in its nominal stance, so that a run with
    /// no inputs set stands up and holds the stand: joint angles are the controller's standing
    /// pose at `config.body_height`, the base is at that height with identity orientation,
    /// every velocity is zero; the reference is the controller's default (mode Stand, flat
    /// terrain at z = 0, default body height). Fails when `config` cannot stand the robot.
    pub fn new(model: &RobotModel, config: &ControllerConfig) -> Result<VariableTable, FmuError> {
        let mut table = VariableTable {
            robot_name: model.name().to_owned(),
            rows: Vec::new(),
            initial_state: RobotState::default(),
        };
        // The parameters' ranges do not depend on the start pose: check them first, so that a
        // bad value is named by its FMI variable rather than by the controller's refusal.
        table.rows = table::build_table(model, config, &table);
        check_parameters(&table, config)?;
        let controller = Controller::new(model.clone(), config.clone()).map_err(|e| {
            FmuError::Resources(format!("the configuration cannot stand the robot: {e}"))
        })?;
        table.initial_state = RobotState {
            base_position: [0.0, 0.0, config.body_height],
            joint_positions: controller.stand_joint_positions(),
            ..RobotState::default()
        };
        table.rows = table::build_table(model, config, &table);
        Ok(table)
    }

    /// The table of the robot described by the robot config at `path` (its URDF resolved as
    /// [`RobotModel::from_config_file`] does), with [`ControllerConfig::for_robot`] as the
    /// parameters' start values: what `bundle-fmu --robot` puts into an FMU.
    pub fn for_robot_config(path: &std::path::Path) -> Result<VariableTable, FmuError> {
        let model =
            RobotModel::from_config_file(path).map_err(|e| FmuError::Resources(e.to_string()))?;
        VariableTable::new(&model, &ControllerConfig::for_robot(&model))
    }

    /// The FMU's GUID (`modelDescription.xml`, checked by `fmi2Instantiate`, carried by saved
    /// states): a name-based UUID (RFC 9562 version 5) of the interface this table describes, i.e.
    /// the model identifier, every variable's name, value reference, type, causality, variability,
    /// declared type and unit, and every enumeration's items and codes. Any change an importer
    /// would notice changes it; the robot's numbers (start values, ranges) do not.
    pub fn guid(&self) -> String {
        use std::fmt::Write as _;
        let mut interface = format!("{}\n", crate::MODEL_IDENTIFIER);
        for v in &self.rows {
            // Writing to a String cannot fail.
            let _ = writeln!(
                interface,
                "{}|{}|{}|{}|{}|{}|{}",
                v.name,
                v.value_reference,
                v.scalar_type().xml_name(),
                v.causality.xml_name(),
                v.variability.xml_name(),
                v.declared_type.unwrap_or(""),
                v.unit.map_or("", Unit::name),
            );
        }
        for t in enum_types() {
            let _ = write!(interface, "{}:", t.name);
            for item in &t.items {
                let _ = write!(interface, " {}={}", item.name, item.value);
            }
            interface.push('\n');
        }
        let id = uuid::Uuid::new_v5(&uuid::Uuid::NAMESPACE_OID, interface.as_bytes());
        format!("{{{id}}}")
    }

    /// The robot's name (the URDF's `<robot name>`).
    pub fn robot_name(&self) -> &str {
        &self.robot_name
    }

    /// All rows, in value-reference order.
    pub fn rows(&self) -> &[Variable] {
        &self.rows
    }

    /// The row of value reference `vr`.
    pub fn get(&self, vr: u32) -> Option<&Variable> {
        self.rows.get(usize::try_from(vr).ok()?)
    }

    /// Finds a variable by name (linear; meant for tests and tools, not the hot path).
    pub fn by_name(&self, name: &str) -> Option<&Variable> {
        self.rows.iter().find(|v| v.name == name)
    }

    /// The inputs of a fresh instance (also the XML `start` values).
    pub fn initial_inputs(&self) -> (RobotState, Reference) {
        (self.initial_state, Reference::default())
    }

    /// The outputs before the first doStep: no torque, no contact scheduled, FSM passive, the
    /// estimate at the start pose at rest.
    pub fn initial_command(&self) -> Command {
        Command {
            joint_torques: [0.0; NUM_JOINTS],
            contacts: [false; NUM_LEGS],
            fsm_state: FsmState::Passive,
            desired_forces: [[0.0; 3]; NUM_LEGS],
            desired_foot_positions: [[0.0; 3]; NUM_LEGS],
            mpc_solve_time_s: 0.0,
            mpc_solved: false,
            estimate: EstimateReport {
                position: self.initial_state.base_position,
                ..EstimateReport::default()
            },
        }
    }
}

/// The table of the repository's own robot (`robot/quadruped.toml`), for unit tests.
#[cfg(test)]
mod our_robot {
    use std::sync::OnceLock;

    use quad_controller::{Command, Reference, RobotModel, RobotState};

    use super::{Variable, VariableTable};

    pub fn robot_model() -> &'static RobotModel {
        static MODEL: OnceLock<RobotModel> = OnceLock::new();
        MODEL.get_or_init(|| {
            RobotModel::from_config_file(
                &crate::bundle::repo_root()
                    .join("robot")
                    .join("quadruped.toml"),
            )
            .expect("robot/quadruped.toml loads")
        })
    }

    pub fn our_table() -> &'static VariableTable {
        static TABLE: OnceLock<VariableTable> = OnceLock::new();
        TABLE.get_or_init(|| {
            let model = robot_model();
            VariableTable::new(model, &quad_controller::ControllerConfig::for_robot(model))
                .expect("the default tuning stands our robot")
        })
    }

    pub fn table() -> &'static [Variable] {
        our_table().rows()
    }

    pub fn by_name(name: &str) -> Option<&'static Variable> {
        our_table().by_name(name)
    }

    pub fn initial_inputs() -> (RobotState, Reference) {
        our_table().initial_inputs()
    }

    pub fn initial_command() -> Command {
        our_table().initial_command()
    }
}
#[cfg(test)]
pub(crate) use our_robot::{
    by_name, initial_command, initial_inputs, our_table, robot_model, table,
};

#[cfg(test)]
mod tests;
