//! State estimation stage: today the measured state is taken as the estimate; this stage derives
//! what the later stages need from it once per tick (rotation, roll/pitch/yaw, per-leg joint
//! angles, world foot positions, gravity in the base frame). A real estimator (contact-aided
//! Kalman filter) would replace `Estimate::from_measurement`.

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

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

impl Estimate {
    /// The estimate of a validated measured state.
    pub fn from_measurement(model: &RobotModel, state: &RobotState) -> Estimate {
        let o = state.base_orientation;
        let quaternion = UnitQuaternion::from_quaternion(Quaternion::new(o[0], o[1], o[2], o[3]));
        let rotation = *quaternion.to_rotation_matrix().matrix();
        let rpy = Vector3::new(
            rotation[(2, 1)].atan2(rotation[(2, 2)]),
            (-rotation[(2, 0)]).clamp(-1.0, 1.0).asin(),
            rotation[(1, 0)].atan2(rotation[(0, 0)]),
        );
        let position = Vector3::from(state.base_position);
        let mut q = [[0.0; 3]; NUM_LEGS];
        let mut dq = [[0.0; 3]; NUM_LEGS];
        let mut feet_world = [Vector3::zeros(); NUM_LEGS];
        for leg in Leg::ALL {
            let l = leg.index();
            q[l] = leg_slice(&state.joint_positions, leg);
            dq[l] = leg_slice(&state.joint_velocities, leg);
            let foot = Vector3::from(model.foot_position_body(leg, q[l]));
            feet_world[l] = position + rotation * foot;
        }
        let gravity = rotation.transpose() * Vector3::new(0.0, 0.0, -GRAVITY);
        Estimate {
            rotation,
            rpy,
            position,
            velocity: Vector3::from(state.base_linear_velocity),
            angular_velocity: Vector3::from(state.base_angular_velocity),
            q,
            dq,
            feet_world,
            gravity_body: [gravity.x, gravity.y, gravity.z],
        }
    }
}
