//! Data-driven Perron-Frobenius generators (ANSDMD), one per control direction.
//!
//! For each direction dₖ the planner generates snapshot pairs `(xₛ, yₛ)` by flowing the single
//! integrator ẋ = dₖ for a time Δtₖ from points xₛ of an exact sub-lattice of every cell in the
//! domain of the basis (the cells that carry an active function), so the generator only ever
//! sees sampled data, never the flow map itself. From the pairs it estimates a transfer matrix U
//! (row i: where the mass of function i goes) and stores `Lₖ = (Uᵀ − I)/Δtₖ` sparse:
//! - indicators ([`ulam`]): Ulam's method, U = G⁻¹A with diagonal G, one deterministic move or
//!   a wall per cell;
//! - Gaussian RBFs, [`RbfGenerators::Transfer`] ([`rbf`], the default): the Galerkin transfer in
//!   the partition of unity of the truncated Gaussians, non-negative and row-stochastic (Markov)
//!   by construction;
//! - Gaussian RBFs, [`RbfGenerators::Ansdmd`] ([`ansdmd`]): the paper's least squares
//!   U = G⁻¹A on seeded random samples, row-normalised.
//!
//! Ulam's and the transfer's U are Markov: every row non-negative and summing to one, a row whose
//! moves are all blocked the identity (a reflecting wall, never a free sink). So their Lₖ conserve
//! mass and the LP is a stochastic shortest path (see [`crate::ssp`]). ANSDMD's rows sum to one
//! after the normalisation but keep negative entries: its LP goes to Clarabel.
//!
//! Δtₖ makes each displacement exactly one lattice vector (Δt = h axially, √2·h diagonally): the
//! condition under which the indicator LP is exactly Dijkstra's problem and the sample images are
//! themselves lattice samples. A move is *blocked* when its image leaves the grid or when the
//! axis-aligned box spanned by the displacement touches a blocked cell (a robot moving past an
//! obstacle corner would graze it; for one-cell moves this is the graph rule "a diagonal step
//! must not cut a blocked corner"). The sampled system stops at obstacles: a blocked move leaves
//! the sample where it is, so its snapshot pair is `(x, x)`.

use std::time::Instant;

use clarabel::algebra::CscMatrix;
use tracing::debug;

use crate::basis::{Basis, BasisKind, RbfGenerators};
use crate::deadline::Deadline;
use crate::error::PlanError;
use crate::grid::PlanningGrid;
use crate::map::Point;

/// One control direction of the split flow: unit vector and the generator's time step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Direction {
    /// Unit direction vector dₖ.
    pub vector: [f64; 2],
    /// Lattice displacement of one step in cells (Δtₖ·dₖ / h).
    pub shift: [i64; 2],
    /// Δtₖ in metres (= seconds at unit speed): the length of one lattice displacement.
    pub step: f64,
}

/// The K control directions: 4 (±x, ±y) or 8 (plus the diagonals), with Δt = one lattice vector.
pub fn directions(count: usize, cell_size: f64) -> Result<Vec<Direction>, PlanError> {
    let shifts: &[[i64; 2]] = match count {
        4 => &[[1, 0], [0, 1], [-1, 0], [0, -1]],
        8 => &[
            [1, 0],
            [1, 1],
            [0, 1],
            [-1, 1],
            [-1, 0],
            [-1, -1],
            [0, -1],
            [1, -1],
        ],
        _ => {
            return Err(PlanError::InvalidOption {
                name: "directions",
                reason: format!("{count}; the P-F planner supports 4 or 8 directions"),
            })
        }
    };
    if !(cell_size.is_finite() && cell_size > 0.0) {
        return Err(PlanError::InvalidOption {
            name: "cell_size",
            reason: format!("{cell_size} must be finite and > 0"),
        });
    }
    Ok(shifts
        .iter()
        .map(|&shift| {
            let norm = ((shift[0] * shift[0] + shift[1] * shift[1]) as f64).sqrt();
            Direction {
                vector: [shift[0] as f64 / norm, shift[1] as f64 / norm],
                shift,
                step: norm * cell_size,
            }
        })
        .collect())
}

/// The dynamics the samples come from: the single integrator ẋ = d, flowed for time `t`.
/// (Constant velocity, so this is exact; it is the only place that knows the flow.)
#[inline]
pub(crate) fn flow(x: Point, d: [f64; 2], t: f64) -> Point {
    [x[0] + t * d[0], x[1] + t * d[1]]
}

/// A compressed-sparse-column matrix: Clarabel's, so generator blocks reach the LP solver as
/// they are.
pub type SparseMatrix = CscMatrix<f64>;

