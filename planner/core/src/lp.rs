//! The P-F linear program in coefficient space, solved with Clarabel.
//!
//! Rows and variables are the active basis functions outside the target set (mass that reaches
//! the target leaves the system):
//! - variables: r ≥ 0 (density), zₖ ≥ 0 for each direction k (flux along dₖ);
//! - minimise `Bᵀr + Σₖ Bᵀzₖ` with `Bᵢ = ∫ p φᵢ dx`;
//! - subject to `−Σₖ Lₖ zₖ = t` (mass balance, t = start density coefficients) and
//!   `Σₖ zₖ ≤ u_max · r` (speed bound, element-wise).
//!
//! Hard obstacles are enforced by the basis: no active function carries mass into an obstacle
//! (see [`crate::basis`]), and flux towards an obstacle has a wall column in Lₖ.
//!
//! For the solver the problem is scaled to unit magnitude (the note measured a 1.7e-4 error
//! without scaling): lengths in cells, the right-hand side by its largest entry, the cost by its
//! largest entry; r is scaled by u_max so that the speed rows read `Σ ẑ − r̂ ≤ 0`. `r ≥ 0` needs
//! no row of its own (it follows from the speed bound), and fluxes whose generator column is
//! empty (walls) are dropped: they move nothing and only cost.

use std::time::Instant;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use tracing::{debug, warn};

use crate::error::PlanError;
use crate::generators::Generators;

/// Solver settings of the LP.
#[derive(Debug, Clone, PartialEq)]
pub struct LpSettings {
    /// Clarabel's absolute/relative gap and feasibility tolerances (scaled problem).
    pub tolerance: f64,
    /// Interior-point iteration limit.
    pub max_iterations: u32,
    /// Wall-clock limit in seconds (`f64::INFINITY` for none).
    pub time_limit_s: f64,
    /// Print Clarabel's iteration log.
    pub verbose: bool,
}

impl Default for LpSettings {
    fn default() -> Self {
        Self {
            tolerance: 1e-9,
            max_iterations: 200,
            time_limit_s: f64::INFINITY,
            verbose: false,
        }
    }
}

/// What the solver reports about one LP solve.
#[derive(Debug, Clone, PartialEq)]
pub struct LpReport {
    /// Clarabel's status (`Solved`, `AlmostSolved`, …).
    pub status: String,
    /// Optimal value of the (unscaled) objective `Bᵀr + Σ Bᵀzₖ`.
    pub objective: f64,
    /// Clarabel's primal residual (scaled problem).
    pub primal_residual: f64,
    /// Clarabel's dual residual (scaled problem).
    pub dual_residual: f64,
    /// Largest violation of the mass balance, relative to the largest start coefficient (unscaled).
    pub mass_balance_residual: f64,
    /// Interior-point iterations.
    pub iterations: u32,
    /// Wall-clock time of the LP (assembly and solve), seconds.
    pub solve_time_s: f64,
    /// Time spent building the generators (filled in by the pipeline), seconds.
    pub generator_time_s: f64,
    /// LP variables.
    pub variables: usize,
    /// LP constraint rows (equalities and inequalities).
    pub constraints: usize,
}

/// The optimal density and fluxes, per active basis function (zero on the targets).
#[derive(Debug, Clone)]
pub struct LpSolution {
    /// Density coefficients r.
    pub density: Vec<f64>,
    /// Flux coefficients zₖ, one vector per direction.
    pub flux: Vec<Vec<f64>>,
    /// Solver report.
    pub report: LpReport,
}

/// Inputs of one LP, all indexed by active basis function.
#[derive(Debug, Clone, Copy)]
pub struct LpProblem<'a> {
    /// Generators and basis.
    pub generators: &'a Generators,
    /// Bᵢ = ∫ p φᵢ, all > 0.
    pub cost: &'a [f64],
    /// Start density coefficients t ≥ 0 (entries on targets are ignored).
    pub start: &'a [f64],
    /// Whether each basis function belongs to the (absorbing) target set.
    pub target: &'a [bool],
    /// Speed bound, > 0.
    pub u_max: f64,
}

fn invalid(name: &'static str, reason: String) -> PlanError {
    PlanError::InvalidOption { name, reason }
}

