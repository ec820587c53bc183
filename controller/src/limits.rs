//! Accepted ranges (inclusive) of the [`ControllerConfig`](crate::ControllerConfig) fields: the
//! operating envelope the controller is tuned and timed for. This is their only definition; each
//! is named once, by its field's declaration in [`crate::config`], and reaches from there
//! [`ControllerConfig::check_ranges`](crate::ControllerConfig::check_ranges) and the FMU, which
//! declares them as the parameters' `min`/`max` in `modelDescription.xml` and refuses values
//! outside them.
//!
//! [`Controller::new`](crate::Controller::new) enforces all of them (and `f_min < f_max`, a
//! reachable standing pose): the upper bounds keep the cost of a tick and the physics sensible
//! (a tick of 1e-12 s, gains of 1e300), whoever builds the controller.

use std::f64::consts::PI;
use std::ops::RangeInclusive;

/// `control_dt`, s: 0.1 ms (10 kHz) … 50 ms (20 Hz).
pub const CONTROL_DT: RangeInclusive<f64> = 1e-4..=0.05;
/// `mpc_every_ticks`.
pub const MPC_EVERY_TICKS: RangeInclusive<usize> = 1..=1000;
/// `mpc_horizon`: what the MPC is sized and tested for.
pub const MPC_HORIZON: RangeInclusive<usize> = 10..=40;
/// `mpc_dt`, s.
pub const MPC_DT: RangeInclusive<f64> = 0.005..=0.1;
/// `gait_period`, s.
pub const GAIT_PERIOD: RangeInclusive<f64> = 0.05..=5.0;
/// `swing_height`, m (the legs are 0.4 m long).
pub const SWING_HEIGHT: RangeInclusive<f64> = 0.0..=0.25;
/// `mu`.
pub const MU: RangeInclusive<f64> = 0.05..=2.0;
/// `mu_slope_margin`.
pub const MU_SLOPE_MARGIN: RangeInclusive<f64> = 0.0..=1.0;
pub const RECOVERY_ACCELERATION: RangeInclusive<f64> = 0.1..=20.0;
/// `recovery_touchdown_time`, s (0: off; a trot's swing lasts 0.15 s).
pub const RECOVERY_TOUCHDOWN_TIME: RangeInclusive<f64> = 0.0..=0.2;
/// `f_min`, N (also `f_min < f_max`).
pub const F_MIN: RangeInclusive<f64> = 0.0..=1000.0;
/// `f_max`, N (the robot weighs about 120 N).
pub const F_MAX: RangeInclusive<f64> = 1.0..=2000.0;
/// `body_height`, m (also: the standing pose must be reachable by the robot's legs).
pub const BODY_HEIGHT: RangeInclusive<f64> = 0.15..=0.5;
/// Each of `mpc_q`.
pub const MPC_Q: RangeInclusive<f64> = 0.0..=1e5;
/// `mpc_r`.
pub const MPC_R: RangeInclusive<f64> = 1e-8..=10.0;
/// Each joint stiffness of `kp_swing` and `kp_stand`, N·m/rad.
pub const JOINT_KP: RangeInclusive<f64> = 0.0..=1000.0;
/// Each joint damping of `kd_swing` and `kd_stand`, and `damping_kd`, N·m·s/rad.
pub const JOINT_KD: RangeInclusive<f64> = 0.0..=100.0;
/// `stand_up_duration`, s.
pub const STAND_UP_DURATION: RangeInclusive<f64> = 0.01..=30.0;
/// `raibert_gain`, s.
pub const RAIBERT_GAIN: RangeInclusive<f64> = 0.0..=1.0;
/// `max_tilt`, rad.
pub const MAX_TILT: RangeInclusive<f64> = 0.05..=PI;
/// `joint_limit_margin`, rad.
pub const JOINT_LIMIT_MARGIN: RangeInclusive<f64> = 0.0..=1.0;
/// `max_terrain_pitch`, rad.
pub const MAX_TERRAIN_PITCH: RangeInclusive<f64> = 0.0..=1.2;
/// `est_gyro_noise`, rad/s/√Hz (MEMS gyros: 1e-4 … 1e-2).
pub const EST_GYRO_NOISE: RangeInclusive<f64> = 1e-6..=1.0;
/// `est_gyro_bias_walk`, rad/s²/√Hz.
pub const EST_GYRO_BIAS_WALK: RangeInclusive<f64> = 1e-8..=0.1;
/// `est_acc_tilt_noise`, m/s².
pub const EST_ACC_TILT_NOISE: RangeInclusive<f64> = 1e-3..=100.0;
/// `est_acc_noise`, m/s²/√Hz.
pub const EST_ACC_NOISE: RangeInclusive<f64> = 1e-5..=10.0;
/// `est_leg_position_noise`, m.
pub const EST_LEG_POSITION_NOISE: RangeInclusive<f64> = 1e-5..=1.0;
/// `est_leg_velocity_noise`, m/s.
pub const EST_LEG_VELOCITY_NOISE: RangeInclusive<f64> = 1e-4..=10.0;
/// `est_foot_drift`, m/√s.
pub const EST_FOOT_DRIFT: RangeInclusive<f64> = 1e-6..=1.0;
/// `est_odometry_drift`, m/√m (0: the position variance does not grow with distance).
pub const EST_ODOMETRY_DRIFT: RangeInclusive<f64> = 0.0..=1.0;
/// `est_fix_noise`, m.
pub const EST_FIX_NOISE: RangeInclusive<f64> = 1e-4..=100.0;
/// `est_swing_noise_factor`.
pub const EST_SWING_NOISE_FACTOR: RangeInclusive<f64> = 1.0..=1e6;
/// `est_foot_rolling` (share of the foot radius).
pub const EST_FOOT_ROLLING: RangeInclusive<f64> = 0.0..=1.0;
/// `est_gyro_limit`, rad/s (±2000 °/s is the usual largest MEMS range).
pub const EST_GYRO_LIMIT: RangeInclusive<f64> = 1.0..=100.0;
