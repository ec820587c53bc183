//! The controller: gait state machine, footholds, MPC scheduling and leg torque control.
//!
//! Frames and signs used throughout:
//! - `R` rotates base-frame vectors into the world frame (the state's quaternion).
//! - MPC forces `f` are ground reaction forces acting ON the robot at the foot, world frame.
//! - A stance leg realises `f` with `τ = Jᵀ (Rᵀ (−f)) + h(q, q̇)`: `−f` is the force the foot
//!   exerts on the ground, `Rᵀ` takes it to the base frame where the foot Jacobian `J` lives, and
//!   `h` (leg gravity + Coriolis, fixed-base model) carries the leg's own weight so that the base
//!   receives exactly `f` minus the leg weight.
//! - A swing leg tracks the swing trajectory in joint space:
//!   `τ = M(q) q̈_ref + h(q, q̇) + K_p (q_ref − q) + K_d (q̇_ref − q̇)` with `q_ref` from IK.
//!
//! Terrain awareness (the paper's "particle → rigid body" step): the reference carries a local
//! terrain plane. The base height reference is `body_height` above that plane at the predicted
//! base position, the pitch reference follows the plane's slope along the heading (clamped to
//! `max_terrain_pitch`), footholds are placed at the plane's height (plus the foot radius), and
//! the MPC's friction pyramid is built about the plane's normal.
//!
//! With a local [`HeightMap`] (`Controller::set_height_map`) the plane is only the fallback and
//! the friction normal: footholds take the map's height and are moved (by at most
//! `FOOTHOLD_SEARCH_RADIUS`) off edges, wall feet and pit rims onto locally flat ground; the swing
//! apex is raised to clear the terrain between lift-off and touchdown; the base height and pitch
//! references follow the ground under the four nominal footholds. A single plane fitted around the
//! reference point is badly wrong beside a wall, a pit or a valley side: footholds at its height
//! land early, late or on a rim, which is what made the robot fall on the scenario maps.

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

use crate::api::{
    Command, ControllerConfig, ControllerError, FsmState, HeightMap, Leg, ModeRequest, Reference,
    RobotState, GRAVITY, NUM_JOINTS, NUM_LEGS,
};
use crate::gait::{swing_trajectory, Gait, LegPhase};
use crate::math::{rot_z, wrap_angle};
use crate::model::RobotModel;
use crate::mpc::{ConvexMpc, MpcInput, MpcParams, MpcStatus, MPC_STATES};

/// Quantities derived from the measured state once per tick.
#[derive(Clone, Debug)]
struct Sense {
    rotation: Matrix3<f64>,
    rpy: Vector3<f64>,
    position: Vector3<f64>,
    velocity: Vector3<f64>,
    angular_velocity: Vector3<f64>,
    q: [[f64; 3]; NUM_LEGS],
    dq: [[f64; 3]; NUM_LEGS],
    feet_world: [Vector3<f64>; NUM_LEGS],
    gravity_body: [f64; 3],
}

/// Output of a state's run step.
struct Actuation {
    torques: [f64; NUM_JOINTS],
    contacts: [bool; NUM_LEGS],
    forces: [[f64; 3]; NUM_LEGS],
    feet: [[f64; 3]; NUM_LEGS],
}

/// Base motion the MPC should follow.
#[derive(Clone, Copy, Debug)]
struct MotionTarget {
    xy: [f64; 2],
    yaw: f64,
    velocity: [f64; 2],
    yaw_rate: f64,
}

/// Where the base should stand relative to the ground its feet will use.
#[derive(Clone, Copy, Debug)]
struct StanceGround {
    /// Mean terrain height under the footholds, m.
    height: f64,
    /// Pitch reference, rad.
    pitch: f64,
    /// Mean displacement of the footholds from their nominal positions, world xy, m.
    shift: [f64; 2],
}

/// The quadruped controller (see the crate docs for the API contract).
pub struct Controller {
    model: RobotModel,
    config: ControllerConfig,
    mpc: ConvexMpc,
    gait: Gait,
    effort_limits: [f64; NUM_JOINTS],
    lower_limits: [f64; NUM_JOINTS],
    upper_limits: [f64; NUM_JOINTS],
    stand_joint_positions: [f64; NUM_JOINTS],
    /// Nominal foot position under each hip, base frame (xy used for footholds).
    nominal_feet_body: [Vector3<f64>; NUM_LEGS],
    com_offset_body: Vector3<f64>,
    /// How long each state given to `step` stays in force (0: a fresh state every tick).
    input_period_s: f64,
    fsm: FsmState,
    state_time: f64,
    stand_up_start: [f64; NUM_JOINTS],
    hold: MotionTarget,
    gait_time: f64,
    ticks_since_mpc: usize,
    forces: [[f64; 3]; NUM_LEGS],
    mpc_contacts: [bool; NUM_LEGS],
    mpc_solved: bool,
    mpc_solve_time_s: f64,
    contacts: [bool; NUM_LEGS],
    swing_start: [Vector3<f64>; NUM_LEGS],
    footholds: [Vector3<f64>; NUM_LEGS],
    stance_anchor: [Vector3<f64>; NUM_LEGS],
    mpc_reference: Vec<[f64; MPC_STATES]>,
    mpc_schedule: Vec<[bool; NUM_LEGS]>,
    mpc_offsets: Vec<[[f64; 3]; NUM_LEGS]>,
    height_map: HeightMap,
    /// Foothold search candidates, ring by ring (nearest first).
    foothold_candidates: Vec<FootholdCandidate>,
}

/// Offset of one foothold search candidate from the nominal foothold.
#[derive(Clone, Copy, Debug)]
struct FootholdCandidate {
    ring: f64,
    dx: f64,
    dy: f64,
}

fn foothold_candidates() -> Vec<FootholdCandidate> {
    let last_ring = (FOOTHOLD_RINGS.len() - 1) as f64;
    FOOTHOLD_RINGS
        .iter()
        .enumerate()
        .flat_map(|(k, &count)| {
            let ring = FOOTHOLD_SEARCH_RADIUS * k as f64 / last_ring;
            (0..count).map(move |i| {
                let angle = std::f64::consts::TAU * i as f64 / count as f64;
                FootholdCandidate {
                    ring,
                    dx: ring * angle.cos(),
                    dy: ring * angle.sin(),
                }
            })
        })
        .collect()
}

