//! Gaussian RBF generators: sparse and positivity-preserving.
//!
//! The least-squares estimate `U = G⁻¹A` of the shared note is dense (G⁻¹ is), costs O(Q³) and has
//! negative entries (fake sinks that only Clarabel can take, and that the feedback field can
//! fall into). Instead the functions are normalised into a partition of unity over the active
//! set, ψᵢ(x) = φᵢ(x) / Σⱼ φⱼ(x) (Shepard), truncated where φ is below [`PU_CUTOFF`], and U is
//! the Galerkin transfer of the snapshot pairs in that basis:
//!
//! `Uᵢⱼ = Σₛ ψᵢ(xₛ) ψⱼ(yₛ) / Σₛ ψᵢ(xₛ)`,
//!
//! the fraction of function i's sampled mass that the flow carries into function j ("fuzzy
//! Ulam"). Every entry is non-negative and every row sums to one because the ψ do: U is a Markov
//! matrix, so Lₖ = (Uᵀ − I)/Δt conserves mass, has no sinks, and the exact SSP solver (policy
//! iteration) applies. It is sparse by construction: row i only reaches functions within the
//! truncated supports around i's samples shifted by one lattice vector. This is the positivity
//! and Markov structure that NSDMD imposes on the regression, obtained in closed form.
//!
//! Samples lie on an exact sub-lattice of every cell and every displacement is one lattice
//! vector, so the image yₛ of a sample is the same sub-lattice point of the shifted cell: ψ is
//! evaluated once per sample and shared by all directions. The move rule is the one of
//! [`super::valid_pair`] (a blocked move leaves the sample where it is), decided per cell.
//! Memory is O(samples · support); time O(Q · samples per function · support) per direction,
//! directions in parallel.

use super::{per_direction, valid_pair, Direction, GeneratorStats, SparseMatrix};
use crate::basis::{Basis, BasisValue};
use crate::error::PlanError;
use crate::grid::PlanningGrid;
use crate::map::Point;

/// Largest accepted number of active RBF functions: 192² centres, so that one request stays well
/// below 1 GB (measured peak of a whole `pf-plan` RBF plan on c_shape: 128² centres 0.24 GB,
/// 256² centres 0.95 GB).
pub const MAX_RBF_FUNCTIONS: usize = 192 * 192;

/// Largest estimated memory of one RBF build, bytes.
pub const MAX_RBF_BUILD_BYTES: usize = 1 << 30;

/// Partition-of-unity weights per sample assumed by the memory estimate (9–13 measured).
const WEIGHTS_PER_SAMPLE: usize = 13;

/// Gaussian values below this (relative to the peak, 1) are left out of the partition of unity:
/// at σ = 0.5 h that keeps the functions within about 1.9 cell spacings, 9–13 per point.
pub const PU_CUTOFF: f64 = 1e-3;

/// Transition probabilities below this are dropped and the row renormalised (keeps Lₖ sparse;
/// the row stays exactly stochastic).
pub const TRANSFER_DROP: f64 = 1e-6;

/// Bytes the build needs for `samples` snapshot points with `per_point` functions each.
pub fn estimated_bytes(
    samples: usize,
    per_point: usize,
    functions: usize,
    directions: usize,
) -> usize {
    let weights = samples.saturating_mul(per_point).saturating_mul(2 * 12);
    let generators = functions
        .saturating_mul(directions)
        .saturating_mul(per_point * 2 * 16);
    weights.saturating_add(generators)
}

/// ψ at every sample, CSR over samples (empty outside the domain of the basis), and its
/// transpose: the samples (with weight) of every function.
struct PartitionOfUnity {
    sample_ptr: Vec<usize>,
    sample_entries: Vec<(u32, f64)>,
    function_ptr: Vec<usize>,
    function_entries: Vec<(u32, f64)>,
}

