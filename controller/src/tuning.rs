//! The default tuning carried over to another robot. [`ControllerConfig::default`] is tuned for a
//! robot of [`TUNED_MASS`] standing [`TUNED_STAND_HEIGHT`] high; a robot of another size gets the
//! same behaviour in dimensionless terms (Froude scaling: forces with the weight, joint stiffness
//! with weight × leg length, times with √(length / g)), so that a 2.5 kg Solo-sized robot does not
//! receive joint gains that saturate its 2.7 N·m motors and a heavier one is not left soft.

use crate::{ControllerConfig, RobotModel};

/// Mass of the robot the default tuning was made on, kg.
pub const TUNED_MASS: f64 = 12.0;
/// Stand height of the robot the default tuning was made on, m.
pub const TUNED_STAND_HEIGHT: f64 = 0.28;

impl ControllerConfig {
    /// The default tuning scaled to `model`: body height = the robot config's stand height;
    /// stance force bounds × mass ratio; MPC force weight ÷ mass ratio² (forces grow with the
    /// weight, the state errors do not); joint stiffness and damping × mass ratio × length
    /// ratio; swing height × length ratio; gait period and Raibert gain × √length ratio. For the
    /// tuned robot itself this is exactly [`ControllerConfig::default`].
    pub fn for_robot(model: &RobotModel) -> ControllerConfig {
        scaled_tuning(
            model.total_mass() / TUNED_MASS,
            model.stand_height() / TUNED_STAND_HEIGHT,
            model.stand_height(),
        )
    }
}

/// The default tuning for a robot of `mass` × the tuned mass and `length` × the tuned stand
/// height, standing `stand_height` high.
fn scaled_tuning(mass: f64, length: f64, stand_height: f64) -> ControllerConfig {
    let defaults = ControllerConfig::default();
    let torque = mass * length;
    let time = length.sqrt();
    let scaled = |values: [f64; 3], by: f64| values.map(|v| v * by);
    ControllerConfig {
        body_height: stand_height,
        swing_height: defaults.swing_height * length,
        gait_period: defaults.gait_period * time,
        raibert_gain: defaults.raibert_gain * time,
        f_min: defaults.f_min * mass,
        f_max: defaults.f_max * mass,
        mpc_r: defaults.mpc_r / (mass * mass),
        kp_swing: scaled(defaults.kp_swing, torque),
        kd_swing: scaled(defaults.kd_swing, torque),
        kp_stand: scaled(defaults.kp_stand, torque),
        kd_stand: scaled(defaults.kd_stand, torque),
        damping_kd: defaults.damping_kd * torque,
        ..defaults
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn robot(file: &str) -> RobotModel {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../robot")
            .join(file);
        RobotModel::from_config_file(&path).expect("robot config loads")
    }

    #[test]
    fn the_tuned_robot_keeps_the_default_tuning_exactly() {
        let ours = robot("quadruped.toml");
        assert_eq!(ours.total_mass(), TUNED_MASS);
        assert_eq!(ours.stand_height(), TUNED_STAND_HEIGHT);
        assert_eq!(
            ControllerConfig::for_robot(&ours),
            ControllerConfig::default()
        );
    }

    #[test]
    fn a_lighter_shorter_robot_gets_proportionally_softer_gains_in_range() {
        // A Solo-12-sized robot: 2.5 kg, 0.24 m.
        let (mass, length) = (2.5 / TUNED_MASS, 0.24 / TUNED_STAND_HEIGHT);
        let defaults = ControllerConfig::default();
        let small = scaled_tuning(mass, length, 0.24);
        assert!((small.kp_swing[0] - defaults.kp_swing[0] * mass * length).abs() < 1e-12);
        assert!((small.kd_stand[2] - defaults.kd_stand[2] * mass * length).abs() < 1e-12);
        assert!((small.f_max - defaults.f_max * mass).abs() < 1e-12);
        assert!((small.f_min - defaults.f_min * mass).abs() < 1e-12);
        assert!((small.mpc_r - defaults.mpc_r / (mass * mass)).abs() < 1e-18);
        assert!((small.gait_period - defaults.gait_period * length.sqrt()).abs() < 1e-12);
        assert_eq!(small.body_height, 0.24);
        assert_eq!(small.mpc_q, defaults.mpc_q);
        small
            .check_ranges()
            .expect("scaled tuning stays in the envelope");
    }
}