/// Largest distance a foothold is moved from its Raibert position to find flat ground, m.
pub const FOOTHOLD_SEARCH_RADIUS: f64 = 0.2;
/// Candidates per ring of the foothold search (ring k at radius k/(len − 1) of the search radius).
const FOOTHOLD_RINGS: [usize; 6] = [1, 8, 12, 16, 16, 20];
/// Distance at which the foothold search probes the height around a candidate, m.
const EDGE_PROBE: f64 = 0.05;
const EDGE_DIAGONAL: f64 = EDGE_PROBE * std::f64::consts::FRAC_1_SQRT_2;
/// The probe offsets around a foothold candidate (8 directions).
const EDGE_PROBES: [(f64, f64); 8] = [
    (EDGE_PROBE, 0.0),
    (-EDGE_PROBE, 0.0),
    (0.0, EDGE_PROBE),
    (0.0, -EDGE_PROBE),
    (EDGE_DIAGONAL, EDGE_DIAGONAL),
    (EDGE_DIAGONAL, -EDGE_DIAGONAL),
    (-EDGE_DIAGONAL, EDGE_DIAGONAL),
    (-EDGE_DIAGONAL, -EDGE_DIAGONAL),
];
/// Cost of one metre of height change around a candidate, in metres of foothold displacement.
const EDGE_WEIGHT: f64 = 2.0;
/// Steepest local slope (rise over run within `EDGE_PROBE`) a foothold may have without extra
/// cost: about half the friction cone of the feet (μ ≈ 0.8 in simulation).
const STEEP_SLOPE: f64 = 0.6;
/// Cost per unit of local slope beyond `STEEP_SLOPE`, in metres of foothold displacement: a foot
/// on a slope steeper than its friction cone slides down it.
const STEEP_WEIGHT: f64 = 0.5;
/// Fraction of the mean foothold displacement the base reference follows.
const BODY_SHIFT_GAIN: f64 = 1.0;
/// Largest shift of the base reference towards displaced footholds, m.
const MAX_BODY_SHIFT: f64 = 0.1;
/// Clearance the swing foot keeps above the terrain between lift-off and touchdown, m.
const SWING_TERRAIN_MARGIN: f64 = 0.06;
/// Joint damping per inertia and input period at most (k_d·T/M_ii): a held velocity feedback with
/// k_d·T/M_ii above 2 reverses the joint's velocity every period, and the joint chatters.
const HELD_KD_LIMIT: f64 = 1.0;
/// Joint stiffness per inertia and squared input period at most (k_p·T²/M_ii).
const HELD_KP_LIMIT: f64 = 0.25;
/// Highest swing apex (above the lift-off/touchdown line) the clearance logic may ask for, m.
const MAX_SWING_HEIGHT: f64 = 0.2;

fn smoothstep(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

fn check_finite(values: &[f64], what: &str) -> Result<(), String> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(format!("{what}[{i}] = {}", values[i])),
        None => Ok(()),
    }
}

fn validate_config(config: &ControllerConfig) -> Result<(), ControllerError> {
    let err = |m: String| Err(ControllerError::Config(m));
    let positive = [
        ("control_dt", config.control_dt),
        ("mpc_dt", config.mpc_dt),
        ("gait_period", config.gait_period),
        ("mu", config.mu),
        ("f_max", config.f_max),
        ("body_height", config.body_height),
        ("mpc_r", config.mpc_r),
        ("stand_up_duration", config.stand_up_duration),
        ("max_tilt", config.max_tilt),
    ];
    for (name, value) in positive {
        if !(value.is_finite() && value > 0.0) {
            return err(format!("{name} = {value} must be finite and > 0"));
        }
    }
    let non_negative = [
        ("swing_height", config.swing_height),
        ("f_min", config.f_min),
        ("raibert_gain", config.raibert_gain),
        ("joint_limit_margin", config.joint_limit_margin),
        ("damping_kd", config.damping_kd),
        ("max_terrain_pitch", config.max_terrain_pitch),
    ];
    for (name, value) in non_negative {
        if !(value.is_finite() && value >= 0.0) {
            return err(format!("{name} = {value} must be finite and ≥ 0"));
        }
    }
    let gains = config
        .mpc_q
        .iter()
        .chain(&config.kp_swing)
        .chain(&config.kd_swing)
        .chain(&config.kp_stand)
        .chain(&config.kd_stand);
    if gains.clone().any(|g| !(g.is_finite() && *g >= 0.0)) {
        return err("weights and gains must be finite and ≥ 0".into());
    }
    if config.mpc_every_ticks == 0 {
        return err("mpc_every_ticks must be ≥ 1".into());
    }
    if !crate::limits::MPC_HORIZON.contains(&config.mpc_horizon) {
        return err(format!(
            "mpc_horizon = {} outside {:?}",
            config.mpc_horizon,
            crate::limits::MPC_HORIZON
        ));
    }
    if config.f_min >= config.f_max {
        return err("f_min must be < f_max".into());
    }
    Ok(())
}

fn validate_state(state: &RobotState) -> Result<(), ControllerError> {
    let bad = |m: String| Err(ControllerError::InvalidState(m));
    for (values, what) in [
        (&state.base_position[..], "base_position"),
        (&state.base_orientation[..], "base_orientation"),
        (&state.base_linear_velocity[..], "base_linear_velocity"),
        (&state.base_angular_velocity[..], "base_angular_velocity"),
        (&state.joint_positions[..], "joint_positions"),
        (&state.joint_velocities[..], "joint_velocities"),
    ] {
        if let Err(m) = check_finite(values, what) {
            return bad(m);
        }
    }
    let norm = state
        .base_orientation
        .iter()
        .map(|v| v * v)
        .sum::<f64>()
        .sqrt();
    if !(0.9..=1.1).contains(&norm) {
        return bad(format!("base_orientation norm {norm} is not ≈ 1"));
    }
    Ok(())
}

fn validate_reference(reference: &Reference, mpc_dt: f64) -> Result<(), ControllerError> {
    let values = [
        reference.x,
        reference.y,
        reference.yaw,
        reference.vx,
        reference.vy,
        reference.yaw_rate,
        reference.body_height,
        reference.terrain.height,
        reference.terrain.slope_x,
        reference.terrain.slope_y,
    ];
    check_finite(&values, "reference").map_err(ControllerError::InvalidReference)?;
    if reference.yaw_rate.abs() * mpc_dt > crate::mpc::MAX_YAW_STEP {
        return Err(ControllerError::InvalidReference(format!(
            "yaw_rate {} rad/s turns by more than π/2 per MPC step of {mpc_dt} s",
            reference.yaw_rate
        )));
    }
    if reference.body_height > 1.0 {
        return Err(ControllerError::InvalidReference(format!(
            "body_height {} m is not reachable",
            reference.body_height
        )));
    }
    if reference.terrain.slope_x.abs() > 2.0 || reference.terrain.slope_y.abs() > 2.0 {
        return Err(ControllerError::InvalidReference(
            "terrain slope steeper than 63°".into(),
        ));
    }
    Ok(())
}

fn terrain_height(reference: &Reference, x: f64, y: f64) -> f64 {
    let t = &reference.terrain;
    t.height + t.slope_x * (x - reference.x) + t.slope_y * (y - reference.y)
}

