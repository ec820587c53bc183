//! The one table of FMU variables. `modelDescription.xml`, the HTML documentation and every
//! `fmi2Get*`/`fmi2Set*` call are driven by it; there is no second list to keep in sync.
//!
//! Value references are the table index (unique across types), so the `index` attribute used in
//! `<ModelStructure>` is always `value_reference + 1`.

use std::sync::OnceLock;

use quad_controller::config::{FieldKind, FieldValue};
use quad_controller::{
    Command, ControllerConfig, FsmState, GaitKind, HeightMap, ModeRequest, Reference, RobotState,
    HEIGHT_MAP_CELLS, HEIGHT_MAP_SIZE, NUM_JOINTS, NUM_LEGS,
};

use crate::FmuError;

/// FMI base type of a variable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScalarType {
    /// `fmi2Real`.
    Real,
    /// `fmi2Integer`.
    Integer,
    /// `fmi2Boolean`.
    Boolean,
}

impl ScalarType {
    /// Element name in `modelDescription.xml`.
    pub fn xml_name(self) -> &'static str {
        match self {
            ScalarType::Real => "Real",
            ScalarType::Integer => "Integer",
            ScalarType::Boolean => "Boolean",
        }
    }
}

/// A typed value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    /// Real.
    Real(f64),
    /// Integer.
    Integer(i32),
    /// Boolean.
    Boolean(bool),
}

impl Value {
    /// Its FMI type.
    pub fn scalar_type(self) -> ScalarType {
        match self {
            Value::Real(_) => ScalarType::Real,
            Value::Integer(_) => ScalarType::Integer,
            Value::Boolean(_) => ScalarType::Boolean,
        }
    }

    /// The value as written in a `start` attribute (round-trips exactly for reals).
    pub fn xml_text(self) -> String {
        match self {
            Value::Real(v) => format!("{v:?}"),
            Value::Integer(v) => v.to_string(),
            Value::Boolean(v) => v.to_string(),
        }
    }
}

/// FMI causality.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Causality {
    /// Set before (fixed) or also during (tunable) the simulation.
    Parameter,
    /// Set by the master before every doStep.
    Input,
    /// Computed by doStep.
    Output,
}

impl Causality {
    /// Attribute value.
    pub fn xml_name(self) -> &'static str {
        match self {
            Causality::Parameter => "parameter",
            Causality::Input => "input",
            Causality::Output => "output",
        }
    }
}

/// FMI variability.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variability {
    /// Parameter that may only change before `fmi2ExitInitializationMode`.
    Fixed,
    /// Parameter that may also change between doSteps.
    Tunable,
    /// Changes only at communication points (all Integer/Boolean signals).
    Discrete,
    /// Real signal.
    Continuous,
}

impl Variability {
    /// Attribute value.
    pub fn xml_name(self) -> &'static str {
        match self {
            Variability::Fixed => "fixed",
            Variability::Tunable => "tunable",
            Variability::Discrete => "discrete",
            Variability::Continuous => "continuous",
        }
    }
}

/// Physical units used by the variables; each is declared in `<UnitDefinitions>`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Unit {
    /// Metre.
    Metre,
    /// Second.
    Second,
    /// Radian.
    Radian,
    /// Metre per second.
    MetrePerSecond,
    /// Radian per second.
    RadianPerSecond,
    /// Newton.
    Newton,
    /// Newton metre.
    NewtonMetre,
    /// Newton metre per radian (joint stiffness).
    NewtonMetrePerRadian,
    /// Newton metre second per radian (joint damping).
    NewtonMetreSecondPerRadian,
}

impl Unit {
    /// Every unit, in declaration order.
    pub const ALL: [Unit; 9] = [
        Unit::Metre,
        Unit::Second,
        Unit::Radian,
        Unit::MetrePerSecond,
        Unit::RadianPerSecond,
        Unit::Newton,
        Unit::NewtonMetre,
        Unit::NewtonMetrePerRadian,
        Unit::NewtonMetreSecondPerRadian,
    ];

