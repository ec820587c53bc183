//! Closed loop on the estimate: the controller in Kalman mode trots on the single-rigid-body
//! simulation of `common`, fed only the IMU the simulated trunk implies (gyro = Rᵀω, accelerometer
//! = Rᵀ(a + g) with a the base origin's velocity change over the previous tick, as a real IMU
//! lags by a sample) and the joint encoders; the base pose is read at the first tick only.
//! Against the truth: tracking within 5 cm, velocity RMS ≤ 0.05 m/s and position drift ≤ 3 % of
//! the distance walked (the targets for the full simulation).
#![allow(clippy::needless_range_loop)] // the shared simulation indexes joints and axes in parallel
use crate::common;

use nalgebra::Vector3;
use quad_controller::{
    ControllerConfig, EstimatorKind, FsmState, ModeRequest, Reference, SensorReadings,
};

#[test]
fn kalman_mode_trots_on_its_own_estimate() {
    let model = common::model();
    let config = ControllerConfig {
        estimator: EstimatorKind::Kalman,
        // This rigid-body simulation holds each stance foot's centre still (a point foot).
        est_foot_rolling: 0.0,
        ..ControllerConfig::default()
    };
    let dt = config.control_dt;
    let (mut controller, mut sim) = common::controller_and_standing_sim(model, &config);
    let speed = 0.5;
    let (stand_ticks, walk_ticks) = ((1.5 / dt) as usize, (4.0 / dt) as usize);
    let mut previous_velocity = Vector3::from(sim.state().base_linear_velocity);
    let mut acceleration = Vector3::zeros();
    let (mut max_error, mut velocity_sq, mut samples) = (0.0_f64, 0.0, 0usize);
    let mut last_drift = 0.0;
    for tick in 0..stand_ticks + walk_ticks {
        let walking = tick >= stand_ticks;
        let t = (tick as f64 - stand_ticks as f64).max(0.0) * dt;
        let state = sim.state();
        let imu = sim.imu(acceleration);
        let sensors = SensorReadings {
            imu,
            ..SensorReadings::default()
        };
        let reference = Reference {
            x: speed * t,
            vx: if walking { speed } else { 0.0 },
            body_height: config.body_height,
            mode: if walking {
                ModeRequest::Locomotion
            } else {
                ModeRequest::Stand
            },
            ..Reference::default()
        };
        let command = controller
            .step_with_sensors(&state, &sensors, &reference, dt)
            .expect("valid input");
        let balancing = matches!(command.fsm_state, FsmState::Stand | FsmState::Locomotion);
        sim.apply_torques(&command, dt, balancing);
        let velocity = Vector3::from(sim.state().base_linear_velocity);
        acceleration = (velocity - previous_velocity) / dt;
        previous_velocity = velocity;
        if walking && t >= 0.5 {
            let base = sim.base_position();
            max_error = max_error.max(((base.x - speed * t).powi(2) + base.y.powi(2)).sqrt());
            velocity_sq += (Vector3::from(command.estimate.velocity) - velocity).norm_squared();
            samples += 1;
            last_drift = (Vector3::from(command.estimate.position) - base).norm();
        }
    }
    let velocity_rms = (velocity_sq / samples as f64).sqrt();
    let distance = speed * 4.0;
    println!(
        "kalman trot: max tracking error {max_error:.4} m, velocity RMS {velocity_rms:.4} m/s, drift {last_drift:.4} m over {distance} m"
    );
    assert_eq!(controller.fsm_state(), FsmState::Locomotion);
    assert!(max_error < 0.05, "tracking error {max_error} m");
    assert!(velocity_rms < 0.05, "velocity RMS {velocity_rms} m/s");
    assert!(last_drift < 0.03 * distance, "drift {last_drift} m");
}
