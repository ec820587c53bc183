//! The P-F pipeline: planning grid → basis and ANSDMD generators → LP → feedback field → path.
//!
//! [`PfGenerators::build`] depends only on the geometry of the grid (origin, cell size, shape and
//! blocked cells), the basis and the number of directions, so a service can cache it and reuse it
//! for any start, goal and traversability p of the same geometry: the cost integrals Bᵢ = ∫ p φᵢ
//! are computed per solve (O(n)), and the goal's basis functions are removed from the LP at solve
//! time (absorbing target).

use std::collections::VecDeque;
use std::time::Instant;

use tracing::{debug, info};

pub use crate::basis::BasisKind;
use crate::deadline::Deadline;
use crate::error::PlanError;
use crate::feedback::integrate;
pub use crate::feedback::{FeedbackField, IntegrationOutcome, IntegrationSettings};
use crate::feedback_grid::{FeedbackGrid, FieldInputs, FieldUnavailable};
use crate::generators::{Generators, SparseColumns};
use crate::graph::endpoints;
use crate::grid::{GoalRegion, PlanningGrid};
use crate::lp::{self, LpProblem, LpSolution, LpStatus, SolverUsed};
pub use crate::lp::{LpReport, LpSettings};
use crate::map::Point;

/// Quadrature points per axis per cell for the cost integrals Bᵢ = ∫ p φᵢ (RBF; indicators are exact with any count).
const COST_QUADRATURE_PER_AXIS: usize = 4;

/// Initial density h₀ of the LP.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum StartDensity {
    /// All mass in the start's basis function: the flow is one optimal tube from the start.
    PointMass,
    /// Uniform over every free basis function that can reach the goal: the law is then a
    /// feedback everywhere (robust to disturbances), at the price of a larger optimal flow.
    #[default]
    UniformFree,
    /// The robot's position belief: a Gaussian of standard deviation `sigma_m` (metres) about
    /// the start, over the free functions that can reach the goal (the belief's mass elsewhere
    /// is left out and the rest renormalised). The LP's objective is then the expected cost from
    /// where the robot may truly be; σ = 0 (or a belief narrower than one function) is the
    /// point mass.
    Belief { sigma_m: f64 },
}

/// Options of one P-F solve.
#[derive(Debug, Clone, PartialEq)]
pub struct PfOptions {
    /// Speed bound of the LP, m/s (the field's speed along the optimal flow).
    pub u_max: f64,
    /// Initial density.
    pub start_density: StartDensity,
    /// LP solver settings.
    pub lp: LpSettings,
    /// RK4 settings.
    pub integration: IntegrationSettings,
}

impl Default for PfOptions {
    fn default() -> Self {
        Self {
            u_max: 1.0,
            start_density: StartDensity::default(),
            lp: LpSettings::default(),
            integration: IntegrationSettings::default(),
        }
    }
}

/// Basis and generators of one grid geometry: build once, solve for many start/goal pairs and
/// traversability maps.
#[derive(Debug, Clone)]
pub struct PfGenerators {
    generators: Generators,
    /// Quadrature points per axis per cell of the integrals ∫ p φᵢ.
    quadrature_per_axis: usize,
    /// ∫ φᵢ, to turn masses into coefficients.
    mass: Vec<f64>,
    /// Identity of the grid the generators were built for.
    grid_key: GridKey,
}

#[derive(Debug, Clone, PartialEq)]
struct GridKey {
    origin: Point,
    cell_size: f64,
    width: usize,
    height: usize,
    blocked: Vec<bool>,
}

impl GridKey {
    fn of(grid: &PlanningGrid) -> Self {
        Self {
            origin: grid.origin,
            cell_size: grid.cell_size,
            width: grid.width,
            height: grid.height,
            blocked: grid.blocked.clone(),
        }
    }
}

