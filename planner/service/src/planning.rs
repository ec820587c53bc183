//! Runs one validated request through pf-planner and turns the result into reply fields. The
//! P-F generators, which depend only on the geometry of the planning grid (origin, cell size,
//! shape, blocked cells), the basis and the direction count, come from a small LRU cache: a new
//! map of the same geometry (new heights, so new traversability), a new start or a new goal is a
//! cache hit and needs only a new solve.

use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};
use std::sync::Arc;
use std::time::Instant;

use lcm_types::pfnav::{FeedbackField, Header, PlanMetrics, PlanReply, TrajectorySample};
use pf_planner::basis::{BasisKind, RbfGenerators};
use pf_planner::deadline::Deadline;
use pf_planner::error::PlanError;
use pf_planner::feedback_grid::FeedbackGrid;
use pf_planner::grid::{GoalRegion, PlanningGrid};
use pf_planner::lp::{LpStatus, SolverUsed};
use pf_planner::pf::PfGenerators;
use pf_planner::plan::{Plan, PlannerOptions, PreparedMap};
use pf_planner::traversability::{block_steep_cells, TraversabilityField, TraversabilityParams};

use tracing::{info, warn};

use crate::cache::BuildCache;
use crate::convert::{Rejection, ResolvedOptions, ValidatedRequest};

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
    Rbf {
        sigma_bits: u64,
        samples: usize,
        generators: RbfGenerators,
    },
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
                generators,
            } => BasisKey::Rbf {
                sigma_bits: sigma_over_spacing.to_bits(),
                samples: samples_per_basis,
                generators,
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
    /// The feedback law of a P-F plan (header, request_id and map_seq are the caller's to fill
    /// in); `None` for graph methods and for the Clarabel point-start case (see
    /// `pf_planner::feedback_grid`).
    pub feedback_field: Option<FeedbackField>,
}

