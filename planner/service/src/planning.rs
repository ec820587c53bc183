//! Runs one validated request through pf-planner and turns the result into reply fields. The
//! P-F generators, which depend only on the geometry of the planning grid (origin, cell size,
//! shape, blocked cells), the basis and the direction count, come from a small LRU cache: a new
//! map of the same geometry (new heights, so new traversability), a new start or a new goal is a
//! cache hit and needs only a new solve.

use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};
use std::sync::Arc;
use std::time::Instant;

use lcm_types::pfnav::{PlanMetrics, PlanReply, TrajectorySample};
use pf_planner::basis::BasisKind;
use pf_planner::deadline::Deadline;
use pf_planner::error::PlanError;
use pf_planner::graph::{self, Connectivity};
use pf_planner::grid::PlanningGrid;
use pf_planner::lp::LpSettings;
use pf_planner::map::Point;
use pf_planner::metrics::evaluate_path;
use pf_planner::pf::{self, PfGenerators, PfOptions};
use pf_planner::trajectory::{build_trajectory, TrajectoryOptions};
use pf_planner::traversability::{TraversabilityField, TraversabilityParams};

use crate::cache::BuildCache;
use crate::convert::{MethodChoice, Rejection, ValidatedRequest};

/// Identity of a generator set: the planning grid's geometry (by content hash; not its
/// traversability) and the basis settings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GeneratorKey {
    grid_hash: u64,
    basis: BasisKey,
    directions: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum BasisKey {
    Indicator,
    Rbf { sigma_bits: u64, samples: usize },
}

impl GeneratorKey {
    fn new(grid: &PlanningGrid, basis: &BasisKind, directions: usize) -> Self {
        let mut hasher = DefaultHasher::new();
        grid.origin.map(f64::to_bits).hash(&mut hasher);
        grid.cell_size.to_bits().hash(&mut hasher);
        (grid.width, grid.height).hash(&mut hasher);
        grid.blocked.hash(&mut hasher);
        let basis = match *basis {
            BasisKind::Indicator => BasisKey::Indicator,
            BasisKind::Rbf {
                sigma_over_spacing,
                samples_per_basis,
            } => BasisKey::Rbf {
                sigma_bits: sigma_over_spacing.to_bits(),
                samples: samples_per_basis,
            },
        };
        Self {
            grid_hash: hasher.finish(),
            basis,
            directions,
        }
    }
}

type CachedGenerators = Result<Arc<PfGenerators>, Rejection>;

/// The service's generator cache.
pub struct GeneratorCache(BuildCache<GeneratorKey, CachedGenerators>);

impl GeneratorCache {
    pub fn new(capacity: usize) -> Self {
        Self(BuildCache::new(capacity))
    }

    /// Generators for `grid`, from the cache when possible; the bool says whether it was a hit.
    /// A build stopped by `deadline` is not kept (the next request builds again); when the
    /// stopped build was another request's, this one builds with its own deadline.
    fn get(
        &self,
        grid: &PlanningGrid,
        basis: &BasisKind,
        directions: usize,
        deadline: Deadline,
    ) -> (CachedGenerators, bool) {
        let build = || {
            PfGenerators::build_until(grid, basis, directions, deadline)
                .map(Arc::new)
                .map_err(|e| rejection_of(&e))
        };
        let key = GeneratorKey::new(grid, basis, directions);
        let (cached, hit) = self.0.get_or_build(key.clone(), build);
        match cached {
            // A 64-bit hash collision between two grids: never use generators of another grid.
            Ok(gens) if !gens.matches(grid) => (build(), false),
            Err(rejection) if rejection.status == PlanReply::STATUS_SOLVER_TIMEOUT => {
                self.0.evict(&key);
                if hit {
                    (build(), false)
                } else {
                    (Err(rejection), false)
                }
            }
            other => (other, hit),
        }
    }