impl PfGenerators {
    /// Builds basis, generators (one per direction, 4 or 8) and cost integrals on `grid`.
    pub fn build(
        grid: &PlanningGrid,
        basis: &BasisKind,
        directions: usize,
    ) -> Result<Self, PlanError> {
        Self::build_until(grid, basis, directions, Deadline::NONE)
    }

    /// [`PfGenerators::build`], stopped with [`PlanError::TimeLimit`] once `deadline` passes.
    pub fn build_until(
        grid: &PlanningGrid,
        basis: &BasisKind,
        directions: usize,
        deadline: Deadline,
    ) -> Result<Self, PlanError> {
        let started = Instant::now();
        let generators = Generators::build_until(grid, *basis, directions, deadline)?;
        let per_axis = match basis {
            BasisKind::Indicator => 1,
            BasisKind::Rbf { .. } => COST_QUADRATURE_PER_AXIS,
        };
        let mass = generators.basis.integrals(per_axis, |_| 1.0);
        info!(
            functions = generators.basis.len(),
            directions,
            nnz = generators.stats.nnz,
            time_s = started.elapsed().as_secs_f64(),
            "P-F generators ready"
        );
        Ok(Self {
            generators,
            quadrature_per_axis: per_axis,
            mass,
            grid_key: GridKey::of(grid),
        })
    }

    /// The generators and their basis.
    pub fn generators(&self) -> &Generators {
        &self.generators
    }

    /// Bᵢ = ∫ p φᵢ per active function, for the traversability of `grid` (same geometry), over
    /// the plane with p clamped at the grid edge.
    pub fn cost_integrals(&self, grid: &PlanningGrid) -> Vec<f64> {
        self.generators
            .basis
            .integrals(self.quadrature_per_axis, |p| grid.cost_at(p))
    }

    /// ∫ φᵢ per active function.
    pub fn mass_integrals(&self) -> &[f64] {
        &self.mass
    }

    /// Whether these generators were built for this grid's geometry (its p may differ).
    pub fn matches(&self, grid: &PlanningGrid) -> bool {
        self.grid_key == GridKey::of(grid)
    }
}

/// Result of one P-F solve.
#[derive(Debug, Clone)]
pub struct PfSolution {
    /// The integrated path from the start (world frame).
    pub path: Vec<Point>,
    /// How the integration ended.
    pub outcome: IntegrationOutcome,
    /// LP report (status, objective, residuals, times, size).
    pub lp: LpReport,
    /// The feedback law u = ρ̄/ρ, evaluable anywhere.
    pub field: FeedbackField,
    /// LP objective divided by (1 + 1/u_max): the traversability-weighted length of the optimal
    /// flow, Σ mass × ∫p ds (comparable with graph distances).
    pub weighted_length: f64,
    /// Start coefficients t that were used (per active function).
    pub start_coefficients: Vec<f64>,
    /// The optimal dual: cost-to-go per active function (0 on targets, `+∞` where the goal
    /// cannot be reached), in LP units (c·∫p ds per unit mass, c = 1 + 1/u_max).
    pub cost_to_go: Vec<f64>,
    /// Target flags per active function.
    pub targets: Vec<bool>,
    /// The greedy law of the optimal cost-to-go on the planning grid (speed = `u_max`), or why
    /// there is none (see [`crate::feedback_grid`]).
    pub feedback_grid: Result<FeedbackGrid, FieldUnavailable>,
}

/// Active functions that can reach the target through the generators' flows (reverse BFS over
/// the transposed move graph, built as one flat CSR: two passes over the non-zeros).
fn can_reach_target(gens: &Generators, target: &[bool]) -> Vec<bool> {
    let n = gens.basis.len();
    let moves = || {
        gens.generators.iter().flat_map(move |l| {
            (0..n).flat_map(move |i| {
                l.column(i)
                    .filter(move |&(j, v)| j != i && v > 0.0)
                    .map(move |(j, _)| (i, j))
            })
        })
    };
    // Incoming adjacency: j ← i when some Lₖ moves mass from i to j.
    let mut start = vec![0usize; n + 1];
    for (_, j) in moves() {
        start[j + 1] += 1;
    }
    for j in 0..n {
        start[j + 1] += start[j];
    }
    let mut fill = start[..n].to_vec();
    let mut predecessors = vec![0usize; start[n]];
    for (i, j) in moves() {
        predecessors[fill[j]] = i;
        fill[j] += 1;
    }
    let mut reach = target.to_vec();
    let mut queue: VecDeque<usize> = (0..n).filter(|&i| target[i]).collect();
    while let Some(j) = queue.pop_front() {
        for &i in &predecessors[start[j]..start[j + 1]] {
            if !reach[i] {
                reach[i] = true;
                queue.push_back(i);
            }
        }
    }
    reach
}

