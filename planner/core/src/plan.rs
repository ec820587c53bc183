//! The planner's front door: one request in, one plan (path, reference trajectory, metrics) out.
//! Used by the `pf-plan` CLI and the LCM service alike.
//!
//! [`Planner`] keeps the resampled grid and the P-F generators of one map, so repeated requests
//! on the same map (a service, or `--method all`) do not rebuild them; [`plan`] is the one-shot form.

use std::fmt;
use std::str::FromStr;
use std::sync::Arc;
use std::time::Instant;

use tracing::info;

use crate::deadline::Deadline;
use crate::error::PlanError;
use crate::feedback::FeedbackField;
use crate::feedback_grid::{FeedbackGrid, FieldUnavailable};
use crate::graph::{astar_admissible_path, astar_path, dijkstra_path, Connectivity, GraphPath};
use crate::grid::{GoalRegion, PlanningGrid};
use crate::lp::LpSolver;
use crate::map::{GridMap, Point};
use crate::metrics::{evaluate_path, PathMetrics};
use crate::pf::{self, BasisKind, LpReport, LpSettings, PfGenerators, PfOptions, StartDensity};
pub use crate::trajectory::TrajectorySample;
use crate::trajectory::{build_trajectory, TrajectoryOptions};
use crate::traversability::{block_steep_cells, TraversabilityField, TraversabilityParams};

/// Planning method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Method {
    /// The Perron-Frobenius density-space LP with the feedback law.
    Pf,
    /// A* with the Euclidean heuristic (the paper's baseline; inadmissible where p < 1).
    AStar,
    /// A* with the admissible, consistent heuristic p_min × distance to the goal
    /// ([`crate::graph::astar_admissible_path`]): Dijkstra's optimum with fewer expansions.
    AStarAdmissible,
    /// Dijkstra (the graph optimum).
    Dijkstra,
}

impl Method {
    /// Every method, in report order.
    pub const ALL: [Method; 4] = [
        Method::Pf,
        Method::AStar,
        Method::AStarAdmissible,
        Method::Dijkstra,
    ];

    /// Short name used on the command line and in file names.
    pub fn name(self) -> &'static str {
        match self {
            Method::Pf => "pf",
            Method::AStar => "astar",
            Method::AStarAdmissible => "astar-admissible",
            Method::Dijkstra => "dijkstra",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Method {
    type Err = PlanError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Method::ALL
            .into_iter()
            .find(|method| method.name() == s)
            .ok_or_else(|| PlanError::InvalidOption {
                name: "method",
                reason: format!(
                    "unknown method {s:?}; use one of {}",
                    Method::ALL.map(Method::name).join(", ")
                ),
            })
    }
}

/// Everything a request can tune.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannerOptions {
    /// Planning cells along the map's longer side.
    pub grid_size: usize,
    /// 4 or 8 move directions (P-F flux directions and graph connectivity alike).
    pub directions: usize,
    /// P-F basis.
    pub basis: BasisKind,
    /// Nominal speed of the reference trajectory, m/s.
    pub speed: f64,
    /// Speed bound of the P-F LP (scales its objective only; the trajectory is re-timed at `speed`).
    pub u_max: f64,
    /// Initial density of the P-F LP.
    pub start_density: StartDensity,
    /// Traversability model.
    pub traversability: TraversabilityParams,
    /// Sample period of the reference trajectory, seconds.
    pub dt: f64,
    /// Solver of the P-F LP.
    pub solver: LpSolver,
    /// Wall-clock limit of the P-F computation (generator build and LP), seconds
    /// (`f64::INFINITY` for none); reached: [`PlanError::TimeLimit`].
    pub max_solve_time: f64,
}

impl Default for PlannerOptions {
    fn default() -> Self {
        Self {
            grid_size: 64,
            directions: 8,
            basis: BasisKind::Indicator,
            speed: 0.5,
            u_max: 1.0,
            start_density: StartDensity::default(),
            traversability: TraversabilityParams::default(),
            dt: 0.1,
            solver: LpSolver::default(),
            max_solve_time: f64::INFINITY,
        }
    }
}

/// A planning request.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanRequest {
    pub map: GridMap,
    pub start: Point,
    pub start_yaw: f64,
    pub goal: GoalRegion,
    pub method: Method,
    pub options: PlannerOptions,
}

