//! Data-driven Perron-Frobenius generators (ANSDMD), one per control direction.
//!
//! For each direction dₖ the planner generates snapshot pairs `(xₛ, yₛ)` by flowing the single
//! integrator ẋ = dₖ for a time Δtₖ from every point xₛ of an exact sub-lattice of every cell in
//! the domain of the basis (the cells that carry an active function), so the generator only ever
//! sees sampled data, never the flow map itself. Then
//! - `G = Φ(X) Φ(X)ᵀ / P`, `A = Φ(X) Φ(Y)ᵀ / P` (P samples),
//! - `U = argmin ‖G U − A‖_F` (G is diagonal for indicators: Ulam's method; a faer Cholesky
//!   factorisation and G⁻¹ for Gaussian RBFs),
//! - every row of `U` is divided by its sum (a row whose moves are all blocked is the identity:
//!   a reflecting wall, never a free sink),
//! - `Lₖ = (Uᵀ − I) / Δtₖ`, stored sparse (entries below [`SPARSITY_THRESHOLD`] × max |U|
//!   dropped).
//!
//! Δtₖ makes each displacement exactly one lattice vector (Δt = h axially, √2·h diagonally): the
//! condition under which the indicator LP is exactly Dijkstra's problem and the RBF generator stays
//! sparse. A move is *blocked* when its image leaves the grid or when the axis-aligned box spanned
//! by the displacement touches a blocked cell (a robot moving past an obstacle corner would graze
//! it; for one-cell moves this is the graph rule "a diagonal step must not cut a blocked corner").
//! The sampled system stops at obstacles: a blocked move leaves the sample where it is, so its
//! snapshot pair is `(x, x)`. This keeps every row of `A` complete (`A` is `G` times a
//! stochastic-like matrix), so the least squares never divides a row by the small remainder of
//! a partly blocked function — which, with the older "blocked pairs carry no data" rule, gave
//! RBF rows next to obstacles tens of units of negative mass, fake sinks the LP exploited (the
//! `pits` failure). For indicators a one-cell move is blocked for all samples of a cell or for
//! none, so a blocked cell-direction is still exactly the wall `U = I` (zero column in Lₖ).

use std::time::Instant;

use faer::linalg::solvers::DenseSolveCore;
use faer::{Mat, Side};
use tracing::debug;

use crate::basis::{Basis, BasisKind, BasisValue};
use crate::error::PlanError;
use crate::grid::PlanningGrid;
use crate::map::Point;

/// Entries of U smaller than this fraction of the largest |U| are dropped (keeps Lₖ sparse).
///
/// Only RBF generators have such entries (Ulam's are exactly 0 or 1). Measured on the three
/// scenarios at 32² centres: going from 1e-9 to 1e-5 changes the LP value by < 1e-5 relative and
/// the trajectories not at all, while the tiny entries made the LP 10–20× slower (`pits`:
/// 11 s → 0.5 s).
pub const SPARSITY_THRESHOLD: f64 = 1e-5;

/// A row of U whose sum is at most this is treated as having lost all its samples (a wall).
pub const WALL_ROW_SUM: f64 = 1e-6;

/// Largest accepted number of active RBF functions (the dense least squares is O(Q³)).
pub const MAX_RBF_FUNCTIONS: usize = 4096;

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
fn flow(x: Point, d: [f64; 2], t: f64) -> Point {
    [x[0] + t * d[0], x[1] + t * d[1]]
}

/// A compressed-sparse-column matrix (the generators and the LP constraint blocks).
#[derive(Debug, Clone, PartialEq)]
pub struct SparseMatrix {
    /// Rows.
    pub nrows: usize,
    /// Columns.
    pub ncols: usize,
    /// Start of each column in `row_idx`/`values` (length `ncols + 1`).
    pub col_ptr: Vec<usize>,
    /// Row index of each stored entry, increasing within a column.
    pub row_idx: Vec<usize>,
    /// Value of each stored entry.
    pub values: Vec<f64>,
}