/// Active functions from whose cell a sequence of the generators' one-lattice-vector moves
/// reaches a target function's cell, staying in the domain of the basis and never touching a
/// blocked cell (the sampling rule of [`crate::generators`]; reverse BFS over cells).
fn can_move_to_target(gens: &Generators, grid: &PlanningGrid, target: &[bool]) -> Vec<bool> {
    let basis = &gens.basis;
    let n = basis.len();
    let mut reach = target.to_vec();
    let mut queue: VecDeque<usize> = (0..n).filter(|&i| target[i]).collect();
    while let Some(j) = queue.pop_front() {
        let (jx, jy) = grid.coords(basis.cell(j));
        for dir in &gens.directions {
            // Predecessor cell: one move against the direction.
            let (ix, iy) = (jx as i64 - dir.shift[0], jy as i64 - dir.shift[1]);
            if ix < 0 || iy < 0 || ix >= grid.width as i64 || iy >= grid.height as i64 {
                continue;
            }
            let (ix, iy) = (ix as usize, iy as usize);
            let Some(i) = basis.index_of_cell(grid.index(ix, iy)) else {
                continue;
            };
            if reach[i] {
                continue;
            }
            let (x0, x1) = (ix.min(jx), ix.max(jx));
            let (y0, y1) = (iy.min(jy), iy.max(jy));
            if (y0..=y1).any(|y| (x0..=x1).any(|x| grid.blocked[grid.index(x, y)])) {
                continue;
            }
            reach[i] = true;
            queue.push_back(i);
        }
    }
    reach
}

/// The LP inputs of one start/goal pair on cached generators (see [`prepare`]).
#[derive(Debug, Clone)]
pub struct PreparedLp {
    /// Start density coefficients t per active function (unit total mass).
    pub start: Vec<f64>,
    /// Target flags per active function.
    pub target: Vec<bool>,
    /// Goal cells of the planning grid.
    pub goal_cells: Vec<usize>,
    /// Bᵢ = ∫ p φᵢ per active function on this grid's traversability.
    pub cost: Vec<f64>,
}

impl PreparedLp {
    /// The LP of this start/goal pair.
    pub fn problem<'a>(&'a self, gens: &'a PfGenerators, u_max: f64) -> LpProblem<'a> {
        LpProblem {
            generators: &gens.generators,
            cost: &self.cost,
            start: &self.start,
            target: &self.target,
            u_max,
        }
    }
}

