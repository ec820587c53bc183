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

    /// +1 for left legs, −1 for right legs (sign of the hip's body-frame y).
    pub fn side_sign(self) -> f64 {
        match self {
            Leg::FL | Leg::RL => 1.0,
            Leg::FR | Leg::RR => -1.0,
        }
    }
}

/// Which gait the locomotion state uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum GaitKind {
    /// Diagonal pairs (FR+RL, FL+RR) in anti-phase, duty factor 0.5.
    Trot,
    /// Static walk, one leg in swing at a time (RR, FR, RL, FL), duty factor 0.75.
    Walk,
}

/// Controller tuning. `Default` is the tuning used with the DART model of `robot/quadruped.urdf`
/// at a 1 kHz control rate; JSON-(de)serialisable (the FMU ships it as `resources/controller.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerConfig {
    /// Nominal leg control tick, s (the `dt` passed to `step` should match it).
    pub control_dt: f64,
    /// The MPC is solved on every k-th call of `step` (k ≥ 1); forces are held in between.
    pub mpc_every_ticks: usize,
    /// MPC horizon length in prediction steps (≥ 10).
    pub mpc_horizon: usize,
    /// MPC prediction step, s (horizon covers `mpc_horizon · mpc_dt`).
    pub mpc_dt: f64,
    /// Gait used in the locomotion state.
    pub gait: GaitKind,
    /// Gait cycle period, s.
    pub gait_period: f64,
    /// Swing-foot apex height above the straight line between lift-off and touchdown, m.
    pub swing_height: f64,
    /// Friction coefficient used by the MPC's friction pyramid.
    pub mu: f64,
    /// Minimum normal force on a stance foot, N.
    pub f_min: f64,
    /// Maximum normal force on a stance foot, N.
    pub f_max: f64,
    /// Nominal standing height of the base above the terrain, m (used when the reference gives ≤ 0).
    pub body_height: f64,
    /// MPC state weights: roll, pitch, yaw, x, y, z, ωx, ωy, ωz, vx, vy, vz, gravity state.
    pub mpc_q: [f64; 13],
    /// MPC force weight (same for every force component).
    pub mpc_r: f64,
    /// Swing-leg joint stiffness (abduction, hip, knee), N·m/rad.
    pub kp_swing: [f64; 3],
    /// Swing-leg joint damping (abduction, hip, knee), N·m·s/rad.
    pub kd_swing: [f64; 3],
    /// Joint stiffness used by the stand-up interpolation, N·m/rad.
    pub kp_stand: [f64; 3],
    /// Joint damping used by the stand-up interpolation, N·m·s/rad.
    pub kd_stand: [f64; 3],
    /// Duration of the stand-up motion, s.
    pub stand_up_duration: f64,
    /// Raibert foothold velocity-feedback gain k in p = p_hip + v·T_stance/2 + k (v − v_ref), s.
    pub raibert_gain: f64,
    /// Tilt (angle between body z and world z) above which the FSM enters damping, rad.
    pub max_tilt: f64,
    /// Joint position margin beyond the URDF limits tolerated before damping, rad.
    pub joint_limit_margin: f64,
    /// Joint damping of the damping (safe) state, N·m·s/rad.
    pub damping_kd: f64,
    /// Largest body pitch the terrain-following reference may ask for, rad.
    pub max_terrain_pitch: f64,
}

impl ControllerConfig {
    /// The MPC's fixed parameters for a robot of `mass` kg with body-frame inertia
    /// `inertia_body` (about its centre of mass), at this configuration's horizon.
    pub fn mpc_params(&self, mass: f64, inertia_body: [[f64; 3]; 3]) -> crate::mpc::MpcParams {
        crate::mpc::MpcParams {
            horizon: self.mpc_horizon,
            dt: self.mpc_dt,
            mass,
            inertia_body,
            q_weights: self.mpc_q,
            r_weight: self.mpc_r,
            mu: self.mu,
            f_min: self.f_min,
            f_max: self.f_max,
        }
    }
}

