//! The controller's tuning, [`ControllerConfig`], declared once: every field is written down a
//! single time below (name, type, default, accepted range, unit, description, FMU parameter
//! name), and [`controller_config!`] generates from that the struct (JSON field names = Rust
//! names, unknown fields rejected), `Default`, [`ControllerConfig::check_ranges`] and the field
//! table [`ControllerConfig::FIELDS`] the FMU makes its parameters from.
//!
//! The ranges are the named envelopes of [`crate::limits`].

use std::ops::RangeInclusive;

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::api::{EstimatorKind, GaitKind};
use crate::limits;

/// The value of one element of a configuration field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FieldValue {
    /// A real number (`f64` fields and the elements of `[f64; N]` fields).
    Real(f64),
    /// A count (`usize` fields).
    Count(usize),
    /// A gait.
    Gait(GaitKind),
    /// An estimator.
    Estimator(EstimatorKind),
}

impl FieldValue {
    /// The value as a number, for range checks: counts exactly (they are small), gaits as their
    /// code.
    pub fn as_f64(self) -> f64 {
        match self {
            FieldValue::Real(v) => v,
            // Counts beyond 2^53 lose precision but stay far outside every range.
            FieldValue::Count(n) => n as f64,
            FieldValue::Gait(g) => f64::from(g.as_code()),
            FieldValue::Estimator(e) => f64::from(e.as_code()),
        }
    }
}

/// What the elements of a field are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldKind {
    /// `f64`.
    Real,
    /// `usize`.
    Count,
    /// [`GaitKind`].
    Gait,
    /// [`EstimatorKind`].
    Estimator,
}

/// A type a configuration field may have: how its elements are read, written and bounded.
pub trait FieldType {
    /// How the accepted range is written in the declaration.
    type Range;
    /// Kind of the elements.
    const KIND: FieldKind;
    /// Number of elements (1 for a scalar).
    const LEN: usize;
    /// Whether the field is an array (one FMU parameter per element).
    const IS_ARRAY: bool;
    /// Element `i` (`i < LEN`).
    fn element(&self, i: usize) -> FieldValue;
    /// Writes element `i`; false (nothing written) when `value` is of another kind.
    fn set_element(&mut self, i: usize, value: FieldValue) -> bool;
    /// The inclusive range as `(min, max)` numbers.
    fn bounds(range: &Self::Range) -> (f64, f64);
}

impl FieldType for f64 {
    type Range = RangeInclusive<f64>;
    const KIND: FieldKind = FieldKind::Real;
    const LEN: usize = 1;
    const IS_ARRAY: bool = false;
    fn element(&self, _: usize) -> FieldValue {
        FieldValue::Real(*self)
    }
    fn set_element(&mut self, _: usize, value: FieldValue) -> bool {
        let FieldValue::Real(v) = value else {
            return false;
        };
        *self = v;
        true
    }
    fn bounds(range: &Self::Range) -> (f64, f64) {
        (*range.start(), *range.end())
    }
}

impl FieldType for usize {
    type Range = RangeInclusive<usize>;
    const KIND: FieldKind = FieldKind::Count;
    const LEN: usize = 1;
    const IS_ARRAY: bool = false;
    fn element(&self, _: usize) -> FieldValue {
        FieldValue::Count(*self)
    }
    fn set_element(&mut self, _: usize, value: FieldValue) -> bool {
        let FieldValue::Count(v) = value else {
            return false;
        };
        *self = v;
        true
    }
    fn bounds(range: &Self::Range) -> (f64, f64) {
        (
            FieldValue::Count(*range.start()).as_f64(),
            FieldValue::Count(*range.end()).as_f64(),
        )
    }
}

