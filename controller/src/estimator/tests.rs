//! Estimator tests on synthetic truth: a trunk moving on a known trajectory, feet held on the
//! ground in stance and swung along the gait's swing curve, and the IMU and encoder readings that
//! truth implies through the model's own kinematics (inverse kinematics for the angles, the
//! Jacobian for the rates).

use nalgebra::{UnitQuaternion, Vector3};

use super::*;
use crate::api::{ImuReading, PositionFix, NUM_JOINTS};
use crate::gait::{swing_trajectory, LegPhase};
use crate::{Controller, GaitKind, ModeRequest, Reference};

const DT: f64 = 0.001;

fn model() -> RobotModel {
    let robot = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robot/quadruped.toml");
    RobotModel::from_config_file(&robot).expect("URDF")
}

fn kalman_config() -> ControllerConfig {
    ControllerConfig {
        estimator: EstimatorKind::Kalman,
        // The synthetic walks below hold each stance foot's centre still (a point foot).
        est_foot_rolling: 0.0,
        ..ControllerConfig::default()
    }
}

/// Foot positions in the base frame at the controller's standing pose.
fn stand_feet_body(model: &RobotModel) -> [Vector3<f64>; NUM_LEGS] {
    let controller = Controller::new(model.clone(), ControllerConfig::default()).expect("stand");
    let q = controller.stand_joint_positions();
    Leg::ALL.map(|leg| Vector3::from(model.foot_position_body(leg, leg_slice(&q, leg))))
}

/// The true motion at one instant.
#[derive(Clone, Copy, Debug)]
struct Truth {
    position: Vector3<f64>,
    velocity: Vector3<f64>,
    acceleration: Vector3<f64>,
    attitude: UnitQuaternion<f64>,
    /// Angular velocity, world frame.
    omega: Vector3<f64>,
    feet: [Vector3<f64>; NUM_LEGS],
    feet_velocity: [Vector3<f64>; NUM_LEGS],
}

impl Truth {
    fn standing(model: &RobotModel) -> Truth {
        let position = Vector3::new(0.0, 0.0, crate::tuning::TUNED_STAND_HEIGHT);
        Truth {
            position,
            velocity: Vector3::zeros(),
            acceleration: Vector3::zeros(),
            attitude: UnitQuaternion::identity(),
            omega: Vector3::zeros(),
            feet: stand_feet_body(model).map(|f| position + f),
            feet_velocity: [Vector3::zeros(); NUM_LEGS],
        }
    }

    /// The encoders (and the ground-truth base fields, read at the first tick only) and the
    /// noise-free IMU this truth implies.
    fn measure(&self, model: &RobotModel) -> (RobotState, ImuReading) {
        let inverse = self.attitude.inverse();
        let omega_body = inverse * self.omega;
        let mut joint_positions = [0.0; NUM_JOINTS];
        let mut joint_velocities = [0.0; NUM_JOINTS];
        for leg in Leg::ALL {
            let l = leg.index();
            let relative = inverse * (self.feet[l] - self.position);
            let q = model
                .inverse_kinematics(leg, relative.into())
                .expect("reachable foot");
            let (_, jacobian) = model.foot_position_and_jacobian(leg, q);
            let relative_velocity =
                inverse * (self.feet_velocity[l] - self.velocity) - omega_body.cross(&relative);
            let dq = jacobian.try_inverse().expect("non-singular leg") * relative_velocity;
            joint_positions[3 * l..3 * l + 3].copy_from_slice(&q);
            joint_velocities[3 * l..3 * l + 3].copy_from_slice(dq.as_slice());
        }
        let state = RobotState {
            base_position: self.position.into(),
            base_orientation: [
                self.attitude.w,
                self.attitude.i,
                self.attitude.j,
                self.attitude.k,
            ],
            base_linear_velocity: self.velocity.into(),
            base_angular_velocity: self.omega.into(),
            joint_positions,
            joint_velocities,
        };
        let imu = ImuReading {
            gyro: omega_body.into(),
            acc: (inverse * (self.acceleration + Vector3::new(0.0, 0.0, GRAVITY))).into(),
        };
        (state, imu)
    }
}

fn sensors(imu: ImuReading) -> SensorReadings {
    SensorReadings {
        imu,
        ..SensorReadings::default()
    }
}

const ALL_STANCE: StancePlan = [Some(0.5); NUM_LEGS];

/// A trot at constant velocity: stance feet stay put, swing feet follow the gait's swing curve
/// to a foothold half a stance ahead of the hip.
struct TrotWalk {
    gait: Gait,
    velocity: Vector3<f64>,
    nominal: [Vector3<f64>; NUM_LEGS],
    start: Vector3<f64>,
    lift_off: [Vector3<f64>; NUM_LEGS],
    touch_down: [Vector3<f64>; NUM_LEGS],
    was_stance: [bool; NUM_LEGS],
}

impl TrotWalk {
    fn new(model: &RobotModel, velocity: Vector3<f64>) -> TrotWalk {
        let start = Vector3::new(0.0, 0.0, crate::tuning::TUNED_STAND_HEIGHT);
        let nominal = stand_feet_body(model);
        TrotWalk {
            gait: Gait::new(GaitKind::Trot, 0.3),
            velocity,
            nominal,
            start,
            lift_off: nominal.map(|f| start + f),
            touch_down: nominal.map(|f| start + f),
            was_stance: [true; NUM_LEGS],
        }
    }

