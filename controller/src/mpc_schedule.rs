//! MPC scheduling stage: when to re-solve the convex MPC (every `mpc_every_ticks` ticks and on
//! contact changes), the reference trajectory over the horizon (terrain-following height and
//! pitch, the base shifted towards displaced footholds), the feet at each horizon step, and the
//! forces held between solves (a static weight share when a solve fails).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::api::{ControllerError, Leg, Reference, GRAVITY, NUM_LEGS};
use crate::config::ControllerConfig;
use crate::estimate::Estimate;
use crate::footholds::{FootholdPlanner, MotionTarget, StanceGround};
use crate::math::{rot_z, wrap_angle};
use crate::mpc::{ConvexMpc, MpcInput, MpcParams, MpcStatus, MPC_STATES};
use crate::steep_ground::SteepGround;

/// Farthest the start of the MPC's xy reference may lead the measured base, m: a larger error
/// would saturate the QP's forces.
const MAX_REFERENCE_LEAD: f64 = 0.25;
/// Fraction of the mean foothold displacement the base reference follows.
const BODY_SHIFT_GAIN: f64 = 1.0;
/// Largest shift of the base reference towards displaced footholds, m.
const MAX_BODY_SHIFT: f64 = 0.1;

/// The MPC, its schedule and the forces it last produced.
pub struct MpcScheduler {
    mpc: ConvexMpc,
    every_ticks: usize,
    horizon: usize,
    dt: f64,
    /// Total robot mass, kg (for the fallback weight share).
    mass: f64,
    /// CoM offset from the base origin, base frame, m.
    com_offset_body: Vector3<f64>,
    /// Configured friction coefficient, and the margin kept above tan(slope) on steep ground.
    mu: f64,
    mu_slope_margin: f64,
    ticks_since_mpc: usize,
    forces: [[f64; 3]; NUM_LEGS],
    /// Contacts of the last solve (a change triggers a new solve).
    solved_contacts: [bool; NUM_LEGS],
    solved: bool,
    solve_time_s: f64,
    reference: Vec<[f64; MPC_STATES]>,
    schedule: Vec<[bool; NUM_LEGS]>,
    offsets: Vec<[[f64; 3]; NUM_LEGS]>,
}

/// What the scheduler carries from one tick to the next (part of a saved controller state).
/// The QP buffers and the solver cache are not in it: every solve rebuilds its QP from this and
/// the tick's inputs, and a solver set up afresh solves it exactly as a cached one does
/// (equilibration is off, so an update leaves no trace of earlier data).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MpcMemory {
    ticks_since_mpc: usize,
    forces: [[f64; 3]; NUM_LEGS],
    solved_contacts: [bool; NUM_LEGS],
    solved: bool,
    solve_time_s: f64,
    schedule: Vec<[bool; NUM_LEGS]>,
}

impl MpcScheduler {
    /// A copy of what the scheduler carries between ticks.
    pub fn memory(&self) -> MpcMemory {
        MpcMemory {
            ticks_since_mpc: self.ticks_since_mpc,
            forces: self.forces,
            solved_contacts: self.solved_contacts,
            solved: self.solved,
            solve_time_s: self.solve_time_s,
            schedule: self.schedule.clone(),
        }
    }

    /// Continues from `memory` (taken from a scheduler of the same configuration); a memory
    /// of another horizon is refused and changes nothing.
    pub fn restore(&mut self, memory: MpcMemory) -> Result<(), String> {
        if memory.schedule.len() != self.horizon {
            return Err(format!(
                "MPC schedule of {} steps, the horizon is {}",
                memory.schedule.len(),
                self.horizon
            ));
        }
        let MpcMemory {
            ticks_since_mpc,
            forces,
            solved_contacts,
            solved,
            solve_time_s,
            schedule,
        } = memory;
        self.ticks_since_mpc = ticks_since_mpc;
        self.forces = forces;
        self.solved_contacts = solved_contacts;
        self.solved = solved;
        self.solve_time_s = solve_time_s;
        self.schedule = schedule;
        Ok(())
    }

