//! Test oracle for the MPC: the exact discrete single-rigid-body model and the condensed QP over
//! the stance forces (states eliminated, dense P). Independent of the sparse formulation that
//! `ConvexMpc` solves, so the two can be compared. Shared by the MPC unit tests (included from
//! `src/mpc/tests.rs`), the integration tests and the MPC benchmark; each includer provides a
//! module `mpc_api` with the MPC's public items, `rot_z` and `NUM_LEGS`.
#![allow(dead_code)] // each includer uses a different part

use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, SMatrix, Vector3};

use super::mpc_api::{rot_z, terrain_tangents, MpcInput, MpcParams, MPC_STATES, NUM_LEGS};

pub type Mat13 = SMatrix<f64, 13, 13>;
pub type Mat13x3 = SMatrix<f64, 13, 3>;
/// Constraint rows per stance foot: four friction-pyramid faces and the two normal-force bounds.
pub const ROWS_PER_FOOT: usize = 6;

/// The body inertia of the parameters as a matrix.
pub fn inertia_body(params: &MpcParams) -> Matrix3<f64> {
    let ib = &params.inertia_body;
    Matrix3::new(
        ib[0][0], ib[0][1], ib[0][2], ib[1][0], ib[1][1], ib[1][2], ib[2][0], ib[2][1], ib[2][2],
    )
}

/// An MPC problem as a condensed QP over the stance forces (N):
/// minimise ½ uᵀPu + qᵀu s.t. A u ≤ b. Same optimum as the sparse QP that `ConvexMpc` solves.
#[derive(Clone, Debug, Default)]
pub struct QpData {
    /// Number of variables.
    pub n: usize,
    /// Dense P, column-major n×n (full, symmetric).
    pub p_dense: Vec<f64>,
    /// Linear cost.
    pub q: Vec<f64>,
    /// Constraint rows.
    pub m: usize,
    /// A in CSC form: column pointers.
    pub a_colptr: Vec<usize>,
    /// A row indices.
    pub a_rowval: Vec<usize>,
    /// A values.
    pub a_nzval: Vec<f64>,
    /// Upper bounds b.
    pub b: Vec<f64>,
}

/// Rows `a` of the per-foot constraints `a·f ≤ b`: friction pyramid, then −f·n ≤ −f_min and
/// f·n ≤ f_max.
pub fn foot_constraint_rows(normal: [f64; 3], mu: f64) -> [Vector3<f64>; ROWS_PER_FOOT] {
    let normal = Vector3::from(normal).normalize();
    let (t1, t2) = terrain_tangents(&normal);
    [
        t1 - normal * mu,
        -t1 - normal * mu,
        t2 - normal * mu,
        -t2 - normal * mu,
        -normal,
        normal,
    ]
}

fn rot_y(angle: f64) -> Matrix3<f64> {
    *Rotation3::from_axis_angle(&Vector3::y_axis(), angle).matrix()
}

fn rot_x(angle: f64) -> Matrix3<f64> {
    *Rotation3::from_axis_angle(&Vector3::x_axis(), angle).matrix()
}

/// The map from a world angular velocity to the ZYX Euler-angle rates, as the inverse of the map
/// `ω = ψ̇ e_z + θ̇ R_z e_y + φ̇ R_z R_y e_x` (its columns: the axes each angle turns about).
fn euler_rates_of_omega(pitch: f64, yaw: f64) -> Matrix3<f64> {
    let rz = rot_z(yaw);
    let omega_of_rates = Matrix3::from_columns(&[
        rz * rot_y(pitch) * Vector3::x(),
        rz * Vector3::y(),
        Vector3::z(),
    ]);
    omega_of_rates
        .try_inverse()
        .expect("the Euler-rate map is invertible away from pitch ±π/2")
}

