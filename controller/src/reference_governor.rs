//! The motion reference the MPC and the footholds follow, governed: its accelerations limited on
//! steep ground (where [`crate::steep_ground::SteepGround`] gives a limit), and a push taken into
//! it instead of fought (the reference restarts at the pushed body's motion and returns to the
//! given one at a bounded acceleration).

use serde::{Deserialize, Serialize};

/// Time constant with which the governed reference returns onto the given one, s.
const LEAD_TIME_CONSTANT: f64 = 2.0;
/// Departure of the measured horizontal velocity from the governed one beyond which the body
/// counts as pushed, m/s: above a trot's own velocity ripple and the estimator's error.
pub const DISTURBANCE_VELOCITY: f64 = 0.35;
/// Largest acceleration with which the reference brings a pushed body back to the given
/// velocity, m/s²: about half the MPC's friction pyramid (μ = 0.6) on level ground. A reference
/// that asks a body moving sideways at 2 m/s to stop within the MPC's horizon makes the MPC put
/// the stance feet's lateral forces at the pyramid's edge, and their roll moment tips the body
/// over its diagonal support (docs/push-recovery.md).
pub const RECOVERY_ACCELERATION: f64 = 2.5;

/// The motion reference with its accelerations limited: the velocity follows the given one at
/// no more than the allowed acceleration, and the position leads (or lags) the given one by what
/// that difference accumulated. Without a limit the velocity is the given one and the lead
/// returns to zero with [`LEAD_TIME_CONSTANT`] (with no lead: the reference unchanged).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceGovernor {
    velocity: [f64; 2],
    /// The acceleration limit while recovering from a push, m/s² (default [`RECOVERY_ACCELERATION`]).
    recovery_acceleration: f64,
    lead: [f64; 2],
    /// A push moved the body off the reference, and the velocity is not back on the given one.
    recovering: bool,
}

impl Default for ReferenceGovernor {
    fn default() -> Self {
        Self::starting_at([0.0; 2])
    }
}

impl ReferenceGovernor {
    /// Starts at `velocity` (world xy, m/s) with no lead.
    pub fn starting_at(velocity: [f64; 2]) -> Self {
        Self::with_recovery_acceleration(velocity, RECOVERY_ACCELERATION)
    }

    /// Starts at `velocity` with no lead, bringing pushed bodies back at no more than
    /// `recovery_acceleration` (m/s²).
    pub fn with_recovery_acceleration(velocity: [f64; 2], recovery_acceleration: f64) -> Self {
        ReferenceGovernor {
            velocity,
            recovery_acceleration,
            lead: [0.0; 2],
            recovering: false,
        }
    }

    /// A governor with the same recovery limit, started at `velocity` with no lead.
    pub fn restarted_at(&self, velocity: [f64; 2]) -> Self {
        Self::with_recovery_acceleration(velocity, self.recovery_acceleration)
    }

    /// Whether the reference is bringing a pushed body back (see [`Self::absorb_push`]).
    pub fn recovering(&self) -> bool {
        self.recovering
    }

    /// Takes a push into the reference instead of fighting it. When the measured velocity
    /// (`measured_velocity`, world xy) departs from the governed one by more than
    /// [`DISTURBANCE_VELOCITY`], the governed velocity is pulled to that distance from it (on the
    /// line between the two) and the governed position restarts at the body (`measured_xy`,
    /// against the given `xy`); [`Self::step`] then brings the velocity back to the given one at
    /// no more than [`RECOVERY_ACCELERATION`], keeping the position lead until it is there. The
    /// MPC thus brakes a pushed body at a bounded rate instead of pulling it back onto the
    /// reference at once. Returns whether it did.
    pub fn absorb_push(
        &mut self,
        xy: [f64; 2],
        measured_xy: [f64; 2],
        measured_velocity: [f64; 2],
    ) -> bool {
        let departure = (measured_velocity[0] - self.velocity[0])
            .hypot(measured_velocity[1] - self.velocity[1]);
        if departure.is_nan() || departure <= DISTURBANCE_VELOCITY {
            return false;
        }
        let keep = DISTURBANCE_VELOCITY / departure;
        for (governed, measured) in self.velocity.iter_mut().zip(measured_velocity) {
            *governed = measured + (*governed - measured) * keep;
        }
        self.lead = [measured_xy[0] - xy[0], measured_xy[1] - xy[1]];
        self.recovering = true;
        true
    }