    /// Truth and stance plan at time `t` (advance in order).
    fn at(&mut self, t: f64) -> (Truth, StancePlan) {
        let position = self.start + self.velocity * t;
        let mut feet = [Vector3::zeros(); NUM_LEGS];
        let mut feet_velocity = [Vector3::zeros(); NUM_LEGS];
        let mut plan = [None; NUM_LEGS];
        for leg in Leg::ALL {
            let l = leg.index();
            match self.gait.phase(leg, t) {
                LegPhase::Stance(s) => {
                    if !self.was_stance[l] {
                        self.lift_off[l] = self.touch_down[l];
                    }
                    self.was_stance[l] = true;
                    feet[l] = self.lift_off[l];
                    plan[l] = Some(s);
                }
                LegPhase::Swing(s) => {
                    if self.was_stance[l] {
                        let remaining = self.gait.swing_time() + self.gait.stance_time() / 2.0;
                        self.touch_down[l] =
                            self.start + self.velocity * (t + remaining) + self.nominal[l];
                    }
                    self.was_stance[l] = false;
                    let sample = swing_trajectory(
                        self.lift_off[l].into(),
                        self.touch_down[l].into(),
                        0.08,
                        self.gait.swing_time(),
                        s,
                    );
                    feet[l] = Vector3::from(sample.position);
                    feet_velocity[l] = Vector3::from(sample.velocity);
                }
            }
        }
        let truth = Truth {
            position,
            velocity: self.velocity,
            acceleration: Vector3::zeros(),
            attitude: UnitQuaternion::identity(),
            omega: Vector3::zeros(),
            feet,
            feet_velocity,
        };
        (truth, plan)
    }
}

#[test]
fn ground_truth_mode_reports_the_measured_state() {
    let model = model();
    let mut estimator = StateEstimator::new(&model, &ControllerConfig::default());
    let mut truth = Truth::standing(&model);
    truth.velocity = Vector3::new(0.2, 0.0, 0.0);
    let (state, _) = truth.measure(&model);
    let nan_imu = ImuReading {
        gyro: [f64::NAN; 3],
        acc: [f64::NAN; 3],
    };
    estimator.update(&model, &state, &sensors(nan_imu), &ALL_STANCE, DT);
    let report = estimator.report();
    assert_eq!(report.position, state.base_position);
    assert_eq!(report.velocity, state.base_linear_velocity);
    assert_eq!(report.status, 0);
    assert!(estimator.reads_base_state());
}

/// Standing still, gyro with a constant bias of 0.0035 rad/s on every axis (0.2 °/s, the
/// ADIS16470's initial bias error: the turn-on bias before any calibration), accelerometer exact. Over 20 s the position stays within 1 cm and the
/// velocity within 1 cm/s; roll and pitch within 2 mrad (the accelerometer sees the roll/pitch
/// bias); yaw drifts by the unobservable yaw bias, 0.07 rad, and no more.
#[test]
fn static_robot_with_gyro_bias_stays_put() {
    let model = model();
    let mut estimator = StateEstimator::new(&model, &kalman_config());
    let truth = Truth::standing(&model);
    let (state, mut imu) = truth.measure(&model);
    let bias = 0.0035;
    imu.gyro = [bias; 3];
    let seconds = 20.0;
    let ticks = (seconds / DT) as usize;
    let mut worst_position = 0.0_f64;
    for _ in 0..ticks {
        let estimate = estimator.update(&model, &state, &sensors(imu), &ALL_STANCE, DT);
        worst_position = worst_position.max((estimate.position - truth.position).norm());
        assert!(estimate.velocity.norm() < 0.01, "{}", estimate.velocity);
    }
    let report = estimator.report();
    assert!(worst_position < 0.01, "position drift {worst_position} m");
    assert!(
        report.rpy[0].abs() < 2e-3 && report.rpy[1].abs() < 2e-3,
        "{:?}",
        report.rpy
    );
    assert!(
        (report.rpy[2] - bias * seconds).abs() < 0.01,
        "yaw {} vs {}",
        report.rpy[2],
        bias * seconds
    );
    let estimated_bias = estimator.gyro_bias();
    assert!(
        (estimated_bias[0] - bias).abs() < 1e-3,
        "{estimated_bias:?}"
    );
    assert!(
        (estimated_bias[1] - bias).abs() < 1e-3,
        "{estimated_bias:?}"
    );
    assert_eq!(report.status, 0);
}

/// Trotting at (0.4, 0.1) m/s for 6 s with exact readings, the filter started at rest: velocity
/// RMS after 0.5 s below 0.005 m/s and the position within 1 % of the distance walked (measured:
/// 0.17 %, most of it from the start-up transient and the swing foot's lag at touch-down).
#[test]
fn constant_velocity_trot_is_tracked() {
    let model = model();
    let mut estimator = StateEstimator::new(&model, &kalman_config());
    let velocity = Vector3::new(0.4, 0.1, 0.0);
    let mut walk = TrotWalk::new(&model, velocity);
    let ticks = 6000;
    let mut squared_error = 0.0;
    let mut last = None;
    for k in 0..ticks {
        let (truth, plan) = walk.at(k as f64 * DT);
        let (state, imu) = truth.measure(&model);
        let estimate = estimator.update(&model, &state, &sensors(imu), &plan, DT);
        // The filter starts at rest (it cannot know better): the first 0.5 s converge.
        if k >= 500 {
            squared_error += (estimate.velocity - truth.velocity).norm_squared();
        }
        last = Some((estimate.position, truth.position));
        assert_eq!(estimator.report().status, 0, "tick {k}");
    }
    let rms = (squared_error / (ticks - 500) as f64).sqrt();
    assert!(rms < 0.005, "velocity RMS {rms} m/s");
    let (estimated, true_position) = last.expect("ticks ran");
    let distance = velocity.norm() * ticks as f64 * DT;
    let drift = (estimated - true_position).norm();
    assert!(drift < 0.01 * distance, "drift {drift} m over {distance} m");
}

