//! Convex MPC on ground reaction forces (Di Carlo et al., "Dynamic Locomotion in the MIT Cheetah 3
//! Through Convex Model-Predictive Control", 2018), solved as a condensed QP with Clarabel.
//!
//! Model: single rigid body with 13 states
//! `x = [roll, pitch, yaw, p_x, p_y, p_z, ω_x, ω_y, ω_z, v_x, v_y, v_z, g]`
//! (CoM position/velocity and angular velocity in the world frame, `g = 9.81` a constant state so
//! gravity enters linearly). Linearised about the reference yaw ψ_k of each step:
//! `Θ̇ = R_z(ψ_k)ᵀ ω`, `ṗ = v`, `ω̇ = I_w⁻¹ Σ r_i × f_i` with `I_w = R_z I_b R_zᵀ`,
//! `v̇ = Σ f_i / m − g e_z`. The discretisation is exact for this model (A³ = 0, zero-order hold).
//!
//! Decision variables: the world-frame ground reaction forces (acting on the robot) of the legs
//! in stance at each step; swing legs are eliminated from the QP, which is the `D_k u = 0`
//! constraint of the paper applied by construction (their forces are exactly zero). Constraints
//! per stance foot: friction pyramid about the terrain normal n with tangents t₁, t₂
//! (`|f·tⱼ| ≤ μ f·n`) and `f_min ≤ f·n ≤ f_max`.
//!
//! Cost: `Σ_k (x_k − x_ref,k)ᵀ Q (x_k − x_ref,k) + Σ_k u_kᵀ R u_k`, condensed to
//! `½ Uᵀ P U + qᵀ U` with `P = 2(S_uᵀ Q̄ S_u + R̄)` and `q = 2 S_uᵀ Q̄ (S_x x₀ − X_ref)`.
//!
//! Reuse: all dense work buffers are allocated once; Clarabel solvers are cached per contact
//! schedule over the horizon (which fixes the sparsity of P and A), and later solves with the same
//! schedule only update the numeric values (`update_P/q/A/b`), skipping symbolic setup.

use std::collections::HashMap;
use std::time::Instant;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use nalgebra::{DMatrix, DVector, Matrix3, SMatrix, Vector3};

use crate::api::NUM_LEGS;

/// Number of MPC states.
pub const MPC_STATES: usize = 13;
const ROWS_PER_FOOT: usize = 6;
const MAX_CACHED_SOLVERS: usize = 32;

type Mat13 = SMatrix<f64, 13, 13>;
type Mat13x3 = SMatrix<f64, 13, 3>;

/// Fixed parameters of the MPC.
#[derive(Clone, Debug)]
pub struct MpcParams {
    /// Horizon length N.
    pub horizon: usize,
    /// Prediction step, s.
    pub dt: f64,
    /// Total mass, kg.
    pub mass: f64,
    /// Body-frame inertia about the CoM, kg·m².
    pub inertia_body: [[f64; 3]; 3],
    /// State weights (diagonal of Q).
    pub q_weights: [f64; 13],
    /// Force weight (diagonal of R).
    pub r_weight: f64,
    /// Friction coefficient.
    pub mu: f64,
    /// Normal force bounds, N.
    pub f_min: f64,
    /// Normal force upper bound, N.
    pub f_max: f64,
}

/// One MPC problem instance.
#[derive(Clone, Debug)]
pub struct MpcInput<'a> {
    /// Current state x₀.
    pub x0: [f64; MPC_STATES],
    /// Reference states x_ref,1..N (length N).
    pub reference: &'a [[f64; MPC_STATES]],
    /// Stance flags for steps 0..N−1 (length N).
    pub contacts: &'a [[bool; NUM_LEGS]],
    /// Foot positions relative to the (predicted) CoM for steps 0..N−1, world frame, m.
    pub foot_offsets: &'a [[[f64; 3]; NUM_LEGS]],
    /// Terrain unit normal (world frame) for the friction pyramid.
    pub terrain_normal: [f64; 3],
}