impl PartitionOfUnity {
    fn new(grid: &PlanningGrid, basis: &Basis, points: &[Point]) -> Self {
        let n = basis.len();
        let mut sample_ptr = Vec::with_capacity(points.len() + 1);
        let mut sample_entries: Vec<(u32, f64)> = Vec::new();
        let mut phi: Vec<BasisValue> = Vec::new();
        sample_ptr.push(0);
        let mut counts = vec![0usize; n + 1];
        for &x in points {
            if super::in_domain(grid, basis, x) {
                truncated_gaussians(grid, basis, x, &mut phi);
                let total: f64 = phi.iter().map(|e| e.1).sum();
                if total > 0.0 {
                    for &(i, v) in &phi {
                        // i < basis.len() ≤ MAX_RBF_FUNCTIONS < 2³²
                        sample_entries.push((i as u32, v / total));
                        counts[i + 1] += 1;
                    }
                }
            }
            sample_ptr.push(sample_entries.len());
        }
        for i in 0..n {
            counts[i + 1] += counts[i];
        }
        let function_ptr = counts;
        let mut fill = function_ptr[..n].to_vec();
        let mut function_entries = vec![(0u32, 0.0); sample_entries.len()];
        for s in 0..points.len() {
            for &(i, w) in &sample_entries[sample_ptr[s]..sample_ptr[s + 1]] {
                // s < points.len(), far below 2³² for any accepted grid.
                function_entries[fill[i as usize]] = (s as u32, w);
                fill[i as usize] += 1;
            }
        }
        Self {
            sample_ptr,
            sample_entries,
            function_ptr,
            function_entries,
        }
    }

    fn at_sample(&self, s: usize) -> &[(u32, f64)] {
        &self.sample_entries[self.sample_ptr[s]..self.sample_ptr[s + 1]]
    }

    fn samples_of(&self, i: usize) -> &[(u32, f64)] {
        &self.function_entries[self.function_ptr[i]..self.function_ptr[i + 1]]
    }
}

/// The values ≥ [`PU_CUTOFF`] of the active Gaussians at `x` (into `out`, cleared first): the same
/// values as [`Basis::eval_into`] keeps after the cut, found in the few cells whose centres lie
/// within the cut-off distance instead of the whole truncation radius (about 16 candidates
/// instead of 81 at σ = 0.5 h).
fn truncated_gaussians(grid: &PlanningGrid, basis: &Basis, x: Point, out: &mut Vec<BasisValue>) {
    out.clear();
    let h = grid.cell_size;
    let sigma = basis.sigma();
    let reach = sigma * (-2.0 * PU_CUTOFF.ln()).sqrt() / h;
    let inv_two_sigma_sq = 0.5 / (sigma * sigma);
    let cutoff = -PU_CUTOFF.ln();
    // Cells whose centre (index + 0.5) lies within `reach` of x along each axis (an empty range
    // when there is none inside the grid).
    let range = |coordinate: f64, origin: f64, cells: usize| {
        let f = (coordinate - origin) / h - 0.5;
        let first = (f - reach).ceil().max(0.0);
        let last = (f + reach).floor().min(cells as f64 - 1.0);
        // Whole numbers of at most the grid size (or NaN, which casts to 0 and -1 below).
        (first as i64, if last >= first { last as i64 } else { -1 })
    };
    let (x0, x1) = range(x[0], grid.origin[0], grid.width);
    let (y0, y1) = range(x[1], grid.origin[1], grid.height);
    for iy in y0..=y1 {
        // 0 ≤ iy < height here.
        let iy = iy as usize;
        let dy = x[1] - (grid.origin[1] + (iy as f64 + 0.5) * h);
        for ix in x0..=x1 {
            let ix = ix as usize;
            let Some(i) = basis.index_of_cell(grid.index(ix, iy)) else {
                continue;
            };
            let dx = x[0] - (grid.origin[0] + (ix as f64 + 0.5) * h);
            let e = (dx * dx + dy * dy) * inv_two_sigma_sq;
            if e <= cutoff {
                out.push((i, (-e).exp()));
            }
        }
    }
}

/// Builds Lₖ for every direction (see the module documentation). `points` is the sub-lattice of
/// `per_axis²` samples per cell, row-major by cell.
pub(super) fn build_rbf(
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
                "{n} RBF functions exceed the limit of {MAX_RBF_FUNCTIONS}; use a coarser grid or the indicator basis"
            ),
        });
    }
    let bytes = estimated_bytes(points.len(), WEIGHTS_PER_SAMPLE, n, directions.len());
    if bytes > MAX_RBF_BUILD_BYTES {
        return Err(PlanError::InvalidOption {
            name: "grid_size",
            reason: format!(
                "the RBF build would need about {} MiB, more than the limit of {} MiB; use fewer samples per function or a coarser grid",
                bytes >> 20,
                MAX_RBF_BUILD_BYTES >> 20
            ),
        });
    }
    let per_cell = points.len() / grid.len().max(1);
    if per_cell == 0
        || per_cell * grid.len() != points.len()
        || u32::try_from(points.len()).is_err()
    {
        return Err(PlanError::InvalidOption {
            name: "rbf samples",
            reason: format!(
                "{} snapshot samples do not form a sub-lattice of the {} cells",
                points.len(),
                grid.len()
            ),
        });
    }
    let pu = PartitionOfUnity::new(grid, basis, points);
    let pu = &pu;
    let built: Vec<(SparseMatrix, GeneratorStats)> =
        per_direction(directions, |dir| transfer(grid, basis, pu, per_cell, dir));
    let mut generators = Vec::with_capacity(built.len());
    for (l, s) in built {
        stats.invalid_pairs += s.invalid_pairs;
        stats.wall_rows += s.wall_rows;
        generators.push(l);
    }
    Ok(generators)
}

