//! Moving values between FMI calls and the controller's structs. Each [`Binding`] is resolved
//! here and only here, and every value is checked against its row before it is stored, so a
//! bad `fmi2Set*` can never reach the controller.

use quad_controller::config::{FieldKind, FieldValue};
use quad_controller::{
    Command, ContactReading, ControllerConfig, EstimatorKind, GaitKind, HeightMap, ModeRequest,
    Reference, RobotState, SensorReadings,
};
use serde::{Deserialize, Serialize};

use super::{Binding, Value, Variable, VariableTable};
use crate::FmuError;

/// Reads element `element` of the config field `field` (index into
/// [`ControllerConfig::FIELDS`]) as an FMI value.
pub fn read_parameter(field: usize, element: usize, config: &ControllerConfig) -> Value {
    let f = &ControllerConfig::FIELDS[field];
    match f.get(config, element) {
        FieldValue::Real(v) => Value::Real(v),
        FieldValue::Count(n) => Value::Integer(i32::try_from(n).unwrap_or(i32::MAX)),
        FieldValue::Gait(g) => Value::Integer(g.as_code()),
        FieldValue::Estimator(e) => Value::Integer(e.as_code()),
    }
}

/// Writes `value` (already type- and range-checked against the table) into element `element` of
/// the config field `field`.
pub fn write_parameter(field: usize, element: usize, config: &mut ControllerConfig, value: Value) {
    let f = &ControllerConfig::FIELDS[field];
    let converted = match (f.kind, value) {
        (FieldKind::Real, Value::Real(v)) => FieldValue::Real(v),
        (FieldKind::Count, Value::Integer(v)) => match usize::try_from(v) {
            Ok(n) => FieldValue::Count(n),
            Err(_) => return,
        },
        (FieldKind::Gait, Value::Integer(v)) => match GaitKind::from_code(v) {
            Some(g) => FieldValue::Gait(g),
            None => return,
        },
        (FieldKind::Estimator, Value::Integer(v)) => match EstimatorKind::from_code(v) {
            Some(e) => FieldValue::Estimator(e),
            None => return,
        },
        // The table gives every parameter exactly one type; other pairs cannot be requested.
        _ => return,
    };
    f.set(config, element, converted);
}

/// Checks that `value` may be stored in `variable` (type, finiteness, range).
pub fn check_value(variable: &Variable, value: Value) -> Result<(), FmuError> {
    let invalid = |reason: String| FmuError::InvalidValue {
        name: variable.name.clone(),
        reason,
    };
    let number = match value {
        Value::Real(v) if !v.is_finite() && variable.accepts_non_finite() => return Ok(()),
        Value::Real(v) if !v.is_finite() => {
            return Err(invalid(format!("{v} is not a finite number")));
        }
        Value::Real(v) => v,
        Value::Integer(v) => f64::from(v),
        Value::Boolean(_) => return Ok(()),
    };
    if !variable.range_is_enforced() {
        return Ok(());
    }
    if let Some(min) = variable.min.filter(|&min| number < min) {
        return Err(invalid(format!("{number} is below the minimum {min}")));
    }
    if let Some(max) = variable.max.filter(|&max| number > max) {
        return Err(invalid(format!("{number} is above the maximum {max}")));
    }
    Ok(())
}

/// Checks every parameter of `config` against its range: the `controller.json` shipped in the
/// resources must lie in the same envelope as values set through `fmi2Set*`.
pub fn check_parameters(table: &VariableTable, config: &ControllerConfig) -> Result<(), FmuError> {
    for v in table.rows() {
        if let Binding::Parameter { field, element } = v.binding {
            check_value(v, read_parameter(field, element, config))?;
        }
    }
    Ok(())
}

/// The inputs of an instance, as the controller takes them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Inputs {
    /// Measured state (ground-truth base pose and twist, joint encoders).
    pub state: RobotState,
    /// Reference from the planner.
    pub reference: Reference,
    /// Local terrain height map.
    pub height_map: HeightMap,
    /// IMU, contact sensors, position fix.
    pub sensors: SensorReadings,
}

