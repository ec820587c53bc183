//! Public types of the controller: the contract shared with the FMU wrapper and the harness
//! (documented on each item below). Everything here is plain data, `Copy` where cheap, and
//! serialisable where the FMU ships it as a resource file.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Number of legs.
pub const NUM_LEGS: usize = 4;
/// Number of actuated joints (3 per leg).
pub const NUM_JOINTS: usize = 12;
/// Standard gravity, m/s².
pub const GRAVITY: f64 = 9.81;

/// A leg. The discriminant is the leg index used everywhere: global joint index = 3·leg + j
/// with j = 0 hip abduction, 1 hip flexion, 2 knee.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Leg {
    /// Front right.
    FR = 0,
    /// Front left.
    FL = 1,
    /// Rear right.
    RR = 2,
    /// Rear left.
    RL = 3,
}

/// The joints of a leg, in index order `3·leg + j`.
pub const LEG_JOINT_NAMES: [&str; 3] = ["hip abduction", "hip flexion", "knee"];

impl Leg {
    /// All legs in index order.
    pub const ALL: [Leg; NUM_LEGS] = [Leg::FR, Leg::FL, Leg::RR, Leg::RL];

    /// Index 0..3.
    pub fn index(self) -> usize {
        self as usize
    }

    /// Leg from its index, `None` when out of range.
    pub fn from_index(index: usize) -> Option<Leg> {
        Leg::ALL.get(index).copied()
    }

    /// URDF prefix of the leg's joints and links (`FR`, `FL`, `RR`, `RL`).
    pub fn name(self) -> &'static str {
        match self {
            Leg::FR => "FR",
            Leg::FL => "FL",
            Leg::RR => "RR",
            Leg::RL => "RL",
        }
    }

    /// Name of joint `j` of this leg, e.g. `FR knee` (logs, FMU descriptions).
    pub fn joint_label(self, j: usize) -> String {
        format!("{} {}", self.name(), LEG_JOINT_NAMES[j])
    }

    /// +1 for left legs, −1 for right legs (sign of the hip's body-frame y).
    pub fn side_sign(self) -> f64 {
        match self {
            Leg::FL | Leg::RL => 1.0,
            Leg::FR | Leg::RR => -1.0,
        }
    }
}

/// Which gait the locomotion state uses. The discriminant is the stable integer code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum GaitKind {
    /// Diagonal pairs (FR+RL, FL+RR) in anti-phase, duty factor 0.5.
    Trot = 0,
    /// Static walk, one leg in swing at a time (RR, FR, RL, FL), duty factor 0.75.
    Walk = 1,
}

impl GaitKind {
    /// Every gait with its name and description (the code is the discriminant): the one list the FMU's
    /// `GaitKind` enumeration type (`gait.kind`) is generated from.
    pub const ALL: [(GaitKind, &'static str, &'static str); 2] = [
        (
            GaitKind::Trot,
            "Trot",
            "Diagonal pairs in anti-phase, duty factor 0.5",
        ),
        (
            GaitKind::Walk,
            "Walk",
            "Static walk, one leg in swing at a time, duty factor 0.75",
        ),
    ];

    /// Stable integer code (the discriminant).
    pub fn as_code(self) -> i32 {
        self as i32
    }

    /// Inverse of [`GaitKind::as_code`].
    pub fn from_code(code: i32) -> Option<GaitKind> {
        GaitKind::ALL
            .iter()
            .find(|&&(v, ..)| v.as_code() == code)
            .map(|&(gait, ..)| gait)
    }
}

/// Measured state of the robot.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobotState {
    /// Base origin, world frame, m.
    pub base_position: [f64; 3],
    /// Base orientation quaternion (w, x, y, z) rotating body → world (need not be exactly unit;
    /// it is normalised, and a norm far from 1 is rejected).
    pub base_orientation: [f64; 4],
    /// Base linear velocity, world frame, m/s.
    pub base_linear_velocity: [f64; 3],
    /// Base angular velocity, world frame, rad/s.
    pub base_angular_velocity: [f64; 3],
    /// Joint positions, index 3·leg + {abd, hip, knee}, rad.
    pub joint_positions: [f64; NUM_JOINTS],
    /// Joint velocities, same order, rad/s.
    pub joint_velocities: [f64; NUM_JOINTS],
}