/// Result status of an MPC solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MpcStatus {
    /// Solved to tolerance (or Clarabel's reduced "almost solved" tolerance).
    Solved,
    /// The solver failed; the caller must fall back.
    Failed,
    /// Invalid input (sizes, non-finite values); the QP was not attempted.
    InvalidInput,
}

/// Outcome of one solve.
#[derive(Clone, Copy, Debug)]
pub struct MpcSolution {
    /// Forces of step 0 (ground reaction on the robot, world frame, N), zero for swing legs.
    pub forces: [[f64; 3]; NUM_LEGS],
    /// Status.
    pub status: MpcStatus,
    /// Wall time of setup + solve, s (diagnostic only).
    pub solve_time_s: f64,
    /// Time spent inside Clarabel's `solve` (its own timer), s; the rest of `solve_time_s` is
    /// condensing and QP assembly.
    pub qp_time_s: f64,
    /// Interior-point iterations.
    pub iterations: u32,
    /// Number of decision variables.
    pub num_variables: usize,
}

/// The assembled QP of the last solve: minimise ½ uᵀPu + qᵀu s.t. A u ≤ b (for comparisons).
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

/// Convex MPC with preallocated buffers and a per-schedule solver cache.
pub struct ConvexMpc {
    params: MpcParams,
    inertia_body: Matrix3<f64>,
    settings: DefaultSettings<f64>,
    a_mats: Vec<Mat13>,
    b_mats: Vec<[Mat13x3; NUM_LEGS]>,
    /// S_x blocks: x_k = S_x[k-1] x₀ + …
    sx: Vec<Mat13>,
    /// Condensed input matrix S_u (13N × max variables).
    su: DMatrix<f64>,
    weighted_su: DMatrix<f64>,
    hessian: DMatrix<f64>,
    gradient: DVector<f64>,
    free_response: DVector<f64>,
    /// (step, leg) of each 3-column variable block.
    blocks: Vec<(usize, usize)>,
    p_values: Vec<f64>,
    a_values: Vec<f64>,
    b_values: Vec<f64>,
    solvers: HashMap<Vec<u8>, DefaultSolver<f64>>,
    last_qp: QpData,
}

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