impl LpProblem<'_> {
    fn validate(&self) -> Result<(), PlanError> {
        let n = self.generators.basis.len();
        for (name, len) in [
            ("lp cost", self.cost.len()),
            ("lp start", self.start.len()),
            ("lp target", self.target.len()),
        ] {
            if len != n {
                return Err(invalid(
                    name,
                    format!("{len} entries, expected {n} (one per basis function)"),
                ));
            }
        }
        if !(self.u_max.is_finite() && self.u_max > 0.0) {
            return Err(invalid(
                "u_max",
                format!("{} must be finite and > 0", self.u_max),
            ));
        }
        if let Some(i) = self.cost.iter().position(|&b| !(b.is_finite() && b > 0.0)) {
            return Err(invalid(
                "lp cost",
                format!("entry {i} is {}, expected > 0", self.cost[i]),
            ));
        }
        if let Some(i) = self
            .start
            .iter()
            .position(|&t| !(t.is_finite() && t >= 0.0))
        {
            return Err(invalid(
                "lp start",
                format!("entry {i} is {}, expected ≥ 0", self.start[i]),
            ));
        }
        if !self.target.iter().any(|&t| t) {
            return Err(invalid(
                "goal",
                "the target set contains no basis function".into(),
            ));
        }
        Ok(())
    }
}