    /// The governed (position, velocity) for the given reference position `xy` and velocity
    /// `velocity` (world xy), `max_acceleration` (m/s², infinite: no limit) and tick `dt`.
    pub fn step(
        &mut self,
        xy: [f64; 2],
        velocity: [f64; 2],
        max_acceleration: f64,
        dt: f64,
    ) -> ([f64; 2], [f64; 2]) {
        let max_acceleration = if self.recovering {
            max_acceleration.min(self.recovery_acceleration)
        } else {
            max_acceleration
        };
        if max_acceleration.is_finite() {
            let change = [
                velocity[0] - self.velocity[0],
                velocity[1] - self.velocity[1],
            ];
            let size = change[0].hypot(change[1]);
            let limit = max_acceleration.max(0.0) * dt;
            let scale = if size > limit { limit / size } else { 1.0 };
            self.velocity[0] += change[0] * scale;
            self.velocity[1] += change[1] * scale;
            self.recovering &= size > limit;
        } else {
            self.velocity = velocity;
        }
        // While limited the lead is kept, not worked off: catching up would ask for more speed
        // than the reference's on the very ground where speed is short (30° up at 0.6 m/s
        // falls), and a speed-up and a stop at the same limit cancel each other's lead.
        let return_rate = if max_acceleration.is_finite() {
            0.0
        } else {
            1.0 / LEAD_TIME_CONSTANT
        };
        let decay = (1.0 - dt * return_rate).max(0.0);
        for ((lead, governed), given) in self.lead.iter_mut().zip(self.velocity).zip(velocity) {
            *lead = *lead * decay + (governed - given) * dt;
        }
        (
            [xy[0] + self.lead[0], xy[1] + self.lead[1]],
            [
                self.velocity[0] - self.lead[0] * return_rate,
                self.velocity[1] - self.lead[1] * return_rate,
            ],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_a_limit_the_governor_passes_the_reference_through_exactly() {
        let mut governor = ReferenceGovernor::starting_at([0.3, -0.1]);
        for k in 0..100 {
            let xy = [0.01 * k as f64, 2.0];
            let velocity = [0.5, if k < 50 { 0.0 } else { 0.2 }];
            assert_eq!(
                governor.step(xy, velocity, f64::INFINITY, 0.001),
                (xy, velocity)
            );
        }
    }

    #[test]
    fn a_dead_stop_becomes_a_braking_ramp_and_the_lead_returns_off_steep_ground() {
        let (dt, a_max) = (0.001, 0.7);
        let mut governor = ReferenceGovernor::starting_at([0.5, 0.0]);
        for k in 0..2000 {
            let (xy, velocity) = governor.step([0.0, 0.0], [0.0, 0.0], a_max, dt);
            // Braking at the limit: the velocity falls by a_max per second, then stays 0.
            let expected = (0.5 - a_max * (k + 1) as f64 * dt).max(0.0);
            assert!((velocity[0] - expected).abs() < 1e-9, "{k}: {velocity:?}");
            assert_eq!(velocity[1], 0.0);
            assert!(xy[0] >= 0.0);
        }
        // Stopped v²/(2a) = 0.179 m beyond the reference, and held there while limited.
        let (xy, _) = governor.step([0.0, 0.0], [0.0, 0.0], a_max, dt);
        assert!((xy[0] - 0.5 * 0.5 / (2.0 * a_max)).abs() < 1e-3, "{xy:?}");
        // Off steep ground the lead returns onto the reference.
        let mut x = xy[0];
        for _ in 0..20_000 {
            let (xy, velocity) = governor.step([0.0, 0.0], [0.0, 0.0], f64::INFINITY, dt);
            assert!(velocity[0] <= 0.0);
            x = xy[0];
        }
        assert!(x.abs() < 1e-3, "back on the reference: {x}");
    }

    #[test]
    fn speeding_up_and_stopping_at_the_limit_cancel_each_others_lead() {
        let (dt, a_max) = (0.001, 0.7);
        let mut governor = ReferenceGovernor::starting_at([0.0, 0.0]);
        let mut xy = [0.0, 0.0];
        for k in 0..12_000 {
            let t = k as f64 * dt;
            let (v, x) = if t < 6.0 { (0.5, 0.5 * t) } else { (0.0, 3.0) };
            xy = governor.step([x, 0.0], [v, 0.0], a_max, dt).0;
        }
        assert!((xy[0] - 3.0).abs() < 2e-3, "{xy:?}");
    }

    #[test]
    fn within_a_trots_velocity_ripple_a_measured_motion_changes_nothing() {
        let mut governor = ReferenceGovernor::starting_at([0.5, 0.0]);
        let mut reference = ReferenceGovernor::starting_at([0.5, 0.0]);
        for k in 0..1000 {
            let t = k as f64 * 0.001;
            // A ripple of 0.3 m/s in every direction, just inside the band.
            let xy = [0.5 * t, 0.0];
            let measured_velocity = [0.5 + 0.3 * (40.0 * t).cos(), 0.3 * (40.0 * t).sin()];
            assert!(!governor.absorb_push(xy, [xy[0] + 0.1, 0.2], measured_velocity));
            assert_eq!(
                governor.step(xy, [0.5, 0.0], f64::INFINITY, 0.001),
                reference.step(xy, [0.5, 0.0], f64::INFINITY, 0.001)
            );
        }
        assert!(!governor.recovering());
    }

    #[test]
    fn a_push_restarts_the_reference_at_the_body_and_brakes_it_at_the_recovery_limit() {
        let dt = 0.001;
        let mut governor = ReferenceGovernor::starting_at([0.5, 0.0]);
        // Walking along x at 0.5 m/s; a side push leaves the body 0.1 m left at 1.5 m/s.
        let xy = [1.0, 0.0];
        let measured = [0.6, 1.5];
        assert!(governor.absorb_push(xy, [1.02, 0.1], measured));
        assert!(governor.recovering());
        // The governed velocity sits DISTURBANCE_VELOCITY from the body's, towards the old one.
        let governed = governor.velocity;
        let gap = (governed[0] - measured[0]).hypot(governed[1] - measured[1]);
        assert!((gap - DISTURBANCE_VELOCITY).abs() < 1e-12, "{governed:?}");
        let cross = (governed[0] - measured[0]) * (0.0 - measured[1])
            - (governed[1] - measured[1]) * (0.5 - measured[0]);
        assert!(cross.abs() < 1e-12, "on the line to the old velocity");
        let (start, velocity) = governor.step(xy, [0.5, 0.0], f64::INFINITY, dt);
        assert!(
            (start[0] - 1.02).abs() < 1e-3 && (start[1] - 0.1).abs() < 2e-3,
            "{start:?}"
        );
        let change = (governed[0] - 0.5).hypot(governed[1]);
        let braked = 1.0 - RECOVERY_ACCELERATION * dt / change;
        assert!(
            (velocity[1] - governed[1] * braked).abs() < 1e-9,
            "{velocity:?}"
        );
        // Back on the given velocity after |Δv| / a, no sooner; the lead stays until then and
        // returns afterwards.
        let ticks = (change / (RECOVERY_ACCELERATION * dt)).ceil() as usize;
        let mut lead_y = 0.0;
        for k in 1..ticks + 5 {
            let given = [1.0 + 0.5 * k as f64 * dt, 0.0];
            let (xy, velocity) = governor.step(given, [0.5, 0.0], f64::INFINITY, dt);
            if k + 1 < ticks {
                assert!(governor.recovering() && velocity[1] > 0.0, "{k}");
            }
            lead_y = xy[1];
        }
        assert!(!governor.recovering());
        // Lead: the 0.1 m of the push plus the y part of the straight-line brake.
        let expected = 0.1 + 0.5 * governed[1] * change / RECOVERY_ACCELERATION;
        assert!((lead_y - expected).abs() < 0.01, "{lead_y} vs {expected}");
        for _ in 0..20_000 {
            lead_y = governor.step([0.0, 0.0], [0.0, 0.0], f64::INFINITY, dt).0[1];
        }
        assert!(lead_y.abs() < 1e-3, "{lead_y}");
    }

    #[test]
    fn on_steep_ground_the_tighter_of_the_two_limits_brakes() {
        let dt = 0.001;
        let mut governor = ReferenceGovernor::starting_at([0.0, 0.0]);
        assert!(governor.absorb_push([0.0, 0.0], [0.0, 0.0], [0.0, 1.0]));
        let start = 1.0 - DISTURBANCE_VELOCITY;
        let (_, velocity) = governor.step([0.0, 0.0], [0.0, 0.0], 0.7, dt);
        assert!((velocity[1] - (start - 0.7 * dt)).abs() < 1e-12);
        let (_, velocity) = governor.step([0.0, 0.0], [0.0, 0.0], 10.0, dt);
        assert!((velocity[1] - (start - (0.7 + RECOVERY_ACCELERATION) * dt)).abs() < 1e-12);
        // A NaN measurement is no push.
        assert!(!governor.absorb_push([0.0, 0.0], [0.0, 0.0], [f64::NAN, 0.0]));
    }

    #[test]
    fn the_configured_recovery_acceleration_brakes() {
        let dt = 0.001;
        for limit in [1.0, RECOVERY_ACCELERATION, 6.0] {
            // Restarted (as locomotion does on entry), it keeps its limit.
            let mut governor = ReferenceGovernor::with_recovery_acceleration([5.0, 5.0], limit)
                .restarted_at([0.0, 0.0]);
            assert!(governor.absorb_push([0.0, 0.0], [0.0, 0.0], [0.0, 2.0]));
            let start = 2.0 - DISTURBANCE_VELOCITY;
            let (_, velocity) = governor.step([0.0, 0.0], [0.0, 0.0], f64::INFINITY, dt);
            assert!(
                (velocity[1] - (start - limit * dt)).abs() < 1e-12,
                "{limit}"
            );
        }
        assert_eq!(
            ReferenceGovernor::default(),
            ReferenceGovernor::starting_at([0.0, 0.0])
        );
    }
}