/// Column-wise access the planner needs on top of [`CscMatrix`].
pub trait SparseColumns {
    /// Builds a CSC matrix from per-column `(row, value)` lists (rows sorted here, duplicates summed).
    fn from_columns(nrows: usize, columns: Vec<Vec<(usize, f64)>>) -> Self;
    /// Stored entries of column `j` as `(row, value)`.
    fn column(&self, j: usize) -> impl Iterator<Item = (usize, f64)> + '_;
    /// `y = self · x`.
    fn mul_vec(&self, x: &[f64]) -> Vec<f64>;
}

impl SparseColumns for SparseMatrix {
    fn from_columns(nrows: usize, columns: Vec<Vec<(usize, f64)>>) -> Self {
        let ncols = columns.len();
        let mut col_ptr = Vec::with_capacity(ncols + 1);
        let mut row_idx: Vec<usize> = Vec::new();
        let mut values: Vec<f64> = Vec::new();
        col_ptr.push(0);
        for mut col in columns {
            col.sort_unstable_by_key(|e| e.0);
            let column_start = row_idx.len();
            for (row, value) in col {
                debug_assert!(row < nrows, "row {row} out of {nrows}");
                match (row_idx.last(), values.last_mut()) {
                    (Some(&last), Some(sum)) if row_idx.len() > column_start && last == row => {
                        *sum += value
                    }
                    _ => {
                        row_idx.push(row);
                        values.push(value);
                    }
                }
            }
            col_ptr.push(row_idx.len());
        }
        CscMatrix::new(nrows, ncols, col_ptr, row_idx, values)
    }

    fn column(&self, j: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let range = self.colptr[j]..self.colptr[j + 1];
        self.rowval[range.clone()]
            .iter()
            .copied()
            .zip(self.nzval[range].iter().copied())
    }

    fn mul_vec(&self, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; self.m];
        for (j, &xj) in x.iter().enumerate().take(self.n) {
            if xj != 0.0 {
                for (i, v) in self.column(j) {
                    y[i] += v * xj;
                }
            }
        }
        y
    }
}

/// Diagnostics of a generator build.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GeneratorStats {
    /// Snapshot samples per direction (RBF: all lattice points of all cells; indicator: one per
    /// active cell, which gives the same U, see `ulam`).
    pub samples: usize,
    /// Samples, summed over directions, whose move was blocked (left the grid or touched an
    /// obstacle) and which therefore stayed in place.
    pub invalid_pairs: usize,
    /// Rows of U, summed over directions, that are the identity (every move blocked: a wall).
    pub wall_rows: usize,
    /// Largest total negative mass of a row of U after normalisation (0 for Ulam and the
    /// transfer, which are non-negative by construction).
    pub max_negative_row_mass: f64,
    /// Negative entries of U after normalisation, summed over directions (ANSDMD only).
    pub negative_entries: usize,
    /// Largest |row sum − 1| of U before the row normalisation: the mass the least-squares
    /// estimate fails to conserve (ANSDMD only; the others conserve it by construction).
    pub max_row_sum_error: f64,
    /// Non-zeros of all Lₖ together.
    pub nnz: usize,
    /// Wall-clock build time, seconds.
    pub build_time_s: f64,
}

/// Generators Lₖ of every direction on one basis.
#[derive(Debug, Clone)]
pub struct Generators {
    /// The basis the generators act on (coefficient space).
    pub basis: Basis,
    /// The control directions, in the order of `generators`.
    pub directions: Vec<Direction>,
    /// Lₖ = (Uₖᵀ − I)/Δtₖ, square of size `basis.len()`.
    pub generators: Vec<SparseMatrix>,
    /// Build diagnostics.
    pub stats: GeneratorStats,
}

/// Whether `p` lies in the domain of the basis: a grid cell that carries an active function
/// (indicator: a free cell; RBF: a cell whose centre is active, i.e. at least one cell away from
/// every blocked cell).
pub(crate) fn in_domain(grid: &PlanningGrid, basis: &Basis, p: Point) -> bool {
    grid.cell_of(p)
        .is_some_and(|(ix, iy)| basis.index_of_cell(grid.index(ix, iy)).is_some())
}

/// Whether the move `x → y` is allowed: `y` in the domain of the basis and the box spanned by the
/// displacement free of blocked cells.
pub(crate) fn valid_pair(grid: &PlanningGrid, basis: &Basis, x: Point, y: Point) -> bool {
    if !in_domain(grid, basis, y) {
        return false;
    }
    let (Some(a), Some(b)) = (grid.cell_of(x), grid.cell_of(y)) else {
        return false;
    };
    let (x0, x1) = (a.0.min(b.0), a.0.max(b.0));
    let (y0, y1) = (a.1.min(b.1), a.1.max(b.1));
    !(y0..=y1).any(|iy| (x0..=x1).any(|ix| grid.blocked[grid.index(ix, iy)]))
}

