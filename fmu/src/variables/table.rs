//! How the table is built: the declaration order here *is* the value-reference order, so
//! appending keeps existing references stable while reordering changes the FMU's interface
//! (and needs a new GUID).

use quad_controller::config::{FieldKind, RobotScale};
use quad_controller::{
    ContactReading, ControllerConfig, HeightMap, Leg, SensorReadings, StatusFlag, HEIGHT_MAP_CELLS,
    HEIGHT_MAP_SIZE, NUM_JOINTS,
};

use quad_controller::RobotModel;

use super::{
    enum_type, read_parameter, Binding, Causality, Unit, Value, Variability, Variable,
    VariableTable, ESTIMATOR_KIND_TYPE, FSM_STATE_TYPE, GAIT_KIND_TYPE, MODE_REQUEST_TYPE,
};

struct TableBuilder {
    rows: Vec<Variable>,
}

impl TableBuilder {
    #[allow(clippy::too_many_arguments)]
    fn push(
        &mut self,
        name: String,
        causality: Causality,
        variability: Variability,
        start: Value,
        description: String,
        unit: Option<Unit>,
        range: (Option<f64>, Option<f64>),
        binding: Binding,
    ) {
        let value_reference = u32::try_from(self.rows.len())
            .expect("the variable table has far fewer than 2^32 rows");
        self.rows.push(Variable {
            name,
            value_reference,
            causality,
            variability,
            start,
            description,
            unit,
            declared_type: None,
            min: range.0,
            max: range.1,
            binding,
        });
    }

    /// Gives the row pushed last the range `[min, max]`.
    fn with_range(&mut self, min: f64, max: f64) {
        debug_assert!(min < max, "{min} < {max}");
        if let Some(row) = self.rows.last_mut() {
            row.min = Some(min);
            row.max = Some(max);
        }
    }

    /// Gives the row pushed last the enumeration type `type_name`.
    fn of_type(&mut self, type_name: &'static str) {
        debug_assert!(enum_type(type_name).is_some(), "{type_name}");
        if let Some(row) = self.rows.last_mut() {
            row.declared_type = Some(type_name);
        }
    }

    fn input(
        &mut self,
        name: String,
        start: f64,
        description: String,
        unit: Option<Unit>,
        binding: Binding,
    ) {
        self.push(
            name,
            Causality::Input,
            Variability::Continuous,
            Value::Real(start),
            description,
            unit,
            (None, None),
            binding,
        );
    }

    fn output(
        &mut self,
        name: String,
        start: Value,
        description: String,
        unit: Option<Unit>,
        binding: Binding,
    ) {
        let variability = match start {
            Value::Real(_) => Variability::Continuous,
            _ => Variability::Discrete,
        };
        self.push(
            name,
            Causality::Output,
            variability,
            start,
            description,
            unit,
            (None, None),
            binding,
        );
    }

    /// One parameter per element of every field of [`ControllerConfig::FIELDS`], in order.
    /// Ranges are the robot's (`scale`): the tuned envelope widened with its size.
    fn parameters(&mut self, config: &ControllerConfig, scale: RobotScale) {
        for (field, f) in ControllerConfig::FIELDS.iter().enumerate() {
            let (min, max) = f.range_for(scale);
            let unit = f.unit.map(|name| {
                Unit::ALL
                    .into_iter()
                    .find(|u| u.name() == name)
                    .unwrap_or_else(|| panic!("unit {name} of {} is not declared", f.name))
            });
            for element in 0..f.len {
                self.push(
                    f.fmi_element_name(element),
                    Causality::Parameter,
                    Variability::Fixed,
                    read_parameter(field, element, config),
                    f.element_description(element),
                    unit,
                    (Some(min), Some(max)),
                    Binding::Parameter { field, element },
                );
                match f.kind {
                    FieldKind::Gait => self.of_type(GAIT_KIND_TYPE),
                    FieldKind::Estimator => self.of_type(ESTIMATOR_KIND_TYPE),
                    FieldKind::Real | FieldKind::Count => {}
                }
            }
        }
    }
}

const AXES: [&str; 3] = ["x", "y", "z"];
const QUATERNION: [&str; 4] = ["w", "x", "y", "z"];
const RPY: [&str; 3] = ["roll", "pitch", "yaw"];
fn joint_label(index: usize) -> String {
    Leg::ALL[index / 3].joint_label(index % 3)
}