impl FieldType for GaitKind {
    /// The gaits accepted: all of [`GaitKind::ALL`].
    type Range = [(GaitKind, &'static str, &'static str); 2];
    const KIND: FieldKind = FieldKind::Gait;
    const LEN: usize = 1;
    const IS_ARRAY: bool = false;
    fn element(&self, _: usize) -> FieldValue {
        FieldValue::Gait(*self)
    }
    fn set_element(&mut self, _: usize, value: FieldValue) -> bool {
        let FieldValue::Gait(v) = value else {
            return false;
        };
        *self = v;
        true
    }
    fn bounds(range: &Self::Range) -> (f64, f64) {
        let codes = range.iter().map(|&(g, ..)| g.as_code());
        let min = codes.clone().min().unwrap_or(0);
        let max = codes.max().unwrap_or(0);
        (f64::from(min), f64::from(max))
    }
}

impl FieldType for EstimatorKind {
    /// The estimators accepted: all of [`EstimatorKind::ALL`].
    type Range = [(EstimatorKind, &'static str, &'static str); 2];
    const KIND: FieldKind = FieldKind::Estimator;
    const LEN: usize = 1;
    const IS_ARRAY: bool = false;
    fn element(&self, _: usize) -> FieldValue {
        FieldValue::Estimator(*self)
    }
    fn set_element(&mut self, _: usize, value: FieldValue) -> bool {
        let FieldValue::Estimator(v) = value else {
            return false;
        };
        *self = v;
        true
    }
    fn bounds(range: &Self::Range) -> (f64, f64) {
        let codes = range.iter().map(|&(e, ..)| e.as_code());
        let min = codes.clone().min().unwrap_or(0);
        let max = codes.max().unwrap_or(0);
        (f64::from(min), f64::from(max))
    }
}

impl<const N: usize> FieldType for [f64; N] {
    /// The range of every element.
    type Range = RangeInclusive<f64>;
    const KIND: FieldKind = FieldKind::Real;
    const LEN: usize = N;
    const IS_ARRAY: bool = true;
    fn element(&self, i: usize) -> FieldValue {
        FieldValue::Real(self[i])
    }
    fn set_element(&mut self, i: usize, value: FieldValue) -> bool {
        let FieldValue::Real(v) = value else {
            return false;
        };
        self[i] = v;
        true
    }
    fn bounds(range: &Self::Range) -> (f64, f64) {
        (*range.start(), *range.end())
    }
}

/// One row of [`ControllerConfig::FIELDS`]: everything declared about a field, and access to it.
#[derive(Clone, Copy, Debug)]
pub struct ConfigField {
    /// Rust and JSON name, e.g. `mpc_q`.
    pub name: &'static str,
    /// FMU parameter name, e.g. `mpc.q` (arrays: `mpc.q[1]` … `mpc.q[13]`).
    pub fmi_name: &'static str,
    /// Kind of the elements.
    pub kind: FieldKind,
    /// Number of elements (1 for a scalar).
    pub len: usize,
    /// Whether the field is an array.
    pub is_array: bool,
    /// Unit in FMI notation (`s`, `N.m/rad`, …), `None` when dimensionless.
    pub unit: Option<&'static str>,
    /// Description; for arrays `{}` stands for the element label.
    pub description: &'static str,
    /// Labels of the elements of an array (empty for scalars).
    pub labels: &'static [&'static str],
    /// How the default and the range carry over to a robot of another size.
    pub scaling: Scaling,
    range: fn() -> (f64, f64),
    get: fn(&ControllerConfig, usize) -> FieldValue,
    set: fn(&mut ControllerConfig, usize, FieldValue) -> bool,
}

impl ConfigField {
    /// The inclusive range `(min, max)` of every element, for the tuned robot.
    pub fn range(&self) -> (f64, f64) {
        (self.range)()
    }

    /// The range for a robot of `scale`: the tuned robot's, widened to hold it scaled by the
    /// field's factor (never narrowed: what suits the tuned robot stays accepted).
    pub fn range_for(&self, scale: RobotScale) -> (f64, f64) {
        let (min, max) = self.range();
        let factor = scale.factor(self.scaling);
        if !(factor.is_finite() && factor > 0.0) {
            return (min, max);
        }
        (min.min(min * factor), max.max(max * factor))
    }

    /// Element `i` of this field of `config` (`i < len`).
    pub fn get(&self, config: &ControllerConfig, i: usize) -> FieldValue {
        (self.get)(config, i)
    }

