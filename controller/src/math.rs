//! Small geometric helpers shared by the model, the MPC and the controller stages (a leaf module,
//! so none of them has to depend on another for these).

use nalgebra::Matrix3;

/// Wrap an angle to (−π, π].
pub fn wrap_angle(angle: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut a = angle % two_pi;
    if a > std::f64::consts::PI {
        a -= two_pi;
    } else if a <= -std::f64::consts::PI {
        a += two_pi;
    }
    a
}

/// Rotation about the world z axis by `yaw` (rad).
pub fn rot_z(yaw: f64) -> Matrix3<f64> {
    let (s, c) = yaw.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_angle_range() {
        assert!((wrap_angle(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
        assert!((wrap_angle(-0.5) + 0.5).abs() < 1e-15);
    }

    #[test]
    fn rot_z_turns_x_into_y() {
        let v = rot_z(std::f64::consts::FRAC_PI_2) * nalgebra::Vector3::x();
        assert!((v - nalgebra::Vector3::y()).norm() < 1e-15);
    }
}
