//! Graph-search baselines on the planning grid: Dijkstra, A* with the paper's Euclidean heuristic,
//! A* with an admissible and consistent heuristic (same optimum as Dijkstra, fewer expansions),
//! and cost-to-go to a target set (the reference the P-F LP optimum is checked against).
//!
//! Graph: one node per free cell; an edge to each 4- or 8-neighbour that is free, with weight
//! `p(source cell) × step length` (`cell_size` axial, `√2·cell_size` diagonal). A diagonal step
//! is only allowed when both cells it passes the corner of are free, so the straight segment
//! between the two centres never touches a blocked cell's interior.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::error::PlanError;
use crate::grid::{GoalRegion, PlanningGrid};
use crate::map::Point;

/// Neighbourhood of a grid cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Connectivity {
    /// ±x, ±y.
    Four,
    /// ±x, ±y and the four diagonals.
    Eight,
}

impl Connectivity {
    /// Maps a direction count (4 or 8) to a connectivity.
    pub fn from_directions(directions: usize) -> Result<Self, PlanError> {
        match directions {
            4 => Ok(Self::Four),
            8 => Ok(Self::Eight),
            other => Err(PlanError::InvalidOption {
                name: "directions",
                reason: format!("must be 4 or 8, got {other}"),
            }),
        }
    }

    /// Number of directions (4 or 8).
    pub fn directions(self) -> usize {
        match self {
            Self::Four => 4,
            Self::Eight => 8,
        }
    }

    /// Unit-cell offsets `(dx, dy)` of the neighbours.
    pub fn offsets(self) -> &'static [(i64, i64)] {
        const FOUR: [(i64, i64); 4] = [(1, 0), (-1, 0), (0, 1), (0, -1)];
        const EIGHT: [(i64, i64); 8] = [
            (1, 0),
            (-1, 0),
            (0, 1),
            (0, -1),
            (1, 1),
            (-1, 1),
            (1, -1),
            (-1, -1),
        ];
        match self {
            Self::Four => &FOUR,
            Self::Eight => &EIGHT,
        }
    }
}

/// A path found by graph search.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphPath {
    /// Row-major indices of the visited cells, start cell first, a goal cell last.
    pub cells: Vec<usize>,
    /// The polyline: the exact start point, then the centre of every cell of `cells`.
    pub points: Vec<Point>,
    /// Sum of edge weights along `cells` (p(source) × step), i.e. the graph's own cost.
    pub cost: f64,
    /// Nodes taken off the priority queue.
    pub expanded: usize,
}

/// Free neighbours of `cell` with the step length to each, honouring the no-corner-cutting rule.
pub fn neighbours(
    grid: &PlanningGrid,
    cell: usize,
    conn: Connectivity,
) -> impl Iterator<Item = (usize, f64)> + '_ {
    let (ix, iy) = grid.coords(cell);
    let (w, h) = (grid.width as i64, grid.height as i64);
    let diagonal = std::f64::consts::SQRT_2 * grid.cell_size;
    conn.offsets().iter().filter_map(move |&(dx, dy)| {
        let (nx, ny) = (ix as i64 + dx, iy as i64 + dy);
        if nx < 0 || ny < 0 || nx >= w || ny >= h {
            return None;
        }
        let next = grid.index(nx as usize, ny as usize);
        if grid.blocked[next] {
            return None;
        }
        if dx != 0 && dy != 0 {
            let side_a = grid.index(nx as usize, iy);
            let side_b = grid.index(ix, ny as usize);
            if grid.blocked[side_a] || grid.blocked[side_b] {
                return None;
            }
            Some((next, diagonal))
        } else {
            Some((next, grid.cell_size))
        }
    })
}