    /// Writes element `i` (not range-checked); false when `value` is of another kind.
    pub fn set(&self, config: &mut ControllerConfig, i: usize, value: FieldValue) -> bool {
        (self.set)(config, i, value)
    }

    /// Rust name of element `i`: `mpc_r`, `mpc_q[0]`.
    pub fn element_name(&self, i: usize) -> String {
        if self.is_array {
            format!("{}[{i}]", self.name)
        } else {
            self.name.to_owned()
        }
    }

    /// FMU parameter name of element `i` (1-based index, FMI structured naming): `mpc.r`,
    /// `mpc.q[1]`.
    pub fn fmi_element_name(&self, i: usize) -> String {
        if self.is_array {
            format!("{}[{}]", self.fmi_name, i + 1)
        } else {
            self.fmi_name.to_owned()
        }
    }

    /// Description of element `i`.
    pub fn element_description(&self, i: usize) -> String {
        match self.labels.get(i) {
            Some(label) => self.description.replacen("{}", label, 1),
            None => self.description.to_owned(),
        }
    }
}

/// A configuration value outside its declared range (or not a finite number).
#[derive(Clone, Debug, PartialEq, Error)]
#[error("{field} = {value} is outside [{min}, {max}]")]
pub struct ConfigError {
    /// The field (element) name, e.g. `mpc_q[2]`.
    pub field: String,
    /// The value.
    pub value: f64,
    /// Smallest accepted value.
    pub min: f64,
    /// Largest accepted value.
    pub max: f64,
}

/// How a field's value carries over to a robot of another size (Froude scaling of the tuned
/// robot): the default tuning of a robot ([`ControllerConfig::for_robot`]) is each default times
/// this factor, and the accepted range widens by the same factor, so a 90 kg robot's stance
/// gains are neither refused nor capped at the 12 kg robot's envelope.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scaling {
    /// Independent of the robot's size (weights of dimensionless errors, counts, angles).
    Fixed,
    /// A length: × length ratio.
    Length,
    /// A time: × √(length ratio).
    Time,
    /// A force: × mass ratio.
    Force,
    /// A joint stiffness or damping (torque per angle): × mass ratio × length ratio.
    Torque,
    /// The MPC's weight on squared forces: ÷ mass ratio².
    ForceWeight,
}

/// A robot's size relative to the one the default tuning was made on
/// ([`crate::tuning::TUNED_MASS`], [`crate::tuning::TUNED_STAND_HEIGHT`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobotScale {
    /// Total mass ÷ the tuned robot's.
    pub mass: f64,
    /// Stand height ÷ the tuned robot's.
    pub length: f64,
}

impl RobotScale {
    /// The tuned robot itself.
    pub const TUNED: RobotScale = RobotScale {
        mass: 1.0,
        length: 1.0,
    };

    /// The factor a value of `scaling` is multiplied by for this robot.
    pub fn factor(&self, scaling: Scaling) -> f64 {
        match scaling {
            Scaling::Fixed => 1.0,
            Scaling::Length => self.length,
            Scaling::Time => self.length.sqrt(),
            Scaling::Force => self.mass,
            Scaling::Torque => self.mass * self.length,
            Scaling::ForceWeight => 1.0 / (self.mass * self.mass),
        }
    }
}

