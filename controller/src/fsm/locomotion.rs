//! Locomotion: the gait following the reference. Each tick runs the pipeline gait schedule →
//! touchdown footholds of the swing legs → MPC forces for the stance legs → leg torque laws
//! (stance `Jᵀ f`, swing trajectory tracking).
//!
//! A push cuts the swings short: when the reference governor takes a new one in, the legs in
//! swing land `recovery_touchdown_time` later at their (velocity-feedback) footholds and stand
//! until their own stance begins, so the trunk stands on four feet instead of a diagonal pair
//! while the push lasts; the legs in stance keep the gait's timing, and the swings that follow
//! while the body is braked run on the gait's clock.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{balancing_transition, Actuation, Stages, Tick};
use crate::api::{FsmState, Leg, ModeRequest, Reference, NUM_JOINTS, NUM_LEGS};
use crate::config::ControllerConfig;
use crate::estimate::Estimate;
use crate::estimator::StancePlan;
use crate::footholds::{FootholdPlanner, MotionTarget};
use crate::gait::{swing_trajectory, Gait, LegPhase};
use crate::reference_governor::ReferenceGovernor;
use crate::steep_ground::SteepGround;

/// A swing cut short by a push: retargeted at gait time `from` (with the foot at `start`), the
/// foot lands at `lands_at` and stands until its own stance begins at `stance_at`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
struct EarlyTouchdown {
    from: f64,
    lands_at: f64,
    stance_at: f64,
    start: Vector3<f64>,
}

/// The phase of `leg` at gait time `t`: the gait's, unless a push cut its swing short.
fn leg_phase(
    gait: &Gait,
    early: &[Option<EarlyTouchdown>; NUM_LEGS],
    leg: Leg,
    t: f64,
) -> LegPhase {
    match early[leg.index()] {
        Some(e) if t < e.lands_at => LegPhase::Swing((t - e.from) / (e.lands_at - e.from)),
        Some(e) if t < e.stance_at => LegPhase::Stance(0.0),
        _ => gait.phase(leg, t),
    }
}