    /// Unit name (FMI/Modelica notation).
    pub fn name(self) -> &'static str {
        match self {
            Unit::Metre => "m",
            Unit::Second => "s",
            Unit::Radian => "rad",
            Unit::MetrePerSecond => "m/s",
            Unit::RadianPerSecond => "rad/s",
            Unit::Newton => "N",
            Unit::NewtonMetre => "N.m",
            Unit::NewtonMetrePerRadian => "N.m/rad",
            Unit::NewtonMetreSecondPerRadian => "N.m.s/rad",
        }
    }

    /// SI base-unit exponents as `(attribute, exponent)` for `<BaseUnit>`.
    pub fn base_units(self) -> &'static [(&'static str, i32)] {
        match self {
            Unit::Metre => &[("m", 1)],
            Unit::Second => &[("s", 1)],
            Unit::Radian => &[("rad", 1)],
            Unit::MetrePerSecond => &[("m", 1), ("s", -1)],
            Unit::RadianPerSecond => &[("s", -1), ("rad", 1)],
            Unit::Newton => &[("kg", 1), ("m", 1), ("s", -2)],
            Unit::NewtonMetre => &[("kg", 1), ("m", 2), ("s", -2)],
            Unit::NewtonMetrePerRadian => &[("kg", 1), ("m", 2), ("s", -2), ("rad", -1)],
            Unit::NewtonMetreSecondPerRadian => &[("kg", 1), ("m", 2), ("s", -1), ("rad", -1)],
        }
    }
}

/// An item of an enumeration type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EnumItem {
    /// Item name (the Rust variant name).
    pub name: &'static str,
    /// Integer code, as read and written with `fmi2GetInteger`/`fmi2SetInteger`.
    pub value: i32,
    /// Human description.
    pub description: &'static str,
}

/// An enumeration type of `<TypeDefinitions>` (FMI 2.0 `<SimpleType>` with `<Enumeration>`),
/// generated from the controller's own list of the variants.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EnumType {
    /// Type name, used as `declaredType` by the variables of this type.
    pub name: &'static str,
    /// Human description.
    pub description: &'static str,
    /// Items in code order.
    pub items: Vec<EnumItem>,
}

impl EnumType {
    fn new<T: Copy>(
        name: &'static str,
        description: &'static str,
        all: &[(T, &'static str, &'static str)],
        code: impl Fn(T) -> i32,
    ) -> EnumType {
        let items = all
            .iter()
            .map(|&(variant, name, description)| EnumItem {
                name,
                value: code(variant),
                description,
            })
            .collect();
        EnumType {
            name,
            description,
            items,
        }
    }

    /// `(min, max)` of the item codes.
    pub fn range(&self) -> (f64, f64) {
        let codes = self.items.iter().map(|item| item.value);
        let min = codes.clone().min().unwrap_or(0);
        let max = codes.max().unwrap_or(0);
        (f64::from(min), f64::from(max))
    }
}

/// Name of the enumeration type of `fsm.state`.
pub const FSM_STATE_TYPE: &str = "FsmState";
/// Name of the enumeration type of `cmd.mode`.
pub const MODE_REQUEST_TYPE: &str = "ModeRequest";
/// Name of the enumeration type of `gait.kind`.
pub const GAIT_KIND_TYPE: &str = "GaitKind";

/// The enumeration types, built once (order of `<TypeDefinitions>`).
pub fn enum_types() -> &'static [EnumType] {
    static TYPES: OnceLock<Vec<EnumType>> = OnceLock::new();
    TYPES.get_or_init(|| {
        vec![
            EnumType::new(
                FSM_STATE_TYPE,
                "State of the controller's gait state machine",
                &FsmState::ALL,
                FsmState::as_code,
            ),
            EnumType::new(
                MODE_REQUEST_TYPE,
                "Mode requested by the master; the state machine decides the state",
                &ModeRequest::ALL,
                ModeRequest::as_code,
            ),
            EnumType::new(
                GAIT_KIND_TYPE,
                "Gait of the locomotion state",
                &GaitKind::ALL,
                GaitKind::as_code,
            ),
        ]
    })
}

/// The enumeration type called `name`.
pub fn enum_type(name: &str) -> Option<&'static EnumType> {
    enum_types().iter().find(|t| t.name == name)
}

