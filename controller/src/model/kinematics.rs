//! Forward kinematics, the foot Jacobian and inverse kinematics of one leg chain. Kept apart from
//! the URDF parsing so the per-tick hot paths (IK is called every control tick) read on their own.

use nalgebra::{Matrix3, Rotation3, Vector3};

use super::{to_array3, to_array33, LegFrames, RobotModel, Transform};
use crate::api::{Leg, ModelError, NUM_JOINTS};
use crate::math::wrap_angle;
use crate::robot_config::KneeDirection;

/// One leg's foot kinematics in the base frame.
#[derive(Clone, Copy, Debug)]
pub struct FootKinematics {
    /// Foot (sphere centre) position, m.
    pub position: Vector3<f64>,
    /// ∂p_foot/∂q (row = Cartesian axis, column = joint).
    pub jacobian: Matrix3<f64>,
    /// ∂ω_foot/∂q̇: the joint axes (the foot link's angular velocity relative to the base is
    /// `angular_jacobian · q̇`).
    pub angular_jacobian: Matrix3<f64>,
}

/// Why an IK target was not reached (turned into [`ModelError::Unreachable`] on demand).
#[derive(Clone, Copy, Debug)]
enum IkFailure {
    NotFinite,
    InsideOffset,
    OutOfReach { reach: f64, min: f64, max: f64 },
    NotConverged { residual: f64 },
}

/// Iterations, damping (added to JᵀJ, m²/rad²) and tolerance (m and rad) of the joint-limited
/// IK's least-squares refinement: it starts from the clamped closed-form solution, and a few
/// steps settle it.
const LIMITED_IK_ITERATIONS: usize = 20;
const LIMITED_IK_DAMPING: f64 = 1e-6;
const LIMITED_IK_TOLERANCE: f64 = 1e-9;

fn axis_rotation(axis: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
    *Rotation3::from_axis_angle(&nalgebra::Unit::new_unchecked(*axis), angle).matrix()
}

impl RobotModel {
    pub(super) fn frames(&self, leg: Leg, q: [f64; 3]) -> LegFrames {
        let chain = &self.legs[leg.index()];
        let mut current = Transform::identity();
        let mut joint_origin = [Vector3::zeros(); 3];
        let mut joint_axis = [Vector3::zeros(); 3];
        let mut link_rotation = [Matrix3::identity(); 3];
        for (i, joint) in chain.joints.iter().enumerate() {
            current = current.then(&joint.pre);
            joint_origin[i] = current.translation;
            joint_axis[i] = current.rotation * joint.axis;
            current.rotation *= axis_rotation(&joint.axis, q[i]);
            link_rotation[i] = current.rotation;
        }
        let foot = current.then(&chain.foot).translation;
        LegFrames {
            joint_origin,
            joint_axis,
            link_rotation,
            foot,
        }
    }

    /// Orientation of the URDF's foot link frame at `q_leg`, in the base frame (maps vectors
    /// given in the foot link's frame, e.g. its collision meshes, to the base frame).
    pub(crate) fn foot_link_rotation(&self, leg: Leg, q_leg: [f64; 3]) -> Matrix3<f64> {
        self.frames(leg, q_leg).link_rotation[2] * self.legs[leg.index()].foot.rotation
    }

    /// Forward kinematics: foot (sphere centre) position in the base frame, m.
    pub fn foot_position_body(&self, leg: Leg, q_leg: [f64; 3]) -> [f64; 3] {
        to_array3(&self.frames(leg, q_leg).foot)
    }

    /// Positions of the leg's three joint origins (abduction, hip, knee) in the base frame, m.
    pub fn joint_positions_body(&self, leg: Leg, q_leg: [f64; 3]) -> [[f64; 3]; 3] {
        self.frames(leg, q_leg).joint_origin.map(|p| to_array3(&p))
    }

    /// Foot Jacobian ∂p_foot/∂q in the base frame (row = Cartesian axis, column = joint).
    pub fn foot_jacobian_body(&self, leg: Leg, q_leg: [f64; 3]) -> [[f64; 3]; 3] {
        to_array33(&self.jacobian(leg, q_leg))
    }

    /// Foot position (base frame, m) and foot Jacobian of one leg from one kinematics pass.
    pub fn foot_position_and_jacobian(
        &self,
        leg: Leg,
        q_leg: [f64; 3],
    ) -> (Vector3<f64>, Matrix3<f64>) {
        let kinematics = self.foot_kinematics(leg, q_leg);
        (kinematics.position, kinematics.jacobian)
    }