/// Reads an input variable from the stored inputs.
pub fn read_input(binding: Binding, inputs: &Inputs) -> Option<Value> {
    let Inputs {
        state,
        reference,
        height_map: map,
        sensors,
    } = inputs;
    let real = match binding {
        Binding::BasePosition(i) => state.base_position[i],
        Binding::BaseOrientation(i) => state.base_orientation[i],
        Binding::BaseLinearVelocity(i) => state.base_linear_velocity[i],
        Binding::BaseAngularVelocity(i) => state.base_angular_velocity[i],
        Binding::JointPosition(i) => state.joint_positions[i],
        Binding::JointVelocity(i) => state.joint_velocities[i],
        Binding::RefX => reference.x,
        Binding::RefY => reference.y,
        Binding::RefZ => reference.terrain.height,
        Binding::RefYaw => reference.yaw,
        Binding::RefVx => reference.vx,
        Binding::RefVy => reference.vy,
        Binding::RefYawRate => reference.yaw_rate,
        Binding::RefBodyHeight => reference.body_height,
        Binding::TerrainSlopeX => reference.terrain.slope_x,
        Binding::TerrainSlopeY => reference.terrain.slope_y,
        Binding::HeightMapOrigin(i) => map.origin[i],
        Binding::HeightMapSpacing => map.spacing,
        Binding::HeightMapHeight(i) => map.heights[i],
        Binding::ImuGyro(i) => sensors.imu.gyro[i],
        Binding::ImuAcc(i) => sensors.imu.acc[i],
        Binding::FixPosition(i) => sensors.fix.position[i],
        Binding::ModeRequest => return Some(Value::Integer(reference.mode.as_code())),
        Binding::ContactSensor(leg) => {
            return Some(Value::Integer(sensors.contacts[leg].as_code()));
        }
        Binding::FixValid => return Some(Value::Boolean(sensors.fix.valid)),
        _ => return None,
    };
    Some(Value::Real(real))
}

/// Writes an input variable (value already checked with [`check_value`]).
pub fn write_input(binding: Binding, value: Value, inputs: &mut Inputs) {
    let Inputs {
        state,
        reference,
        height_map: map,
        sensors,
    } = inputs;
    match (binding, value) {
        (Binding::ModeRequest, Value::Integer(code)) => {
            if let Some(mode) = ModeRequest::from_code(code) {
                reference.mode = mode;
            }
            return;
        }
        (Binding::ContactSensor(leg), Value::Integer(code)) => {
            if let Some(reading) = ContactReading::from_code(code) {
                sensors.contacts[leg] = reading;
            }
            return;
        }
        (Binding::FixValid, Value::Boolean(valid)) => {
            sensors.fix.valid = valid;
            return;
        }
        _ => {}
    }
    let Value::Real(v) = value else { return };
    let field = match binding {
        Binding::BasePosition(i) => &mut state.base_position[i],
        Binding::BaseOrientation(i) => &mut state.base_orientation[i],
        Binding::BaseLinearVelocity(i) => &mut state.base_linear_velocity[i],
        Binding::BaseAngularVelocity(i) => &mut state.base_angular_velocity[i],
        Binding::JointPosition(i) => &mut state.joint_positions[i],
        Binding::JointVelocity(i) => &mut state.joint_velocities[i],
        Binding::RefX => &mut reference.x,
        Binding::RefY => &mut reference.y,
        Binding::RefZ => &mut reference.terrain.height,
        Binding::RefYaw => &mut reference.yaw,
        Binding::RefVx => &mut reference.vx,
        Binding::RefVy => &mut reference.vy,
        Binding::RefYawRate => &mut reference.yaw_rate,
        Binding::RefBodyHeight => &mut reference.body_height,
        Binding::TerrainSlopeX => &mut reference.terrain.slope_x,
        Binding::TerrainSlopeY => &mut reference.terrain.slope_y,
        Binding::HeightMapOrigin(i) => &mut map.origin[i],
        Binding::HeightMapSpacing => &mut map.spacing,
        Binding::HeightMapHeight(i) => &mut map.heights[i],
        Binding::ImuGyro(i) => &mut sensors.imu.gyro[i],
        Binding::ImuAcc(i) => &mut sensors.imu.acc[i],
        Binding::FixPosition(i) => &mut sensors.fix.position[i],
        _ => return,
    };
    *field = v;
}

/// Reads an output variable from the last command.
pub fn read_output(binding: Binding, command: &Command) -> Option<Value> {
    Some(match binding {
        Binding::JointTorque(i) => Value::Real(command.joint_torques[i]),
        Binding::ScheduledStance(leg) => Value::Boolean(command.contacts[leg]),
        Binding::FsmState => Value::Integer(command.fsm_state.as_code()),
        Binding::DesiredForce(leg, axis) => Value::Real(command.desired_forces[leg][axis]),
        Binding::MpcSolveTime => Value::Real(command.mpc_solve_time_s),
        Binding::MpcSolved => Value::Boolean(command.mpc_solved),
        Binding::EstimatedPosition(i) => Value::Real(command.estimate.position[i]),
        Binding::EstimatedVelocity(i) => Value::Real(command.estimate.velocity[i]),
        Binding::EstimatedRpy(i) => Value::Real(command.estimate.rpy[i]),
        Binding::EstimatedPositionVariance(i) => Value::Real(command.estimate.position_variance[i]),
        Binding::EstimatedAttitudeVariance(i) => Value::Real(command.estimate.attitude_variance[i]),
        // The status word has 7 bits: it always fits.
        Binding::EstimatorStatus => {
            Value::Integer(i32::try_from(command.estimate.status).unwrap_or(i32::MAX))
        }
        _ => return None,
    })
}
