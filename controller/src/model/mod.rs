//! Robot model built from a URDF and its robot config ([`crate::robot_config`]): per-leg
//! kinematic chains, forward/inverse kinematics, foot Jacobian and per-leg rigid-body dynamics.
//!
//! The robot config names, for each leg (FR, FL, RR, RL), the three actuated joints and the foot
//! link (plus an optional foot offset), and the base link. The chain from the base to the foot is
//! found by walking the URDF tree from the foot up; fixed joints on the way are merged into the
//! neighbouring moving link. No link or joint name is assumed anywhere in the crate.
//!
//! Leg dynamics treat the base as fixed (an inertial frame): `M(q)` and `h(q, q̇)` are those of the
//! 3-link chain hanging from a motionless base, with gravity expressed in the base frame. The
//! coupling with base acceleration is neglected; this is the usual assumption of MIT-style leg
//! controllers, where the legs are ~15 % of the mass and the base moves slowly compared to a
//! swinging leg.
//!
//! The model is split by concern so each part can be read alone: `urdf` turns the URDF tree into
//! leg chains (and is the only place that validates it), `kinematics` holds forward kinematics,
//! the foot Jacobian and IK, and `dynamics` the rigid-body terms built on those frames.

mod dynamics;
mod kinematics;

pub use kinematics::FootKinematics;
mod urdf;
pub(crate) use urdf::unusable_inertials;
pub(crate) use urdf::{foot_sphere_radius, is_massless_frame};

#[cfg(test)]
mod tests;

use nalgebra::{Matrix3, Rotation3, Vector3};

use crate::api::{Leg, NUM_JOINTS, NUM_LEGS};
use crate::robot_config::KneeDirection;

/// Rigid transform (rotation, translation) mapping child-frame coordinates to the parent frame.
#[derive(Clone, Copy, Debug)]
struct Transform {
    rotation: Matrix3<f64>,
    translation: Vector3<f64>,
}

impl Transform {
    fn identity() -> Self {
        Transform {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
        }
    }

    fn from_pose(pose: &urdf_rs::Pose) -> Self {
        let rotation = Rotation3::from_euler_angles(pose.rpy[0], pose.rpy[1], pose.rpy[2]);
        Transform {
            rotation: *rotation.matrix(),
            translation: Vector3::new(pose.xyz[0], pose.xyz[1], pose.xyz[2]),
        }
    }

    fn then(&self, child: &Transform) -> Transform {
        Transform {
            rotation: self.rotation * child.rotation,
            translation: self.translation + self.rotation * child.translation,
        }
    }
}

/// Mass properties of a rigid body: mass, centre of mass and rotational inertia about the CoM,
/// both in the frame of the body it is expressed in.
#[derive(Clone, Copy, Debug)]
struct MassProperties {
    mass: f64,
    com: Vector3<f64>,
    inertia_com: Matrix3<f64>,
}

impl MassProperties {
    /// The same body expressed in a frame rotated by `rotation` (new = rotation · old).
    fn rotated(&self, rotation: &Matrix3<f64>) -> MassProperties {
        MassProperties {
            mass: self.mass,
            com: rotation * self.com,
            inertia_com: rotation * self.inertia_com * rotation.transpose(),
        }
    }

    /// Merge `other` (expressed in a frame placed at `pose` relative to ours) into `self`.
    fn merge(&mut self, other: &MassProperties, pose: &Transform) {
        let other_com = pose.translation + pose.rotation * other.com;
        let other_inertia = pose.rotation * other.inertia_com * pose.rotation.transpose();
        let total = self.mass + other.mass;
        if total <= 0.0 {
            return;
        }
        let com = (self.com * self.mass + other_com * other.mass) / total;
        let shifted = |inertia: Matrix3<f64>, mass: f64, c: Vector3<f64>| {
            let d = c - com;
            inertia + mass * (Matrix3::identity() * d.dot(&d) - d * d.transpose())
        };
        self.inertia_com = shifted(self.inertia_com, self.mass, self.com)
            + shifted(other_inertia, other.mass, other_com);
        self.com = com;
        self.mass = total;
    }
}

/// One actuated joint of a leg chain.
#[derive(Clone, Debug)]
struct ChainJoint {
    /// Pose of the joint frame (before its rotation) in the previous moving frame (the base for
    /// the first joint), fixed joints in between included. Every frame of the chain is parallel
    /// to the base at q = 0 (the URDF's origin rotations are folded into axes and bodies), so
    /// the rotation is the identity.
    pre: Transform,
    /// Unit rotation axis in the joint frame (= in the base frame at q = 0).
    axis: Vector3<f64>,
    /// Everything rigidly attached after this joint, in the joint frame.
    body: MassProperties,
    lower: f64,
    upper: f64,
    effort: f64,
    velocity: f64,
}

/// Geometry used by the closed-form IK initial guess, exact for any leg whose axes, in the base
/// frame at q = 0, are ±x for the abduction and ±y for the hip and knee (checked when the model
/// is built; the chain's frames are stored parallel to the base at q = 0). Lengths are in the leg's sagittal plane.
#[derive(Clone, Copy, Debug)]
struct LegGeometry {
    abd_origin: Vector3<f64>,
    /// Hip-flexion joint origin in the abduction joint's frame.
    hip_origin: Vector3<f64>,
    /// Signed lateral offset from the abduction axis to the foot's sagittal plane (hip, knee and
    /// foot offsets along y summed).
    lateral_offset: f64,
    thigh_length: f64,
    calf_length: f64,
    /// Forward angle of the thigh (hip → knee) and calf (knee → foot) from straight down at
    /// q = 0, rad.
    thigh_angle: f64,
    calf_angle: f64,
    /// URDF angle = sign · angle about the canonical axis (+x, +y, +y).
    axis_signs: [f64; 3],
    knee: KneeDirection,
}

