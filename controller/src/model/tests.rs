use super::*;

#[test]
fn zero_mass_properties_merge_is_identity() {
    let mut a = MassProperties {
        mass: 0.0,
        com: Vector3::zeros(),
        inertia_com: Matrix3::zeros(),
    };
    let b = MassProperties {
        mass: 2.0,
        com: Vector3::new(0.1, 0.0, 0.0),
        inertia_com: Matrix3::identity() * 0.01,
    };
    a.merge(&b, &Transform::identity());
    assert!((a.mass - 2.0).abs() < 1e-15);
    assert!((a.com.x - 0.1).abs() < 1e-15);
    assert!((a.inertia_com[(0, 0)] - 0.01).abs() < 1e-15);
}

fn our_model() -> RobotModel {
    let robot = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robot/quadruped.toml");
    RobotModel::from_config_file(&robot).expect("robot/quadruped.toml loads")
}

fn leg_limits(model: &RobotModel, leg: Leg) -> ([f64; 3], [f64; 3]) {
    let (lower, upper) = (model.lower_limits(), model.upper_limits());
    let base = 3 * leg.index();
    let pick = |all: [f64; NUM_JOINTS]| [all[base], all[base + 1], all[base + 2]];
    (pick(lower), pick(upper))
}

fn foot_distance(model: &RobotModel, leg: Leg, q: [f64; 3], target: [f64; 3]) -> f64 {
    (Vector3::from(model.foot_position_body(leg, q)) - Vector3::from(target)).norm()
}

#[test]
fn limited_ik_is_the_ik_inside_the_limits() {
    let model = our_model();
    for leg in Leg::ALL {
        let (lower, upper) = leg_limits(&model, leg);
        let target = model.nominal_foot_position(leg, crate::tuning::TUNED_STAND_HEIGHT);
        let free = model.inverse_kinematics(leg, target).expect("reachable");
        let limited = model
            .inverse_kinematics_within_limits(leg, target, lower, upper)
            .expect("reachable");
        assert_eq!(free, limited);
    }
}

#[test]
fn limited_ik_holds_the_knee_at_its_limit_and_keeps_the_foot_nearest_the_target() {
    let model = our_model();
    for leg in Leg::ALL {
        let (lower, mut upper) = leg_limits(&model, leg);
        // A foot drawn up close under the hip needs a knee bend beyond a limit set 0.4 rad short
        // of the IK's own knee angle.
        let target = model.nominal_foot_position(leg, 0.12);
        let free = model.inverse_kinematics(leg, target).expect("reachable");
        let mut lower = lower;
        if free[2] < 0.0 {
            lower[2] = free[2] + 0.4;
        } else {
            upper[2] = free[2] - 0.4;
        }
        let limited = model
            .inverse_kinematics_within_limits(leg, target, lower, upper)
            .expect("reachable");
        for j in 0..3 {
            assert!(
                lower[j] <= limited[j] && limited[j] <= upper[j],
                "{leg:?} joint {j}: {limited:?}"
            );
        }
        let knee_limit = if free[2] < 0.0 { lower[2] } else { upper[2] };
        assert_eq!(
            limited[2], knee_limit,
            "{leg:?}: the knee is held at its limit"
        );
        let clamped = [0, 1, 2].map(|j| free[j].clamp(lower[j], upper[j]));
        let near = foot_distance(&model, leg, limited, target);
        assert!(
            near < foot_distance(&model, leg, clamped, target),
            "{leg:?}: nearer than clamping the IK solution"
        );
        // The best the other two joints can do with the knee held, by a search over their ranges.
        let steps = 300;
        let mut best = f64::INFINITY;
        for a in 0..=steps {
            for h in 0..=steps {
                let at =
                    |j: usize, i: usize| lower[j] + (upper[j] - lower[j]) * i as f64 / steps as f64;
                let q = [at(0, a), at(1, h), knee_limit];
                best = best.min(foot_distance(&model, leg, q, target));
            }
        }
        assert!(
            near <= best + 1e-9,
            "{leg:?}: {near} vs the search's {best}"
        );
    }
}
