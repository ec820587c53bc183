//! The linear Kalman filter of MIT Cheetah-Software's `LinearKFPositionVelocityEstimator`:
//! 18 states, world frame — trunk position (0..3), trunk velocity (3..6) and the four foot
//! positions (6..18). The accelerometer (rotated into the world, gravity removed) drives the
//! prediction, the feet are constant; leg kinematics measure each foot relative to the trunk
//! and each stance foot's velocity relative to the trunk.
//!
//! Every measurement row has one or two ±1 entries and the measurement noise is diagonal, so
//! the update is done as sequential scalar updates: exactly the batch update, without forming
//! or inverting the 24×24 innovation covariance.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::{Deserialize, Serialize};

use crate::api::NUM_LEGS;

/// Number of filter states.
pub const STATES: usize = 6 + 3 * NUM_LEGS;
type StateVector = SVector<f64, STATES>;
type StateMatrix = SMatrix<f64, STATES, STATES>;

const POSITION: usize = 0;
const VELOCITY: usize = 3;
fn foot(leg: usize) -> usize {
    6 + 3 * leg
}

/// Initial standard deviations at the placed start: position and feet, m; velocity, m/s.
pub const INITIAL_POSITION_SIGMA: f64 = 1e-3;
const INITIAL_VELOCITY_SIGMA: f64 = 0.05;
const INITIAL_FOOT_SIGMA: f64 = 0.01;
/// A covariance diagonal beyond this (m², (m/s)²) means the filter has run away.
const MAX_VARIANCE: f64 = 1e6;

/// Trunk position/velocity and foot positions with their covariance.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LegKalman {
    x: StateVector,
    p: StateMatrix,
}

/// Outcome of fusing a position fix.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FixOutcome {
    /// Fused.
    Fused,
    /// Refused by the gate (state untouched).
    Rejected,
}

impl LegKalman {
    /// A filter at rest at `position` with feet at `feet` (world frame).
    pub fn new(
        position: Vector3<f64>,
        velocity: Vector3<f64>,
        feet: &[Vector3<f64>; NUM_LEGS],
        position_sigma: f64,
    ) -> Self {
        let mut filter = LegKalman {
            x: StateVector::zeros(),
            p: StateMatrix::zeros(),
        };
        filter.reset(position, velocity, feet, position_sigma);
        filter
    }

    /// Puts the state at the given values with the initial covariance (position σ given).
    pub fn reset(
        &mut self,
        position: Vector3<f64>,
        velocity: Vector3<f64>,
        feet: &[Vector3<f64>; NUM_LEGS],
        position_sigma: f64,
    ) {
        self.x.fixed_rows_mut::<3>(POSITION).copy_from(&position);
        self.x.fixed_rows_mut::<3>(VELOCITY).copy_from(&velocity);
        for (leg, f) in feet.iter().enumerate() {
            self.x.fixed_rows_mut::<3>(foot(leg)).copy_from(f);
        }
        self.p = StateMatrix::zeros();
        for i in 0..3 {
            self.p[(POSITION + i, POSITION + i)] = position_sigma.powi(2);
            self.p[(VELOCITY + i, VELOCITY + i)] = INITIAL_VELOCITY_SIGMA.powi(2);
            for leg in 0..NUM_LEGS {
                // The feet are known relative to the trunk far better than absolutely: they
                // share the position's uncertainty.
                self.p[(foot(leg) + i, foot(leg) + i)] =
                    position_sigma.powi(2) + INITIAL_FOOT_SIGMA.powi(2);
                self.p[(foot(leg) + i, POSITION + i)] = position_sigma.powi(2);
                self.p[(POSITION + i, foot(leg) + i)] = position_sigma.powi(2);
            }
        }
        for a in 0..NUM_LEGS {
            for b in 0..NUM_LEGS {
                if a != b {
                    for i in 0..3 {
                        self.p[(foot(a) + i, foot(b) + i)] = position_sigma.powi(2);
                    }
                }
            }
        }
    }

    /// Trunk position, world frame, m.
    pub fn position(&self) -> Vector3<f64> {
        self.x.fixed_rows::<3>(POSITION).into_owned()
    }

    /// Trunk velocity, world frame, m/s.
    pub fn velocity(&self) -> Vector3<f64> {
        self.x.fixed_rows::<3>(VELOCITY).into_owned()
    }

    /// Trunk velocity covariance, (m/s)².
    pub fn velocity_covariance(&self) -> Matrix3<f64> {
        self.p.fixed_view::<3, 3>(VELOCITY, VELOCITY).into_owned()
    }

    /// Squared Mahalanobis distance of a trunk-velocity measurement `velocity` (m/s, world
    /// frame) with per-axis noise variance `variance` from the predicted velocity, the state
    /// propagated over `dt` with `acceleration` first (`None` when the innovation covariance is
    /// singular or not finite).
    pub fn velocity_distance2(
        &self,
        velocity: &Vector3<f64>,
        variance: f64,
        acceleration: &Vector3<f64>,
        dt: f64,
    ) -> Option<f64> {
        let innovation = velocity - (self.velocity() + acceleration * dt);
        let s = self.velocity_covariance() + Matrix3::identity() * variance;
        s.try_inverse()
            .map(|inverse| innovation.dot(&(inverse * innovation)))
            .filter(|d2| d2.is_finite())
    }

    /// Foot position of `leg`, world frame, m.
    pub fn foot(&self, leg: usize) -> Vector3<f64> {
        self.x.fixed_rows::<3>(foot(leg)).into_owned()
    }

    /// Position covariance, m².
    pub fn position_covariance(&self) -> Matrix3<f64> {
        self.p.fixed_view::<3, 3>(POSITION, POSITION).into_owned()
    }

