//! Cost of one estimator tick (issue 18 target: ≤ 20 µs per control tick): the Kalman mode
//! (orientation filter + contact detection from leg effort + 18-state leg-kinematics filter) on
//! a trot tick with two feet in stance and two in swing, with and without a position fix, and the
//! ground-truth mode for comparison.
use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use quad_controller::api::{EstimatorKind, PositionFix, SensorReadings};
use quad_controller::estimator::{StancePlan, StateEstimator};
use quad_controller::{Controller, ControllerConfig, RobotModel, RobotState};

fn bench_estimator(c: &mut Criterion) {
    let robot = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robot/quadruped.toml");
    let model = RobotModel::from_config_file(&robot).expect("URDF");
    let stand = Controller::new(model.clone(), ControllerConfig::default())
        .expect("controller")
        .stand_joint_positions();
    let state = RobotState {
        base_position: [0.0, 0.0, quad_controller::tuning::TUNED_STAND_HEIGHT],
        joint_positions: stand,
        ..RobotState::default()
    };
    // Trot: FR and RL in mid-stance, FL and RR in swing.
    let plan: StancePlan = [Some(0.5), None, None, Some(0.5)];
    let mut sensors = SensorReadings::default();
    sensors.imu.gyro = [0.01, -0.02, 0.005];
    let with_fix = SensorReadings {
        fix: PositionFix {
            position: [0.0, 0.0, quad_controller::tuning::TUNED_STAND_HEIGHT],
            valid: true,
        },
        ..sensors
    };
    for (name, kind, readings) in [
        ("estimator_tick_kalman_trot", EstimatorKind::Kalman, sensors),
        (
            "estimator_tick_kalman_trot_with_fix",
            EstimatorKind::Kalman,
            with_fix,
        ),
        (
            "estimator_tick_ground_truth",
            EstimatorKind::GroundTruth,
            sensors,
        ),
    ] {
        let config = ControllerConfig {
            estimator: kind,
            ..ControllerConfig::default()
        };
        let mut estimator = StateEstimator::new(&model, &config);
        // A commanded torque makes every Kalman tick run the contact detector's force estimate
        // (the last command stays the one read until the next is recorded).
        estimator.record_applied_torques(&std::array::from_fn(|j| [0.5, -2.0, 4.0][j % 3]));
        estimator.update(&model, &state, &sensors, &plan, 0.001);
        c.bench_function(name, |b| {
            b.iter(|| {
                let estimate = estimator.update(
                    &model,
                    black_box(&state),
                    black_box(&readings),
                    &plan,
                    0.001,
                );
                black_box(estimate.position)
            })
        });
        println!(
            "{name}: estimate {:?}, status {}",
            estimator.report().position,
            estimator.report().status
        );
    }
}

criterion_group!(benches, bench_estimator);
criterion_main!(benches);
