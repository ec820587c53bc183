//! Leg control stage: the joint torque laws. Stance legs realise the MPC's ground reaction force
//! `f` with `τ = Jᵀ (Rᵀ (−f)) + h(q, q̇)`: `−f` is the force the foot exerts on the ground, `Rᵀ`
//! takes it to the base frame where the foot Jacobian `J` lives, and `h` (leg gravity + Coriolis,
//! fixed-base model) carries the leg's own weight so that the base receives exactly `f` minus the
//! leg weight. Swing legs track the swing trajectory in joint space:
//! `τ = M(q) q̈_ref + h(q, q̇) + K_p (q_ref − q) + K_d (q̇_ref − q̇)` with `q_ref` from IK. Also the
//! stand-up (joint targets from the feet and a base pose, a statically balanced feed-forward),
//! joint damping, and the final clamp to the URDF effort limits.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::api::{Leg, RobotState, GRAVITY, NUM_JOINTS, NUM_LEGS};
use crate::config::ControllerConfig;
use crate::estimate::{leg_slice, Estimate};
use crate::gait::SwingSample;
use crate::model::RobotModel;
use crate::statics::{static_vertical_forces, BasePose};

/// Joint damping per inertia and input period at most (k_d·T/M_ii): a held velocity feedback with
/// k_d·T/M_ii above 2 reverses the joint's velocity every period, and the joint chatters.
const HELD_KD_LIMIT: f64 = 1.0;
/// Joint stiffness per inertia and squared input period at most (k_p·T²/M_ii).
const HELD_KP_LIMIT: f64 = 0.25;
/// Step of the finite difference that gives J̇q̇ along the reference joint velocity, s.
const JDOT_STEP: f64 = 1e-6;
/// The knee guard acts once a knee is bent less than this towards its branch, rad. Walking keeps
/// every shipped robot's knees bent 0.5 rad or more (ANYmal's the least); a leg that reaches
/// for ground that is not there straightens through this.
pub const KNEE_GUARD_BEND: f64 = 0.25;
/// Fractions of the hip → target distance tried, in order, when a swing target is out of reach.
const IK_PULL_IN: [f64; 5] = [1.0, 0.95, 0.9, 0.8, 0.7];

/// The torque laws and their gains and limits.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LegControl {
    effort_limits: [f64; NUM_JOINTS],
    lower_limits: [f64; NUM_JOINTS],
    upper_limits: [f64; NUM_JOINTS],
    stand_joint_positions: [f64; NUM_JOINTS],
    kp_swing: [f64; 3],
    kd_swing: [f64; 3],
    kp_stand: [f64; 3],
    kd_stand: [f64; 3],
    damping_kd: f64,
    /// Least vertical force on a foot in the stand-up's weight distribution, N.
    f_min: f64,
    /// CoM offset from the base origin, base frame, m.
    com_offset_body: Vector3<f64>,
    /// How long each state given to `step` stays in force (0: a fresh state every tick).
    input_period_s: f64,
}

impl LegControl {
    /// The torque laws of `model` with the gains of `config`; `stand_joint_positions` is the
    /// standing pose (index 3·leg + j), whose CoM is at `com_offset_body` from the base origin.
    pub fn new(
        model: &RobotModel,
        config: &ControllerConfig,
        stand_joint_positions: [f64; NUM_JOINTS],
        com_offset_body: Vector3<f64>,
    ) -> Self {
        LegControl {
            effort_limits: model.effort_limits(),
            lower_limits: model.lower_limits(),
            upper_limits: model.upper_limits(),
            stand_joint_positions,
            kp_swing: config.kp_swing,
            kd_swing: config.kd_swing,
            kp_stand: config.kp_stand,
            kd_stand: config.kd_stand,
            damping_kd: config.damping_kd,
            f_min: config.f_min,
            com_offset_body,
            input_period_s: 0.0,
        }
    }

    /// Declares how long each input is held (see `Controller::set_input_period`).
    pub fn set_input_period(&mut self, seconds: f64) {
        self.input_period_s = seconds;
    }

    /// Joint angles of the standing pose, index 3·leg + j.
    pub fn stand_joint_positions(&self) -> [f64; NUM_JOINTS] {
        self.stand_joint_positions
    }

    /// CoM offset from the base origin in the standing pose, base frame, m.
    pub fn com_offset_body(&self) -> Vector3<f64> {
        self.com_offset_body
    }

    /// Lower and upper joint limits, index 3·leg + j, rad.
    pub fn joint_limits(&self) -> (&[f64; NUM_JOINTS], &[f64; NUM_JOINTS]) {
        (&self.lower_limits, &self.upper_limits)
    }

