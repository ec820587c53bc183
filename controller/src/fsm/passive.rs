//! Passive: zero torque. Left when the master asks for standing or walking (via stand-up).

use super::{Actuation, Stages};
use crate::api::{FsmState, ModeRequest, NUM_JOINTS, NUM_LEGS};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Passive;

impl Passive {
    pub fn enter(&mut self, stages: &mut Stages) {
        stages.mpc.clear_forces();
    }

    pub fn run(&mut self) -> Actuation {
        Actuation {
            torques: [0.0; NUM_JOINTS],
            contacts: [false; NUM_LEGS],
            forces: [[0.0; 3]; NUM_LEGS],
            feet: [[0.0; 3]; NUM_LEGS],
        }
    }

    pub fn check_transition(&self, mode: ModeRequest) -> Option<FsmState> {
        match mode {
            ModeRequest::Passive => None,
            ModeRequest::Stand | ModeRequest::Locomotion => Some(FsmState::StandUp),
        }
    }
}
