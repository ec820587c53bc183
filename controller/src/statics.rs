//! Statics of a four-foot stance: how vertical ground forces must be shared so that they hold the
//! weight without turning the body, and where the base must stand for its centre of mass (CoM) to
//! be over the feet. On an incline the CoM of a body parallel to the plane sits about h·sin θ
//! downhill of the feet's centroid, so equal shares push the uphill legs too hard and the robot
//! rotates about its downhill feet (docs/slopes.md, 3a–3b).

use nalgebra::{Matrix3, Rotation3, Vector3};

use crate::api::NUM_LEGS;

/// Vertical ground forces f_i ≥ `f_min` with Σ f_i = `total` and no moment about the CoM:
/// Σ f_i·(p_i − c)_xy = 0. Of all such forces the one of least norm (the load spread as evenly as
/// the balance allows), found by fixing at `f_min` the feet the unconstrained solution would
/// unload. When the CoM lies outside the feet's polygon no distribution balances it; the result
/// is then the least-squares one, every foot still carrying at least `f_min`. Equal shares when
/// `4·f_min` exceeds `total` or the input is not finite.
pub fn static_vertical_forces(
    feet: &[Vector3<f64>; NUM_LEGS],
    com: &Vector3<f64>,
    total: f64,
    f_min: f64,
) -> [f64; NUM_LEGS] {
    let equal = [total / NUM_LEGS as f64; NUM_LEGS];
    let finite = feet.iter().all(|p| p.iter().all(|v| v.is_finite()))
        && com.iter().all(|v| v.is_finite())
        && total.is_finite()
        && f_min.is_finite();
    if !finite || total <= 0.0 || f_min * NUM_LEGS as f64 >= total {
        return equal;
    }
    let lever = feet.map(|p| Vector3::new(1.0, p.x - com.x, p.y - com.y));
    // The optimum is the minimum-norm solution with some set of feet held at `f_min`; with four
    // feet all 16 sets are tried and the least-norm feasible one kept (an exact small QP). When
    // none balances, the set whose solution leaves the smallest residual moment is used.
    let mut best: Option<(f64, [f64; NUM_LEGS])> = None;
    let mut closest: Option<(f64, [f64; NUM_LEGS])> = None;
    for held in 0u32..(1 << NUM_LEGS) {
        let is_held = |l: usize| held & (1 << l) != 0;
        // Equations over the free feet: Σ f = total − Σ held, Σ f·d = −f_min·Σ_held d.
        let mut rhs = Vector3::new(total, 0.0, 0.0);
        let mut gram = Matrix3::zeros();
        for (l, column) in lever.iter().enumerate() {
            if is_held(l) {
                rhs -= f_min * column;
            } else {
                gram += column * column.transpose();
            }
        }
        // Minimum norm over the free columns of A = [1; d_x; d_y]: f = Aᵀ (A Aᵀ)⁺ b.
        let Ok(inverse) = gram.pseudo_inverse(1e-12) else {
            continue;
        };
        let multipliers = inverse * rhs;
        let mut forces = [f_min; NUM_LEGS];
        let mut achieved = Vector3::zeros();
        for (l, column) in lever.iter().enumerate() {
            if !is_held(l) {
                forces[l] = multipliers.dot(column);
                achieved += forces[l] * column;
            }
        }
        let residual = (achieved - rhs).norm() / total;
        let feasible = forces.iter().all(|&f| f >= f_min - 1e-9 * total);
        let norm = forces.iter().map(|f| f * f).sum::<f64>();
        if feasible && residual < 1e-9 && best.map_or(true, |(n, _)| norm < n) {
            best = Some((norm, forces));
        }
        if closest.map_or(true, |(r, _)| residual < r) && forces.iter().all(|&f| f >= 0.0) {
            closest = Some((residual, forces));
        }
    }
    match (best, closest) {
        (Some((_, forces)), _) | (None, Some((_, forces))) => forces.map(|f| f.max(f_min)),
        (None, None) => equal,
    }
}

/// Centroid of the feet, world frame, m.
pub fn feet_centroid(feet: &[Vector3<f64>; NUM_LEGS]) -> Vector3<f64> {
    feet.iter().sum::<Vector3<f64>>() / NUM_LEGS as f64
}