/// Reads element `element` of the config field `field` (index into
/// [`ControllerConfig::FIELDS`]) as an FMI value.
pub fn read_parameter(field: usize, element: usize, config: &ControllerConfig) -> Value {
    let f = &ControllerConfig::FIELDS[field];
    match f.get(config, element) {
        FieldValue::Real(v) => Value::Real(v),
        FieldValue::Count(n) => Value::Integer(i32::try_from(n).unwrap_or(i32::MAX)),
        FieldValue::Gait(g) => Value::Integer(g.as_code()),
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
        // The table gives every parameter exactly one type; other pairs cannot be requested.
        _ => return,
    };
    f.set(config, element, converted);
}

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
    TABLE.get_or_init(build_table)
}

/// Finds a variable by name (linear; meant for tests and tools, not the hot path).
pub fn by_name(name: &str) -> Option<&'static Variable> {
    table().iter().find(|v| v.name == name)
}

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
    fn parameters(&mut self) {
        let config = ControllerConfig::default();
        for (field, f) in ControllerConfig::FIELDS.iter().enumerate() {
            let (min, max) = f.range();
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
                    read_parameter(field, element, &config),
                    f.element_description(element),
                    unit,
                    (Some(min), Some(max)),
                    Binding::Parameter { field, element },
                );
                if f.kind == FieldKind::Gait {
                    self.of_type(GAIT_KIND_TYPE);
                }
            }
        }
    }
}

const AXES: [&str; 3] = ["x", "y", "z"];
const QUATERNION: [&str; 4] = ["w", "x", "y", "z"];
const LEG_NAMES: [&str; NUM_LEGS] = ["FR", "FL", "RR", "RL"];
const JOINT_NAMES: [&str; 3] = ["hip abduction", "hip flexion", "knee"];

fn joint_label(index: usize) -> String {
    format!("{} {}", LEG_NAMES[index / 3], JOINT_NAMES[index % 3])
}