    /// Generator sets held.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

/// A successful plan, in reply fields (solve_time is filled in by the caller).
#[derive(Debug, Clone)]
pub struct PlanOutcome {
    pub samples: Vec<TrajectorySample>,
    pub metrics: PlanMetrics,
    /// Whether the P-F generators came from the cache.
    pub cache_hit: bool,
}

/// Reply status and reason for a planner error.
pub fn rejection_of(error: &PlanError) -> Rejection {
    let status = match error {
        PlanError::InvalidMap(_) => PlanReply::STATUS_INVALID_MAP,
        PlanError::StartOffMap { .. } | PlanError::StartInObstacle { .. } => {
            PlanReply::STATUS_START_INVALID
        }
        PlanError::GoalOffMap { .. }
        | PlanError::GoalInObstacle { .. }
        | PlanError::Unreachable { .. } => PlanReply::STATUS_GOAL_UNREACHABLE,
        PlanError::InvalidOption { .. } => PlanReply::STATUS_INVALID_REQUEST,
        PlanError::TimeLimit { .. } => PlanReply::STATUS_SOLVER_TIMEOUT,
        PlanError::Infeasible { .. }
        | PlanError::LpFailed { .. }
        | PlanError::TrajectoryFailed { .. } => PlanReply::STATUS_SOLVER_FAILED,
        PlanError::Io { .. } | PlanError::Format { .. } => PlanReply::STATUS_INTERNAL_ERROR,
    };
    Rejection::new(status, error.to_string())
}

/// The LP report's status names mapped to `plan_metrics_t.LP_*`.
/// The LP report's solver names mapped to `plan_metrics_t.SOLVER_*`.
fn lp_solver_code(solver: &str) -> i8 {
    match solver {
        "dijkstra" => PlanMetrics::SOLVER_DIJKSTRA,
        "policy-iteration" => PlanMetrics::SOLVER_POLICY_ITERATION,
        "clarabel" => PlanMetrics::SOLVER_CLARABEL,
        _ => PlanMetrics::SOLVER_NONE,
    }
}

fn lp_status_code(status: &str) -> i8 {
    match status {
        "Solved" | "Trivial" => PlanMetrics::LP_SOLVED,
        "AlmostSolved" => PlanMetrics::LP_ALMOST_SOLVED,
        s if s.contains("Infeasible") => PlanMetrics::LP_INFEASIBLE,
        "MaxIterations" | "AlmostMaxIterations" => PlanMetrics::LP_MAX_ITERATIONS,
        "MaxTime" => PlanMetrics::LP_MAX_TIME,
        _ => PlanMetrics::LP_NUMERICAL_ERROR,
    }
}

/// Plans `request` on the traversability model `traversability` (the service's configuration:
/// the wire contract has no field for it).
pub fn plan(
    request: &ValidatedRequest,
    cache: &GeneratorCache,
    traversability: &TraversabilityParams,
) -> Result<PlanOutcome, Rejection> {
    let started = Instant::now();
    let map = &*request.map;
    let opts = &request.options;
    let reject = |e: PlanError| rejection_of(&e);
    // max_solve_time bounds the P-F computation from the moment a worker takes the request:
    // generators (unless cached), then the LP, checked inside both.
    let deadline = Deadline::after(started, opts.max_solve_time);
    let field = TraversabilityField::from_map(map, traversability).map_err(reject)?;
    let grid = PlanningGrid::from_field(map, &field, opts.grid_size).map_err(reject)?;
    let mut metrics = PlanMetrics {
        lp_status: PlanMetrics::LP_NOT_APPLICABLE,
        ..PlanMetrics::default()
    };
    let mut cache_hit = false;
    let path: Vec<Point> = match request.method {
        MethodChoice::Dijkstra | MethodChoice::AStar => {
            let conn = Connectivity::from_directions(opts.directions).map_err(reject)?;
            let searched = Instant::now();
            let found = if request.method == MethodChoice::Dijkstra {
                graph::dijkstra_path(&grid, request.start, &request.goal, conn)
            } else {
                graph::astar_path(&grid, request.start, &request.goal, conn)
            }
            .map_err(reject)?;
            metrics.solve_phase_time = searched.elapsed().as_secs_f64();
            metrics.objective = found.cost;
            metrics.expanded_nodes = i64::try_from(found.expanded).unwrap_or(i64::MAX);
            found.points
        }
        MethodChoice::Pf => {
            let built = Instant::now();
            let (gens, hit) = cache.get(&grid, &opts.basis, opts.directions, deadline);
            cache_hit = hit;
            let gens = gens?;
            if !hit {
                metrics.generator_time = built.elapsed().as_secs_f64();
            }
            deadline.check("the generator build").map_err(reject)?;
            // The LP's speed bound stays the library's (it scales the objective and the feedback
            // field); the reference is re-timed at `opts.speed` below, as `pf-plan` does.
            let pf_options = PfOptions {
                start_density: opts.start_density,
                lp: LpSettings {
                    time_limit_s: deadline.remaining_s(),
                    solver: opts.solver,
                    ..LpSettings::default()
                },
                ..PfOptions::default()
            };
            let solved = Instant::now();
            let solution = pf::solve(&gens, &grid, request.start, &request.goal, &pf_options)
                .map_err(reject)?;
            let lp = &solution.lp;
            metrics.solve_phase_time = lp.solve_time_s;
            metrics.path_time = solved.elapsed().as_secs_f64() - lp.solve_time_s;
            metrics.objective = lp.objective;
            metrics.lp_status = lp_status_code(&lp.status);
            metrics.lp_iterations = i32::try_from(lp.iterations).unwrap_or(i32::MAX);
            metrics.lp_solver = lp_solver_code(&lp.solver);
            metrics.primal_residual = lp.certificate.primal_residual;
            metrics.dual_residual = lp.certificate.dual_residual;
            metrics.duality_gap = lp.certificate.duality_gap;
            metrics.certified = lp.certificate.holds();
            metrics.certificate_tolerance = lp.certificate.tolerance;
            if !solution.outcome.reached_goal() {
                return Err(rejection_of(&PlanError::TrajectoryFailed {
                    reason: format!("{:?}", solution.outcome),
                }));
            }
            solution.path
        }
    };
    let retimed = Instant::now();
    let path_metrics = evaluate_path(map, &field, &path);
    let trajectory_options = TrajectoryOptions {
        speed: opts.speed,
        dt: opts.sample_period,
        ..TrajectoryOptions::default()
    };
    let samples: Vec<TrajectorySample> =
        build_trajectory(map, &path, request.start_yaw, &trajectory_options)
            .map_err(reject)?
            .into_iter()
            .map(|s| TrajectorySample {
                t: s.t,
                x: s.x,
                y: s.y,
                z: s.z,
                yaw: s.yaw,
                vx: s.vx,
                vy: s.vy,
                yaw_rate: s.yaw_rate,
            })
            .collect();
    metrics.path_time += retimed.elapsed().as_secs_f64();
    metrics.cache_hit = cache_hit;
    metrics.cost = path_metrics.cost_integral;
    metrics.length = path_metrics.length;
    metrics.duration = samples.last().map_or(0.0, |s| s.t);
    metrics.reached_goal = path.last().is_some_and(|&p| request.goal.contains(p));
    Ok(PlanOutcome {
        samples,
        metrics,
        cache_hit,
    })
}
