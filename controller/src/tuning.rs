//! The default tuning carried over to another robot. [`ControllerConfig::default`] is tuned for a
//! robot of [`TUNED_MASS`] standing [`TUNED_STAND_HEIGHT`] high; a robot of another size gets the
//! same behaviour in dimensionless terms (Froude scaling: forces with the weight, joint stiffness
//! with weight × leg length, times with √(length / g)), so that a 2.5 kg Solo-sized robot does not
//! receive joint gains that saturate its 2.7 N·m motors and a heavier one is not left soft.

use serde::Deserialize;

use crate::config::{FieldValue, RobotScale, Scaling};
use crate::robot_config::KeyProblem;
use crate::{ControllerConfig, RobotModel};

/// Mass of the robot the default tuning was made on, kg.
pub const TUNED_MASS: f64 = 12.0;
/// Stand height of the robot the default tuning was made on, m.
pub const TUNED_STAND_HEIGHT: f64 = 0.28;

impl RobotScale {
    /// `model`'s size relative to the tuned robot: total mass and stand height ratios.
    pub fn of(model: &RobotModel) -> RobotScale {
        RobotScale {
            mass: model.total_mass() / TUNED_MASS,
            length: model.stand_height() / TUNED_STAND_HEIGHT,
        }
    }
}

impl ControllerConfig {
    /// The default tuning scaled to `model`: every field declared with a [`Scaling`] is its
    /// default times the robot's factor (stance force bounds × mass ratio; MPC force weight ÷
    /// mass ratio², as forces grow with the weight and the state errors do not; joint stiffness
    /// and damping × mass ratio × length ratio; swing height × length ratio; gait period and
    /// Raibert gain × √length ratio), and the body height is the robot config's stand height.
    /// For the tuned robot itself this is exactly [`ControllerConfig::default`].
    /// A robot config's `[tuning]` table replaces the fields it names (checked when the model
    /// was built, [`tuned_for_robot`]).
    pub fn for_robot(model: &RobotModel) -> ControllerConfig {
        model
            .configured_tuning()
            .cloned()
            .unwrap_or_else(|| default_tuning_for(model))
    }
}

/// Walking speed the swing's joint speeds are checked at, m/s: the paper scenarios' plans, which
/// every robot walks at the same speed.
pub const SWING_CHECK_SPEED: f64 = 0.5;
/// Largest share of a joint's velocity limit the nominal swing may ask for: the swing foot's
/// tracking overshoots the plan, and a joint held at its limit makes a torque the leg model does
/// not see (ANYmal C's knees at 7.5 rad/s read as 400 N on a foot in the air).
pub const SWING_SPEED_SHARE: f64 = 0.6;
/// The swing height is lowered to this share of its scaled value at most.
const MIN_SWING_HEIGHT_SHARE: f64 = 0.4;

/// The scaled default tuning of `model`, with its swing lowered (to [`MIN_SWING_HEIGHT_SHARE`] of
/// the scaled height at most) until the swing's joint speeds are within [`SWING_SPEED_SHARE`] of
/// the velocity limits ([`swing_speed_share`]).
fn default_tuning_for(model: &RobotModel) -> ControllerConfig {
    let scale = RobotScale::of(model);
    let scaled = scaled_tuning(scale, model.stand_height());
    let share = |config: &ControllerConfig| swing_speed_share(model, config);
    if share(&scaled) <= SWING_SPEED_SHARE {
        return scaled;
    }
    let with_height = |factor: f64| ControllerConfig {
        swing_height: scaled.swing_height * factor,
        ..scaled.clone()
    };
    // Below the lowest swing the stride itself sets the joint speeds, which a slower gait does
    // not help (the stride lengthens with the period; ANYmal C slowed to a 0.65 s trot fell in
    // the pits where its 0.42 s trot walked): the lowest swing is as far as it goes.
    let lowest = with_height(MIN_SWING_HEIGHT_SHARE);
    if share(&lowest) > SWING_SPEED_SHARE {
        return lowest;
    }
    // The share grows with the height: bisect for the highest swing within the limit.
    let (mut low, mut high) = (MIN_SWING_HEIGHT_SHARE, 1.0);
    for _ in 0..30 {
        let middle = 0.5 * (low + high);
        if share(&with_height(middle)) <= SWING_SPEED_SHARE {
            low = middle;
        } else {
            high = middle;
        }
    }
    with_height(low)
}

