//! Convex MPC on ground reaction forces (Di Carlo et al., "Dynamic Locomotion in the MIT Cheetah 3
//! Through Convex Model-Predictive Control", 2018), solved as a sparse QP with Clarabel.
//!
//! Model: single rigid body with 13 states
//! `x = [roll, pitch, yaw, p_x, p_y, p_z, ω_x, ω_y, ω_z, v_x, v_y, v_z, g]`
//! (CoM position/velocity and angular velocity in the world frame, `g = 9.81` a constant state so
//! gravity enters linearly). Linearised about the reference yaw ψ_k of each step:
//! `Θ̇ = R_z(ψ_k)ᵀ ω`, `ṗ = v`, `ω̇ = I_w⁻¹ Σ r_i × f_i` with `I_w = R_z I_b R_zᵀ`,
//! `v̇ = Σ f_i / m − g e_z`. The discretisation is exact for this model (A³ = 0, zero-order hold).
//!
//! Decision variables: the ground reaction forces (acting on the robot) of the legs in stance at
//! each step; swing legs are eliminated from the QP, which is the `D_k u = 0`
//! constraint of the paper applied by construction (their forces are exactly zero). Constraints
//! per stance foot: friction pyramid about the terrain normal n with tangents t₁, t₂
//! (`|f·tⱼ| ≤ μ f·n`) and `f_min ≤ f·n ≤ f_max`.
//!
//! Cost: `Σ_k (x_k − x_ref,k)ᵀ Q (x_k − x_ref,k) + Σ_k u_kᵀ R u_k`.
//!
//! Formulation (sparse, not condensed): the predicted states are QP variables next to the
//! forces (the constant g is folded into an offset), and the dynamics are equality constraints.
//! P is then (block-)diagonal and the KKT matrix is banded (stage-wise), so Clarabel's sparse
//! LDL costs O(N) per iteration instead of the O(n_u³) of the dense condensed Hessian (which also
//! made every KKT product O(n_u²)). The optimum is the one of the condensed QP
//! ([`ConvexMpc::last_qp`]), which the tests check. The KKT factorisation and its triangular
//! solves are most of the solve time, so the formulation keeps the KKT small and its factor
//! sparse:
//!
//! - The dynamics rows are written in trapezoidal form,
//!   `(I − dt/2 A_c) x_{k+1} = (I + dt/2 A_c) x_k + dt B_c u_k` (gravity on the right-hand side).
//!   Because A_c³ = 0 and A_c² B_c = 0 this is `(I − dt/2 A_c)` times the exact discretisation
//!   `x_{k+1} = A_k x_k + B_k u_k`, so the feasible set is the same; but the forces only enter the
//!   ω and v rows instead of also Θ and p through the dt²/2 terms, which halves the rows each
//!   force block couples and the fill-in they cause.
//! - The translational states are `a_k = p_k + dt/2 v_k` instead of p_k and v_k: the trapezoidal
//!   p rows say `p_{k+1} − dt/2 v_{k+1} = a_k`, so `p_k = (a_k + a_{k−1})/2` and
//!   `v_k = (a_k − a_{k−1})/dt`, and the p rows and the v variables drop out. The v rows become
//!   second differences of a, and the p and v costs couple consecutive a_k (a tridiagonal block of
//!   P per axis).
//! - The rotational states get the same treatment with the step's own yaw:
//!   `c_k = Θ_k + dt/2 R_kᵀ ω_k` (R_k = R_z(ψ_k), and R_N := R_{N−1} for the last state). The Θ
//!   rows `Θ_{k+1} − dt/2 R_kᵀ ω_{k+1} = c_k` give `ω_{k+1} = N_k (c_{k+1} − c_k)` with
//!   `N_k = (dt/2 (R_k + R_{k+1})ᵀ)⁻¹` (invertible while the reference yaw turns by less than π
//!   per step; [`ConvexMpc::solve`] accepts at most π/2) and
//!   `Θ_{k+1} = (I − G_k) c_k + G_k c_{k+1}` with `G_k = dt/2 R_kᵀ N_k` (½ I when the yaw is
//!   constant). The Θ rows and the Θ and ω variables drop out, the ω rows couple c_{k−1}, c_k
//!   and c_{k+1}, and the Θ and ω costs become 3×3 blocks of P on (c_k, c_{k+1}). N_k and G_k
//!   have the pattern of a yaw rotation (x and y mix, z stays apart), which P and A keep.
//!
//!   Per step that leaves 6 state variables (c, a) and 6 rows (ω, v), against 12 and 12 for
//!   (Θ, p, ω, v): the KKT matrix of a trot has 300 rows and its LDL factor 1 950 nonzeros (360
//!   and 2 146 with a alone), and a trot solve takes about a fifth less time. Both substitutions
//!   are invertible linear changes of variables, so the optimum is the condensed QP's.
//! - The forces are QP variables in the terrain frame (t₁, t₂, n), in units of m·g. The friction
//!   pyramid rows then have two entries and the normal-force bounds one (instead of three each,
//!   whatever the normal); R is isotropic, so the cost is unchanged.
//!
//! The cost is multiplied by a constant (`COST_SCALE`) inside the QP: it does not move the
//! optimum but puts Clarabel's starting point closer to the central path, which saves about one
//! interior-point iteration and lands nearer the exact optimum.
//!
//! Reuse: all work buffers are allocated once; Clarabel solvers are cached per contact schedule
//! over the horizon (which fixes the sparsity of P and A), and later solves with the same
//! schedule only update the numeric values (`update_P/q/A/b`; P changes with the reference yaw
//! through N_k and G_k), skipping symbolic setup.

