//! Contact detection from leg effort, fused with the gait phase (a static form of Bledt et al.
//! 2018, "Contact Model Fusion for Event-Based Locomotion in Unstructured Terrains", MIT
//! Cheetah 3): per leg a prior contact probability from the stance schedule and a likelihood from
//! the ground reaction force the joint torques imply, combined by Bayes' rule; the decision has
//! hysteresis.
//!
//! The force: the fixed-base leg dynamics `M(q)q̈ + h(q, q̇) = τ + Jᵀf` give the external joint
//! torque `Jᵀf = M(q)q̈ + h − τ`, with τ the torques the controller commanded on the previous tick
//! (applied over the interval that produced this tick's q̇), q̈ the encoder rate's difference over
//! that interval and the trunk's own acceleration taken into `h` through the accelerometer: the
//! leg's "gravity" in the base frame is `−f_imu` (the specific force), which is gravity minus
//! the trunk's acceleration. The raw estimate is low-passed (a discrete momentum observer
//! without the Ṁq̇ term), turned into a foot force with `J⁻ᵀ` and rotated into the world; its
//! vertical component is the evidence. A foot in the air while the schedule says stance gives
//! `f ≈ 0` however large the commanded stance torque is, since that torque goes into
//! accelerating the light leg.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::api::{Leg, NUM_JOINTS, NUM_LEGS};
use crate::estimate::leg_slice;
use crate::model::{FootKinematics, RobotModel};

/// Time constant of the force estimate's low-pass, s: long enough to average the tick-to-tick
/// noise of a differentiated joint rate, short against the 0.1–0.3 s of a touch-down or a
/// foot lifted by a rough rim.
pub const FORCE_FILTER_TIME: f64 = 0.005;
/// Vertical foot force at which the force evidence is neutral (probability ½), as a fraction of
/// the robot's weight: a trotting stance foot carries about half the weight, a swinging leg's
/// model error (unmodelled joint friction, the trunk's angular acceleration) stays below a few
/// per cent of it.
pub const CONTACT_FORCE_FRACTION: f64 = 0.12;
/// Spread of the force evidence's logistic, fraction of the weight: the evidence is 0.95 at
/// `CONTACT_FORCE_FRACTION + 3·spread` (about 0.2 of the weight) and 0.05 at 0.05 of it.
pub const CONTACT_FORCE_SPREAD_FRACTION: f64 = 0.025;
/// Prior contact probability of a foot in swing, and of a scheduled stance at its very start and
/// end; mid-stance it is `1 − PHASE_PRIOR_FLOOR`. Not 0/1 so that a clear force overrules the
/// schedule both ways (early touch-down, a foot in the air during stance).
pub const PHASE_PRIOR_FLOOR: f64 = 0.1;
/// The fused probability above which a foot not in contact becomes in contact, and below which a
/// foot in contact leaves it (hysteresis against chatter when the evidence is ambiguous).
pub const CONTACT_ON_PROBABILITY: f64 = 0.65;
/// See [`CONTACT_ON_PROBABILITY`].
pub const CONTACT_OFF_PROBABILITY: f64 = 0.35;
/// Share of a joint's velocity limit from which the leg's effort is no evidence: a joint held at
/// its limit (by the motor, or a simulator's velocity constraint) makes a torque the leg model
/// does not see. ANYmal C's knees pinned at 7.5 rad/s mid-swing read as 400 N on a foot in the
/// air, twice its stance load; the schedule decides while it lasts.
pub const VELOCITY_LIMIT_SHARE: f64 = 0.97;
/// Distance from a joint's position limit within which the leg counts as against its stop, rad.
/// The stop's reaction is a torque the leg model does not see, so the leg's effort there says
/// nothing new: the force measured before the stop holds. A hind leg of ours, in the air and
/// stretched to its knee stop while reaching for ground a push had moved away, read as a
/// 30–45 N stance load and alone carried the velocity estimate off by 2.6 m/s (headline sweep
/// run 23); a loaded leg folded to a stop under a sagging trunk still stands.
pub const POSITION_LIMIT_BAND: f64 = 0.02;