/// The rows for `model`, parameters starting at `config`, inputs and outputs at the start values
/// of `start` (whose rows are not read).
pub(super) fn build_table(
    model: &RobotModel,
    config: &ControllerConfig,
    start: &VariableTable,
) -> Vec<Variable> {
    use Unit::*;
    let mut t = TableBuilder { rows: Vec::new() };
    let (state, reference) = start.initial_inputs();
    let command = start.initial_command();
    // Joint ranges from the URDF: positions and velocities are the region the controller is
    // designed for (documented, not refused, see `Variable::range_is_enforced`); torques are
    // clamped to the effort limits.
    let (lower, upper) = (model.lower_limits(), model.upper_limits());
    let (velocity, effort) = (model.velocity_limits(), model.effort_limits());

    // Inputs: measured state.
    for (i, axis) in AXES.iter().enumerate() {
        t.input(
            format!("base.pos.{axis}"),
            state.base_position[i],
            format!("Base origin {axis}, world frame"),
            Some(Metre),
            Binding::BasePosition(i),
        );
    }
    for (i, c) in QUATERNION.iter().enumerate() {
        t.input(
            format!("base.quat.{c}"),
            state.base_orientation[i],
            format!("Base orientation quaternion component {c} (rotates body to world; normalised by the controller)"),
            None,
            Binding::BaseOrientation(i),
        );
    }
    for (i, axis) in AXES.iter().enumerate() {
        t.input(
            format!("base.vel.{axis}"),
            state.base_linear_velocity[i],
            format!("Base linear velocity {axis}, world frame"),
            Some(MetrePerSecond),
            Binding::BaseLinearVelocity(i),
        );
    }
    for (i, axis) in AXES.iter().enumerate() {
        t.input(
            format!("base.omega.{axis}"),
            state.base_angular_velocity[i],
            format!("Base angular velocity {axis}, world frame"),
            Some(RadianPerSecond),
            Binding::BaseAngularVelocity(i),
        );
    }
    for i in 0..NUM_JOINTS {
        t.input(
            format!("joint.q[{}]", i + 1),
            state.joint_positions[i],
            format!(
                "Measured joint position, {} (range: URDF limits; outside them, beyond the fault margin, the controller drops to damping)",
                joint_label(i)
            ),
            Some(Radian),
            Binding::JointPosition(i),
        );
        t.with_range(lower[i], upper[i]);
    }
    for (i, &limit) in velocity.iter().enumerate() {
        t.input(
            format!("joint.dq[{}]", i + 1),
            state.joint_velocities[i],
            format!(
                "Measured joint velocity, {} (range: URDF velocity limit)",
                joint_label(i)
            ),
            Some(RadianPerSecond),
            Binding::JointVelocity(i),
        );
        t.with_range(-limit, limit);
    }

    // Inputs: reference from the planner.
    let reference_inputs: [(&str, f64, &str, Option<Unit>, Binding); 10] = [
        ("ref.x", reference.x, "Reference base x, world frame", Some(Metre), Binding::RefX),
        ("ref.y", reference.y, "Reference base y, world frame", Some(Metre), Binding::RefY),
        (
            "ref.z",
            reference.terrain.height,
            "Terrain height at (ref.x, ref.y), world z: the plan sample's z and the height of the local terrain plane",
            Some(Metre),
            Binding::RefZ,
        ),
        ("ref.yaw", reference.yaw, "Reference yaw about +z, counter-clockwise from +x", Some(Radian), Binding::RefYaw),
        ("ref.vx", reference.vx, "Reference velocity x, world frame", Some(MetrePerSecond), Binding::RefVx),
        ("ref.vy", reference.vy, "Reference velocity y, world frame", Some(MetrePerSecond), Binding::RefVy),
        ("ref.yawRate", reference.yaw_rate, "Reference yaw rate", Some(RadianPerSecond), Binding::RefYawRate),
        (
            "ref.bodyHeight",
            reference.body_height,
            "Desired base height above the terrain (<= 0 selects the parameter stand.bodyHeight)",
            Some(Metre),
            Binding::RefBodyHeight,
        ),
        (
            "terrain.dzdx",
            reference.terrain.slope_x,
            "Terrain slope dz/dx of the local plane through (ref.x, ref.y, ref.z)",
            None,
            Binding::TerrainSlopeX,
        ),
        (
            "terrain.dzdy",
            reference.terrain.slope_y,
            "Terrain slope dz/dy of the local plane through (ref.x, ref.y, ref.z)",
            None,
            Binding::TerrainSlopeY,
        ),
    ];
    for (name, start, description, unit, binding) in reference_inputs {
        t.input(
            name.to_owned(),
            start,
            description.to_owned(),
            unit,
            binding,
        );
    }
    // Inputs: local terrain height map (elevation map around the robot).
    let map = HeightMap::default();
    for (i, axis) in ["x0", "y0"].iter().enumerate() {
        t.input(
            format!("terrain.map.{axis}"),
            map.origin[i],
            format!("World {} of height-map sample (1, 1)", &axis[..1]),
            Some(Metre),
            Binding::HeightMapOrigin(i),
        );
    }
    t.input(
        "terrain.map.spacing".to_owned(),
        map.spacing,
        format!(
            "Height-map sample spacing (<= 0: no map, the terrain plane is used alone); the map has {HEIGHT_MAP_SIZE}x{HEIGHT_MAP_SIZE} samples, triangulated like the terrain mesh"
        ),
        Some(Metre),
        Binding::HeightMapSpacing,
    );
    for i in 0..HEIGHT_MAP_CELLS {
        t.input(
            format!("terrain.map.h[{}]", i + 1),
            map.heights[i],
            format!(
                "Terrain height of height-map sample (ix={}, iy={}) at (x0 + ix*spacing, y0 + iy*spacing), row-major by iy",
                i % HEIGHT_MAP_SIZE,
                i / HEIGHT_MAP_SIZE
            ),
            Some(Metre),
            Binding::HeightMapHeight(i),
        );
    }
    let mode_range = enum_type(MODE_REQUEST_TYPE)
        .map_or((None, None), |e| (Some(e.range().0), Some(e.range().1)));
    t.push(
        "cmd.mode".to_owned(),
        Causality::Input,
        Variability::Discrete,
        Value::Integer(reference.mode.as_code()),
        "Requested mode (the FSM stands up first and may enter damping on faults)".to_owned(),
        None,
        mode_range,
        Binding::ModeRequest,
    );
    t.of_type(MODE_REQUEST_TYPE);

    // Inputs: the sensors the estimator runs on (estimator = kalman).
    let sensors = SensorReadings::default();
    for (i, axis) in AXES.iter().enumerate() {
        t.input(
            format!("imu.gyro[{}]", i + 1),
            sensors.imu.gyro[i],
            format!("IMU angular velocity about body {axis}, body frame (NaN/inf accepted: the estimator holds the last valid rate and sets est.status)"),
            Some(RadianPerSecond),
            Binding::ImuGyro(i),
        );
    }
    for (i, axis) in AXES.iter().enumerate() {
        t.input(
            format!("imu.acc[{}]", i + 1),
            sensors.imu.acc[i],
            format!("IMU specific force a - g along body {axis}, body frame (+9.81 on z standing level; NaN/inf accepted and reported in est.status)"),
            Some(MetrePerSecondSquared),
            Binding::ImuAcc(i),
        );
    }
    for (leg, leg_name) in Leg::ALL.iter().map(|l| l.name()).enumerate() {
        t.push(
            format!("contact[{}]", leg + 1),
            Causality::Input,
            Variability::Discrete,
            Value::Integer(sensors.contacts[leg].as_code()),
            format!("Foot contact of leg {leg_name}: -1 unknown (the estimator uses the controller's stance schedule), 0 no contact, 1 contact"),
            None,
            (
                Some(f64::from(ContactReading::Unknown.as_code())),
                Some(f64::from(ContactReading::InContact.as_code())),
            ),
            Binding::ContactSensor(leg),
        );
    }
    for (i, axis) in AXES.iter().enumerate() {
        t.input(
            format!("fix.pos[{}]", i + 1),
            sensors.fix.position[i],
            format!("Absolute position fix of the base origin, {axis}, world frame (read when fix.valid)"),
            Some(Metre),
            Binding::FixPosition(i),
        );
    }
    t.push(
        "fix.valid".to_owned(),
        Causality::Input,
        Variability::Discrete,
        Value::Boolean(sensors.fix.valid),
        "A new position fix in fix.pos: set true only for the doStep in which it arrived (fused once, at the step's first control tick)".to_owned(),
        None,
        (None, None),
        Binding::FixValid,
    );

    // Outputs.
    for (i, &limit) in effort.iter().enumerate() {
        t.output(
            format!("joint.tau[{}]", i + 1),
            Value::Real(command.joint_torques[i]),
            format!(
                "Joint torque command, {} (clamped to the URDF effort limit)",
                joint_label(i)
            ),
            Some(NewtonMetre),
            Binding::JointTorque(i),
        );
        t.with_range(-limit, limit);
    }
    for (leg, leg_name) in Leg::ALL.iter().map(|l| l.name()).enumerate() {
        t.output(
            format!("stance[{}]", leg + 1),
            Value::Boolean(command.contacts[leg]),
            format!("Scheduled stance of leg {leg_name} (the gait plan; the measured contact is the input contact[{}])", leg + 1),
            None,
            Binding::ScheduledStance(leg),
        );
    }
    t.output(
        "fsm.state".to_owned(),
        Value::Integer(command.fsm_state.as_code()),
        "Controller state".to_owned(),
        None,
        Binding::FsmState,
    );
    t.of_type(FSM_STATE_TYPE);
    for (leg, leg_name) in Leg::ALL.iter().map(|l| l.name()).enumerate() {
        for (axis, axis_name) in AXES.iter().enumerate() {
            t.output(
                format!("force[{}].{axis_name}", leg + 1),
                Value::Real(command.desired_forces[leg][axis]),
                format!("Desired ground reaction force on the robot at foot {leg_name}, {axis_name}, world frame"),
                Some(Newton),
                Binding::DesiredForce(leg, axis),
            );
        }
    }
    t.output(
        "mpc.solveTime".to_owned(),
        Value::Real(command.mpc_solve_time_s),
        "Wall time of the last MPC solve (diagnostic; not deterministic)".to_owned(),
        Some(Second),
        Binding::MpcSolveTime,
    );
    t.output(
        "mpc.solved".to_owned(),
        Value::Boolean(command.mpc_solved),
        "Whether the last MPC solve succeeded".to_owned(),
        None,
        Binding::MpcSolved,
    );
    let estimate = command.estimate;
    for (i, axis) in AXES.iter().enumerate() {
        t.output(
            format!("est.pos[{}]", i + 1),
            Value::Real(estimate.position[i]),
            format!("Estimated base origin {axis}, world frame (groundTruth: base.pos.{axis})"),
            Some(Metre),
            Binding::EstimatedPosition(i),
        );
    }
    for (i, axis) in AXES.iter().enumerate() {
        t.output(
            format!("est.vel[{}]", i + 1),
            Value::Real(estimate.velocity[i]),
            format!("Estimated base velocity {axis}, world frame (groundTruth: base.vel.{axis})"),
            Some(MetrePerSecond),
            Binding::EstimatedVelocity(i),
        );
    }
    for (i, angle) in RPY.iter().enumerate() {
        t.output(
            format!("est.rpy[{}]", i + 1),
            Value::Real(estimate.rpy[i]),
            format!("Estimated base {angle} (ZYX Euler angles: yaw about world z, then pitch, then roll)"),
            Some(Radian),
            Binding::EstimatedRpy(i),
        );
    }
    for (i, axis) in AXES.iter().enumerate() {
        t.output(
            format!("est.posVar[{}]", i + 1),
            Value::Real(estimate.position_variance[i]),
            format!("Variance of est.pos[{}] (the Kalman filter's position covariance diagonal, world {axis}; 0 in groundTruth mode)", i + 1),
            Some(SquareMetre),
            Binding::EstimatedPositionVariance(i),
        );
    }
    for (i, axis) in AXES.iter().enumerate() {
        t.output(
            format!("est.attVar[{}]", i + 1),
            Value::Real(estimate.attitude_variance[i]),
            format!("Variance of the attitude error about body {axis} (the orientation filter's covariance diagonal; 0 in groundTruth mode)"),
            Some(SquareRadian),
            Binding::EstimatedAttitudeVariance(i),
        );
    }
    let bits: Vec<String> = StatusFlag::ALL
        .iter()
        .map(|&(flag, name, description)| format!("{} {name}: {description}", flag.bit()))
        .collect();
    t.output(
        "est.status".to_owned(),
        Value::Integer(0),
        format!(
            "Estimator status bit mask, OR over the control ticks of the last doStep (0 = healthy; always 0 in groundTruth mode); bits: {}",
            bits.join("; ")
        ),
        None,
        Binding::EstimatorStatus,
    );

    // Parameters are all fixed: `Controller` is built from them in fmi2ExitInitializationMode
    // (MPC matrices, standing pose, gait) and offers no way to change them afterwards.
    t.parameters(config, RobotScale::of(model));
    t.rows
}
