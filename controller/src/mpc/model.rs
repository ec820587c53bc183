//! The per-step matrices of the MPC's dynamics rows (about each step's reference yaw) and the
//! terrain frame of the force variables.

use nalgebra::{Matrix3, Vector3};

use super::{MpcInput, MpcParams};
use crate::api::NUM_LEGS;
use crate::math::rot_z;

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
    /// `R_z(ψ_k)ᵀ`.
    pub(super) rz_t: Vec<Matrix3<f64>>,
    /// `dt I_w⁻¹ [r]×` of each leg (the angular-velocity rows of B_k).
    pub(super) b_omega: Vec<[Matrix3<f64>; NUM_LEGS]>,
    /// `N_k = (dt/2 (R_k + R_{k+1})ᵀ)⁻¹`: `ω_{k+1} = N_k (c_{k+1} − c_k)`.
    pub(super) omega_of_c: Vec<Matrix3<f64>>,
    /// `G_k = dt/2 R_kᵀ N_k`: `Θ_{k+1} = (I − G_k) c_k + G_k c_{k+1}`.
    pub(super) theta_of_c: Vec<Matrix3<f64>>,
}

impl StageModel {
    pub(super) fn new(horizon: usize) -> Self {
        StageModel {
            rz_t: vec![Matrix3::zeros(); horizon],
            b_omega: vec![[Matrix3::zeros(); NUM_LEGS]; horizon],
            omega_of_c: vec![Matrix3::zeros(); horizon],
            theta_of_c: vec![Matrix3::zeros(); horizon],
        }
    }

    /// Fill every step's matrices for this input (reference yaw per step, foot offsets).
    pub(super) fn update(
        &mut self,
        params: &MpcParams,
        inertia_body: &Matrix3<f64>,
        input: &MpcInput<'_>,
    ) {
        let n = params.horizon;
        let half_dt = 0.5 * params.dt;
        for k in 0..n {
            let rz = rot_z(input.reference[k][2]);
            let inertia_world_inv = (rz * inertia_body * rz.transpose())
                .try_inverse()
                .unwrap_or_else(Matrix3::identity);
            self.rz_t[k] = rz.transpose();
            for (b, offset) in self.b_omega[k].iter_mut().zip(&input.foot_offsets[k]) {
                *b = (inertia_world_inv * Vector3::from(*offset).cross_matrix()) * params.dt;
            }
        }
        for k in 0..n {
            let next = self.rz_t[(k + 1).min(n - 1)];
            let m = (self.rz_t[k] + next) * half_dt;
            self.omega_of_c[k] = yaw_pattern_inverse(&m);
            self.theta_of_c[k] = self.rz_t[k] * self.omega_of_c[k] * half_dt;
        }
    }
}

/// Inverse of a matrix with the pattern of a yaw rotation (an xy block and a z entry), computed
/// blockwise so that the entries outside the pattern stay exactly zero. The caller guarantees
/// invertibility (see `MAX_YAW_STEP`).
fn yaw_pattern_inverse(m: &Matrix3<f64>) -> Matrix3<f64> {
    let det = m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)];
    Matrix3::new(
        m[(1, 1)] / det,
        -m[(0, 1)] / det,
        0.0,
        -m[(1, 0)] / det,
        m[(0, 0)] / det,
        0.0,
        0.0,
        0.0,
        1.0 / m[(2, 2)],
    )
}
