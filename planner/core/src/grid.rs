//! The planning grid: the map resampled to the planner's resolution, with the traversability cost
//! and the (padded) obstacle set every planner shares.
//!
//! Same conventions as [`GridMap`]: cell `(ix, iy)` covers
//! `[origin.x + ix·cell_size, …) × [origin.y + iy·cell_size, …)`, row-major `iy · width + ix`.
//!
//! A planning cell is *blocked* when it overlaps an obstacle cell of the map with positive area,
//! i.e. every cell that touches an obstacle is blocked. Seen from cell centres this pads the
//! obstacle by up to half a cell diagonal, so mass (P-F) or a path (graph search) in a free cell —
//! anywhere inside it — is never inside an obstacle, and a diagonal step between free cells that does
//! not cut a blocked corner stays in free space.

use serde::{Deserialize, Serialize};

use crate::error::PlanError;
use crate::map::{GridMap, Point};
use crate::traversability::{block_steep_cells, TraversabilityField, TraversabilityParams};

/// Largest accepted number of planning cells along one side (keeps requests from allocating without limit).
pub const MAX_GRID_SIDE: usize = 1024;
/// Smallest accepted number of planning cells along the longer side.
pub const MIN_GRID_SIDE: usize = 2;

/// The goal: a disc in the map's world frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GoalRegion {
    /// Centre, metres.
    pub center: Point,
    /// Radius, metres (≥ 0; a zero radius means "the cell containing the centre").
    pub radius: f64,
}

impl GoalRegion {
    /// Whether `p` lies in the closed goal disc.
    pub fn contains(&self, p: Point) -> bool {
        (p[0] - self.center[0]).hypot(p[1] - self.center[1]) <= self.radius
    }
}

/// The map resampled for planning: per-cell traversability and the padded obstacle set.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanningGrid {
    /// Lower-left corner of cell (0, 0), metres.
    pub origin: Point,
    /// Edge length of one square planning cell, metres.
    pub cell_size: f64,
    /// Cells along x.
    pub width: usize,
    /// Cells along y.
    pub height: usize,
    /// Traversability p per cell in [p_floor, 1] with p_floor > 0, row-major.
    pub cost: Vec<f64>,
    /// Cells that overlap a hard obstacle (padded, see the module docs), row-major.
    pub blocked: Vec<bool>,
}

impl PlanningGrid {
    /// Resamples `map` so that its longer side has `cells_along_longer_side` cells.
    ///
    /// The cost of a planning cell is the mean of p over a sub-lattice of sample points
    /// (nearest map cell per sample), i.e. the area average when the map is finer than the grid.
    pub fn from_map(
        map: &GridMap,
        params: &TraversabilityParams,
        cells_along_longer_side: usize,
    ) -> Result<Self, PlanError> {
        let map = block_steep_cells(map, None, params);
        let field = TraversabilityField::from_map(&map, params)?;
        Self::from_field(&map, &field, cells_along_longer_side)
    }