impl Default for RobotState {
    fn default() -> Self {
        RobotState {
            base_position: [0.0; 3],
            base_orientation: [1.0, 0.0, 0.0, 0.0],
            base_linear_velocity: [0.0; 3],
            base_angular_velocity: [0.0; 3],
            joint_positions: [0.0; NUM_JOINTS],
            joint_velocities: [0.0; NUM_JOINTS],
        }
    }
}

/// Local terrain plane under the reference point:
/// z = height + slope_x·(x − x_ref) + slope_y·(y − y_ref), world frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TerrainPlane {
    /// Terrain height at the reference point (x_ref, y_ref), m.
    pub height: f64,
    /// ∂z/∂x, dimensionless.
    pub slope_x: f64,
    /// ∂z/∂y, dimensionless.
    pub slope_y: f64,
}

/// Side length (samples per row and column) of a [`HeightMap`].
pub const HEIGHT_MAP_SIZE: usize = 11;
/// Number of samples of a [`HeightMap`].
pub const HEIGHT_MAP_CELLS: usize = HEIGHT_MAP_SIZE * HEIGHT_MAP_SIZE;

/// Local terrain height samples around the robot (what a perception stack's elevation map gives):
/// a square grid of `HEIGHT_MAP_SIZE`² heights, axis-aligned in the world frame, sample (ix, iy) at
/// `origin + spacing·(ix, iy)`, stored row-major `heights[iy·HEIGHT_MAP_SIZE + ix]`. Between
/// samples the surface is the triangle mesh through them, each cell split along its
/// (ix, iy)–(ix+1, iy+1) diagonal (the triangulation of the simulated terrain mesh).
/// `spacing` ≤ 0 means "no map": the controller then uses the [`TerrainPlane`] only.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeightMap {
    /// World (x, y) of sample (0, 0), m.
    pub origin: [f64; 2],
    /// Distance between neighbouring samples, m (≤ 0: no map).
    pub spacing: f64,
    /// Heights, world z, m.
    #[serde(with = "height_samples")]
    pub heights: [f64; HEIGHT_MAP_CELLS],
}

/// Serde of the height samples as a sequence (serde derives arrays of at most 32 elements); a
/// sequence of any other length is refused.
mod height_samples {
    use serde::de::Error;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use super::HEIGHT_MAP_CELLS;

    pub fn serialize<S: Serializer>(
        heights: &[f64; HEIGHT_MAP_CELLS],
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        heights.as_slice().serialize(serializer)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<[f64; HEIGHT_MAP_CELLS], D::Error> {
        let samples = Vec::<f64>::deserialize(deserializer)?;
        let len = samples.len();
        samples
            .try_into()
            .map_err(|_| D::Error::invalid_length(len, &"the height map's sample count"))
    }
}

impl Default for HeightMap {
    fn default() -> Self {
        HeightMap {
            origin: [0.0; 2],
            spacing: 0.0,
            heights: [0.0; HEIGHT_MAP_CELLS],
        }
    }
}

impl HeightMap {
    /// Whether the map holds data (positive spacing).
    pub fn is_present(&self) -> bool {
        self.spacing > 0.0
    }

    /// Checks a present map for non-finite values.
    pub fn validate(&self) -> Result<(), String> {
        if !self.spacing.is_finite() || !self.origin.iter().all(|v| v.is_finite()) {
            return Err("height map origin/spacing must be finite".into());
        }
        if self.is_present() {
            if let Some(i) = self.heights.iter().position(|h| !h.is_finite()) {
                return Err(format!("height map sample {i} = {}", self.heights[i]));
            }
        }
        Ok(())
    }

    /// Terrain height at (x, y); `None` without a map or outside it.
    pub fn height(&self, x: f64, y: f64) -> Option<f64> {
        if !self.is_present() {
            return None;
        }
        let last = (HEIGHT_MAP_SIZE - 1) as f64;
        let fx = (x - self.origin[0]) / self.spacing;
        let fy = (y - self.origin[1]) / self.spacing;
        if !(fx >= 0.0 && fy >= 0.0 && fx <= last && fy <= last) {
            return None;
        }
        // In range 0..=last, so the casts are exact.
        let ix = (fx.floor() as usize).min(HEIGHT_MAP_SIZE - 2);
        let iy = (fy.floor() as usize).min(HEIGHT_MAP_SIZE - 2);
        let u = fx - ix as f64;
        let v = fy - iy as f64;
        let at = |i: usize, j: usize| self.heights[j * HEIGHT_MAP_SIZE + i];
        let za = at(ix, iy);
        let zb = at(ix + 1, iy);
        let zc = at(ix + 1, iy + 1);
        let zd = at(ix, iy + 1);
        Some(if u >= v {
            za + u * (zb - za) + v * (zc - zb)
        } else {
            za + u * (zc - zd) + v * (zd - za)
        })
    }
}

/// What the master asks for; the FSM decides (stand-up first, damping on faults). The
/// discriminant is the stable integer code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ModeRequest {
    /// Zero torque.
    Passive = 0,
    /// Stand still (stand-up first when coming from passive).
    Stand = 1,
    /// Walk/trot following the reference (stand-up and stand first).
    Locomotion = 2,
}