use std::cell::OnceCell;
use std::collections::HashMap;
use std::time::Instant;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use nalgebra::{DMatrix, DVector, Matrix3, SMatrix, Vector3};

use crate::api::NUM_LEGS;
use crate::model::wrap_angle;

/// Number of MPC states.
pub const MPC_STATES: usize = 13;
/// State variables and dynamics rows of the QP per step: c = Θ + dt/2 R_zᵀ ω and
/// a = p + dt/2 v (variables); ω and v rows (see the module documentation).
const NS: usize = 6;
/// Components of a rotational 3-vector that a yaw rotation mixes with component j: x and y mix,
/// z stays apart. N_k, G_k and hence the c blocks of P and A have this pattern.
const YAW_GROUP: [&[usize]; 3] = [&[0, 1], &[0, 1], &[2]];
/// Largest change of the reference yaw between two MPC steps, rad (N_k is singular at π); a
/// reference turning faster is invalid input.
pub const MAX_YAW_STEP: f64 = std::f64::consts::FRAC_PI_2;
const ROWS_PER_FOOT: usize = 6;
const MAX_CACHED_SOLVERS: usize = 32;
/// Factor on the whole cost inside the QP (the optimum does not change). Clarabel starts by
/// shifting slacks and duals into the cone by at least 1 in absolute terms, so the size of the
/// duals (proportional to the cost) relative to the slacks (forces in m·g) steers the
/// interior-point path. On 300 random trot/stand problems (perturbed states, yaw, slopes) this
/// factor took 4.4 instead of 5.4 iterations on average and moved the step-0 forces closer to the
/// exact optimum (95th percentile 0.10 instead of 0.23 N trotting and 0.35 N standing, worst
/// 0.30 instead of 1.0 N); smaller factors save little more, larger ones are more accurate but
/// need more iterations again.
const COST_SCALE: f64 = 50.0;

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
    /// Time spent inside Clarabel's `solve`, s; the rest of `solve_time_s` is model building and
    /// QP assembly (and, on a new contact schedule, the solver's symbolic setup).
    pub qp_time_s: f64,
    /// Interior-point iterations.
    pub iterations: u32,
    /// Number of decision variables of the QP solved (stance forces and predicted states).
    pub num_variables: usize,
}

/// The last solve's problem as a condensed QP over the stance forces (N):
/// minimise ½ uᵀPu + qᵀu s.t. A u ≤ b. Same optimum as the sparse QP that [`ConvexMpc`] solves;
/// built on demand for comparisons (other solvers, reference checks).
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

/// A copy of the last solve's input, for the on-demand condensed QP.
#[derive(Clone, Debug, Default)]
struct LastInput {
    valid: bool,
    x0: [f64; MPC_STATES],
    reference: Vec<[f64; MPC_STATES]>,
    contacts: Vec<[bool; NUM_LEGS]>,
    foot_offsets: Vec<[[f64; 3]; NUM_LEGS]>,
    terrain_normal: [f64; 3],
}