fn terrain_normal(reference: &Reference) -> Vector3<f64> {
    Vector3::new(-reference.terrain.slope_x, -reference.terrain.slope_y, 1.0).normalize()
}

fn leg_slice<const N: usize>(values: &[f64; N], leg: Leg) -> [f64; 3] {
    let l = leg.index();
    [values[3 * l], values[3 * l + 1], values[3 * l + 2]]
}

impl Controller {
    /// Build a controller; fails on an invalid config or when the standing pose is unreachable.
    pub fn new(model: RobotModel, config: ControllerConfig) -> Result<Self, ControllerError> {
        validate_config(&config)?;
        let mut stand_joint_positions = [0.0; NUM_JOINTS];
        let mut nominal_feet_body = [Vector3::zeros(); NUM_LEGS];
        for leg in Leg::ALL {
            let hip = model.hip_position_body(leg);
            let foot = [
                hip[0],
                hip[1] + model.hip_lateral_offset(leg),
                -(config.body_height - model.foot_radius()),
            ];
            nominal_feet_body[leg.index()] = Vector3::from(foot);
            let q = model.inverse_kinematics(leg, foot)?;
            stand_joint_positions[3 * leg.index()..3 * leg.index() + 3].copy_from_slice(&q);
        }
        let (inertia, com) = model.composite_inertia(&stand_joint_positions);
        let mpc = ConvexMpc::new(MpcParams::from_config(&config, model.total_mass(), inertia))
            .map_err(ControllerError::Config)?;
        let n = config.mpc_horizon;
        Ok(Controller {
            effort_limits: model.effort_limits(),
            lower_limits: model.lower_limits(),
            upper_limits: model.upper_limits(),
            gait: Gait::new(config.gait, config.gait_period),
            stand_joint_positions,
            nominal_feet_body,
            com_offset_body: Vector3::from(com),
            fsm: FsmState::Passive,
            state_time: 0.0,
            stand_up_start: [0.0; NUM_JOINTS],
            hold: MotionTarget {
                xy: [0.0; 2],
                yaw: 0.0,
                velocity: [0.0; 2],
                yaw_rate: 0.0,
            },
            gait_time: 0.0,
            input_period_s: 0.0,
            ticks_since_mpc: 0,
            forces: [[0.0; 3]; NUM_LEGS],
            mpc_contacts: [false; NUM_LEGS],
            mpc_solved: false,
            mpc_solve_time_s: 0.0,
            contacts: [false; NUM_LEGS],
            swing_start: [Vector3::zeros(); NUM_LEGS],
            footholds: [Vector3::zeros(); NUM_LEGS],
            stance_anchor: [Vector3::zeros(); NUM_LEGS],
            mpc_reference: vec![[0.0; MPC_STATES]; n],
            mpc_schedule: vec![[false; NUM_LEGS]; n],
            mpc_offsets: vec![[[0.0; 3]; NUM_LEGS]; n],
            height_map: HeightMap::default(),
            foothold_candidates: foothold_candidates(),
            mpc,
            model,
            config,
        })
    }

    /// Sets the local terrain height map used from the next `step` on (a map with spacing ≤ 0
    /// clears it: the terrain plane of the reference is used alone). On an invalid map the
    /// previous one is kept and an error returned.
    pub fn set_height_map(&mut self, map: &HeightMap) -> Result<(), ControllerError> {
        map.validate().map_err(ControllerError::InvalidReference)?;
        self.height_map = *map;
        Ok(())
    }

    /// The height map in use.
    pub fn height_map(&self) -> &HeightMap {
        &self.height_map
    }

    /// Current FSM state.
    pub fn fsm_state(&self) -> FsmState {
        self.fsm
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
        self.input_period_s = seconds;
        Ok(())
    }

    /// PD gains for a joint of inertia `inertia` under the declared input period.
    fn held_gains(&self, kp: f64, kd: f64, inertia: f64) -> (f64, f64) {
        let period = self.input_period_s;
        if period <= 0.0 || !(inertia.is_finite() && inertia > 0.0) {
            return (kp, kd);
        }
        (
            kp.min(HELD_KP_LIMIT * inertia / (period * period)),
            kd.min(HELD_KD_LIMIT * inertia / period),
        )
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
        self.stand_joint_positions
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
        let mut torques = [0.0; NUM_JOINTS];
        for (i, tau) in torques.iter_mut().enumerate() {
            let dq = state.joint_velocities[i];
            if dq.is_finite() {
                // The state may be invalid: the joint inertia is taken at the standing pose.
                let leg = Leg::ALL[i / 3];
                let mass = self
                    .model
                    .mass_matrix(leg, leg_slice(&self.stand_joint_positions, leg));
                let (_, kd) = self.held_gains(0.0, self.config.damping_kd, mass[(i % 3, i % 3)]);
                let limit = self.effort_limits[i];
                *tau = (-kd * dq).clamp(-limit, limit);
            }
        }
        Command {
            joint_torques: torques,
            contacts: [false; NUM_LEGS],
            fsm_state: FsmState::Damping,
            desired_forces: [[0.0; 3]; NUM_LEGS],
            desired_foot_positions: [[0.0; 3]; NUM_LEGS],
            mpc_solve_time_s: 0.0,
            mpc_solved: false,
        }
    }

