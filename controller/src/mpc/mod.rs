//! Convex MPC on ground reaction forces (Di Carlo et al., "Dynamic Locomotion in the MIT Cheetah 3
//! Through Convex Model-Predictive Control", 2018), solved as a sparse QP with Clarabel.
//!
//! Model: single rigid body with 13 states
//! `x = [roll, pitch, yaw, p_x, p_y, p_z, ω_x, ω_y, ω_z, v_x, v_y, v_z, g]`
//! (CoM position/velocity and angular velocity in the world frame, `g = 9.81` a constant state so
//! gravity enters linearly). Linearised about the reference attitude (φ_k, θ_k, ψ_k) of each step:
//! `Θ̇ = T_k ω` with `T_k = T(θ_k, ψ_k)` the ZYX Euler-rate map (`R_z(ψ_k)ᵀ` at θ = 0, the
//! paper's map, which assumes a level body), `ṗ = v`, `ω̇ = I_w⁻¹ Σ r_i × f_i` with
//! `I_w = R_k I_b R_kᵀ` and `R_k` the reference rotation (roll and pitch included: on a slope
//! the body is pitched with the ground, and the yaw-only model destabilised the stand there),
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
//! made every KKT product O(n_u²)). The optimum is the one of the condensed QP (the test oracle
//! in `tests/support/mpc_oracle.rs`), which the tests check. The KKT factorisation and its triangular
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
//! - The rotational states get the same treatment with the step's own rate map:
//!   `c_k = Θ_k + dt/2 T_k ω_k` (T_N := T_{N−1} for the last state). The Θ
//!   rows `Θ_{k+1} − dt/2 T_k ω_{k+1} = c_k` give `ω_{k+1} = N_k (c_{k+1} − c_k)` with
//!   `N_k = (dt/2 (T_k + T_{k+1}))⁻¹` (invertible while the reference yaw turns by less than π
//!   per step; [`ConvexMpc::solve`] accepts at most π/2) and
//!   `Θ_{k+1} = (I − G_k) c_k + G_k c_{k+1}` with `G_k = dt/2 T_k N_k` (½ I when the attitude is
//!   constant). The Θ rows and the Θ and ω variables drop out, the ω rows couple c_{k−1}, c_k
//!   and c_{k+1}, and the Θ and ω costs become 3×3 blocks of P on (c_k, c_{k+1}). N_k and G_k
//!   have the pattern of T (x and y mix, the z row takes all three, nothing above the z entry),
//!   which the c columns of A keep; the cost blocks of P are full.
//!
//!   Per step that leaves 6 state variables (c, a) and 6 rows (ω, v), against 12 and 12 for
//!   (Θ, p, ω, v): the KKT matrix of a trot has 300 rows; its LDL factor had 1 950 nonzeros (360
//!   and 2 146 with a alone) with the yaw-only model, whose c blocks were sparser, and a trot
//!   solve took about a fifth less time. Both substitutions
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
//! schedule only update the numeric values (`update_P/q/A/b`; P changes with the reference
//! attitude).
//!
//! Layout: [`model`] holds the per-step matrices of the dynamics rows and the terrain frame,
//! `qp` assembles the sparse QP, `solver` validates input, caches Clarabel solvers per contact
//! schedule and solves.

mod model;
mod qp;
mod solver;
#[cfg(test)]
mod tests;

use std::collections::HashMap;

use clarabel::solver::{DefaultSettings, DefaultSolver};
use nalgebra::{Matrix3, Vector3};

use crate::api::NUM_LEGS;
use crate::config::ControllerConfig;
pub use model::terrain_tangents;
use model::StageModel;

/// Number of MPC states.
pub const MPC_STATES: usize = 13;
/// State variables and dynamics rows of the QP per step: c = Θ + dt/2 T ω and
/// a = p + dt/2 v (variables); ω and v rows (see the module documentation).
const NS: usize = 6;
/// Rows of column j that N_k (like the Euler-rate map T_k) can fill: x and y mix, and the z row
/// takes all three; column z has its z entry only. The c columns of A have this pattern.
const RATE_ROWS: [&[usize]; 3] = [&[0, 1, 2], &[0, 1, 2], &[2]];
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

impl MpcParams {
    /// The MPC of a controller configuration for a robot of `mass` kg with body-frame inertia
    /// `inertia_body` (about its centre of mass), at the configuration's horizon.
    pub fn from_config(
        config: &ControllerConfig,
        mass: f64,
        inertia_body: [[f64; 3]; 3],
    ) -> MpcParams {
        MpcParams {
            horizon: config.mpc_horizon,
            dt: config.mpc_dt,
            mass,
            inertia_body,
            q_weights: config.mpc_q,
            r_weight: config.mpc_r,
            mu: config.mu,
            f_min: config.f_min,
            f_max: config.f_max,
        }
    }
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
}