/// What the force-based detector concluded for one leg.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LegContact {
    /// Fused contact probability, 0..1.
    pub probability: f64,
    /// Hysteresis decision.
    pub in_contact: bool,
    /// Estimated vertical ground reaction force on the foot, world frame, N (`None` before the
    /// detector has two ticks of torques and rates, at a singular leg pose or at a velocity
    /// limit). Against a position stop, the force measured before it.
    pub normal_force: Option<f64>,
}

/// The detector's state between ticks.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ContactDetector {
    /// Torques applied since the last tick (the previous command), or `None` when unknown.
    applied_torques: Option<[f64; NUM_JOINTS]>,
    /// Joint rates of the last tick, `None` before the first.
    previous_rates: Option<[f64; NUM_JOINTS]>,
    /// Low-passed external joint torque per leg, N·m.
    external_torque: [Vector3<f64>; NUM_LEGS],
    /// Whether `external_torque` holds an estimate (after the first tick with torques).
    primed: bool,
    in_contact: [bool; NUM_LEGS],
    weight: f64,
    /// Joint rate from which a leg's effort is no evidence, rad/s: [`VELOCITY_LIMIT_SHARE`] of
    /// each joint's velocity limit.
    rate_limits: [f64; NUM_JOINTS],
    /// Each joint's (lower, upper) position limit, rad.
    position_limits: [(f64, f64); NUM_JOINTS],
    /// Each leg's force measured last away from its position stops (held against one).
    force_before_stop: [Option<f64>; NUM_LEGS],
}

/// The readings the detector needs on one tick.
pub struct ContactInputs<'a> {
    /// Joint angles, rad.
    pub joint_positions: &'a [f64; NUM_JOINTS],
    /// Joint rates, rad/s.
    pub joint_rates: &'a [f64; NUM_JOINTS],
    /// Gravity minus the trunk's acceleration in the base frame (−specific force), m/s².
    pub effective_gravity_body: Vector3<f64>,
    /// Base-to-world rotation.
    pub rotation: &'a Matrix3<f64>,
    /// Each leg's foot kinematics at `joint_positions`.
    pub feet: &'a [FootKinematics; NUM_LEGS],
    /// Prior contact trust of each leg from the schedule (0 swing … 1 mid-stance).
    pub schedule_trust: [f64; NUM_LEGS],
}

impl ContactDetector {
    /// A detector for `model`, starting with every foot on the ground.
    pub fn new(model: &RobotModel) -> Self {
        let (lower, upper) = (model.lower_limits(), model.upper_limits());
        ContactDetector {
            applied_torques: None,
            previous_rates: None,
            external_torque: [Vector3::zeros(); NUM_LEGS],
            primed: false,
            in_contact: [true; NUM_LEGS],
            weight: model.total_mass() * crate::api::GRAVITY,
            rate_limits: model
                .velocity_limits()
                .map(|limit| VELOCITY_LIMIT_SHARE * limit),
            position_limits: std::array::from_fn(|j| (lower[j], upper[j])),
            force_before_stop: [None; NUM_LEGS],
        }
    }

    /// Records the joint torques sent to the motors on this tick (applied until the next).
    /// Non-finite torques make the force unknown until the next finite command.
    pub fn record_applied_torques(&mut self, torques: &[f64; NUM_JOINTS]) {
        self.applied_torques = torques.iter().all(|t| t.is_finite()).then_some(*torques);
        if self.applied_torques.is_none() {
            self.primed = false;
        }
    }

