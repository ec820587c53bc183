//! Damping: the safe state after a fault, joint damping only. Left only through an explicit
//! request for passive (a fault is not cleared by asking to walk again).

use super::{measured_feet, Actuation, Stages, Tick};
use crate::api::{FsmState, ModeRequest, NUM_LEGS};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Damping;

impl Damping {
    pub fn enter(&mut self, stages: &mut Stages) {
        stages.mpc.clear_forces();
    }

    pub fn run(&mut self, stages: &Stages, tick: &Tick) -> Actuation {
        let Tick {
            model, estimate, ..
        } = *tick;
        Actuation {
            torques: stages.legs.damping_torques(model, estimate),
            contacts: [false; NUM_LEGS],
            forces: [[0.0; 3]; NUM_LEGS],
            feet: measured_feet(estimate),
        }
    }

    pub fn check_transition(&self, mode: ModeRequest) -> Option<FsmState> {
        match mode {
            ModeRequest::Passive => Some(FsmState::Passive),
            _ => None,
        }
    }
}
