//! The P-F linear program in coefficient space, solved exactly by the SSP solver
//! ([`crate::ssp`], the default) or with Clarabel ([`LpSolver::Clarabel`], the cross-check and the
//! fallback for generators that are not Markov). Every solution carries a duality certificate
//! ([`crate::certificate`]).
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
//! ## What is handed to the solver (and why it is the same optimum)
//! 1. **r is eliminated.** r enters only the cost, with weights Bᵢ > 0, and the speed bound
//!    `Σₖ zₖᵢ ≤ u_max rᵢ`. For any feasible (r, z), `rᵢ ≥ Σₖ zₖᵢ / u_max`, so the cost is at least
//!    `(1 + 1/u_max) Σᵢ Bᵢ Σₖ zₖᵢ`, with equality for `rᵢ = Σₖ zₖᵢ / u_max` (which is feasible,
//!    ≥ 0). Hence the original LP and the flux-only LP `min (1 + 1/u_max) Bᵀ Σₖ zₖ` s.t.
//!    `−Σₖ Lₖ zₖ = t`, `z ≥ 0` have the same optimal value, and (Σₖ z*ₖ / u_max, z*) is optimal
//!    for the original: the m speed rows and the m density variables disappear.
//! 2. **Walls are dropped.** A flux whose generator column is empty moves nothing and only costs,
//!    so it is zero at every optimum.
//! 3. **The dual is solved** (default, [`LpForm::Dual`]): `max tᵀy` s.t. `(−Σ Lₖᵀ y)ₖᵢ ≤ cᵢ`
//!    for each flux variable. Clarabel is a primal-dual interior-point method, so it returns the
//!    optimal fluxes as the multipliers of these inequalities, and its stopping rule bounds both
//!    the duality gap and the mass-balance residual. The KKT system has m + (number of fluxes)
//!    rows instead of m + 2·(number of fluxes) for the primal with `z ≥ 0` rows; the
//!    factorisation of its Schur complement is the same 2-D stencil as a grid Laplacian. (128²
//!    cells, 8 directions: 30 s → 2.2 s on two loaded cores.)
//!
//! For the solver the problem is scaled to unit magnitude (the note measured a 1.7e-4 error
//! without scaling): lengths in cells, the right-hand side by its largest entry, the cost by its
//! largest entry. The reported objective is the original one, `Bᵀr + Σ Bᵀzₖ`, evaluated at the
//! returned solution.

use std::fmt;
use std::str::FromStr;
use std::time::Instant;

use clarabel::algebra::{BlockConcatenate, CscMatrix, MatrixMathMut};
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use tracing::{debug, info, warn};

use crate::certificate::{certify, Certificate};
use crate::deadline::Deadline;
use crate::error::PlanError;
use crate::generators::SparseColumns;
use crate::lp_problem::invalid;
pub use crate::lp_problem::LpProblem;
pub use crate::solve_status::{LpStatus, SolverUsed};
use crate::ssp;

/// Which solver handles the LP.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum LpSolver {
    /// The exact SSP solver (Dijkstra or policy iteration, [`crate::ssp`]); falls back to Clarabel
    /// when the generators are not Markov.
    #[default]
    Exact,
    /// Clarabel's interior-point method on the reduced LP.
    Clarabel,
}

impl LpSolver {
    /// Name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            LpSolver::Exact => "exact",
            LpSolver::Clarabel => "clarabel",
        }
    }
}

impl fmt::Display for LpSolver {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for LpSolver {
    type Err = PlanError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "exact" => Ok(LpSolver::Exact),
            "clarabel" => Ok(LpSolver::Clarabel),
            other => Err(PlanError::InvalidOption {
                name: "solver",
                reason: format!("unknown LP solver {other:?}; use exact or clarabel"),
            }),
        }
    }
}

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
    /// Threads of the sparse factorisation (0: all available).
    pub max_threads: u32,
    /// Which of the two equivalent programs Clarabel solves.
    pub form: LpForm,
    /// Which solver runs.
    pub solver: LpSolver,
}

impl Default for LpSettings {
    fn default() -> Self {
        Self {
            tolerance: 1e-9,
            max_iterations: 200,
            time_limit_s: f64::INFINITY,
            verbose: false,
            max_threads: 0,
            form: LpForm::default(),
            solver: LpSolver::default(),
        }
    }
}