impl SparseMatrix {
    /// Builds a CSC matrix from per-column `(row, value)` lists (rows sorted here, duplicates summed).
    pub fn from_columns(nrows: usize, columns: Vec<Vec<(usize, f64)>>) -> Self {
        let ncols = columns.len();
        let mut col_ptr = Vec::with_capacity(ncols + 1);
        let mut row_idx = Vec::new();
        let mut values = Vec::new();
        col_ptr.push(0);
        for mut col in columns {
            col.sort_unstable_by_key(|e| e.0);
            for (row, value) in col {
                debug_assert!(row < nrows, "row {row} out of {nrows}");
                if row_idx.len() > *col_ptr.last().unwrap_or(&0) && row_idx.last() == Some(&row) {
                    *values.last_mut().unwrap_or(&mut 0.0) += value;
                } else {
                    row_idx.push(row);
                    values.push(value);
                }
            }
            col_ptr.push(row_idx.len());
        }
        Self {
            nrows,
            ncols,
            col_ptr,
            row_idx,
            values,
        }
    }

    /// Stored entries of column `j` as `(row, value)`.
    pub fn column(&self, j: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let range = self.col_ptr[j]..self.col_ptr[j + 1];
        self.row_idx[range.clone()]
            .iter()
            .copied()
            .zip(self.values[range].iter().copied())
    }

    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    /// `y = self · x`.
    pub fn mul_vec(&self, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; self.nrows];
        for (j, &xj) in x.iter().enumerate().take(self.ncols) {
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
    /// Snapshot samples per direction (all lattice points of all cells).
    pub samples: usize,
    /// Samples, summed over directions, whose move was blocked (left the grid or touched an
    /// obstacle) and which therefore stayed in place.
    pub invalid_pairs: usize,
    /// Rows of U, summed over directions, that are the identity (every move blocked: a wall).
    pub wall_rows: usize,
    /// Largest total negative mass of a row of U after normalisation (0 for indicators).
    pub max_negative_row_mass: f64,
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
fn in_domain(grid: &PlanningGrid, basis: &Basis, p: Point) -> bool {
    grid.cell_of(p)
        .is_some_and(|(ix, iy)| basis.index_of_cell(grid.index(ix, iy)).is_some())
}

/// Whether the move `x → y` is allowed: `y` in the domain of the basis and the box spanned by the
/// displacement free of blocked cells.
fn valid_pair(grid: &PlanningGrid, basis: &Basis, x: Point, y: Point) -> bool {
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
        let started = Instant::now();
        let basis = Basis::new(grid, kind)?;
        let directions = directions(direction_count, grid.cell_size)?;
        let per_axis = kind.samples_per_axis();
        let points = sample_points(grid, per_axis);
        let mut stats = GeneratorStats {
            samples: points.len(),
            ..GeneratorStats::default()
        };
        let generators = match kind {
            BasisKind::Indicator => build_ulam(grid, &basis, &directions, &points, &mut stats),
            BasisKind::Rbf { .. } => build_rbf(grid, &basis, &directions, &points, &mut stats)?,
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

/// Lₖ = (Uᵀ − I)/Δt from the row-normalised rows of U (each row a sparse list `(column, value)`).
fn generator_from_rows(n: usize, rows: Vec<Vec<(usize, f64)>>, step: f64) -> SparseMatrix {
    // Row i of U is column i of Uᵀ.
    let columns = rows
        .into_iter()
        .enumerate()
        .map(|(i, row)| {
            let mut col: Vec<(usize, f64)> = row.into_iter().map(|(j, u)| (j, u / step)).collect();
            col.push((i, -1.0 / step));
            col
        })
        .collect();
    let mut l = SparseMatrix::from_columns(n, columns);
    // A self-loop (U_ii = 1, a wall) cancels against −I: drop the exact zeros it leaves.
    let mut columns = Vec::with_capacity(n);
    for j in 0..n {
        columns.push(l.column(j).filter(|&(_, v)| v != 0.0).collect());
    }
    l = SparseMatrix::from_columns(n, columns);
    l
}

/// Divides each row by its sum; a row without data (no samples) becomes the identity (a wall).
fn normalise_rows(rows: &mut [Vec<(usize, f64)>], stats: &mut GeneratorStats) {
    for (i, row) in rows.iter_mut().enumerate() {
        let sum: f64 = row.iter().map(|e| e.1).sum();
        if sum <= WALL_ROW_SUM || (row.len() == 1 && row[0].0 == i) {
            stats.wall_rows += 1;
            row.clear();
            row.push((i, 1.0));
            continue;
        }
        let mut negative = 0.0;
        for e in row.iter_mut() {
            e.1 /= sum;
            if e.1 < 0.0 {
                negative -= e.1;
            }
        }
        stats.max_negative_row_mass = stats.max_negative_row_mass.max(negative);
    }
}

/// Ulam's method: G is diagonal (sample count per cell), so U = G⁻¹A row by row.
fn build_ulam(
    grid: &PlanningGrid,
    basis: &Basis,
    directions: &[Direction],
    points: &[Point],
    stats: &mut GeneratorStats,
) -> Vec<SparseMatrix> {
    let n = basis.len();
    let p = points.len() as f64;
    let mut phi_x = Vec::new();
    let mut phi_y = Vec::new();
    // G = Φ(X)Φ(X)ᵀ/P is diagonal for indicators.
    let mut gram = vec![0.0; n];
    for &x in points {
        basis.eval_into(x, &mut phi_x);
        for &(i, v) in &phi_x {
            gram[i] += v * v / p;
        }
    }
    directions
        .iter()
        .map(|dir| {
            let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
            for &x in points {
                basis.eval_into(x, &mut phi_x);
                if phi_x.is_empty() {
                    continue;
                }
                let y = flow(x, dir.vector, dir.step);
                // A blocked move stays where it is: the pair (x, x).
                if valid_pair(grid, basis, x, y) {
                    basis.eval_into(y, &mut phi_y);
                } else {
                    stats.invalid_pairs += 1;
                    phi_y.clone_from(&phi_x);
                }
                for &(i, vi) in &phi_x {
                    for &(j, vj) in &phi_y {
                        accumulate(&mut rows[i], j, vi * vj / p);
                    }
                }
            }
            for (i, row) in rows.iter_mut().enumerate() {
                for e in row.iter_mut() {
                    e.1 /= gram[i];
                }
            }
            normalise_rows(&mut rows, stats);
            generator_from_rows(n, rows, dir.step)
        })
        .collect()
}

/// Adds `v` to entry `j` of a short sparse row.
#[inline]
fn accumulate(row: &mut Vec<(usize, f64)>, j: usize, v: f64) {
    match row.iter_mut().find(|e| e.0 == j) {
        Some(e) => e.1 += v,
        None => row.push((j, v)),
    }
}

/// Gaussian RBFs: dense Gram matrix over the samples in the domain of the basis, one faer
/// Cholesky factorisation and G⁻¹ shared by all directions; each direction's sparse A is
/// multiplied by G⁻¹ and U is then sparsified (see [`rbf_direction`]).
fn build_rbf(
    grid: &PlanningGrid,
    basis: &Basis,
    directions: &[Direction],
    points: &[Point],
    stats: &mut GeneratorStats,
) -> Result<Vec<SparseMatrix>, PlanError> {
    let n = basis.len();
    if n > MAX_RBF_FUNCTIONS {
        return Err(PlanError::InvalidOption {
            name: "grid_size",
            reason: format!(
                "{n} RBF functions exceed the limit of {MAX_RBF_FUNCTIONS} for the dense least squares; use a coarser grid or the indicator basis"
            ),
        });
    }
    let p = points.len() as f64;
    let t0 = Instant::now();
    let phis: Vec<Vec<BasisValue>> = points
        .iter()
        .map(|&x| {
            // The regression lives on the domain of the basis: samples in the hole around an
            // obstacle (where no active function is centred) are not data.
            let mut v = Vec::new();
            if in_domain(grid, basis, x) {
                basis.eval_into(x, &mut v);
            }
            v
        })
        .collect();
    let mut gram = Mat::<f64>::zeros(n, n);
    for phi in &phis {
        for &(i, vi) in phi {
            for &(j, vj) in phi {
                gram[(i, j)] += vi * vj / p;
            }
        }
    }
    let llt = gram.llt(Side::Lower).map_err(|e| PlanError::InvalidOption {
        name: "rbf basis",
        reason: format!(
            "Gram matrix of the RBF samples is not positive definite ({e:?}): use more samples per basis function or a smaller sigma"
        ),
    })?;
    // G is symmetric: G⁻¹ once, shared by all directions (column l = row l).
    let g_inv = llt.inverse();
    debug!(
        gram_and_inverse_s = t0.elapsed().as_secs_f64(),
        "RBF Gram matrix inverted"
    );
    let data = RbfData {
        grid,
        basis,
        points,
        phis: &phis,
        g_inv: &g_inv,
        weight: 1.0 / p,
    };
    let results: Vec<(SparseMatrix, GeneratorStats)> = directions
        .iter()
        .map(|dir| rbf_direction(&data, dir))
        .collect();
    let mut out = Vec::with_capacity(directions.len());
    for (l, s) in results {
        stats.invalid_pairs += s.invalid_pairs;
        stats.wall_rows += s.wall_rows;
        stats.max_negative_row_mass = stats.max_negative_row_mass.max(s.max_negative_row_mass);
        out.push(l);
    }
    Ok(out)
}

/// Shared, read-only inputs of the per-direction RBF regression.
struct RbfData<'a> {
    grid: &'a PlanningGrid,
    basis: &'a Basis,
    points: &'a [Point],
    /// Basis values at every sample (empty outside the domain of the basis).
    phis: &'a [Vec<BasisValue>],
    /// G⁻¹ (symmetric).
    g_inv: &'a Mat<f64>,
    /// 1 / number of samples.
    weight: f64,
}

/// Lₖ of one direction: A from the snapshot pairs, U = G⁻¹A, sparsified and row-normalised.
fn rbf_direction(data: &RbfData<'_>, dir: &Direction) -> (SparseMatrix, GeneratorStats) {
    let n = data.basis.len();
    let mut stats = GeneratorStats::default();
    let mut phi_y = Vec::new();
    let mut a = Mat::<f64>::zeros(n, n);
    for (&x, phi_x) in data.points.iter().zip(data.phis) {
        if phi_x.is_empty() {
            continue;
        }
        let y = flow(x, dir.vector, dir.step);
        // A blocked move stays where it is: the pair (x, x).
        if valid_pair(data.grid, data.basis, x, y) {
            data.basis.eval_into(y, &mut phi_y);
        } else {
            stats.invalid_pairs += 1;
            phi_y.clone_from(phi_x);
        }
        for &(j, vj) in &phi_y {
            let col = a.col_as_slice_mut(j);
            let wj = vj * data.weight;
            for &(i, vi) in phi_x {
                col[i] += vi * wj;
            }
        }
    }
    // U = G⁻¹ A (least squares of G U = A with G symmetric positive definite). A has only the
    // overlaps of truncated Gaussians (a few dozen entries per column), so G⁻¹ A costs
    // n · nnz(A) flops instead of the 2n³ of a dense triangular solve per direction.
    let mut u = Mat::<f64>::zeros(n, n);
    for j in 0..n {
        let u_col = u.col_as_slice_mut(j);
        for (l, &a_lj) in a.col_as_slice(j).iter().enumerate() {
            if a_lj != 0.0 {
                for (u_ij, &g_il) in u_col.iter_mut().zip(data.g_inv.col_as_slice(l)) {
                    *u_ij += g_il * a_lj;
                }
            }
        }
    }
    let mut max_abs = 0.0f64;
    for j in 0..n {
        for &v in u.col_as_slice(j) {
            max_abs = max_abs.max(v.abs());
        }
    }
    let cut = SPARSITY_THRESHOLD * max_abs;
    let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    for j in 0..n {
        for (i, &v) in u.col_as_slice(j).iter().enumerate() {
            if v.abs() > cut {
                rows[i].push((j, v));
            }
        }
    }
    normalise_rows(&mut rows, &mut stats);
    (generator_from_rows(n, rows, dir.step), stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn open_grid(width: usize, height: usize, blocked: &[usize]) -> PlanningGrid {
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

    #[test]
    fn ulam_generator_is_the_one_cell_shift_with_walls_at_the_edge_and_obstacles() {
        // 4 x 3 grid, cell (2, 1) blocked.
        let grid = open_grid(4, 3, &[6]);
        let gens = Generators::build(&grid, BasisKind::Indicator, 8).expect("generators");
        let basis = &gens.basis;
        let h = grid.cell_size;
        let east = &gens.generators[0];
        let ne = &gens.generators[1];
        let idx =
            |ix: usize, iy: usize| basis.index_of_cell(grid.index(ix, iy)).expect("free cell");
        // Cell (0, 1) moves east into (1, 1): column has −1/h on the diagonal and +1/h at (1, 1).
        let col: Vec<(usize, f64)> = east.column(idx(0, 1)).collect();
        assert_eq!(col.len(), 2);
        assert!(col.contains(&(idx(0, 1), -1.0 / h)) && col.contains(&(idx(1, 1), 1.0 / h)));
        // Cell (1, 1) would move east into the blocked cell: a wall (zero column).
        assert_eq!(east.column(idx(1, 1)).count(), 0);
        // Cell (3, 0) is at the east edge: a wall.
        assert_eq!(east.column(idx(3, 0)).count(), 0);
        // NE from (1, 0) would pass the blocked corner (2, 1)... it lands in (2, 1) itself: wall.
        assert_eq!(ne.column(idx(1, 0)).count(), 0);
        // NE from (2, 0) passes (2, 1) on its way to (3, 1): cutting the corner is not allowed.
        assert_eq!(ne.column(idx(2, 0)).count(), 0);
        // NE from (0, 0) to (1, 1) is free.
        let diag = 2f64.sqrt() * h;
        let col: Vec<(usize, f64)> = ne.column(idx(0, 0)).collect();
        assert!(col.contains(&(idx(1, 1), 1.0 / diag)));
        // Every column of every Lₖ sums to zero: mass is conserved.
        for l in &gens.generators {
            for j in 0..l.ncols {
                let s: f64 = l.column(j).map(|e| e.1).sum();
                assert!(s.abs() < 1e-12);
            }
        }
        assert_eq!(gens.stats.max_negative_row_mass, 0.0);
    }

    #[test]
    fn rbf_generator_is_close_to_a_lattice_shift_in_the_interior_and_conserves_mass() {
        let grid = open_grid(10, 10, &[]);
        let gens = Generators::build(&grid, BasisKind::DEFAULT_RBF, 4).expect("generators");
        let basis = &gens.basis;
        let h = grid.cell_size;
        let east = &gens.generators[0];
        let i = basis.index_of_cell(grid.index(4, 5)).expect("active");
        let j = basis.index_of_cell(grid.index(5, 5)).expect("active");
        let col: Vec<(usize, f64)> = east.column(i).collect();
        let to_j = col.iter().find(|e| e.0 == j).expect("shift entry").1;
        let self_entry = col.iter().find(|e| e.0 == i).expect("diagonal").1;
        // Edge effects of a 10 x 10 grid reach the interior at the 0.4 % level (as in the prototype).
        assert!((to_j * h - 1.0).abs() < 1e-2, "U(i→i+e1) = {}", to_j * h);
        assert!(
            (self_entry * h + 1.0).abs() < 1e-2,
            "diagonal {}",
            self_entry * h
        );
        for l in &gens.generators {
            for j in 0..l.ncols {
                let s: f64 = l.column(j).map(|e| e.1).sum();
                assert!(s.abs() < 1e-9 / h, "column sum {s}");
            }
        }
        // Rows next to the map edge carry the largest negative mass (8 % here, on a tiny grid).
        assert!(gens.stats.max_negative_row_mass < 0.1, "{:?}", gens.stats);
        // Moves off the map stay in place: the edge functions keep part of their mass (no
        // function is a complete wall on an open grid), and the blocked samples are counted.
        assert_eq!(gens.stats.wall_rows, 0, "{:?}", gens.stats);
        assert!(gens.stats.invalid_pairs > 0, "{:?}", gens.stats);
    }

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