/// Base xy that puts the CoM (at `com_offset_world` from the base origin) over the feet's
/// centroid, m.
pub fn base_xy_over_feet(
    feet: &[Vector3<f64>; NUM_LEGS],
    com_offset_world: &Vector3<f64>,
) -> [f64; 2] {
    let centroid = feet_centroid(feet);
    [
        centroid.x - com_offset_world.x,
        centroid.y - com_offset_world.y,
    ]
}

/// A base pose: position (world frame, m) and roll, pitch, yaw (ZYX Euler angles, rad).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BasePose {
    /// Base origin, world frame, m.
    pub position: Vector3<f64>,
    /// Roll, pitch, yaw, rad.
    pub rpy: Vector3<f64>,
}

impl BasePose {
    /// Body → world rotation.
    pub fn rotation(&self) -> Matrix3<f64> {
        *Rotation3::from_euler_angles(self.rpy.x, self.rpy.y, self.rpy.z).matrix()
    }

    /// The pose a fraction `s` of the way from `self` to `to` (position and angles linearly).
    pub fn lerp(&self, to: &BasePose, s: f64) -> BasePose {
        BasePose {
            position: self.position + (to.position - self.position) * s,
            rpy: self.rpy + (to.rpy - self.rpy) * s,
        }
    }
}