/// Lₖ of one direction, column by column (column i of Lₖ is row i of Uₖ, over Δt, minus eᵢ/Δt).
fn transfer(
    grid: &PlanningGrid,
    basis: &Basis,
    pu: &PartitionOfUnity,
    per_cell: usize,
    dir: &Direction,
) -> (SparseMatrix, GeneratorStats) {
    let n = basis.len();
    let mut stats = GeneratorStats::default();
    // Where each cell's samples go: the shifted cell, or nowhere (a blocked move stays).
    let h = grid.cell_size;
    let moved: Vec<Option<usize>> = (0..grid.len())
        .map(|c| {
            let x = grid.center_of_index(c);
            let y = [
                x[0] + dir.shift[0] as f64 * h,
                x[1] + dir.shift[1] as f64 * h,
            ];
            if valid_pair(grid, basis, x, y) {
                grid.cell_of(y).map(|(ix, iy)| grid.index(ix, iy))
            } else {
                None
            }
        })
        .collect();
    let rate = 1.0 / dir.step;
    let mut acc = vec![0.0; n];
    let mut touched: Vec<u32> = Vec::new();
    let mut column: Vec<(usize, f64)> = Vec::new();
    let mut col_ptr = Vec::with_capacity(n + 1);
    let mut row_idx = Vec::new();
    let mut values = Vec::new();
    col_ptr.push(0);
    for i in 0..n {
        let mut total = 0.0;
        for &(s, w) in pu.samples_of(i) {
            let s = s as usize;
            let (cell, sub) = (s / per_cell, s % per_cell);
            let image = match moved[cell] {
                Some(target) => target * per_cell + sub,
                None => {
                    stats.invalid_pairs += 1;
                    s
                }
            };
            total += w;
            for &(j, v) in pu.at_sample(image) {
                if acc[j as usize] == 0.0 {
                    touched.push(j);
                }
                acc[j as usize] += w * v;
            }
        }
        // Drop the tiny transitions, then renormalise so the row stays exactly stochastic.
        let mut kept = 0.0;
        for &j in &touched {
            let u = acc[j as usize] / total;
            if u < TRANSFER_DROP {
                acc[j as usize] = 0.0;
            } else {
                acc[j as usize] = u;
                kept += u;
            }
        }
        let stay = if kept > 0.0 { acc[i] / kept } else { 1.0 };
        if stay >= 1.0 - 1e-15 {
            // Every sample stays: U_ii = 1 cancels against −I, an empty column (a wall).
            stats.wall_rows += 1;
        } else {
            column.clear();
            column.push((i, (stay - 1.0) * rate));
            for &j in &touched {
                let j = j as usize;
                if j != i && acc[j] > 0.0 {
                    column.push((j, acc[j] / kept * rate));
                }
            }
            column.sort_unstable_by_key(|e| e.0);
            for &(j, v) in &column {
                row_idx.push(j);
                values.push(v);
            }
        }
        for &j in &touched {
            acc[j as usize] = 0.0;
        }
        touched.clear();
        col_ptr.push(row_idx.len());
    }
    (SparseMatrix::new(n, n, col_ptr, row_idx, values), stats)
}

#[cfg(test)]
mod tests {
    use super::super::test_grids::open_grid;
    use super::super::{Generators, SparseColumns};
    use crate::basis::BasisKind;