/// A planning answer.
#[derive(Debug, Clone)]
pub struct Plan {
    pub method: Method,
    /// The continuous path (polyline), start first, ending at the goal's centre (or, when the
    /// straight way there from where the path enters the goal region is blocked, at that entry).
    pub path: Vec<Point>,
    /// The time-parameterised reference along `path`.
    pub trajectory: Vec<TrajectorySample>,
    /// The shared metric, measured on the map.
    pub metrics: PathMetrics,
    /// The method's own optimal value on the planning grid: graph path cost for A*/Dijkstra,
    /// LP objective / (1 + 1/u_max) for P-F (the latter summed over the start density's mass).
    pub planner_cost: f64,
    /// Nodes expanded (graph methods).
    pub expanded: Option<usize>,
    /// LP report (P-F).
    pub lp: Option<LpReport>,
    /// Wall-clock time of the method (P-F: generators, unless cached, plus LP and integration), seconds.
    pub solve_time_s: f64,
    /// Wall-clock time of the path metrics and the re-timed reference, seconds.
    pub trajectory_time_s: f64,
    /// Whether the P-F generators came from a cache (always false for graph methods).
    pub generators_cached: bool,
    /// The optimal feedback law on the planning grid (P-F; speed = the request's `speed`), or
    /// why there is none (graph methods; Clarabel with a point start). Computed with every P-F
    /// plan at O(cells × directions).
    pub feedback_field: Result<FeedbackGrid, FieldUnavailable>,
    /// The LP's density and flux (P-F; `None` for graph methods), kept as solved: its occupation
    /// density ([`FeedbackField::density_on`]) is evaluated only by those who ask for it.
    pub lp_flow: Option<FeedbackField>,
}

/// Where the P-F generators of a plan come from: `(generators, taken from a cache)` for a grid,
/// basis and direction count, built no later than the deadline. [`Planner`] keeps the last set;
/// the LCM service shares an LRU cache between its workers.
pub type GeneratorLookup<'a, E> = dyn FnMut(&PlanningGrid, &BasisKind, usize, Deadline) -> Result<(Arc<PfGenerators>, bool), E>
    + 'a;

/// A map prepared for planning, by reference: the one planning pipeline behind
/// [`Planner::plan`] and the LCM service.
pub struct PreparedMap<'a> {
    /// The terrain.
    pub map: &'a GridMap,
    /// p on the map.
    pub field: &'a TraversabilityField,
    /// The planning grid resampled from `field`.
    pub grid: &'a PlanningGrid,
}

impl PreparedMap<'_> {
    /// Plans from `start` to `goal` with `method`; `deadline` bounds the P-F computation
    /// (generators, unless cached, and the LP). Endpoints and options are checked first.
    #[allow(clippy::too_many_arguments)]
    pub fn plan<E: From<PlanError>>(
        &self,
        start: Point,
        start_yaw: f64,
        goal: &GoalRegion,
        method: Method,
        options: &PlannerOptions,
        deadline: Deadline,
        generators: &mut GeneratorLookup<'_, E>,
    ) -> Result<Plan, E> {
        let trajectory_options = TrajectoryOptions {
            speed: options.speed,
            dt: options.dt,
            ..TrajectoryOptions::default()
        };
        trajectory_options.validate()?;
        let connectivity = Connectivity::from_directions(options.directions)?;
        check_endpoints(self.map, start, start_yaw, goal)?;
        let started = Instant::now();
        let mut generators_cached = false;
        let mut feedback_field = Err(FieldUnavailable::NotPf {
            method: method.name(),
        });
        let mut lp_flow = None;
        let (path, planner_cost, expanded, lp) = match method {
            Method::Dijkstra => graph_plan(dijkstra_path(self.grid, start, goal, connectivity)?),
            Method::AStar => graph_plan(astar_path(self.grid, start, goal, connectivity)?),
            Method::AStarAdmissible => {
                graph_plan(astar_admissible_path(self.grid, start, goal, connectivity)?)
            }
            Method::Pf => {
                options.basis.validate()?;
                let built = Instant::now();
                let (pf_generators, cached) =
                    generators(self.grid, &options.basis, options.directions, deadline)?;
                generators_cached = cached;
                let generator_time_s = if cached {
                    0.0
                } else {
                    built.elapsed().as_secs_f64()
                };
                deadline.check("the generator build")?;
                let pf_options = PfOptions {
                    u_max: options.u_max,
                    start_density: options.start_density,
                    lp: LpSettings {
                        solver: options.solver,
                        time_limit_s: deadline.remaining_s(),
                        ..LpSettings::default()
                    },
                    ..PfOptions::default()
                };
                // The LP ran on the time left; a timeout there names the request's limit.
                let solution = pf::solve(&pf_generators, self.grid, start, goal, &pf_options)
                    .map_err(|error| deadline.restate(error))?;
                if !solution.outcome.reached_goal() {
                    return Err(PlanError::TrajectoryFailed {
                        reason: format!("{:?}", solution.outcome),
                    }
                    .into());
                }
                let mut lp = solution.lp;
                lp.generator_time_s = generator_time_s;
                feedback_field = solution.feedback_grid.map(|mut grid| {
                    grid.set_speed(options.speed);
                    grid
                });
                lp_flow = Some(solution.field);
                (solution.path, solution.weighted_length, None, Some(lp))
            }
        };
        let solve_time_s = started.elapsed().as_secs_f64();
        let retimed = Instant::now();
        let mut path = path;
        walk_into_goal(self.grid, &mut path, goal);
        let metrics = evaluate_path(self.map, self.field, &path);
        let trajectory = build_trajectory(self.map, &path, start_yaw, &trajectory_options)?;
        let trajectory_time_s = retimed.elapsed().as_secs_f64();
        info!(
            %method,
            cost_integral = metrics.cost_integral,
            length = metrics.length,
            solve_time_s,
            generators_cached,
            "plan ready"
        );
        Ok(Plan {
            method,
            path,
            trajectory,
            metrics,
            planner_cost,
            expanded,
            lp,
            solve_time_s,
            trajectory_time_s,
            generators_cached,
            feedback_field,
            lp_flow,
        })
    }
}

