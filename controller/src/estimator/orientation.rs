//! Attitude and gyro bias from gyro + accelerometer: a multiplicative error-state Kalman filter
//! (6 error states: attitude error in the body frame, gyro bias). The gyro drives the prediction;
//! the accelerometer corrects roll and pitch (and the bias of the axes it sees). While walking it
//! measures the trunk's accelerations too; they average out over a gait cycle, so every sample is
//! used with a noise (`est_acc_tilt_noise`, 10 m/s²) that makes the correction an average over
//! many cycles. Only an implausible innovation (an impact) is refused. A gate on |f| ≈ g would
//! pick the samples of some phases of the gait, whose mean acceleration is not zero: on a trot it
//! tilted the estimate by about 2°, and the leg odometry, rotated by that tilt, sank by 2.5 % of
//! the distance walked. Yaw and the bias about gravity are not observable from these two sensors:
//! the update leaves them alone and their variance grows.

use nalgebra::{Matrix3, SMatrix, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::api::GRAVITY;
use crate::config::ControllerConfig;

type Matrix6 = SMatrix<f64, 6, 6>;

/// An accelerometer sample whose innovation has a squared Mahalanobis distance beyond this is
/// not used (3 dof, P ≈ 10⁻³ for a consistent filter): an impact is no gravity reference.
pub const ACC_INNOVATION_GATE_CHI2: f64 = 16.27;
/// Initial attitude standard deviation, rad (the start pose is given).
const INITIAL_ATTITUDE_SIGMA: f64 = 0.01;
/// Initial gyro-bias standard deviation, rad/s (typical MEMS turn-on bias).
const INITIAL_BIAS_SIGMA: f64 = 0.01;
/// A covariance diagonal beyond this (rad², (rad/s)²) means the filter has run away.
const MAX_VARIANCE: f64 = 1e3;
/// Largest gyro bias the filter may estimate per axis, rad/s (datasheet turn-on bias is
/// below 0.05 rad/s; beyond that the "bias" would be a modelling error absorbed).
const MAX_BIAS: f64 = 0.2;

/// Noise model of the orientation filter.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct OrientationNoise {
    /// Gyro white-noise density, rad/s/√Hz.
    pub gyro: f64,
    /// Gyro bias random-walk density, rad/s²/√Hz.
    pub gyro_bias_walk: f64,
    /// Accelerometer standard deviation as a gravity reference, m/s².
    pub acc_tilt: f64,
}

impl OrientationNoise {
    /// The noise model of `config` (`est_gyro_noise`, `est_gyro_bias_walk`, `est_acc_tilt_noise`).
    pub fn from_config(config: &ControllerConfig) -> Self {
        OrientationNoise {
            gyro: config.est_gyro_noise,
            gyro_bias_walk: config.est_gyro_bias_walk,
            acc_tilt: config.est_acc_tilt_noise,
        }
    }
}

/// Attitude (body → world) and gyro bias with their error covariance.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct OrientationFilter {
    attitude: UnitQuaternion<f64>,
    bias: Vector3<f64>,
    covariance: Matrix6,
    noise: OrientationNoise,
}

impl OrientationFilter {
    /// A filter at `attitude` with zero bias.
    pub fn new(attitude: UnitQuaternion<f64>, noise: OrientationNoise) -> Self {
        let mut filter = OrientationFilter {
            attitude,
            bias: Vector3::zeros(),
            covariance: Matrix6::zeros(),
            noise,
        };
        filter.reset_covariance();
        filter
    }

    /// The initial covariance (also after a detected numerical failure).
    pub fn reset_covariance(&mut self) {
        let mut p = Matrix6::zeros();
        for i in 0..3 {
            p[(i, i)] = INITIAL_ATTITUDE_SIGMA.powi(2);
            p[(i + 3, i + 3)] = INITIAL_BIAS_SIGMA.powi(2);
        }
        self.covariance = p;
    }

    /// Body → world attitude.
    pub fn attitude(&self) -> UnitQuaternion<f64> {
        self.attitude
    }

    /// Gyro bias estimate, body frame, rad/s.
    pub fn bias(&self) -> Vector3<f64> {
        self.bias
    }

    /// Variance of the attitude error about the body axes, rad².
    pub fn attitude_variance(&self) -> [f64; 3] {
        [0, 1, 2].map(|i| self.covariance[(i, i)])
    }

