//! The paper's ANSDMD for Gaussian RBFs: least squares on the snapshot pairs, row-normalised.
//!
//! For every active function, [`BasisKind::Rbf::samples_per_basis`] points are drawn uniformly in
//! its cell (one seeded generator, [`ANSDMD_SEED`], so every build is the same); together they
//! cover the domain of the basis. For each direction dₖ the sample moves to `y = x + Δt·dₖ`, or
//! stays (`y = x`) when the move is blocked ([`super::valid_pair`]). Then, with Φ(X) the basis
//! values at the samples and P their number,
//!
//! `G = Φ(X)Φ(X)ᵀ/P`, `A = Φ(X)Φ(Y)ᵀ/P`, `U = argmin ‖G U − A‖_F = G⁻¹A`,
//!
//! entries below [`ANSDMD_DROP`] × max |U| are dropped, every row of U is divided by its sum (the
//! paper's row normalisation; a row whose sum is not positive, or that only stays, is the
//! identity: a wall) and `Lₖ = (Uᵀ − I)/Δtₖ`.
//!
//! G is symmetric positive definite for enough samples and σ < h (condition number about 30 at
//! σ = 0.5 h), so the least-squares solution is G⁻¹A. G⁻¹ is formed once with faer's dense
//! Cholesky and shared by all directions: A has only the overlaps of truncated Gaussians (about
//! 150 entries per column), so each column of U costs that many dense axpys of length Q instead of
//! the 2Q² of a triangular solve per column. U itself is dense (G⁻¹ is), which is what bounds the
//! size ([`MAX_ANSDMD_FUNCTIONS`]).
//!
//! **Where the result fails to be a generator of a Markov flow.** Row normalisation makes every
//! row of U sum to one, so Lₖ conserves coefficient mass exactly, but the raw least-squares rows do
//! not sum to one (their largest deviation is [`GeneratorStats::max_row_sum_error`]) and U keeps
//! negative entries ([`GeneratorStats::negative_entries`],
//! [`GeneratorStats::max_negative_row_mass`]): mass moved by such a row creates negative density
//! elsewhere, a fake sink the LP can use to lower its cost. The exact SSP solver needs a
//! non-negative U ([`crate::ssp::Structure::General`] otherwise), so the LP of these generators
//! goes to Clarabel.

use faer::linalg::solvers::DenseSolveCore;
use faer::{Mat, Side};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tracing::debug;

use super::rbf::MAX_RBF_BUILD_BYTES;
use super::SparseMatrix;
use super::{flow, per_direction, valid_pair, Direction, GeneratorStats, SparseColumns};
use crate::basis::{Basis, BasisValue};
use crate::deadline::Deadline;
use crate::error::PlanError;
use crate::grid::PlanningGrid;
use crate::map::Point;

/// Largest number of active functions of an ANSDMD build: G⁻¹ and, per direction built at once, A
/// and U are dense Q × Q (64²: 134 MB each).
pub const MAX_ANSDMD_FUNCTIONS: usize = 64 * 64;

/// Seed of the snapshot samples (fixed: the same map always gives the same generators).
pub const ANSDMD_SEED: u64 = 0x00a5_d3d0_2026;

/// Entries of U below this fraction of max |U| are dropped before the row normalisation (the
/// shared note: from 1e-9 to 1e-5 the LP value changed by < 1e-5 relative, and U turns sparse).
pub const ANSDMD_DROP: f64 = 1e-5;

/// A row of U whose sum is at most this is treated as a wall (identity), not normalised: dividing
/// by a vanishing sum would blow its entries up.
pub const WALL_ROW_SUM: f64 = 1e-6;

/// Bytes of the dense matrices of a build of `functions` with `workers` directions at once.
pub fn estimated_bytes(functions: usize, workers: usize) -> usize {
    let dense = functions.saturating_mul(functions).saturating_mul(8);
    // G (then G⁻¹ in its place, plus faer's factor) and A, U per worker.
    dense.saturating_mul(2usize.saturating_add(workers.saturating_mul(2)))
}

/// ANSDMD statistics of one direction (merged into [`GeneratorStats`]).
#[derive(Default)]
struct DirectionStats {
    invalid_pairs: usize,
    wall_rows: usize,
    negative_entries: usize,
    max_negative_row_mass: f64,
    max_row_sum_error: f64,
}