    /// Foot position, linear and angular Jacobians of one leg from one kinematics pass (the
    /// estimator needs all three every tick).
    pub fn foot_kinematics(&self, leg: Leg, q_leg: [f64; 3]) -> FootKinematics {
        let frames = self.frames(leg, q_leg);
        let mut jacobian = Matrix3::zeros();
        let mut angular_jacobian = Matrix3::zeros();
        for i in 0..3 {
            let column = frames.joint_axis[i].cross(&(frames.foot - frames.joint_origin[i]));
            jacobian.set_column(i, &column);
            angular_jacobian.set_column(i, &frames.joint_axis[i]);
        }
        FootKinematics {
            position: frames.foot,
            jacobian,
            angular_jacobian,
        }
    }

    fn jacobian(&self, leg: Leg, q: [f64; 3]) -> Matrix3<f64> {
        self.foot_position_and_jacobian(leg, q).1
    }

    /// Inverse kinematics: joint angles placing the foot at `p_body` (base frame), on the knee
    /// branch of the robot config (`knee_points`), foot below the hip axis in the leg plane.
    /// Closed-form for the leg layout checked at load time, refined by Newton steps on the full
    /// URDF kinematics. Joint limits are not enforced here (callers clamp).
    pub fn inverse_kinematics(&self, leg: Leg, p_body: [f64; 3]) -> Result<[f64; 3], ModelError> {
        self.solve_ik(leg, p_body)
            .map_err(|failure| ModelError::Unreachable {
                leg,
                reason: match failure {
                    IkFailure::NotFinite => "target is not finite".into(),
                    IkFailure::InsideOffset => "target inside the abduction offset".into(),
                    IkFailure::OutOfReach { reach, min, max } => {
                        format!("distance {reach:.4} m outside [{min:.4}, {max:.4}] m")
                    }
                    IkFailure::NotConverged { residual } => {
                        format!("IK did not converge (residual {residual:.2e} m)")
                    }
                },
            })
    }

    /// Foot (sphere centre) position of the nominal stand in the base frame: in the leg's
    /// sagittal plane under the abduction joint, the sphere's bottom `height` below the base
    /// origin.
    pub fn nominal_foot_position(&self, leg: Leg, height: f64) -> [f64; 3] {
        let hip = self.hip_position_body(leg);
        [
            hip[0],
            hip[1] + self.hip_lateral_offset(leg),
            -(height - self.foot_radius),
        ]
    }

    /// Joint angles of the nominal stand at `height` (see [`RobotModel::nominal_foot_position`]).
    pub fn stand_joint_positions(&self, height: f64) -> Result<[f64; NUM_JOINTS], ModelError> {
        let mut q = [0.0; NUM_JOINTS];
        for leg in Leg::ALL {
            let leg_q = self.inverse_kinematics(leg, self.nominal_foot_position(leg, height))?;
            q[3 * leg.index()..3 * leg.index() + 3].copy_from_slice(&leg_q);
        }
        Ok(q)
    }

    /// [`RobotModel::inverse_kinematics`] without building an error message: for callers that
    /// retry or fall back on failure every control tick (formatting the message's floats cost
    /// more than the IK itself).
    pub(crate) fn try_inverse_kinematics(&self, leg: Leg, p_body: [f64; 3]) -> Option<[f64; 3]> {
        self.solve_ik(leg, p_body).ok()
    }