    /// One control tick. Deterministic: the same sequence of inputs gives bit-identical outputs.
    /// On invalid input the controller's internal state is left untouched and an error returned.
    pub fn step(
        &mut self,
        state: &RobotState,
        reference: &Reference,
        dt: f64,
    ) -> Result<Command, ControllerError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(ControllerError::InvalidDt(dt));
        }
        validate_state(state)?;
        validate_reference(reference, self.config.mpc_dt)?;
        let sense = self.sense(state);

        if let Some(next) = self.transition(&sense, reference) {
            tracing::debug!(from = ?self.fsm, to = ?next, "FSM transition");
            self.enter(next, &sense);
        }
        let actuation = match self.fsm {
            FsmState::Passive => self.run_passive(),
            FsmState::StandUp => self.run_stand_up(&sense),
            FsmState::Stand => self.run_stand(&sense, reference),
            FsmState::Locomotion => self.run_locomotion(&sense, reference, dt),
            FsmState::Damping => self.run_damping(&sense),
        };
        self.state_time += dt;
        let mut torques = actuation.torques;
        for (i, tau) in torques.iter_mut().enumerate() {
            let limit = self.effort_limits[i];
            *tau = if tau.is_finite() {
                tau.clamp(-limit, limit)
            } else {
                0.0
            };
        }
        Ok(Command {
            joint_torques: torques,
            contacts: actuation.contacts,
            fsm_state: self.fsm,
            desired_forces: actuation.forces,
            desired_foot_positions: actuation.feet,
            mpc_solve_time_s: self.mpc_solve_time_s,
            mpc_solved: self.mpc_solved,
        })
    }

    fn sense(&self, state: &RobotState) -> Sense {
        let o = state.base_orientation;
        let quaternion = UnitQuaternion::from_quaternion(Quaternion::new(o[0], o[1], o[2], o[3]));
        let rotation = *quaternion.to_rotation_matrix().matrix();
        let rpy = Vector3::new(
            rotation[(2, 1)].atan2(rotation[(2, 2)]),
            (-rotation[(2, 0)]).clamp(-1.0, 1.0).asin(),
            rotation[(1, 0)].atan2(rotation[(0, 0)]),
        );
        let position = Vector3::from(state.base_position);
        let mut q = [[0.0; 3]; NUM_LEGS];
        let mut dq = [[0.0; 3]; NUM_LEGS];
        let mut feet_world = [Vector3::zeros(); NUM_LEGS];
        for leg in Leg::ALL {
            let l = leg.index();
            q[l] = leg_slice(&state.joint_positions, leg);
            dq[l] = leg_slice(&state.joint_velocities, leg);
            let foot = Vector3::from(self.model.foot_position_body(leg, q[l]));
            feet_world[l] = position + rotation * foot;
        }
        let gravity = rotation.transpose() * Vector3::new(0.0, 0.0, -GRAVITY);
        Sense {
            rotation,
            rpy,
            position,
            velocity: Vector3::from(state.base_linear_velocity),
            angular_velocity: Vector3::from(state.base_angular_velocity),
            q,
            dq,
            feet_world,
            gravity_body: [gravity.x, gravity.y, gravity.z],
        }
    }

    /// Tilt or joint-limit fault.
    fn fault(&self, sense: &Sense) -> Option<String> {
        let tilt = sense.rotation[(2, 2)].clamp(-1.0, 1.0).acos();
        if tilt > self.config.max_tilt {
            return Some(format!("tilt {tilt:.3} rad"));
        }
        let margin = self.config.joint_limit_margin;
        for leg in Leg::ALL {
            for j in 0..3 {
                let i = 3 * leg.index() + j;
                let q = sense.q[leg.index()][j];
                if q < self.lower_limits[i] - margin || q > self.upper_limits[i] + margin {
                    return Some(format!("joint {i} at {q:.3} rad beyond its limits"));
                }
            }
        }
        None
    }

    // ---------------------------------------------------------------------------------------
    // State machine. `transition` holds every state's exit conditions, `enter` every state's
    // entry actions, and the `run_*` functions every state's per-tick behaviour.
    // ---------------------------------------------------------------------------------------

    fn transition(&self, sense: &Sense, reference: &Reference) -> Option<FsmState> {
        let mode = reference.mode;
        match self.fsm {
            FsmState::Passive => match mode {
                ModeRequest::Passive => None,
                ModeRequest::Stand | ModeRequest::Locomotion => Some(FsmState::StandUp),
            },
            FsmState::StandUp => {
                if let Some(reason) = self.fault(sense) {
                    tracing::warn!(%reason, "fault during stand-up: damping");
                    Some(FsmState::Damping)
                } else if mode == ModeRequest::Passive {
                    Some(FsmState::Passive)
                } else if self.state_time >= self.config.stand_up_duration {
                    Some(FsmState::Stand)
                } else {
                    None
                }
            }
            FsmState::Stand => {
                if let Some(reason) = self.fault(sense) {
                    tracing::warn!(%reason, "fault while standing: damping");
                    Some(FsmState::Damping)
                } else {
                    match mode {
                        ModeRequest::Passive => Some(FsmState::Passive),
                        ModeRequest::Stand => None,
                        ModeRequest::Locomotion => Some(FsmState::Locomotion),
                    }
                }
            }
            FsmState::Locomotion => {
                if let Some(reason) = self.fault(sense) {
                    tracing::warn!(%reason, "fault during locomotion: damping");
                    Some(FsmState::Damping)
                } else {
                    match mode {
                        ModeRequest::Passive => Some(FsmState::Passive),
                        ModeRequest::Stand => Some(FsmState::Stand),
                        ModeRequest::Locomotion => None,
                    }
                }
            }
            // Damping is left only through an explicit reset to passive.
            FsmState::Damping => match mode {
                ModeRequest::Passive => Some(FsmState::Passive),
                _ => None,
            },
        }
    }

    fn enter(&mut self, next: FsmState, sense: &Sense) {
        self.fsm = next;
        self.state_time = 0.0;
        self.ticks_since_mpc = usize::MAX;
        match next {
            FsmState::Passive | FsmState::Damping => {
                self.forces = [[0.0; 3]; NUM_LEGS];
                self.mpc_solved = false;
            }
            FsmState::StandUp => {
                for leg in Leg::ALL {
                    let l = leg.index();
                    self.stand_up_start[3 * l..3 * l + 3].copy_from_slice(&sense.q[l]);
                }
            }
            FsmState::Stand => {
                self.hold = MotionTarget {
                    xy: [sense.position.x, sense.position.y],
                    yaw: sense.rpy.z,
                    velocity: [0.0; 2],
                    yaw_rate: 0.0,
                };
            }
            FsmState::Locomotion => {
                self.gait_time = 0.0;
                self.contacts = [true; NUM_LEGS];
                self.stance_anchor = sense.feet_world;
                self.swing_start = sense.feet_world;
                self.footholds = sense.feet_world;
            }
        }
    }

    fn run_passive(&mut self) -> Actuation {
        self.contacts = [false; NUM_LEGS];
        Actuation {
            torques: [0.0; NUM_JOINTS],
            contacts: [false; NUM_LEGS],
            forces: [[0.0; 3]; NUM_LEGS],
            feet: [[0.0; 3]; NUM_LEGS],
        }
    }

    fn run_damping(&mut self, sense: &Sense) -> Actuation {
        self.contacts = [false; NUM_LEGS];
        let mut torques = [0.0; NUM_JOINTS];
        for leg in Leg::ALL {
            let mass = self.model.mass_matrix(leg, sense.q[leg.index()]);
            for j in 0..3 {
                let (_, kd) = self.held_gains(0.0, self.config.damping_kd, mass[(j, j)]);
                torques[3 * leg.index() + j] = -kd * sense.dq[leg.index()][j];
            }
        }
        Actuation {
            torques,
            contacts: [false; NUM_LEGS],
            forces: [[0.0; 3]; NUM_LEGS],
            feet: sense.feet_world.map(|f| [f.x, f.y, f.z]),
        }
    }

    /// Joint-space interpolation to the standing pose with a growing weight feed-forward.
    fn run_stand_up(&mut self, sense: &Sense) -> Actuation {
        let s = smoothstep(self.state_time / self.config.stand_up_duration);
        let weight_share = self.model.total_mass() * GRAVITY / NUM_LEGS as f64 * s;
        let mut torques = [0.0; NUM_JOINTS];
        let mut forces = [[0.0; 3]; NUM_LEGS];
        for leg in Leg::ALL {
            let l = leg.index();
            let ground_force = Vector3::new(0.0, 0.0, weight_share);
            let foot_force_body = sense.rotation.transpose() * (-ground_force);
            let jac = Matrix3::from(self.model.foot_jacobian_body(leg, sense.q[l])).transpose();
            let feed_forward = jac.transpose() * foot_force_body;
            let mass = self.model.mass_matrix(leg, sense.q[l]);
            for j in 0..3 {
                let i = 3 * l + j;
                let q_ref = self.stand_up_start[i]
                    + (self.stand_joint_positions[i] - self.stand_up_start[i]) * s;
                let (kp, kd) = self.held_gains(
                    self.config.kp_stand[j],
                    self.config.kd_stand[j],
                    mass[(j, j)],
                );
                torques[i] = kp * (q_ref - sense.q[l][j]) - kd * sense.dq[l][j] + feed_forward[j];
            }
            forces[l] = [0.0, 0.0, weight_share];
        }
        self.contacts = [true; NUM_LEGS];
        Actuation {
            torques,
            contacts: [true; NUM_LEGS],
            forces,
            feet: sense.feet_world.map(|f| [f.x, f.y, f.z]),
        }
    }

    fn run_stand(&mut self, sense: &Sense, reference: &Reference) -> Actuation {
        let contacts = [true; NUM_LEGS];
        self.contacts = contacts;
        for k in 0..self.config.mpc_horizon {
            self.mpc_schedule[k] = contacts;
        }
        let target = self.hold;
        self.update_forces(sense, reference, &target, contacts, |_, leg, _| {
            sense.feet_world[leg.index()]
        });
        let mut torques = [0.0; NUM_JOINTS];
        for leg in Leg::ALL {
            self.stance_torques(sense, leg, &mut torques);
        }
        Actuation {
            torques,
            contacts,
            forces: self.forces,
            feet: sense.feet_world.map(|f| [f.x, f.y, f.z]),
        }
    }

    fn run_locomotion(&mut self, sense: &Sense, reference: &Reference, dt: f64) -> Actuation {
        let t = self.gait_time;
        let contacts = self.gait.contacts(t);
        for leg in Leg::ALL {
            let l = leg.index();
            if self.contacts[l] && !contacts[l] {
                self.swing_start[l] = sense.feet_world[l];
            } else if !self.contacts[l] && contacts[l] {
                self.stance_anchor[l] = sense.feet_world[l];
            }
        }
        self.contacts = contacts;
        let target = MotionTarget {
            xy: [reference.x, reference.y],
            yaw: reference.yaw,
            velocity: [reference.vx, reference.vy],
            yaw_rate: reference.yaw_rate,
        };
        // Touchdown targets of the legs in swing (Raibert heuristic, recomputed every tick).
        for leg in Leg::ALL {
            if let LegPhase::Swing(s) = self.gait.phase(leg, t) {
                let remaining = (1.0 - s) * self.gait.swing_time();
                self.footholds[leg.index()] =
                    self.raibert_foothold(sense, reference, &target, leg, remaining);
            }
        }
        for k in 0..self.config.mpc_horizon {
            self.mpc_schedule[k] = self.gait.contacts(t + k as f64 * self.config.mpc_dt);
        }
        self.update_forces(sense, reference, &target, contacts, |c, leg, k| {
            c.planned_foot(sense, reference, &target, leg, k)
        });

        let mut torques = [0.0; NUM_JOINTS];
        let mut feet = [[0.0; 3]; NUM_LEGS];
        for leg in Leg::ALL {
            let l = leg.index();
            match self.gait.phase(leg, t) {
                LegPhase::Stance(_) => {
                    self.stance_torques(sense, leg, &mut torques);
                    let a = self.stance_anchor[l];
                    feet[l] = [a.x, a.y, a.z];
                }
                LegPhase::Swing(s) => {
                    let start = self.swing_start[l];
                    let end = self.footholds[l];
                    let sample = swing_trajectory(
                        [start.x, start.y, start.z],
                        [end.x, end.y, end.z],
                        self.swing_apex(reference, &start, &end),
                        self.gait.swing_time(),
                        s,
                    );
                    self.swing_torques(sense, leg, &sample, &mut torques);
                    feet[l] = sample.position;
                }
            }
        }
        self.gait_time += dt;
        Actuation {
            torques,
            contacts,
            forces: self.forces,
            feet,
        }
    }

    // ---------------------------------------------------------------------------------------
    // Footholds and MPC.
    // ---------------------------------------------------------------------------------------

    /// Raibert foothold with velocity feedback and the centrifugal term, at terrain height:
    /// `p = p_hip(t_td) + v T_st/2 + k (v − v_ref) + (z/2g) v × ω_ref`.
    fn raibert_foothold(
        &self,
        sense: &Sense,
        reference: &Reference,
        target: &MotionTarget,
        leg: Leg,
        time_to_touchdown: f64,
    ) -> Vector3<f64> {
        let stance_time = self.gait.stance_time();
        let yaw = sense.rpy.z + target.yaw_rate * (time_to_touchdown + 0.5 * stance_time);
        let hip = rot_z(yaw) * self.nominal_feet_body[leg.index()];
        let v = sense.velocity;
        let v_ref = Vector3::new(target.velocity[0], target.velocity[1], 0.0);
        let base_at_touchdown = sense.position + v_ref * time_to_touchdown;
        let height = self.body_height(reference);
        let centrifugal = height / (2.0 * GRAVITY);
        let mut offset = v * (0.5 * stance_time) + (v - v_ref) * self.config.raibert_gain;
        offset.x += centrifugal * v.y * target.yaw_rate;
        offset.y -= centrifugal * v.x * target.yaw_rate;
        let limit = 0.15;
        offset.x = offset.x.clamp(-limit, limit);
        offset.y = offset.y.clamp(-limit, limit);
        let x = base_at_touchdown.x + hip.x + offset.x;
        let y = base_at_touchdown.y + hip.y + offset.y;
        self.select_foothold(reference, x, y)
    }

    /// Terrain height at (x, y): the height map where it covers the point, else the plane.
    fn ground(&self, reference: &Reference, x: f64, y: f64) -> f64 {
        self.height_map
            .height(x, y)
            .unwrap_or_else(|| terrain_height(reference, x, y))
    }

    /// Cost of a foothold candidate at (cx, cy), `ring` metres from the nominal foothold:
    /// `ring + EDGE_WEIGHT·edge + STEEP_WEIGHT·(edge/EDGE_PROBE − STEEP_SLOPE)⁺`, where `edge` is
    /// the largest height change within `EDGE_PROBE` (8 directions). `None` when a probe leaves
    /// the map, or as soon as the cost reaches `reject_at`: the cost only grows with `edge`, so
    /// the remaining probes cannot make the candidate win.
    fn foothold_cost(&self, ring: f64, cx: f64, cy: f64, reject_at: f64) -> Option<f64> {
        let map = &self.height_map;
        let cost_of = |edge: f64| {
            let steep = (edge / EDGE_PROBE - STEEP_SLOPE).max(0.0);
            ring + EDGE_WEIGHT * edge + STEEP_WEIGHT * steep
        };
        let centre = map.height(cx, cy)?;
        let mut edge: f64 = 0.0;
        for (dx, dy) in EDGE_PROBES {
            edge = edge.max((map.height(cx + dx, cy + dy)? - centre).abs());
            if cost_of(edge) >= reject_at {
                return None;
            }
        }
        Some(cost_of(edge))
    }

    /// Foot (sphere centre) target near the nominal foothold (x, y): with a height map, the
    /// candidate within `FOOTHOLD_SEARCH_RADIUS` minimising displacement + `EDGE_WEIGHT`·edge +
    /// `STEEP_WEIGHT`·(slope − `STEEP_SLOPE`)⁺
    /// (rings of `FOOTHOLD_RINGS` candidates; ties keep the earlier, nearer one), at the map's
    /// height; without one, (x, y) at the plane's height.
    ///
    /// The search runs ring by ring and stops at the first ring whose displacement alone
    /// already costs as much as the best candidate (on even ground: after the first one); this
    /// is what keeps the search cheap enough for every tick and every MPC horizon step.
    fn select_foothold(&self, reference: &Reference, x: f64, y: f64) -> Vector3<f64> {
        let radius = self.model.foot_radius();
        let mut best: Option<(f64, f64, f64)> = None;
        if self.height_map.is_present() {
            for candidate in &self.foothold_candidates {
                // A candidate replaces the best only when cheaper by more than 1e-9.
                let reject_at = best.map_or(f64::INFINITY, |(c, _, _)| c - 1e-9);
                if candidate.ring >= reject_at {
                    break; // rings only grow from here on
                }
                let (cx, cy) = (x + candidate.dx, y + candidate.dy);
                if let Some(cost) = self.foothold_cost(candidate.ring, cx, cy, reject_at) {
                    best = Some((cost, cx, cy));
                }
            }
        }
        let (fx, fy) = best.map_or((x, y), |(_, bx, by)| (bx, by));
        Vector3::new(fx, fy, self.ground(reference, fx, fy) + radius)
    }

    /// Swing apex height (above the straight lift-off → touchdown line) that keeps the foot
    /// `SWING_TERRAIN_MARGIN` above the terrain along the way: at least `swing_height`, at most
    /// `MAX_SWING_HEIGHT`.
    fn swing_apex(&self, reference: &Reference, start: &Vector3<f64>, end: &Vector3<f64>) -> f64 {
        let nominal = self.config.swing_height;
        if !self.height_map.is_present() {
            return nominal;
        }
        // The bump is 64·h·u³ (u = s(1 − s)): ask for `SWING_TERRAIN_MARGIN` of it above the
        // terrain's rise over the lift-off → touchdown line, on the middle of the swing only (at
        // the ends the foot is on the ground by construction).
        let radius = self.model.foot_radius();
        let mut apex = nominal;
        for i in 2..=8 {
            let s = 0.1 * i as f64;
            let blend = 3.0 * s * s - 2.0 * s * s * s;
            let p = start + (end - start) * blend;
            let rise = self.ground(reference, p.x, p.y) + radius - p.z;
            if rise > 0.0 {
                let u = s * (1.0 - s);
                let shape = 64.0 * u * u * u;
                apex = apex.max(SWING_TERRAIN_MARGIN + rise / shape);
            }
        }
        apex.min(MAX_SWING_HEIGHT.max(nominal))
    }

    /// Ground height, pitch and xy shift reference for a base at (x, y) facing `yaw`: the mean
    /// terrain height, the front/rear slope and the mean displacement of the (edge-avoiding)
    /// nominal footholds under the hips with a height map; the plane and no shift otherwise.
    fn stance_ground(&self, reference: &Reference, x: f64, y: f64, yaw: f64) -> StanceGround {
        let plane_pitch = self.terrain_pitch(reference, yaw);
        if !self.height_map.is_present() {
            return StanceGround {
                height: terrain_height(reference, x, y),
                pitch: plane_pitch,
                shift: [0.0; 2],
            };
        }
        let rotation = rot_z(yaw);
        let mut heights = [0.0; NUM_LEGS];
        let mut shift = [0.0; 2];
        for leg in Leg::ALL {
            let hip = rotation * self.nominal_feet_body[leg.index()];
            let foot = self.select_foothold(reference, x + hip.x, y + hip.y);
            heights[leg.index()] = foot.z - self.model.foot_radius();
            shift[0] += (foot.x - x - hip.x) / NUM_LEGS as f64;
            shift[1] += (foot.y - y - hip.y) / NUM_LEGS as f64;
        }
        let mean = heights.iter().sum::<f64>() / NUM_LEGS as f64;
        let front = 0.5 * (heights[Leg::FR.index()] + heights[Leg::FL.index()]);
        let rear = 0.5 * (heights[Leg::RR.index()] + heights[Leg::RL.index()]);
        let length =
            self.nominal_feet_body[Leg::FR.index()].x - self.nominal_feet_body[Leg::RR.index()].x;
        let limit = self.config.max_terrain_pitch;
        let pitch = if length > 1e-6 {
            (-((front - rear) / length).atan()).clamp(-limit, limit)
        } else {
            plane_pitch
        };
        StanceGround {
            height: mean,
            pitch,
            shift,
        }
    }

    fn body_height(&self, reference: &Reference) -> f64 {
        if reference.body_height > 0.0 {
            reference.body_height
        } else {
            self.config.body_height
        }
    }

    fn terrain_pitch(&self, reference: &Reference, yaw: f64) -> f64 {
        let slope = reference.terrain.slope_x * yaw.cos() + reference.terrain.slope_y * yaw.sin();
        let limit = self.config.max_terrain_pitch;
        (-slope.atan()).clamp(-limit, limit)
    }

    /// Re-solve the MPC when due (every `mpc_every_ticks` ticks or on a contact change) and
    /// refresh `self.forces`; `foot_at(self, leg, k)` gives the world foot position of a stance
    /// leg at horizon step k.
    fn update_forces(
        &mut self,
        sense: &Sense,
        reference: &Reference,
        target: &MotionTarget,
        contacts: [bool; NUM_LEGS],
        foot_at: impl Fn(&Self, Leg, usize) -> Vector3<f64>,
    ) {
        let due = self.ticks_since_mpc >= self.config.mpc_every_ticks.saturating_sub(1)
            || contacts != self.mpc_contacts;
        if !due {
            self.ticks_since_mpc += 1;
            self.zero_swing_forces(contacts);
            return;
        }
        self.ticks_since_mpc = 0;
        self.mpc_contacts = contacts;
        let n = self.config.mpc_horizon;
        let dt = self.config.mpc_dt;
        let height = self.body_height(reference);
        let com_now = sense.position + sense.rotation * self.com_offset_body;
        let yaw_now = target.yaw + wrap_angle(sense.rpy.z - target.yaw);
        let x0 = {
            let v_com = sense.velocity
                + sense
                    .angular_velocity
                    .cross(&(sense.rotation * self.com_offset_body));
            let w = sense.angular_velocity;
            [
                sense.rpy.x,
                sense.rpy.y,
                yaw_now,
                com_now.x,
                com_now.y,
                com_now.z,
                w.x,
                w.y,
                w.z,
                v_com.x,
                v_com.y,
                v_com.z,
                GRAVITY,
            ]
        };
        // Keep the start of the reference within reach so a large error cannot saturate the QP.
        let mut start = Vector3::new(target.xy[0], target.xy[1], 0.0);
        let base_xy = Vector3::new(sense.position.x, sense.position.y, 0.0);
        let error = start - base_xy;
        let max_error = 0.25;
        if error.norm() > max_error {
            start = base_xy + error * (max_error / error.norm());
        }
        // Beside a wall or a rim the footholds of one side move inwards; the base follows its
        // feet by their mean displacement so that the support stays balanced about the CoM.
        let shift = self
            .stance_ground(reference, start.x, start.y, target.yaw)
            .shift;
        let mut shift = Vector3::new(shift[0], shift[1], 0.0) * BODY_SHIFT_GAIN;
        if shift.norm() > MAX_BODY_SHIFT {
            shift *= MAX_BODY_SHIFT / shift.norm();
        }
        start += shift;
        let velocity0 = Vector3::new(target.velocity[0], target.velocity[1], 0.0);
        let mut base_xy_k = start;
        for k in 0..n {
            let tk = (k + 1) as f64 * dt;
            let yaw_k = target.yaw + target.yaw_rate * tk;
            let velocity_k = rot_z(target.yaw_rate * tk) * velocity0;
            base_xy_k += velocity_k * dt;
            let StanceGround {
                height: ground,
                pitch,
                ..
            } = self.stance_ground(reference, base_xy_k.x, base_xy_k.y, yaw_k);
            let com_k = Vector3::new(base_xy_k.x, base_xy_k.y, ground + height)
                + rot_z(yaw_k) * self.com_offset_body;
            let vz =
                reference.terrain.slope_x * velocity_k.x + reference.terrain.slope_y * velocity_k.y;
            self.mpc_reference[k] = [
                0.0,
                pitch,
                yaw_k,
                com_k.x,
                com_k.y,
                com_k.z,
                0.0,
                0.0,
                target.yaw_rate,
                velocity_k.x,
                velocity_k.y,
                vz,
                GRAVITY,
            ];
        }
        for k in 0..n {
            let com_k = if k == 0 {
                com_now
            } else {
                let r = &self.mpc_reference[k - 1];
                Vector3::new(r[3], r[4], r[5])
            };
            for leg in Leg::ALL {
                let l = leg.index();
                self.mpc_offsets[k][l] = if self.mpc_schedule[k][l] {
                    let foot = foot_at(self, leg, k);
                    let r = foot - com_k;
                    [r.x, r.y, r.z]
                } else {
                    [0.0; 3]
                };
            }
        }
        let normal = self.friction_normal(reference, sense, contacts);
        let input = MpcInput {
            x0,
            reference: &self.mpc_reference,
            contacts: &self.mpc_schedule,
            foot_offsets: &self.mpc_offsets,
            terrain_normal: [normal.x, normal.y, normal.z],
        };
        let solution = self.mpc.solve(&input);
        self.mpc_solve_time_s = solution.solve_time_s;
        if solution.status == MpcStatus::Solved {
            self.forces = solution.forces;
            self.mpc_solved = true;
        } else {
            tracing::warn!(status = ?solution.status, "MPC failed: static weight distribution");
            self.mpc_solved = false;
            let stance = contacts.iter().filter(|c| **c).count().max(1) as f64;
            let share = self.model.total_mass() * GRAVITY / stance;
            self.forces = [[0.0, 0.0, share]; NUM_LEGS];
        }
        self.zero_swing_forces(contacts);
    }

    /// Normal of the MPC's friction pyramids: with a height map, the mean of the local terrain
    /// normals under the stance feet (a plane fitted around the base tilts by tens of degrees
    /// beside a valley side or a wall while the feet stand on flat ground), else the plane's.
    fn friction_normal(
        &self,
        reference: &Reference,
        sense: &Sense,
        contacts: [bool; NUM_LEGS],
    ) -> Vector3<f64> {
        let map = &self.height_map;
        let d = EDGE_PROBE;
        let mut sum = Vector3::zeros();
        for leg in Leg::ALL {
            let l = leg.index();
            if !contacts[l] {
                continue;
            }
            let p = sense.feet_world[l];
            let samples = (
                map.height(p.x + d, p.y),
                map.height(p.x - d, p.y),
                map.height(p.x, p.y + d),
                map.height(p.x, p.y - d),
            );
            if let (Some(xp), Some(xm), Some(yp), Some(ym)) = samples {
                sum +=
                    Vector3::new(-(xp - xm) / (2.0 * d), -(yp - ym) / (2.0 * d), 1.0).normalize();
            }
        }
        if sum.norm() > 1e-9 {
            sum.normalize()
        } else {
            terrain_normal(reference)
        }
    }

    fn zero_swing_forces(&mut self, contacts: [bool; NUM_LEGS]) {
        for (force, stance) in self.forces.iter_mut().zip(contacts) {
            if !stance {
                *force = [0.0; 3];
            }
        }
    }

    /// Foot of a leg at horizon step k: its current position in the current stance, its
    /// touchdown target for the stance after the current swing, a nominal foothold afterwards.
    fn planned_foot(
        &self,
        sense: &Sense,
        reference: &Reference,
        target: &MotionTarget,
        leg: Leg,
        k: usize,
    ) -> Vector3<f64> {
        let l = leg.index();
        let mut liftoffs = 0;
        let mut previous = self.contacts[l];
        for step in 1..=k {
            let stance = self.mpc_schedule[step][l];
            if previous && !stance {
                liftoffs += 1;
            }
            previous = stance;
        }
        if liftoffs == 0 {
            if self.contacts[l] {
                sense.feet_world[l]
            } else {
                self.footholds[l]
            }
        } else {
            let tk = k as f64 * self.config.mpc_dt;
            self.raibert_foothold(sense, reference, target, leg, tk)
        }
    }

    // ---------------------------------------------------------------------------------------
    // Leg control.
    // ---------------------------------------------------------------------------------------

    /// Stance: `τ = Jᵀ Rᵀ (−f) + h(q, q̇)`.
    fn stance_torques(&self, sense: &Sense, leg: Leg, torques: &mut [f64; NUM_JOINTS]) {
        let l = leg.index();
        let f = Vector3::from(self.forces[l]);
        let foot_force_body = sense.rotation.transpose() * (-f);
        let jac = Matrix3::from(self.model.foot_jacobian_body(leg, sense.q[l])).transpose();
        let tau = jac.transpose() * foot_force_body;
        let bias = self
            .model
            .leg_bias(leg, sense.q[l], sense.dq[l], sense.gravity_body);
        for j in 0..3 {
            torques[3 * l + j] = tau[j] + bias[j];
        }
    }

    /// Swing: `τ = M q̈_ref + h + K_p (q_ref − q) + K_d (q̇_ref − q̇)` along the swing trajectory.
    fn swing_torques(
        &self,
        sense: &Sense,
        leg: Leg,
        sample: &crate::gait::SwingSample,
        torques: &mut [f64; NUM_JOINTS],
    ) {
        let l = leg.index();
        let rt = sense.rotation.transpose();
        let relative = Vector3::from(sample.position) - sense.position;
        let p_body = rt * relative;
        let omega_body = rt * sense.angular_velocity;
        let v_body =
            rt * (Vector3::from(sample.velocity) - sense.velocity) - omega_body.cross(&p_body);
        let a_body = rt * Vector3::from(sample.acceleration);
        let q_ref = self.reachable_ik(leg, p_body, sense.q[l]);
        let jac_ref = Matrix3::from(self.model.foot_jacobian_body(leg, q_ref)).transpose();
        let (dq_ref, ddq_ref) = match jac_ref.try_inverse() {
            Some(inverse) => {
                let dq_ref = inverse * v_body;
                let eps = 1e-6;
                let q_ahead = [
                    q_ref[0] + eps * dq_ref[0],
                    q_ref[1] + eps * dq_ref[1],
                    q_ref[2] + eps * dq_ref[2],
                ];
                let jac_ahead =
                    Matrix3::from(self.model.foot_jacobian_body(leg, q_ahead)).transpose();
                let jdot_qdot = (jac_ahead - jac_ref) * dq_ref / eps;
                (dq_ref, inverse * (a_body - jdot_qdot))
            }
            None => (Vector3::zeros(), Vector3::zeros()),
        };
        let mass = self.model.mass_matrix(leg, sense.q[l]);
        let bias = self
            .model
            .leg_bias(leg, sense.q[l], sense.dq[l], sense.gravity_body);
        let inertial = mass * ddq_ref;
        for j in 0..3 {
            let (kp, kd) = self.held_gains(
                self.config.kp_swing[j],
                self.config.kd_swing[j],
                mass[(j, j)],
            );
            torques[3 * l + j] = inertial[j]
                + bias[j]
                + kp * (q_ref[j] - sense.q[l][j])
                + kd * (dq_ref[j] - sense.dq[l][j]);
        }
    }

    /// IK of a swing target, pulled towards the hip until reachable and clamped to the joint
    /// limits; falls back to the current joint angles.
    fn reachable_ik(&self, leg: Leg, p_body: Vector3<f64>, current: [f64; 3]) -> [f64; 3] {
        let hip = Vector3::from(self.model.hip_position_body(leg));
        let mut q = current;
        for scale in [1.0, 0.95, 0.9, 0.8, 0.7] {
            let target = hip + (p_body - hip) * scale;
            if let Some(solution) = self
                .model
                .try_inverse_kinematics(leg, [target.x, target.y, target.z])
            {
                q = solution;
                break;
            }
        }
        let base = 3 * leg.index();
        for (j, angle) in q.iter_mut().enumerate() {
            *angle = angle.clamp(self.lower_limits[base + j], self.upper_limits[base + j]);
        }
        q
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::{HEIGHT_MAP_CELLS, HEIGHT_MAP_SIZE};

    /// The pruned foothold search returns bit for bit what evaluating every candidate returns.
    #[test]
    fn pruned_foothold_search_equals_the_exhaustive_search() {
        let urdf = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robot/quadruped.urdf");
        let model = RobotModel::from_urdf_file(&urdf).expect("URDF");
        let mut controller =
            Controller::new(model, ControllerConfig::default()).expect("controller");
        let reference = Reference::default();
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        let mut uniform = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let exhaustive = |c: &Controller, x: f64, y: f64| {
            let mut best: Option<(f64, f64, f64)> = None;
            for k in &c.foothold_candidates {
                let (cx, cy) = (x + k.dx, y + k.dy);
                if let Some(cost) = c.foothold_cost(k.ring, cx, cy, f64::INFINITY) {
                    if best.map_or(true, |(b, _, _)| cost < b - 1e-9) {
                        best = Some((cost, cx, cy));
                    }
                }
            }
            let (fx, fy) = best.map_or((x, y), |(_, bx, by)| (bx, by));
            [fx, fy]
        };
        for map_index in 0..40 {
            // Flat, stepped (walls and pits) and rough maps.
            let mut map = HeightMap {
                origin: [-0.5, -0.5],
                spacing: 0.1,
                heights: [0.0; HEIGHT_MAP_CELLS],
            };
            for iy in 0..HEIGHT_MAP_SIZE {
                for ix in 0..HEIGHT_MAP_SIZE {
                    map.heights[iy * HEIGHT_MAP_SIZE + ix] = match map_index % 4 {
                        0 => 0.0,
                        1 => (if ix > 5 { 0.3 } else { 0.0 }) + 0.01 * uniform(),
                        2 => {
                            if (ix + iy) % 5 == 0 {
                                -0.2
                            } else {
                                0.0
                            }
                        }
                        _ => 0.15 * uniform(),
                    };
                }
            }
            controller.set_height_map(&map).expect("valid map");
            for _ in 0..50 {
                let x = -0.6 + 1.2 * uniform();
                let y = -0.6 + 1.2 * uniform();
                let pruned = controller.select_foothold(&reference, x, y);
                let full = exhaustive(&controller, x, y);
                assert_eq!(
                    [pruned.x.to_bits(), pruned.y.to_bits()],
                    [full[0].to_bits(), full[1].to_bits()],
                    "map {map_index} at ({x}, {y})"
                );
            }
        }
    }
}