/// Builds Lₖ for every direction (see the module documentation).
pub(super) fn build_ansdmd(
    grid: &PlanningGrid,
    basis: &Basis,
    directions: &[Direction],
    samples_per_basis: usize,
    deadline: Deadline,
    stats: &mut GeneratorStats,
) -> Result<Vec<SparseMatrix>, PlanError> {
    let n = basis.len();
    if n > MAX_ANSDMD_FUNCTIONS {
        return Err(PlanError::InvalidOption {
            name: "grid_size",
            reason: format!(
                "{n} RBF functions exceed the limit of {MAX_ANSDMD_FUNCTIONS} for ANSDMD generators (its least squares is dense); use a coarser grid or the transfer generators"
            ),
        });
    }
    let workers = std::thread::available_parallelism()
        .map_or(1, usize::from)
        .clamp(1, directions.len().max(1));
    let bytes = estimated_bytes(n, workers);
    if bytes > MAX_RBF_BUILD_BYTES {
        return Err(PlanError::InvalidOption {
            name: "grid_size",
            reason: format!(
                "the ANSDMD build would need about {} MiB, more than the limit of {} MiB; use a coarser grid or the transfer generators",
                bytes >> 20,
                MAX_RBF_BUILD_BYTES >> 20
            ),
        });
    }
    let samples = sample_points(grid, basis, samples_per_basis);
    let p = samples.len() as f64;
    stats.samples = samples.len();
    let phi_x: Vec<Vec<BasisValue>> = samples
        .iter()
        .map(|&x| {
            let mut v = Vec::new();
            basis.eval_into(x, &mut v);
            v
        })
        .collect();
    let mut gram = Mat::<f64>::zeros(n, n);
    for phi in &phi_x {
        for &(j, vj) in phi {
            let column = gram.col_as_slice_mut(j);
            for &(i, vi) in phi {
                column[i] += vi * vj / p;
            }
        }
    }
    deadline.check("the ANSDMD Gram matrix")?;
    let llt = gram.llt(Side::Lower).map_err(|e| PlanError::InvalidOption {
        name: "rbf basis",
        reason: format!(
            "the Gram matrix of the ANSDMD samples is not positive definite ({e:?}): use more samples per basis function or a smaller sigma"
        ),
    })?;
    drop(gram);
    // G is symmetric, so column l of G⁻¹ is also its row l.
    let g_inv = llt.inverse();
    drop(llt);
    deadline.check("the ANSDMD least squares")?;
    let data = Data {
        grid,
        basis,
        samples: &samples,
        phi_x: &phi_x,
        g_inv: &g_inv,
        weight: 1.0 / p,
        deadline,
    };
    let built = per_direction(directions, |dir| direction(&data, dir));
    let mut generators = Vec::with_capacity(built.len());
    for result in built {
        let (l, s) = result?;
        stats.invalid_pairs += s.invalid_pairs;
        stats.wall_rows += s.wall_rows;
        stats.negative_entries += s.negative_entries;
        stats.max_negative_row_mass = stats.max_negative_row_mass.max(s.max_negative_row_mass);
        stats.max_row_sum_error = stats.max_row_sum_error.max(s.max_row_sum_error);
        generators.push(l);
    }
    debug!(
        negative_entries = stats.negative_entries,
        max_negative_row_mass = stats.max_negative_row_mass,
        max_row_sum_error = stats.max_row_sum_error,
        "ANSDMD generators"
    );
    Ok(generators)
}

/// `per_basis` seeded uniform samples in the cell of every active function, in function order.
fn sample_points(grid: &PlanningGrid, basis: &Basis, per_basis: usize) -> Vec<Point> {
    let mut rng = ChaCha8Rng::seed_from_u64(ANSDMD_SEED);
    let h = grid.cell_size;
    let mut points = Vec::with_capacity(basis.len() * per_basis);
    for i in 0..basis.len() {
        let (ix, iy) = grid.coords(basis.cell(i));
        for _ in 0..per_basis {
            let (u, v): (f64, f64) = (rng.random(), rng.random());
            points.push([
                grid.origin[0] + (ix as f64 + u) * h,
                grid.origin[1] + (iy as f64 + v) * h,
            ]);
        }
    }
    points
}

/// Shared, read-only inputs of the per-direction regression.
struct Data<'a> {
    grid: &'a PlanningGrid,
    basis: &'a Basis,
    samples: &'a [Point],
    /// Basis values at every sample.
    phi_x: &'a [Vec<BasisValue>],
    /// G⁻¹ (symmetric).
    g_inv: &'a Mat<f64>,
    /// 1 / number of samples.
    weight: f64,
    deadline: Deadline,
}

