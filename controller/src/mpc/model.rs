//! The per-step matrices of the MPC's dynamics rows (about each step's reference attitude) and
//! the terrain frame of the force variables.

use nalgebra::{Matrix3, Rotation3, Vector3};

use super::{MpcInput, MpcParams};
use crate::api::NUM_LEGS;

/// Largest reference roll or pitch the dynamics are linearised at, rad. The Euler-rate map is
/// singular at a pitch of ±π/2; a reference tilted further (no gait asks for one) is linearised
/// at this tilt instead of being refused.
pub(super) const MAX_LINEARISATION_TILT: f64 = 1.2;

/// `T(θ, ψ)`: the rates of the ZYX Euler angles (roll, pitch, yaw) of a world-frame angular
/// velocity ω, `Θ̇ = T ω`, at pitch θ and yaw ψ (roll does not enter). At θ = 0 it is `R_z(ψ)ᵀ`,
/// the map of Di Carlo et al.; a body pitched on a slope needs the full map: there a roll rate
/// turns the yaw by tan θ as much, and the MPC that ignored it fed roll corrections back as yaw
/// errors and oscillated at its own update rate (docs/slopes.md, 4c).
pub(super) fn euler_rate_map(pitch: f64, yaw: f64) -> Matrix3<f64> {
    let (sy, cy) = yaw.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    Matrix3::new(
        cy / cp,
        sy / cp,
        0.0,
        -sy,
        cy,
        0.0,
        cy * sp / cp,
        sy * sp / cp,
        1.0,
    )
}

/// Two unit tangents completing the unit normal n to a right-handed frame.
pub fn terrain_tangents(normal: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if normal.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let t1 = (helper - normal * normal.dot(&helper)).normalize();
    let t2 = normal.cross(&t1);
    (t1, t2)
}

/// The terrain frame `[t₁ t₂ n]` (columns) of a normal.
pub(super) fn terrain_frame(normal: [f64; 3]) -> Matrix3<f64> {
    let normal = Vector3::from(normal).normalize();
    let (t1, t2) = terrain_tangents(&normal);
    Matrix3::from_columns(&[t1, t2, normal])
}

/// What the sparse QP's dynamics rows need per step.
#[derive(Clone, Debug)]
pub(super) struct StageModel {
    /// `T_k`: the Euler-angle rates of an angular velocity at the step's reference attitude
    /// ([`euler_rate_map`]).
    pub(super) rate_map: Vec<Matrix3<f64>>,
    /// `dt I_w⁻¹ [r]×` of each leg (the angular-velocity rows of B_k).
    pub(super) b_omega: Vec<[Matrix3<f64>; NUM_LEGS]>,
    /// `N_k = (dt/2 (T_k + T_{k+1}))⁻¹`: `ω_{k+1} = N_k (c_{k+1} − c_k)`.
    pub(super) omega_of_c: Vec<Matrix3<f64>>,
    /// `G_k = dt/2 T_k N_k`: `Θ_{k+1} = (I − G_k) c_k + G_k c_{k+1}`.
    pub(super) theta_of_c: Vec<Matrix3<f64>>,
}

impl StageModel {
    pub(super) fn new(horizon: usize) -> Self {
        StageModel {
            rate_map: vec![Matrix3::zeros(); horizon],
            b_omega: vec![[Matrix3::zeros(); NUM_LEGS]; horizon],
            omega_of_c: vec![Matrix3::zeros(); horizon],
            theta_of_c: vec![Matrix3::zeros(); horizon],
        }
    }

