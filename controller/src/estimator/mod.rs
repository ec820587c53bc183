//! State estimation from what a real robot measures: IMU (gyro, accelerometer), joint encoders,
//! optional foot contact sensors and an optional absolute position fix. The structure of MIT
//! Cheetah-Software: an orientation filter ([`orientation`]) feeds the rotation to an 18-state
//! linear Kalman filter of trunk position/velocity and foot positions ([`kalman`]) whose
//! measurements are leg kinematics. Design, noise values and their reasons: `docs/estimation.md`.
//!
//! The base pose of [`RobotState`] is read once, at the first tick, to place the robot (a robot
//! started at a known pose, at rest); afterwards only the joints of `RobotState` are read.
//! Bad sensor input never makes the estimate non-finite: it is held, clamped or skipped, and
//! reported in the status word ([`StatusFlag`]).

pub mod contact;
pub mod kalman;
pub mod orientation;
mod status;
#[cfg(test)]
mod tests;

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

pub use status::{EstimatorStatus, StatusFlag};

use crate::api::{
    ContactReading, EstimateReport, EstimatorKind, Leg, RobotState, SensorReadings, GRAVITY,
    NUM_JOINTS, NUM_LEGS,
};
use crate::config::ControllerConfig;
use crate::estimate::{leg_slice, BaseState, Estimate};
use crate::gait::Gait;
use crate::model::RobotModel;
use contact::{ContactDetector, ContactInputs, LegContact};
use kalman::{FixOutcome, LegKalman};
use orientation::{OrientationFilter, OrientationNoise};

/// The stance schedule per leg: `Some(progress)` (0 → 1 through the stance) for a leg planned in
/// stance, `None` for a leg planned in swing.
pub type StancePlan = [Option<f64>; NUM_LEGS];

/// Fraction of a stance at its start and its end over which the leg-kinematics noise ramps from
/// the swing value to the stance value (Cheetah-Software's trust window): the touch-down may come
/// early or late and the foot settles, lift-off unloads it.
pub const TRUST_WINDOW: f64 = 0.2;
/// Squared Mahalanobis distance beyond which a position fix is refused (3 degrees of freedom:
/// P(χ² > 25) ≈ 1.5·10⁻⁵ for a consistent filter).
pub const FIX_GATE_CHI2: f64 = 25.0;
/// Squared Mahalanobis distance of a stance foot's implied trunk velocity from the predicted
/// velocity beyond which the foot counts as slipping (3 degrees of freedom: P(χ² > 16.3) = 10⁻³
/// for a consistent filter). Feet sliding down a flank moved the estimate by 0.47 m sideways and
/// 0.26 m up in 6 s of turning in place (c_shape, depth camera) before this gate.
pub const SLIP_GATE_CHI2: f64 = 16.27;
/// Consecutive refused fixes after which the filter trusts the fixes and relocates to them (a
/// filter whose own position has drifted away would otherwise refuse every fix for good).
pub const FIX_REJECTIONS_BEFORE_RELOCATION: u32 = 3;
/// A foot out of contact for longer than this many swing durations (at least
/// [`MIN_CONTACT_TIMEOUT`]) sets [`StatusFlag::FootWithoutContact`].
pub const CONTACT_TIMEOUT_SWINGS: f64 = 3.0;
/// Smallest contact timeout, s.
pub const MIN_CONTACT_TIMEOUT: f64 = 1.0;
/// Time constant of the running share of ticks on which the slip gate dropped a stance foot, s.
pub const SLIP_SHARE_TIME: f64 = 1.0;
/// Running slip share above which [`StatusFlag::OdometryDoubtful`] is set. Feet that really
/// slip, or contacts the detector misjudges, make the leg kinematics disagree with the
/// prediction this often: ANYmal C with its knees at their velocity limits dropped a foot on
/// 17 % of its ticks and its height estimate drifted 0.4 m in 20 s; a sound walk drops one on
/// 0.2–1.3 % (docs/robots.md).
pub const DOUBTFUL_SLIP_SHARE: f64 = 0.12;

/// Noise values of the Kalman filter (from [`ControllerConfig`]).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
struct LegNoise {
    acc_density: f64,
    leg_position_variance: f64,
    leg_velocity_variance: f64,
    foot_drift: f64,
    /// Variance of the robot's horizontal translation per metre walked, m²/m.
    odometry_variance_per_metre: f64,
    fix_sigma: f64,
    swing_factor: f64,
    /// Rolling radius of a stance foot, m (foot radius × `est_foot_rolling`).
    rolling_radius: f64,
}