    /// PD gains for a joint of inertia `inertia` under the declared input period.
    fn held_gains(&self, kp: f64, kd: f64, inertia: f64) -> (f64, f64) {
        let period = self.input_period_s;
        if period <= 0.0 || !(inertia.is_finite() && inertia > 0.0) {
            return (kp, kd);
        }
        (
            kp.min(HELD_KP_LIMIT * inertia / (period * period)),
            kd.min(HELD_KD_LIMIT * inertia / period),
        )
    }

    /// Stance: `τ = Jᵀ Rᵀ (−f) + h(q, q̇)`.
    pub fn stance_torques(
        &self,
        model: &RobotModel,
        estimate: &Estimate,
        leg: Leg,
        force: [f64; 3],
        torques: &mut [f64; NUM_JOINTS],
    ) {
        let l = leg.index();
        let f = Vector3::from(force);
        let foot_force_body = estimate.rotation.transpose() * (-f);
        let jac = Matrix3::from(model.foot_jacobian_body(leg, estimate.q[l])).transpose();
        let tau = jac.transpose() * foot_force_body;
        let bias = model.leg_bias(leg, estimate.q[l], estimate.dq[l], estimate.gravity_body);
        for j in 0..3 {
            torques[3 * l + j] = tau[j] + bias[j];
        }
    }

    /// Swing: `τ = M q̈_ref + h + K_p (q_ref − q) + K_d (q̇_ref − q̇)` along the swing trajectory.
    pub fn swing_torques(
        &self,
        model: &RobotModel,
        estimate: &Estimate,
        leg: Leg,
        sample: &SwingSample,
        torques: &mut [f64; NUM_JOINTS],
    ) {
        let l = leg.index();
        let rt = estimate.rotation.transpose();
        let relative = Vector3::from(sample.position) - estimate.position;
        let p_body = rt * relative;
        let omega_body = rt * estimate.angular_velocity;
        let v_body =
            rt * (Vector3::from(sample.velocity) - estimate.velocity) - omega_body.cross(&p_body);
        let a_body = rt * Vector3::from(sample.acceleration);
        let q_ref = self.reachable_ik(model, leg, p_body, estimate.q[l]);
        let jac_ref = Matrix3::from(model.foot_jacobian_body(leg, q_ref)).transpose();
        let (dq_ref, ddq_ref) = match jac_ref.try_inverse() {
            Some(inverse) => {
                let dq_ref = inverse * v_body;
                let eps = JDOT_STEP;
                let q_ahead = [
                    q_ref[0] + eps * dq_ref[0],
                    q_ref[1] + eps * dq_ref[1],
                    q_ref[2] + eps * dq_ref[2],
                ];
                let jac_ahead = Matrix3::from(model.foot_jacobian_body(leg, q_ahead)).transpose();
                let jdot_qdot = (jac_ahead - jac_ref) * dq_ref / eps;
                (dq_ref, inverse * (a_body - jdot_qdot))
            }
            None => (Vector3::zeros(), Vector3::zeros()),
        };
        let mass = model.mass_matrix(leg, estimate.q[l]);
        let bias = model.leg_bias(leg, estimate.q[l], estimate.dq[l], estimate.gravity_body);
        let inertial = mass * ddq_ref;
        for j in 0..3 {
            let (kp, kd) = self.held_gains(self.kp_swing[j], self.kd_swing[j], mass[(j, j)]);
            torques[3 * l + j] = inertial[j]
                + bias[j]
                + kp * (q_ref[j] - estimate.q[l][j])
                + kd * (dq_ref[j] - estimate.dq[l][j]);
        }
    }

    /// IK of a swing target, pulled towards the hip until reachable and clamped to the joint
    /// limits; falls back to the current joint angles.
    fn reachable_ik(
        &self,
        model: &RobotModel,
        leg: Leg,
        p_body: Vector3<f64>,
        current: [f64; 3],
    ) -> [f64; 3] {
        let hip = Vector3::from(model.hip_position_body(leg));
        let mut q = current;
        for scale in IK_PULL_IN {
            let target = hip + (p_body - hip) * scale;
            if let Some(solution) =
                model.try_inverse_kinematics(leg, [target.x, target.y, target.z])
            {
                q = solution;
                break;
            }
        }
        let base = 3 * leg.index();
        for (j, angle) in q.iter_mut().enumerate() {
            *angle = angle.clamp(self.lower_limits[base + j], self.upper_limits[base + j]);
        }
        q
    }

