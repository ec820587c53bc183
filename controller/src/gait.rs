//! Periodic gait schedules: contact state and swing/stance phase per leg from the gait time, and
//! the swing-foot trajectory.

use crate::api::{GaitKind, Leg, NUM_LEGS};
use serde::{Deserialize, Serialize};

/// A periodic gait: each leg is in stance for the first `duty` fraction of its cycle, which starts
/// at `offset[leg]` (fractions of the period).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Gait {
    /// Cycle period, s.
    pub period: f64,
    /// Stance fraction of the cycle.
    pub duty: f64,
    /// Phase offset of each leg's stance start, in cycles.
    pub offsets: [f64; NUM_LEGS],
}

/// Phase of one leg at a given time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LegPhase {
    /// In stance; progress 0→1 through the stance.
    Stance(f64),
    /// In swing; progress 0→1 through the swing.
    Swing(f64),
}

impl Gait {
    /// The gait of the given kind and period.
    pub fn new(kind: GaitKind, period: f64) -> Self {
        match kind {
            // Diagonal pairs: FR+RL, then FL+RR.
            GaitKind::Trot => Gait {
                period,
                duty: 0.5,
                offsets: [0.0, 0.5, 0.5, 0.0],
            },
            // Lateral-sequence walk: swings in the order RR, FR, RL, FL.
            GaitKind::Walk => Gait {
                period,
                duty: 0.75,
                offsets: [0.5, 0.0, 0.25, 0.75],
            },
        }
    }

    /// Stance duration, s.
    pub fn stance_time(&self) -> f64 {
        self.duty * self.period
    }

    /// Swing duration, s.
    pub fn swing_time(&self) -> f64 {
        (1.0 - self.duty) * self.period
    }

    /// Phase of `leg` at gait time `t` (s since the gait started).
    pub fn phase(&self, leg: Leg, t: f64) -> LegPhase {
        let cycle = (t / self.period - self.offsets[leg.index()]).rem_euclid(1.0);
        if cycle < self.duty {
            LegPhase::Stance(cycle / self.duty)
        } else {
            LegPhase::Swing((cycle - self.duty) / (1.0 - self.duty))
        }
    }

    /// Stance flags of all legs at gait time `t`.
    pub fn contacts(&self, t: f64) -> [bool; NUM_LEGS] {
        Leg::ALL.map(|leg| matches!(self.phase(leg, t), LegPhase::Stance(_)))
    }
}

/// Swing-foot trajectory sample: position, velocity, acceleration (world frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SwingSample {
    /// Position, m.
    pub position: [f64; 3],
    /// Velocity, m/s.
    pub velocity: [f64; 3],
    /// Acceleration, m/s².
    pub acceleration: [f64; 3],
}

/// Horizontal progress of the swing foot at swing progress `s ∈ [0, 1]`: the smoothstep
/// 3s² − 2s³ (zero velocity at lift-off and touchdown).
pub fn swing_blend(s: f64) -> f64 {
    3.0 * s * s - 2.0 * s.powi(3)
}

/// Vertical bump of the swing foot above the straight lift-off → touchdown line for a unit apex,
/// at swing progress `s ∈ [0, 1]`: 64 s³(1 − s)³, 1 at mid-swing, zero velocity and acceleration
/// at both ends.
pub fn swing_bump_shape(s: f64) -> f64 {
    let u = s * (1.0 - s);
    64.0 * u.powi(3)
}

/// Swing trajectory from `start` to `end` over `duration` seconds, sampled at progress `s ∈ [0,1]`:
/// a smoothstep (3s² − 2s³) blend for every axis plus a vertical bump `h·64 s³(1 − s)³` that
/// peaks at `h` mid-swing and has zero velocity and acceleration at both ends.
pub fn swing_trajectory(
    start: [f64; 3],
    end: [f64; 3],
    height: f64,
    duration: f64,
    s: f64,
) -> SwingSample {
    let s = s.clamp(0.0, 1.0);
    let blend = swing_blend(s);
    let blend_d = 6.0 * s - 6.0 * s * s;
    let blend_dd = 6.0 - 12.0 * s;
    let u = s * (1.0 - s);
    // bump = 64 h u³, u' = 1 − 2s, u'' = −2
    let du = 1.0 - 2.0 * s;
    let bump = height * swing_bump_shape(s);
    let bump_d = 64.0 * height * 3.0 * u * u * du;
    let bump_dd = 64.0 * height * (6.0 * u * du * du - 6.0 * u * u);
    let inv_t = 1.0 / duration;
    let mut sample = SwingSample {
        position: [0.0; 3],
        velocity: [0.0; 3],
        acceleration: [0.0; 3],
    };
    for axis in 0..3 {
        let delta = end[axis] - start[axis];
        sample.position[axis] = start[axis] + delta * blend;
        sample.velocity[axis] = delta * blend_d * inv_t;
        sample.acceleration[axis] = delta * blend_dd * inv_t * inv_t;
    }
    sample.position[2] += bump;
    sample.velocity[2] += bump_d * inv_t;
    sample.acceleration[2] += bump_dd * inv_t * inv_t;
    sample
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // parallel indexing of several 3-vectors
mod tests {
    use super::*;

    #[test]
    fn trot_diagonal_pairs_alternate() {
        let gait = Gait::new(GaitKind::Trot, 0.3);
        assert_eq!(gait.contacts(0.01), [true, false, false, true]);
        assert_eq!(gait.contacts(0.16), [false, true, true, false]);
    }

    #[test]
    fn walk_keeps_three_feet_down() {
        let gait = Gait::new(GaitKind::Walk, 0.8);
        for i in 0..80 {
            let stance = gait.contacts(i as f64 * 0.01 + 0.001);
            assert_eq!(stance.iter().filter(|s| **s).count(), 3, "t index {i}");
        }
    }

    #[test]
    fn swing_trajectory_endpoints_apex_and_derivatives() {
        let start = [0.0, 0.0, 0.0];
        let end = [0.2, 0.1, 0.05];
        let a = swing_trajectory(start, end, 0.08, 0.15, 0.0);
        let b = swing_trajectory(start, end, 0.08, 0.15, 1.0);
        let mid = swing_trajectory(start, end, 0.08, 0.15, 0.5);
        assert_eq!(a.position, start);
        for i in 0..3 {
            assert!((b.position[i] - end[i]).abs() < 1e-12);
            assert!(a.velocity[i].abs() < 1e-12 && b.velocity[i].abs() < 1e-12);
        }
        assert!((mid.position[2] - (0.025 + 0.08)).abs() < 1e-12);
        // Velocity matches a finite difference of the position.
        let h = 1e-6;
        let p0 = swing_trajectory(start, end, 0.08, 0.15, 0.3);
        let p1 = swing_trajectory(start, end, 0.08, 0.15, 0.3 + h);
        for i in 0..3 {
            let fd = (p1.position[i] - p0.position[i]) / (h * 0.15);
            assert!(
                (fd - p0.velocity[i]).abs() < 1e-4,
                "axis {i}: {fd} vs {}",
                p0.velocity[i]
            );
            let fda = (p1.velocity[i] - p0.velocity[i]) / (h * 0.15);
            assert!((fda - p0.acceleration[i]).abs() < 1e-2 * (1.0 + fda.abs()));
        }
    }
}