/// Lₖ of one direction: A from the snapshot pairs, U = G⁻¹A, sparsified and row-normalised.
fn direction(
    data: &Data<'_>,
    dir: &Direction,
) -> Result<(SparseMatrix, DirectionStats), PlanError> {
    let n = data.basis.len();
    let mut stats = DirectionStats::default();
    let mut a = Mat::<f64>::zeros(n, n);
    let mut phi_y = Vec::new();
    for (&x, phi_x) in data.samples.iter().zip(data.phi_x) {
        let y = flow(x, dir.vector, dir.step);
        // A blocked move stays where it is: the pair (x, x).
        let phi_y: &[BasisValue] = if valid_pair(data.grid, data.basis, x, y) {
            data.basis.eval_into(y, &mut phi_y);
            &phi_y
        } else {
            stats.invalid_pairs += 1;
            phi_x
        };
        for &(j, vj) in phi_y {
            let column = a.col_as_slice_mut(j);
            let wj = vj * data.weight;
            for &(i, vi) in phi_x {
                column[i] += vi * wj;
            }
        }
    }
    let mut u = Mat::<f64>::zeros(n, n);
    for j in 0..n {
        if j % 64 == 0 {
            data.deadline.check("the ANSDMD least squares")?;
        }
        let u_col = u.col_as_slice_mut(j);
        for (l, &a_lj) in a.col_as_slice(j).iter().enumerate() {
            if a_lj != 0.0 {
                for (u_ij, &g_il) in u_col.iter_mut().zip(data.g_inv.col_as_slice(l)) {
                    *u_ij += g_il * a_lj;
                }
            }
        }
    }
    drop(a);
    let max_abs = (0..n)
        .flat_map(|j| u.col_as_slice(j).iter().map(|v| v.abs()))
        .fold(0.0f64, f64::max);
    let cut = ANSDMD_DROP * max_abs;
    let rate = 1.0 / dir.step;
    let mut columns: Vec<Vec<(usize, f64)>> = Vec::with_capacity(n);
    let mut row: Vec<(usize, f64)> = Vec::new();
    for i in 0..n {
        row.clear();
        let mut raw_sum = 0.0;
        for j in 0..n {
            let v = u[(i, j)];
            raw_sum += v;
            if v.abs() > cut {
                row.push((j, v));
            }
        }
        stats.max_row_sum_error = stats.max_row_sum_error.max((raw_sum - 1.0).abs());
        let sum: f64 = row.iter().map(|e| e.1).sum();
        let only_stays = row.iter().all(|&(j, _)| j == i);
        if sum <= WALL_ROW_SUM || only_stays {
            // A wall: U's row is the identity, so column i of Lₖ is empty.
            stats.wall_rows += 1;
            columns.push(Vec::new());
            continue;
        }
        let mut negative = 0.0;
        let mut column = Vec::with_capacity(row.len() + 1);
        let mut stay = 0.0;
        for &(j, v) in &row {
            let v = v / sum;
            if v < 0.0 {
                negative -= v;
                stats.negative_entries += 1;
            }
            if j == i {
                stay = v;
            } else {
                column.push((j, v * rate));
            }
        }
        column.push((i, (stay - 1.0) * rate));
        stats.max_negative_row_mass = stats.max_negative_row_mass.max(negative);
        columns.push(column);
    }
    Ok((SparseMatrix::from_columns(n, columns), stats))
}

#[cfg(test)]
mod tests {
    use super::super::test_grids::open_grid;
    use super::super::{Generators, SparseColumns};
    use crate::basis::BasisKind;

    /// The least-squares generator is close to a lattice shift in the interior, every column of
    /// Lₖ sums to zero after the row normalisation, and, unlike the transfer, it has negative
    /// transition mass (measured, not assumed away).
    #[test]
    fn ansdmd_rows_are_normalised_near_a_lattice_shift_and_keep_negative_mass() {
        let grid = open_grid(12, 12, &[]);
        let gens = Generators::build(&grid, BasisKind::ANSDMD_RBF, 8).expect("generators");
        let basis = &gens.basis;
        for (dir, l) in gens.directions.iter().zip(&gens.generators) {
            for i in 0..l.n {
                let sum: f64 = l.column(i).map(|e| e.1).sum();
                assert!(sum.abs() < 1e-9 / dir.step, "column sum {sum}");
            }
            let i = basis.index_of_cell(grid.index(5, 6)).expect("active");
            let j = basis
                .index_of_cell(grid.index((5 + dir.shift[0]) as usize, (6 + dir.shift[1]) as usize))
                .expect("active");
            let to_j = l.column(i).find(|e| e.0 == j).expect("shift entry").1 * dir.step;
            assert!((to_j - 1.0).abs() < 0.05, "U(i→i+shift) = {to_j}");
        }
        let s = &gens.stats;
        assert!(s.negative_entries > 0, "{s:?}");
        assert!(s.max_negative_row_mass > 0.0, "{s:?}");
        // The raw rows do not sum to one: what the normalisation corrects.
        assert!(s.max_row_sum_error > 1e-6, "{s:?}");
        assert_eq!(s.samples, 144 * 16);
    }

    /// The same map gives the same generators (seeded samples).
    #[test]
    fn ansdmd_build_is_deterministic() {
        let grid = open_grid(9, 7, &[4 * 9 + 4]);
        let a = Generators::build(&grid, BasisKind::ANSDMD_RBF, 4).expect("generators");
        let b = Generators::build(&grid, BasisKind::ANSDMD_RBF, 4).expect("generators");
        for (la, lb) in a.generators.iter().zip(&b.generators) {
            assert_eq!(la.colptr, lb.colptr);
            assert_eq!(la.rowval, lb.rowval);
            assert_eq!(la.nzval, lb.nzval);
        }
    }
}
