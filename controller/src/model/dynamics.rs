//! Fixed-base leg dynamics (see the base-is-inertial assumption in the parent module) and the
//! whole-robot composite inertia, both built on the kinematic frames.

use nalgebra::{Matrix3, Vector3};

use super::{to_array3, to_array33, RobotModel, Transform};
use crate::api::{Leg, NUM_JOINTS};

impl RobotModel {
    /// Recursive Newton–Euler on the fixed-base leg chain: joint torques for (q, q̇, q̈) with the
    /// base frame taken as inertial and `gravity_base` the gravity acceleration in the base frame.
    pub(crate) fn rnea(
        &self,
        leg: Leg,
        q: [f64; 3],
        dq: [f64; 3],
        ddq: [f64; 3],
        gravity_base: Vector3<f64>,
    ) -> Vector3<f64> {
        let chain = &self.legs[leg.index()];
        let frames = self.frames(leg, q);
        let mut omega = [Vector3::zeros(); 3];
        let mut alpha = [Vector3::zeros(); 3];
        let mut accel_origin = [Vector3::zeros(); 3];
        let mut com = [Vector3::zeros(); 3];
        let mut inertia = [Matrix3::zeros(); 3];
        let (mut prev_omega, mut prev_alpha) = (Vector3::zeros(), Vector3::zeros());
        // Gravity enters as an upward acceleration of the (fixed) base.
        let (mut prev_accel, mut prev_origin) = (-gravity_base, frames.joint_origin[0]);
        for i in 0..3 {
            let z = frames.joint_axis[i];
            let lever = frames.joint_origin[i] - prev_origin;
            accel_origin[i] =
                prev_accel + prev_alpha.cross(&lever) + prev_omega.cross(&prev_omega.cross(&lever));
            omega[i] = prev_omega + z * dq[i];
            alpha[i] = prev_alpha + z * ddq[i] + prev_omega.cross(&(z * dq[i]));
            let r = frames.link_rotation[i];
            com[i] = frames.joint_origin[i] + r * chain.joints[i].body.com;
            inertia[i] = r * chain.joints[i].body.inertia_com * r.transpose();
            prev_omega = omega[i];
            prev_alpha = alpha[i];
            prev_accel = accel_origin[i];
            prev_origin = frames.joint_origin[i];
        }
        let mut tau = Vector3::zeros();
        let (mut f_next, mut n_next) = (Vector3::zeros(), Vector3::zeros());
        for i in (0..3).rev() {
            let body = &chain.joints[i].body;
            let c = com[i] - frames.joint_origin[i];
            let accel_com =
                accel_origin[i] + alpha[i].cross(&c) + omega[i].cross(&omega[i].cross(&c));
            let force = accel_com * body.mass;
            let moment = inertia[i] * alpha[i] + omega[i].cross(&(inertia[i] * omega[i]));
            let next_lever = if i < 2 {
                frames.joint_origin[i + 1] - frames.joint_origin[i]
            } else {
                Vector3::zeros()
            };
            let f = force + f_next;
            let n = moment + c.cross(&force) + n_next + next_lever.cross(&f_next);
            tau[i] = frames.joint_axis[i].dot(&n);
            f_next = f;
            n_next = n;
        }
        tau
    }

    /// Joint-space inertia matrix M(q) of one leg (fixed base), kg·m².
    pub fn leg_mass_matrix(&self, leg: Leg, q_leg: [f64; 3]) -> [[f64; 3]; 3] {
        to_array33(&self.mass_matrix(leg, q_leg))
    }

    pub(crate) fn mass_matrix(&self, leg: Leg, q: [f64; 3]) -> Matrix3<f64> {
        let mut m = Matrix3::zeros();
        for j in 0..3 {
            let mut unit = [0.0; 3];
            unit[j] = 1.0;
            let column = self.rnea(leg, q, [0.0; 3], unit, Vector3::zeros());
            m.set_column(j, &column);
        }
        // RNEA columns are symmetric up to rounding; symmetrise so callers get an exact SPD matrix.
        (m + m.transpose()) * 0.5
    }

    /// Bias torques h(q, q̇) = C(q, q̇)q̇ + g(q) of one leg (fixed base), N·m, with
    /// `gravity_base` the gravity acceleration expressed in the base frame (e.g. Rᵀ(0, 0, −9.81)).
    pub fn leg_bias(
        &self,
        leg: Leg,
        q_leg: [f64; 3],
        dq_leg: [f64; 3],
        gravity_base: [f64; 3],
    ) -> [f64; 3] {
        let g = Vector3::new(gravity_base[0], gravity_base[1], gravity_base[2]);
        to_array3(&self.rnea(leg, q_leg, dq_leg, [0.0; 3], g))
    }

    /// Inertia of the whole robot about its centre of mass in the base frame, with all legs at
    /// `joint_positions`, and the CoM offset from the base origin (base frame). Used as the
    /// single-rigid-body inertia of the MPC.
    pub fn composite_inertia(
        &self,
        joint_positions: &[f64; NUM_JOINTS],
    ) -> ([[f64; 3]; 3], [f64; 3]) {
        let mut total = self.base_body;
        for leg in Leg::ALL {
            let l = leg.index();
            let q = [
                joint_positions[3 * l],
                joint_positions[3 * l + 1],
                joint_positions[3 * l + 2],
            ];
            let frames = self.frames(leg, q);
            for (i, joint) in self.legs[l].joints.iter().enumerate() {
                let pose = Transform {
                    rotation: frames.link_rotation[i],
                    translation: frames.joint_origin[i],
                };
                total.merge(&joint.body, &pose);
            }
        }
        (to_array33(&total.inertia_com), to_array3(&total.com))
    }
}