    /// The MPC of `config` for a robot of `mass` kg with body inertia `inertia_body` about its
    /// CoM, which sits at `com_offset_body` from the base origin (base frame).
    pub fn new(
        config: &ControllerConfig,
        mass: f64,
        inertia_body: [[f64; 3]; 3],
        com_offset_body: Vector3<f64>,
    ) -> Result<Self, ControllerError> {
        let mpc = ConvexMpc::new(MpcParams::from_config(config, mass, inertia_body))
            .map_err(ControllerError::Config)?;
        let n = config.mpc_horizon;
        Ok(MpcScheduler {
            mpc,
            every_ticks: config.mpc_every_ticks,
            mu: config.mu,
            mu_slope_margin: config.mu_slope_margin,
            horizon: n,
            dt: config.mpc_dt,
            mass,
            com_offset_body,
            ticks_since_mpc: 0,
            forces: [[0.0; 3]; NUM_LEGS],
            solved_contacts: [false; NUM_LEGS],
            solved: false,
            solve_time_s: 0.0,
            reference: vec![[0.0; MPC_STATES]; n],
            schedule: vec![[false; NUM_LEGS]; n],
            offsets: vec![[[0.0; 3]; NUM_LEGS]; n],
        })
    }

    /// Forces the next `update_forces` to solve (on entering a state).
    pub fn solve_on_next_update(&mut self) {
        self.ticks_since_mpc = usize::MAX;
    }

    /// Drops the held forces (states that do not balance).
    pub fn clear_forces(&mut self) {
        self.forces = [[0.0; 3]; NUM_LEGS];
        self.solved = false;
    }

    /// Sets the contact schedule over the horizon: `contacts_at(k)` for step k.
    pub fn set_schedule(&mut self, contacts_at: impl Fn(usize) -> [bool; NUM_LEGS]) {
        for (k, contacts) in self.schedule.iter_mut().enumerate() {
            *contacts = contacts_at(k);
        }
    }

    /// Ground reaction forces on the robot per foot, world frame, N (zero for swing legs).
    pub fn forces(&self) -> [[f64; 3]; NUM_LEGS] {
        self.forces
    }

    /// Whether the last solve succeeded.
    pub fn solved(&self) -> bool {
        self.solved
    }

    /// Wall time of the last solve, s (diagnostic only).
    pub fn solve_time_s(&self) -> f64 {
        self.solve_time_s
    }