/// Largest joint speed of the nominal swing (flat ground, trotting straight ahead at
/// [`SWING_CHECK_SPEED`], apex `swing_height`) as a share of that joint's velocity limit, over
/// every leg and joint.
pub fn swing_speed_share(model: &RobotModel, config: &ControllerConfig) -> f64 {
    use crate::api::Leg;
    use crate::gait::{swing_trajectory, Gait};
    let gait = Gait::new(config.gait, config.gait_period);
    let speed = SWING_CHECK_SPEED;
    // The foot lifts off half a stance behind its nominal spot and lands half a stance ahead of
    // it (base frame); on the ground it travels a whole cycle of the base's motion.
    let half_stance = 0.5 * speed * gait.stance_time();
    let limits = model.velocity_limits();
    let mut worst = 0.0_f64;
    for leg in Leg::ALL {
        let nominal = model.nominal_foot_position(leg, config.body_height);
        let start = [nominal[0] - half_stance, nominal[1], nominal[2]];
        let end = [start[0] + speed * gait.period, nominal[1], nominal[2]];
        for i in 0..=100 {
            let progress = f64::from(i) / 100.0;
            let sample =
                swing_trajectory(start, end, config.swing_height, gait.swing_time(), progress);
            let mut position = sample.position;
            position[0] -= speed * progress * gait.swing_time();
            let Some(q) = model.try_inverse_kinematics(leg, position) else {
                return f64::INFINITY;
            };
            let jacobian = model.foot_kinematics(leg, q).jacobian;
            let mut velocity = nalgebra::Vector3::from(sample.velocity);
            velocity.x -= speed;
            let Some(rates) = jacobian.try_inverse().map(|inverse| inverse * velocity) else {
                return f64::INFINITY;
            };
            for j in 0..3 {
                worst = worst.max(rates[j].abs() / limits[3 * leg.index() + j]);
            }
        }
    }
    worst
}

/// The default tuning of `model` (scaled, swing within the velocity limits) with the robot
/// config's `[tuning]` overrides applied and checked against the robot's ranges. Errors name the
/// key (`tuning.kp_stand[1] = 1500 is outside [0, 1000]`).
pub(crate) fn tuned_for_robot(
    model: &RobotModel,
    overrides: &toml::Table,
) -> Result<ControllerConfig, KeyProblem> {
    let scale = RobotScale::of(model);
    let scaled = default_tuning_for(model);
    if overrides.is_empty() {
        return Ok(scaled);
    }
    let whole = |reason: String| KeyProblem::of("tuning", reason);
    let mut table = toml::Table::try_from(&scaled)
        .map_err(|e| whole(format!("cannot express the tuning as TOML: {e}")))?;
    for (key, value) in overrides {
        if ControllerConfig::field(key).is_none() {
            let known: Vec<&str> = ControllerConfig::FIELDS.iter().map(|f| f.name).collect();
            return Err(KeyProblem::of(
                format!("tuning.{key}"),
                format!(
                    "key `tuning.{key}` is not a controller config field (one of: {})",
                    known.join(", ")
                ),
            ));
        }
        table.insert(key.clone(), value.clone());
    }
    let config = ControllerConfig::deserialize(toml::Value::Table(table)).map_err(|e| {
        whole(format!(
            "table `tuning`: {}",
            e.to_string().trim_end().replace('\n', " ")
        ))
    })?;
    if let Err(e) = config.check_ranges_for(scale) {
        return Err(KeyProblem::of(
            format!("tuning.{}", e.field),
            format!("key `tuning.{e}`"),
        ));
    }
    crate::validation::validate_config(&config, scale)
        .map_err(|e| whole(format!("table `tuning`: {e}")))?;
    Ok(config)
}

