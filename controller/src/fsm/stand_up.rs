//! Stand-up: joint-space interpolation from the pose at entry to the standing pose over
//! `stand_up_duration`, with a feed-forward of a growing share of the weight on each foot.

use super::{balancing_transition, Actuation, Stages, Tick};
use crate::api::{FsmState, ModeRequest, GRAVITY, NUM_JOINTS, NUM_LEGS};
use crate::estimate::Estimate;
use serde::{Deserialize, Serialize};

/// 3s² − 2s³ on s clamped to [0, 1]: starts and ends the interpolation at zero joint velocity.
fn smoothstep(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StandUp {
    duration: f64,
    /// Joint angles at entry, index 3·leg + j, rad.
    start: [f64; NUM_JOINTS],
}

impl StandUp {
    pub fn new(duration: f64) -> Self {
        StandUp {
            duration,
            start: [0.0; NUM_JOINTS],
        }
    }

    pub fn enter(&mut self, estimate: &Estimate) {
        for (l, q) in estimate.q.iter().enumerate() {
            self.start[3 * l..3 * l + 3].copy_from_slice(q);
        }
    }

    pub fn run(&mut self, stages: &Stages, tick: &Tick) -> Actuation {
        let Tick {
            model,
            estimate,
            state_time,
            ..
        } = *tick;
        let s = smoothstep(state_time / self.duration);
        let weight_share = model.total_mass() * GRAVITY / NUM_LEGS as f64 * s;
        let (torques, forces) =
            stages
                .legs
                .stand_up_torques(model, estimate, &self.start, s, weight_share);
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