fn stance_flags(
    gait: &Gait,
    early: &[Option<EarlyTouchdown>; NUM_LEGS],
    t: f64,
) -> [bool; NUM_LEGS] {
    Leg::ALL.map(|leg| matches!(leg_phase(gait, early, leg, t), LegPhase::Stance(_)))
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Locomotion {
    gait: Gait,
    mpc_dt: f64,
    /// Time since entering locomotion, s (the gait's clock).
    gait_time: f64,
    /// Stance flags of the previous tick (edges start swings and stances).
    contacts: [bool; NUM_LEGS],
    /// Foot position at lift-off of each leg's current swing, world frame, m.
    swing_start: [Vector3<f64>; NUM_LEGS],
    /// Touchdown target of each leg's current (or last) swing, world frame, m.
    footholds: [Vector3<f64>; NUM_LEGS],
    /// Foot position at touchdown of each leg's current stance, world frame, m.
    stance_anchor: [Vector3<f64>; NUM_LEGS],
    /// The reference's accelerations limited on steep ground.
    governor: ReferenceGovernor,
    /// Configured friction coefficient and the margin kept above tan(slope) (steep ground).
    mu: f64,
    mu_slope_margin: f64,
    /// How long after a detected push the swinging legs land, s (0: on the gait's clock).
    touchdown_time: f64,
    /// The swings a push cut short, per leg (until the leg's own stance begins).
    early: [Option<EarlyTouchdown>; NUM_LEGS],
}

impl Locomotion {
    pub fn new(gait: Gait, config: &ControllerConfig) -> Self {
        Locomotion {
            gait,
            mpc_dt: config.mpc_dt,
            gait_time: 0.0,
            contacts: [false; NUM_LEGS],
            swing_start: [Vector3::zeros(); NUM_LEGS],
            footholds: [Vector3::zeros(); NUM_LEGS],
            stance_anchor: [Vector3::zeros(); NUM_LEGS],
            governor: ReferenceGovernor::with_recovery_acceleration(
                [0.0; 2],
                config.recovery_acceleration,
            ),
            mu: config.mu,
            mu_slope_margin: config.mu_slope_margin,
            touchdown_time: config.recovery_touchdown_time,
            early: [None; NUM_LEGS],
        }
    }

    pub fn enter(&mut self, estimate: &Estimate) {
        self.gait_time = 0.0;
        self.contacts = [true; NUM_LEGS];
        self.stance_anchor = estimate.feet_world;
        self.swing_start = estimate.feet_world;
        self.footholds = estimate.feet_world;
        self.early = [None; NUM_LEGS];
        self.governor = self
            .governor
            .restarted_at([estimate.velocity.x, estimate.velocity.y]);
    }

    pub fn run(&mut self, stages: &mut Stages, tick: &Tick) -> Actuation {
        let Tick {
            model,
            estimate,
            reference,
            dt,
            ..
        } = *tick;
        let t = self.gait_time;
        for early in &mut self.early {
            if early.is_some_and(|e| t >= e.stance_at) {
                *early = None;
            }
        }
        let was_recovering = self.governor.recovering();
        let pushed = self.governor.absorb_push(
            [reference.x, reference.y],
            [estimate.position.x, estimate.position.y],
            [estimate.velocity.x, estimate.velocity.y],
        );
        // Only the push's onset cuts swings short: while the governor brakes the body, the
        // departure exceeds the threshold again and again, and the gait has to step.
        if pushed && !was_recovering {
            self.cut_swings_short(estimate, t);
        }
        let contacts = stance_flags(&self.gait, &self.early, t);
        self.track_contact_edges(estimate, contacts);
        let normal = stages
            .footholds
            .friction_normal(reference, estimate, contacts);
        let steep = SteepGround::new(&normal, self.mu, self.mu_slope_margin);
        let (xy, velocity) = self.governor.step(
            [reference.x, reference.y],
            [reference.vx, reference.vy],
            steep.max_acceleration,
            dt,
        );
        let target = MotionTarget {
            xy,
            roll: 0.0,
            yaw: reference.yaw,
            velocity,
            foothold_velocity: if self.governor.recovering() {
                [reference.vx, reference.vy]
            } else {
                velocity
            },
            yaw_rate: reference.yaw_rate,
        };
        self.plan_touchdowns(&stages.footholds, estimate, reference, &target);
        let (gait, early, mpc_dt) = (self.gait, self.early, self.mpc_dt);
        stages
            .mpc
            .set_schedule(|k| stance_flags(&gait, &early, t + k as f64 * mpc_dt));
        let this = &*self;
        stages.mpc.update_forces(
            &stages.footholds,
            estimate,
            reference,
            &target,
            contacts,
            |schedule, leg, k| {
                this.planned_foot(
                    &stages.footholds,
                    estimate,
                    reference,
                    &target,
                    schedule,
                    leg,
                    k,
                )
            },
        );
        let forces = stages.mpc.forces();
        let mut torques = [0.0; NUM_JOINTS];
        let mut feet = [[0.0; 3]; NUM_LEGS];
        for leg in Leg::ALL {
            let l = leg.index();
            match self.phase(leg, t) {
                LegPhase::Stance(_) => {
                    stages
                        .legs
                        .stance_torques(model, estimate, leg, forces[l], &mut torques);
                    let a = self.stance_anchor[l];
                    feet[l] = [a.x, a.y, a.z];
                }
                LegPhase::Swing(s) => {
                    let end = self.footholds[l];
                    let (start, apex, duration) = match self.early[l] {
                        Some(e) => (
                            e.start,
                            stages.footholds.landing_apex(reference, &e.start, &end),
                            e.lands_at - e.from,
                        ),
                        None => {
                            let start = self.swing_start[l];
                            let apex = stages.footholds.swing_apex(reference, &start, &end);
                            (start, apex, self.gait.swing_time())
                        }
                    };
                    let sample = swing_trajectory(
                        [start.x, start.y, start.z],
                        [end.x, end.y, end.z],
                        apex,
                        duration,
                        s,
                    );
                    stages
                        .legs
                        .swing_torques(model, estimate, leg, &sample, &mut torques);
                    feet[l] = sample.position;
                }
            }
        }
        stages.legs.guard_knees(model, estimate, &mut torques);
        self.gait_time += dt;
        Actuation {
            torques,
            contacts,
            forces,
            feet,
        }
    }

    /// The phase of `leg` at gait time `t`, swings cut short included.
    fn phase(&self, leg: Leg, t: f64) -> LegPhase {
        leg_phase(&self.gait, &self.early, leg, t)
    }

    /// The gait's phase of every leg at the coming tick.
    pub fn stance_plan(&self) -> StancePlan {
        Leg::ALL.map(|leg| match self.phase(leg, self.gait_time) {
            LegPhase::Stance(s) => Some(s),
            LegPhase::Swing(_) => None,
        })
    }

    pub fn check_transition(&self, fault: Option<&str>, mode: ModeRequest) -> Option<FsmState> {
        balancing_transition(fault, mode, FsmState::Locomotion)
    }

    /// Lands the legs in swing `touchdown_time` from now (those with more of their swing left),
    /// from where their feet are. Not in the gait's first cycle: a walk that starts from
    /// standing departs from the reference's speed by itself, and its first steps are the gait's.
    fn cut_swings_short(&mut self, estimate: &Estimate, t: f64) {
        if self.touchdown_time <= 0.0 || t < self.gait.period {
            return;
        }
        for leg in Leg::ALL {
            let l = leg.index();
            if self.early[l].is_some() {
                continue;
            }
            if let LegPhase::Swing(s) = self.gait.phase(leg, t) {
                let remaining = (1.0 - s) * self.gait.swing_time();
                if remaining > self.touchdown_time {
                    self.early[l] = Some(EarlyTouchdown {
                        from: t,
                        lands_at: t + self.touchdown_time,
                        stance_at: t + remaining,
                        start: estimate.feet_world[l],
                    });
                }
            }
        }
    }

    /// Records where each swing starts (lift-off) and each stance is anchored (touchdown).
    fn track_contact_edges(&mut self, estimate: &Estimate, contacts: [bool; NUM_LEGS]) {
        for leg in Leg::ALL {
            let l = leg.index();
            if self.contacts[l] && !contacts[l] {
                self.swing_start[l] = estimate.feet_world[l];
            } else if !self.contacts[l] && contacts[l] {
                self.stance_anchor[l] = estimate.feet_world[l];
            }
        }
        self.contacts = contacts;
    }

    /// Touchdown targets of the legs in swing (Raibert heuristic, recomputed every tick).
    fn plan_touchdowns(
        &mut self,
        planner: &FootholdPlanner,
        estimate: &Estimate,
        reference: &Reference,
        target: &MotionTarget,
    ) {
        let stance_time = self.gait.stance_time();
        for leg in Leg::ALL {
            if let LegPhase::Swing(s) = self.phase(leg, self.gait_time) {
                let remaining = match self.early[leg.index()] {
                    Some(e) => e.lands_at - self.gait_time,
                    None => (1.0 - s) * self.gait.swing_time(),
                };
                self.footholds[leg.index()] = planner.raibert_foothold(
                    estimate,
                    reference,
                    target,
                    leg,
                    remaining,
                    stance_time,
                );
            }
        }
    }

    /// Foot of a leg at horizon step k: its current position in the current stance, its
    /// touchdown target for the stance after the current swing, a nominal foothold afterwards.
    #[allow(clippy::too_many_arguments)] // the MPC's foot callback needs every input of the plan
    fn planned_foot(
        &self,
        planner: &FootholdPlanner,
        estimate: &Estimate,
        reference: &Reference,
        target: &MotionTarget,
        schedule: &[[bool; NUM_LEGS]],
        leg: Leg,
        k: usize,
    ) -> Vector3<f64> {
        let l = leg.index();
        let mut liftoffs = 0;
        let mut previous = self.contacts[l];
        for stance in schedule.iter().take(k + 1).skip(1).map(|step| step[l]) {
            if previous && !stance {
                liftoffs += 1;
            }
            previous = stance;
        }
        if liftoffs == 0 {
            if self.contacts[l] {
                estimate.feet_world[l]
            } else {
                self.footholds[l]
            }
        } else {
            let tk = k as f64 * self.mpc_dt;
            planner.raibert_foothold(
                estimate,
                reference,
                target,
                leg,
                tk,
                self.gait.stance_time(),
            )
        }
    }
}