/// What the solver reports about one LP solve.
#[derive(Debug, Clone, PartialEq)]
pub struct LpReport {
    /// How the solve ended: `Trivial`, `Solved`, `AlmostSolved` (Clarabel) or `Uncertified`.
    pub status: LpStatus,
    /// The method that produced the solution.
    pub solver: SolverUsed,
    /// Duality certificate of the returned primal-dual pair, checked in the original units.
    pub certificate: Certificate,
    /// Optimal value of the (unscaled) objective `Bᵀr + Σ Bᵀzₖ`.
    pub objective: f64,
    /// The solver's own primal residual (Clarabel: scaled problem; exact: the certificate's).
    pub primal_residual: f64,
    /// The solver's own dual residual (Clarabel: scaled problem; exact: the certificate's).
    pub dual_residual: f64,
    /// Largest violation of the mass balance, relative to the largest start coefficient (unscaled).
    pub mass_balance_residual: f64,
    /// Interior-point iterations (Clarabel) or policy evaluations (policy iteration).
    pub iterations: u32,
    /// Wall-clock time of the LP (assembly and solve), seconds.
    pub solve_time_s: f64,
    /// Time spent building the generators (filled in by the pipeline), seconds.
    pub generator_time_s: f64,
    /// Variables of the program handed to Clarabel (dual form: one potential per non-target
    /// function; primal form: one per flux).
    pub variables: usize,
    /// Constraint rows of the program handed to Clarabel (dual form: one inequality per flux;
    /// primal form: mass balance plus flux non-negativity).
    pub constraints: usize,
}

/// The optimal density and fluxes, per active basis function (zero on the targets).
#[derive(Debug, Clone)]
pub struct LpSolution {
    /// Density coefficients r.
    pub density: Vec<f64>,
    /// Flux coefficients zₖ, one vector per direction.
    pub flux: Vec<Vec<f64>>,
    /// Optimal dual: the cost-to-go V per active function (0 on targets, `+∞` where the target
    /// cannot be reached), in the LP's units (c·∫p ds per unit mass, c = 1 + 1/u_max).
    pub potential: Vec<f64>,
    /// Solver report.
    pub report: LpReport,
}

/// Which equivalent program is handed to Clarabel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LpForm {
    /// The reduced primal: fluxes z ≥ 0, `min ĉᵀz` s.t. `−Σₖ Lₖ zₖ = t`.
    Primal,
    /// Its dual: potentials y, `max tᵀy` s.t. `(−Lₖᵀ y)ᵢ ≤ ĉᵢ` for every flux; the fluxes are the
    /// multipliers of these inequalities. Half the KKT system of the primal.
    #[default]
    Dual,
}

/// The reduced LP in the solver's units: one column of the mass-balance matrix per flux.
struct Reduced {
    /// Reduced row of every active function (`usize::MAX` on targets).
    kept: Vec<usize>,
    /// (direction, function) of every flux variable.
    flux_vars: Vec<(usize, usize)>,
    /// Mass-balance matrix `−h Lₖ` restricted to non-target rows, one column per flux.
    balance: CscMatrix<f64>,
    /// Scaled cost of each flux (`(1 + 1/u_max) Bᵢ / max B`).
    cost: Vec<f64>,
    /// Scaled right-hand side `t / max t`.
    rhs: Vec<f64>,
}