/// Checks start and goal and builds the start density and the target set.
///
/// Errors: start/goal off the map or in an obstacle, a goal that no basis function covers, a
/// start that cannot reach the goal ([`PlanError::Unreachable`]).
pub fn prepare(
    gens: &PfGenerators,
    grid: &PlanningGrid,
    start: Point,
    goal: &GoalRegion,
    density: StartDensity,
) -> Result<PreparedLp, PlanError> {
    if !gens.matches(grid) {
        return Err(PlanError::InvalidOption {
            name: "generators",
            reason: "the P-F generators were built for a different planning grid".into(),
        });
    }
    let (start_cell, goal_cells) = endpoints(grid, start, goal)?;
    let g = &gens.generators;
    let basis = &g.basis;
    let n = basis.len();
    let mut target = vec![false; n];
    for &c in &goal_cells {
        if let Some(i) = basis.index_of_cell(c) {
            target[i] = true;
        }
    }
    if !target.iter().any(|&t| t) {
        return Err(PlanError::GoalInObstacle { point: goal.center });
    }
    // The start's function: its own cell's, or (RBF next to an obstacle) the nearest active centre.
    let start_fn = match basis.index_of_cell(start_cell) {
        Some(i) => i,
        None => (0..n)
            .min_by(|&a, &b| dist(basis.center(a), start).total_cmp(&dist(basis.center(b), start)))
            .ok_or(PlanError::StartInObstacle { point: start })?,
    };
    // Reachable through the generators' flows *and* by moves of the sampled system over the
    // domain of the basis: RBF generators carry small entries (above the sparsity threshold)
    // across gaps that the robot cannot pass, which would otherwise put start mass into pockets
    // that can only leak out at enormous cost. Ulam's generators are exactly those moves, so
    // one search suffices for them.
    let moves = can_move_to_target(g, grid, &target);
    let reach: Vec<bool> = match basis.kind() {
        BasisKind::Indicator => moves,
        BasisKind::Rbf { .. } => can_reach_target(g, &target)
            .into_iter()
            .zip(moves)
            .map(|(a, b)| a && b)
            .collect(),
    };
    if !reach[start_fn] {
        return Err(PlanError::Unreachable {
            reason: "no sequence of moves through free cells connects the start to the goal region"
                .into(),
        });
    }
    let mut t = vec![0.0; n];
    let point_mass = |t: &mut Vec<f64>| {
        if !target[start_fn] {
            t[start_fn] = 1.0 / gens.mass[start_fn];
        }
    };
    match density {
        StartDensity::PointMass => point_mass(&mut t),
        StartDensity::Belief { sigma_m } => {
            let weight = |i: usize| {
                let d = dist(basis.center(i), start);
                (-0.5 * (d / sigma_m).powi(2)).exp()
            };
            let free = |i: usize| reach[i] && !target[i];
            let total: f64 = if sigma_m > 0.0 && sigma_m.is_finite() {
                (0..n)
                    .filter(|&i| free(i))
                    .map(|i| weight(i) * gens.mass[i])
                    .sum()
            } else {
                0.0
            };
            if total > 0.0 && total.is_finite() && !target[start_fn] {
                for i in (0..n).filter(|&i| free(i)) {
                    t[i] = weight(i) / total;
                }
            } else {
                point_mass(&mut t);
            }
        }
        StartDensity::UniformFree => {
            let total: f64 = (0..n)
                .filter(|&i| reach[i] && !target[i])
                .map(|i| gens.mass[i])
                .sum();
            if total > 0.0 {
                for i in 0..n {
                    if reach[i] && !target[i] {
                        t[i] = 1.0 / total;
                    }
                }
            }
        }
    }
    Ok(PreparedLp {
        start: t,
        target,
        goal_cells,
        cost: gens.cost_integrals(grid),
    })
}

