//! Steep ground: where the friction pyramid of the configured μ would leave almost nothing
//! beyond holding the body on the incline, the MPC plans with a coefficient that keeps a fixed
//! margin above tan(slope), the body stands lower (less load moves from the uphill to the
//! downhill feet), and the reference may not speed up or brake faster than that margin allows
//! ([`crate::reference_governor::ReferenceGovernor`]: a plan that stops dead at its end would otherwise ask a robot walking
//! down 30° to brake from 0.5 m/s within the MPC's horizon, and its feet slip). Below the
//! threshold slope nothing changes.

use nalgebra::Vector3;

use crate::api::GRAVITY;

/// Share of the friction margin the reference's accelerations may use (the rest is left for
/// the body's own disturbances).
const BRAKING_SHARE: f64 = 0.5;

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
}
