//! Unit tests of the sparse QP against the exact discrete model (the oracle in
//! `tests/support/mpc_oracle.rs`).
use nalgebra::{SMatrix, Vector3};

use super::model::terrain_frame;
use super::*;

/// What the shared oracle needs from this crate.
mod mpc_api {
    pub use crate::api::NUM_LEGS;
    pub use crate::math::rot_z;
    pub use crate::mpc::{terrain_tangents, MpcInput, MpcParams, MPC_STATES};
}
#[path = "../../tests/support/mpc_oracle.rs"]
mod mpc_oracle;
use mpc_oracle::{discrete_model, foot_constraint_rows, Mat13, Mat13x3};

fn test_params() -> MpcParams {
    MpcParams {
        horizon: 3,
        dt: 0.03,
        mass: 12.0,
        inertia_body: [
            [0.05, 0.002, -0.003],
            [0.002, 0.08, 0.001],
            [-0.003, 0.001, 0.1],
        ],
        q_weights: [1.0; 13],
        r_weight: 1e-5,
        mu: 0.6,
        f_min: 5.0,
        f_max: 150.0,
    }
}

const REFERENCE: [[f64; 13]; 3] = [
    [0.0; 13],
    [
        0.0, 0.0, 0.7, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 9.81,
    ],
    [
        0.1, -0.2, -2.3, 1.0, 2.0, 0.3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 9.81,
    ],
];
const FEET: [[[f64; 3]; NUM_LEGS]; 3] = [[
    [0.2, 0.15, -0.3],
    [0.21, -0.14, -0.28],
    [-0.2, 0.16, -0.31],
    [-0.19, -0.15, -0.27],
]; 3];

/// A problem with turning reference yaw, mixed contacts and a sloped terrain normal.
struct Problem {
    x0: [f64; 13],
    contacts: [[bool; NUM_LEGS]; 3],
    normal: [f64; 3],
}

impl Problem {
    fn input(&self) -> MpcInput<'_> {
        MpcInput {
            x0: self.x0,
            reference: &REFERENCE,
            contacts: &self.contacts,
            foot_offsets: &FEET,
            terrain_normal: self.normal,
        }
    }
}

/// The problem's sparse QP, assembled, and trajectories rolled out with the exact discrete
/// model from given forces.
struct Rollout {
    mpc: ConvexMpc,
    problem: Problem,
}

impl Rollout {
    fn new() -> Self {
        let mut x0 = [0.0; 13];
        for (i, v) in x0.iter_mut().enumerate() {
            *v = 0.1 * (i as f64 * 1.7).sin();
        }
        x0[12] = 9.81;
        let problem = Problem {
            x0,
            contacts: [
                [true, false, false, true],
                [true, true, true, true],
                [false, true, true, false],
            ],
            normal: Vector3::new(-0.15, 0.1, 1.0).normalize().into(),
        };
        let mut mpc = ConvexMpc::new(test_params()).expect("MPC");
        assert!(
            mpc.build_qp(&problem.input()),
            "the problem has stance legs"
        );
        Rollout { mpc, problem }
    }

    /// Roll out forces (world frame, N; one per force block, in block order) with the exact
    /// discrete model. Returns the QP variables of that trajectory, the world-frame
    /// constraint rows of the forces (in units of m·g) and the MPC cost (with the QP's
    /// scale factor).
    fn roll_out(&self, forces: &[Vector3<f64>]) -> (Vec<f64>, Vec<f64>, f64) {
        let mpc = &self.mpc;
        let params = &mpc.params;
        let input = self.problem.input();
        let mut a_mats = vec![Mat13::zeros(); 3];
        let mut b_mats = vec![[Mat13x3::zeros(); NUM_LEGS]; 3];
        discrete_model(params, &input, &mut a_mats, &mut b_mats);
        let frame = terrain_frame(input.terrain_normal);
        let foot_rows = foot_constraint_rows(input.terrain_normal, params.mu);
        let mut z: Vec<f64> = Vec::new();
        let mut world_rows: Vec<f64> = Vec::new();
        let mut cost = 0.0;
        let mut x = SMatrix::<f64, 13, 1>::from(input.x0);
        for k in 0..3 {
            let mut next = a_mats[k] * x;
            for (b, &(_, leg)) in mpc.blocks.iter().enumerate().filter(|(_, bl)| bl.0 == k) {
                let f = forces[b];
                next += b_mats[k][leg] * f;
                z.extend((frame.transpose() * f / mpc.force_scale).iter());
                world_rows.extend(foot_rows.iter().map(|row| row.dot(&f) / mpc.force_scale));
                cost += params.r_weight * f.norm_squared();
            }
            x = next;
            for i in 0..12 {
                cost += params.q_weights[i] * (x[i] - REFERENCE[k][i]).powi(2);
            }
            // c_{k+1} uses T_{k+1}, and T_N := T_{N−1} for the last step.
            let rate_map = mpc.stages.rate_map[(k + 1).min(2)];
            let c = Vector3::new(x[0], x[1], x[2])
                + rate_map * Vector3::new(x[6], x[7], x[8]) * (0.5 * params.dt);
            z.extend(c.iter());
            z.extend((3..6).map(|i| x[i] + 0.5 * params.dt * x[i + 6]));
        }
        (z, world_rows, COST_SCALE * cost)
    }