    /// As [`Self::from_map`] with a traversability field that was already evaluated on `map`.
    pub fn from_field(
        map: &GridMap,
        field: &TraversabilityField,
        cells_along_longer_side: usize,
    ) -> Result<Self, PlanError> {
        map.validate()?;
        if !(MIN_GRID_SIDE..=MAX_GRID_SIDE).contains(&cells_along_longer_side) {
            return Err(PlanError::InvalidOption {
                name: "grid_size",
                reason: format!(
                    "{cells_along_longer_side} cells along the longer side; accepted range is {MIN_GRID_SIDE}..={MAX_GRID_SIDE}"
                ),
            });
        }
        if field.width != map.width || field.height != map.height || field.values.len() != map.len()
        {
            return Err(PlanError::InvalidOption {
                name: "traversability field",
                reason: "field was not evaluated on this map".into(),
            });
        }
        let extent = [
            map.width as f64 * map.resolution,
            map.height as f64 * map.resolution,
        ];
        let cell_size = extent[0].max(extent[1]) / cells_along_longer_side as f64;
        // Round, not ceil, so a side that is an exact multiple does not gain a sliver cell through rounding error.
        let cells_along = |len: f64| ((len / cell_size).round() as usize).max(1);
        let (width, height) = (cells_along(extent[0]), cells_along(extent[1]));
        let sub = ((cell_size / map.resolution).ceil() as usize).clamp(1, 16);
        let mut cost = Vec::with_capacity(width * height);
        let mut blocked = Vec::with_capacity(width * height);
        for iy in 0..height {
            for ix in 0..width {
                let x0 = map.origin[0] + ix as f64 * cell_size;
                let y0 = map.origin[1] + iy as f64 * cell_size;
                let mut sum = 0.0;
                for sy in 0..sub {
                    for sx in 0..sub {
                        let p = [
                            x0 + (sx as f64 + 0.5) / sub as f64 * cell_size,
                            y0 + (sy as f64 + 0.5) / sub as f64 * cell_size,
                        ];
                        sum += field.cell_value_at(p);
                    }
                }
                cost.push(sum / (sub * sub) as f64);
                blocked.push(overlaps_obstacle(map, [x0, y0], cell_size));
            }
        }
        Self::from_parts(map.origin, cell_size, width, height, cost, blocked)
    }

    /// Builds a grid from explicit per-cell cost and obstacle flags (random test terrains).
    pub fn from_parts(
        origin: Point,
        cell_size: f64,
        width: usize,
        height: usize,
        cost: Vec<f64>,
        blocked: Vec<bool>,
    ) -> Result<Self, PlanError> {
        let bad =
            |name: &'static str, reason: String| Err(PlanError::InvalidOption { name, reason });
        if !(origin[0].is_finite() && origin[1].is_finite()) {
            return bad("grid origin", "must be finite".into());
        }
        if !(cell_size.is_finite() && cell_size > 0.0) {
            return bad(
                "cell_size",
                format!("must be finite and > 0, got {cell_size}"),
            );
        }
        if width == 0 || height == 0 || width > MAX_GRID_SIDE || height > MAX_GRID_SIDE {
            return bad(
                "grid dimensions",
                format!("{width} x {height}; each side must lie in 1..={MAX_GRID_SIDE}"),
            );
        }
        let cells = width * height;
        if cost.len() != cells || blocked.len() != cells {
            return bad(
                "grid arrays",
                format!(
                    "cost has {} and blocked {} entries, expected {cells}",
                    cost.len(),
                    blocked.len()
                ),
            );
        }
        if let Some(i) = cost
            .iter()
            .position(|&c| !(c.is_finite() && c > 0.0 && c <= 1.0))
        {
            return bad(
                "grid cost",
                format!("cell {i} has p = {}, expected a value in (0, 1]", cost[i]),
            );
        }
        Ok(Self {
            origin,
            cell_size,
            width,
            height,
            cost,
            blocked,
        })
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.width * self.height
    }

    /// A valid grid is never empty; provided for API completeness.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Row-major index of `(ix, iy)`.
    #[inline]
    pub fn index(&self, ix: usize, iy: usize) -> usize {
        iy * self.width + ix
    }

    /// `(ix, iy)` of a row-major index.
    #[inline]
    pub fn coords(&self, index: usize) -> (usize, usize) {
        (index % self.width, index / self.width)
    }

    /// Centre of cell `(ix, iy)`.
    #[inline]
    pub fn cell_center(&self, ix: usize, iy: usize) -> Point {
        [
            self.origin[0] + (ix as f64 + 0.5) * self.cell_size,
            self.origin[1] + (iy as f64 + 0.5) * self.cell_size,
        ]
    }

    /// Centre of the cell with row-major index `index`.
    #[inline]
    pub fn center_of_index(&self, index: usize) -> Point {
        let (ix, iy) = self.coords(index);
        self.cell_center(ix, iy)
    }