impl LegNoise {
    /// Factor on each leg's kinematics noise from its trust (1 trusted … 1 + swing_factor swinging).
    fn suspicion(&self, trust: [f64; NUM_LEGS]) -> [f64; NUM_LEGS] {
        trust.map(|t| 1.0 + (1.0 - t) * self.swing_factor)
    }
}

/// The two filters, created at the first tick.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Filters {
    orientation: OrientationFilter,
    kalman: LegKalman,
    /// The last state that passed the health check (restart point after a numerical failure).
    last_good: BaseState,
}

/// The estimator stage: ground truth or the filters, per [`EstimatorKind`].
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StateEstimator {
    kind: EstimatorKind,
    orientation_noise: OrientationNoise,
    leg_noise: LegNoise,
    gyro_limit: f64,
    contact_timeout: f64,
    filters: Option<Filters>,
    last_gyro: Vector3<f64>,
    time_without_contact: [f64; NUM_LEGS],
    fix_rejections: u32,
    contact_detector: ContactDetector,
    contacts: [LegContact; NUM_LEGS],
    /// Time since each leg's detected touch-down, s.
    time_in_contact: [f64; NUM_LEGS],
    /// Over how long after a detected touch-down the leg's trust ramps up, s.
    settle_time: f64,
    /// Running share of ticks on which the slip gate dropped a stance foot.
    slip_share: f64,
    report: EstimateReport,
}

/// How much a leg's kinematics are trusted this tick: 1 in mid-stance, 0 in swing, ramped in the
/// trust window at both ends of a scheduled stance.
pub fn leg_trust(reading: ContactReading, planned: Option<f64>) -> f64 {
    match reading {
        ContactReading::InContact => 1.0,
        ContactReading::NoContact => 0.0,
        ContactReading::Unknown => planned.map_or(0.0, |s| {
            (s / TRUST_WINDOW)
                .min((1.0 - s) / TRUST_WINDOW)
                .clamp(0.0, 1.0)
        }),
    }
}

impl StateEstimator {
    /// The estimator configured by `config` (nothing is estimated before the first tick).
    pub fn new(model: &RobotModel, config: &ControllerConfig) -> Self {
        let gait = Gait::new(config.gait, config.gait_period);
        StateEstimator {
            kind: config.estimator,
            orientation_noise: OrientationNoise::from_config(config),
            leg_noise: LegNoise {
                acc_density: config.est_acc_noise,
                leg_position_variance: config.est_leg_position_noise.powi(2),
                leg_velocity_variance: config.est_leg_velocity_noise.powi(2),
                foot_drift: config.est_foot_drift,
                odometry_variance_per_metre: config.est_odometry_drift.powi(2),
                fix_sigma: config.est_fix_noise,
                swing_factor: config.est_swing_noise_factor,
                rolling_radius: config.est_foot_rolling * model.foot_radius(),
            },
            gyro_limit: config.est_gyro_limit,
            contact_timeout: (CONTACT_TIMEOUT_SWINGS * gait.swing_time()).max(MIN_CONTACT_TIMEOUT),
            filters: None,
            last_gyro: Vector3::zeros(),
            time_without_contact: [0.0; NUM_LEGS],
            fix_rejections: 0,
            slip_share: 0.0,
            contact_detector: ContactDetector::new(model),
            contacts: [LegContact {
                probability: 1.0,
                in_contact: true,
                normal_force: None,
            }; NUM_LEGS],
            // The robot starts standing, its feet settled.
            time_in_contact: [TRUST_WINDOW * gait.stance_time(); NUM_LEGS],
            settle_time: TRUST_WINDOW * gait.stance_time(),
            report: EstimateReport::default(),
        }
    }

    /// Whether this tick reads the base pose/twist of the measured state (ground truth always,
    /// Kalman only at its first tick).
    pub fn reads_base_state(&self) -> bool {
        self.kind == EstimatorKind::GroundTruth || self.filters.is_none()
    }

    /// The estimate of the last tick, and the status it came with.
    pub fn report(&self) -> EstimateReport {
        self.report
    }

    /// Records the joint torques sent to the motors on this tick: the leg effort the contact
    /// detector reads on the next tick.
    pub fn record_applied_torques(&mut self, torques: &[f64; NUM_JOINTS]) {
        self.contact_detector.record_applied_torques(torques);
    }

    /// The force-based contact detector's view of each leg on the last Kalman tick.
    pub fn detected_contacts(&self) -> [LegContact; NUM_LEGS] {
        self.contacts
    }

    /// Gyro bias estimate, body frame, rad/s (zero before the first Kalman tick or in
    /// ground-truth mode).
    pub fn gyro_bias(&self) -> [f64; 3] {
        self.filters
            .as_ref()
            .map_or([0.0; 3], |f| f.orientation.bias().into())
    }