/// A graph-search result as `(path, planner cost, nodes expanded, no LP report)`.
fn graph_plan(found: GraphPath) -> (Vec<Point>, f64, Option<usize>, Option<LpReport>) {
    (found.points, found.cost, Some(found.expanded), None)
}

/// A map prepared for planning: traversability, planning grid and cached P-F generators.
pub struct Planner {
    map: GridMap,
    traversability: TraversabilityParams,
    grid_size: usize,
    field: TraversabilityField,
    grid: PlanningGrid,
    pf_cache: Option<(BasisKind, usize, Arc<PfGenerators>)>,
}

impl Planner {
    /// Evaluates p on `map` and resamples it to `grid_size` cells along the longer side.
    pub fn new(
        map: GridMap,
        traversability: TraversabilityParams,
        grid_size: usize,
    ) -> Result<Self, PlanError> {
        let map = block_steep_cells(&map, None, &traversability).into_owned();
        let field = TraversabilityField::from_map(&map, &traversability)?;
        let grid = PlanningGrid::from_field(&map, &field, grid_size)?;
        Ok(Self {
            map,
            traversability,
            grid_size,
            field,
            grid,
            pf_cache: None,
        })
    }

    /// The terrain.
    pub fn map(&self) -> &GridMap {
        &self.map
    }

    /// p on the map.
    pub fn field(&self) -> &TraversabilityField {
        &self.field
    }

    /// The planning grid.
    pub fn grid(&self) -> &PlanningGrid {
        &self.grid
    }

    /// Plans from `start` to `goal` with `method`. A grid size or traversability model different
    /// from the prepared one rebuilds the grid (and drops cached generators).
    pub fn plan(
        &mut self,
        start: Point,
        start_yaw: f64,
        goal: &GoalRegion,
        method: Method,
        options: &PlannerOptions,
    ) -> Result<Plan, PlanError> {
        if options.grid_size != self.grid_size || options.traversability != self.traversability {
            *self = Planner::new(self.map.clone(), options.traversability, options.grid_size)?;
        }
        // max_solve_time bounds the whole P-F computation: generators, then the LP.
        let deadline = Deadline::after(Instant::now(), options.max_solve_time);
        let prepared = PreparedMap {
            map: &self.map,
            field: &self.field,
            grid: &self.grid,
        };
        let cache = &mut self.pf_cache;
        let mut last_set = |grid: &PlanningGrid,
                            basis: &BasisKind,
                            directions: usize,
                            deadline: Deadline|
         -> Result<(Arc<PfGenerators>, bool), PlanError> {
            if let Some((b, d, g)) = cache.as_ref() {
                if b == basis && *d == directions && g.matches(grid) {
                    return Ok((Arc::clone(g), true));
                }
            }
            let built = Arc::new(PfGenerators::build_until(
                grid, basis, directions, deadline,
            )?);
            *cache = Some((*basis, directions, Arc::clone(&built)));
            Ok((built, false))
        };
        prepared.plan(
            start,
            start_yaw,
            goal,
            method,
            options,
            deadline,
            &mut last_set,
        )
    }
}