    /// The cell containing `p`, or `None` outside the grid (or for non-finite coordinates).
    pub fn cell_of(&self, p: Point) -> Option<(usize, usize)> {
        let fx = (p[0] - self.origin[0]) / self.cell_size;
        let fy = (p[1] - self.origin[1]) / self.cell_size;
        if !(fx.is_finite() && fy.is_finite()) || fx < 0.0 || fy < 0.0 {
            return None;
        }
        let (ix, iy) = (fx.floor() as usize, fy.floor() as usize);
        (ix < self.width && iy < self.height).then_some((ix, iy))
    }

    /// `p` itself when its cell is free, else the centre of the nearest free cell whose centre
    /// lies within `max_distance` of `p` (ties: the lower row-major index), else `None`; `None`
    /// also off the grid. Bounded: it looks at the cells within `max_distance` only.
    pub fn nearest_free_point(&self, p: Point, max_distance: f64) -> Option<Point> {
        let (sx, sy) = self.cell_of(p)?;
        if !self.blocked[self.index(sx, sy)] {
            return Some(p);
        }
        if !(max_distance.is_finite() && max_distance > 0.0) {
            return None;
        }
        let reach = (max_distance / self.cell_size).ceil() as usize + 1;
        let (x0, x1) = (sx.saturating_sub(reach), (sx + reach).min(self.width - 1));
        let (y0, y1) = (sy.saturating_sub(reach), (sy + reach).min(self.height - 1));
        let mut best: Option<(f64, Point)> = None;
        for iy in y0..=y1 {
            for ix in x0..=x1 {
                if self.blocked[self.index(ix, iy)] {
                    continue;
                }
                let c = self.cell_center(ix, iy);
                let d = (c[0] - p[0]).hypot(c[1] - p[1]);
                if d <= max_distance && best.map_or(true, |(bd, _)| d < bd) {
                    best = Some((d, c));
                }
            }
        }
        best.map(|(_, c)| c)
    }

    /// Whether `p` lies inside the grid's rectangle.
    pub fn contains(&self, p: Point) -> bool {
        self.cell_of(p).is_some()
    }

    /// The cell containing `p` after clamping `p` into the grid (NaN maps to cell (0, 0)).
    pub fn clamped_cell_of(&self, p: Point) -> (usize, usize) {
        let clamp = |v: f64, n: usize| {
            if v.is_nan() {
                0
            } else {
                (v.floor().max(0.0) as usize).min(n - 1)
            }
        };
        (
            clamp((p[0] - self.origin[0]) / self.cell_size, self.width),
            clamp((p[1] - self.origin[1]) / self.cell_size, self.height),
        )
    }

    /// p at `p`: piecewise constant per cell, clamped at the grid edge (so integrals over the
    /// whole plane, as the RBF basis needs, see the edge cells extended outward).
    pub fn cost_at(&self, p: Point) -> f64 {
        let (ix, iy) = self.clamped_cell_of(p);
        self.cost[self.index(ix, iy)]
    }

    /// Whether the straight segment `a → b` stays on the grid and out of every blocked cell
    /// (see [`segment_is_clear`]).
    pub fn segment_is_free(&self, a: Point, b: Point) -> bool {
        segment_is_clear(
            self.origin,
            self.cell_size,
            (self.width, self.height),
            a,
            b,
            |ix, iy| self.blocked[self.index(ix, iy)],
        )
    }

    /// Whether the cell containing `p` is blocked, clamped at the grid edge like [`Self::cost_at`];
    /// use [`Self::contains`] to reject points off the grid.
    pub fn blocked_at(&self, p: Point) -> bool {
        let (ix, iy) = self.clamped_cell_of(p);
        self.blocked[self.index(ix, iy)]
    }

