//! Input checks run before a tick touches any controller state: the configuration (once, in
//! `Controller::new`), the measured state and the reference (every tick).

use crate::api::{ControllerError, Reference, RobotState};
use crate::config::{ControllerConfig, RobotScale};

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

/// Checks the configuration against its declared operating envelope for a robot of `scale`
/// (every field's range in [`crate::config`], widened with the robot's size) and the one
/// relation between fields that a range cannot state.
pub fn validate_config(
    config: &ControllerConfig,
    scale: RobotScale,
) -> Result<(), ControllerError> {
    config
        .check_ranges_for(scale)
        .map_err(|e| ControllerError::Config(e.to_string()))?;
    if config.f_min >= config.f_max {
        return Err(ControllerError::Config(format!(
            "f_min must be < f_max (f_min = {}, f_max = {})",
            config.f_min, config.f_max
        )));
    }
    Ok(())
}

/// Checks the measured state: finite joint values and, when `with_base` (the base pose and twist
/// are used this tick), finite base values and a quaternion of norm ≈ 1.
pub fn validate_state(state: &RobotState, with_base: bool) -> Result<(), ControllerError> {
    let bad = |m: String| Err(ControllerError::InvalidState(m));
    let base: [(&[f64], &str); 4] = [
        (&state.base_position, "base_position"),
        (&state.base_orientation, "base_orientation"),
        (&state.base_linear_velocity, "base_linear_velocity"),
        (&state.base_angular_velocity, "base_angular_velocity"),
    ];
    let joints: [(&[f64], &str); 2] = [
        (&state.joint_positions, "joint_positions"),
        (&state.joint_velocities, "joint_velocities"),
    ];
    let checked = if with_base { &base[..] } else { &[] };
    for &(values, what) in checked.iter().chain(&joints) {
        if let Err(m) = check_finite(values, what) {
            return bad(m);
        }
    }
    if !with_base {
        return Ok(());
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