/// The odometry drift term lets the whole robot wander with the distance walked: the same trot
/// gives the same estimate with and without it (the leg measurements cannot see a common
/// translation), and the position variance of each axis grows by drift² per metre walked.
#[test]
fn position_variance_grows_with_the_distance_walked() {
    let model = model();
    let velocity = Vector3::new(0.4, 0.1, 0.0);
    let run = |odometry_drift: f64| {
        let config = ControllerConfig {
            est_odometry_drift: odometry_drift,
            ..kalman_config()
        };
        let mut estimator = StateEstimator::new(&model, &config);
        let mut walk = TrotWalk::new(&model, velocity);
        let mut position = Vector3::zeros();
        for k in 0..6000 {
            let (truth, plan) = walk.at(k as f64 * DT);
            let (state, imu) = truth.measure(&model);
            position = estimator
                .update(&model, &state, &sensors(imu), &plan, DT)
                .position;
        }
        (position, estimator.report().position_variance)
    };
    let (still, variance_without) = run(0.0);
    let drift = 0.03;
    let (wandering, variance_with) = run(drift);
    assert!((still - wandering).norm() < 1e-9, "{still} vs {wandering}");
    let distance = velocity.xy().norm() * 6.0;
    for axis in 0..3 {
        let added = variance_with[axis] - variance_without[axis];
        let expected = drift * drift * distance;
        assert!(
            (added - expected).abs() < 0.1 * expected,
            "axis {axis}: variance grew by {added:e} m², expected {expected:e} m²"
        );
    }
}

/// Turning in place at 0.5 rad/s for 2 s: the yaw estimate is the integrated rate, 1 rad.
#[test]
fn yaw_rate_integrates_to_the_known_angle() {
    let model = model();
    let mut estimator = StateEstimator::new(&model, &kalman_config());
    let standing = Truth::standing(&model);
    let feet_body = stand_feet_body(&model);
    let rate = 0.5;
    let ticks = 2000;
    for k in 0..ticks {
        let yaw = rate * k as f64 * DT;
        let attitude = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
        let omega = Vector3::new(0.0, 0.0, rate);
        // The feet turn with the trunk (they slide; the estimator is told they are in swing,
        // so only the IMU turns the estimate).
        let feet: [Vector3<f64>; NUM_LEGS] =
            std::array::from_fn(|l| standing.position + attitude * feet_body[l]);
        let truth = Truth {
            attitude,
            omega,
            feet,
            feet_velocity: feet.map(|f| omega.cross(&(f - standing.position))),
            ..standing
        };
        let (state, imu) = truth.measure(&model);
        // The gyro sample of a tick is the rate over that tick.
        estimator.update(&model, &state, &sensors(imu), &[None; NUM_LEGS], DT);
    }
    let yaw = estimator.report().rpy[2];
    assert!((yaw - rate * ticks as f64 * DT).abs() < 1e-9, "yaw {yaw}");
}

/// A trunk on a slope that rocks at the gait frequency, swerves and turns about, swaying as a
/// trot does (accelerations that pass the accelerometer's gates), read by a perfect, bias-free
/// gyro: the accelerometer cannot tell yaw, so after a minute the yaw must still be the gyro's.
/// (0.5° here; a filter that learns yaw and the vertical bias from the sway is 10° off.)
#[test]
fn walking_accelerations_do_not_turn_into_yaw() {
    use super::orientation::{OrientationFilter, OrientationNoise};
    use std::f64::consts::{PI, TAU};
    let gait_hz = 2.0;
    let yaw_at = |t: f64| 1.2 * (TAU * t / 9.0).sin() + 0.4 * t;
    let attitude_at = |t: f64| {
        let phase = TAU * gait_hz * t;
        UnitQuaternion::from_euler_angles(0.04 * phase.sin(), 0.15 + 0.04 * phase.cos(), yaw_at(t))
    };
    let acceleration_at = |t: f64| {
        let phase = TAU * gait_hz * t;
        attitude_at(t)
            * Vector3::new(
                0.6 * phase.cos(),
                0.7 * phase.sin(),
                0.5 * (2.0 * phase).sin(),
            )
    };
    let noise = OrientationNoise::from_config(&ControllerConfig::default());
    let mut filter = OrientationFilter::new(attitude_at(0.0), noise);
    let ticks = 60_000;
    let mut used = 0;
    for k in 0..ticks {
        let (t0, t1) = (k as f64 * DT, (k + 1) as f64 * DT);
        let omega_body = (attitude_at(t0).inverse() * attitude_at(t1)).scaled_axis() / DT;
        let specific_force = attitude_at(t1)
            .inverse_transform_vector(&(acceleration_at(t1) + Vector3::new(0.0, 0.0, GRAVITY)));
        filter.predict(&omega_body, DT);
        used += usize::from(filter.correct_with_accelerometer(&specific_force));
    }
    assert!(used > ticks / 2, "the accelerometer was used {used} times");
    let truth = attitude_at(ticks as f64 * DT);
    let (_, _, estimated_yaw) = filter.attitude().euler_angles();
    let (_, _, true_yaw) = truth.euler_angles();
    let yaw_error = (estimated_yaw - true_yaw + PI).rem_euclid(TAU) - PI;
    assert!(
        yaw_error.abs() < 1.0_f64.to_radians(),
        "yaw error {:.3}°",
        yaw_error.to_degrees()
    );
    // The whole attitude, roll and pitch included, stays within 1°.
    let tilt_error = (truth.inverse() * filter.attitude()).angle();
    assert!(
        tilt_error < 1.0_f64.to_radians(),
        "attitude error {:.3}°",
        tilt_error.to_degrees()
    );
}