    /// One tick: the estimate the later stages run on. `state` must be validated (its base
    /// fields only when [`StateEstimator::reads_base_state`]); `sensors` may hold anything.
    pub fn update(
        &mut self,
        model: &RobotModel,
        state: &RobotState,
        sensors: &SensorReadings,
        plan: &StancePlan,
        dt: f64,
    ) -> Estimate {
        let (estimate, status) = match self.kind {
            EstimatorKind::GroundTruth => (
                Estimate::from_measurement(model, state),
                EstimatorStatus::HEALTHY,
            ),
            EstimatorKind::Kalman => self.kalman_tick(model, state, sensors, plan, dt),
        };
        let (position_variance, attitude_variance) =
            self.filters.as_ref().map_or(([0.0; 3], [0.0; 3]), |f| {
                let p = f.kalman.position_covariance();
                (
                    [p[(0, 0)], p[(1, 1)], p[(2, 2)]],
                    f.orientation.attitude_variance(),
                )
            });
        self.report = EstimateReport {
            position: estimate.position.into(),
            velocity: estimate.velocity.into(),
            rpy: estimate.rpy.into(),
            position_variance,
            attitude_variance,
            status: status.bits(),
        };
        estimate
    }

    /// The filters placed at the measured base pose, at rest.
    fn start_filters(&self, state: &RobotState, feet_body: &[Vector3<f64>; NUM_LEGS]) -> Filters {
        let o = state.base_orientation;
        let start = BaseState {
            attitude: UnitQuaternion::from_quaternion(Quaternion::new(o[0], o[1], o[2], o[3])),
            position: Vector3::from(state.base_position),
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
        };
        self.filters_at(&start, feet_body, kalman::INITIAL_POSITION_SIGMA)
    }

    /// Filters at `base` with the feet at `feet_body` (base frame) and position σ `position_sigma`.
    fn filters_at(
        &self,
        base: &BaseState,
        feet_body: &[Vector3<f64>; NUM_LEGS],
        position_sigma: f64,
    ) -> Filters {
        let feet = feet_body.map(|foot| base.position + base.attitude * foot);
        Filters {
            orientation: OrientationFilter::new(base.attitude, self.orientation_noise),
            kalman: LegKalman::new(base.position, base.velocity, &feet, position_sigma),
            last_good: *base,
        }
    }

    /// The gyro reading to use: the last valid one for a non-finite reading, clamped to the
    /// full-scale range.
    fn checked_gyro(&mut self, gyro: [f64; 3], status: &mut EstimatorStatus) -> Vector3<f64> {
        if gyro.iter().any(|g| !g.is_finite()) {
            status.set(StatusFlag::GyroInvalid);
            return self.last_gyro;
        }
        let limit = self.gyro_limit;
        if gyro.iter().any(|g| g.abs() >= limit) {
            status.set(StatusFlag::GyroSaturated);
        }
        self.last_gyro = Vector3::from(gyro).map(|g| g.clamp(-limit, limit));
        self.last_gyro
    }