/// The discrete model of every step: A_k about the reference attitude, B_k from the feet.
pub fn discrete_model(
    params: &MpcParams,
    input: &MpcInput<'_>,
    a_mats: &mut [Mat13],
    b_mats: &mut [[Mat13x3; NUM_LEGS]],
) {
    let dt = params.dt;
    let inertia_body = inertia_body(params);
    let inv_mass = 1.0 / params.mass;
    for k in 0..params.horizon {
        let [roll, pitch, yaw] = [0, 1, 2].map(|i| input.reference[k][i]);
        let rotation = rot_z(yaw) * rot_y(pitch) * rot_x(roll);
        let inertia_world = rotation * inertia_body * rotation.transpose();
        let inertia_world_inv = inertia_world
            .try_inverse()
            .unwrap_or_else(Matrix3::identity);
        let mut a_c = Mat13::zeros();
        a_c.fixed_view_mut::<3, 3>(0, 6)
            .copy_from(&euler_rates_of_omega(pitch, yaw));
        a_c.fixed_view_mut::<3, 3>(3, 9)
            .copy_from(&Matrix3::identity());
        a_c[(11, 12)] = -1.0;
        let a_c2 = a_c * a_c;
        a_mats[k] = Mat13::identity() + a_c * dt + a_c2 * (dt * dt * 0.5);
        for (b_leg, offset) in b_mats[k].iter_mut().zip(&input.foot_offsets[k]) {
            let r = Vector3::from(*offset);
            let mut b_c = Mat13x3::zeros();
            b_c.fixed_view_mut::<3, 3>(6, 0)
                .copy_from(&(inertia_world_inv * r.cross_matrix()));
            b_c.fixed_view_mut::<3, 3>(9, 0)
                .copy_from(&(Matrix3::identity() * inv_mass));
            *b_leg = b_c * dt + a_c * b_c * (dt * dt * 0.5);
        }
    }
}

/// The problem as a condensed QP: states eliminated, `P = 2(S_uᵀ Q̄ S_u + R̄)`,
/// `q = 2 S_uᵀ Q̄ (S_x x₀ − X_ref)` over the stance forces (N), constraints `A u ≤ b`.
pub fn condensed_qp(params: &MpcParams, input: &MpcInput<'_>) -> QpData {
    let n = params.horizon;
    let mut a_mats = vec![Mat13::zeros(); n];
    let mut b_mats = vec![[Mat13x3::zeros(); NUM_LEGS]; n];
    discrete_model(params, input, &mut a_mats, &mut b_mats);
    let blocks: Vec<(usize, usize)> = (0..n)
        .flat_map(|k| (0..NUM_LEGS).map(move |leg| (k, leg)))
        .filter(|&(k, leg)| input.contacts[k][leg])
        .collect();
    let nv = 3 * blocks.len();
    let rows = MPC_STATES * n;
    let mut su = DMatrix::<f64>::zeros(rows, nv);
    let mut free_response = DVector::<f64>::zeros(rows);
    let mut state = Mat13::identity();
    let x0 = SMatrix::<f64, 13, 1>::from(input.x0);
    for k in 0..n {
        state = a_mats[k] * state;
        let row = MPC_STATES * k;
        for (b, &(step, leg)) in blocks.iter().enumerate() {
            if step > k {
                break;
            }
            let block = if step == k {
                b_mats[k][leg]
            } else {
                a_mats[k] * su.fixed_view::<13, 3>(row - MPC_STATES, 3 * b)
            };
            su.fixed_view_mut::<13, 3>(row, 3 * b).copy_from(&block);
        }
        let free = state * x0;
        for i in 0..MPC_STATES {
            free_response[row + i] = free[i] - input.reference[k][i];
        }
    }
    let mut weighted_su = su.clone();
    for r in 0..rows {
        let w = params.q_weights[r % MPC_STATES];
        weighted_su.row_mut(r).scale_mut(w);
    }
    let mut hessian = su.tr_mul(&weighted_su) * 2.0;
    for i in 0..nv {
        hessian[(i, i)] += 2.0 * params.r_weight;
    }
    let gradient = weighted_su.tr_mul(&free_response) * 2.0;

    let rows_of_block = foot_constraint_rows(input.terrain_normal, params.mu);
    let nblocks = blocks.len();
    let mut a_colptr = Vec::with_capacity(nv + 1);
    let mut a_rowval = Vec::with_capacity(18 * nblocks);
    let mut a_nzval = Vec::with_capacity(18 * nblocks);
    a_colptr.push(0);
    for b in 0..nblocks {
        for axis in 0..3 {
            for (r, row) in rows_of_block.iter().enumerate() {
                a_rowval.push(ROWS_PER_FOOT * b + r);
                a_nzval.push(row[axis]);
            }
            a_colptr.push(a_rowval.len());
        }
    }
    let b = (0..nblocks)
        .flat_map(|_| [0.0, 0.0, 0.0, 0.0, -params.f_min, params.f_max])
        .collect();
    QpData {
        n: nv,
        p_dense: hessian.as_slice().to_vec(),
        q: gradient.as_slice().to_vec(),
        m: ROWS_PER_FOOT * nblocks,
        a_colptr,
        a_rowval,
        a_nzval,
        b,
    }
}