/// A trot's accelerations, vertical bounce with a forward surge that is not zero-mean at the
/// phases where |f| ≈ g (zero-mean over the cycle), on level ground, read by perfect sensors:
/// the tilt must stay level. A filter that uses only samples with |f| near g averages the surge
/// of those phases and tilts by about 1.7°.
#[test]
fn a_bouncing_trot_does_not_tilt_the_estimate() {
    use super::orientation::{OrientationFilter, OrientationNoise};
    use std::f64::consts::TAU;
    let gait_hz = 2.0;
    let acceleration_at = |t: f64| {
        let phase = TAU * gait_hz * t;
        Vector3::new(0.6 * phase.sin().powi(2) - 0.3, 0.0, 4.0 * phase.cos())
    };
    let noise = OrientationNoise::from_config(&ControllerConfig::default());
    let level = UnitQuaternion::identity();
    let mut filter = OrientationFilter::new(level, noise);
    for k in 0..120_000 {
        let t = (k + 1) as f64 * DT;
        filter.predict(&Vector3::zeros(), DT);
        filter.correct_with_accelerometer(&(acceleration_at(t) + Vector3::new(0.0, 0.0, GRAVITY)));
    }
    let tilt = filter.attitude().angle();
    assert!(
        tilt < 0.2_f64.to_radians(),
        "tilt {:.3}°",
        tilt.to_degrees()
    );
}

/// A standing robot whose front-right leg is waved about: in swing it does not pull the trunk
/// estimate; the same readings declared in stance do.
#[test]
fn swing_feet_do_not_pull_the_estimate() {
    let model = model();
    let run = |waving_leg_in_stance: bool| {
        let mut estimator = StateEstimator::new(&model, &kalman_config());
        let truth = Truth::standing(&model);
        let mut plan = ALL_STANCE;
        plan[0] = waving_leg_in_stance.then_some(0.5);
        let mut worst = 0.0_f64;
        for k in 0..2000 {
            let t = k as f64 * DT;
            let mut moving = truth;
            let wave = Vector3::new(0.05 * (8.0 * t).sin(), 0.0, 0.04 * (1.0 - (8.0 * t).cos()));
            let wave_velocity = Vector3::new(0.4 * (8.0 * t).cos(), 0.0, 0.32 * (8.0 * t).sin());
            moving.feet[0] += wave;
            moving.feet_velocity[0] = wave_velocity;
            let (state, imu) = moving.measure(&model);
            let estimate = estimator.update(&model, &state, &sensors(imu), &plan, DT);
            worst = worst.max((estimate.position - truth.position).norm());
            worst = worst.max(estimate.velocity.norm());
        }
        worst
    };
    let in_swing = run(false);
    let in_stance = run(true);
    assert!(
        in_swing < 1e-3,
        "swing leg moved the estimate by {in_swing}"
    );
    assert!(
        in_stance > 10.0 * in_swing,
        "stance {in_stance} vs swing {in_swing}"
    );
}

/// A stance foot sliding down and away (a foot on a flank) while the robot stands: the other
/// three feet agree with the prediction, so the sliding one is gated out as slipping and the
/// trunk estimate stays put instead of moving up and towards the flank.
#[test]
fn a_slipping_foot_does_not_drag_the_estimate() {
    let model = model();
    let mut estimator = StateEstimator::new(&model, &kalman_config());
    let truth = Truth::standing(&model);
    // A slip is quick: 0.8 m/s for 0.2 s.
    let slide = Vector3::new(-0.75, 0.0, -0.25);
    let (mut worst, mut status) = (0.0_f64, 0);
    for k in 0..1500 {
        let t = k as f64 * DT;
        let mut moving = truth;
        if (0.5..0.7).contains(&t) {
            moving.feet[0] += slide * (t - 0.5);
            moving.feet_velocity[0] = slide;
        } else if t >= 0.7 {
            moving.feet[0] += slide * 0.2;
        }
        let (state, imu) = moving.measure(&model);
        let estimate = estimator.update(&model, &state, &sensors(imu), &ALL_STANCE, DT);
        worst = worst.max((estimate.position - truth.position).norm());
        status |= estimator.report().status;
    }
    // The foot slid 0.16 m; trusted, it moved the estimate by 4 cm.
    assert!(
        worst < 0.01,
        "a slipping foot moved the estimate by {worst} m"
    );
    assert!(
        status & StatusFlag::FootSlip.bit() != 0,
        "status {status:#x}"
    );
}