/// Declares [`ControllerConfig`]; see the module documentation. Each field reads
/// `name: type = default, fmi "fmu.name", range RANGE, unit "unit" (or ""), "description"
/// [, labels LABELS];`.
macro_rules! controller_config {
    (
        $(#[$struct_meta:meta])*
        pub struct $config:ident {
            $(
                $(#[$field_meta:meta])*
                $field:ident: $ty:ty = $default:expr,
                    fmi $fmi:literal, range $range:expr, unit $unit:literal, $description:literal
                    $(, labels $labels:expr)? $(, scales $scaling:ident)?;
            )*
        }
    ) => {
        $(#[$struct_meta])*
        pub struct $config {
            $(
                $(#[$field_meta])*
                pub $field: $ty,
            )*
        }

        impl Default for $config {
            fn default() -> Self {
                $config {
                    $($field: $default,)*
                }
            }
        }

        impl $config {
            /// Every field, in declaration order (the order of the FMU's parameters).
            pub const FIELDS: &'static [ConfigField] = &[
                $(
                    ConfigField {
                        name: stringify!($field),
                        fmi_name: $fmi,
                        kind: <$ty as FieldType>::KIND,
                        len: <$ty as FieldType>::LEN,
                        is_array: <$ty as FieldType>::IS_ARRAY,
                        unit: if $unit.is_empty() { None } else { Some($unit) },
                        description: $description,
                        labels: controller_config!(@labels $($labels)?),
                        scaling: controller_config!(@scaling $($scaling)?),
                        range: || <$ty as FieldType>::bounds(&$range),
                        get: |config, i| FieldType::element(&config.$field, i),
                        set: |config, i, value| FieldType::set_element(&mut config.$field, i, value),
                    },
                )*
            ];
        }
    };
    (@labels) => { &[] };
    (@labels $labels:expr) => { $labels };
    (@scaling) => { Scaling::Fixed };
    (@scaling $scaling:ident) => { Scaling::$scaling };
}

/// Labels of the MPC state weights.
const MPC_STATE_LABELS: &[&str] = &[
    "roll",
    "pitch",
    "yaw",
    "x",
    "y",
    "z",
    "omega x",
    "omega y",
    "omega z",
    "vx",
    "vy",
    "vz",
    "gravity state",
];
/// Labels of the per-joint gains (the same for every leg).
const JOINT_LABELS: &[&str] = &crate::api::LEG_JOINT_NAMES;

controller_config! {
    /// Controller tuning. `Default` is the tuning used with the DART model of
    /// `robot/quadruped.urdf` at a 1 kHz control rate; JSON-(de)serialisable (the FMU ships it as
    /// `resources/controller.json`).
    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct ControllerConfig {
        /// Nominal leg control tick, s (the `dt` passed to `step` should match it).
        control_dt: f64 = 0.001,
            fmi "control.dt", range limits::CONTROL_DT, unit "s",
            "Leg control tick; a doStep runs round(h / control.dt) ticks";
        /// The MPC is solved on every k-th call of `step` (k ≥ 1); forces are held in between.
        mpc_every_ticks: usize = 10,
            fmi "mpc.everyTicks", range limits::MPC_EVERY_TICKS, unit "",
            "The MPC is solved every k-th control tick";
        /// MPC horizon length in prediction steps.
        mpc_horizon: usize = 10,
            fmi "mpc.horizon", range limits::MPC_HORIZON, unit "",
            "MPC horizon length in prediction steps";
        /// MPC prediction step, s (horizon covers `mpc_horizon · mpc_dt`).
        mpc_dt: f64 = 0.03,
            fmi "mpc.dt", range limits::MPC_DT, unit "s",
            "MPC prediction step";
        /// Gait used in the locomotion state.
        gait: GaitKind = GaitKind::Trot,
            fmi "gait.kind", range GaitKind::ALL, unit "",
            "Gait of the locomotion state";
        /// Gait cycle period, s.
        gait_period: f64 = 0.3,
            fmi "gait.period", range limits::GAIT_PERIOD, unit "s",
            "Gait cycle period", scales Time;
        /// Swing-foot apex height above the straight line between lift-off and touchdown, m.
        swing_height: f64 = 0.08,
            fmi "gait.swingHeight", range limits::SWING_HEIGHT, unit "m",
            "Swing-foot apex height", scales Length;
        /// Friction coefficient used by the MPC's friction pyramid. Below the ground's μ on purpose
        /// (a safety factor of 0.75 on the μ = 0.8 of issue 19's inclines): planned at the real μ
        /// the forces sit on the cone's edge, stance feet slip (2–18 cm per stance) and 20° down
        /// falls (docs/slopes.md, fix 4).
        mu: f64 = 0.6,
            fmi "mpc.mu", range limits::MU, unit "",
            "Friction coefficient of the MPC friction pyramid";
        /// Minimum normal force on a stance foot, N.
        f_min: f64 = 5.0,
            fmi "mpc.fMin", range limits::F_MIN, unit "N",
            "Minimum normal force on a stance foot", scales Force;
        /// Maximum normal force on a stance foot, N.
        f_max: f64 = 150.0,
            fmi "mpc.fMax", range limits::F_MAX, unit "N",
            "Maximum normal force on a stance foot", scales Force;
        /// Nominal standing height of the base above the terrain, m (used when the reference
        /// gives ≤ 0).
        body_height: f64 = crate::tuning::TUNED_STAND_HEIGHT,
            fmi "stand.bodyHeight", range limits::BODY_HEIGHT, unit "m",
            "Nominal standing height above the terrain (used when ref.bodyHeight <= 0)", scales Length;
        /// MPC state weights: roll, pitch, yaw, x, y, z, ωx, ωy, ωz, vx, vy, vz, gravity state.
        mpc_q: [f64; 13] = [10.0, 10.0, 5.0, 50.0, 50.0, 50.0, 0.05, 0.05, 0.3, 1.0, 1.0, 0.5, 0.0],
            fmi "mpc.q", range limits::MPC_Q, unit "",
            "MPC state weight: {}", labels MPC_STATE_LABELS;
        /// MPC force weight (same for every force component).
        mpc_r: f64 = 1e-5,
            fmi "mpc.r", range limits::MPC_R, unit "",
            "MPC force weight", scales ForceWeight;
        /// Swing-leg joint stiffness (abduction, hip, knee), N·m/rad.
        kp_swing: [f64; 3] = [60.0, 60.0, 60.0],
            fmi "swing.kp", range limits::JOINT_KP, unit "N.m/rad",
            "Swing-leg joint stiffness, {}", labels JOINT_LABELS, scales Torque;
        /// Swing-leg joint damping (abduction, hip, knee), N·m·s/rad.
        kd_swing: [f64; 3] = [2.0, 2.0, 2.0],
            fmi "swing.kd", range limits::JOINT_KD, unit "N.m.s/rad",
            "Swing-leg joint damping, {}", labels JOINT_LABELS, scales Torque;
        /// Joint stiffness used by the stand-up interpolation, N·m/rad.
        kp_stand: [f64; 3] = [80.0, 80.0, 80.0],
            fmi "stand.kp", range limits::JOINT_KP, unit "N.m/rad",
            "Stand-up joint stiffness, {}", labels JOINT_LABELS, scales Torque;
        /// Joint damping used by the stand-up interpolation, N·m·s/rad.
        kd_stand: [f64; 3] = [3.0, 3.0, 3.0],
            fmi "stand.kd", range limits::JOINT_KD, unit "N.m.s/rad",
            "Stand-up joint damping, {}", labels JOINT_LABELS, scales Torque;
        /// Duration of the stand-up motion, s.
        stand_up_duration: f64 = 1.0,
            fmi "stand.upDuration", range limits::STAND_UP_DURATION, unit "s",
            "Duration of the stand-up motion";
        /// Raibert foothold velocity-feedback gain k in p = p_hip + v·T_stance/2 + k (v − v_ref), s.
        raibert_gain: f64 = 0.03,
            fmi "gait.raibertGain", range limits::RAIBERT_GAIN, unit "s",
            "Raibert foothold velocity-feedback gain", scales Time;
        /// Tilt (angle between body z and world z) above which the FSM enters damping, rad.
        max_tilt: f64 = 0.9,
            fmi "safety.maxTilt", range limits::MAX_TILT, unit "rad",
            "Tilt above which the FSM enters damping";
        /// Joint position margin beyond the URDF limits tolerated before damping, rad.
        joint_limit_margin: f64 = 0.15,
            fmi "safety.jointLimitMargin", range limits::JOINT_LIMIT_MARGIN, unit "rad",
            "Joint position margin beyond the URDF limits before damping";
        /// Joint damping of the damping (safe) state, N·m·s/rad.
        damping_kd: f64 = 2.0,
            fmi "safety.dampingKd", range limits::JOINT_KD, unit "N.m.s/rad",
            "Joint damping of the damping state", scales Torque;
        /// Largest body pitch the terrain-following reference may ask for, rad.
        max_terrain_pitch: f64 = 0.35,
            fmi "terrain.maxPitch", range limits::MAX_TERRAIN_PITCH, unit "rad",
            "Largest body pitch the terrain-following reference may ask for";
        /// Which state the controller runs on (see `docs/estimation.md`).
        estimator: EstimatorKind = EstimatorKind::GroundTruth,
            fmi "estimator", range EstimatorKind::ALL, unit "",
            "State estimator: groundTruth (the base.* inputs) or kalman (IMU + leg kinematics; base.pos/base.quat read at the first tick only)";
        /// Gyro white-noise density (angle random walk), rad/s/√Hz.
        est_gyro_noise: f64 = 3e-4,
            fmi "est.gyroNoise", range limits::EST_GYRO_NOISE, unit "rad/s/sqrt(Hz)",
            "Gyro white-noise density (angle random walk) of the orientation filter";
        /// Gyro bias random-walk density, rad/s²/√Hz.
        est_gyro_bias_walk: f64 = 1e-4,
            fmi "est.gyroBiasWalk", range limits::EST_GYRO_BIAS_WALK, unit "rad/s2/sqrt(Hz)",
            "Gyro bias random-walk density of the orientation filter";
        /// Standard deviation of the accelerometer as a gravity-direction reference, m/s² (sensor
        /// noise plus the trunk's own accelerations while walking). Large on purpose: the trot's
        /// accelerations are several m/s² and average out only over many gait cycles, so the tilt
        /// correction must average over minutes, not seconds (with the default gyro noise its time
        /// constant is about 100 s at 1 kHz; see docs/estimation.md).
        est_acc_tilt_noise: f64 = 10.0,
            fmi "est.accTiltNoise", range limits::EST_ACC_TILT_NOISE, unit "m/s2",
            "Accelerometer noise as a gravity-direction (tilt) reference, walking accelerations included";
        /// Accelerometer noise density driving the Kalman filter's velocity, m/s²/√Hz (sensor
        /// noise plus vibration and the tilt error times g).
        est_acc_noise: f64 = 0.1,
            fmi "est.accNoise", range limits::EST_ACC_NOISE, unit "m/s2/sqrt(Hz)",
            "Accelerometer noise density, the velocity process noise of the Kalman filter";
        /// Standard deviation of a stance foot's position relative to the trunk from leg
        /// kinematics, m.
        est_leg_position_noise: f64 = 0.01,
            fmi "est.legPosNoise", range limits::EST_LEG_POSITION_NOISE, unit "m",
            "Leg-kinematics foot position noise (stance, per axis)";
        /// Standard deviation of a stance foot's velocity relative to the trunk from leg
        /// kinematics, m/s.
        est_leg_velocity_noise: f64 = 0.1,
            fmi "est.legVelNoise", range limits::EST_LEG_VELOCITY_NOISE, unit "m/s",
            "Leg-kinematics foot velocity noise (stance, per axis)";
        /// Random-walk density of a stance foot's world position (rolling foot, slip), m/√s.
        est_foot_drift: f64 = 0.02,
            fmi "est.footDrift", range limits::EST_FOOT_DRIFT, unit "m/sqrt(s)",
            "Process noise density of a stance foot's world position (rolling foot sphere, slip)";
        /// Position random walk per distance walked (each axis, height included), m/√m: legged
        /// odometry drifts with the distance (slip, kinematic errors, a residual tilt) by amounts
        /// the leg measurements cannot see, so the whole robot (trunk and feet together) is let
        /// wander by this much. It changes the reported position variance and the weight of
        /// position fixes, not the estimate.
        est_odometry_drift: f64 = 0.03,
            fmi "est.odometryDrift", range limits::EST_ODOMETRY_DRIFT, unit "m/sqrt(m)",
            "Position random walk per distance walked, each axis (the reported position variance grows with the distance)";
        /// Standard deviation of an absolute position fix, m.
        est_fix_noise: f64 = 0.02,
            fmi "est.fixNoise", range limits::EST_FIX_NOISE, unit "m",
            "Absolute position fix noise (per axis)";
        /// Factor on the leg-kinematics noise variances of a foot in swing (and, ramped, around
        /// touch-down and lift-off).
        est_swing_noise_factor: f64 = 100.0,
            fmi "est.swingNoiseFactor", range limits::EST_SWING_NOISE_FACTOR, unit "",
            "Factor on the leg-kinematics noise variances of a swing foot (ramped around touch-down)";
        /// How far a stance foot's sphere rolls, as a share of its radius: 1 = it rolls without
        /// slipping (rubber feet, the simulated body), so its centre moves at ω_foot × r·ẑ while
        /// the contact point stands still; 0 = the foot centre itself stands still (point feet).
        est_foot_rolling: f64 = 1.0,
            fmi "est.footRolling", range limits::EST_FOOT_ROLLING, unit "",
            "Share of the foot radius a stance foot rolls over (1 = rolls without slipping, 0 = point foot)";
        /// Gyro full-scale range, rad/s: a reading at or beyond it is saturated.
        est_gyro_limit: f64 = 34.9,
            fmi "est.gyroLimit", range limits::EST_GYRO_LIMIT, unit "rad/s",
            "Gyro full-scale range (34.9 rad/s = 2000 deg/s); readings at or beyond it are saturated";
        /// Friction kept above what holding the body on the ground's incline takes (tan of the
        /// slope under the stance feet). Where tan(slope) + this margin exceeds `mu` (23° with the
        /// defaults) the MPC plans with that coefficient instead, the body height shrinks with
        /// cos(slope) and the motion reference's accelerations are limited to half this margin of
        /// friction (`steep_ground.rs`): on a 30° plane a pyramid of μ 0.6 leaves 0.02 of friction
        /// for braking and turning, and the robot runs away downhill or falls (docs/slopes.md).
        /// Last in the table, so that the parameters before it keep their value references.
        mu_slope_margin: f64 = 0.17,
            fmi "mpc.muSlopeMargin", range limits::MU_SLOPE_MARGIN, unit "",
            "Friction kept above tan(slope) on steep ground: where tan(slope) + margin > mpc.mu the MPC plans with that coefficient, lowers the body by cos(slope)/cos(slope where they are equal) and limits the reference's accelerations to half the margin times g cos(slope)";
        /// Largest acceleration with which the motion reference brings a pushed body back to the
        /// given velocity, m/s² (`reference_governor.rs`, docs/push-recovery.md).
        recovery_acceleration: f64 = crate::reference_governor::RECOVERY_ACCELERATION,
            fmi "recovery.acceleration", range limits::RECOVERY_ACCELERATION, unit "m/s2",
            "Largest acceleration with which the reference brings a pushed body back to the given velocity";
        /// When a push begins, the legs in swing land this long after it instead of on the
        /// gait's clock, and stand until their own stance begins (the legs in stance keep their
        /// timing), s; 0, the default, turns it off. Opt-in until the whole push-recovery set is
        /// re-measured with it: 0.08 s measured on the headline sweep in docs/push-recovery.md
        /// (`fsm/locomotion.rs`).
        recovery_touchdown_time: f64 = 0.0,
            fmi "recovery.touchdownTime", range limits::RECOVERY_TOUCHDOWN_TIME, unit "s",
            "When a push begins, the swinging legs land this long after it and stand until their own stance begins (0: off)", scales Time;
    }
}

impl ControllerConfig {
    /// Checks every field (every element of the arrays) against its declared range: the
    /// operating envelope of [`crate::limits`]. Non-finite values are refused. The error names
    /// the first offending field and its value.
    pub fn check_ranges(&self) -> Result<(), ConfigError> {
        self.check_ranges_for(RobotScale::TUNED)
    }

    /// [`ControllerConfig::check_ranges`] with the ranges of a robot of `scale`
    /// ([`ConfigField::range_for`]).
    pub fn check_ranges_for(&self, scale: RobotScale) -> Result<(), ConfigError> {
        for field in Self::FIELDS {
            let (min, max) = field.range_for(scale);
            for i in 0..field.len {
                let value = field.get(self, i).as_f64();
                if !(value.is_finite() && min <= value && value <= max) {
                    return Err(ConfigError {
                        field: field.element_name(i),
                        value,
                        min,
                        max,
                    });
                }
            }
        }
        Ok(())
    }

    /// The field called `name` (Rust/JSON name).
    pub fn field(name: &str) -> Option<&'static ConfigField> {
        Self::FIELDS.iter().find(|f| f.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_covers_every_field_once_with_its_default_in_range() {
        let config = ControllerConfig::default();
        config.check_ranges().unwrap();
        let json = serde_json::to_value(&config).unwrap();
        let object = json.as_object().unwrap();
        assert_eq!(object.len(), ControllerConfig::FIELDS.len());
        for field in ControllerConfig::FIELDS {
            assert!(object.contains_key(field.name), "{}", field.name);
            let (min, max) = field.range();
            assert!(
                min < max && min.is_finite() && max.is_finite(),
                "{}",
                field.name
            );
            assert_eq!(
                field.labels.len(),
                if field.is_array { field.len } else { 0 }
            );
            assert_eq!(field.description.contains("{}"), field.is_array);
        }
        assert_eq!(
            ControllerConfig::FIELDS
                .iter()
                .map(|f| f.len)
                .sum::<usize>(),
            59
        );
    }

    #[test]
    fn fields_read_and_write_their_own_element() {
        let mut config = ControllerConfig::default();
        let q = ControllerConfig::field("mpc_q").unwrap();
        assert_eq!(q.get(&config, 12), FieldValue::Real(0.0));
        assert!(q.set(&mut config, 3, FieldValue::Real(7.0)));
        assert_eq!(config.mpc_q[3], 7.0);
        assert!(!q.set(&mut config, 3, FieldValue::Count(1)));
        assert_eq!(q.fmi_element_name(3), "mpc.q[4]");
        assert_eq!(q.element_description(12), "MPC state weight: gravity state");
        let gait = ControllerConfig::field("gait").unwrap();
        assert!(gait.set(&mut config, 0, FieldValue::Gait(GaitKind::Walk)));
        assert_eq!(config.gait, GaitKind::Walk);
        assert_eq!(gait.range(), (0.0, 1.0));
        let horizon = ControllerConfig::field("mpc_horizon").unwrap();
        assert_eq!(horizon.range(), (10.0, 40.0));
        assert_eq!(horizon.unit, None);
        assert_eq!(
            ControllerConfig::field("control_dt").unwrap().unit,
            Some("s")
        );
    }

    #[test]
    fn range_errors_name_the_field_and_the_value() {
        let mut config = ControllerConfig {
            mpc_r: f64::NAN,
            ..ControllerConfig::default()
        };
        let err = config.check_ranges().unwrap_err();
        assert_eq!(err.field, "mpc_r");
        assert!(
            err.to_string().starts_with("mpc_r = NaN is outside"),
            "{err}"
        );
        config.mpc_r = 1e-5;
        config.kd_stand[2] = 101.0;
        assert_eq!(
            config.check_ranges().unwrap_err().to_string(),
            "kd_stand[2] = 101 is outside [0, 100]"
        );
        config.kd_stand[2] = 3.0;
        config.mpc_horizon = 41;
        assert_eq!(config.check_ranges().unwrap_err().field, "mpc_horizon");
    }

    #[test]
    fn json_is_the_struct_with_its_rust_names() {
        let text = serde_json::to_string(&ControllerConfig::default()).unwrap();
        let back: ControllerConfig = serde_json::from_str(&text).unwrap();
        assert_eq!(back, ControllerConfig::default());
        assert!(text.contains("\"gait\":\"Trot\""));
        let unknown = text.replacen("\"mu\"", "\"friction\"", 1);
        assert!(serde_json::from_str::<ControllerConfig>(&unknown).is_err());
    }
}
