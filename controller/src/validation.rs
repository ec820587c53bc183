//! Input checks run before a tick touches any controller state: the configuration (once, in
//! `Controller::new`), the measured state and the reference (every tick).

use crate::api::{ControllerConfig, ControllerError, Reference, RobotState};

/// Accepted norms of the state quaternion (it is normalised; a norm outside this range means a
/// corrupted input, not rounding).
const QUATERNION_NORM_RANGE: std::ops::RangeInclusive<f64> = 0.9..=1.1;
/// Largest base height above the terrain a reference may ask for, m (the legs are ~0.4 m long).
const MAX_REFERENCE_BODY_HEIGHT: f64 = 1.0;
/// Steepest terrain plane slope (rise over run, ≈ 63°) a reference may carry.
const MAX_TERRAIN_SLOPE: f64 = 2.0;

fn check_finite(values: &[f64], what: &str) -> Result<(), String> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(format!("{what}[{i}] = {}", values[i])),
        None => Ok(()),
    }
}

/// Checks that every field of the configuration is usable.
pub fn validate_config(config: &ControllerConfig) -> Result<(), ControllerError> {
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

/// Checks the measured state: finite values, a quaternion of norm ≈ 1.
pub fn validate_state(state: &RobotState) -> Result<(), ControllerError> {
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
    if !QUATERNION_NORM_RANGE.contains(&norm) {
        return bad(format!("base_orientation norm {norm} is not ≈ 1"));
    }
    Ok(())
}

/// Checks the reference: finite values, a yaw rate the MPC can linearise, a reachable height
/// and a plausible terrain slope.
pub fn validate_reference(reference: &Reference, mpc_dt: f64) -> Result<(), ControllerError> {
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
    if reference.body_height > MAX_REFERENCE_BODY_HEIGHT {
        return Err(ControllerError::InvalidReference(format!(
            "body_height {} m is not reachable",
            reference.body_height
        )));
    }
    if reference.terrain.slope_x.abs() > MAX_TERRAIN_SLOPE
        || reference.terrain.slope_y.abs() > MAX_TERRAIN_SLOPE
    {
        return Err(ControllerError::InvalidReference(
            "terrain slope steeper than 63°".into(),
        ));
    }
    Ok(())
}