/// Readings of a robot standing still for `ticks` ticks with `corrupt` applied to the sensors of
/// tick k; the worst status seen and whether every estimate was finite.
fn standing_with(ticks: usize, corrupt: impl Fn(usize, &mut SensorReadings)) -> (u32, bool) {
    let model = model();
    let mut estimator = StateEstimator::new(&model, &kalman_config());
    let truth = Truth::standing(&model);
    let (state, imu) = truth.measure(&model);
    let mut status = 0;
    let mut finite = true;
    for k in 0..ticks {
        let mut readings = sensors(imu);
        corrupt(k, &mut readings);
        let estimate = estimator.update(&model, &state, &readings, &ALL_STANCE, DT);
        let report = estimator.report();
        status |= report.status;
        finite &= report
            .position
            .iter()
            .chain(&report.velocity)
            .chain(&report.rpy)
            .all(|v| v.is_finite())
            && estimate.rotation.iter().all(|v| v.is_finite())
            && estimate
                .feet_world
                .iter()
                .all(|f| f.iter().all(|v| v.is_finite()));
    }
    (status, finite)
}

#[test]
fn bad_sensor_input_is_reported_and_the_estimate_stays_finite() {
    let has = |status: u32, flag: StatusFlag| status & flag.bit() != 0;

    let (status, finite) = standing_with(500, |k, r| {
        if k % 3 == 0 {
            r.imu.gyro[1] = f64::NAN;
        }
    });
    assert!(finite && has(status, StatusFlag::GyroInvalid), "{status}");

    let (status, finite) = standing_with(500, |_, r| r.imu.gyro = [40.0, -40.0, f64::INFINITY]);
    assert!(finite && has(status, StatusFlag::GyroInvalid), "{status}");
    let (status, finite) = standing_with(500, |_, r| r.imu.gyro[2] = 35.0);
    assert!(finite && has(status, StatusFlag::GyroSaturated), "{status}");
    assert!(!has(status, StatusFlag::GyroInvalid));

    let (status, finite) =
        standing_with(500, |_, r| r.imu.acc = [f64::NAN, 0.0, f64::NEG_INFINITY]);
    assert!(finite && has(status, StatusFlag::AccInvalid), "{status}");

    // A foot whose contact sensor never closes: reported once the timeout (1 s) has passed.
    let (status, _) = standing_with(900, |_, r| r.contacts[2] = ContactReading::NoContact);
    assert_eq!(status, 0);
    let (status, finite) = standing_with(1200, |_, r| r.contacts[2] = ContactReading::NoContact);
    assert!(
        finite && has(status, StatusFlag::FootWithoutContact),
        "{status}"
    );

    let (status, finite) = standing_with(100, |_, r| r.contacts = [ContactReading::NoContact; 4]);
    assert!(finite && has(status, StatusFlag::NoStance), "{status}");

    assert_eq!(standing_with(300, |_, _| {}), (0, true));
}

#[test]
fn position_fixes_correct_drift_and_absurd_fixes_are_gated() {
    let model = model();
    let truth = Truth::standing(&model);
    let (state, imu) = truth.measure(&model);
    let mut estimator = StateEstimator::new(&model, &kalman_config());
    let fix_at = |position: Vector3<f64>| SensorReadings {
        imu,
        fix: PositionFix {
            position: position.into(),
            valid: true,
        },
        ..SensorReadings::default()
    };
    estimator.update(&model, &state, &sensors(imu), &ALL_STANCE, DT);
    // A fix 2 cm off the estimate: consistent with σ = 2 cm, fused, the estimate moves towards it.
    let offset = Vector3::new(0.02, 0.0, 0.0);
    estimator.update(
        &model,
        &state,
        &fix_at(truth.position + offset),
        &ALL_STANCE,
        DT,
    );
    let report = estimator.report();
    assert_eq!(report.status, 0);
    // Gain ≈ P/(P + σ²) with the start's σ_p = 1 mm: the estimate moves by about 1e-6/4e-4 of
    // the 2 cm.
    let moved = report.position[0] - truth.position.x;
    assert!(moved > 2e-5 && moved < 2e-4, "{moved}");
    // 5 m off: refused twice, then (third in a row) trusted and relocated to.
    let far = truth.position + Vector3::new(5.0, 0.0, 0.0);
    for expected in [16, 16, 16 | 32] {
        estimator.update(&model, &state, &fix_at(far), &ALL_STANCE, DT);
        assert_eq!(estimator.report().status, expected);
    }
    assert!((estimator.report().position[0] - far.x).abs() < 1e-9);
    // A non-finite fix is refused, never fused.
    estimator.update(
        &model,
        &state,
        &fix_at(Vector3::new(f64::NAN, 0.0, 0.0)),
        &ALL_STANCE,
        DT,
    );
    assert_eq!(estimator.report().status, StatusFlag::FixRejected.bit());
    assert!(estimator.report().position.iter().all(|v| v.is_finite()));
}

#[test]
fn the_estimator_is_deterministic() {
    let model = model();
    let run = || {
        let mut estimator = StateEstimator::new(&model, &kalman_config());
        let mut walk = TrotWalk::new(&model, Vector3::new(0.3, -0.1, 0.0));
        let mut trace = Vec::new();
        for k in 0..1500 {
            let (truth, plan) = walk.at(k as f64 * DT);
            let (state, mut imu) = truth.measure(&model);
            // Deterministic pseudo-noise and a bad sample now and then.
            imu.acc[0] += 0.3 * ((k * 7919 % 1000) as f64 / 1000.0 - 0.5);
            if k % 97 == 0 {
                imu.gyro[0] = f64::NAN;
            }
            let readings = SensorReadings {
                imu,
                fix: PositionFix {
                    position: truth.position.into(),
                    valid: k % 500 == 0,
                },
                ..SensorReadings::default()
            };
            estimator.update(&model, &state, &readings, &plan, DT);
            // Leg effort for the contact detector: deterministic, loading and unloading feet.
            let torques: [f64; NUM_JOINTS] =
                std::array::from_fn(|j| 8.0 * (((k * 31 + j * 17) % 200) as f64 / 100.0 - 1.0));
            estimator.record_applied_torques(&torques);
            trace.extend(
                estimator
                    .detected_contacts()
                    .iter()
                    .map(|c| c.probability.to_bits()),
            );
            let r = estimator.report();
            trace.extend(
                r.position
                    .iter()
                    .chain(&r.velocity)
                    .chain(&r.rpy)
                    .map(|v| v.to_bits()),
            );
            trace.push(u64::from(r.status));
        }
        trace
    };
    assert_eq!(run(), run());
}