    /// Joint angles inside `[lower, upper]` that put the foot as close to `p_body` (base frame)
    /// as those limits allow: the IK solution where it lies inside them; otherwise the joints
    /// beyond a limit are held at it and the others are moved (least squares) to bring the foot
    /// nearest the target. Clamping the IK solution alone would keep the hip aimed for a knee
    /// bend the knee cannot make and swing the foot off its spot. `None` when the IK has no
    /// solution at all (target out of reach, not finite).
    pub(crate) fn inverse_kinematics_within_limits(
        &self,
        leg: Leg,
        p_body: [f64; 3],
        lower: [f64; 3],
        upper: [f64; 3],
    ) -> Option<[f64; 3]> {
        let mut q = self.try_inverse_kinematics(leg, p_body)?;
        let inside = |j: usize, v: f64| v >= lower[j] && v <= upper[j];
        if q.iter().enumerate().all(|(j, &v)| inside(j, v)) {
            return Some(q);
        }
        let mut held = [false; 3];
        for j in 0..3 {
            held[j] = !inside(j, q[j]);
            q[j] = q[j].clamp(lower[j], upper[j]);
        }
        let target = Vector3::from(p_body);
        for _ in 0..LIMITED_IK_ITERATIONS {
            let kinematics = self.foot_kinematics(leg, q);
            let error = target - kinematics.position;
            if error.norm() < LIMITED_IK_TOLERANCE {
                break;
            }
            let mut jacobian = kinematics.jacobian;
            for (j, &is_held) in held.iter().enumerate() {
                if is_held {
                    jacobian.set_column(j, &Vector3::zeros());
                }
            }
            // Damped least squares: the held columns are zero, so their joints do not move.
            let normal = jacobian.transpose() * jacobian + Matrix3::identity() * LIMITED_IK_DAMPING;
            let Some(step) = normal
                .try_inverse()
                .map(|n| n * jacobian.transpose() * error)
            else {
                break;
            };
            let mut moved = 0.0_f64;
            for j in 0..3 {
                let next = (q[j] + step[j]).clamp(lower[j], upper[j]);
                if next != q[j] + step[j] {
                    held[j] = true;
                }
                moved = moved.max((next - q[j]).abs());
                q[j] = next;
            }
            if moved < LIMITED_IK_TOLERANCE {
                break;
            }
        }
        q.iter().all(|v| v.is_finite()).then_some(q)
    }

    fn solve_ik(&self, leg: Leg, p_body: [f64; 3]) -> Result<[f64; 3], IkFailure> {
        if p_body.iter().any(|v| !v.is_finite()) {
            return Err(IkFailure::NotFinite);
        }
        let g = &self.legs[leg.index()].geometry;
        let rel = Vector3::new(p_body[0], p_body[1], p_body[2]) - g.abd_origin;
        let d = g.lateral_offset;
        let (l1, l2) = (g.thigh_length, g.calf_length);
        let yz_sq = rel.y * rel.y + rel.z * rel.z;
        if yz_sq < d * d + 1e-12 {
            return Err(IkFailure::InsideOffset);
        }
        // Foot in the abduction frame before its rotation: (x, d, z_abd), foot below the axis.
        let z_abd = -(yz_sq - d * d).sqrt();
        let abduction = rel.z.atan2(rel.y) - z_abd.atan2(d);
        // Foot relative to the hip-flexion joint in the sagittal plane.
        let x_plane = rel.x - g.hip_origin.x;
        let z_plane = z_abd - g.hip_origin.z;
        let reach_sq = x_plane * x_plane + z_plane * z_plane;
        let reach = reach_sq.sqrt();
        if reach > l1 + l2 - 1e-9 || reach < (l1 - l2).abs() + 1e-9 {
            return Err(IkFailure::OutOfReach {
                reach,
                min: (l1 - l2).abs(),
                max: l1 + l2,
            });
        }
        // Two-link solution for links hanging straight down at zero angles; the thigh and calf
        // angle offsets shift it to the URDF's zero pose.
        let cos_knee = ((reach_sq - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)).clamp(-1.0, 1.0);
        let bend = match g.knee {
            KneeDirection::Backward => -cos_knee.acos(),
            KneeDirection::Forward => cos_knee.acos(),
        };
        let direction = (-x_plane).atan2(-z_plane);
        let swing = direction - (l2 * bend.sin()).atan2(l1 + l2 * bend.cos());
        let hip = swing + g.thigh_angle;
        let knee = bend + g.calf_angle - g.thigh_angle;
        let mut q = [
            wrap_angle(g.axis_signs[0] * abduction),
            wrap_angle(g.axis_signs[1] * hip),
            g.axis_signs[2] * knee,
        ];
        let target = Vector3::new(p_body[0], p_body[1], p_body[2]);
        for _ in 0..20 {
            let error = target - self.frames(leg, q).foot;
            if error.norm() < 1e-12 {
                break;
            }
            let Some(inverse) = self.jacobian(leg, q).try_inverse() else {
                break;
            };
            let dq = inverse * error;
            for i in 0..3 {
                q[i] += dq[i];
            }
        }
        let residual = (target - self.frames(leg, q).foot).norm();
        if residual > 1e-6 {
            return Err(IkFailure::NotConverged { residual });
        }
        Ok(q)
    }
}