impl ModeRequest {
    /// Every mode with its name and description (the code is the discriminant): the one list the FMU's
    /// `ModeRequest` enumeration type (`cmd.mode`) is generated from.
    pub const ALL: [(ModeRequest, &'static str, &'static str); 3] = [
        (ModeRequest::Passive, "Passive", "Zero torque"),
        (
            ModeRequest::Stand,
            "Stand",
            "Stand still (stand-up first when coming from passive)",
        ),
        (
            ModeRequest::Locomotion,
            "Locomotion",
            "Follow the reference with the gait (stand-up and stand first)",
        ),
    ];

    /// Stable integer code (the discriminant).
    pub fn as_code(self) -> i32 {
        self as i32
    }

    /// Inverse of [`ModeRequest::as_code`].
    pub fn from_code(code: i32) -> Option<ModeRequest> {
        ModeRequest::ALL
            .iter()
            .find(|&&(v, ..)| v.as_code() == code)
            .map(|&(mode, ..)| mode)
    }
}

/// Reference from the planner (through the harness), world frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reference {
    /// Desired base x, m.
    pub x: f64,
    /// Desired base y, m.
    pub y: f64,
    /// Desired yaw, rad.
    pub yaw: f64,
    /// Desired velocity x (world), m/s.
    pub vx: f64,
    /// Desired velocity y (world), m/s.
    pub vy: f64,
    /// Desired yaw rate, rad/s.
    pub yaw_rate: f64,
    /// Desired base height above the terrain, m (≤ 0 selects `ControllerConfig::body_height`).
    pub body_height: f64,
    /// Terrain plane around (x, y).
    pub terrain: TerrainPlane,
    /// Requested mode.
    pub mode: ModeRequest,
}

impl Default for Reference {
    fn default() -> Self {
        Reference {
            x: 0.0,
            y: 0.0,
            yaw: 0.0,
            vx: 0.0,
            vy: 0.0,
            yaw_rate: 0.0,
            body_height: 0.0,
            terrain: TerrainPlane::default(),
            mode: ModeRequest::Stand,
        }
    }
}

/// Gait state machine state. The discriminant is the stable integer code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum FsmState {
    /// Zero torque.
    Passive = 0,
    /// Joint-space interpolation from the current pose to the standing pose.
    StandUp = 1,
    /// Four-leg balance with the MPC, zero velocity.
    Stand = 2,
    /// Gait following the reference.
    Locomotion = 3,
    /// Safe state after a fault (tilt, joint limit, bad input): joint damping only.
    Damping = 4,
}

impl FsmState {
    /// Every state with its name and description (the code is the discriminant): the one list the FMU's
    /// `FsmState` enumeration type (`fsm.state`) is generated from.
    pub const ALL: [(FsmState, &'static str, &'static str); 5] = [
        (FsmState::Passive, "Passive", "Zero torque"),
        (
            FsmState::StandUp,
            "StandUp",
            "Joint-space interpolation from the current pose to the standing pose",
        ),
        (
            FsmState::Stand,
            "Stand",
            "Four-leg balance with the MPC, zero velocity",
        ),
        (
            FsmState::Locomotion,
            "Locomotion",
            "Gait following the reference",
        ),
        (
            FsmState::Damping,
            "Damping",
            "Safe state after a fault (tilt, joint limit, bad input): joint damping only",
        ),
    ];

    /// Stable integer code (the discriminant).
    pub fn as_code(self) -> i32 {
        self as i32
    }

    /// Inverse of [`FsmState::as_code`].
    pub fn from_code(code: i32) -> Option<FsmState> {
        FsmState::ALL
            .iter()
            .find(|&&(v, ..)| v.as_code() == code)
            .map(|&(state, ..)| state)
    }
}

