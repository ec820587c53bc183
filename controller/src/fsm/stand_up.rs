//! Stand-up: the base moves from its pose at entry to a standing pose over the feet where they
//! are, over `stand_up_duration`; the joint targets are the leg inverse kinematics of that
//! moving base, and a statically balanced, growing share of the weight is fed forward.
//!
//! The standing pose has the CoM over the feet's centroid, roll 0 and the pitch the MPC will ask
//! for (the clamped terrain pitch), so the balancing states take over a robot already in their
//! reference pose. A fixed body-frame pose would keep a body set down parallel to an incline
//! with its CoM downhill of the feet (docs/slopes.md, 3b).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{balancing_transition, Actuation, Stages, Tick};
use crate::api::{FsmState, ModeRequest, Reference, NUM_JOINTS, NUM_LEGS};
use crate::estimate::Estimate;
use crate::model::RobotModel;
use crate::statics::{standing_pose_over_feet, BasePose};

/// 3s² − 2s³ on s clamped to [0, 1]: starts and ends the interpolation at zero joint velocity.
fn smoothstep(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

/// Time over which the feed-forward grows to the full weight, s: a robot set down on its feet
/// carries its weight from the start, and legs without it sag unevenly and tip it.
const WEIGHT_RAMP_S: f64 = 0.1;
/// Time over which the base moves horizontally and turns to the standing pose, s (its height
/// follows over the whole stand-up).
const BALANCE_SHIFT_S: f64 = 0.3;

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StandUp {
    duration: f64,
    /// Joint angles at entry, index 3·leg + j, rad.
    start: [f64; NUM_JOINTS],
    /// Base pose at entry.
    start_pose: BasePose,
    /// Standing pose the base moves to.
    target_pose: BasePose,
    /// Feet at entry, world frame, m: the stand-up keeps them where they are.
    feet: [Vector3<f64>; NUM_LEGS],
}

impl StandUp {
    pub fn new(duration: f64) -> Self {
        let rest = BasePose {
            position: Vector3::zeros(),
            rpy: Vector3::zeros(),
        };
        StandUp {
            duration,
            start: [0.0; NUM_JOINTS],
            start_pose: rest,
            target_pose: rest,
            feet: [Vector3::zeros(); NUM_LEGS],
        }
    }

    pub fn enter(
        &mut self,
        model: &RobotModel,
        stages: &Stages,
        estimate: &Estimate,
        reference: &Reference,
    ) {
        for (l, q) in estimate.q.iter().enumerate() {
            self.start[3 * l..3 * l + 3].copy_from_slice(q);
        }
        self.feet = estimate.feet_world;
        self.start_pose = BasePose {
            position: estimate.position,
            rpy: estimate.rpy,
        };
        let yaw = estimate.rpy.z;
        let pitch = stages
            .footholds
            .stance_ground(reference, estimate.position.x, estimate.position.y, yaw)
            .pitch;
        // The ground under the feet, not the reference's plane: the stand-up must reach from
        // where the feet are whatever the reference says.
        let ground =
            self.feet.iter().map(|f| f.z).sum::<f64>() / NUM_LEGS as f64 - model.foot_radius();
        self.target_pose = standing_pose_over_feet(
            &self.feet,
            &stages.legs.com_offset_body(),
            yaw,
            pitch,
            ground,
            stages.footholds.body_height(reference),
        );
    }

    pub fn run(&mut self, stages: &Stages, tick: &Tick) -> Actuation {
        let Tick {
            model,
            estimate,
            state_time,
            ..
        } = *tick;
        let s = smoothstep(state_time / self.duration);
        // The CoM goes over the feet first: set down parallel to a steep incline it may start
        // at or beyond the downhill feet, and it tips within a few tenths of a second.
        let shift = smoothstep(state_time / BALANCE_SHIFT_S.min(self.duration));
        let mut pose = self.start_pose.lerp(&self.target_pose, shift);
        pose.position.z = self.start_pose.position.z
            + (self.target_pose.position.z - self.start_pose.position.z) * s;
        let q_ref = stages
            .legs
            .stand_up_joint_targets(model, &pose, &self.feet, &self.start, s);
        let load = smoothstep(state_time / WEIGHT_RAMP_S.min(self.duration));
        let (torques, forces) = stages.legs.stand_up_torques(model, estimate, &q_ref, load);
        Actuation::all_stance(torques, forces, estimate)
    }

    pub fn check_transition(
        &self,
        fault: Option<&str>,
        mode: ModeRequest,
        state_time: f64,
    ) -> Option<FsmState> {
        // Stand-up runs to its end whatever balancing mode is asked for; only passive or a
        // fault cuts it short.
        match balancing_transition(fault, mode, FsmState::StandUp) {
            Some(next @ (FsmState::Damping | FsmState::Passive)) => Some(next),
            _ => (state_time >= self.duration).then_some(FsmState::Stand),
        }
    }
}
