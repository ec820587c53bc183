//! Input validation, the per-contact-schedule cache of Clarabel solvers, and the solve.

use std::collections::HashMap;
use std::time::Instant;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use nalgebra::{Matrix3, Vector3};

use super::model::StageModel;
use super::{
    ConvexMpc, MpcInput, MpcParams, MpcSolution, MpcStatus, MAX_CACHED_SOLVERS, MAX_YAW_STEP, NS,
    ROWS_PER_FOOT,
};
use crate::api::NUM_LEGS;
use crate::math::wrap_angle;

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
            params,
        })
    }

    /// Parameters.
    pub fn params(&self) -> &MpcParams {
        &self.params
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

    /// Sets the friction coefficient of the following solves' pyramids (finite and > 0; else
    /// refused and unchanged).
    pub fn set_friction(&mut self, mu: f64) -> Result<(), String> {
        if !(mu.is_finite() && mu > 0.0) {
            return Err(format!("friction coefficient {mu} must be finite and > 0"));
        }
        self.params.mu = mu;
        Ok(())
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
}