/// Through the controller: Kalman mode reads the base pose at the first tick only (a NaN base
/// pose afterwards is not an error) and stands on its estimate.
#[test]
fn the_controller_reads_the_base_pose_once_in_kalman_mode() {
    let model = model();
    let mut controller = Controller::new(model.clone(), kalman_config()).expect("controller");
    let truth = Truth::standing(&model);
    let (mut state, imu) = truth.measure(&model);
    let reference = Reference {
        mode: ModeRequest::Stand,
        ..Reference::default()
    };
    controller
        .step_with_sensors(&state, &sensors(imu), &reference, DT)
        .expect("first tick");
    state.base_position = [f64::NAN; 3];
    state.base_orientation = [f64::NAN; 4];
    state.base_linear_velocity = [f64::NAN; 3];
    state.base_angular_velocity = [f64::NAN; 3];
    for _ in 0..200 {
        let command = controller
            .step_with_sensors(&state, &sensors(imu), &reference, DT)
            .expect("the base pose is not read after the first tick");
        assert!(command.joint_torques.iter().all(|t| t.is_finite()));
        let error = Vector3::from(command.estimate.position) - truth.position;
        assert!(error.norm() < 1e-3, "{error}");
    }
    // Ground-truth mode refuses the same state.
    let mut ground_truth = Controller::new(model, ControllerConfig::default()).expect("controller");
    assert!(ground_truth.step(&state, &reference, DT).is_err());
}

/// The torques that make the fixed-base leg dynamics produce `next` from rates `rates_before`
/// over one tick with `foot_forces_body[leg]` the ground reaction on each foot (base frame):
/// `τ = M q̈ + h − Jᵀf`, what the contact detector inverts.
fn torques_for(
    model: &RobotModel,
    next: &RobotState,
    rates_before: &[f64; NUM_JOINTS],
    gravity_body: Vector3<f64>,
    foot_forces_body: &[Vector3<f64>; NUM_LEGS],
) -> [f64; NUM_JOINTS] {
    let mut torques = [0.0; NUM_JOINTS];
    for leg in Leg::ALL {
        let l = leg.index();
        let q = leg_slice(&next.joint_positions, leg);
        let dq = leg_slice(&next.joint_velocities, leg);
        let before = leg_slice(rates_before, leg);
        let ddq = Vector3::from_fn(|j, _| (dq[j] - before[j]) / DT);
        let bias = Vector3::from(model.leg_bias(leg, q, dq, gravity_body.into()));
        let jacobian = model.foot_kinematics(leg, q).jacobian;
        let tau =
            model.mass_matrix(leg, q) * ddq + bias - jacobian.transpose() * foot_forces_body[l];
        torques[3 * l..3 * l + 3].copy_from_slice(tau.as_slice());
    }
    torques
}

/// The torques of a level trunk at rest whose joints keep the rates of `state` (no joint
/// acceleration) with `foot_forces_body` on the feet.
fn steady_effort(
    model: &RobotModel,
    state: &RobotState,
    foot_forces_body: &[Vector3<f64>; NUM_LEGS],
) -> [f64; NUM_JOINTS] {
    torques_for(
        model,
        state,
        &state.joint_velocities,
        Vector3::new(0.0, 0.0, -GRAVITY),
        foot_forces_body,
    )
}

/// A robot standing still, leg 0 waved in the air, every leg planned `plan`, the others carrying
/// the weight, and the leg effort those motions imply recorded every tick when `with_effort`.
/// Returns the estimator after 1.5 s and the worst position/velocity error after the first 10
/// ticks.
fn standing_with_a_waving_leg(plan: StancePlan, with_effort: bool) -> (StateEstimator, f64) {
    let model = model();
    let mut estimator = StateEstimator::new(&model, &kalman_config());
    let truth = Truth::standing(&model);
    let weight = model.total_mass() * GRAVITY;
    let mut forces = [Vector3::new(0.0, 0.0, weight / 3.0); NUM_LEGS];
    forces[0] = Vector3::zeros();
    let gravity_body = Vector3::new(0.0, 0.0, -GRAVITY);
    let at = |k: usize| {
        let t = k as f64 * DT;
        let mut moving = truth;
        moving.feet[0] += Vector3::new(0.05 * (8.0 * t).sin(), 0.0, 0.04 * (1.0 - (8.0 * t).cos()));
        moving.feet_velocity[0] = Vector3::new(0.4 * (8.0 * t).cos(), 0.0, 0.32 * (8.0 * t).sin());
        moving.measure(&model)
    };
    let mut worst = 0.0_f64;
    let (mut state, mut imu) = at(0);
    for k in 0..1500 {
        let estimate = estimator.update(&model, &state, &sensors(imu), &plan, DT);
        // The first tick has no effort to read yet (the schedule decides).
        if k >= 10 {
            worst = worst.max((estimate.position - truth.position).norm());
            worst = worst.max(estimate.velocity.norm());
        }
        let (next, next_imu) = at(k + 1);
        if with_effort {
            let torques = torques_for(
                &model,
                &next,
                &state.joint_velocities,
                gravity_body,
                &forces,
            );
            estimator.record_applied_torques(&torques);
        }
        (state, imu) = (next, next_imu);
    }
    (estimator, worst)
}