/// Which state the controller runs on. The discriminant is the stable integer code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum EstimatorKind {
    /// The measured base pose and twist of [`RobotState`] (simulation ground truth).
    GroundTruth = 0,
    /// Orientation filter (gyro + accelerometer) and the 18-state leg-kinematics Kalman filter;
    /// the base pose of [`RobotState`] is read once, at the first tick, to place the robot.
    Kalman = 1,
}

impl EstimatorKind {
    /// Every estimator with its name and description (the code is the discriminant): the one list
    /// the FMU's `EstimatorKind` enumeration type (`estimator`) is generated from.
    pub const ALL: [(EstimatorKind, &'static str, &'static str); 2] = [
        (
            EstimatorKind::GroundTruth,
            "groundTruth",
            "The base pose and twist inputs (base.*) are the state",
        ),
        (
            EstimatorKind::Kalman,
            "kalman",
            "IMU orientation filter + leg-kinematics Kalman filter; base.pos/base.quat read at the first tick only",
        ),
    ];

    /// Stable integer code (the discriminant).
    pub fn as_code(self) -> i32 {
        self as i32
    }

    /// Inverse of [`EstimatorKind::as_code`].
    pub fn from_code(code: i32) -> Option<EstimatorKind> {
        EstimatorKind::ALL
            .iter()
            .find(|&&(v, ..)| v.as_code() == code)
            .map(|&(kind, ..)| kind)
    }
}

/// One IMU sample, body frame (the IMU sits at the base origin, axes along the base axes).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImuReading {
    /// Angular velocity, body frame, rad/s.
    pub gyro: [f64; 3],
    /// Specific force a − g, body frame, m/s² (+[`GRAVITY`] on z when standing level).
    pub acc: [f64; 3],
}

impl Default for ImuReading {
    /// A level robot at rest.
    fn default() -> Self {
        ImuReading {
            gyro: [0.0; 3],
            acc: [0.0, 0.0, GRAVITY],
        }
    }
}

/// What a foot contact sensor (or the master) says about one foot. The discriminant is the
/// stable integer code of the FMU inputs `contact[1..4]`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ContactReading {
    /// No sensor: the estimator uses the controller's own stance schedule.
    #[default]
    Unknown = -1,
    /// The foot is off the ground.
    NoContact = 0,
    /// The foot is on the ground.
    InContact = 1,
}

impl ContactReading {
    /// Stable integer code (the discriminant).
    pub fn as_code(self) -> i32 {
        self as i32
    }

    /// Inverse of [`ContactReading::as_code`].
    pub fn from_code(code: i32) -> Option<ContactReading> {
        [
            ContactReading::Unknown,
            ContactReading::NoContact,
            ContactReading::InContact,
        ]
        .into_iter()
        .find(|c| c.as_code() == code)
    }
}

/// An absolute position measurement of the base origin (GNSS, motion capture), world frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PositionFix {
    /// Base origin, world frame, m.
    pub position: [f64; 3],
    /// Whether `position` is a new measurement to fuse (false: no fix this tick).
    pub valid: bool,
}

/// The sensor inputs of one control tick besides the encoders of [`RobotState`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SensorReadings {
    /// IMU sample.
    pub imu: ImuReading,
    /// Contact per leg (index = [`Leg::index`]).
    pub contacts: [ContactReading; NUM_LEGS],
    /// Absolute position fix, fused once when `valid`.
    pub fix: PositionFix,
}

/// The estimate the controller ran on this tick, as reported to the master.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EstimateReport {
    /// Base origin, world frame, m.
    pub position: [f64; 3],
    /// Base linear velocity, world frame, m/s.
    pub velocity: [f64; 3],
    /// Roll, pitch, yaw (ZYX Euler angles), rad.
    pub rpy: [f64; 3],
    /// Variance of the base origin per world axis, m² (the Kalman filter's position covariance
    /// diagonal; 0 in ground-truth mode). A map built on this estimate grows its cells'
    /// variances with it.
    pub position_variance: [f64; 3],
    /// Variance of the attitude error about the body axes, rad² (the orientation filter's
    /// covariance diagonal; 0 in ground-truth mode).
    pub attitude_variance: [f64; 3],
    /// Estimator status bits ([`crate::estimator::StatusFlag`]); 0 = healthy.
    pub status: u32,
}

