//! Stand: four-leg balance with the MPC, holding the base where it was on entry.

use super::{balancing_transition, Actuation, Stages, Tick};
use crate::api::{FsmState, Leg, ModeRequest, NUM_JOINTS, NUM_LEGS};
use crate::estimate::Estimate;
use crate::footholds::MotionTarget;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Stand {
    /// Base pose held, taken on entry.
    hold: MotionTarget,
}

impl Stand {
    pub fn new() -> Self {
        Stand {
            hold: MotionTarget {
                xy: [0.0; 2],
                yaw: 0.0,
                velocity: [0.0; 2],
                yaw_rate: 0.0,
            },
        }
    }

    pub fn enter(&mut self, estimate: &Estimate) {
        self.hold = MotionTarget {
            xy: [estimate.position.x, estimate.position.y],
            yaw: estimate.rpy.z,
            velocity: [0.0; 2],
            yaw_rate: 0.0,
        };
    }

    pub fn run(&mut self, stages: &mut Stages, tick: &Tick) -> Actuation {
        let Tick {
            model,
            estimate,
            reference,
            ..
        } = *tick;
        let contacts = [true; NUM_LEGS];
        stages.mpc.set_schedule(|_| contacts);
        stages.mpc.update_forces(
            &stages.footholds,
            estimate,
            reference,
            &self.hold,
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
        Actuation::all_stance(torques, forces, estimate)
    }

    pub fn check_transition(&self, fault: Option<&str>, mode: ModeRequest) -> Option<FsmState> {
        balancing_transition(fault, mode, FsmState::Stand)
    }
}