    /// Fill every step's matrices for this input (reference attitude per step, foot offsets).
    pub(super) fn update(
        &mut self,
        params: &MpcParams,
        inertia_body: &Matrix3<f64>,
        input: &MpcInput<'_>,
    ) {
        let n = params.horizon;
        let half_dt = 0.5 * params.dt;
        for k in 0..n {
            let [roll, pitch] = [0, 1].map(|i| {
                input.reference[k][i].clamp(-MAX_LINEARISATION_TILT, MAX_LINEARISATION_TILT)
            });
            let yaw = input.reference[k][2];
            let rotation = *Rotation3::from_euler_angles(roll, pitch, yaw).matrix();
            let inertia_world_inv = (rotation * inertia_body * rotation.transpose())
                .try_inverse()
                .unwrap_or_else(Matrix3::identity);
            self.rate_map[k] = euler_rate_map(pitch, yaw);
            for (b, offset) in self.b_omega[k].iter_mut().zip(&input.foot_offsets[k]) {
                *b = (inertia_world_inv * Vector3::from(*offset).cross_matrix()) * params.dt;
            }
        }
        for k in 0..n {
            let next = self.rate_map[(k + 1).min(n - 1)];
            let m = (self.rate_map[k] + next) * half_dt;
            self.omega_of_c[k] = rate_pattern_inverse(&m);
            self.theta_of_c[k] = self.rate_map[k] * self.omega_of_c[k] * half_dt;
        }
    }
}

/// Inverse of a matrix with the pattern of [`euler_rate_map`] (an xy block, a z row, nothing
/// above the z entry), computed blockwise so that the entries outside the pattern stay exactly
/// zero. The xy block of a sum of two rate maps has the determinant
/// `(1/cos θ_k + 1/cos θ_{k+1})(1 + cos Δψ)` (times dt²/4), so it is invertible while the yaw
/// turns by less than π per step (`MAX_YAW_STEP`) and the tilt is bounded
/// (`MAX_LINEARISATION_TILT`).
fn rate_pattern_inverse(m: &Matrix3<f64>) -> Matrix3<f64> {
    let det = m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)];
    let xy_inverse = [
        [m[(1, 1)] / det, -m[(0, 1)] / det],
        [-m[(1, 0)] / det, m[(0, 0)] / det],
    ];
    let z = 1.0 / m[(2, 2)];
    // Bottom row: −z · [m₂₀ m₂₁] · (xy block)⁻¹.
    let bottom = [0, 1].map(|j| -z * (m[(2, 0)] * xy_inverse[0][j] + m[(2, 1)] * xy_inverse[1][j]));
    Matrix3::new(
        xy_inverse[0][0],
        xy_inverse[0][1],
        0.0,
        xy_inverse[1][0],
        xy_inverse[1][1],
        0.0,
        bottom[0],
        bottom[1],
        z,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ZYX Euler angles of a rotation matrix (pitch inside ±π/2).
    fn euler_angles(rotation: &Matrix3<f64>) -> Vector3<f64> {
        let (roll, pitch, yaw) = Rotation3::from_matrix_unchecked(*rotation).euler_angles();
        Vector3::new(roll, pitch, yaw)
    }

    #[test]
    fn the_rate_map_gives_the_euler_angle_rates_of_a_turning_body() {
        let omega = Vector3::new(0.7, -0.4, 0.3);
        let dt = 1e-6;
        for (roll, pitch, yaw) in [(0.0, 0.0, 0.4), (0.1, 0.35, 3.0), (-0.3, -0.9, -1.2)] {
            let start = *Rotation3::from_euler_angles(roll, pitch, yaw).matrix();
            // A world-frame angular velocity turns the body as R(t) = exp([ω]× t) R(0).
            let turned = *Rotation3::new(omega * dt).matrix() * start;
            let rates = (euler_angles(&turned) - euler_angles(&start)) / dt;
            let mapped = euler_rate_map(pitch, yaw) * omega;
            assert!((rates - mapped).norm() < 1e-5, "{rates} vs {mapped}");
        }
    }

    #[test]
    fn the_blockwise_inverse_is_the_inverse_and_keeps_the_pattern() {
        let m = (euler_rate_map(0.3, 0.2) + euler_rate_map(-0.1, 0.9)) * 0.015;
        let inverse = rate_pattern_inverse(&m);
        assert!((inverse * m - Matrix3::identity()).norm() < 1e-12);
        assert_eq!((inverse[(0, 2)], inverse[(1, 2)]), (0.0, 0.0));
    }
}