    /// Free target cells of the goal: every cell whose centre lies in the goal disc, plus the
    /// cell containing the goal centre; blocked cells are left out (the result may be empty).
    pub fn goal_cells(&self, goal: &GoalRegion) -> Vec<usize> {
        let mut cells = Vec::new();
        let r = goal.radius.max(0.0);
        if goal.center[0].is_finite() && goal.center[1].is_finite() && r.is_finite() {
            let lo = self.clamped_cell_of([goal.center[0] - r, goal.center[1] - r]);
            let hi = self.clamped_cell_of([goal.center[0] + r, goal.center[1] + r]);
            for iy in lo.1..=hi.1 {
                for ix in lo.0..=hi.0 {
                    if goal.contains(self.cell_center(ix, iy)) {
                        cells.push(self.index(ix, iy));
                    }
                }
            }
        }
        if let Some((ix, iy)) = self.cell_of(goal.center) {
            let own = self.index(ix, iy);
            if !cells.contains(&own) {
                cells.push(own);
            }
        }
        cells.retain(|&i| !self.blocked[i]);
        cells.sort_unstable();
        cells
    }
}

/// Whether the square `[corner, corner + size]²` overlaps an obstacle cell of `map` with positive area.
fn overlaps_obstacle(map: &GridMap, corner: Point, size: f64) -> bool {
    let Some(mask) = &map.obstacles else {
        return false;
    };
    // Tolerance so that a shared edge (zero-area contact) is not an overlap despite rounding.
    let eps = 1e-9 * map.resolution;
    let range = |lo: f64, origin: f64, n: usize| {
        let first = ((lo + eps - origin) / map.resolution).floor().max(0.0) as usize;
        let last = (((lo + size - eps - origin) / map.resolution).ceil() as usize).min(n);
        first..last
    };
    let xs = range(corner[0], map.origin[0], map.width);
    let ys = range(corner[1], map.origin[1], map.height);
    ys.into_iter()
        .any(|iy| xs.clone().any(|ix| mask[map.index(ix, iy)]))
}