#[test]
fn a_foot_in_scheduled_stance_without_load_is_no_contact() {
    let model = model();
    let weight = model.total_mass() * GRAVITY;
    let (estimator, worst_with_effort) = standing_with_a_waving_leg(ALL_STANCE, true);
    let contacts = estimator.detected_contacts();
    assert!(!contacts[0].in_contact, "{:?}", contacts[0]);
    assert!(contacts[0].probability < 0.1, "{:?}", contacts[0]);
    let unloaded = contacts[0].normal_force.expect("force estimate");
    assert!(
        unloaded.abs() < 0.01 * weight,
        "waving leg force {unloaded} N"
    );
    for contact in &contacts[1..] {
        assert!(contact.in_contact, "{contact:?}");
        let force = contact.normal_force.expect("force estimate");
        assert!(
            (force - weight / 3.0).abs() < 0.01 * weight,
            "loaded leg force {force} N, expected {}",
            weight / 3.0
        );
    }
    // The schedule alone (no effort recorded) takes the waving leg as standing still.
    let (schedule_only, worst_schedule_only) = standing_with_a_waving_leg(ALL_STANCE, false);
    assert!(schedule_only.detected_contacts()[0].normal_force.is_none());
    assert!(
        worst_with_effort < 0.02 && worst_schedule_only > 5.0 * worst_with_effort,
        "with effort {worst_with_effort}, schedule only {worst_schedule_only}"
    );
}

/// 100 ticks of a robot standing still with `knee_rate` on leg 0's knee, a quarter of the weight
/// on every foot (the leg effort recorded says so), leg 0 planned in swing (an early
/// touch-down). Continues `estimator`.
fn loaded_with_leg_0_planned_in_swing(
    model: &RobotModel,
    estimator: &mut StateEstimator,
    knee_rate: f64,
) {
    let weight = model.total_mass() * GRAVITY;
    let (mut state, imu) = Truth::standing(model).measure(model);
    state.joint_velocities[2] = knee_rate;
    let torques = steady_effort(
        model,
        &state,
        &[Vector3::new(0.0, 0.0, weight / 4.0); NUM_LEGS],
    );
    let mut plan = ALL_STANCE;
    plan[0] = None;
    for _ in 0..100 {
        estimator.update(model, &state, &sensors(imu), &plan, DT);
        estimator.record_applied_torques(&torques);
    }
}

#[test]
fn a_loaded_foot_in_scheduled_swing_is_contact() {
    let model = model();
    let weight = model.total_mass() * GRAVITY;
    let mut estimator = StateEstimator::new(&model, &kalman_config());
    loaded_with_leg_0_planned_in_swing(&model, &mut estimator, 0.0);
    let contacts = estimator.detected_contacts();
    for contact in &contacts {
        assert!(contact.in_contact, "{contact:?}");
        let force = contact.normal_force.expect("force estimate");
        assert!(
            (force - weight / 4.0).abs() < 0.01 * weight,
            "force {force} N"
        );
    }
    assert!(contacts[0].probability > 0.8, "{:?}", contacts[0]);
    assert_eq!(
        estimator.report().status & StatusFlag::FootWithoutContact.bit(),
        0
    );
}

#[test]
fn a_leg_at_its_velocity_limit_gives_no_force_evidence() {
    // The same load, but leg 0's knee turns at its velocity limit: whatever its effort implies,
    // the schedule (swing) decides.
    let model = model();
    let limit = model.velocity_limits()[2];
    let mut estimator = StateEstimator::new(&model, &kalman_config());
    loaded_with_leg_0_planned_in_swing(&model, &mut estimator, limit);
    let contacts = estimator.detected_contacts();
    assert!(contacts[0].normal_force.is_none(), "{:?}", contacts[0]);
    assert!(!contacts[0].in_contact, "{:?}", contacts[0]);
    assert!(contacts[0].probability < 0.2, "{:?}", contacts[0]);
    // Just below the limit the effort is evidence again: the loaded foot is in contact.
    loaded_with_leg_0_planned_in_swing(&model, &mut estimator, 0.9 * limit);
    let contact = estimator.detected_contacts()[0];
    assert!(
        contact.in_contact && contact.normal_force.is_some(),
        "{contact:?}"
    );
    for contact in &estimator.detected_contacts()[1..] {
        assert!(contact.in_contact, "{contact:?}");
    }
}

/// Leg 0's readings with its knee `from_stop` rad inside its upper position limit, its hip
/// turning at `hip_rate`, and the leg effort of `load` N on its foot (the robot standing still).
fn leg_0_near_its_knee_stop(
    model: &RobotModel,
    from_stop: f64,
    hip_rate: f64,
    load: f64,
) -> (RobotState, ImuReading, [f64; NUM_JOINTS]) {
    let (mut state, imu) = Truth::standing(model).measure(model);
    state.joint_positions[2] = model.upper_limits()[2] - from_stop;
    state.joint_velocities[1] = hip_rate;
    let mut forces = [Vector3::zeros(); NUM_LEGS];
    forces[0] = Vector3::new(0.0, 0.0, load);
    let torques = steady_effort(model, &state, &forces);
    (state, imu, torques)
}