/// All snapshot points: an exact `m × m` sub-lattice of every grid cell, row-major by cell.
fn sample_points(grid: &PlanningGrid, per_axis: usize) -> Vec<Point> {
    let mut points = Vec::with_capacity(grid.len() * per_axis * per_axis);
    for iy in 0..grid.height {
        for ix in 0..grid.width {
            for sy in 0..per_axis {
                for sx in 0..per_axis {
                    points.push([
                        grid.origin[0]
                            + (ix as f64 + (sx as f64 + 0.5) / per_axis as f64) * grid.cell_size,
                        grid.origin[1]
                            + (iy as f64 + (sy as f64 + 0.5) / per_axis as f64) * grid.cell_size,
                    ]);
                }
            }
        }
    }
    points
}

impl Generators {
    /// Builds the basis and the K generators on `grid`.
    pub fn build(
        grid: &PlanningGrid,
        kind: BasisKind,
        direction_count: usize,
    ) -> Result<Self, PlanError> {
        Self::build_until(grid, kind, direction_count, Deadline::NONE)
    }

    /// [`Generators::build`], stopped with [`PlanError::TimeLimit`] once `deadline` passes
    /// (checked inside the Ulam and ANSDMD builds; transfer builds are checked when they finish).
    pub fn build_until(
        grid: &PlanningGrid,
        kind: BasisKind,
        direction_count: usize,
        deadline: Deadline,
    ) -> Result<Self, PlanError> {
        let started = Instant::now();
        let basis = Basis::new(grid, kind)?;
        let directions = directions(direction_count, grid.cell_size)?;
        let mut stats = GeneratorStats::default();
        let generators = match kind {
            BasisKind::Indicator => {
                ulam::build_ulam(grid, &basis, &directions, deadline, &mut stats)?
            }
            BasisKind::Rbf {
                generators: RbfGenerators::Ansdmd,
                samples_per_basis,
                ..
            } => ansdmd::build_ansdmd(
                grid,
                &basis,
                &directions,
                samples_per_basis,
                deadline,
                &mut stats,
            )?,
            BasisKind::Rbf {
                generators: RbfGenerators::Transfer,
                ..
            } => {
                let points = sample_points(grid, kind.samples_per_axis());
                stats.samples = points.len();
                let built = rbf::build_rbf(grid, &basis, &directions, &points, &mut stats)?;
                deadline.check("the RBF generator build")?;
                built
            }
        };
        stats.nnz = generators.iter().map(SparseMatrix::nnz).sum();
        stats.build_time_s = started.elapsed().as_secs_f64();
        debug!(
            functions = basis.len(),
            directions = directions.len(),
            nnz = stats.nnz,
            wall_rows = stats.wall_rows,
            time_s = stats.build_time_s,
            "P-F generators built"
        );
        Ok(Self {
            basis,
            directions,
            generators,
            stats,
        })
    }
}

pub mod ansdmd;
pub mod rbf;
pub mod ulam;

/// `build(direction)` for every direction, spread over the available cores, in order.
fn per_direction<T: Send>(
    directions: &[Direction],
    build: impl Fn(&Direction) -> T + Sync,
) -> Vec<T> {
    let workers = std::thread::available_parallelism()
        .map_or(1, usize::from)
        .clamp(1, directions.len().max(1));
    let chunk = directions.len().div_ceil(workers).max(1);
    let build = &build;
    std::thread::scope(|scope| {
        let handles: Vec<_> = directions
            .chunks(chunk)
            .map(|dirs| scope.spawn(move || dirs.iter().map(build).collect::<Vec<T>>()))
            .collect();
        handles
            .into_iter()
            .flat_map(|h| match h.join() {
                Ok(v) => v,
                // A panic in a worker is a bug of the builder: re-raise it where it belongs.
                Err(payload) => std::panic::resume_unwind(payload),
            })
            .collect()
    })
}

pub use ansdmd::MAX_ANSDMD_FUNCTIONS;
pub use rbf::MAX_RBF_FUNCTIONS;

#[cfg(test)]
pub(crate) mod test_grids {
    use crate::grid::PlanningGrid;

    /// A grid of `width × height` cells of 0.25 m with the given cells blocked.
    pub(crate) fn open_grid(width: usize, height: usize, blocked: &[usize]) -> PlanningGrid {
        let mut b = vec![false; width * height];
        for &i in blocked {
            b[i] = true;
        }
        PlanningGrid::from_parts(
            [0.0, 0.0],
            0.25,
            width,
            height,
            vec![0.7; width * height],
            b,
        )
        .expect("valid grid")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn direction_count_other_than_four_or_eight_is_rejected() {
        assert!(matches!(
            directions(6, 1.0),
            Err(PlanError::InvalidOption { .. })
        ));
        assert!(directions(4, f64::NAN).is_err());
        let d = directions(8, 0.5).expect("8 directions");
        assert!((d[1].step - 0.5 * 2f64.sqrt()).abs() < 1e-15);
        assert!(d
            .iter()
            .all(|d| (d.vector[0].hypot(d.vector[1]) - 1.0).abs() < 1e-15));
    }
}
