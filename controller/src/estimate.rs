//! The state the later stages run on: rotation, roll/pitch/yaw, base position and twist, per-leg
//! joint angles, world foot positions, gravity in the base frame. In ground-truth mode it is the
//! measured state ([`Estimate::from_measurement`]); in Kalman mode the base pose and twist come
//! from [`crate::estimator`] and the rest from the encoders ([`Estimate::from_base`]).

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::api::{Leg, RobotState, GRAVITY, NUM_LEGS};
use crate::model::RobotModel;

/// The robot's state as the controller stages use it.
#[derive(Clone, Debug)]
pub struct Estimate {
    /// Rotates base-frame vectors into the world frame.
    pub rotation: Matrix3<f64>,
    /// Roll, pitch, yaw (ZYX Euler angles), rad.
    pub rpy: Vector3<f64>,
    /// Base origin, world frame, m.
    pub position: Vector3<f64>,
    /// Base linear velocity, world frame, m/s.
    pub velocity: Vector3<f64>,
    /// Base angular velocity, world frame, rad/s.
    pub angular_velocity: Vector3<f64>,
    /// Joint angles per leg (abduction, hip, knee), rad.
    pub q: [[f64; 3]; NUM_LEGS],
    /// Joint velocities per leg, rad/s.
    pub dq: [[f64; 3]; NUM_LEGS],
    /// Foot (sphere centre) positions, world frame, m.
    pub feet_world: [Vector3<f64>; NUM_LEGS],
    /// Gravity acceleration in the base frame, m/s².
    pub gravity_body: [f64; 3],
}

/// The three values of `leg` in a per-joint array (index 3·leg + j).
pub fn leg_slice<const N: usize>(values: &[f64; N], leg: Leg) -> [f64; 3] {
    let l = leg.index();
    [values[3 * l], values[3 * l + 1], values[3 * l + 2]]
}

/// Roll, pitch, yaw (ZYX Euler angles) of a rotation matrix, rad.
pub fn rpy_of(rotation: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(
        rotation[(2, 1)].atan2(rotation[(2, 2)]),
        (-rotation[(2, 0)]).clamp(-1.0, 1.0).asin(),
        rotation[(1, 0)].atan2(rotation[(0, 0)]),
    )
}

/// The base pose and twist an [`Estimate`] is built around.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct BaseState {
    /// Body → world attitude.
    pub attitude: UnitQuaternion<f64>,
    /// Base origin, world frame, m.
    pub position: Vector3<f64>,
    /// Base linear velocity, world frame, m/s.
    pub velocity: Vector3<f64>,
    /// Base angular velocity, world frame, rad/s.
    pub angular_velocity: Vector3<f64>,
}

impl Estimate {
    /// The estimate of a validated measured state.
    pub fn from_measurement(model: &RobotModel, state: &RobotState) -> Estimate {
        let o = state.base_orientation;
        let base = BaseState {
            attitude: UnitQuaternion::from_quaternion(Quaternion::new(o[0], o[1], o[2], o[3])),
            position: Vector3::from(state.base_position),
            velocity: Vector3::from(state.base_linear_velocity),
            angular_velocity: Vector3::from(state.base_angular_velocity),
        };
        let feet_body = Leg::ALL.map(|leg| {
            Vector3::from(model.foot_position_body(leg, leg_slice(&state.joint_positions, leg)))
        });
        Estimate::from_base(&base, state, &feet_body)
    }

    /// The estimate around `base` with the joints of `state` (its base fields are not read) and
    /// the feet at `feet_body` (base frame, the forward kinematics of those joints).
    pub fn from_base(
        base: &BaseState,
        state: &RobotState,
        feet_body: &[Vector3<f64>; NUM_LEGS],
    ) -> Estimate {
        let rotation = *base.attitude.to_rotation_matrix().matrix();
        let mut q = [[0.0; 3]; NUM_LEGS];
        let mut dq = [[0.0; 3]; NUM_LEGS];
        let mut feet_world = [Vector3::zeros(); NUM_LEGS];
        for leg in Leg::ALL {
            let l = leg.index();
            q[l] = leg_slice(&state.joint_positions, leg);
            dq[l] = leg_slice(&state.joint_velocities, leg);
            feet_world[l] = base.position + rotation * feet_body[l];
        }
        let gravity = rotation.transpose() * Vector3::new(0.0, 0.0, -GRAVITY);
        Estimate {
            rotation,
            rpy: rpy_of(&rotation),
            position: base.position,
            velocity: base.velocity,
            angular_velocity: base.angular_velocity,
            q,
            dq,
            feet_world,
            gravity_body: [gravity.x, gravity.y, gravity.z],
        }
    }
}