impl Default for ControllerConfig {
    fn default() -> Self {
        ControllerConfig {
            control_dt: 0.001,
            mpc_every_ticks: 10,
            mpc_horizon: 10,
            mpc_dt: 0.03,
            gait: GaitKind::Trot,
            gait_period: 0.3,
            swing_height: 0.08,
            mu: 0.6,
            f_min: 5.0,
            f_max: 150.0,
            body_height: 0.28,
            mpc_q: [
                10.0, 10.0, 5.0, 50.0, 50.0, 50.0, 0.05, 0.05, 0.3, 1.0, 1.0, 0.5, 0.0,
            ],
            mpc_r: 1e-5,
            kp_swing: [60.0, 60.0, 60.0],
            kd_swing: [2.0, 2.0, 2.0],
            kp_stand: [80.0, 80.0, 80.0],
            kd_stand: [3.0, 3.0, 3.0],
            stand_up_duration: 1.0,
            raibert_gain: 0.03,
            max_tilt: 0.9,
            joint_limit_margin: 0.15,
            damping_kd: 2.0,
            max_terrain_pitch: 0.35,
        }
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
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeightMap {
    /// World (x, y) of sample (0, 0), m.
    pub origin: [f64; 2],
    /// Distance between neighbouring samples, m (≤ 0: no map).
    pub spacing: f64,
    /// Heights, world z, m.
    pub heights: [f64; HEIGHT_MAP_CELLS],
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

/// What the master asks for; the FSM decides (stand-up first, damping on faults).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ModeRequest {
    /// Zero torque.
    Passive,
    /// Stand still (stand-up first when coming from passive).
    Stand,
    /// Walk/trot following the reference (stand-up and stand first).
    Locomotion,
}

impl ModeRequest {
    /// Stable integer code: Passive 0, Stand 1, Locomotion 2.
    pub fn as_code(self) -> i32 {
        match self {
            ModeRequest::Passive => 0,
            ModeRequest::Stand => 1,
            ModeRequest::Locomotion => 2,
        }
    }

    /// Inverse of [`ModeRequest::as_code`].
    pub fn from_code(code: i32) -> Option<ModeRequest> {
        match code {
            0 => Some(ModeRequest::Passive),
            1 => Some(ModeRequest::Stand),
            2 => Some(ModeRequest::Locomotion),
            _ => None,
        }
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

/// Gait state machine state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum FsmState {
    /// Zero torque.
    Passive,
    /// Joint-space interpolation from the current pose to the standing pose.
    StandUp,
    /// Four-leg balance with the MPC, zero velocity.
    Stand,
    /// Gait following the reference.
    Locomotion,
    /// Safe state after a fault (tilt, joint limit, bad input): joint damping only.
    Damping,
}

impl FsmState {
    /// Stable integer code: Passive 0, StandUp 1, Stand 2, Locomotion 3, Damping 4.
    pub fn as_code(self) -> i32 {
        match self {
            FsmState::Passive => 0,
            FsmState::StandUp => 1,
            FsmState::Stand => 2,
            FsmState::Locomotion => 3,
            FsmState::Damping => 4,
        }
    }

    /// Inverse of [`FsmState::as_code`].
    pub fn from_code(code: i32) -> Option<FsmState> {
        match code {
            0 => Some(FsmState::Passive),
            1 => Some(FsmState::StandUp),
            2 => Some(FsmState::Stand),
            3 => Some(FsmState::Locomotion),
            4 => Some(FsmState::Damping),
            _ => None,
        }
    }
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
}

/// Errors while building a [`crate::RobotModel`].
#[derive(Debug, Error)]
pub enum ModelError {
    /// The URDF text could not be parsed.
    #[error("cannot parse URDF: {0}")]
    Parse(String),
    /// The URDF file could not be read.
    #[error("cannot read URDF file {path}: {reason}")]
    Io {
        /// File path.
        path: String,
        /// OS error text.
        reason: String,
    },
    /// A link or joint required by the naming convention is missing.
    #[error("URDF is missing {0} (naming convention: base link `base`, joints `<LEG>_hip_abd_joint`, `<LEG>_hip_flex_joint`, `<LEG>_knee_joint`, foot link `<LEG>_foot`)")]
    Missing(String),
    /// The URDF is structurally not a quadruped of the expected topology.
    #[error("unsupported URDF structure: {0}")]
    Structure(String),
    /// A numeric value in the URDF is invalid (non-finite, non-positive mass, …).
    #[error("invalid value in URDF: {0}")]
    InvalidValue(String),
    /// Inverse kinematics has no solution for the requested foot position.
    #[error("foot position out of the {leg:?} leg's workspace: {reason}")]
    Unreachable {
        /// Leg.
        leg: Leg,
        /// Why.
        reason: String,
    },
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