/// The standing pose over feet that stay where they are: roll 0, the given `pitch` and `yaw`, the
/// base origin `body_height` above `ground_height` and placed so that the CoM (at
/// `com_offset_body` from the base origin, base frame) is over the feet's centroid.
pub fn standing_pose_over_feet(
    feet: &[Vector3<f64>; NUM_LEGS],
    com_offset_body: &Vector3<f64>,
    yaw: f64,
    pitch: f64,
    ground_height: f64,
    body_height: f64,
) -> BasePose {
    let rpy = Vector3::new(0.0, pitch, yaw);
    let rotation = *Rotation3::from_euler_angles(0.0, pitch, yaw).matrix();
    let xy = base_xy_over_feet(feet, &(rotation * com_offset_body));
    BasePose {
        position: Vector3::new(xy[0], xy[1], ground_height + body_height),
        rpy,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    const WEIGHT: f64 = 120.0;
    const F_MIN: f64 = 5.0;

    /// A 0.37 m × 0.25 m rectangle of feet (FR, FL, RR, RL) on a plane rising `slope` along x.
    fn rectangle(slope: f64) -> [Vector3<f64>; NUM_LEGS] {
        [
            (0.185, -0.125),
            (0.185, 0.125),
            (-0.185, -0.125),
            (-0.185, 0.125),
        ]
        .map(|(x, y)| Vector3::new(x, y, x * slope))
    }

    fn moment_about(feet: &[Vector3<f64>; NUM_LEGS], com: &Vector3<f64>, f: &[f64; 4]) -> [f64; 2] {
        let mut m = [0.0; 2];
        for (p, fi) in feet.iter().zip(f) {
            m[0] += fi * (p.x - com.x);
            m[1] += fi * (p.y - com.y);
        }
        m
    }

    #[test]
    fn a_centred_com_gets_equal_shares() {
        let feet = rectangle(0.0);
        let f = static_vertical_forces(&feet, &Vector3::new(0.0, 0.0, 0.3), WEIGHT, F_MIN);
        for fi in f {
            assert!((fi - WEIGHT / 4.0).abs() < 1e-9, "{f:?}");
        }
    }

    #[test]
    fn a_com_off_the_centroid_is_balanced_by_loading_the_nearer_feet() {
        // 30° across-slope geometry: the CoM 0.08 m towards the left feet, 0.03 m forward.
        let feet = rectangle(0.0);
        let com = Vector3::new(0.03, 0.08, 0.25);
        let f = static_vertical_forces(&feet, &com, WEIGHT, F_MIN);
        assert!((f.iter().sum::<f64>() - WEIGHT).abs() < 1e-9);
        let m = moment_about(&feet, &com, &f);
        assert!(
            m[0].abs() < 1e-9 && m[1].abs() < 1e-9,
            "moment {m:?}, forces {f:?}"
        );
        assert!(f.iter().all(|&fi| fi >= F_MIN - 1e-12), "{f:?}");
        // FL carries the most, RR the least.
        assert!(
            f[1] > f[0] && f[1] > f[3] && f[2] < f[0] && f[2] < f[3],
            "{f:?}"
        );
    }

    #[test]
    fn the_minimum_force_holds_when_the_balance_would_unload_a_foot() {
        // The CoM towards FL: the least-norm balance without the bound would pull on RR (−2.2 N).
        let feet = rectangle(0.0);
        let com = Vector3::new(0.08, 0.08, 0.25);
        let f = static_vertical_forces(&feet, &com, WEIGHT, F_MIN);
        assert!((f.iter().sum::<f64>() - WEIGHT).abs() < 1e-9);
        assert!(f.iter().all(|&fi| fi >= F_MIN - 1e-9), "{f:?}");
        assert!(f.iter().any(|&fi| (fi - F_MIN).abs() < 1e-9), "{f:?}");
        let m = moment_about(&feet, &com, &f);
        assert!(
            m[0].abs() < 1e-9 && m[1].abs() < 1e-9,
            "moment {m:?}, forces {f:?}"
        );
    }

    #[test]
    fn a_com_outside_the_feet_still_gives_the_minimum_on_every_foot() {
        let feet = rectangle(0.0);
        let f = static_vertical_forces(&feet, &Vector3::new(0.0, 0.3, 0.25), WEIGHT, F_MIN);
        assert!(
            f.iter().all(|&fi| fi.is_finite() && fi >= F_MIN - 1e-12),
            "{f:?}"
        );
    }

    #[test]
    fn non_finite_input_gives_equal_shares() {
        let mut feet = rectangle(0.0);
        feet[2].x = f64::NAN;
        let f = static_vertical_forces(&feet, &Vector3::zeros(), WEIGHT, F_MIN);
        assert_eq!(f, [WEIGHT / 4.0; 4]);
    }

    #[test]
    fn the_standing_pose_puts_the_com_over_the_feet_at_the_stand_height() {
        // Feet on a 30° plane rising along x, robot facing across it (yaw 90°), CoM ahead of and
        // above the base origin.
        let slope = 30f64.to_radians();
        let feet = [
            (0.125, 0.185),
            (-0.125, 0.185),
            (0.125, -0.185),
            (-0.125, -0.185),
        ]
        .map(|(x, y)| Vector3::new(x + 2.0, y + 1.0, (x + 2.0) * slope.tan()));
        let com_offset = Vector3::new(0.02, 0.0, 0.05);
        let pitch = 0.1;
        let pose = standing_pose_over_feet(
            &feet,
            &com_offset,
            FRAC_PI_2,
            pitch,
            1.1,
            crate::tuning::TUNED_STAND_HEIGHT,
        );
        let com = pose.position + pose.rotation() * com_offset;
        let centroid = feet_centroid(&feet);
        assert!((com.x - centroid.x).abs() < 1e-12, "{com} vs {centroid}");
        assert!((com.y - centroid.y).abs() < 1e-12, "{com} vs {centroid}");
        assert!((pose.position.z - 1.38).abs() < 1e-12);
        // Roll 0: the body's y axis (pointing downhill, −x) stays level.
        let body_y = pose.rotation() * Vector3::y();
        assert!(
            body_y.z.abs() < 1e-12 && (body_y.x + 1.0).abs() < 1e-12,
            "{body_y}"
        );
        assert_eq!(pose.rpy, Vector3::new(0.0, pitch, FRAC_PI_2));
    }

    #[test]
    fn the_pose_ramp_starts_and_ends_at_its_poses() {
        let a = BasePose {
            position: Vector3::new(0.0, 0.0, 0.1),
            rpy: Vector3::new(-0.5, 0.2, 1.0),
        };
        let b = BasePose {
            position: Vector3::new(0.1, -0.2, 0.3),
            rpy: Vector3::new(0.0, 0.4, 1.0),
        };
        assert_eq!(a.lerp(&b, 0.0), a);
        assert!((a.lerp(&b, 1.0).position - b.position).norm() < 1e-15);
        let half = a.lerp(&b, 0.5);
        assert!((half.rpy.x + 0.25).abs() < 1e-15 && (half.position.z - 0.2).abs() < 1e-15);
    }
}