    /// Whether state and covariance are finite and bounded.
    pub fn is_healthy(&self) -> bool {
        self.x.iter().all(|v| v.is_finite())
            && (0..STATES).all(|i| {
                let d = self.p[(i, i)];
                (0.0..MAX_VARIANCE).contains(&d)
            })
    }

    /// Prediction over `dt` with world acceleration `acceleration` (m/s²): p += v·dt + a·dt²/2,
    /// v += a·dt, feet constant. `acc_density` (m/s²/√Hz) is the white acceleration noise, whose
    /// exact discretisation gives the position/velocity process noise; `foot_density[leg]`
    /// (m/√s) the random walk of each foot; `translation_variance` (m², per axis) that of the
    /// whole robot (trunk and feet moved together: invisible to the leg measurements, so the
    /// estimate is unchanged and only fixes can take that variance back).
    pub fn predict(
        &mut self,
        acceleration: &Vector3<f64>,
        dt: f64,
        acc_density: f64,
        foot_density: &[f64; NUM_LEGS],
        translation_variance: f64,
    ) {
        for i in 0..3 {
            self.x[POSITION + i] += self.x[VELOCITY + i] * dt + 0.5 * acceleration[i] * dt * dt;
            self.x[VELOCITY + i] += acceleration[i] * dt;
        }
        // P ← F P Fᵀ with F = I + dt·E (E moves velocity into position): a row then a column
        // operation.
        for i in 0..3 {
            for c in 0..STATES {
                let v = self.p[(VELOCITY + i, c)];
                self.p[(POSITION + i, c)] += dt * v;
            }
        }
        for i in 0..3 {
            for r in 0..STATES {
                let v = self.p[(r, VELOCITY + i)];
                self.p[(r, POSITION + i)] += dt * v;
            }
        }
        let q = acc_density * acc_density;
        for i in 0..3 {
            self.p[(POSITION + i, POSITION + i)] += q * dt.powi(3) / 3.0;
            self.p[(POSITION + i, VELOCITY + i)] += q * dt * dt / 2.0;
            self.p[(VELOCITY + i, POSITION + i)] += q * dt * dt / 2.0;
            self.p[(VELOCITY + i, VELOCITY + i)] += q * dt;
            for (leg, density) in foot_density.iter().enumerate() {
                self.p[(foot(leg) + i, foot(leg) + i)] += density * density * dt;
            }
        }
        let bodies = || std::iter::once(POSITION).chain((0..NUM_LEGS).map(foot));
        for i in 0..3 {
            for a in bodies() {
                for b in bodies() {
                    self.p[(a + i, b + i)] += translation_variance;
                }
            }
        }
    }

    /// Scalar update of the measurement `x[plus] − x[minus] = z` (or `x[plus] = z` when
    /// `minus` is `None`) with noise variance `variance`.
    fn update_scalar(&mut self, plus: usize, minus: Option<usize>, z: f64, variance: f64) {
        let mut ph = self.p.column(plus).into_owned();
        let mut predicted = self.x[plus];
        if let Some(m) = minus {
            ph -= self.p.column(m);
            predicted -= self.x[m];
        }
        let s = ph[plus] - minus.map_or(0.0, |m| ph[m]) + variance;
        if !(s.is_finite() && s > 0.0) {
            return;
        }
        let gain = ph / s;
        self.x += gain * (z - predicted);
        self.p -= gain * ph.transpose();
    }

    /// Leg kinematics of one leg: `relative` = foot − trunk (world frame, m) with per-axis
    /// variance `position_variance`, and, when `velocity_variance` is given, the trunk velocity
    /// `trunk_velocity` the stance foot implies (m/s, world frame).
    pub fn update_leg(
        &mut self,
        leg: usize,
        relative: &Vector3<f64>,
        position_variance: f64,
        trunk_velocity: Option<(&Vector3<f64>, f64)>,
    ) {
        for i in 0..3 {
            self.update_scalar(
                foot(leg) + i,
                Some(POSITION + i),
                relative[i],
                position_variance,
            );
        }
        if let Some((velocity, variance)) = trunk_velocity {
            for i in 0..3 {
                self.update_scalar(VELOCITY + i, None, velocity[i], variance);
            }
        }
    }

    /// Keeps the covariance symmetric (rounding in the scalar updates breaks it slowly).
    pub fn symmetrise(&mut self) {
        self.p = 0.5 * (self.p + self.p.transpose());
    }

    /// Fuses an absolute position fix with per-axis variance `variance` unless its squared
    /// Mahalanobis distance exceeds `gate`.
    pub fn fuse_fix(&mut self, fix: &Vector3<f64>, variance: f64, gate: f64) -> FixOutcome {
        let innovation = fix - self.position();
        let s = self.position_covariance() + Matrix3::identity() * variance;
        let distance2 = s
            .try_inverse()
            .map(|inv| innovation.dot(&(inv * innovation)));
        match distance2 {
            Some(d2) if d2.is_finite() && d2 <= gate => {
                for i in 0..3 {
                    self.update_scalar(POSITION + i, None, fix[i], variance);
                }
                FixOutcome::Fused
            }
            _ => FixOutcome::Rejected,
        }
    }

    /// Moves the trunk and the feet by `offset` (a relocation: the geometry between them is
    /// kept) and restarts the covariance with position σ `position_sigma`.
    pub fn relocate(&mut self, offset: &Vector3<f64>, position_sigma: f64) {
        let position = self.position() + offset;
        let velocity = self.velocity();
        let feet: [Vector3<f64>; NUM_LEGS] = std::array::from_fn(|leg| self.foot(leg) + offset);
        self.reset(position, velocity, &feet, position_sigma);
    }
}