/// Builds the reduced program. The density is eliminated analytically: r appears only in the cost
/// `Bᵀr` (B > 0) and in the speed bound `Σₖ zₖ ≤ u_max r`, so every optimum has
/// `r = Σₖ zₖ / u_max` and the cost becomes `(1 + 1/u_max) Bᵀ Σₖ zₖ` (see the module docs).
fn reduce(problem: &LpProblem<'_>, reduced_of: &[usize], kept: Vec<usize>, t_max: f64) -> Reduced {
    let gens = problem.generators;
    let h = gens.basis.cell_size();
    let b_max = kept.iter().map(|&i| problem.cost[i]).fold(0.0f64, f64::max);
    let mut flux_vars = Vec::new();
    let mut col_ptr = vec![0];
    let mut row_idx = Vec::new();
    let mut values = Vec::new();
    let mut cost = Vec::new();
    let mut column: Vec<(usize, f64)> = Vec::new();
    for (k, l) in gens.generators.iter().enumerate() {
        for &i in &kept {
            // A wall (empty column) moves nothing and only costs: always zero, dropped.
            if !l.column(i).any(|(j, v)| j == i && v != 0.0) {
                continue;
            }
            column.clear();
            for (j, value) in l.column(i) {
                if reduced_of[j] != usize::MAX {
                    column.push((reduced_of[j], -h * value));
                }
            }
            column.sort_unstable_by_key(|e| e.0);
            for &(row, value) in &column {
                row_idx.push(row);
                values.push(value);
            }
            col_ptr.push(row_idx.len());
            flux_vars.push((k, i));
            cost.push(problem.cost[i] / b_max);
        }
    }
    let rhs = kept.iter().map(|&i| problem.start[i] / t_max).collect();
    let balance = CscMatrix::new(kept.len(), flux_vars.len(), col_ptr, row_idx, values);
    Reduced {
        kept,
        flux_vars,
        balance,
        cost,
        rhs,
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
    let mut reduced_of = vec![usize::MAX; n];
    let mut kept = Vec::new();
    for (i, (slot, &is_target)) in reduced_of.iter_mut().zip(problem.target).enumerate() {
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
            potential: vec![0.0; n],
            report: LpReport {
                status: LpStatus::Trivial,
                solver: SolverUsed::None,
                certificate: Certificate::trivial(),
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
    let deadline = Deadline::after(started, settings.time_limit_s);
    if settings.solver == LpSolver::Exact {
        if let Some(exact) = ssp::solve(problem, deadline)? {
            let density: Vec<f64> = (0..n)
                .map(|i| exact.flux.iter().map(|z| z[i]).sum::<f64>() / problem.u_max)
                .collect();
            let solved_s = started.elapsed().as_secs_f64();
            let certificate = certify(problem, &exact.flux, &exact.potential);
            debug!(
                solved_s,
                certified_s = started.elapsed().as_secs_f64(),
                "exact LP phases"
            );
            let report = LpReport {
                status: if certificate.holds() {
                    LpStatus::Solved
                } else {
                    LpStatus::Uncertified
                },
                solver: exact.method,
                certificate,
                objective: certificate.primal_objective,
                primal_residual: certificate.primal_residual,
                dual_residual: certificate.dual_residual,
                mass_balance_residual: certificate.primal_residual,
                iterations: exact.iterations,
                solve_time_s: started.elapsed().as_secs_f64(),
                generator_time_s: gens.stats.build_time_s,
                variables: n * k_count,
                constraints: m,
            };
            if !certificate.holds() {
                warn!(
                    ?certificate,
                    "exact P-F solution failed its duality certificate"
                );
            }
            debug!(?report, "P-F LP solved exactly");
            return Ok(LpSolution {
                density,
                flux: exact.flux,
                potential: exact.potential,
                report,
            });
        }
        info!("generators are not Markov (e.g. ANSDMD): solving the LP with Clarabel");
    }
    let h = gens.basis.cell_size();
    let b_max = kept.iter().map(|&i| problem.cost[i]).fold(0.0f64, f64::max);
    // z = (h τ) ẑ; objective = (1 + 1/u_max) (h τ β) ĉᵀẑ.
    let z_scale = h * t_max;
    let obj_scale = z_scale * b_max * (1.0 + 1.0 / problem.u_max);
    let red = reduce(problem, &reduced_of, kept, t_max);
    let n_flux = red.flux_vars.len();

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
        .max_threads(settings.max_threads)
        .direct_solve_method("faer".to_owned())
        .build()
        .map_err(|e| invalid("lp settings", e.to_string()))?;
    let setup_failed = |e: clarabel::solver::SolverError| PlanError::LpFailed {
        status: LpStatus::SetupFailed,
        reason: e.to_string(),
    };
    let (mut solver, variables, constraints) = match settings.form {
        LpForm::Primal => {
            // Variables ẑ; rows: m equalities, then ẑ ≥ 0 as −ẑ + s = 0, s ≥ 0.
            let mut nonnegative = CscMatrix::<f64>::identity(n_flux);
            nonnegative.negate();
            let a = CscMatrix::vcat(&red.balance, &nonnegative)
                .map_err(|e| invalid("lp assembly", e.to_string()))?;
            let p = CscMatrix::<f64>::zeros((n_flux, n_flux));
            let mut b = red.rhs.clone();
            b.resize(m + n_flux, 0.0);
            let cones = [
                SupportedConeT::ZeroConeT(m),
                SupportedConeT::NonnegativeConeT(n_flux),
            ];
            let solver = DefaultSolver::new(&p, &red.cost, &a, &b, &cones, clarabel_settings)
                .map_err(setup_failed)?;
            (solver, n_flux, m + n_flux)
        }
        LpForm::Dual => {
            // Variables ŷ (m, free); rows: Aᵀŷ + s = ĉ, s ≥ 0; minimise −t̂ᵀŷ.
            let a = CscMatrix::from(red.balance.t());
            let p = CscMatrix::<f64>::zeros((m, m));
            let q: Vec<f64> = red.rhs.iter().map(|&t| -t).collect();
            let cones = [SupportedConeT::NonnegativeConeT(n_flux)];
            let solver = DefaultSolver::new(&p, &q, &a, &red.cost, &cones, clarabel_settings)
                .map_err(setup_failed)?;
            (solver, m, n_flux)
        }
    };
    solver.solve();
    let sol = &solver.solution;
    // In the dual form Clarabel's infeasibility certificates swap roles.
    let status = match (settings.form, sol.status) {
        (LpForm::Dual, SolverStatus::DualInfeasible) => SolverStatus::PrimalInfeasible,
        (LpForm::Dual, SolverStatus::AlmostDualInfeasible) => SolverStatus::AlmostPrimalInfeasible,
        (LpForm::Dual, SolverStatus::PrimalInfeasible) => SolverStatus::DualInfeasible,
        (LpForm::Dual, SolverStatus::AlmostPrimalInfeasible) => SolverStatus::AlmostDualInfeasible,
        (_, s) => s,
    };
    let lp_status = LpStatus::from(status);
    match status {
        SolverStatus::Solved => {}
        SolverStatus::AlmostSolved => warn!(status = %lp_status, "P-F LP solved to reduced accuracy"),
        SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
            return Err(PlanError::Infeasible {
                reason: "no flow carries the start density into the goal region without entering an obstacle or leaving the map (the goal is walled off)".into(),
            })
        }
        SolverStatus::MaxTime => {
            return Err(PlanError::TimeLimit {
                phase: "the LP solve (Clarabel)",
                limit_s: settings.time_limit_s,
            })
        }
        _ => {
            // Neither solver applies when the exact one was asked for and fell back here: say
            // why it did not take the problem.
            let not_markov = match (settings.solver, ssp::structure(problem)) {
                (LpSolver::Exact, ssp::Structure::General { reason }) => format!(
                    "; the exact solver does not apply either: the generators are not Markov ({reason})"
                ),
                _ => String::new(),
            };
            return Err(PlanError::LpFailed {
                status: lp_status,
                reason: format!(
                    "after {} iterations (primal residual {:.2e}, dual residual {:.2e}){not_markov}",
                    sol.iterations, sol.r_prim, sol.r_dual
                ),
            });
        }
    }
    let z_hat: &[f64] = match settings.form {
        LpForm::Primal => &sol.x[..n_flux],
        LpForm::Dual => &sol.z[..n_flux],
    };
    let mut flux = vec![vec![0.0; n]; k_count];
    let mut density = vec![0.0; n];
    let mut objective = 0.0;
    for (v, &(k, i)) in red.flux_vars.iter().enumerate() {
        let z = z_hat[v].max(0.0);
        objective += red.cost[v] * z;
        flux[k][i] = z * z_scale;
        // The eliminated density: r = Σₖ zₖ / u_max.
        density[i] += z * z_scale / problem.u_max;
    }
    debug_assert_eq!(red.kept.len(), m);
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
    let mass_balance_residual = red
        .kept
        .iter()
        .map(|&i| (balance[i] - problem.start[i]).abs())
        .fold(0.0f64, f64::max)
        / t_max;
    // The dual potentials in the original units: V = c·max B·h·ŷ (see `reduce` for the scaling).
    let y_hat: Vec<f64> = match settings.form {
        LpForm::Primal => sol.z[..m].iter().map(|&z| -z).collect(),
        LpForm::Dual => sol.x[..m].to_vec(),
    };
    let mut potential = vec![0.0; n];
    for (r, &i) in red.kept.iter().enumerate() {
        potential[i] = obj_scale / z_scale * h * y_hat[r];
    }
    let certificate = certify(problem, &flux, &potential);
    let report = LpReport {
        status: lp_status,
        solver: SolverUsed::Clarabel,
        certificate,
        objective: objective * obj_scale,
        primal_residual: sol.r_prim,
        dual_residual: sol.r_dual,
        mass_balance_residual,
        iterations: sol.iterations,
        solve_time_s: started.elapsed().as_secs_f64(),
        generator_time_s: gens.stats.build_time_s,
        variables,
        constraints,
    };
    debug!(?report, "P-F LP solved");
    Ok(LpSolution {
        density,
        flux,
        potential,
        report,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::basis::BasisKind;
    use crate::generators::Generators;
    use crate::grid::PlanningGrid;

    /// A 4 × 3 grid whose third column is blocked: start on the left, target on the right.
    fn walled_off() -> Generators {
        let (w, h) = (4, 3);
        let blocked = (0..w * h).map(|c| c % w == 2).collect();
        let grid = PlanningGrid::from_parts([0.0, 0.0], 1.0, w, h, vec![0.5; w * h], blocked)
            .expect("grid");
        Generators::build(&grid, BasisKind::Indicator, 8).expect("generators")
    }

    #[test]
    fn a_walled_off_target_is_infeasible_in_both_forms() {
        let gens = walled_off();
        let n = gens.basis.len();
        let target_cell = 3; // (3, 0), right of the wall
        let target: Vec<bool> = (0..n).map(|i| gens.basis.cell(i) == target_cell).collect();
        let mut start = vec![0.0; n];
        start[gens.basis.index_of_cell(0).expect("free")] = 1.0;
        let cost = vec![0.5; n];
        let problem = LpProblem {
            generators: &gens,
            cost: &cost,
            start: &start,
            target: &target,
            u_max: 1.0,
        };
        for form in [LpForm::Primal, LpForm::Dual] {
            let settings = LpSettings {
                form,
                ..LpSettings::default()
            };
            let result = solve(&problem, &settings);
            assert!(
                matches!(result, Err(PlanError::Infeasible { .. })),
                "{form:?}: {result:?}"
            );
        }
    }

    #[test]
    fn the_eliminated_density_is_the_speed_bound_at_equality() {
        // Open 5 × 1 corridor, mass in cell 0, target cell 4, u_max = 2: the flux is 1 per cell
        // along the corridor (per unit length), the density flux / u_max, the value 4 × 0.5 × 1.5.
        let grid = PlanningGrid::from_parts([0.0, 0.0], 1.0, 5, 1, vec![0.5; 5], vec![false; 5])
            .expect("grid");
        let gens = Generators::build(&grid, BasisKind::Indicator, 4).expect("generators");
        let target = vec![false, false, false, false, true];
        let start = vec![1.0, 0.0, 0.0, 0.0, 0.0];
        let cost = vec![0.5; 5];
        let problem = LpProblem {
            generators: &gens,
            cost: &cost,
            start: &start,
            target: &target,
            u_max: 2.0,
        };
        for form in [LpForm::Primal, LpForm::Dual] {
            let settings = LpSettings {
                form,
                ..LpSettings::default()
            };
            let sol = solve(&problem, &settings).expect("solved");
            assert!(
                (sol.report.objective - 4.0 * 0.5 * 1.5).abs() < 1e-7,
                "{form:?}: {:?}",
                sol.report
            );
            for i in 0..4 {
                let z: f64 = sol.flux.iter().map(|f| f[i]).sum();
                assert!((z - 1.0).abs() < 1e-7, "{form:?}: flux {z} at {i}");
                assert!((sol.density[i] - z / 2.0).abs() < 1e-12);
            }
        }
    }
}