    /// Re-solve the MPC when due (every `mpc_every_ticks` ticks or on a contact change) and
    /// refresh the forces; `foot_at(schedule, leg, k)` gives the world foot position of a
    /// stance leg at horizon step k of the schedule.
    pub fn update_forces(
        &mut self,
        footholds: &FootholdPlanner,
        estimate: &Estimate,
        reference: &Reference,
        target: &MotionTarget,
        contacts: [bool; NUM_LEGS],
        foot_at: impl Fn(&[[bool; NUM_LEGS]], Leg, usize) -> Vector3<f64>,
    ) {
        let due = self.ticks_since_mpc >= self.every_ticks.saturating_sub(1)
            || contacts != self.solved_contacts;
        if !due {
            self.ticks_since_mpc += 1;
            self.zero_swing_forces(contacts);
            return;
        }
        self.ticks_since_mpc = 0;
        self.solved_contacts = contacts;
        let n = self.horizon;
        let dt = self.dt;
        let normal = footholds.friction_normal(reference, estimate, contacts);
        let steep = SteepGround::new(&normal, self.mu, self.mu_slope_margin);
        let height = footholds.body_height(reference) * steep.height_scale;
        let com_now = estimate.position + estimate.rotation * self.com_offset_body;
        let yaw_now = target.yaw + wrap_angle(estimate.rpy.z - target.yaw);
        let x0 = {
            let v_com = estimate.velocity
                + estimate
                    .angular_velocity
                    .cross(&(estimate.rotation * self.com_offset_body));
            let w = estimate.angular_velocity;
            [
                estimate.rpy.x,
                estimate.rpy.y,
                yaw_now,
                com_now.x,
                com_now.y,
                com_now.z,
                w.x,
                w.y,
                w.z,
                v_com.x,
                v_com.y,
                v_com.z,
                GRAVITY,
            ]
        };
        // Keep the start of the reference within reach so a large error cannot saturate the QP.
        let mut start = Vector3::new(target.xy[0], target.xy[1], 0.0);
        let base_xy = Vector3::new(estimate.position.x, estimate.position.y, 0.0);
        let error = start - base_xy;
        if error.norm() > MAX_REFERENCE_LEAD {
            start = base_xy + error * (MAX_REFERENCE_LEAD / error.norm());
        }
        // Beside a wall or a rim the footholds of one side move inwards; the base follows its
        // feet by their mean displacement so that the support stays balanced about the CoM.
        let shift = footholds
            .stance_ground(reference, start.x, start.y, target.yaw)
            .shift;
        let mut shift = Vector3::new(shift[0], shift[1], 0.0) * BODY_SHIFT_GAIN;
        if shift.norm() > MAX_BODY_SHIFT {
            shift *= MAX_BODY_SHIFT / shift.norm();
        }
        start += shift;
        let velocity0 = Vector3::new(target.velocity[0], target.velocity[1], 0.0);
        let mut base_xy_k = start;
        for k in 0..n {
            let tk = (k + 1) as f64 * dt;
            let yaw_k = target.yaw + target.yaw_rate * tk;
            let velocity_k = rot_z(target.yaw_rate * tk) * velocity0;
            base_xy_k += velocity_k * dt;
            let StanceGround {
                height: ground,
                pitch,
                ..
            } = footholds.stance_ground(reference, base_xy_k.x, base_xy_k.y, yaw_k);
            let com_k = Vector3::new(base_xy_k.x, base_xy_k.y, ground + height)
                + rot_z(yaw_k) * self.com_offset_body;
            let vz =
                reference.terrain.slope_x * velocity_k.x + reference.terrain.slope_y * velocity_k.y;
            self.reference[k] = [
                target.roll,
                pitch,
                yaw_k,
                com_k.x,
                com_k.y,
                com_k.z,
                0.0,
                0.0,
                target.yaw_rate,
                velocity_k.x,
                velocity_k.y,
                vz,
                GRAVITY,
            ];
        }
        for k in 0..n {
            let com_k = if k == 0 {
                com_now
            } else {
                let r = &self.reference[k - 1];
                Vector3::new(r[3], r[4], r[5])
            };
            for leg in Leg::ALL {
                let l = leg.index();
                self.offsets[k][l] = if self.schedule[k][l] {
                    let foot = foot_at(&self.schedule, leg, k);
                    let r = foot - com_k;
                    [r.x, r.y, r.z]
                } else {
                    [0.0; 3]
                };
            }
        }
        if let Err(reason) = self.mpc.set_friction(steep.mu) {
            tracing::warn!(%reason, "steep-ground friction refused; the last one is kept");
        }
        let input = MpcInput {
            x0,
            reference: &self.reference,
            contacts: &self.schedule,
            foot_offsets: &self.offsets,
            terrain_normal: [normal.x, normal.y, normal.z],
        };
        let solution = self.mpc.solve(&input);
        self.solve_time_s = solution.solve_time_s;
        if solution.status == MpcStatus::Solved {
            self.forces = solution.forces;
            self.solved = true;
        } else {
            tracing::warn!(status = ?solution.status, "MPC failed: static weight distribution");
            self.solved = false;
            let stance = contacts.iter().filter(|c| **c).count().max(1) as f64;
            let share = self.mass * GRAVITY / stance;
            self.forces = [[0.0, 0.0, share]; NUM_LEGS];
        }
        self.zero_swing_forces(contacts);
    }

    fn zero_swing_forces(&mut self, contacts: [bool; NUM_LEGS]) {
        for (force, stance) in self.forces.iter_mut().zip(contacts) {
            if !stance {
                *force = [0.0; 3];
            }
        }
    }
}