/// Convex MPC with preallocated buffers and a per-schedule solver cache.
pub struct ConvexMpc {
    params: MpcParams,
    inertia_body: Matrix3<f64>,
    settings: DefaultSettings<f64>,
    /// Force unit inside the QP (m·g), N.
    force_scale: f64,
    /// Per-step matrices of the dynamics rows.
    stages: StageModel,
    /// The Θ and ω costs as blocks on the c variables: `c_diag[j]` on (c_{j+1}, c_{j+1}),
    /// `c_off[j]` on (c_j, c_{j+1}) (unused for j = 0, c_0 is known), `c_linear[j]` the linear
    /// term of c_{j+1}. Scaled like the rest of the cost.
    c_diag: Vec<Matrix3<f64>>,
    c_off: Vec<Matrix3<f64>>,
    c_linear: Vec<Vector3<f64>>,
    /// Columns t₁, t₂, n of the last solve's terrain frame (the QP's force coordinates).
    terrain_frame: Matrix3<f64>,
    /// (step, leg) of each 3-column force block, in column order.
    blocks: Vec<(usize, usize)>,
    p_colptr: Vec<usize>,
    p_rowval: Vec<usize>,
    p_values: Vec<f64>,
    q_values: Vec<f64>,
    a_colptr: Vec<usize>,
    a_rowval: Vec<usize>,
    a_values: Vec<f64>,
    b_values: Vec<f64>,
    key: Vec<u8>,
    solvers: HashMap<Vec<u8>, DefaultSolver<f64>>,
    last_input: LastInput,
    last_qp: OnceCell<QpData>,
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

/// The terrain frame `[t₁ t₂ n]` (columns) of a normal.
fn terrain_frame(normal: [f64; 3]) -> Matrix3<f64> {
    let normal = Vector3::from(normal).normalize();
    let (t1, t2) = terrain_tangents(&normal);
    Matrix3::from_columns(&[t1, t2, normal])
}

/// Rows `a` of the per-foot constraints `a·f ≤ b`: friction pyramid, then −f·n ≤ −f_min and
/// f·n ≤ f_max.
fn foot_constraint_rows(normal: [f64; 3], mu: f64) -> [Vector3<f64>; ROWS_PER_FOOT] {
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

/// The discrete model of every step: A_k about the reference yaw, B_k from the feet.
fn discrete_model(
    params: &MpcParams,
    inertia_body: &Matrix3<f64>,
    input: &MpcInput<'_>,
    a_mats: &mut [Mat13],
    b_mats: &mut [[Mat13x3; NUM_LEGS]],
) {
    let dt = params.dt;
    let inv_mass = 1.0 / params.mass;
    for k in 0..params.horizon {
        let yaw = input.reference[k][2];
        let rz = rot_z(yaw);
        let inertia_world = rz * inertia_body * rz.transpose();
        let inertia_world_inv = inertia_world
            .try_inverse()
            .unwrap_or_else(Matrix3::identity);
        let mut a_c = Mat13::zeros();
        a_c.fixed_view_mut::<3, 3>(0, 6).copy_from(&rz.transpose());
        a_c.fixed_view_mut::<3, 3>(3, 9)
            .copy_from(&Matrix3::identity());
        a_c[(11, 12)] = -1.0;
        let a_c2 = a_c * a_c;
        a_mats[k] = Mat13::identity() + a_c * dt + a_c2 * (dt * dt * 0.5);
        for (b_leg, offset) in b_mats[k].iter_mut().zip(&input.foot_offsets[k]) {
            let r = Vector3::from(*offset);
            let mut b_c = Mat13x3::zeros();
            b_c.fixed_view_mut::<3, 3>(6, 0)
                .copy_from(&(inertia_world_inv * skew(&r)));
            b_c.fixed_view_mut::<3, 3>(9, 0)
                .copy_from(&(Matrix3::identity() * inv_mass));
            *b_leg = b_c * dt + a_c * b_c * (dt * dt * 0.5);
        }
    }
}

/// What the sparse QP's dynamics rows need per step.
#[derive(Clone, Debug)]
struct StageModel {
    /// `R_z(ψ_k)ᵀ`.
    rz_t: Vec<Matrix3<f64>>,
    /// `dt I_w⁻¹ [r]×` of each leg (the angular-velocity rows of B_k).
    b_omega: Vec<[Matrix3<f64>; NUM_LEGS]>,
    /// `N_k = (dt/2 (R_k + R_{k+1})ᵀ)⁻¹`: `ω_{k+1} = N_k (c_{k+1} − c_k)`.
    omega_of_c: Vec<Matrix3<f64>>,
    /// `G_k = dt/2 R_kᵀ N_k`: `Θ_{k+1} = (I − G_k) c_k + G_k c_{k+1}`.
    theta_of_c: Vec<Matrix3<f64>>,
}

impl StageModel {
    fn new(horizon: usize) -> Self {
        StageModel {
            rz_t: vec![Matrix3::zeros(); horizon],
            b_omega: vec![[Matrix3::zeros(); NUM_LEGS]; horizon],
            omega_of_c: vec![Matrix3::zeros(); horizon],
            theta_of_c: vec![Matrix3::zeros(); horizon],
        }
    }

    /// Fill every step's matrices for this input (reference yaw per step, foot offsets).
    fn update(&mut self, params: &MpcParams, inertia_body: &Matrix3<f64>, input: &MpcInput<'_>) {
        let n = params.horizon;
        let half_dt = 0.5 * params.dt;
        for k in 0..n {
            let rz = rot_z(input.reference[k][2]);
            let inertia_world_inv = (rz * inertia_body * rz.transpose())
                .try_inverse()
                .unwrap_or_else(Matrix3::identity);
            self.rz_t[k] = rz.transpose();
            for (b, offset) in self.b_omega[k].iter_mut().zip(&input.foot_offsets[k]) {
                *b = (inertia_world_inv * skew(&Vector3::from(*offset))) * params.dt;
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
        // Tolerances 1e-6 (in the scaled units) as before: the step-0 forces then match the exact
        // optimum closely even on a perturbed standing problem, where the internal force
        // distribution only has the curvature of R (1e-5 allowed ~0.4 N there). Equilibration
        // and iterative refinement are off: the QP is already scaled (forces in m·g, states
        // O(1)); refinement cost ~35 % of the solve time without changing the forces
        // measurably, and equilibration cost iterations.
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .input_sparse_dropzeros(false)
            .equilibrate_enable(false)
            .iterative_refinement_enable(false)
            .max_iter(50)
            .tol_gap_abs(1e-6)
            .tol_gap_rel(1e-6)
            .tol_feas(1e-6)
            .build()
            .map_err(|e| format!("clarabel settings: {e:?}"))?;
        let n = params.horizon;
        let max_vars = 3 * NUM_LEGS * n + NS * n;
        // Per force block: 3 columns × 6 dynamics rows + 10 inequality entries; per state
        // column: ≤ 2 entries in each of three steps.
        let max_a_nnz = NUM_LEGS * n * (18 + 10) + NS * n * 6;
        // P: one entry per force; per c column ≤ 2 of the previous step and ≤ 2 of its own, per
        // a column 2.
        let max_p_nnz = 3 * NUM_LEGS * n + 4 * 3 * n + 2 * 3 * n;
        let max_rows = NS * n + ROWS_PER_FOOT * NUM_LEGS * n;
        Ok(ConvexMpc {
            inertia_body,
            settings,
            force_scale: params.mass * crate::GRAVITY,
            stages: StageModel::new(n),
            c_diag: vec![Matrix3::zeros(); n],
            c_off: vec![Matrix3::zeros(); n],
            c_linear: vec![Vector3::zeros(); n],
            terrain_frame: Matrix3::identity(),
            blocks: Vec::with_capacity(NUM_LEGS * n),
            p_colptr: Vec::with_capacity(max_vars + 1),
            p_rowval: Vec::with_capacity(max_p_nnz),
            p_values: Vec::with_capacity(max_p_nnz),
            q_values: Vec::with_capacity(max_vars),
            a_colptr: Vec::with_capacity(max_vars + 1),
            a_rowval: Vec::with_capacity(max_a_nnz),
            a_values: Vec::with_capacity(max_a_nnz),
            b_values: Vec::with_capacity(max_rows),
            key: Vec::with_capacity(n),
            solvers: HashMap::new(),
            last_input: LastInput {
                valid: false,
                x0: [0.0; MPC_STATES],
                reference: Vec::with_capacity(n),
                contacts: Vec::with_capacity(n),
                foot_offsets: Vec::with_capacity(n),
                terrain_normal: [0.0; 3],
            },
            last_qp: OnceCell::new(),
            params,
        })
    }

    /// Parameters.
    pub fn params(&self) -> &MpcParams {
        &self.params
    }

    /// The last call of [`ConvexMpc::solve`] as a condensed QP over the stance forces (built on
    /// first access; empty when the last input was invalid).
    pub fn last_qp(&self) -> &QpData {
        self.last_qp.get_or_init(|| self.condensed_qp())
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
            && input
                .reference
                .windows(2)
                .all(|pair| wrap_angle(pair[1][2] - pair[0][2]).abs() <= MAX_YAW_STEP)
    }

    fn remember_input(&mut self, input: &MpcInput<'_>, valid: bool) {
        self.last_qp = OnceCell::new();
        let last = &mut self.last_input;
        last.valid = valid;
        last.reference.clear();
        last.contacts.clear();
        last.foot_offsets.clear();
        if valid {
            last.x0 = input.x0;
            last.reference.extend_from_slice(input.reference);
            last.contacts.extend_from_slice(input.contacts);
            last.foot_offsets.extend_from_slice(input.foot_offsets);
            last.terrain_normal = input.terrain_normal;
        }
    }

    /// The Θ and ω costs as blocks on the c variables (`c_diag`, `c_off`, `c_linear`): per step
    /// k, `Θ_{k+1} = E_k [c_k; c_{k+1}]` with `E_k = [I − G_k, G_k]` and
    /// `ω_{k+1} = F_k [c_k; c_{k+1}]` with `F_k = [−N_k, N_k]`, so the cost
    /// `(Θ_{k+1} − Θ_ref)ᵀ Q_Θ (…) + (ω_{k+1} − ω_ref)ᵀ Q_ω (…)` adds `2(EᵀQ_ΘE + FᵀQ_ωF)` to P and
    /// `−2(EᵀQ_Θ Θ_ref + FᵀQ_ω ω_ref)` to q; the known c_0 moves its part into q of c_1.
    fn rotational_cost(&mut self, input: &MpcInput<'_>, c0: &Vector3<f64>) {
        let n = self.params.horizon;
        let w = self.params.q_weights.map(|w| COST_SCALE * w);
        let q_theta = Matrix3::from_diagonal(&Vector3::new(w[0], w[1], w[2]));
        let q_omega = Matrix3::from_diagonal(&Vector3::new(w[6], w[7], w[8]));
        for k in 0..n {
            let g = self.stages.theta_of_c[k];
            let nk = self.stages.omega_of_c[k];
            let keep = Matrix3::identity() - g;
            let omega_part = nk.transpose() * q_omega * nk;
            let h00 = (keep.transpose() * q_theta * keep + omega_part) * 2.0;
            let h01 = (keep.transpose() * q_theta * g - omega_part) * 2.0;
            let h11 = (g.transpose() * q_theta * g + omega_part) * 2.0;
            let reference = &input.reference[k];
            let theta_ref = q_theta * Vector3::new(reference[0], reference[1], reference[2]);
            let omega_ref = q_omega * Vector3::new(reference[6], reference[7], reference[8]);
            let linear_k = (keep.transpose() * theta_ref - nk.transpose() * omega_ref) * -2.0;
            let linear_next = (g.transpose() * theta_ref + nk.transpose() * omega_ref) * -2.0;
            // c_{k+1} is variable j = k; c_k is variable j = k − 1 (known for k = 0).
            self.c_diag[k] = h11;
            self.c_linear[k] = linear_next;
            if k == 0 {
                self.c_linear[0] += h01.transpose() * c0;
            } else {
                self.c_diag[k - 1] += h00;
                self.c_linear[k - 1] += linear_k;
                self.c_off[k] = h01;
            }
        }
    }

    /// Fill the sparse QP (CSC pattern and values of P and A, q, b) for the current model and
    /// `self.blocks`. Variables, stage by stage: the stance forces of step k (terrain frame
    /// t₁, t₂, n, in units of m·g), then c and a of step k + 1. Rows: the ω and v dynamics of
    /// steps 0..N−1 (zero cone), then 6 inequality rows per force block (nonnegative cone).
    fn assemble_sparse(&mut self, input: &MpcInput<'_>) {
        let n = self.params.horizon;
        let dt = self.params.dt;
        let half_dt = 0.5 * dt;
        let scale = self.force_scale;
        let force_to_v = dt / self.params.mass * scale;
        let n_eq = NS * n;
        let frame = terrain_frame(input.terrain_normal);
        self.terrain_frame = frame;
        let mu = self.params.mu;
        let r_diag = 2.0 * COST_SCALE * self.params.r_weight * scale * scale;
        let q_w = self.params.q_weights.map(|w| COST_SCALE * w);
        let x0 = &input.x0;
        let a0 = [0, 1, 2].map(|j| x0[3 + j] + half_dt * x0[9 + j]);
        let omega0 = Vector3::new(x0[6], x0[7], x0[8]);
        let c0 = Vector3::new(x0[0], x0[1], x0[2]) + self.stages.rz_t[0] * omega0 * half_dt;
        self.rotational_cost(input, &c0);
        self.p_colptr.clear();
        self.p_rowval.clear();
        self.p_values.clear();
        self.q_values.clear();
        self.a_colptr.clear();
        self.a_rowval.clear();
        self.a_values.clear();
        self.p_colptr.push(0);
        self.a_colptr.push(0);
        let mut col = 0;
        let mut block = 0;
        let mut prev_c_col = 0;
        let mut prev_a_col = 0;
        for k in 0..n {
            let row0 = NS * k;
            while block < self.blocks.len() && self.blocks[block].0 == k {
                let b_omega = self.stages.b_omega[k][self.blocks[block].1] * frame;
                let ineq0 = n_eq + ROWS_PER_FOOT * block;
                for axis in 0..3 {
                    for i in 0..3 {
                        self.a_rowval.push(row0 + i);
                        self.a_values.push(-b_omega[(i, axis)] * scale);
                    }
                    for i in 0..3 {
                        self.a_rowval.push(row0 + 3 + i);
                        self.a_values.push(-force_to_v * frame[(i, axis)]);
                    }
                    let rows: &[(usize, f64)] = match axis {
                        0 => &[(0, 1.0), (1, -1.0)],
                        1 => &[(2, 1.0), (3, -1.0)],
                        _ => &[(0, -mu), (1, -mu), (2, -mu), (3, -mu), (4, -1.0), (5, 1.0)],
                    };
                    for &(r, value) in rows {
                        self.a_rowval.push(ineq0 + r);
                        self.a_values.push(value);
                    }
                    self.a_colptr.push(self.a_rowval.len());
                    self.p_rowval.push(col);
                    self.p_values.push(r_diag);
                    self.p_colptr.push(self.p_rowval.len());
                    self.q_values.push(0.0);
                    col += 1;
                }
                block += 1;
            }
            // c_{k+1}: ω rows of step k (N_k), k + 1 (−N_k − N_{k+1}) and k + 2 (N_{k+1}).
            let this_c_col = col;
            let omega_of_c = &self.stages.omega_of_c;
            let next = omega_of_c[(k + 1).min(n - 1)];
            let coefficients = [omega_of_c[k], -(omega_of_c[k] + next), next];
            for j in 0..3 {
                for (step, coefficient) in (k..n).zip(&coefficients) {
                    for &i in YAW_GROUP[j] {
                        self.a_rowval.push(NS * step + i);
                        self.a_values.push(coefficient[(i, j)]);
                    }
                }
                self.a_colptr.push(self.a_rowval.len());
                if k > 0 {
                    for &i in YAW_GROUP[j] {
                        self.p_rowval.push(prev_c_col + i);
                        self.p_values.push(self.c_off[k][(i, j)]);
                    }
                }
                for &i in YAW_GROUP[j].iter().filter(|&&i| i <= j) {
                    self.p_rowval.push(this_c_col + i);
                    self.p_values.push(self.c_diag[k][(i, j)]);
                }
                self.p_colptr.push(self.p_rowval.len());
                self.q_values.push(self.c_linear[k][j]);
                col += 1;
            }
            prev_c_col = this_c_col;
            // a_{k+1}: v rows of steps k, k + 1, k + 2 (second difference / dt).
            let this_a_col = col;
            for j in 0..3 {
                for (step, c) in [(k, 1.0), (k + 1, -2.0), (k + 2, 1.0)] {
                    if step < n {
                        self.a_rowval.push(NS * step + 3 + j);
                        self.a_values.push(c / dt);
                    }
                }
                self.a_colptr.push(self.a_rowval.len());
                // Cost of p_s = (a_s + a_{s−1})/2 and v_s = (a_s − a_{s−1})/dt for s = k + 1
                // and s = k + 2.
                let (qp, qv) = (q_w[3 + j], q_w[9 + j]);
                let same = 2.0 * (0.25 * qp + qv / (dt * dt));
                let cross = 2.0 * (0.25 * qp - qv / (dt * dt));
                if k > 0 {
                    self.p_rowval.push(prev_a_col + j);
                    self.p_values.push(cross);
                }
                self.p_rowval.push(col);
                self.p_values
                    .push(if k + 1 < n { 2.0 * same } else { same });
                self.p_colptr.push(self.p_rowval.len());
                let reference = &input.reference[k];
                let (p_ref, v_ref) = (reference[3 + j], reference[9 + j]);
                let mut linear = -qp * p_ref - 2.0 * qv / dt * v_ref;
                if k == 0 {
                    linear += qp * 0.5 * a0[j] - 2.0 * qv / (dt * dt) * a0[j];
                }
                if k + 1 < n {
                    let next = &input.reference[k + 1];
                    linear += -qp * next[3 + j] + 2.0 * qv / dt * next[9 + j];
                }
                self.q_values.push(linear);
                col += 1;
            }
            prev_a_col = this_a_col;
        }
        // b: gravity in the v rows; step 0 gets `ω_0 + N_0 c_0` and `v_0 + a_0/dt`, step 1
        // `−N_0 c_0` and `−a_0/dt` (the known c_0 and a_0 of the differences).
        self.b_values.clear();
        let g = input.x0[MPC_STATES - 1];
        for _ in 0..n {
            self.b_values.extend_from_slice(&[0.0; NS - 1]);
            self.b_values.push(-dt * g);
        }
        let omega_from_c0 = self.stages.omega_of_c[0] * c0;
        for i in 0..3 {
            self.b_values[i] += omega0[i] + omega_from_c0[i];
            self.b_values[3 + i] += x0[9 + i] + a0[i] / dt;
            if n > 1 {
                self.b_values[NS + i] -= omega_from_c0[i];
                self.b_values[NS + 3 + i] -= a0[i] / dt;
            }
        }
        let (f_min, f_max) = (self.params.f_min / scale, self.params.f_max / scale);
        for _ in 0..self.blocks.len() {
            self.b_values
                .extend_from_slice(&[0.0, 0.0, 0.0, 0.0, -f_min, f_max]);
        }
    }

    /// Fill the per-step model, the force blocks (stance legs of each step) and the sparse QP
    /// for a validated input; false when no leg is in stance over the whole horizon (no QP).
    fn build_qp(&mut self, input: &MpcInput<'_>) -> bool {
        self.stages.update(&self.params, &self.inertia_body, input);
        self.blocks.clear();
        for (k, contacts) in input.contacts.iter().enumerate() {
            for (leg, &stance) in contacts.iter().enumerate() {
                if stance {
                    self.blocks.push((k, leg));
                }
            }
        }
        if self.blocks.is_empty() {
            return false;
        }
        self.assemble_sparse(input);
        true
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
        let valid = self.validate(input);
        self.remember_input(input, valid);
        if !valid {
            return solution;
        }
        let n = self.params.horizon;
        if !self.build_qp(input) {
            // Flight over the whole horizon: nothing to optimise, zero forces are the answer.
            solution.status = MpcStatus::Solved;
            solution.solve_time_s = start.elapsed().as_secs_f64();
            return solution;
        }
        let nv = self.q_values.len();
        let m = self.b_values.len();
        solution.num_variables = nv;

        self.key.clear();
        self.key.extend(input.contacts.iter().map(|c| {
            c.iter()
                .enumerate()
                .fold(0u8, |acc, (i, &s)| acc | ((s as u8) << i))
        }));
        // The schedule fixes the sparsity of P and A, so a cached solver only needs new values.
        let reused = match self.solvers.get_mut(self.key.as_slice()) {
            Some(solver) => {
                solver.update_P(&self.p_values).is_ok()
                    && solver.update_q(&self.q_values).is_ok()
                    && solver.update_A(&self.a_values).is_ok()
                    && solver.update_b(&self.b_values).is_ok()
            }
            None => false,
        };
        if !reused {
            self.solvers.remove(self.key.as_slice());
            if self.solvers.len() >= MAX_CACHED_SOLVERS {
                self.solvers.clear();
            }
            let p = CscMatrix::new(
                nv,
                nv,
                self.p_colptr.clone(),
                self.p_rowval.clone(),
                self.p_values.clone(),
            );
            let a = CscMatrix::new(
                m,
                nv,
                self.a_colptr.clone(),
                self.a_rowval.clone(),
                self.a_values.clone(),
            );
            let cones = [
                SupportedConeT::ZeroConeT(NS * n),
                SupportedConeT::NonnegativeConeT(m - NS * n),
            ];
            match DefaultSolver::new(
                &p,
                &self.q_values,
                &a,
                &self.b_values,
                &cones,
                self.settings.clone(),
            ) {
                Ok(solver) => {
                    self.solvers.insert(self.key.clone(), solver);
                }
                Err(error) => {
                    tracing::warn!(?error, "MPC QP setup failed");
                    solution.status = MpcStatus::Failed;
                    solution.solve_time_s = start.elapsed().as_secs_f64();
                    return solution;
                }
            }
        }
        let Some(solver) = self.solvers.get_mut(self.key.as_slice()) else {
            solution.status = MpcStatus::Failed;
            return solution;
        };
        let qp_start = Instant::now();
        solver.solve();
        solution.qp_time_s = qp_start.elapsed().as_secs_f64();
        let result = &solver.solution;
        solution.iterations = result.iterations;
        let ok = matches!(
            result.status,
            SolverStatus::Solved | SolverStatus::AlmostSolved
        ) && result.x.iter().all(|v| v.is_finite());
        if ok {
            // Step 0's force blocks are the first columns.
            for (b, &(step, leg)) in self.blocks.iter().enumerate() {
                if step != 0 {
                    break;
                }
                let f =
                    self.terrain_frame * Vector3::from_column_slice(&result.x[3 * b..3 * b + 3]);
                solution.forces[leg] = (f * self.force_scale).into();
            }
            solution.status = MpcStatus::Solved;
        } else {
            tracing::debug!(status = ?result.status, "MPC solve failed");
            solution.status = MpcStatus::Failed;
        }
        solution.solve_time_s = start.elapsed().as_secs_f64();
        solution
    }

    /// The last input as a condensed QP: states eliminated, `P = 2(S_uᵀ Q̄ S_u + R̄)`,
    /// `q = 2 S_uᵀ Q̄ (S_x x₀ − X_ref)` over the stance forces (N), constraints `A u ≤ b`.
    fn condensed_qp(&self) -> QpData {
        let last = &self.last_input;
        if !last.valid {
            return QpData::default();
        }
        let input = MpcInput {
            x0: last.x0,
            reference: &last.reference,
            contacts: &last.contacts,
            foot_offsets: &last.foot_offsets,
            terrain_normal: last.terrain_normal,
        };
        let n = self.params.horizon;
        let mut a_mats = vec![Mat13::zeros(); n];
        let mut b_mats = vec![[Mat13x3::zeros(); NUM_LEGS]; n];
        discrete_model(
            &self.params,
            &self.inertia_body,
            &input,
            &mut a_mats,
            &mut b_mats,
        );
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
            let w = self.params.q_weights[r % MPC_STATES];
            weighted_su.row_mut(r).scale_mut(w);
        }
        let mut hessian = su.tr_mul(&weighted_su) * 2.0;
        for i in 0..nv {
            hessian[(i, i)] += 2.0 * self.params.r_weight;
        }
        let gradient = weighted_su.tr_mul(&free_response) * 2.0;

        let rows_of_block = foot_constraint_rows(input.terrain_normal, self.params.mu);
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
            .flat_map(|_| [0.0, 0.0, 0.0, 0.0, -self.params.f_min, self.params.f_max])
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
}

#[cfg(test)]
mod tests {
    use super::*;

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
            discrete_model(params, &mpc.inertia_body, &input, &mut a_mats, &mut b_mats);
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
                // c_{k+1} uses R_{k+1}, and R_N := R_{N−1} for the last step.
                let rz_t = mpc.stages.rz_t[(k + 1).min(2)];
                let c = Vector3::new(x[0], x[1], x[2])
                    + rz_t * Vector3::new(x[6], x[7], x[8]) * (0.5 * params.dt);
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
}