/// Cost-to-go from every cell to the target set: `d(u) = min_v p(u)·step(u, v) + d(v)`, 0 on free
/// targets, `f64::INFINITY` where unreachable and on blocked cells. Out-of-range or blocked target
/// indices are ignored.
pub fn distances_to_targets(
    grid: &PlanningGrid,
    targets: &[usize],
    conn: Connectivity,
) -> Vec<f64> {
    let mut dist = vec![f64::INFINITY; grid.len()];
    let mut heap = BinaryHeap::new();
    for &t in targets {
        if t < grid.len() && !grid.blocked[t] && dist[t] > 0.0 {
            dist[t] = 0.0;
            heap.push(Entry { key: 0.0, cell: t });
        }
    }
    while let Some(Entry { key, cell }) = heap.pop() {
        if key > dist[cell] {
            continue;
        }
        // The neighbourhood is symmetric (including the corner rule), so the predecessors of
        // `cell` are exactly its neighbours; the edge u → cell is paid at p(u).
        for (prev, step) in neighbours(grid, cell, conn) {
            let candidate = key + grid.cost[prev] * step;
            if candidate < dist[prev] {
                dist[prev] = candidate;
                heap.push(Entry {
                    key: candidate,
                    cell: prev,
                });
            }
        }
    }
    dist
}

/// Shortest path from `start` to the goal region (Dijkstra, exact optimum on the graph).
pub fn dijkstra_path(
    grid: &PlanningGrid,
    start: Point,
    goal: &GoalRegion,
    conn: Connectivity,
) -> Result<GraphPath, PlanError> {
    search(grid, start, goal, conn, |_: &[usize]| |_: Point| 0.0)
}

/// A* with the plain Euclidean distance to the goal centre as heuristic: the paper's baseline.
/// Because edge weights are p × step with p < 1, the heuristic over-estimates the cost-to-go
/// (it is inadmissible), so the path is in general not optimal — which is the paper's point.
/// Closed nodes are never reopened (textbook graph-search A*).
pub fn astar_path(
    grid: &PlanningGrid,
    start: Point,
    goal: &GoalRegion,
    conn: Connectivity,
) -> Result<GraphPath, PlanError> {
    let center = goal.center;
    search(grid, start, goal, conn, |_: &[usize]| {
        move |p: Point| (p[0] - center[0]).hypot(p[1] - center[1])
    })
}

/// A* with an admissible and consistent heuristic: it returns a path of Dijkstra's optimal cost
/// (up to floating-point rounding) while expanding no more nodes than Dijkstra.
///
/// Heuristic: `h(x) = p_min · max(0, ‖x − goal.center‖ − R)`, where
/// - `p_min` is the smallest p over the free cells of this grid (≥ the traversability model's
///   p_floor > 0): every edge leaves a free cell, so every edge weight `p(u)·step(u, v)` is at
///   least `p_min · ‖c_u − c_v‖` (a step is exactly the distance between the two cell centres);
/// - `R` is the largest distance from the goal centre to the centre of a free goal cell of
///   [`PlanningGrid::goal_cells`] (at most `max(radius, cell_size·√2/2)`: those are the cells
///   whose centre lies in the disc plus the cell containing the centre), so `h = 0` on every
///   goal cell and, by the triangle inequality, `h(x) ≤ p_min · ‖x − c_g‖` for every goal cell g.
///
/// Consistency: `D(x) = max(0, ‖x − center‖ − R)` is 1-Lipschitz, so for every edge u → v
/// `h(u) − h(v) ≤ p_min·‖c_u − c_v‖ ≤ p(u)·step(u, v)`. A consistent heuristic that vanishes on
/// the targets is admissible, and graph-search A* that never reopens closed nodes is then
/// optimal. Each node costs O(1) to evaluate, whatever the goal's size.
pub fn astar_admissible_path(
    grid: &PlanningGrid,
    start: Point,
    goal: &GoalRegion,
    conn: Connectivity,
) -> Result<GraphPath, PlanError> {
    search(grid, start, goal, conn, |targets: &[usize]| {
        let heuristic = AdmissibleHeuristic::from_targets(grid, goal.center, targets);
        move |p: Point| heuristic.at(p)
    })
}

/// The heuristic of [`astar_admissible_path`]: a lower bound on the cost-to-go from any point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdmissibleHeuristic {
    /// Smallest p over the free cells of the grid.
    pub p_min: f64,
    /// Goal centre.
    pub center: Point,
    /// Largest distance from `center` to the centre of a free goal cell.
    pub reach: f64,
}

