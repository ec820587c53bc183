//! The optimal feedback law of a P-F plan, sampled on the planning grid: for every cell the unit
//! direction of the optimal move, a speed and the cost-to-go. This is what a robot follows when
//! it is pushed off its reference (or the map changes under it): wherever it stands, it reads
//! its cell and moves on.
//!
//! The direction is the greedy action of the optimal cost-to-go V* (the SSP policy, see
//! [`crate::ssp`]): argminₖ c·Bᵢ·Δtₖ + Σⱼ Uₖ(i, j)·V*(j), over the actions (non-wall fluxes)
//! of the cell's basis function. Where several actions tie (relative 1e-9) their unit vectors
//! are averaged and renormalised: on open ground an 8-direction lattice has two equally short
//! routes to most goals (axial and diagonal steps in any order), and picking one of them per
//! cell would zig-zag, while their mean points straight at the goal's side. Only lattice
//! neighbours are averaged (one angular run around the best action): where two separate routes
//! tie, on a watershed, their mean would point between them, at an obstacle.
//!
//! The cost-to-go is in the planner's cost convention, ∫p ds to the goal: V*ᵢ is per unit
//! coefficient in LP units (c·∫p ds, c = 1 + 1/u_max), and a unit mass in function i has
//! coefficient 1/∫φᵢ, so the field holds V*ᵢ / (c·∫φᵢ). For the indicator basis that is the
//! Dijkstra distance of the cell on the grid graph (tested).
//!
//! Which V* the field reads:
//! - the exact solver's potential is V* on every state (Dijkstra from the target, or policy
//!   iteration over every state that can reach it);
//! - Clarabel's dual equals V* only where the start density is positive (elsewhere the dual
//!   inequality leaves it free below V*): with the uniform start density that is every state
//!   that can reach the goal, so the field is available; with a point start it is not
//!   ([`FieldUnavailable::DualNotCostToGo`]);
//! - an LP that was trivial (all start mass already in the target) has no dual to read: V* is
//!   then computed by the exact solver alone.
//!
//! Bases: both live on the planning grid (one candidate function per cell: the cell's indicator
//! or a Gaussian centred on it), so the field is always on the planning grid's lattice
//! (origin, cell size, width, height). With the RBF basis the functions next to obstacles are
//! inactive, so those free cells read as unreachable (-1) like the obstacles themselves.

use std::path::Path;

use thiserror::Error;

use crate::error::PlanError;
use crate::generators::{Generators, SparseColumns};
use crate::grid::{GoalRegion, PlanningGrid};
use crate::map::Point;

/// Cost-to-go of a cell from which the goal cannot be reached (obstacles, cut-off cells).
pub const UNREACHABLE: f64 = -1.0;

/// Actions whose Q-values lie within this relative distance of the best are ties.
pub const TIE_TOLERANCE: f64 = 1e-9;

/// Transition mass at or below this is no transition (the SSP solver's threshold).
const TRANSITION_EPS: f64 = 1e-12;

/// Most actions of one state: one per control direction (4 or 8).
const MAX_ACTIONS: usize = 8;

/// Why a plan carries no feedback field.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FieldUnavailable {
    /// Graph methods give one path, not a law.
    #[error("{method} plans carry no feedback field; only P-F plans do")]
    NotPf { method: &'static str },
    /// Clarabel with a point start: its dual is the cost-to-go only on the start's tube.
    #[error(
        "Clarabel's dual is the cost-to-go only where the start density is positive; plan with \
         the uniform start density or the exact solver to get a feedback field"
    )]
    DualNotCostToGo,
    /// No Markov structure, so no SSP cost-to-go (never for the generators this crate builds).
    #[error("the generators are not Markov: no cost-to-go for a feedback field")]
    NotMarkov,
}

/// The feedback law on the planning grid. Arrays are row-major `iy · width + ix`.
#[derive(Debug, Clone, PartialEq)]
pub struct FeedbackGrid {
    /// Lower-left corner of cell (0, 0) of the planning grid, metres.
    pub origin: Point,
    /// Edge length of the planning cells, metres.
    pub resolution: f64,
    /// Cells along x.
    pub width: usize,
    /// Cells along y.
    pub height: usize,
    /// x component of the unit direction of the optimal move; 0 where there is none.
    pub dir_x: Vec<f64>,
    /// y component of the unit direction of the optimal move; 0 where there is none.
    pub dir_y: Vec<f64>,
    /// Speed along the direction, m/s (0 where there is no direction).
    pub speed: Vec<f64>,
    /// ∫p ds to the goal along the optimal route; 0 in the target set, [`UNREACHABLE`] where
    /// the goal cannot be reached.
    pub cost_to_go: Vec<f64>,
    /// The goal region the field leads to.
    pub goal: GoalRegion,
}