/// The trunk velocity estimated for a robot standing still whose leg 0, planned mid-stance,
/// first hangs unloaded 0.1 rad from its knee stop for 100 ticks and then, for 300 ticks, has
/// its knee `from_stop` rad inside the stop, its hip turning at 5 rad/s and the effort of a
/// quarter of the weight on its foot; the other legs are planned in swing and carry nothing
/// (a robot pushed off its feet, one leg reaching down).
fn reaching_leg_velocity_error(from_stop: f64) -> f64 {
    let model = model();
    let mut estimator = StateEstimator::new(&model, &kalman_config());
    let weight = model.total_mass() * GRAVITY;
    let plan = [Some(0.5), None, None, None];
    let hanging = leg_0_near_its_knee_stop(&model, 0.1, 0.0, 0.0);
    let reaching = leg_0_near_its_knee_stop(&model, from_stop, 5.0, weight / 4.0);
    let mut velocity = f64::NAN;
    for k in 0..400 {
        let (state, imu, torques) = if k < 100 { &hanging } else { &reaching };
        velocity = estimator
            .update(&model, state, &sensors(*imu), &plan, DT)
            .velocity
            .norm();
        estimator.record_applied_torques(torques);
    }
    velocity
}

#[test]
fn a_leg_against_its_stop_keeps_the_contact_it_had() {
    // At the stop the stop's reaction reads as a load on a foot in the air; the force from before
    // the stop holds, so the leg stays out of contact and the trunk, standing still, is
    // estimated still although that leg's kinematics say it moves at about 1.9 m/s.
    let at_stop = reaching_leg_velocity_error(0.005);
    assert!(at_stop < 0.05, "velocity error {at_stop} m/s at the stop");
    // Away from the stop the same load is a contact, the leg is the only trusted foot and the
    // slip gate keeps it: the estimate follows its kinematics.
    let away = reaching_leg_velocity_error(0.1);
    assert!(away > 0.5, "velocity error {away} m/s away from the stop");
    // A loaded leg that reaches its stop stays in contact, even where the stop takes the load
    // off what its effort shows.
    let model = model();
    let weight = model.total_mass() * GRAVITY;
    let mut estimator = StateEstimator::new(&model, &kalman_config());
    for (from_stop, load) in [(0.1, weight / 4.0), (0.005, 0.0)] {
        let (state, imu, torques) = leg_0_near_its_knee_stop(&model, from_stop, 0.0, load);
        for _ in 0..100 {
            estimator.update(&model, &state, &sensors(imu), &ALL_STANCE, DT);
            estimator.record_applied_torques(&torques);
        }
        let contact = estimator.detected_contacts()[0];
        assert!(
            contact.in_contact,
            "{from_stop} rad from the stop: {contact:?}"
        );
    }
}

/// A robot standing still whose foot 0 slides back and forth on `sliding(t)` (its velocity then);
/// the status bits seen before and after `split` s.
fn standing_with_a_sliding_foot(
    sliding: impl Fn(f64) -> Option<Vector3<f64>>,
    ticks: usize,
    split: f64,
) -> (u32, u32) {
    let model = model();
    let mut estimator = StateEstimator::new(&model, &kalman_config());
    let truth = Truth::standing(&model);
    let mut offset = Vector3::zeros();
    let (mut before, mut after) = (0, 0);
    for k in 0..ticks {
        let t = k as f64 * DT;
        let mut moving = truth;
        if let Some(velocity) = sliding(t) {
            offset += velocity * DT;
            moving.feet_velocity[0] = velocity;
        }
        moving.feet[0] += offset;
        let (state, imu) = moving.measure(&model);
        estimator.update(&model, &state, &sensors(imu), &ALL_STANCE, DT);
        let status = estimator.report().status;
        if t < split {
            before |= status;
        } else {
            after |= status;
        }
    }
    (before, after)
}

#[test]
fn a_foot_slipping_on_many_ticks_makes_the_odometry_doubtful_and_an_occasional_slip_does_not() {
    let doubtful = StatusFlag::OdometryDoubtful.bit();
    let slip = StatusFlag::FootSlip.bit();
    // One quick slip of 50 ms every second: flagged as slips, not as doubtful odometry.
    let occasional = |t: f64| {
        (t.fract() > 0.5 && t.fract() < 0.55)
            .then(|| Vector3::new(0.8 * (std::f64::consts::PI * t).cos().signum(), 0.0, 0.0))
    };
    let (before, after) = standing_with_a_sliding_foot(occasional, 4000, 2.0);
    assert!(
        before & slip != 0 && after & slip != 0,
        "{before:#x} {after:#x}"
    );
    assert_eq!((before | after) & doubtful, 0, "{:#x}", before | after);
    // The foot skating for good from 1 s on (back and forth, 0.6 m/s): doubtful within 0.5 s.
    let skating =
        |t: f64| (t >= 1.0).then(|| Vector3::new(0.6 * (8.0 * t).sin().signum(), 0.0, 0.0));
    let (before, _) = standing_with_a_sliding_foot(skating, 1500, 1.0);
    assert_eq!(before & (doubtful | slip), 0, "{before:#x}");
    let (_, skated) = standing_with_a_sliding_foot(skating, 2500, 1.5);
    assert!(skated & doubtful != 0, "{skated:#x}");
}