impl LegGeometry {
    /// Sign of the canonical knee bend on the configured branch (backward knees bend negative).
    fn knee_branch_sign(&self) -> f64 {
        match self.knee {
            KneeDirection::Backward => -1.0,
            KneeDirection::Forward => 1.0,
        }
    }
}

#[derive(Clone, Debug)]
struct LegChain {
    joints: [ChainJoint; 3],
    /// Foot point (sphere centre) and the foot link's orientation in the knee's moving frame.
    foot: Transform,
    geometry: LegGeometry,
}

/// Per-joint frames of one leg at a configuration, all in the base frame.
#[derive(Clone, Copy, Debug)]
struct LegFrames {
    joint_origin: [Vector3<f64>; 3],
    joint_axis: [Vector3<f64>; 3],
    link_rotation: [Matrix3<f64>; 3],
    foot: Vector3<f64>,
}

/// Robot model for the controller, built from the URDF.
#[derive(Clone, Debug)]
pub struct RobotModel {
    name: String,
    total_mass: f64,
    base_body: MassProperties,
    legs: [LegChain; NUM_LEGS],
    foot_radius: f64,
    stand_height: f64,
    crouch: Option<[f64; NUM_JOINTS]>,
    /// The robot config's `[tuning]` applied over the scaled default tuning (checked when
    /// built); `None` without one.
    tuning: Option<Box<crate::ControllerConfig>>,
}

fn to_array3(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

fn to_array33(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    [
        [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
        [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
        [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
    ]
}

impl RobotModel {
    /// Robot name from the URDF.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Sum of all link masses, kg.
    pub fn total_mass(&self) -> f64 {
        self.total_mass
    }

    /// Radius of the foot spheres, m.
    pub fn foot_radius(&self) -> f64 {
        self.foot_radius
    }

    /// Nominal height of the base origin above flat ground when standing (robot config), m.
    pub fn stand_height(&self) -> f64 {
        self.stand_height
    }

    /// The crouch a simulation places the robot in before its stand-up (robot config key
    /// `legs.*.crouch`), rad, index 3·leg + j; `None` unless every leg gives one.
    pub fn crouch_joint_positions(&self) -> Option<[f64; NUM_JOINTS]> {
        self.crouch
    }

    /// The controller tuning of the robot config's `[tuning]` table (over the default scaled to
    /// the robot), if it has one; [`crate::ControllerConfig::for_robot`] reads it.
    pub fn configured_tuning(&self) -> Option<&crate::ControllerConfig> {
        self.tuning.as_deref()
    }

    /// Effort limits (URDF, or the robot config's overrides), N·m, index 3·leg + j.
    pub fn effort_limits(&self) -> [f64; NUM_JOINTS] {
        self.per_joint(|j| j.effort)
    }

    /// Velocity limits (URDF, or the robot config's overrides), rad/s.
    pub fn velocity_limits(&self) -> [f64; NUM_JOINTS] {
        self.per_joint(|j| j.velocity)
    }

    /// URDF lower position limits, rad.
    pub fn lower_limits(&self) -> [f64; NUM_JOINTS] {
        self.per_joint(|j| j.lower)
    }

    /// URDF upper position limits, rad.
    pub fn upper_limits(&self) -> [f64; NUM_JOINTS] {
        self.per_joint(|j| j.upper)
    }

    fn per_joint(&self, f: impl Fn(&ChainJoint) -> f64) -> [f64; NUM_JOINTS] {
        let mut out = [0.0; NUM_JOINTS];
        for (l, leg) in self.legs.iter().enumerate() {
            for (j, joint) in leg.joints.iter().enumerate() {
                out[3 * l + j] = f(joint);
            }
        }
        out
    }

    /// Position of the hip-abduction joint in the base frame, m.
    pub fn hip_position_body(&self, leg: Leg) -> [f64; 3] {
        to_array3(&self.legs[leg.index()].geometry.abd_origin)
    }

    /// Signed lateral offset from the abduction axis to the leg's sagittal plane, m (positive to
    /// the left).
    pub fn hip_lateral_offset(&self, leg: Leg) -> f64 {
        self.legs[leg.index()].geometry.lateral_offset
    }

    /// How far the knee is bent towards its configured branch (`knee_points`) at `q_leg`, rad:
    /// 0 with the thigh and calf in line, positive on the branch's side, negative once the knee
    /// has gone through straight to the other branch.
    pub fn knee_bend(&self, leg: Leg, q_leg: [f64; 3]) -> f64 {
        let g = &self.legs[leg.index()].geometry;
        let canonical_bend = g.axis_signs[2] * q_leg[2] - (g.calf_angle - g.thigh_angle);
        g.knee_branch_sign() * canonical_bend
    }

    /// d(knee_bend)/d(knee joint angle): +1 or −1.
    pub fn knee_bend_per_angle(&self, leg: Leg) -> f64 {
        let g = &self.legs[leg.index()].geometry;
        g.knee_branch_sign() * g.axis_signs[2]
    }

    /// Thigh (hip → knee) and calf (knee → foot) lengths in the leg's sagittal plane, m.
    pub fn link_lengths(&self, leg: Leg) -> (f64, f64) {
        let g = &self.legs[leg.index()].geometry;
        (g.thigh_length, g.calf_length)
    }

    /// Masses of the base cluster and of the moving links of one leg (hip, thigh, calf+foot), kg.
    pub fn link_masses(&self, leg: Leg) -> (f64, [f64; 3]) {
        let chain = &self.legs[leg.index()];
        (
            self.base_body.mass,
            [
                chain.joints[0].body.mass,
                chain.joints[1].body.mass,
                chain.joints[2].body.mass,
            ],
        )
    }
}