/// What [`FeedbackGrid::from_values`] needs of one solved LP.
pub struct FieldInputs<'a> {
    /// Generators (and basis) of the plan.
    pub generators: &'a Generators,
    /// The planning grid they live on.
    pub grid: &'a PlanningGrid,
    /// The goal disc.
    pub goal: GoalRegion,
    /// Goal cells of the planning grid (the target set).
    pub goal_cells: &'a [usize],
    /// Bᵢ = ∫p φᵢ per active function.
    pub cost: &'a [f64],
    /// ∫φᵢ per active function.
    pub mass: &'a [f64],
    /// V* per active function in LP units (0 on targets, +∞ where the goal cannot be reached).
    pub value: &'a [f64],
    /// Speed bound of the LP (c = 1 + 1/u_max).
    pub u_max: f64,
    /// Speed written where a direction exists, m/s.
    pub speed: f64,
}

impl FeedbackGrid {
    /// The greedy policy of `inputs.value`, sampled per planning cell. O(non-zeros of the
    /// generators): for the indicator basis cells × directions.
    pub fn from_values(inputs: &FieldInputs<'_>) -> Self {
        let grid = inputs.grid;
        let gens = inputs.generators;
        let basis = &gens.basis;
        let c = 1.0 + 1.0 / inputs.u_max;
        let cells = grid.len();
        let mut field = Self {
            origin: grid.origin,
            resolution: grid.cell_size,
            width: grid.width,
            height: grid.height,
            dir_x: vec![0.0; cells],
            dir_y: vec![0.0; cells],
            speed: vec![0.0; cells],
            cost_to_go: vec![UNREACHABLE; cells],
            goal: inputs.goal,
        };
        let mut is_goal_cell = vec![false; cells];
        for &cell in inputs.goal_cells {
            is_goal_cell[cell] = true;
        }
        // V per active function with the target at 0, read once per transition below.
        let value_of: Vec<f64> = (0..basis.len())
            .map(|j| {
                if is_goal_cell[basis.cell(j)] {
                    0.0
                } else {
                    inputs.value[j]
                }
            })
            .collect();
        // Q-values of every (state, direction), infinite where the direction is no action
        // (a wall, a flux that only stays) or leads where the goal cannot be reached. Filled
        // one generator at a time: each matrix is then read as one sequential stream, which
        // is what keeps this pass at the cost of reading the generators once.
        let k_count = gens.directions.len();
        let n = basis.len();
        let mut q_values = vec![f64::INFINITY; n * k_count];
        for (k, l) in gens.generators.iter().enumerate() {
            let step = gens.directions[k].step;
            for i in 0..n {
                let v = value_of[i];
                if !v.is_finite() || is_goal_cell[basis.cell(i)] {
                    continue;
                }
                let mut stay = 1.0;
                let mut expected = 0.0;
                let mut moves = false;
                for (j, entry) in l.column(i) {
                    if j == i {
                        stay += step * entry;
                    } else if step * entry > TRANSITION_EPS {
                        moves = true;
                        expected += step * entry * value_of[j];
                    }
                }
                if !moves {
                    continue;
                }
                if stay > TRANSITION_EPS {
                    expected += stay * v;
                }
                q_values[i * k_count + k] = c * inputs.cost[i] * step + expected;
            }
        }
        let mut actions: Vec<(f64, [f64; 2])> = Vec::with_capacity(k_count);
        for (cell, &in_goal) in is_goal_cell.iter().enumerate() {
            if in_goal {
                field.cost_to_go[cell] = 0.0;
                continue;
            }
            let Some(i) = basis.index_of_cell(cell) else {
                continue;
            };
            let v = inputs.value[i];
            if !v.is_finite() {
                continue;
            }
            field.cost_to_go[cell] = v / (c * inputs.mass[i]);
            actions.clear();
            for (k, &q) in q_values[i * k_count..(i + 1) * k_count].iter().enumerate() {
                if q.is_finite() {
                    actions.push((q, gens.directions[k].vector));
                }
            }
            if let Some(direction) = tied_direction(&actions, gens.directions.len()) {
                let cell_speed = if direction == [0.0, 0.0] {
                    0.0
                } else {
                    inputs.speed
                };
                field.dir_x[cell] = direction[0];
                field.dir_y[cell] = direction[1];
                field.speed[cell] = cell_speed;
            }
        }
        field
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.width * self.height
    }