fn build_table() -> Vec<Variable> {
    use Unit::*;
    let mut t = TableBuilder { rows: Vec::new() };
    let (state, reference) = initial_inputs();
    let command = initial_command();

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
            format!("Joint position, {}", joint_label(i)),
            Some(Radian),
            Binding::JointPosition(i),
        );
    }
    for i in 0..NUM_JOINTS {
        t.input(
            format!("joint.dq[{}]", i + 1),
            state.joint_velocities[i],
            format!("Joint velocity, {}", joint_label(i)),
            Some(RadianPerSecond),
            Binding::JointVelocity(i),
        );
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

    // Outputs.
    for i in 0..NUM_JOINTS {
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
    }
    for (leg, leg_name) in LEG_NAMES.iter().enumerate() {
        t.output(
            format!("contact[{}]", leg + 1),
            Value::Boolean(command.contacts[leg]),
            format!("Scheduled stance of leg {leg_name}"),
            None,
            Binding::Contact(leg),
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
    for (leg, leg_name) in LEG_NAMES.iter().enumerate() {
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

    // Parameters are all fixed: `Controller` is built from them in fmi2ExitInitializationMode
    // (MPC matrices, standing pose, gait) and offers no way to change them afterwards.
    t.parameters();
    t.rows
}

/// Checks that `value` may be stored in `variable` (type, finiteness, range).
pub fn check_value(variable: &Variable, value: Value) -> Result<(), FmuError> {
    let invalid = |reason: String| FmuError::InvalidValue {
        name: variable.name.clone(),
        reason,
    };
    let number = match value {
        Value::Real(v) if !v.is_finite() => {
            return Err(invalid(format!("{v} is not a finite number")));
        }
        Value::Real(v) => v,
        Value::Integer(v) => f64::from(v),
        Value::Boolean(_) => return Ok(()),
    };
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
pub fn check_parameters(config: &ControllerConfig) -> Result<(), FmuError> {
    for v in table() {
        if let Binding::Parameter { field, element } = v.binding {
            check_value(v, read_parameter(field, element, config))?;
        }
    }
    Ok(())
}

/// Reads an input variable from the stored inputs.
pub fn read_input(
    binding: Binding,
    state: &RobotState,
    reference: &Reference,
    map: &HeightMap,
) -> Option<Value> {
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
        Binding::ModeRequest => return Some(Value::Integer(reference.mode.as_code())),
        _ => return None,
    };
    Some(Value::Real(real))
}

/// Writes an input variable (value already checked with [`check_value`]).
pub fn write_input(
    binding: Binding,
    value: Value,
    state: &mut RobotState,
    reference: &mut Reference,
    map: &mut HeightMap,
) {
    if let (Binding::ModeRequest, Value::Integer(code)) = (binding, value) {
        if let Some(mode) = ModeRequest::from_code(code) {
            reference.mode = mode;
        }
        return;
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
        _ => return,
    };
    *field = v;
}

/// Reads an output variable from the last command.
pub fn read_output(binding: Binding, command: &Command) -> Option<Value> {
    Some(match binding {
        Binding::JointTorque(i) => Value::Real(command.joint_torques[i]),
        Binding::Contact(leg) => Value::Boolean(command.contacts[leg]),
        Binding::FsmState => Value::Integer(command.fsm_state.as_code()),
        Binding::DesiredForce(leg, axis) => Value::Real(command.desired_forces[leg][axis]),
        Binding::MpcSolveTime => Value::Real(command.mpc_solve_time_s),
        Binding::MpcSolved => Value::Boolean(command.mpc_solved),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use quad_controller::config::ConfigField;
    use std::collections::HashSet;

    #[test]
    fn names_and_references_are_unique_and_dense() {
        let rows = table();
        let names: HashSet<&str> = rows.iter().map(|v| v.name.as_str()).collect();
        assert_eq!(names.len(), rows.len());
        for (i, v) in rows.iter().enumerate() {
            assert_eq!(v.value_reference as usize, i);
        }
    }

    #[test]
    fn table_has_the_documented_signals() {
        let count = |c: Causality| table().iter().filter(|v| v.causality == c).count();
        // 3 pos + 4 quat + 3 vel + 3 omega + 12 q + 12 dq + 10 reference/terrain + cmd.mode
        // + height map (x0, y0, spacing, 121 heights)
        assert_eq!(count(Causality::Input), 48 + 3 + HEIGHT_MAP_CELLS);
        // 12 tau + 4 contact + fsm + 12 force + solve time + solved
        assert_eq!(count(Causality::Output), 31);
        for name in [
            "base.quat.w",
            "joint.q[12]",
            "joint.dq[1]",
            "ref.yawRate",
            "cmd.mode",
            "joint.tau[12]",
            "contact[4]",
            "force[4].z",
            "mpc.solved",
            "gait.period",
            "mpc.q[13]",
            "swing.kd[3]",
        ] {
            assert!(by_name(name).is_some(), "{name}");
        }
        assert_eq!(
            by_name("cmd.mode").unwrap().scalar_type(),
            ScalarType::Integer
        );
        assert_eq!(
            by_name("contact[1]").unwrap().scalar_type(),
            ScalarType::Boolean
        );
    }

    #[test]
    fn every_binding_round_trips_through_its_storage() {
        let (mut state, mut reference) = initial_inputs();
        let mut map = HeightMap::default();
        let mut config = ControllerConfig::default();
        for (k, v) in table().iter().enumerate() {
            let probe = match v.start {
                Value::Real(_) => Value::Real(0.5 + k as f64),
                Value::Integer(_) => Value::Integer(1),
                Value::Boolean(b) => Value::Boolean(!b),
            };
            match v.binding {
                Binding::Parameter { field, element } => {
                    assert_eq!(
                        read_parameter(field, element, &config),
                        v.start,
                        "{}",
                        v.name
                    );
                    write_parameter(field, element, &mut config, probe);
                    assert_eq!(read_parameter(field, element, &config), probe, "{}", v.name);
                }
                b if v.causality == Causality::Input => {
                    assert_eq!(
                        read_input(b, &state, &reference, &map),
                        Some(v.start),
                        "{}",
                        v.name
                    );
                    write_input(b, probe, &mut state, &mut reference, &mut map);
                    assert_eq!(
                        read_input(b, &state, &reference, &map),
                        Some(probe),
                        "{}",
                        v.name
                    );
                }
                b => assert_eq!(
                    read_output(b, &initial_command()),
                    Some(v.start),
                    "{}",
                    v.name
                ),
            }
        }
    }

    fn next_up(x: f64) -> f64 {
        if x == 0.0 {
            f64::from_bits(1)
        } else if x > 0.0 {
            f64::from_bits(x.to_bits() + 1)
        } else {
            f64::from_bits(x.to_bits() - 1)
        }
    }

    fn next_down(x: f64) -> f64 {
        -next_up(-x)
    }

    /// Every parameter with its config field and element.
    fn parameters() -> impl Iterator<Item = (&'static Variable, &'static ConfigField, usize)> {
        table().iter().filter_map(|v| match v.binding {
            Binding::Parameter { field, element } => {
                Some((v, &ControllerConfig::FIELDS[field], element))
            }
            _ => None,
        })
    }

    #[test]
    fn every_parameter_has_a_range_holding_its_start_value() {
        assert_eq!(parameters().count(), 43);
        for (v, field, _) in parameters() {
            let (min, max) = field.range();
            assert_eq!((v.min, v.max), (Some(min), Some(max)), "{}", v.name);
            assert!(
                min.is_finite() && max.is_finite() && min < max,
                "{}",
                v.name
            );
            check_value(v, v.start).unwrap_or_else(|e| panic!("{e}"));
        }
        check_parameters(&ControllerConfig::default()).unwrap();
    }

    #[test]
    fn values_just_outside_a_range_and_non_finite_values_are_refused() {
        for (v, field, _) in parameters() {
            let (min, max) = field.range();
            let (below, above) = match v.start {
                Value::Real(_) => (Value::Real(next_down(min)), Value::Real(next_up(max))),
                _ => (
                    Value::Integer(min as i32 - 1),
                    Value::Integer(max as i32 + 1),
                ),
            };
            for bad in [below, above] {
                let err = check_value(v, bad).unwrap_err().to_string();
                assert!(
                    err.starts_with(&format!("invalid value for {}", v.name)),
                    "{err}"
                );
            }
            if let Value::Real(_) = v.start {
                for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, -1e300] {
                    assert!(
                        check_value(v, Value::Real(bad)).is_err(),
                        "{} {bad}",
                        v.name
                    );
                }
            }
            for good in [min, max] {
                let value = match v.start {
                    Value::Real(_) => Value::Real(good),
                    _ => Value::Integer(good as i32),
                };
                check_value(v, value).unwrap_or_else(|e| panic!("{e}"));
            }
        }
    }

    /// The ranges are the controller's operating envelope: every end point, with the other
    /// parameters at their defaults, builds a controller, except where a parameter is also
    /// checked against another one in fmi2ExitInitializationMode (`f_min < f_max`, a standing
    /// height the legs reach); those work with a matching partner.
    #[test]
    fn every_range_end_point_builds_a_controller() {
        use quad_controller::{Controller, RobotModel};
        let model = RobotModel::from_urdf_file(
            &crate::bundle::repo_root()
                .join("robot")
                .join("quadruped.urdf"),
        )
        .unwrap();
        for (v, field, element) in parameters() {
            let (min, max) = field.range();
            let index = ControllerConfig::FIELDS
                .iter()
                .position(|f| f.name == field.name)
                .unwrap();
            for end in [min, max] {
                let mut config = ControllerConfig::default();
                let value = match v.start {
                    Value::Real(_) => Value::Real(end),
                    _ => Value::Integer(end as i32),
                };
                write_parameter(index, element, &mut config, value);
                assert_eq!(read_parameter(index, element, &config), value);
                config.check_ranges().unwrap();
                match (field.name, end == max) {
                    ("f_min", true) => config.f_max = end + 1.0,
                    ("f_max", false) => config.f_min = 0.0,
                    _ => {}
                }
                let result = Controller::new(model.clone(), config.clone());
                if field.name == "body_height" && end == max {
                    assert!(result.is_err(), "legs of 0.4 m cannot stand 0.5 m high");
                } else {
                    result.unwrap_or_else(|e| panic!("{} = {end}: {e}", v.name));
                }
            }
        }
    }

    #[test]
    fn values_are_checked() {
        let x = by_name("base.pos.x").unwrap();
        assert!(check_value(x, Value::Real(f64::NAN))
            .unwrap_err()
            .to_string()
            .contains("base.pos.x"));
        assert!(check_value(x, Value::Real(f64::INFINITY)).is_err());
        assert!(check_value(x, Value::Real(-3.0)).is_ok());
        let mode = by_name("cmd.mode").unwrap();
        assert!(check_value(mode, Value::Integer(3)).is_err());
        assert!(check_value(mode, Value::Integer(-1)).is_err());
        assert!(check_value(mode, Value::Integer(2)).is_ok());
        let dt = by_name("control.dt").unwrap();
        assert!(check_value(dt, Value::Real(0.0)).is_err());
    }
}