    fn kalman_tick(
        &mut self,
        model: &RobotModel,
        state: &RobotState,
        sensors: &SensorReadings,
        plan: &StancePlan,
        dt: f64,
    ) -> (Estimate, EstimatorStatus) {
        let mut status = EstimatorStatus::HEALTHY;
        let gyro = self.checked_gyro(sensors.imu.gyro, &mut status);
        let feet =
            Leg::ALL.map(|leg| model.foot_kinematics(leg, leg_slice(&state.joint_positions, leg)));
        let feet_body = feet.map(|foot| foot.position);
        let mut filters = match self.filters.take() {
            Some(filters) => filters,
            None => self.start_filters(state, &feet_body),
        };
        let noise = self.leg_noise;

        // Orientation: gyro prediction, accelerometer tilt correction.
        let body_rate = filters.orientation.predict(&gyro, dt);
        let acc = Vector3::from(sensors.imu.acc);
        let acc_valid = acc.iter().all(|a| a.is_finite());
        if acc_valid {
            filters.orientation.correct_with_accelerometer(&acc);
        } else {
            status.set(StatusFlag::AccInvalid);
        }
        let attitude = filters.orientation.attitude();
        let rotation = *attitude.to_rotation_matrix().matrix();

        // Kalman prediction: the specific force back into a world acceleration.
        let acceleration = if acc_valid {
            rotation * acc - Vector3::new(0.0, 0.0, GRAVITY)
        } else {
            Vector3::zeros()
        };
        // Contact: a sensor's reading when there is one, else the leg effort fused with the
        // schedule (the schedule alone before the detector has torques to read).
        let schedule_trust = plan.map(|planned| leg_trust(ContactReading::Unknown, planned));
        let effective_gravity_body = if acc_valid {
            -acc
        } else {
            rotation.transpose() * Vector3::new(0.0, 0.0, -GRAVITY)
        };
        self.contacts = self.contact_detector.update(
            model,
            &ContactInputs {
                joint_positions: &state.joint_positions,
                joint_rates: &state.joint_velocities,
                effective_gravity_body,
                rotation: &rotation,
                feet: &feet,
                schedule_trust,
            },
            dt,
        );
        let detected = self.contacts;
        for (time, contact) in self.time_in_contact.iter_mut().zip(&detected) {
            *time = if contact.in_contact { *time + dt } else { 0.0 };
        }
        // A detected contact is trusted as much as it is probable, ramped in over the settling
        // after its touch-down (whenever that came) and out towards a planned lift-off.
        let trust: [f64; NUM_LEGS] = std::array::from_fn(|l| match sensors.contacts[l] {
            ContactReading::Unknown if detected[l].normal_force.is_some() => {
                if detected[l].in_contact {
                    let settled = (self.time_in_contact[l] / self.settle_time).min(1.0);
                    let before_lift_off =
                        plan[l].map_or(1.0, |s| ((1.0 - s) / TRUST_WINDOW).clamp(0.0, 1.0));
                    detected[l].probability * settled * before_lift_off
                } else {
                    0.0
                }
            }
            reading => leg_trust(reading, plan[l]),
        });
        // Leg kinematics' trunk velocity from every foot trusted to stand still.
        let omega_body = body_rate;
        let leg_velocity: [Option<Vector3<f64>>; NUM_LEGS] = std::array::from_fn(|l| {
            (trust[l] > 0.0).then(|| {
                let foot = &feet[l];
                let dq = Vector3::from(leg_slice(&state.joint_velocities, Leg::ALL[l]));
                let foot_velocity_body = foot.jacobian * dq + omega_body.cross(&foot.position);
                // A sphere foot rolls while it stands: its contact point is still, its centre
                // moves at ω_foot × r·ẑ (about 4 cm/s when trotting at 0.5 m/s, a 7 % bias on
                // the trunk velocity if ignored).
                let foot_rate_world = rotation * (omega_body + foot.angular_jacobian * dq);
                let rolling = foot_rate_world.cross(&Vector3::new(0.0, 0.0, noise.rolling_radius));
                rolling - rotation * foot_velocity_body
            })
        });
        let trust = self.without_slipping_feet(
            &filters.kalman,
            trust,
            &leg_velocity,
            &acceleration,
            dt,
            &mut status,
        );
        self.track_slip_share(dt, &mut status);
        let suspicion = noise.suspicion(trust);
        let foot_density = suspicion.map(|k| noise.foot_drift * k.sqrt());
        let walked = filters.kalman.velocity().xy().norm() * dt;
        filters.kalman.predict(
            &acceleration,
            dt,
            noise.acc_density,
            &foot_density,
            noise.odometry_variance_per_metre * walked,
        );

        // Leg kinematics: every foot relative to the trunk; the trunk velocity from the feet
        // trusted to stand still.
        for l in 0..NUM_LEGS {
            let relative = rotation * feet[l].position;
            let velocity = leg_velocity[l].filter(|_| trust[l] > 0.0);
            filters.kalman.update_leg(
                l,
                &relative,
                noise.leg_position_variance * suspicion[l],
                velocity
                    .as_ref()
                    .map(|v| (v, noise.leg_velocity_variance * suspicion[l])),
            );
        }
        filters.kalman.symmetrise();

        // Absolute position fix, once per arrival.
        if sensors.fix.valid {
            self.fuse_fix(
                &mut filters,
                &Vector3::from(sensors.fix.position),
                &mut status,
            );
        }

        let in_contact: [bool; NUM_LEGS] = std::array::from_fn(|l| match sensors.contacts[l] {
            ContactReading::InContact => true,
            ContactReading::NoContact => false,
            ContactReading::Unknown => match detected[l].normal_force {
                Some(_) => detected[l].in_contact,
                None => plan[l].is_some(),
            },
        });
        self.track_contacts(&in_contact, dt, &mut status);

        if filters.kalman.is_healthy() && filters.orientation.is_healthy() {
            filters.last_good = BaseState {
                attitude,
                position: filters.kalman.position(),
                velocity: filters.kalman.velocity(),
                angular_velocity: rotation * omega_body,
            };
        } else {
            status.set(StatusFlag::CovarianceReset);
            tracing::warn!("estimator diverged: restarting from the last healthy state");
            // Restarted with the velocity it had and a position as uncertain as a fix.
            filters = self.filters_at(&filters.last_good, &feet_body, self.leg_noise.fix_sigma);
        }
        let estimate = Estimate::from_base(&filters.last_good, state, &feet_body);
        self.filters = Some(filters);
        (estimate, status)
    }