    /// A field of a valid grid is never empty; provided for API completeness.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Sets the speed of every cell that has a direction (the plan's nominal speed).
    pub fn set_speed(&mut self, speed: f64) {
        for (s, (&x, &y)) in self
            .speed
            .iter_mut()
            .zip(self.dir_x.iter().zip(&self.dir_y))
        {
            *s = if x != 0.0 || y != 0.0 { speed } else { 0.0 };
        }
    }

    /// Row-major index of `(ix, iy)`.
    #[inline]
    pub fn index(&self, ix: usize, iy: usize) -> usize {
        iy * self.width + ix
    }

    /// Centre of cell `(ix, iy)`.
    pub fn cell_center(&self, ix: usize, iy: usize) -> Point {
        [
            self.origin[0] + (ix as f64 + 0.5) * self.resolution,
            self.origin[1] + (iy as f64 + 0.5) * self.resolution,
        ]
    }

    /// Writes the field as a numpy `.npz` archive: `dir_x`, `dir_y`, `speed`, `cost_to_go`
    /// float64 of shape (height, width) indexed `[iy, ix]`, `origin` (2,), `resolution` (),
    /// `goal` (3,) = centre x, y and radius. Entries are stored uncompressed (numpy reads both).
    pub fn write_npz(&self, path: &Path) -> Result<(), PlanError> {
        let shape = [self.height, self.width];
        crate::io::write_npz(
            path,
            &[
                ("dir_x", &shape, &self.dir_x),
                ("dir_y", &shape, &self.dir_y),
                ("speed", &shape, &self.speed),
                ("cost_to_go", &shape, &self.cost_to_go),
                ("origin", &[2], &self.origin),
                ("resolution", &[], &[self.resolution]),
                (
                    "goal",
                    &[3],
                    &[self.goal.center[0], self.goal.center[1], self.goal.radius],
                ),
            ],
        )
    }
}

/// The direction of the optimal actions (`(Q-value, unit vector)` each) on a lattice of
/// `lattice_directions` equally spaced directions. The actions within [`TIE_TOLERANCE`] of the
/// best Q-value are optimal; the ones that form one angular run with the best action (each
/// one lattice step from the next: axial and diagonal on 8, or two axial on 4) are averaged.
/// That straightens open ground, where the run is an axial and a diagonal step, while on a
/// watershed, where two separate routes tie (north and south around an obstacle), the mean of
/// their first moves would point between them, at no optimal move at all: there the best
/// action's run is taken alone. `None` without actions.
fn tied_direction(actions: &[(f64, [f64; 2])], lattice_directions: usize) -> Option<[f64; 2]> {
    let (best_q, best_dir) = actions.iter().copied().min_by(|a, b| a.0.total_cmp(&b.0))?;
    let slack = TIE_TOLERANCE * best_q.abs();
    // At most MAX_ACTIONS directions (4 or 8): fixed arrays keep this per-cell step free of
    // heap allocations (it runs for every cell of every plan).
    let mut tied = [[0.0; 2]; MAX_ACTIONS];
    let mut tied_count = 0;
    for &(q, d) in actions.iter().take(MAX_ACTIONS) {
        if q <= best_q + slack {
            tied[tied_count] = d;
            tied_count += 1;
        }
    }
    let tied = &tied[..tied_count];
    // Unit vectors one lattice step apart have this dot product (cos 45° or cos 90°).
    let step_cos = (std::f64::consts::TAU / lattice_directions.max(1) as f64).cos();
    let adjacent = |a: [f64; 2], b: [f64; 2]| (a[0] * b[0] + a[1] * b[1] - step_cos).abs() < 1e-9;
    let mut in_run = [false; MAX_ACTIONS];
    let mut sum = best_dir;
    for (k, &d) in tied.iter().enumerate() {
        in_run[k] = d == best_dir;
    }
    let mut grown = true;
    while grown {
        grown = false;
        for k in 0..tied.len() {
            if in_run[k] {
                continue;
            }
            let joins = (0..tied.len()).any(|r| in_run[r] && adjacent(tied[r], tied[k]));
            if joins {
                in_run[k] = true;
                sum = [sum[0] + tied[k][0], sum[1] + tied[k][1]];
                grown = true;
            }
        }
    }
    let norm = sum[0].hypot(sum[1]);
    // A run round the whole circle (a cell in a symmetric ring of routes) cancels out.
    Some(if norm > 1e-6 {
        [sum[0] / norm, sum[1] / norm]
    } else {
        best_dir
    })
}

#[cfg(test)]
mod tests;