/// The default tuning for a robot of `scale`, standing `stand_height` high.
fn scaled_tuning(scale: RobotScale, stand_height: f64) -> ControllerConfig {
    let defaults = ControllerConfig::default();
    let mut config = defaults.clone();
    for field in ControllerConfig::FIELDS {
        if field.scaling == Scaling::Fixed {
            continue;
        }
        let factor = scale.factor(field.scaling);
        for i in 0..field.len {
            if let FieldValue::Real(value) = field.get(&defaults, i) {
                field.set(&mut config, i, FieldValue::Real(value * factor));
            }
        }
    }
    ControllerConfig {
        body_height: stand_height,
        ..config
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
    fn our_robots_swing_is_within_its_velocity_limits_as_tuned() {
        let ours = robot("quadruped.toml");
        let share = swing_speed_share(&ours, &ControllerConfig::default());
        // Our robot's own swing needs no change (the default tuning is kept exactly).
        assert!(share < SWING_SPEED_SHARE, "our robot: {share}");
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
        let small = scaled_tuning(RobotScale { mass, length }, 0.24);
        assert!((small.kp_swing[0] - defaults.kp_swing[0] * mass * length).abs() < 1e-12);
        assert!((small.kd_stand[2] - defaults.kd_stand[2] * mass * length).abs() < 1e-12);
        assert!((small.f_max - defaults.f_max * mass).abs() < 1e-12);
        assert!((small.f_min - defaults.f_min * mass).abs() < 1e-12);
        assert!((small.mpc_r - defaults.mpc_r / (mass * mass)).abs() < 1e-18);
        assert!((small.gait_period - defaults.gait_period * length.sqrt()).abs() < 1e-12);
        assert!((small.raibert_gain - defaults.raibert_gain * length.sqrt()).abs() < 1e-12);
        assert!((small.swing_height - defaults.swing_height * length).abs() < 1e-12);
        assert!((small.damping_kd - defaults.damping_kd * mass * length).abs() < 1e-12);
        assert_eq!(small.body_height, 0.24);
        assert_eq!(small.mpc_q, defaults.mpc_q);
        small
            .check_ranges()
            .expect("scaled tuning stays in the envelope");
    }

    #[test]
    fn a_heavy_tall_robot_gets_its_scaled_tuning_accepted_by_its_own_ranges() {
        // A HyQ-sized robot: 87 kg standing 0.6 m (the tuned robot's envelope refuses its stand
        // height and its stance gains).
        let scale = RobotScale {
            mass: 87.0 / TUNED_MASS,
            length: 0.6 / TUNED_STAND_HEIGHT,
        };
        let big = scaled_tuning(scale, 0.6);
        let err = big
            .check_ranges()
            .expect_err("outside the tuned robot's envelope");
        assert!(
            ["body_height", "kp_stand[0]", "kp_swing[0]"].contains(&err.field.as_str()),
            "{err}"
        );
        big.check_ranges_for(scale)
            .expect("the robot's own ranges hold its scaled tuning");
        // Widened, never narrowed: the tuned robot's values stay accepted, and values beyond
        // the scaled envelope are still refused.
        ControllerConfig::default()
            .check_ranges_for(scale)
            .expect("defaults in the big robot's ranges");
        let field = ControllerConfig::field("kp_stand").expect("field");
        let (_, max) = field.range_for(scale);
        assert!((max - field.range().1 * scale.mass * scale.length).abs() < 1e-9);
        let too_stiff = ControllerConfig {
            kp_stand: [max * 1.01; 3],
            ..big
        };
        assert_eq!(
            too_stiff.check_ranges_for(scale).unwrap_err().field,
            "kp_stand[0]"
        );
    }
}