    /// `trust` with every slipping stance foot set to 0 (a swinging foot for this tick): a foot
    /// whose implied trunk velocity fails [`SLIP_GATE_CHI2`] against the prediction while
    /// another trusted foot passes it. When every trusted foot fails, the prediction itself is
    /// in doubt (a push, a stumble) and all of them are kept.
    fn without_slipping_feet(
        &self,
        kalman: &LegKalman,
        trust: [f64; NUM_LEGS],
        leg_velocity: &[Option<Vector3<f64>>; NUM_LEGS],
        acceleration: &Vector3<f64>,
        dt: f64,
        status: &mut EstimatorStatus,
    ) -> [f64; NUM_LEGS] {
        let suspicion = self.leg_noise.suspicion(trust);
        let passes: [Option<bool>; NUM_LEGS] = std::array::from_fn(|l| {
            leg_velocity[l].map(|v| {
                let variance = self.leg_noise.leg_velocity_variance * suspicion[l];
                kalman
                    .velocity_distance2(&v, variance, acceleration, dt)
                    .is_some_and(|d2| d2 <= SLIP_GATE_CHI2)
            })
        });
        if !passes.contains(&Some(true)) {
            return trust;
        }
        let mut kept = trust;
        for (t, pass) in kept.iter_mut().zip(passes) {
            if pass == Some(false) {
                *t = 0.0;
                status.set(StatusFlag::FootSlip);
            }
        }
        kept
    }

    fn fuse_fix(
        &mut self,
        filters: &mut Filters,
        fix: &Vector3<f64>,
        status: &mut EstimatorStatus,
    ) {
        let sigma = self.leg_noise.fix_sigma;
        if !fix.iter().all(|v| v.is_finite()) {
            status.set(StatusFlag::FixRejected);
            return;
        }
        match filters.kalman.fuse_fix(fix, sigma * sigma, FIX_GATE_CHI2) {
            FixOutcome::Fused => self.fix_rejections = 0,
            FixOutcome::Rejected => {
                status.set(StatusFlag::FixRejected);
                self.fix_rejections += 1;
                if self.fix_rejections >= FIX_REJECTIONS_BEFORE_RELOCATION {
                    let offset = fix - filters.kalman.position();
                    filters.kalman.relocate(&offset, sigma);
                    status.set(StatusFlag::CovarianceReset);
                    self.fix_rejections = 0;
                    tracing::warn!(
                        offset = offset.norm(),
                        "estimator relocated to repeated position fixes"
                    );
                }
            }
        }
    }

    /// The running share of ticks with a foot dropped at the slip gate; above
    /// [`DOUBTFUL_SLIP_SHARE`] the leg odometry is flagged (and logged once as it crosses).
    fn track_slip_share(&mut self, dt: f64, status: &mut EstimatorStatus) {
        let slipped = status.bits() & StatusFlag::FootSlip.bit() != 0;
        let was_doubtful = self.slip_share > DOUBTFUL_SLIP_SHARE;
        let sample = if slipped { 1.0 } else { 0.0 };
        self.slip_share += (sample - self.slip_share) * (dt / (SLIP_SHARE_TIME + dt));
        if self.slip_share > DOUBTFUL_SLIP_SHARE {
            status.set(StatusFlag::OdometryDoubtful);
            if !was_doubtful {
                tracing::warn!(
                    slip_share = self.slip_share,
                    "leg odometry doubtful: stance feet disagree with the prediction on {:.0} % of ticks (slipping feet or misjudged contacts); the position estimate may drift",
                    100.0 * self.slip_share
                );
            }
        }
    }

    fn track_contacts(
        &mut self,
        in_contact: &[bool; NUM_LEGS],
        dt: f64,
        status: &mut EstimatorStatus,
    ) {
        for (time, &contact) in self.time_without_contact.iter_mut().zip(in_contact) {
            *time = if contact { 0.0 } else { *time + dt };
            if *time > self.contact_timeout {
                status.set(StatusFlag::FootWithoutContact);
            }
        }
        if !in_contact.iter().any(|&c| c) {
            status.set(StatusFlag::NoStance);
        }
    }
}
