//! Stand: four-leg balance with the MPC, holding the base with its CoM over the feet's centroid
//! (on an incline the pose at entry may leave it downhill of them, and the first diagonal support
//! of a trot then cannot hold it: docs/slopes.md, 3d) and the roll reference ramped from the
//! measured roll to 0.

use super::{balancing_transition, Actuation, Stages, Tick};
use crate::api::{FsmState, Leg, ModeRequest, NUM_JOINTS, NUM_LEGS};
use crate::estimate::Estimate;
use crate::footholds::MotionTarget;
use crate::math::rot_z;
use crate::statics::base_xy_over_feet;
use serde::{Deserialize, Serialize};

/// Time over which the roll reference goes from the roll at entry to 0, s: a stepped reference
/// makes the MPC roll the body as fast as its forces allow, loading the downhill legs at once.
const ROLL_RAMP_S: f64 = 0.3;

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Stand {
    /// Base pose held, taken on entry (its roll is the roll at entry).
    hold: MotionTarget,
    /// Time since entry, s.
    time: f64,
}

impl Stand {
    pub fn new() -> Self {
        Stand {
            hold: MotionTarget {
                xy: [0.0; 2],
                roll: 0.0,
                yaw: 0.0,
                velocity: [0.0; 2],
                foothold_velocity: [0.0; 2],
                yaw_rate: 0.0,
            },
            time: 0.0,
        }
    }

    pub fn enter(&mut self, stages: &Stages, estimate: &Estimate) {
        let yaw = estimate.rpy.z;
        // The MPC's reference places the CoM at the base xy plus the yawed CoM offset.
        let com_offset = rot_z(yaw) * stages.legs.com_offset_body();
        self.hold = MotionTarget {
            xy: base_xy_over_feet(&estimate.feet_world, &com_offset),
            roll: estimate.rpy.x,
            yaw,
            velocity: [0.0; 2],
            foothold_velocity: [0.0; 2],
            yaw_rate: 0.0,
        };
        self.time = 0.0;
    }

    /// The roll reference `time` after entry: the roll at entry ramped linearly to 0.
    fn roll_reference(&self) -> f64 {
        self.hold.roll * (1.0 - self.time / ROLL_RAMP_S).max(0.0)
    }

    pub fn run(&mut self, stages: &mut Stages, tick: &Tick) -> Actuation {
        let Tick {
            model,
            estimate,
            reference,
            dt,
            ..
        } = *tick;
        let contacts = [true; NUM_LEGS];
        let target = MotionTarget {
            roll: self.roll_reference(),
            ..self.hold
        };
        self.time += dt;
        stages.mpc.set_schedule(|_| contacts);
        stages.mpc.update_forces(
            &stages.footholds,
            estimate,
            reference,
            &target,
            contacts,
            |_, leg, _| estimate.feet_world[leg.index()],
        );
        let forces = stages.mpc.forces();
        let mut torques = [0.0; NUM_JOINTS];
        for leg in Leg::ALL {
            stages
                .legs
                .stance_torques(model, estimate, leg, forces[leg.index()], &mut torques);
        }
        stages.legs.guard_knees(model, estimate, &mut torques);
        Actuation::all_stance(torques, forces, estimate)
    }

    pub fn check_transition(&self, fault: Option<&str>, mode: ModeRequest) -> Option<FsmState> {
        balancing_transition(fault, mode, FsmState::Stand)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_roll_reference_ramps_from_the_entry_roll_to_zero() {
        let mut stand = Stand::new();
        stand.hold.roll = -0.4;
        assert_eq!(stand.roll_reference(), -0.4);
        stand.time = 0.5 * ROLL_RAMP_S;
        assert!((stand.roll_reference() + 0.2).abs() < 1e-12);
        stand.time = 2.0 * ROLL_RAMP_S;
        assert_eq!(stand.roll_reference(), 0.0);
    }
}