fn rot_z(yaw: f64) -> Matrix3<f64> {
    let (s, c) = yaw.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
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

impl ConvexMpc {
    /// Create the MPC; fails when a parameter is invalid.
    pub fn new(params: MpcParams) -> Result<Self, String> {
        if params.horizon == 0 || params.horizon > 40 {
            return Err(format!("horizon {} outside 1..=40", params.horizon));
        }
        let positive = [params.dt, params.mass, params.mu, params.f_max];
        if positive.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return Err("dt, mass, mu and f_max must be finite and > 0".into());
        }
        if !(params.f_min.is_finite() && params.f_min >= 0.0 && params.f_min < params.f_max) {
            return Err(format!(
                "normal force bounds [{}, {}] invalid",
                params.f_min, params.f_max
            ));
        }
        if params
            .q_weights
            .iter()
            .any(|w| !(w.is_finite() && *w >= 0.0))
            || !(params.r_weight.is_finite() && params.r_weight > 0.0)
        {
            return Err("Q weights must be ≥ 0 and R > 0".into());
        }
        let ib = &params.inertia_body;
        let inertia_body = Matrix3::new(
            ib[0][0], ib[0][1], ib[0][2], ib[1][0], ib[1][1], ib[1][2], ib[2][0], ib[2][1],
            ib[2][2],
        );
        if inertia_body.cholesky().is_none() {
            return Err("body inertia is not positive definite".into());
        }
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .input_sparse_dropzeros(false)
            .max_iter(50)
            .tol_gap_abs(1e-6)
            .tol_gap_rel(1e-6)
            .tol_feas(1e-6)
            .build()
            .map_err(|e| format!("clarabel settings: {e:?}"))?;
        let n = params.horizon;
        let max_vars = 3 * NUM_LEGS * n;
        Ok(ConvexMpc {
            inertia_body,
            settings,
            a_mats: vec![Mat13::zeros(); n],
            b_mats: vec![[Mat13x3::zeros(); NUM_LEGS]; n],
            sx: vec![Mat13::zeros(); n],
            su: DMatrix::zeros(MPC_STATES * n, max_vars),
            weighted_su: DMatrix::zeros(MPC_STATES * n, max_vars),
            hessian: DMatrix::zeros(max_vars, max_vars),
            gradient: DVector::zeros(max_vars),
            free_response: DVector::zeros(MPC_STATES * n),
            blocks: Vec::with_capacity(NUM_LEGS * n),
            p_values: Vec::with_capacity(max_vars * (max_vars + 1) / 2),
            a_values: Vec::with_capacity(max_vars * ROWS_PER_FOOT * 2),
            b_values: Vec::with_capacity(ROWS_PER_FOOT * NUM_LEGS * n),
            solvers: HashMap::new(),
            last_qp: QpData::default(),
            params,
        })
    }

    /// Parameters.
    pub fn params(&self) -> &MpcParams {
        &self.params
    }

    /// The QP assembled by the last call of [`ConvexMpc::solve`].
    pub fn last_qp(&self) -> &QpData {
        &self.last_qp
    }

    fn validate(&self, input: &MpcInput<'_>) -> bool {
        let n = self.params.horizon;
        input.reference.len() == n
            && input.contacts.len() == n
            && input.foot_offsets.len() == n
            && input.x0.iter().all(|v| v.is_finite())
            && input.reference.iter().flatten().all(|v| v.is_finite())
            && input
                .foot_offsets
                .iter()
                .flatten()
                .flatten()
                .all(|v| v.is_finite())
            && input.terrain_normal.iter().all(|v| v.is_finite())
            && Vector3::from(input.terrain_normal).norm() > 0.5
    }

    /// Build the discrete model of every step: A_k about the reference yaw, B_k from the feet.
    fn build_model(&mut self, input: &MpcInput<'_>) {
        let dt = self.params.dt;
        let inv_mass = 1.0 / self.params.mass;
        for k in 0..self.params.horizon {
            let yaw = input.reference[k][2];
            let rz = rot_z(yaw);
            let inertia_world = rz * self.inertia_body * rz.transpose();
            let inertia_world_inv = inertia_world
                .try_inverse()
                .unwrap_or_else(Matrix3::identity);
            let mut a_c = Mat13::zeros();
            a_c.fixed_view_mut::<3, 3>(0, 6).copy_from(&rz.transpose());
            a_c.fixed_view_mut::<3, 3>(3, 9)
                .copy_from(&Matrix3::identity());
            a_c[(11, 12)] = -1.0;
            let a_c2 = a_c * a_c;
            self.a_mats[k] = Mat13::identity() + a_c * dt + a_c2 * (dt * dt * 0.5);
            for leg in 0..NUM_LEGS {
                let r = Vector3::from(input.foot_offsets[k][leg]);
                let mut b_c = Mat13x3::zeros();
                b_c.fixed_view_mut::<3, 3>(6, 0)
                    .copy_from(&(inertia_world_inv * skew(&r)));
                b_c.fixed_view_mut::<3, 3>(9, 0)
                    .copy_from(&(Matrix3::identity() * inv_mass));
                self.b_mats[k][leg] = b_c * dt + a_c * b_c * (dt * dt * 0.5);
            }
        }
    }

    /// Solve one MPC problem. Never panics; invalid input or solver failure is reported in the
    /// status (forces are then zero and the caller falls back).
    pub fn solve(&mut self, input: &MpcInput<'_>) -> MpcSolution {
        let start = Instant::now();
        let mut solution = MpcSolution {
            forces: [[0.0; 3]; NUM_LEGS],
            status: MpcStatus::InvalidInput,
            solve_time_s: 0.0,
            qp_time_s: 0.0,
            iterations: 0,
            num_variables: 0,
        };
        if !self.validate(input) {
            return solution;
        }
        let n = self.params.horizon;
        self.build_model(input);

        self.blocks.clear();
        for (k, contacts) in input.contacts.iter().enumerate() {
            for (leg, &stance) in contacts.iter().enumerate() {
                if stance {
                    self.blocks.push((k, leg));
                }
            }
        }
        let nv = 3 * self.blocks.len();
        solution.num_variables = nv;
        if nv == 0 {
            // Flight over the whole horizon: nothing to optimise, zero forces are the answer.
            solution.status = MpcStatus::Solved;
            solution.solve_time_s = start.elapsed().as_secs_f64();
            return solution;
        }

        // Condensed prediction: x_{k+1} = A_k x_k + B_k u_k.
        let mut state = Mat13::identity();
        let x0 = SMatrix::<f64, 13, 1>::from(input.x0);
        for k in 0..n {
            state = self.a_mats[k] * state;
            self.sx[k] = state;
            let row = MPC_STATES * k;
            self.su.view_mut((row, 0), (MPC_STATES, nv)).fill(0.0);
            for (b, &(step, leg)) in self.blocks.iter().enumerate() {
                if step > k {
                    break;
                }
                let block = if step == k {
                    self.b_mats[k][leg]
                } else {
                    let prev = self
                        .su
                        .fixed_view::<13, 3>(row - MPC_STATES, 3 * b)
                        .into_owned();
                    self.a_mats[k] * prev
                };
                self.su
                    .fixed_view_mut::<13, 3>(row, 3 * b)
                    .copy_from(&block);
            }
            let free = state * x0;
            for i in 0..MPC_STATES {
                self.free_response[row + i] = free[i] - input.reference[k][i];
            }
        }
        // P = 2 (S_uᵀ Q̄ S_u + R̄), q = 2 S_uᵀ Q̄ (S_x x₀ − X_ref).
        let rows = MPC_STATES * n;
        for k in 0..n {
            for i in 0..MPC_STATES {
                let w = self.params.q_weights[i];
                let r = MPC_STATES * k + i;
                for c in 0..nv {
                    self.weighted_su[(r, c)] = w * self.su[(r, c)];
                }
            }
        }
        {
            let su = self.su.view((0, 0), (rows, nv));
            let wsu = self.weighted_su.view((0, 0), (rows, nv));
            let mut h = self.hessian.view_mut((0, 0), (nv, nv));
            h.gemm_tr(2.0, &su, &wsu, 0.0);
            for i in 0..nv {
                h[(i, i)] += 2.0 * self.params.r_weight;
            }
            let mut g = self.gradient.rows_mut(0, nv);
            g.gemv_tr(2.0, &wsu, &self.free_response, 0.0);
        }

        // Upper triangle of P, column by column (dense pattern; structural zeros are kept so the
        // pattern only depends on the number of variables).
        self.p_values.clear();
        for c in 0..nv {
            for r in 0..=c {
                self.p_values.push(self.hessian[(r, c)]);
            }
        }
        // A: per stance foot block, 6 rows × 3 columns.
        let normal = Vector3::from(input.terrain_normal).normalize();
        let (t1, t2) = terrain_tangents(&normal);
        let mu = self.params.mu;
        let rows_of_block = [
            t1 - normal * mu,
            -t1 - normal * mu,
            t2 - normal * mu,
            -t2 - normal * mu,
            -normal,
            normal,
        ];
        let nblocks = self.blocks.len();
        let m = ROWS_PER_FOOT * nblocks;
        self.a_values.clear();
        for _ in 0..nblocks {
            for axis in 0..3 {
                for row in &rows_of_block {
                    self.a_values.push(row[axis]);
                }
            }
        }
        self.b_values.clear();
        for _ in 0..nblocks {
            self.b_values.extend_from_slice(&[
                0.0,
                0.0,
                0.0,
                0.0,
                -self.params.f_min,
                self.params.f_max,
            ]);
        }
        let q_values: Vec<f64> = self.gradient.rows(0, nv).iter().copied().collect();

        let key: Vec<u8> = input
            .contacts
            .iter()
            .map(|c| {
                c.iter()
                    .enumerate()
                    .fold(0u8, |acc, (i, &s)| acc | ((s as u8) << i))
            })
            .collect();
        let (p_colptr, p_rowval) = dense_upper_pattern(nv);
        let (a_colptr, a_rowval) = block_pattern(nblocks);
        self.last_qp = QpData {
            n: nv,
            p_dense: self
                .hessian
                .view((0, 0), (nv, nv))
                .iter()
                .copied()
                .collect(),
            q: q_values.clone(),
            m,
            a_colptr: a_colptr.clone(),
            a_rowval: a_rowval.clone(),
            a_nzval: self.a_values.clone(),
            b: self.b_values.clone(),
        };
        let reused = match self.solvers.get_mut(&key) {
            Some(solver) => {
                solver.update_P(&self.p_values).is_ok()
                    && solver.update_q(&q_values).is_ok()
                    && solver.update_A(&self.a_values).is_ok()
                    && solver.update_b(&self.b_values).is_ok()
            }
            None => false,
        };
        if !reused {
            self.solvers.remove(&key);
            if self.solvers.len() >= MAX_CACHED_SOLVERS {
                self.solvers.clear();
            }
            let p = CscMatrix::new(nv, nv, p_colptr, p_rowval, self.p_values.clone());
            let a = CscMatrix::new(m, nv, a_colptr, a_rowval, self.a_values.clone());
            let cones = [SupportedConeT::NonnegativeConeT(m)];
            match DefaultSolver::new(
                &p,
                &q_values,
                &a,
                &self.b_values,
                &cones,
                self.settings.clone(),
            ) {
                Ok(solver) => {
                    self.solvers.insert(key.clone(), solver);
                }
                Err(error) => {
                    tracing::warn!(?error, "MPC QP setup failed");
                    solution.status = MpcStatus::Failed;
                    solution.solve_time_s = start.elapsed().as_secs_f64();
                    return solution;
                }
            }
        }
        let Some(solver) = self.solvers.get_mut(&key) else {
            solution.status = MpcStatus::Failed;
            return solution;
        };
        solver.solve();
        let result = &solver.solution;
        solution.iterations = result.iterations;
        solution.qp_time_s = result.solve_time;
        let ok = matches!(
            result.status,
            SolverStatus::Solved | SolverStatus::AlmostSolved
        ) && result.x.iter().all(|v| v.is_finite());
        if ok {
            for (b, &(step, leg)) in self.blocks.iter().enumerate() {
                if step != 0 {
                    break;
                }
                solution.forces[leg] = [result.x[3 * b], result.x[3 * b + 1], result.x[3 * b + 2]];
            }
            solution.status = MpcStatus::Solved;
        } else {
            tracing::debug!(status = ?result.status, "MPC solve failed");
            solution.status = MpcStatus::Failed;
        }
        solution.solve_time_s = start.elapsed().as_secs_f64();
        solution
    }
}

/// CSC pattern of a dense upper triangle n×n.
fn dense_upper_pattern(n: usize) -> (Vec<usize>, Vec<usize>) {
    let mut colptr = Vec::with_capacity(n + 1);
    let mut rowval = Vec::with_capacity(n * (n + 1) / 2);
    colptr.push(0);
    for c in 0..n {
        rowval.extend(0..=c);
        colptr.push(rowval.len());
    }
    (colptr, rowval)
}

/// CSC pattern of the block-diagonal constraint matrix: block b has rows 6b..6b+5 and columns
/// 3b..3b+2, all entries present.
fn block_pattern(nblocks: usize) -> (Vec<usize>, Vec<usize>) {
    let mut colptr = Vec::with_capacity(3 * nblocks + 1);
    let mut rowval = Vec::with_capacity(18 * nblocks);
    colptr.push(0);
    for b in 0..nblocks {
        for _ in 0..3 {
            rowval.extend(ROWS_PER_FOOT * b..ROWS_PER_FOOT * (b + 1));
            colptr.push(rowval.len());
        }
    }
    (colptr, rowval)
}