    /// Stand-up joint targets: for each leg, the joints that keep its foot at `feet[leg]`
    /// (world frame) with the base at `pose`; where that is out of reach, the pose at entry
    /// `start` interpolated by `s` towards the standing pose in joint space.
    pub fn stand_up_joint_targets(
        &self,
        model: &RobotModel,
        pose: &BasePose,
        feet: &[Vector3<f64>; NUM_LEGS],
        start: &[f64; NUM_JOINTS],
        s: f64,
    ) -> [f64; NUM_JOINTS] {
        let rt = pose.rotation().transpose();
        let mut targets = [0.0; NUM_JOINTS];
        for leg in Leg::ALL {
            let base = 3 * leg.index();
            let p_body = rt * (feet[leg.index()] - pose.position);
            let solution = model.inverse_kinematics_within_limits(
                leg,
                [p_body.x, p_body.y, p_body.z],
                std::array::from_fn(|j| self.lower_limits[base + j]),
                std::array::from_fn(|j| self.upper_limits[base + j]),
            );
            for j in 0..3 {
                let i = base + j;
                targets[i] = match solution {
                    Some(q) => q[j],
                    None => start[i] + (self.stand_joint_positions[i] - start[i]) * s,
                };
            }
        }
        targets
    }

    /// Stand-up: joint PD towards `q_ref` plus the feed-forward of vertical ground forces that
    /// carry the share `s` of the weight with no moment about the CoM over the measured feet
    /// (`static_vertical_forces`). Returns the torques and the forces assumed.
    pub fn stand_up_torques(
        &self,
        model: &RobotModel,
        estimate: &Estimate,
        q_ref: &[f64; NUM_JOINTS],
        s: f64,
    ) -> ([f64; NUM_JOINTS], [[f64; 3]; NUM_LEGS]) {
        let com = estimate.position + estimate.rotation * self.com_offset_body;
        let weight = model.total_mass() * GRAVITY * s;
        let vertical = static_vertical_forces(&estimate.feet_world, &com, weight, self.f_min * s);
        let mut torques = [0.0; NUM_JOINTS];
        let mut forces = [[0.0; 3]; NUM_LEGS];
        for leg in Leg::ALL {
            let l = leg.index();
            let ground_force = Vector3::new(0.0, 0.0, vertical[l]);
            let foot_force_body = estimate.rotation.transpose() * (-ground_force);
            let jac = Matrix3::from(model.foot_jacobian_body(leg, estimate.q[l])).transpose();
            let feed_forward = jac.transpose() * foot_force_body;
            let mass = model.mass_matrix(leg, estimate.q[l]);
            for j in 0..3 {
                let i = 3 * l + j;
                let (kp, kd) = self.held_gains(self.kp_stand[j], self.kd_stand[j], mass[(j, j)]);
                torques[i] =
                    kp * (q_ref[i] - estimate.q[l][j]) - kd * estimate.dq[l][j] + feed_forward[j];
            }
            forces[l] = [0.0, 0.0, vertical[l]];
        }
        (torques, forces)
    }

    /// A virtual end stop at the straight knee: a knee bent less than [`KNEE_GUARD_BEND`] towards
    /// its branch gets a spring (the full effort limit at straight) and a damper against
    /// straightening further, added to `torques`. A knee without a mechanical stop (ANYmal B's
    /// turn all the way round) that goes through straight flips the leg to the other branch,
    /// where the IK and the stance forces no longer fit it, and the robot falls.
    pub fn guard_knees(
        &self,
        model: &RobotModel,
        estimate: &Estimate,
        torques: &mut [f64; NUM_JOINTS],
    ) {
        for leg in Leg::ALL {
            let l = leg.index();
            let bend = model.knee_bend(leg, estimate.q[l]);
            if bend >= KNEE_GUARD_BEND {
                continue;
            }
            let per_angle = model.knee_bend_per_angle(leg);
            let bend_rate = per_angle * estimate.dq[l][2];
            let i = 3 * l + 2;
            let stiffness = self.effort_limits[i] / KNEE_GUARD_BEND;
            let inertia = model.mass_matrix(leg, estimate.q[l])[(2, 2)];
            let (stiffness, damping) =
                self.held_gains(stiffness, 2.0 * (stiffness * inertia).sqrt(), inertia);
            let push = stiffness * (KNEE_GUARD_BEND - bend) - damping * bend_rate.min(0.0);
            torques[i] += per_angle * push;
        }
    }

    /// Joint damping `−k_d q̇` with the joint inertia of the current pose.
    pub fn damping_torques(&self, model: &RobotModel, estimate: &Estimate) -> [f64; NUM_JOINTS] {
        let mut torques = [0.0; NUM_JOINTS];
        for leg in Leg::ALL {
            let mass = model.mass_matrix(leg, estimate.q[leg.index()]);
            for j in 0..3 {
                let (_, kd) = self.held_gains(0.0, self.damping_kd, mass[(j, j)]);
                torques[3 * leg.index() + j] = -kd * estimate.dq[leg.index()][j];
            }
        }
        torques
    }