/// Output of one control tick.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Command {
    /// Joint torques, N·m, clamped to the URDF effort limits, index 3·leg + j.
    pub joint_torques: [f64; NUM_JOINTS],
    /// Scheduled stance per leg.
    pub contacts: [bool; NUM_LEGS],
    /// FSM state after this tick.
    pub fsm_state: FsmState,
    /// Ground reaction force acting ON the robot at each foot, world frame, N (zero for swing legs).
    pub desired_forces: [[f64; 3]; NUM_LEGS],
    /// Desired foot (sphere centre) positions, world frame, m: the swing trajectory sample for
    /// swing legs, the stance foothold for stance legs.
    pub desired_foot_positions: [[f64; 3]; NUM_LEGS],
    /// Wall time of the last MPC solve, s (measured with `std::time::Instant`; diagnostic only,
    /// never fed back into the control law, so `step` stays deterministic).
    pub mpc_solve_time_s: f64,
    /// Whether the last MPC solve succeeded (false also when no MPC ran yet).
    pub mpc_solved: bool,
    /// The state estimate this tick ran on, and the estimator's status.
    pub estimate: EstimateReport,
}

/// Errors while building a [`crate::RobotModel`].
#[derive(Debug, Error)]
pub enum ModelError {
    /// The URDF text could not be parsed.
    #[error("cannot parse URDF: {0}")]
    Parse(String),
    /// A file (the robot config or its URDF) could not be read.
    #[error("{path}: cannot read it ({reason})")]
    Io {
        /// File path.
        path: String,
        /// OS error text.
        reason: String,
    },
    /// A link or joint named by the robot config is missing from the URDF.
    #[error("URDF is missing {0}")]
    Missing(String),
    /// The URDF is structurally not a quadruped of the expected topology.
    #[error("unsupported URDF structure: {0}")]
    Structure(String),
    /// A numeric value in the URDF is invalid (non-finite, non-positive mass, …).
    #[error("invalid value in URDF: {0}")]
    InvalidValue(String),
    /// The robot config (TOML) is invalid: syntax (with its line), an unknown or missing key, a
    /// bad value, a file it names that cannot be found.
    #[error("robot config {file}: {reason}")]
    Config {
        /// Config file (or the label of a config given as text).
        file: String,
        /// The key whose value is wrong (`stand_height`, `legs.FR.crouch`, …), when one is; a
        /// syntax error has none.
        key: Option<String>,
        /// What is wrong, naming the key.
        reason: String,
    },
    /// An error in the description read from `file` (the URDF, or the config for config-side
    /// problems found while building the model).
    #[error("{file}: {source}")]
    InFile {
        /// File path (or the label of a text given in memory).
        file: String,
        /// The error.
        source: Box<ModelError>,
    },
    /// Inverse kinematics has no solution for the requested foot position.
    #[error("foot position out of the {leg:?} leg's workspace: {reason}")]
    Unreachable {
        /// Leg.
        leg: Leg,
        /// Why.
        reason: String,
    },
}

impl ModelError {
    /// The error without its [`ModelError::InFile`] wrappers (for matching on the kind).
    pub fn innermost(&self) -> &ModelError {
        match self {
            ModelError::InFile { source, .. } => source.innermost(),
            other => other,
        }
    }

    /// The config key an error is about (see [`ModelError::Config`]), through file wrappers.
    pub fn config_key(&self) -> Option<&str> {
        match self.innermost() {
            ModelError::Config { key, .. } => key.as_deref(),
            _ => None,
        }
    }

    /// Wrap `self` with the file it was found in.
    pub fn in_file(self, file: &str) -> ModelError {
        ModelError::InFile {
            file: file.to_string(),
            source: Box::new(self),
        }
    }
}

/// Errors of [`crate::Controller`].
#[derive(Debug, Error)]
pub enum ControllerError {
    /// The configuration is invalid.
    #[error("invalid controller config: {0}")]
    Config(String),
    /// The state contains NaN/inf or an invalid quaternion.
    #[error("invalid robot state: {0}")]
    InvalidState(String),
    /// The reference contains NaN/inf or an impossible value.
    #[error("invalid reference: {0}")]
    InvalidReference(String),
    /// The time step is not a positive finite number.
    #[error("invalid time step dt = {0} (must be finite and > 0)")]
    InvalidDt(f64),
    /// Model error.
    #[error(transparent)]
    Model(#[from] ModelError),
}