impl AdmissibleHeuristic {
    /// The heuristic towards the free goal cells `targets` (as [`PlanningGrid::goal_cells`]
    /// returns them) of the goal centred at `center`. With no target it is 0 everywhere.
    pub fn from_targets(grid: &PlanningGrid, center: Point, targets: &[usize]) -> Self {
        let reach = targets
            .iter()
            .map(|&t| {
                let c = grid.center_of_index(t);
                (c[0] - center[0]).hypot(c[1] - center[1])
            })
            .fold(0.0, f64::max);
        // 0 without a free cell (nothing to search then): the heuristic stays finite.
        let p_min = grid
            .cost
            .iter()
            .zip(&grid.blocked)
            .filter(|(_, &blocked)| !blocked)
            .map(|(&p, _)| p)
            .reduce(f64::min)
            .unwrap_or(0.0);
        let p_min = if targets.is_empty() { 0.0 } else { p_min };
        Self {
            p_min,
            center,
            reach,
        }
    }

    /// `p_min · max(0, ‖p − center‖ − reach)`.
    pub fn at(&self, p: Point) -> f64 {
        let distance = (p[0] - self.center[0]).hypot(p[1] - self.center[1]);
        self.p_min * (distance - self.reach).max(0.0)
    }
}

/// Checks the start and the goal against the grid and returns (start cell, goal cells).
pub fn endpoints(
    grid: &PlanningGrid,
    start: Point,
    goal: &GoalRegion,
) -> Result<(usize, Vec<usize>), PlanError> {
    let (sx, sy) = grid
        .cell_of(start)
        .ok_or(PlanError::StartOffMap { point: start })?;
    let start_cell = grid.index(sx, sy);
    if grid.blocked[start_cell] {
        return Err(PlanError::StartInObstacle { point: start });
    }
    if !(goal.radius.is_finite() && goal.radius >= 0.0) {
        return Err(PlanError::InvalidOption {
            name: "goal.radius",
            reason: format!("must be finite and >= 0, got {}", goal.radius),
        });
    }
    if !grid.contains(goal.center) {
        return Err(PlanError::GoalOffMap { point: goal.center });
    }
    let targets = grid.goal_cells(goal);
    if targets.is_empty() {
        return Err(PlanError::GoalInObstacle { point: goal.center });
    }
    Ok((start_cell, targets))
}

/// Graph-search A* from `start` to the goal's cells; `make_heuristic` receives the free goal
/// cells (after the endpoints are checked) and returns the heuristic at a cell centre.
fn search<H: Fn(Point) -> f64>(
    grid: &PlanningGrid,
    start: Point,
    goal: &GoalRegion,
    conn: Connectivity,
    make_heuristic: impl FnOnce(&[usize]) -> H,
) -> Result<GraphPath, PlanError> {
    let (start_cell, targets) = endpoints(grid, start, goal)?;
    let heuristic = make_heuristic(&targets);
    let mut is_target = vec![false; grid.len()];
    for &t in &targets {
        is_target[t] = true;
    }
    let mut g = vec![f64::INFINITY; grid.len()];
    let mut parent = vec![usize::MAX; grid.len()];
    let mut closed = vec![false; grid.len()];
    let mut heap = BinaryHeap::new();
    g[start_cell] = 0.0;
    heap.push(Entry {
        key: heuristic(grid.center_of_index(start_cell)),
        cell: start_cell,
    });
    let mut expanded = 0;
    while let Some(Entry { cell, .. }) = heap.pop() {
        if closed[cell] {
            continue;
        }
        closed[cell] = true;
        expanded += 1;
        if is_target[cell] {
            let mut cells = vec![cell];
            while let Some(&last) = cells.last() {
                if last == start_cell {
                    break;
                }
                cells.push(parent[last]);
            }
            cells.reverse();
            let mut points = Vec::with_capacity(cells.len() + 1);
            points.push(start);
            for &c in &cells {
                let p = grid.center_of_index(c);
                if points.last() != Some(&p) {
                    points.push(p);
                }
            }
            return Ok(GraphPath {
                cells,
                points,
                cost: g[cell],
                expanded,
            });
        }
        for (next, step) in neighbours(grid, cell, conn) {
            if closed[next] {
                continue;
            }
            let candidate = g[cell] + grid.cost[cell] * step;
            if candidate < g[next] {
                g[next] = candidate;
                parent[next] = cell;
                heap.push(Entry {
                    key: candidate + heuristic(grid.center_of_index(next)),
                    cell: next,
                });
            }
        }
    }
    Err(PlanError::Unreachable {
        reason: format!(
            "no free {}-connected path from the start cell to the {} goal cell(s); {expanded} cells explored",
            conn.directions(),
            targets.len()
        ),
    })
}