    /// Damping torques `−k_d q̇` of a possibly invalid state: clamped, zero for non-finite
    /// velocities, the joint inertia taken at the standing pose.
    pub fn safe_damping_torques(
        &self,
        model: &RobotModel,
        state: &RobotState,
    ) -> [f64; NUM_JOINTS] {
        let mut torques = [0.0; NUM_JOINTS];
        for (i, tau) in torques.iter_mut().enumerate() {
            let dq = state.joint_velocities[i];
            if dq.is_finite() {
                let leg = Leg::ALL[i / 3];
                let mass = model.mass_matrix(leg, leg_slice(&self.stand_joint_positions, leg));
                let (_, kd) = self.held_gains(0.0, self.damping_kd, mass[(i % 3, i % 3)]);
                let limit = self.effort_limits[i];
                *tau = (-kd * dq).clamp(-limit, limit);
            }
        }
        torques
    }

    /// The torques the motors get: clamped to the URDF effort limits, zero where not finite.
    pub fn clamp_to_effort_limits(&self, mut torques: [f64; NUM_JOINTS]) -> [f64; NUM_JOINTS] {
        for (i, tau) in torques.iter_mut().enumerate() {
            let limit = self.effort_limits[i];
            *tau = if tau.is_finite() {
                tau.clamp(-limit, limit)
            } else {
                0.0
            };
        }
        torques
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn our_robot() -> RobotModel {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robot/quadruped.toml");
        RobotModel::from_config_file(&path).expect("our robot loads")
    }

    fn guard_at(
        model: &RobotModel,
        legs: &LegControl,
        q: [f64; NUM_JOINTS],
        dq: [f64; NUM_JOINTS],
    ) -> [f64; NUM_JOINTS] {
        let state = RobotState {
            base_position: [0.0, 0.0, model.stand_height()],
            joint_positions: q,
            joint_velocities: dq,
            ..RobotState::default()
        };
        let estimate = Estimate::from_measurement(model, &state);
        let mut torques = [0.0; NUM_JOINTS];
        legs.guard_knees(model, &estimate, &mut torques);
        torques
    }

    #[test]
    fn the_knee_guard_pushes_a_nearly_straight_knee_back_to_its_branch_and_leaves_bent_knees_alone()
    {
        let model = our_robot();
        let stand = model
            .stand_joint_positions(model.stand_height())
            .expect("stand");
        let legs = LegControl::new(
            &model,
            &ControllerConfig::default(),
            stand,
            Vector3::zeros(),
        );
        assert_eq!(
            guard_at(&model, &legs, stand, [0.0; NUM_JOINTS]),
            [0.0; NUM_JOINTS]
        );
        for leg in Leg::ALL {
            let l = leg.index();
            let i = 3 * l + 2;
            let per_angle = model.knee_bend_per_angle(leg);
            let stand_bend = model.knee_bend(leg, leg_slice(&stand, leg));
            assert!(stand_bend > 2.0 * KNEE_GUARD_BEND, "{leg:?}: {stand_bend}");
            // The knee angle at which the leg is straight, and three bends around it.
            let straight = stand[i] - stand_bend / per_angle;
            let push_at = |bend: f64, rate: f64| {
                let mut q = stand;
                q[i] = straight + bend / per_angle;
                let mut dq = [0.0; NUM_JOINTS];
                dq[i] = rate / per_angle;
                let torques = guard_at(&model, &legs, q, dq);
                assert!(torques.iter().enumerate().all(|(k, t)| k == i || *t == 0.0));
                per_angle * torques[i]
            };
            let (near, flipped) = (push_at(0.1, 0.0), push_at(-0.1, 0.0));
            let expected = model.effort_limits()[i] * (KNEE_GUARD_BEND - 0.1) / KNEE_GUARD_BEND;
            assert!(
                (near - expected).abs() < 1e-9,
                "{leg:?}: {near} vs {expected}"
            );
            assert!(flipped > near, "{leg:?}: a flipped knee is pushed harder");
            assert!(
                push_at(0.1, -2.0) > near,
                "{leg:?}: straightening is damped"
            );
            assert_eq!(
                push_at(0.1, 2.0),
                near,
                "{leg:?}: bending back is not damped"
            );
            assert_eq!(push_at(KNEE_GUARD_BEND + 1e-3, -5.0), 0.0, "{leg:?}");
        }
    }
}
