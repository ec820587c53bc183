//! Ulam's method: with indicator functions G is diagonal (samples per cell), so U = G⁻¹A row
//! by row, and `U_ij` is the fraction of cell i's snapshot samples that land in cell j.
//!
//! Every displacement is exactly one lattice vector and every sample lies strictly inside its
//! cell, so all samples of a cell land in the same cell, and the move rule (`valid_pair`)
//! depends on the two cells only: one sample per cell (its centre) gives the same U as any
//! sub-lattice, in O(cells) per direction instead of O(cells · samples) with a sparse row per
//! cell. Each column of Lₖ = (Uᵀ − I)/Δt is then `{i: −1/Δt, j: +1/Δt}` or empty (a wall), and
//! is written straight into CSC arrays. The directions are built on all cores.

use super::{flow, per_direction, valid_pair, Direction, GeneratorStats, SparseMatrix};
use crate::basis::Basis;
use crate::deadline::Deadline;
use crate::error::PlanError;
use crate::grid::PlanningGrid;

/// Cells built between two deadline checks (about 0.1 ms of work).
const CELLS_PER_DEADLINE_CHECK: usize = 4096;

/// One direction's generator and its blocked-move count.
struct UlamDirection {
    generator: SparseMatrix,
    walls: usize,
}

/// Builds Lₖ for every direction (see the module documentation).
pub(super) fn build_ulam(
    grid: &PlanningGrid,
    basis: &Basis,
    directions: &[Direction],
    deadline: Deadline,
    stats: &mut GeneratorStats,
) -> Result<Vec<SparseMatrix>, PlanError> {
    let built: Vec<Option<UlamDirection>> =
        per_direction(directions, |dir| ulam_direction(grid, basis, dir, deadline));
    stats.samples = basis.len();
    let mut generators = Vec::with_capacity(built.len());
    for d in built {
        let Some(d) = d else {
            return Err(PlanError::TimeLimit {
                phase: "the generator build",
                limit_s: deadline.limit_s(),
            });
        };
        stats.invalid_pairs += d.walls;
        stats.wall_rows += d.walls;
        generators.push(d.generator);
    }
    Ok(generators)
}

/// Lₖ of one direction, column by column in CSC order; `None` once `deadline` has passed.
fn ulam_direction(
    grid: &PlanningGrid,
    basis: &Basis,
    dir: &Direction,
    deadline: Deadline,
) -> Option<UlamDirection> {
    let n = basis.len();
    let rate = 1.0 / dir.step;
    let mut col_ptr = Vec::with_capacity(n + 1);
    let mut row_idx = Vec::with_capacity(2 * n);
    let mut values = Vec::with_capacity(2 * n);
    let mut walls = 0;
    col_ptr.push(0);
    for i in 0..n {
        if i % CELLS_PER_DEADLINE_CHECK == 0 && deadline.passed() {
            return None;
        }
        let x = grid.center_of_index(basis.cell(i));
        let y = flow(x, dir.vector, dir.step);
        let target = if valid_pair(grid, basis, x, y) {
            grid.cell_of(y)
                .and_then(|(ix, iy)| basis.index_of_cell(grid.index(ix, iy)))
        } else {
            None
        };
        match target {
            // A self-loop would be a wall as well; lattice shifts never produce one.
            Some(j) if j != i => {
                let (first, second) = if i < j {
                    ((i, -rate), (j, rate))
                } else {
                    ((j, rate), (i, -rate))
                };
                row_idx.extend([first.0, second.0]);
                values.extend([first.1, second.1]);
            }
            // Every move blocked: U_ii = 1 cancels against −I, an empty column.
            _ => walls += 1,
        }
        col_ptr.push(row_idx.len());
    }
    Some(UlamDirection {
        generator: SparseMatrix::new(n, n, col_ptr, row_idx, values),
        walls,
    })
}

#[cfg(test)]
mod tests {
    use super::super::test_grids::open_grid;
    use super::super::{Generators, SparseColumns};
    use crate::basis::BasisKind;

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
            for j in 0..l.n {
                let s: f64 = l.column(j).map(|e| e.1).sum();
                assert!(s.abs() < 1e-12);
            }
        }
        assert_eq!(gens.stats.max_negative_row_mass, 0.0);
    }

    /// The one-sample-per-cell build equals Ulam's estimate from the full sub-lattice of
    /// samples (fraction of each cell's samples landing in each cell, blocked moves staying).
    #[test]
    fn one_sample_per_cell_equals_the_sub_lattice_estimate_on_a_random_map() {
        use super::super::{flow, valid_pair};
        use rand::{Rng, SeedableRng};
        let (width, height) = (23, 17);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let blocked: Vec<usize> = (0..width * height)
            .filter(|_| rng.random_bool(0.2))
            .collect();
        let grid = open_grid(width, height, &blocked);
        let gens = Generators::build(&grid, BasisKind::Indicator, 8).expect("generators");
        let basis = &gens.basis;
        let per_axis = 3;
        let mut phi = Vec::new();
        for (dir, l) in gens.directions.iter().zip(&gens.generators) {
            for i in 0..basis.len() {
                let (ix, iy) = grid.coords(basis.cell(i));
                let mut landed = vec![0.0; basis.len()];
                for sy in 0..per_axis {
                    for sx in 0..per_axis {
                        let x = [
                            (ix as f64 + (sx as f64 + 0.5) / per_axis as f64) * grid.cell_size,
                            (iy as f64 + (sy as f64 + 0.5) / per_axis as f64) * grid.cell_size,
                        ];
                        let y = flow(x, dir.vector, dir.step);
                        let end = if valid_pair(&grid, basis, x, y) { y } else { x };
                        basis.eval_into(end, &mut phi);
                        assert_eq!(phi.len(), 1, "a sample lands in exactly one free cell");
                        landed[phi[0].0] += 1.0 / (per_axis * per_axis) as f64;
                    }
                }
                // Column i of L = (row i of U − e_i) / Δt.
                landed[i] -= 1.0;
                let mut expected: Vec<(usize, f64)> = landed
                    .iter()
                    .enumerate()
                    .filter(|e| e.1.abs() > 1e-12)
                    .map(|(j, &u)| (j, u / dir.step))
                    .collect();
                expected.sort_by_key(|e| e.0);
                let got: Vec<(usize, f64)> = l.column(i).collect();
                assert_eq!(
                    got.len(),
                    expected.len(),
                    "cell {i}, direction {:?}",
                    dir.shift
                );
                for (g, e) in got.iter().zip(&expected) {
                    assert_eq!(g.0, e.0);
                    assert!((g.1 - e.1).abs() < 1e-9 * e.1.abs(), "{g:?} vs {e:?}");
                }
            }
        }
    }
}