    /// Whether the state and covariance are finite and bounded.
    pub fn is_healthy(&self) -> bool {
        self.attitude.coords.iter().all(|v| v.is_finite())
            && self.bias.iter().all(|v| v.is_finite())
            && (0..6).all(|i| (0.0..MAX_VARIANCE).contains(&self.covariance[(i, i)]))
    }

    /// Propagates by `dt` with the (valid, clamped) gyro reading `gyro` (body frame, rad/s).
    /// Returns the bias-corrected body rate.
    pub fn predict(&mut self, gyro: &Vector3<f64>, dt: f64) -> Vector3<f64> {
        let rate = gyro - self.bias;
        self.attitude *= UnitQuaternion::from_scaled_axis(rate * dt);
        // Error dynamics: δθ' = −[ω]× δθ − δb, δb' = noise; first-order transition matrix.
        let mut f = Matrix6::identity();
        let rotation_step = Matrix3::identity() - (rate * dt).cross_matrix();
        f.fixed_view_mut::<3, 3>(0, 0).copy_from(&rotation_step);
        f.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-Matrix3::identity() * dt));
        self.covariance = f * self.covariance * f.transpose();
        let q_attitude = self.noise.gyro.powi(2) * dt;
        let q_bias = self.noise.gyro_bias_walk.powi(2) * dt;
        for i in 0..3 {
            self.covariance[(i, i)] += q_attitude;
            self.covariance[(i + 3, i + 3)] += q_bias;
        }
        rate
    }

    /// Corrects roll, pitch and the bias with the specific force `acc` (body frame, m/s²) unless
    /// its innovation is implausible. Returns whether it was used.
    pub fn correct_with_accelerometer(&mut self, acc: &Vector3<f64>) -> bool {
        // Predicted specific force at rest: gravity's reaction in the body frame. With the true
        // attitude R·Exp(δθ), f ≈ f̂ + [f̂]× δθ.
        let predicted = self
            .attitude
            .inverse_transform_vector(&Vector3::new(0.0, 0.0, GRAVITY));
        let jacobian = predicted.cross_matrix();
        let variance = self.noise.acc_tilt.powi(2);
        let attitude_covariance = self.covariance.fixed_view::<3, 3>(0, 0).into_owned();
        let innovation_covariance =
            jacobian * attitude_covariance * jacobian.transpose() + Matrix3::identity() * variance;
        let innovation = acc - predicted;
        let Some(inverse) = innovation_covariance.try_inverse() else {
            return false;
        };
        if innovation.dot(&(inverse * innovation)) > ACC_INNOVATION_GATE_CHI2 {
            return false;
        }
        // The accelerometer cannot see a rotation about gravity nor the bias along it, but a
        // linearised filter learns both from the attitude–bias cross-covariance, and walking
        // accelerations that pass the gates then turn into a false vertical bias: on the c_shape
        // walk, 0.006 rad/s and 18° of yaw in 55 s against a true bias of 4·10⁻⁵ rad/s. So the
        // gain is projected off the gravity axis (observability-constrained update), and the
        // Joseph form keeps the covariance right for that suboptimal gain.
        let mut h = SMatrix::<f64, 3, 6>::zeros();
        h.fixed_view_mut::<3, 3>(0, 0).copy_from(&jacobian);
        let mut gain: SMatrix<f64, 6, 3> = self.covariance * h.transpose() * inverse;
        let vertical = predicted / GRAVITY;
        let off_vertical = Matrix3::identity() - vertical * vertical.transpose();
        for block in [0, 3] {
            let projected = off_vertical * gain.fixed_view::<3, 3>(block, 0);
            gain.fixed_view_mut::<3, 3>(block, 0).copy_from(&projected);
        }
        let error = gain * innovation;
        let update = Matrix6::identity() - gain * h;
        self.covariance =
            update * self.covariance * update.transpose() + gain * gain.transpose() * variance;
        self.covariance = 0.5 * (self.covariance + self.covariance.transpose());
        let attitude_error = Vector3::new(error[0], error[1], error[2]);
        self.attitude *= UnitQuaternion::from_scaled_axis(attitude_error);
        let bias_error = Vector3::new(error[3], error[4], error[5]);
        self.bias = (self.bias + bias_error).map(|b| b.clamp(-MAX_BIAS, MAX_BIAS));
        true
    }
}
