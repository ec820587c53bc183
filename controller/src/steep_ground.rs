//! Steep ground: where the friction pyramid of the configured μ would leave almost nothing
//! beyond holding the body on the incline, the MPC plans with a coefficient that keeps a fixed
//! margin above tan(slope), the body stands lower (less load moves from the uphill to the
//! downhill feet), and the reference may not speed up or brake faster than that margin allows
//! ([`ReferenceGovernor`]: a plan that stops dead at its end would otherwise ask a robot walking
//! down 30° to brake from 0.5 m/s within the MPC's horizon, and its feet slip). Below the
//! threshold slope nothing changes.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::api::GRAVITY;

/// Share of the friction margin the reference's accelerations may use (the rest is left for
/// the body's own disturbances).
const BRAKING_SHARE: f64 = 0.5;
/// Time constant with which the governed reference returns onto the given one, s.
const LEAD_TIME_CONSTANT: f64 = 2.0;

/// What the MPC uses on the ground under the stance feet.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SteepGround {
    /// Friction coefficient of the MPC's pyramids.
    pub mu: f64,
    /// Factor on the body height reference (1 below the threshold slope).
    pub height_scale: f64,
    /// Largest horizontal acceleration of the motion reference, m/s² (infinite below the
    /// threshold slope).
    pub max_acceleration: f64,
}

impl SteepGround {
    /// For ground of unit normal `normal` (world frame), the configured `mu` and the margin kept
    /// above tan(slope): `mu` and full height while tan(slope) + `margin` ≤ `mu`; beyond, μ =
    /// tan(slope) + `margin` and the height scaled by cos(slope) / cos(threshold slope).
    pub fn new(normal: &Vector3<f64>, mu: f64, margin: f64) -> SteepGround {
        let length = normal.norm();
        let unchanged = SteepGround {
            mu,
            height_scale: 1.0,
            max_acceleration: f64::INFINITY,
        };
        if !(length > 0.0 && normal.z > 0.0) {
            return unchanged;
        }
        let cos_slope = normal.z / length;
        let tan_slope = (1.0 - cos_slope * cos_slope).max(0.0).sqrt() / cos_slope;
        if tan_slope + margin <= mu {
            return unchanged;
        }
        let tan_threshold = (mu - margin).max(0.0);
        let cos_threshold = 1.0 / (1.0 + tan_threshold * tan_threshold).sqrt();
        SteepGround {
            mu: tan_slope + margin,
            height_scale: cos_slope / cos_threshold,
            max_acceleration: BRAKING_SHARE * margin * GRAVITY * cos_slope,
        }
    }
}

/// The motion reference with its accelerations limited: the velocity follows the given one at
/// no more than the allowed acceleration, and the position leads (or lags) the given one by what
/// that difference accumulated. Without a limit the velocity is the given one and the lead
/// returns to zero with [`LEAD_TIME_CONSTANT`] (with no lead: the reference unchanged).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReferenceGovernor {
    velocity: [f64; 2],
    lead: [f64; 2],
}

impl ReferenceGovernor {
    /// Starts at `velocity` (world xy, m/s) with no lead.
    pub fn starting_at(velocity: [f64; 2]) -> Self {
        ReferenceGovernor {
            velocity,
            lead: [0.0; 2],
        }
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

    fn plane(degrees: f64) -> Vector3<f64> {
        let angle = degrees.to_radians();
        Vector3::new(-angle.sin(), 0.0, angle.cos())
    }

    #[test]
    fn up_to_the_threshold_slope_nothing_changes() {
        for degrees in [0.0, 10.0, 20.0, 23.0] {
            assert_eq!(
                SteepGround::new(&plane(degrees), 0.6, 0.17),
                SteepGround {
                    mu: 0.6,
                    height_scale: 1.0,
                    max_acceleration: f64::INFINITY,
                },
                "{degrees}°"
            );
        }
    }

    #[test]
    fn beyond_it_the_margin_is_kept_and_the_body_lowered() {
        let at_30 = SteepGround::new(&plane(30.0), 0.6, 0.17);
        assert!((at_30.mu - (30f64.to_radians().tan() + 0.17)).abs() < 1e-12);
        let threshold = 0.43f64.atan();
        assert!((at_30.height_scale - 30f64.to_radians().cos() / threshold.cos()).abs() < 1e-12);
        assert!(at_30.height_scale < 1.0 && at_30.height_scale > 0.9);
        // Continuous at the threshold, monotonic beyond it.
        let just_above = SteepGround::new(&plane(threshold.to_degrees() + 1e-6), 0.6, 0.17);
        assert!((just_above.mu - 0.6).abs() < 1e-6 && (just_above.height_scale - 1.0).abs() < 1e-6);
        let at_35 = SteepGround::new(&plane(35.0), 0.6, 0.17);
        assert!(at_35.mu > at_30.mu && at_35.height_scale < at_30.height_scale);
        // Normal length does not matter; a degenerate normal changes nothing.
        assert_eq!(SteepGround::new(&(plane(30.0) * 3.0), 0.6, 0.17), at_30);
        assert_eq!(SteepGround::new(&Vector3::zeros(), 0.6, 0.17).mu, 0.6);
        let braking = 0.5 * 0.17 * GRAVITY * 30f64.to_radians().cos();
        assert!((at_30.max_acceleration - braking).abs() < 1e-12);
    }

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
}