    /// `½ zᵀPz + qᵀz` of the assembled QP (P stored as its upper triangle).
    fn objective(&self, z: &[f64]) -> f64 {
        let mpc = &self.mpc;
        let mut value = 0.0;
        for c in 0..z.len() {
            value += mpc.q_values[c] * z[c];
            for idx in mpc.p_colptr[c]..mpc.p_colptr[c + 1] {
                let r = mpc.p_rowval[idx];
                let weight = if r == c { 0.5 } else { 1.0 };
                value += weight * mpc.p_values[idx] * z[r] * z[c];
            }
        }
        value
    }
}

fn random_forces(count: usize, seed: usize) -> Vec<Vector3<f64>> {
    (0..count)
        .map(|b| {
            let s = (seed * 31 + b) as f64;
            Vector3::new(
                30.0 * (1.3 * s).sin(),
                -25.0 * (0.7 * s + 1.0).cos(),
                60.0 + 20.0 * (2.1 * s).sin(),
            )
        })
        .collect()
}

/// The sparse QP's rows describe the same problem as the exact discrete model: a trajectory
/// rolled out with `x_{k+1} = A_k x_k + B_k u_k` satisfies the dynamics rows in the (c, a)
/// variables, and the terrain-frame force rows equal the world-frame foot constraints.
#[test]
fn sparse_rows_match_the_discrete_model() {
    let rollout = Rollout::new();
    let mpc = &rollout.mpc;
    let (z, world_rows, _) = rollout.roll_out(&random_forces(mpc.blocks.len(), 1));
    assert_eq!(z.len(), mpc.q_values.len());
    let mut ax = vec![0.0; mpc.b_values.len()];
    for (c, zc) in z.iter().enumerate() {
        for idx in mpc.a_colptr[c]..mpc.a_colptr[c + 1] {
            ax[mpc.a_rowval[idx]] += mpc.a_values[idx] * zc;
        }
    }
    let (dynamics, force_rows) = ax.split_at(NS * 3);
    for (r, (lhs, rhs)) in dynamics.iter().zip(&mpc.b_values).enumerate() {
        assert!(
            (lhs - rhs).abs() < 1e-12,
            "dynamics row {r}: {lhs} vs {rhs}"
        );
    }
    assert_eq!(force_rows.len(), world_rows.len());
    for (r, (lhs, expected)) in force_rows.iter().zip(&world_rows).enumerate() {
        assert!((lhs - expected).abs() < 1e-12, "force row {r}");
    }
}

/// The QP objective is the MPC cost up to a constant: over several rolled-out trajectories
/// the two differ by the same amount (so they have the same minimiser on the feasible set).
#[test]
fn sparse_objective_equals_the_mpc_cost_up_to_a_constant() {
    let rollout = Rollout::new();
    let blocks = rollout.mpc.blocks.len();
    let offsets: Vec<(f64, f64)> = (0..4)
        .map(|seed| {
            let (z, _, cost) = rollout.roll_out(&random_forces(blocks, seed));
            (cost, rollout.objective(&z) - cost)
        })
        .collect();
    for &(cost, offset) in &offsets[1..] {
        assert!(
            (offset - offsets[0].1).abs() < 1e-9 * cost.max(1.0),
            "objective − cost: {offset} vs {} (cost {cost})",
            offsets[0].1
        );
    }
}

/// A reference yaw that turns by more than `MAX_YAW_STEP` between two steps is refused
/// (N_k would be near-singular), and a wrap-around of ±π between steps is not a turn.
#[test]
fn yaw_jumps_between_steps_are_refused_but_wrapping_is_not() {
    let mut mpc = ConvexMpc::new(test_params()).expect("MPC");
    let contacts = [[true; NUM_LEGS]; 3];
    let mut reference = [[0.0; 13]; 3];
    for r in &mut reference {
        r[5] = 0.3;
        r[12] = 9.81;
    }
    let mut x0 = reference[0];
    x0[5] = 0.3;
    let mut solve = |yaws: [f64; 3]| {
        for (r, yaw) in reference.iter_mut().zip(yaws) {
            r[2] = yaw;
        }
        let input = MpcInput {
            x0,
            reference: &reference,
            contacts: &contacts,
            foot_offsets: &FEET,
            terrain_normal: [0.0, 0.0, 1.0],
        };
        mpc.solve(&input).status
    };
    assert_eq!(solve([0.0, 0.1, 0.2]), MpcStatus::Solved);
    let pi = std::f64::consts::PI;
    assert_eq!(solve([pi - 0.05, -pi + 0.05, -pi + 0.1]), MpcStatus::Solved);
    assert_eq!(solve([0.0, 2.0, 2.1]), MpcStatus::InvalidInput);
}