/// Min-heap entry ordered by `key` (ties broken by cell index for determinism).
#[derive(Debug, Clone, Copy)]
struct Entry {
    key: f64,
    cell: usize,
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        // Reversed: BinaryHeap is a max-heap.
        other
            .key
            .total_cmp(&self.key)
            .then_with(|| other.cell.cmp(&self.cell))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn uniform(w: usize, h: usize, p: f64) -> PlanningGrid {
        PlanningGrid::from_parts([0.0, 0.0], 1.0, w, h, vec![p; w * h], vec![false; w * h])
            .expect("grid")
    }

    #[test]
    fn distances_on_uniform_grid_are_octile_times_p() {
        let grid = uniform(6, 5, 0.5);
        let d8 = distances_to_targets(&grid, &[0], Connectivity::Eight);
        let d4 = distances_to_targets(&grid, &[0], Connectivity::Four);
        for iy in 0..5 {
            for ix in 0..6 {
                let (a, b) = (ix.max(iy) as f64, ix.min(iy) as f64);
                let octile = (a - b) + b * std::f64::consts::SQRT_2;
                let i = grid.index(ix, iy);
                assert!((d8[i] - 0.5 * octile).abs() < 1e-12);
                assert!((d4[i] - 0.5 * (ix + iy) as f64).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn edge_weight_is_paid_at_the_source_cell() {
        // 3 x 1 corridor with p = [0.2, 0.6, 1.0]; target is the right cell.
        let grid =
            PlanningGrid::from_parts([0.0, 0.0], 2.0, 3, 1, vec![0.2, 0.6, 1.0], vec![false; 3])
                .expect("grid");
        let d = distances_to_targets(&grid, &[2], Connectivity::Four);
        assert!((d[1] - 1.2).abs() < 1e-12);
        assert!((d[0] - (0.4 + 1.2)).abs() < 1e-12);
        let path = dijkstra_path(
            &grid,
            [0.5, 1.0],
            &GoalRegion {
                center: [5.0, 1.0],
                radius: 0.0,
            },
            Connectivity::Four,
        )
        .expect("path");
        assert_eq!(path.cells, vec![0, 1, 2]);
        assert!((path.cost - d[0]).abs() < 1e-12);
        assert_eq!(path.points[0], [0.5, 1.0]);
    }

    #[test]
    fn diagonal_steps_do_not_cut_blocked_corners() {
        let mut blocked = vec![false; 4];
        blocked[1] = true; // (1, 0)
        let grid =
            PlanningGrid::from_parts([0.0, 0.0], 1.0, 2, 2, vec![1.0; 4], blocked).expect("grid");
        let d = distances_to_targets(&grid, &[3], Connectivity::Eight);
        // From (0,0) to (1,1): the diagonal passes the corner of blocked (1,0): must go via (0,1).
        assert!((d[0] - 2.0).abs() < 1e-12);
        assert!(d[1].is_infinite());
    }

    #[test]
    fn walled_goal_is_unreachable() {
        let mut blocked = vec![false; 9];
        blocked[1] = true;
        blocked[4] = true;
        blocked[7] = true;
        let grid =
            PlanningGrid::from_parts([0.0, 0.0], 1.0, 3, 3, vec![0.5; 9], blocked).expect("grid");
        let goal = GoalRegion {
            center: [2.5, 2.5],
            radius: 0.1,
        };
        assert!(matches!(
            dijkstra_path(&grid, [0.5, 0.5], &goal, Connectivity::Eight),
            Err(PlanError::Unreachable { .. })
        ));
        assert!(matches!(
            astar_path(&grid, [0.5, 0.5], &goal, Connectivity::Four),
            Err(PlanError::Unreachable { .. })
        ));
    }
}