/// Whether the straight segment `a → b` crosses no cell for which `blocked(ix, iy)` holds, on a
/// grid of `shape = (width, height)` square cells of side `cell` from `origin`; leaving the grid
/// counts as blocked. Every cell the segment passes through is visited (grid traversal after
/// Amanatides and Woo), so a step can never cut an obstacle corner between two checked points.
/// Where the segment runs exactly through a cell corner, both side cells are checked too
/// (conservative: touching a blocked cell at a point is refused).
pub fn segment_is_clear(
    origin: Point,
    cell: f64,
    shape: (usize, usize),
    a: Point,
    b: Point,
    blocked: impl Fn(usize, usize) -> bool,
) -> bool {
    let (width, height) = (shape.0 as i64, shape.1 as i64);
    let to_cell = |p: Point| [(p[0] - origin[0]) / cell, (p[1] - origin[1]) / cell];
    let (fa, fb) = (to_cell(a), to_cell(b));
    if !fa.iter().chain(fb.iter()).all(|v| v.is_finite()) {
        return false;
    }
    let is_blocked = |ix: i64, iy: i64| {
        ix < 0 || iy < 0 || ix >= width || iy >= height || blocked(ix as usize, iy as usize)
    };
    let (mut ix, mut iy) = (fa[0].floor() as i64, fa[1].floor() as i64);
    let (ex, ey) = (fb[0].floor() as i64, fb[1].floor() as i64);
    let (dx, dy) = (fb[0] - fa[0], fb[1] - fa[1]);
    let sign = |d: f64| match d.partial_cmp(&0.0) {
        Some(std::cmp::Ordering::Greater) => 1i64,
        Some(std::cmp::Ordering::Less) => -1,
        _ => 0,
    };
    let (sx, sy) = (sign(dx), sign(dy));
    let boundary = |f: f64, i: i64, d: f64| {
        if d > 0.0 {
            (i as f64 + 1.0 - f) / d
        } else if d < 0.0 {
            (i as f64 - f) / d
        } else {
            f64::INFINITY
        }
    };
    let mut t_x = boundary(fa[0], ix, dx);
    let mut t_y = boundary(fa[1], iy, dy);
    let delta_x = if dx != 0.0 {
        1.0 / dx.abs()
    } else {
        f64::INFINITY
    };
    let delta_y = if dy != 0.0 {
        1.0 / dy.abs()
    } else {
        f64::INFINITY
    };
    let steps = (ex - ix).abs() + (ey - iy).abs();
    for _ in 0..=steps {
        if is_blocked(ix, iy) {
            return false;
        }
        if ix == ex && iy == ey {
            return true;
        }
        let corner = t_x.is_finite()
            && t_y.is_finite()
            && (t_x - t_y).abs() <= 1e-12 * t_x.abs().max(t_y.abs()).max(1.0);
        if corner {
            if is_blocked(ix + sx, iy) || is_blocked(ix, iy + sy) {
                return false;
            }
            ix += sx;
            iy += sy;
            t_x += delta_x;
            t_y += delta_y;
        } else if t_x < t_y {
            ix += sx;
            t_x += delta_x;
        } else {
            iy += sy;
            t_y += delta_y;
        }
    }
    // Rounding took the walk past the end cell without meeting it: refuse rather than guess.
    !is_blocked(ex, ey) && ix == ex && iy == ey
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_are_checked_cell_by_cell_including_corners() {
        // 4 x 4 unit cells, blocked: (1, 1) and (2, 2) (touching at a corner).
        let blocked = |ix: usize, iy: usize| (ix, iy) == (1, 1) || (ix, iy) == (2, 2);
        let clear = |a: Point, b: Point| segment_is_clear([0.0, 0.0], 1.0, (4, 4), a, b, blocked);
        assert!(clear([0.5, 0.5], [0.5, 3.5]), "vertical, free column");
        assert!(clear([0.5, 0.5], [3.5, 0.5]), "horizontal, free row");
        assert!(!clear([0.5, 1.5], [2.5, 1.5]), "through (1, 1)");
        // End points free, the segment clips the corner of (1, 1): an end-point check misses it.
        assert!(!clear([0.9, 0.5], [1.5, 1.05]));
        // Exactly through the shared corner of the two blocked cells: refused.
        assert!(!clear([1.5, 2.5], [2.5, 1.5]));
        assert!(!clear([0.5, 0.5], [5.0, 0.5]), "leaves the grid");
        assert!(!clear([0.5, f64::NAN], [0.5, 0.5]), "not finite");
        assert!(clear([3.2, 0.1], [3.2, 0.1]), "a point");
    }

    fn map_with_obstacle() -> GridMap {
        // 8 x 8 map of 0.5 m cells; heights = ix (so p varies along x); one obstacle cell at (3, 4).
        let (w, h) = (8, 8);
        let heights = (0..w * h).map(|i| (i % w) as f64).collect();
        let mut mask = vec![false; w * h];
        mask[4 * w + 3] = true;
        GridMap::new([1.0, -2.0], 0.5, w, h, heights, Some(mask)).expect("valid map")
    }

    #[test]
    fn resampling_averages_cost_and_blocks_touching_cells() {
        let map = map_with_obstacle();
        let grid = PlanningGrid::from_map(&map, &TraversabilityParams::default(), 4).expect("grid");
        assert_eq!((grid.width, grid.height), (4, 4));
        assert!((grid.cell_size - 1.0).abs() < 1e-12);
        // Planning cell ix covers map columns 2ix, 2ix+1: p = h/7 averaged.
        for iy in 0..4 {
            for ix in 0..4 {
                let expected =
                    ((2 * ix) as f64 / 7.0).max(0.05) / 2.0 + (2 * ix + 1) as f64 / 7.0 / 2.0;
                assert!((grid.cost[grid.index(ix, iy)] - expected).abs() < 1e-12);
            }
        }
        // Map cell (3, 4) lies in planning cell (1, 2) only.
        let blocked: Vec<usize> = (0..16).filter(|&i| grid.blocked[i]).collect();
        assert_eq!(blocked, vec![grid.index(1, 2)]);
    }

    #[test]
    fn obstacle_on_a_cell_border_blocks_both_neighbours_when_grid_is_offset() {
        let map = map_with_obstacle();
        // 8 cells along the side: planning cells equal map cells; only (3,4) is blocked.
        let grid = PlanningGrid::from_map(&map, &TraversabilityParams::default(), 8).expect("grid");
        assert_eq!(grid.blocked.iter().filter(|&&b| b).count(), 1);
        // 3 cells along the side (4/3 m cells): map cell x in [2.5, 3.0) + 1 => planning col 1 only,
        // y in [0, 0.5) - 2 => planning row 1 (rows of 4/3 m starting at -2).
        let grid = PlanningGrid::from_map(&map, &TraversabilityParams::default(), 3).expect("grid");
        let blocked: Vec<usize> = (0..9).filter(|&i| grid.blocked[i]).collect();
        assert_eq!(blocked, vec![grid.index(1, 1)]);
    }

    #[test]
    fn lookups_clamp_and_goal_cells_cover_the_disc() {
        let grid = PlanningGrid::from_parts([0.0, 0.0], 1.0, 5, 5, vec![0.5; 25], vec![false; 25])
            .expect("grid");
        assert_eq!(grid.cell_of([4.99, 0.0]), Some((4, 0)));
        assert_eq!(grid.cell_of([5.0, 0.0]), None);
        assert_eq!(grid.clamped_cell_of([-3.0, 17.0]), (0, 4));
        let goal = GoalRegion {
            center: [2.5, 2.5],
            radius: 1.0,
        };
        let cells = grid.goal_cells(&goal);
        assert_eq!(cells, vec![7, 11, 12, 13, 17]);
        let tiny = GoalRegion {
            center: [0.2, 0.2],
            radius: 0.0,
        };
        assert_eq!(grid.goal_cells(&tiny), vec![0]);
    }

    #[test]
    fn from_parts_rejects_bad_arrays() {
        assert!(
            PlanningGrid::from_parts([0.0, 0.0], 1.0, 2, 2, vec![0.5; 3], vec![false; 4]).is_err()
        );
        assert!(
            PlanningGrid::from_parts([0.0, 0.0], 1.0, 2, 2, vec![0.0; 4], vec![false; 4]).is_err()
        );
        assert!(
            PlanningGrid::from_parts([0.0, 0.0], f64::NAN, 2, 2, vec![0.5; 4], vec![false; 4])
                .is_err()
        );
        assert!(PlanningGrid::from_parts([0.0, 0.0], 1.0, 0, 2, vec![], vec![]).is_err());
    }

    #[test]
    fn a_start_on_a_blocked_cell_moves_to_the_nearest_free_one_within_reach() {
        // 6 × 4 unit cells; a block of columns 2 … 4 on rows 0 … 2.
        let blocked: Vec<bool> = (0..24)
            .map(|i| (2..=4).contains(&(i % 6)) && i / 6 <= 2)
            .collect();
        let grid =
            PlanningGrid::from_parts([0.0, 0.0], 1.0, 6, 4, vec![0.5; 24], blocked).expect("grid");
        // Free: unchanged, whatever the reach.
        assert_eq!(grid.nearest_free_point([0.3, 0.7], 0.0), Some([0.3, 0.7]));
        // On the block's left edge: the free cell to its left (1 m off), not the one above (2.3 m).
        assert_eq!(grid.nearest_free_point([2.2, 0.5], 1.5), Some([1.5, 0.5]));
        // Deep inside: nothing within reach, or the nearest free centre when the reach allows.
        assert_eq!(grid.nearest_free_point([3.5, 0.5], 1.0), None);
        assert_eq!(grid.nearest_free_point([3.5, 2.4], 3.0), Some([3.5, 3.5]));
        // Off the grid or no reach: none.
        assert_eq!(grid.nearest_free_point([-1.0, 0.5], 5.0), None);
        assert_eq!(grid.nearest_free_point([3.5, 0.5], f64::NAN), None);
    }
}