/// Start and goal against the map itself (the grid adds its padding later).
/// Continues `path` from where it entered the goal region straight to the goal's centre, when
/// that segment is free: a plan that ends on the region's rim leaves a robot no room for tracking
/// or localisation error, and it stops just outside as often as just inside.
pub fn walk_into_goal(grid: &PlanningGrid, path: &mut Vec<Point>, goal: &GoalRegion) {
    let Some(&last) = path.last() else {
        return;
    };
    let centre = goal.center;
    let remaining = (centre[0] - last[0]).hypot(centre[1] - last[1]);
    // A zero-radius goal is the cell containing its centre.
    let in_goal = goal.contains(last) || grid.cell_of(last) == grid.cell_of(centre);
    if in_goal && remaining > 1e-9 && grid.segment_is_free(last, centre) {
        path.push(centre);
    }
}

fn check_endpoints(
    map: &GridMap,
    start: Point,
    start_yaw: f64,
    goal: &GoalRegion,
) -> Result<(), PlanError> {
    if !map.contains(start) {
        return Err(PlanError::StartOffMap { point: start });
    }
    if !start_yaw.is_finite() {
        return Err(PlanError::InvalidOption {
            name: "start_yaw",
            reason: format!("{start_yaw} is not finite"),
        });
    }
    if map.is_obstacle_at(start) {
        return Err(PlanError::StartInObstacle { point: start });
    }
    if !map.contains(goal.center) {
        return Err(PlanError::GoalOffMap { point: goal.center });
    }
    if !(goal.radius.is_finite() && goal.radius >= 0.0) {
        return Err(PlanError::InvalidOption {
            name: "goal.radius",
            reason: format!("{} must be finite and >= 0", goal.radius),
        });
    }
    if map.is_obstacle_at(goal.center) {
        return Err(PlanError::GoalInObstacle { point: goal.center });
    }
    Ok(())
}

/// One-shot planning: prepares the map and plans once.
pub fn plan(req: &PlanRequest) -> Result<Plan, PlanError> {
    let mut planner = Planner::new(
        req.map.clone(),
        req.options.traversability,
        req.options.grid_size,
    )?;
    planner.plan(
        req.start,
        req.start_yaw,
        &req.goal,
        req.method,
        &req.options,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 10 × 10 cells of 1 m, origin at 0; `wall` blocks the cells of column 6, rows 3..=6.
    fn grid(wall: bool) -> PlanningGrid {
        let blocked = (0..100)
            .map(|i| wall && i % 10 == 6 && (3..=6).contains(&(i / 10)))
            .collect();
        PlanningGrid::from_parts([0.0, 0.0], 1.0, 10, 10, vec![0.1; 100], blocked).expect("grid")
    }

    const GOAL: GoalRegion = GoalRegion {
        center: [7.5, 5.5],
        radius: 2.0,
    };

    #[test]
    fn a_path_that_stops_on_the_goal_rim_goes_on_to_the_centre() {
        let mut path = vec![[1.5, 5.5], [5.5, 5.5]];
        walk_into_goal(&grid(false), &mut path, &GOAL);
        assert_eq!(path, vec![[1.5, 5.5], [5.5, 5.5], GOAL.center]);
    }

    #[test]
    fn a_blocked_way_to_the_centre_leaves_the_path_at_its_entry() {
        let mut path = vec![[1.5, 5.5], [5.5, 5.5]];
        walk_into_goal(&grid(true), &mut path, &GOAL);
        assert_eq!(path, vec![[1.5, 5.5], [5.5, 5.5]]);
    }

    #[test]
    fn a_path_outside_the_goal_or_at_its_centre_is_left_alone() {
        let mut outside = vec![[1.5, 5.5], [3.5, 5.5]];
        walk_into_goal(&grid(false), &mut outside, &GOAL);
        assert_eq!(outside.len(), 2);
        let mut at_centre = vec![[1.5, 5.5], GOAL.center];
        walk_into_goal(&grid(false), &mut at_centre, &GOAL);
        assert_eq!(at_centre.len(), 2);
    }

    #[test]
    fn a_zero_radius_goal_is_entered_through_its_cell() {
        let goal = GoalRegion {
            center: [7.2, 5.7],
            radius: 0.0,
        };
        let mut path = vec![[1.5, 5.5], [7.5, 5.5]];
        walk_into_goal(&grid(false), &mut path, &goal);
        assert_eq!(path.last(), Some(&goal.center));
    }
}