/// The wire form of a feedback grid (header, request_id and map_seq left for the caller).
/// Grids are at most 512² cells, far inside `int32_t`.
pub fn feedback_field_message(grid: &FeedbackGrid) -> FeedbackField {
    let floats = |values: &[f64]| values.iter().map(|&v| v as f32).collect::<Vec<f32>>();
    let int = |n: usize| i32::try_from(n).unwrap_or(i32::MAX);
    FeedbackField {
        header: Header::default(),
        request_id: 0,
        map_seq: -1,
        origin_x: grid.origin[0],
        origin_y: grid.origin[1],
        resolution: grid.resolution,
        width: int(grid.width),
        height: int(grid.height),
        num_cells: int(grid.len()),
        dir_x: floats(&grid.dir_x),
        dir_y: floats(&grid.dir_y),
        speed: floats(&grid.speed),
        cost_to_go: floats(&grid.cost_to_go),
        goal_x: grid.goal.center[0],
        goal_y: grid.goal.center[1],
        goal_radius: grid.goal.radius,
    }
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

/// The LP status mapped to `plan_metrics_t.LP_*`.
fn lp_status_code(status: LpStatus) -> i8 {
    match status {
        LpStatus::Solved | LpStatus::Trivial => PlanMetrics::LP_SOLVED,
        LpStatus::AlmostSolved => PlanMetrics::LP_ALMOST_SOLVED,
        LpStatus::PrimalInfeasible | LpStatus::DualInfeasible => PlanMetrics::LP_INFEASIBLE,
        LpStatus::MaxIterations => PlanMetrics::LP_MAX_ITERATIONS,
        LpStatus::MaxTime => PlanMetrics::LP_MAX_TIME,
        LpStatus::Uncertified
        | LpStatus::NumericalError
        | LpStatus::InsufficientProgress
        | LpStatus::SetupFailed
        | LpStatus::Unsolved => PlanMetrics::LP_NUMERICAL_ERROR,
    }
}

/// The method behind an LP solution mapped to `plan_metrics_t.SOLVER_*`.
fn lp_solver_code(solver: SolverUsed) -> i8 {
    match solver {
        SolverUsed::None => PlanMetrics::SOLVER_NONE,
        SolverUsed::Dijkstra => PlanMetrics::SOLVER_DIJKSTRA,
        SolverUsed::PolicyIteration => PlanMetrics::SOLVER_POLICY_ITERATION,
        SolverUsed::Clarabel => PlanMetrics::SOLVER_CLARABEL,
    }
}

impl From<PlanError> for Rejection {
    fn from(error: PlanError) -> Self {
        rejection_of(&error)
    }
}

/// The planner's options for a validated request, with the service's traversability model (the
/// wire contract has no field for it). The LP's speed bound stays the library's default (it
/// scales the objective and the feedback field); the reference is timed at `options.speed`.
fn planner_options(
    options: &ResolvedOptions,
    traversability: &TraversabilityParams,
) -> PlannerOptions {
    PlannerOptions {
        grid_size: options.grid_size,
        directions: options.directions,
        basis: options.basis,
        speed: options.speed,
        start_density: options.start_density,
        traversability: *traversability,
        dt: options.sample_period,
        solver: options.solver,
        max_solve_time: options.max_solve_time,
        ..PlannerOptions::default()
    }
}

/// Plans `request` through the planner's own pipeline ([`PreparedMap::plan`]), with the
/// generators from the service's shared cache, on the service's cost model `traversability`
/// widened for the request's start uncertainty ([`ValidatedRequest::traversability`]).
pub fn plan(
    request: &ValidatedRequest,
    cache: &GeneratorCache,
    traversability: &TraversabilityParams,
) -> Result<PlanOutcome, Rejection> {
    let started = Instant::now();
    let traversability = &request.traversability(traversability);
    let map = &*block_steep_cells(
        &request.map.map,
        request.map.knowledge.as_ref(),
        traversability,
    );
    let options = planner_options(&request.options, traversability);
    // max_solve_time bounds the P-F computation from the moment a worker takes the request:
    // traversability and grid, generators (unless cached), then the LP, checked inside both.
    let deadline = Deadline::after(started, options.max_solve_time);
    // Unknown cells cost the map's prior; the blocked cells, and so the cached generators,
    // depend only on the known obstacles: a map update that reveals heights re-solves only.
    let field =
        TraversabilityField::from_partial_map(map, request.map.knowledge.as_ref(), traversability)?;
    let grid = PlanningGrid::from_field(map, &field, options.grid_size)?;
    // A robot believed on a blocked cell (it slipped onto a flank, or the margin grew round it)
    // is led off by the shortest way: the plan starts at the nearest free cell within its reach
    // (footprint and margin, plus a cell's diagonal); farther in, the start stays refused.
    let reach = traversability.footprint_radius_m + grid.cell_size * std::f64::consts::SQRT_2;
    let start = match grid.nearest_free_point(request.start, reach) {
        Some(free) if free != request.start => {
            info!(request_id = request.request_id, from = ?request.start, to = ?free, "start moved off a blocked cell");
            free
        }
        _ => request.start,
    };
    let prepared = PreparedMap {
        map,
        field: &field,
        grid: &grid,
    };
    let mut from_cache = |grid: &PlanningGrid, basis: &BasisKind, directions: usize, deadline| {
        let (generators, hit) = cache.get(grid, basis, directions, deadline);
        generators.map(|g| (g, hit))
    };
    let plan = prepared.plan(
        start,
        request.start_yaw,
        &request.goal,
        request.method,
        &options,
        deadline,
        &mut from_cache,
    )?;
    let samples: Vec<TrajectorySample> = plan
        .trajectory
        .iter()
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
    let feedback_field = match &plan.feedback_field {
        Ok(grid) => Some(feedback_field_message(grid)),
        Err(reason) => {
            if request.method == pf_planner::plan::Method::Pf {
                warn!(request_id = request.request_id, %reason, "P-F plan without a feedback field");
            }
            None
        }
    };
    Ok(PlanOutcome {
        metrics: plan_metrics(&plan, &request.goal),
        samples,
        cache_hit: plan.generators_cached,
        feedback_field,
    })
}

/// The reply's metrics of a plan.
fn plan_metrics(plan: &Plan, goal: &GoalRegion) -> PlanMetrics {
    let mut metrics = PlanMetrics {
        lp_status: PlanMetrics::LP_NOT_APPLICABLE,
        cache_hit: plan.generators_cached,
        cost: plan.metrics.cost_integral,
        length: plan.metrics.length,
        duration: plan.trajectory.last().map_or(0.0, |s| s.t),
        reached_goal: plan.path.last().is_some_and(|&p| goal.contains(p)),
        ..PlanMetrics::default()
    };
    match &plan.lp {
        None => {
            metrics.solve_phase_time = plan.solve_time_s;
            metrics.path_time = plan.trajectory_time_s;
            metrics.objective = plan.planner_cost;
            metrics.expanded_nodes = plan
                .expanded
                .map_or(0, |n| i64::try_from(n).unwrap_or(i64::MAX));
        }
        Some(lp) => {
            metrics.generator_time = lp.generator_time_s;
            metrics.solve_phase_time = lp.solve_time_s;
            // The feedback-law integration (what the method took beyond generators and LP)
            // plus the path metrics and the re-timed reference.
            metrics.path_time = (plan.solve_time_s - lp.generator_time_s - lp.solve_time_s)
                .max(0.0)
                + plan.trajectory_time_s;
            metrics.objective = lp.objective;
            metrics.lp_status = lp_status_code(lp.status);
            metrics.lp_iterations = i32::try_from(lp.iterations).unwrap_or(i32::MAX);
            metrics.lp_solver = lp_solver_code(lp.solver);
            metrics.primal_residual = lp.certificate.primal_residual;
            metrics.dual_residual = lp.certificate.dual_residual;
            metrics.duality_gap = lp.certificate.duality_gap;
            metrics.certified = lp.certificate.holds();
            metrics.certificate_tolerance = lp.certificate.tolerance;
        }
    }
    metrics
}

#[cfg(test)]
mod tests {
    use lcm_types::pfnav::PlanRequest;
    use pf_planner::map::GridMap;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::convert::ReceivedMap;
    use crate::convert::{partial_map_to_message, validate_request, MapSource, OptionDefaults};

    struct NoMaps;
    impl MapSource for NoMaps {
        fn map_by_seq(&self, _seq: i64) -> Option<(i64, Arc<ReceivedMap>)> {
            None
        }
    }

    const RESOLUTION: f64 = 0.0625;
    const FOOTPRINT: f64 = 0.25;

    /// Flat 8 m × 6 m ground with a wall across x = 4 m and a 2 m gap at y = 2 … 4 m.
    fn gap_map() -> GridMap {
        let (width, height) = (128, 96);
        let obstacles = (0..width * height)
            .map(|i| {
                let (x, y) = (
                    (i % width) as f64 * RESOLUTION,
                    (i / width) as f64 * RESOLUTION,
                );
                (4.0..4.25).contains(&x) && !(2.0..4.0).contains(&y)
            })
            .collect();
        GridMap::new(
            [0.0, 0.0],
            RESOLUTION,
            width,
            height,
            vec![0.0; width * height],
            Some(obstacles),
        )
        .expect("valid map")
    }

    /// The P-F reference round the gap's lower corner from (1, 1) to (7, 1) for a start known to
    /// `sigma`.
    fn reference(map: &GridMap, sigma: f64, kappa: f64) -> Vec<[f64; 2]> {
        let request = PlanRequest {
            request_id: 1,
            num_inline_maps: 1,
            inline_map: vec![partial_map_to_message(map, None, 1)],
            start_x: 1.0,
            start_y: 1.0,
            goal_x: 7.0,
            goal_y: 1.0,
            goal_radius: 0.3,
            method: PlanRequest::METHOD_PF,
            start_sigma: sigma,
            options: lcm_types::pfnav::PlanOptions {
                confidence_sigmas: kappa,
                ..Default::default()
            },
            ..PlanRequest::default()
        };
        let validated = validate_request(&request, &NoMaps, 1 << 20, &OptionDefaults::default())
            .expect("valid request");
        let service = TraversabilityParams {
            footprint_radius_m: FOOTPRINT,
            ..TraversabilityParams::default()
        };
        let outcome = plan(&validated, &GeneratorCache::new(1), &service).expect("plan");
        outcome.samples.iter().map(|s| [s.x, s.y]).collect()
    }

    /// Share of a Gaussian belief N(point, σ²I) whose footprint (radius FOOTPRINT, cell centres
    /// as the planner counts them) covers an obstacle cell, by Monte Carlo.
    fn hit_share(point: [f64; 2], sigma: f64, obstacles: &[[f64; 2]], rng: &mut ChaCha8Rng) -> f64 {
        let draws = 2000;
        let hits = (0..draws)
            .filter(|_| {
                // Box–Muller: two standard normals.
                let (u, v): (f64, f64) = (rng.random::<f64>().max(1e-300), rng.random());
                let radius = sigma * (-2.0 * u.ln()).sqrt();
                let (dx, dy) = (
                    radius * (std::f64::consts::TAU * v).cos(),
                    radius * (std::f64::consts::TAU * v).sin(),
                );
                obstacles
                    .iter()
                    .any(|o| (o[0] - point[0] - dx).hypot(o[1] - point[1] - dy) <= FOOTPRINT)
            })
            .count();
        hits as f64 / draws as f64
    }

    /// The stated bound: with the footprint widened by κσ, a path point's true footprint reaches
    /// an obstacle only if the robot is more than κσ (less the half-diagonal of a cell, the
    /// planner's resolution) off its belief, which a Gaussian belief is with probability
    /// exp(−(κσ − res/√2)²/(2σ²)). The plan that ignores σ passes the gap's corner closer and
    /// sends more than that into the wall (σ = 0.2 m, κ = 2: bound 0.205; measured 0.018 with
    /// the margin, 0.36 without).
    #[test]
    fn the_belief_mass_sent_into_obstacles_is_bounded() {
        let map = gap_map();
        let obstacles: Vec<[f64; 2]> = (0..map.len())
            .filter(|&i| map.obstacles.as_ref().is_some_and(|m| m[i]))
            .map(|i| {
                [
                    ((i % map.width) as f64 + 0.5) * RESOLUTION,
                    ((i / map.width) as f64 + 0.5) * RESOLUTION,
                ]
            })
            .collect();
        let (sigma, kappa) = (0.2, 2.0);
        let margin = kappa * sigma - RESOLUTION * std::f64::consts::FRAC_1_SQRT_2;
        let bound = (-margin * margin / (2.0 * sigma * sigma)).exp();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let worst = |path: &[[f64; 2]], rng: &mut ChaCha8Rng| {
            path.iter()
                .map(|&p| hit_share(p, sigma, &obstacles, rng))
                .fold(0.0, f64::max)
        };
        let careful = reference(&map, sigma, kappa);
        let careless = reference(&map, 0.0, kappa);
        assert!(careful.len() > 10 && careless.len() > 10);
        let (careful_share, careless_share) =
            (worst(&careful, &mut rng), worst(&careless, &mut rng));
        // Monte Carlo error of 2000 draws at p ≈ 0.2: σ ≈ 0.009.
        assert!(
            careful_share <= bound + 0.03,
            "belief mass into the wall {careful_share:.3} > bound {bound:.3}"
        );
        assert!(
            careless_share > bound + 0.1,
            "the plan without margin sends only {careless_share:.3} (bound {bound:.3})"
        );
    }

    /// A start on the wall's edge (a robot that slipped onto it) gets a plan from the nearest
    /// free cell; a start deep inside the wall is still refused.
    #[test]
    fn a_start_on_a_blocked_cell_is_led_off_it() {
        let map = gap_map();
        let plan_from = |x: f64| {
            let request = PlanRequest {
                request_id: 1,
                num_inline_maps: 1,
                inline_map: vec![partial_map_to_message(&map, None, 1)],
                start_x: x,
                start_y: 1.0,
                goal_x: 7.0,
                goal_y: 1.0,
                goal_radius: 0.3,
                method: PlanRequest::METHOD_PF,
                ..PlanRequest::default()
            };
            let validated =
                validate_request(&request, &NoMaps, 1 << 20, &OptionDefaults::default())
                    .expect("valid request");
            let service = TraversabilityParams {
                footprint_radius_m: FOOTPRINT,
                ..TraversabilityParams::default()
            };
            plan(&validated, &GeneratorCache::new(1), &service)
        };
        // The wall spans x = 4 … 4.25 m: 4.02 m is on its edge, a cell off the free side.
        let outcome = plan_from(4.02).expect("led off the wall");
        let first = outcome.samples.first().expect("a trajectory");
        assert!(
            first.x < 4.0 && (first.x - 4.02).abs() < FOOTPRINT + 0.1,
            "starts at {}",
            first.x
        );
        let last = outcome.samples.last().expect("a trajectory");
        assert!(
            (last.x - 7.0).hypot(last.y - 1.0) <= 0.35,
            "ends at ({}, {})",
            last.x,
            last.y
        );
        // A wall 0.25 m thick has no cell deeper than 0.125 m from free ground: use a start
        // that is off the map's free cells by more than the reach instead (none).
        let refused = plan_from(-1.0).expect_err("off the map");
        assert!(refused.reason.contains("off the map"), "{}", refused.reason);
    }
}