    /// One tick: the force estimate, the fused probability and the decision per leg.
    pub fn update(
        &mut self,
        model: &RobotModel,
        inputs: &ContactInputs,
        dt: f64,
    ) -> [LegContact; NUM_LEGS] {
        let rates_valid = inputs.joint_rates.iter().all(|r| r.is_finite())
            && inputs.effective_gravity_body.iter().all(|g| g.is_finite());
        let measurable = match (self.applied_torques, self.previous_rates) {
            (Some(torques), Some(previous)) if rates_valid && dt > 0.0 => {
                self.update_external_torques(model, inputs, &torques, &previous, dt);
                true
            }
            _ => {
                self.primed = false;
                false
            }
        };
        self.previous_rates = rates_valid.then_some(*inputs.joint_rates);
        let at_velocity_limit: [bool; NUM_LEGS] = std::array::from_fn(|l| {
            (3 * l..3 * l + 3).any(|j| inputs.joint_rates[j].abs() >= self.rate_limits[j])
        });
        let at_position_limit: [bool; NUM_LEGS] = std::array::from_fn(|l| {
            (3 * l..3 * l + 3).any(|j| {
                let (lower, upper) = self.position_limits[j];
                let q = inputs.joint_positions[j];
                q <= lower + POSITION_LIMIT_BAND || q >= upper - POSITION_LIMIT_BAND
            })
        });
        let spread = CONTACT_FORCE_SPREAD_FRACTION * self.weight;
        let neutral = CONTACT_FORCE_FRACTION * self.weight;
        std::array::from_fn(|l| {
            let leg = Leg::ALL[l];
            let prior = PHASE_PRIOR_FLOOR
                + (1.0 - 2.0 * PHASE_PRIOR_FLOOR) * inputs.schedule_trust[l].clamp(0.0, 1.0);
            let normal_force = if at_position_limit[l] {
                self.force_before_stop[l]
            } else {
                let measured = if measurable && !at_velocity_limit[l] {
                    self.normal_force(leg, inputs)
                } else {
                    None
                };
                self.force_before_stop[l] = measured;
                measured
            };
            let probability = match normal_force {
                Some(force) => {
                    let likelihood = 1.0 / (1.0 + (-(force - neutral) / spread).exp());
                    let contact = prior * likelihood;
                    contact / (contact + (1.0 - prior) * (1.0 - likelihood))
                }
                None => prior,
            };
            let contact = &mut self.in_contact[l];
            if *contact && probability < CONTACT_OFF_PROBABILITY {
                *contact = false;
            } else if !*contact && probability > CONTACT_ON_PROBABILITY {
                *contact = true;
            }
            LegContact {
                probability,
                in_contact: *contact,
                normal_force,
            }
        })
    }

    fn update_external_torques(
        &mut self,
        model: &RobotModel,
        inputs: &ContactInputs,
        torques: &[f64; NUM_JOINTS],
        previous_rates: &[f64; NUM_JOINTS],
        dt: f64,
    ) {
        let blend = if self.primed {
            dt / (FORCE_FILTER_TIME + dt)
        } else {
            1.0
        };
        for leg in Leg::ALL {
            let l = leg.index();
            let q = leg_slice(inputs.joint_positions, leg);
            let dq = leg_slice(inputs.joint_rates, leg);
            let dq_before = leg_slice(previous_rates, leg);
            let ddq = std::array::from_fn(|j| (dq[j] - dq_before[j]) / dt);
            // M(q)q̈ + h(q, q̇) in one Newton–Euler pass.
            let raw = model.rnea(leg, q, dq, ddq, inputs.effective_gravity_body)
                - Vector3::from(leg_slice(torques, leg));
            self.external_torque[l] += (raw - self.external_torque[l]) * blend;
        }
        self.primed = true;
    }

    /// Vertical ground reaction force on `leg`'s foot, world frame, from the external torque.
    fn normal_force(&self, leg: Leg, inputs: &ContactInputs) -> Option<f64> {
        let foot_force_body = inputs.feet[leg.index()]
            .jacobian
            .transpose()
            .try_inverse()
            .map(|inverse| inverse * self.external_torque[leg.index()])?;
        let force = (inputs.rotation * foot_force_body).z;
        force.is_finite().then_some(force)
    }
}