/// Solves the LP; an infeasible program (mass that cannot reach the target) is [`PlanError::Infeasible`].
pub fn solve(problem: &LpProblem<'_>, settings: &LpSettings) -> Result<LpSolution, PlanError> {
    problem.validate()?;
    let started = Instant::now();
    let gens = problem.generators;
    let n = gens.basis.len();
    let k_count = gens.directions.len();
    // Reduced index of every non-target function.
    let mut reduced = vec![usize::MAX; n];
    let mut kept = Vec::new();
    for (i, (slot, &is_target)) in reduced.iter_mut().zip(problem.target).enumerate() {
        if !is_target {
            *slot = kept.len();
            kept.push(i);
        }
    }
    let m = kept.len();
    let t_max = kept
        .iter()
        .map(|&i| problem.start[i])
        .fold(0.0f64, f64::max);
    if m == 0 || t_max == 0.0 {
        // Everything already sits in the target: the empty flow is optimal.
        return Ok(LpSolution {
            density: vec![0.0; n],
            flux: vec![vec![0.0; n]; k_count],
            report: LpReport {
                status: "Trivial".into(),
                objective: 0.0,
                primal_residual: 0.0,
                dual_residual: 0.0,
                mass_balance_residual: 0.0,
                iterations: 0,
                solve_time_s: started.elapsed().as_secs_f64(),
                generator_time_s: gens.stats.build_time_s,
                variables: 0,
                constraints: 0,
            },
        });
    }
    let h = gens.basis.cell_size();
    let b_max = kept.iter().map(|&i| problem.cost[i]).fold(0.0f64, f64::max);
    // z = (h τ) ẑ, r = (h τ / u_max) r̂, objective = (h τ β) ĉᵀx̂.
    let z_scale = h * t_max;
    let r_scale = z_scale / problem.u_max;
    let obj_scale = z_scale * b_max;

    // Variables: r̂ (m), then the non-wall fluxes (direction, function).
    let mut flux_vars: Vec<(usize, usize)> = Vec::new();
    for (k, l) in gens.generators.iter().enumerate() {
        for &i in &kept {
            if l.column(i).any(|(j, v)| j == i && v != 0.0) {
                flux_vars.push((k, i));
            }
        }
    }
    let n_vars = m + flux_vars.len();
    // Rows: m equalities, m speed rows, one non-negativity row per flux.
    let eq_rows = m;
    let speed_row0 = m;
    let nonneg_row0 = 2 * m;
    let n_rows = 2 * m + flux_vars.len();

    let mut q = Vec::with_capacity(n_vars);
    let mut col_ptr = Vec::with_capacity(n_vars + 1);
    let mut row_idx = Vec::new();
    let mut values = Vec::new();
    col_ptr.push(0);
    for (ri, &i) in kept.iter().enumerate() {
        q.push(problem.cost[i] / (b_max * problem.u_max));
        row_idx.push(speed_row0 + ri);
        values.push(-1.0);
        col_ptr.push(row_idx.len());
    }
    let mut column: Vec<(usize, f64)> = Vec::new();
    for (v, &(k, i)) in flux_vars.iter().enumerate() {
        q.push(problem.cost[i] / b_max);
        column.clear();
        for (j, value) in gens.generators[k].column(i) {
            if reduced[j] != usize::MAX {
                column.push((reduced[j], -h * value));
            }
        }
        column.sort_unstable_by_key(|e| e.0);
        for &(row, value) in &column {
            row_idx.push(row);
            values.push(value);
        }
        row_idx.push(speed_row0 + reduced[i]);
        values.push(1.0);
        row_idx.push(nonneg_row0 + v);
        values.push(-1.0);
        col_ptr.push(row_idx.len());
    }
    let a = CscMatrix::new(n_rows, n_vars, col_ptr, row_idx, values);
    let p = CscMatrix::<f64>::zeros((n_vars, n_vars));
    let mut b = vec![0.0; n_rows];
    for (ri, &i) in kept.iter().enumerate() {
        b[ri] = problem.start[i] / t_max;
    }
    let cones = [
        SupportedConeT::ZeroConeT(eq_rows),
        SupportedConeT::NonnegativeConeT(n_rows - eq_rows),
    ];
    let tol = settings.tolerance;
    let clarabel_settings = DefaultSettingsBuilder::default()
        .verbose(settings.verbose)
        .max_iter(settings.max_iterations)
        .time_limit(settings.time_limit_s)
        .tol_gap_abs(tol)
        .tol_gap_rel(tol)
        .tol_feas(tol)
        .tol_infeas_abs(tol)
        .tol_infeas_rel(tol)
        .direct_solve_method("faer".to_owned())
        .build()
        .map_err(|e| invalid("lp settings", e.to_string()))?;
    let mut solver =
        DefaultSolver::new(&p, &q, &a, &b, &cones, clarabel_settings).map_err(|e| {
            PlanError::LpFailed {
                status: "SetupFailed".into(),
                reason: e.to_string(),
            }
        })?;
    solver.solve();
    let sol = &solver.solution;
    let status = format!("{:?}", sol.status);
    match sol.status {
        SolverStatus::Solved => {}
        SolverStatus::AlmostSolved => warn!(status, "P-F LP solved to reduced accuracy"),
        SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
            return Err(PlanError::Infeasible {
                reason: "no flow carries the start density into the goal region without entering an obstacle or leaving the map (the goal is walled off)".into(),
            })
        }
        _ => {
            return Err(PlanError::LpFailed {
                status,
                reason: format!(
                    "after {} iterations (primal residual {:.2e}, dual residual {:.2e})",
                    sol.iterations, sol.r_prim, sol.r_dual
                ),
            })
        }
    }

    let mut density = vec![0.0; n];
    for (ri, &i) in kept.iter().enumerate() {
        density[i] = sol.x[ri].max(0.0) * r_scale;
    }
    let mut flux = vec![vec![0.0; n]; k_count];
    for (v, &(k, i)) in flux_vars.iter().enumerate() {
        flux[k][i] = sol.x[m + v].max(0.0) * z_scale;
    }
    // Mass balance residual in the original units, relative to the largest start coefficient.
    let mut balance = vec![0.0; n];
    for (k, l) in gens.generators.iter().enumerate() {
        for (i, &z) in flux[k].iter().enumerate() {
            if z != 0.0 {
                for (j, value) in l.column(i) {
                    balance[j] -= value * z;
                }
            }
        }
    }
    let mass_balance_residual = kept
        .iter()
        .map(|&i| (balance[i] - problem.start[i]).abs())
        .fold(0.0f64, f64::max)
        / t_max;
    let report = LpReport {
        status,
        objective: sol.obj_val * obj_scale,
        primal_residual: sol.r_prim,
        dual_residual: sol.r_dual,
        mass_balance_residual,
        iterations: sol.iterations,
        solve_time_s: started.elapsed().as_secs_f64(),
        generator_time_s: gens.stats.build_time_s,
        variables: n_vars,
        constraints: n_rows,
    };
    debug!(?report, "P-F LP solved");
    Ok(LpSolution {
        density,
        flux,
        report,
    })
}