    /// The transfer is Markov (non-negative, rows of U summing to one, columns of L to zero) and
    /// moves an interior function's mass by one lattice vector on average.
    #[test]
    fn rbf_transfer_is_markov_and_shifts_interior_mass_by_one_lattice_vector() {
        let grid = open_grid(12, 12, &[]);
        let gens = Generators::build(&grid, BasisKind::DEFAULT_RBF, 8).expect("generators");
        let basis = &gens.basis;
        let h = grid.cell_size;
        for (dir, l) in gens.directions.iter().zip(&gens.generators) {
            for i in 0..l.n {
                let column: Vec<(usize, f64)> = l.column(i).collect();
                let sum: f64 = column.iter().map(|e| e.1).sum();
                assert!(sum.abs() < 1e-9 / dir.step, "column sum {sum}");
                for &(j, v) in &column {
                    if j == i {
                        assert!(v <= 0.0, "diagonal {v}");
                    } else {
                        assert!(v > 0.0, "off-diagonal {v}");
                    }
                }
            }
            // Mean displacement of the function at cell (5, 6): Σⱼ Uᵢⱼ (cⱼ − cᵢ) = Δt·Σⱼ Lⱼᵢ cⱼ.
            let i = basis.index_of_cell(grid.index(5, 6)).expect("active");
            let ci = basis.center(i);
            let mut mean = [0.0, 0.0];
            for (j, v) in gens.generators
                [gens.directions.iter().position(|d| d == dir).expect("dir")]
            .column(i)
            {
                let cj = basis.center(j);
                mean[0] += v * dir.step * (cj[0] - ci[0]);
                mean[1] += v * dir.step * (cj[1] - ci[1]);
            }
            let want = [dir.shift[0] as f64 * h, dir.shift[1] as f64 * h];
            let error = (mean[0] - want[0]).hypot(mean[1] - want[1]);
            assert!(
                error < 0.05 * h,
                "direction {:?}: mean {mean:?}, want {want:?}",
                dir.shift
            );
        }
        assert_eq!(gens.stats.wall_rows, 0, "{:?}", gens.stats);
        assert!(gens.stats.invalid_pairs > 0, "{:?}", gens.stats);
    }

    /// The fast candidate search finds exactly the values `eval_into` keeps after the cut.
    #[test]
    fn truncated_gaussians_equal_the_cut_basis_values() {
        let blocked: Vec<usize> = vec![3 * 9 + 4, 5 * 9 + 6];
        let grid = open_grid(9, 8, &blocked);
        let basis = crate::basis::Basis::new(&grid, BasisKind::DEFAULT_RBF).expect("basis");
        let (mut fast, mut full) = (Vec::new(), Vec::new());
        for k in 0..400 {
            // A deterministic scatter over the grid and a margin around it.
            let x = [
                -0.3 + (k as f64 * 0.618_034).fract() * (9.0 * 0.25 + 0.6),
                -0.3 + (k as f64 * 0.414_214).fract() * (8.0 * 0.25 + 0.6),
            ];
            super::truncated_gaussians(&grid, &basis, x, &mut fast);
            basis.eval_into(x, &mut full);
            full.retain(|&(_, v)| v >= super::PU_CUTOFF);
            fast.sort_by_key(|e| e.0);
            full.sort_by_key(|e| e.0);
            assert_eq!(fast.len(), full.len(), "{x:?}");
            for (a, b) in fast.iter().zip(&full) {
                assert_eq!(a.0, b.0);
                assert!((a.1 - b.1).abs() < 1e-15, "{a:?} vs {b:?}");
            }
        }
    }

    /// Next to an obstacle the functions that would carry mass into it keep it instead: nothing
    /// reaches an inactive function, and every column still sums to zero.
    #[test]
    fn rbf_transfer_never_moves_mass_into_the_obstacle_padding() {
        // A 3 x 3 block of obstacles in the middle of a 14 x 14 grid.
        let blocked: Vec<usize> = (6..9)
            .flat_map(|iy| (6..9).map(move |ix| iy * 14 + ix))
            .collect();
        let grid = open_grid(14, 14, &blocked);
        let gens = Generators::build(&grid, BasisKind::DEFAULT_RBF, 8).expect("generators");
        let n = gens.basis.len();
        for l in &gens.generators {
            assert_eq!(l.m, n);
            for i in 0..n {
                let sum: f64 = l.column(i).map(|e| e.1).sum();
                assert!(sum.abs() < 1e-9, "column sum {sum}");
            }
        }
        // The padding (one cell around the block) carries no function.
        assert!(gens.basis.index_of_cell(grid.index(5, 5)).is_none());
        assert!(gens.basis.index_of_cell(grid.index(4, 4)).is_some());
    }
}