/// Plans with the P-F method: LP on the cached generators, then the feedback law from `start`.
///
/// Errors as [`prepare`], plus an infeasible or failed LP. A trajectory that does not reach the
/// goal is *not* an error here: see [`PfSolution::outcome`].
pub fn solve(
    gens: &PfGenerators,
    grid: &PlanningGrid,
    start: Point,
    goal: &GoalRegion,
    opts: &PfOptions,
) -> Result<PfSolution, PlanError> {
    if !(opts.u_max.is_finite() && opts.u_max > 0.0) {
        return Err(PlanError::InvalidOption {
            name: "u_max",
            reason: format!("{} must be finite and > 0", opts.u_max),
        });
    }
    let prepared = prepare(gens, grid, start, goal, opts.start_density)?;
    let problem = prepared.problem(gens, opts.u_max);
    let solution = lp::solve(&problem, &opts.lp)?;
    let field_started = Instant::now();
    let feedback_grid = optimal_values(&problem, &solution, opts).map(|value| {
        FeedbackGrid::from_values(&FieldInputs {
            generators: &gens.generators,
            grid,
            goal: *goal,
            goal_cells: &prepared.goal_cells,
            cost: &prepared.cost,
            mass: &gens.mass,
            value: &value,
            u_max: opts.u_max,
            speed: opts.u_max,
        })
    });
    debug!(
        time_s = field_started.elapsed().as_secs_f64(),
        available = feedback_grid.is_ok(),
        "feedback grid extracted"
    );
    let weighted_length = solution.report.objective / (1.0 + 1.0 / opts.u_max);
    let g = &gens.generators;
    let field = FeedbackField::new(
        g.basis.clone(),
        &g.directions,
        solution.density,
        &solution.flux,
    );
    let mut is_goal_cell = vec![false; grid.len()];
    for &c in &prepared.goal_cells {
        is_goal_cell[c] = true;
    }
    let (mut path, outcome) = integrate(
        &field,
        grid,
        start,
        &|c| is_goal_cell[c],
        opts.u_max,
        &opts.integration,
    );
    if outcome.reached_goal() {
        finish_into_goal_disc(grid, goal, &mut path);
    }
    debug!(?outcome, points = path.len(), "P-F trajectory integrated");
    Ok(PfSolution {
        path,
        outcome,
        lp: solution.report,
        field,
        weighted_length,
        start_coefficients: prepared.start,
        cost_to_go: solution.potential,
        targets: prepared.target,
        feedback_grid,
    })
}

/// V* per active function for the feedback grid (see [`crate::feedback_grid`] for which
/// solver's potential is V* where).
fn optimal_values(
    problem: &LpProblem<'_>,
    solution: &LpSolution,
    opts: &PfOptions,
) -> Result<Vec<f64>, FieldUnavailable> {
    if solution.report.status == LpStatus::Trivial {
        // No flow, so no dual: the cost-to-go of the same SSP from the exact solver (its start
        // density plays no part in V*).
        return match crate::ssp::solve(problem, crate::deadline::Deadline::NONE) {
            Ok(Some(exact)) => Ok(exact.potential),
            Ok(None) | Err(_) => Err(FieldUnavailable::NotMarkov),
        };
    }
    match solution.report.solver {
        SolverUsed::Dijkstra | SolverUsed::PolicyIteration => Ok(solution.potential.clone()),
        SolverUsed::Clarabel | SolverUsed::None => {
            if opts.start_density != StartDensity::UniformFree {
                return Err(FieldUnavailable::DualNotCostToGo);
            }
            // Uniform start: positive density on every state that can reach the goal, so the
            // dual is pinned to V* there; every other non-target state cannot reach it.
            Ok((0..problem.target.len())
                .map(|i| {
                    if problem.target[i] {
                        0.0
                    } else if problem.start[i] > 0.0 {
                        solution.potential[i]
                    } else {
                        f64::INFINITY
                    }
                })
                .collect())
        }
    }
}

fn dist(a: Point, b: Point) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// The integration stops on entering a target cell, whose corner may lie just outside the goal
/// disc; append the straight move to the goal centre when it stays in free cells.
fn finish_into_goal_disc(grid: &PlanningGrid, goal: &GoalRegion, path: &mut Vec<Point>) {
    let Some(&end) = path.last() else {
        return;
    };
    if goal.contains(end) {
        return;
    }
    let length = dist(end, goal.center);
    let steps = ((length / (0.1 * grid.cell_size)).ceil() as usize).max(1);
    let point = |s: usize| {
        let a = s as f64 / steps as f64;
        [
            end[0] + a * (goal.center[0] - end[0]),
            end[1] + a * (goal.center[1] - end[1]),
        ]
    };
    if grid.segment_is_free(end, goal.center) {
        // Stop at the first point inside the disc rather than running to the centre.
        if let Some(s) = (1..=steps).find(|&s| goal.contains(point(s))) {
            path.push(point(s));
        }
    }
}
