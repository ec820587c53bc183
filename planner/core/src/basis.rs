//! Basis functions of the density space: grid-cell indicators (Ulam's method) and Gaussian radial
//! basis functions on a lattice of centres (the paper's choice).
//!
//! Both bases live on a [`PlanningGrid`]: there is one candidate basis function per planning cell
//! (the indicator of the cell, or a Gaussian centred on the cell centre, so the RBF spacing is the
//! cell size). Candidates that would carry mass into an obstacle are left out of the basis
//! ("inactive"), which is how the hard obstacle constraint enters the density space:
//! - indicator: blocked cells are inactive (the grid's blocked set is already padded);
//! - RBF: centres in a blocked cell or next to one (8-neighbourhood) are inactive, because every
//!   Gaussian overlaps its neighbours a little and the literal `∫ 1_obstacle ρ = 0` would be
//!   infeasible (see `shared/notes/pf-planner.md`).

use crate::error::PlanError;
use crate::grid::PlanningGrid;
use crate::map::Point;

/// Gaussians are cut off where they fall below this fraction of their peak, so that the Gram
/// matrix, the generators and the field evaluation stay sparse. At this level the dropped tail
/// (perturbing U by about cond(G) × 1e-9 ≈ 3e-8) is far below the 1e-5 relative threshold used
/// to sparsify the generators.
pub const RBF_TRUNCATION: f64 = 1e-9;

/// Samples per axis per cell for the indicator basis (exact lattice quadrature: with a shift of
/// exactly one cell any count gives the same Ulam matrix; 3 × 3 keeps the construction honest).
pub const INDICATOR_SAMPLES_PER_AXIS: usize = 3;

/// Largest accepted number of samples per RBF centre (keeps the snapshot data bounded).
pub const MAX_SAMPLES_PER_BASIS: usize = 400;

/// How the generators of the RBF basis are estimated from the snapshot pairs (see
/// [`crate::generators`]). The indicator basis has one estimate, Ulam's method, which both are.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum RbfGenerators {
    /// The Galerkin transfer in the partition of unity of the truncated Gaussians: Markov by
    /// construction, so the exact SSP solver applies ([`crate::generators::rbf`]).
    #[default]
    Transfer,
    /// The paper's ANSDMD: the least-squares solve `G U = A` with row normalisation; it has
    /// negative transition mass, so the LP goes to Clarabel ([`crate::generators::ansdmd`]).
    Ansdmd,
}

impl RbfGenerators {
    /// Every kind, in the order of their names on the command line and the wire
    /// (`plan_options_t.GENERATORS_*` = index + 1; 0 is the default, `Transfer`).
    pub const ALL: [RbfGenerators; 2] = [RbfGenerators::Transfer, RbfGenerators::Ansdmd];

    /// Name on the command line, in reports and (upper case) in the wire constants.
    pub fn name(self) -> &'static str {
        match self {
            RbfGenerators::Transfer => "transfer",
            RbfGenerators::Ansdmd => "ansdmd",
        }
    }
}

impl std::fmt::Display for RbfGenerators {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for RbfGenerators {
    type Err = PlanError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|g| g.name() == s)
            .ok_or_else(|| PlanError::InvalidOption {
                name: "generators",
                reason: format!("unknown RBF generators {s:?}; use transfer or ansdmd"),
            })
    }
}

/// Which basis the P-F planner uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BasisKind {
    /// Indicator functions of the planning cells (Ulam's method; the LP is then a shortest-path problem).
    Indicator,
    /// Gaussian RBFs centred on the planning cell centres (spacing = cell size).
    Rbf {
        /// Gaussian width σ divided by the centre spacing; 0.5 is well conditioned, ≥ 1 is not.
        sigma_over_spacing: f64,
        /// Snapshot samples per basis function (transfer: rounded up to a square sub-lattice
        /// per cell; ANSDMD: this many seeded uniform samples in the function's cell).
        samples_per_basis: usize,
        /// How the generators are estimated from the snapshot pairs.
        generators: RbfGenerators,
    },
}

impl BasisKind {
    /// The configuration that worked in the prototype: σ = 0.5 h, 16 samples per function.
    pub const DEFAULT_RBF: BasisKind = BasisKind::Rbf {
        sigma_over_spacing: 0.5,
        samples_per_basis: 16,
        generators: RbfGenerators::Transfer,
    };

    /// [`BasisKind::DEFAULT_RBF`] with the paper's ANSDMD generators.
    pub const ANSDMD_RBF: BasisKind = BasisKind::Rbf {
        sigma_over_spacing: 0.5,
        samples_per_basis: 16,
        generators: RbfGenerators::Ansdmd,
    };

    /// Checks the parameters; the error names the offending option.
    pub fn validate(&self) -> Result<(), PlanError> {
        if let BasisKind::Rbf {
            sigma_over_spacing,
            samples_per_basis,
            ..
        } = *self
        {
            if !(sigma_over_spacing.is_finite() && (0.05..=3.0).contains(&sigma_over_spacing)) {
                return Err(PlanError::InvalidOption {
                    name: "rbf sigma_over_spacing",
                    reason: format!("{sigma_over_spacing} is outside 0.05..=3 (0.5 recommended)"),
                });
            }
            if !(1..=MAX_SAMPLES_PER_BASIS).contains(&samples_per_basis) {
                return Err(PlanError::InvalidOption {
                    name: "rbf samples_per_basis",
                    reason: format!(
                        "{samples_per_basis} is outside 1..={MAX_SAMPLES_PER_BASIS} (≥ 10 recommended)"
                    ),
                });
            }
        }
        Ok(())
    }

    /// Samples per axis of the square sub-lattice placed in every cell.
    pub fn samples_per_axis(&self) -> usize {
        match *self {
            BasisKind::Indicator => INDICATOR_SAMPLES_PER_AXIS,
            BasisKind::Rbf {
                samples_per_basis, ..
            } => (samples_per_basis as f64).sqrt().ceil().max(1.0) as usize,
        }
    }
}

/// One value of one basis function at a point: `(active basis index, φ(x))`.
pub type BasisValue = (usize, f64);

/// The active basis functions on a planning grid, with point evaluation.
#[derive(Debug, Clone)]
pub struct Basis {
    kind: BasisKind,
    origin: Point,
    cell_size: f64,
    width: usize,
    height: usize,
    /// Grid cell of each active basis function (its cell, or the cell of its centre).
    cells: Vec<usize>,
    /// Active index of the function of each grid cell, `None` where inactive.
    index_of_cell: Vec<Option<usize>>,
    /// σ in metres (RBF only).
    sigma: f64,
    /// Support radius in cells of a truncated Gaussian (RBF only).
    radius_cells: usize,
}

impl Basis {
    /// Builds the basis on `grid`; fails on invalid parameters or when no function remains active.
    pub fn new(grid: &PlanningGrid, kind: BasisKind) -> Result<Self, PlanError> {
        kind.validate()?;
        let blocked = |ix: usize, iy: usize| grid.blocked[grid.index(ix, iy)];
        let active = |ix: usize, iy: usize| match kind {
            BasisKind::Indicator => !blocked(ix, iy),
            BasisKind::Rbf { .. } => {
                let (x0, x1) = (ix.saturating_sub(1), (ix + 1).min(grid.width - 1));
                let (y0, y1) = (iy.saturating_sub(1), (iy + 1).min(grid.height - 1));
                !(y0..=y1).any(|y| (x0..=x1).any(|x| blocked(x, y)))
            }
        };
        let mut cells = Vec::new();
        let mut index_of_cell = vec![None; grid.len()];
        for iy in 0..grid.height {
            for ix in 0..grid.width {
                if active(ix, iy) {
                    index_of_cell[grid.index(ix, iy)] = Some(cells.len());
                    cells.push(grid.index(ix, iy));
                }
            }
        }
        if cells.is_empty() {
            return Err(PlanError::InvalidOption {
                name: "basis",
                reason: "no basis function lies in free space (the map is all obstacle)".into(),
            });
        }
        let (sigma, radius_cells) = match kind {
            BasisKind::Indicator => (0.0, 0),
            BasisKind::Rbf {
                sigma_over_spacing, ..
            } => {
                let sigma = sigma_over_spacing * grid.cell_size;
                let radius = sigma * (-2.0 * RBF_TRUNCATION.ln()).sqrt();
                (sigma, (radius / grid.cell_size).ceil() as usize)
            }
        };
        Ok(Self {
            kind,
            origin: grid.origin,
            cell_size: grid.cell_size,
            width: grid.width,
            height: grid.height,
            cells,
            index_of_cell,
            sigma,
            radius_cells,
        })
    }

    /// The basis kind.
    pub fn kind(&self) -> BasisKind {
        self.kind
    }

    /// Number of active basis functions.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Whether the basis is empty (never, for a basis that [`Basis::new`] returned).
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Grid cell (row-major index) of active function `i`.
    pub fn cell(&self, i: usize) -> usize {
        self.cells[i]
    }

    /// Active index of the function attached to grid cell `cell`, if active.
    pub fn index_of_cell(&self, cell: usize) -> Option<usize> {
        self.index_of_cell.get(cell).copied().flatten()
    }

    /// Centre of function `i` (the centre of its cell).
    pub fn center(&self, i: usize) -> Point {
        let c = self.cells[i];
        [
            self.origin[0] + ((c % self.width) as f64 + 0.5) * self.cell_size,
            self.origin[1] + ((c / self.width) as f64 + 0.5) * self.cell_size,
        ]
    }

    /// Edge length of the grid cells the basis lives on (the RBF centre spacing), metres.
    pub fn cell_size(&self) -> f64 {
        self.cell_size
    }

    /// σ in metres (0 for the indicator basis).
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// How far (in cells) a basis function reaches beyond its own cell.
    pub fn support_radius_cells(&self) -> usize {
        self.radius_cells
    }

    /// Integer cell coordinates of `p` without clamping (may lie outside the grid).
    fn raw_cell(&self, p: Point) -> (i64, i64) {
        (
            ((p[0] - self.origin[0]) / self.cell_size).floor() as i64,
            ((p[1] - self.origin[1]) / self.cell_size).floor() as i64,
        )
    }

    /// Appends the non-zero values of all active functions at `p` to `out` (cleared first).
    /// Points off the grid see the indicator basis as zero; Gaussians extend over the whole plane.
    pub fn eval_into(&self, p: Point, out: &mut Vec<BasisValue>) {
        out.clear();
        if !(p[0].is_finite() && p[1].is_finite()) {
            return;
        }
        let (cx, cy) = self.raw_cell(p);
        match self.kind {
            BasisKind::Indicator => {
                if cx >= 0 && cy >= 0 && (cx as usize) < self.width && (cy as usize) < self.height {
                    if let Some(i) = self.index_of_cell[cy as usize * self.width + cx as usize] {
                        out.push((i, 1.0));
                    }
                }
            }
            BasisKind::Rbf { .. } => {
                let r = self.radius_cells as i64;
                let inv_two_sigma_sq = 0.5 / (self.sigma * self.sigma);
                let cutoff = -RBF_TRUNCATION.ln();
                let x_range = (cx - r).max(0)..=(cx + r).min(self.width as i64 - 1);
                for iy in (cy - r).max(0)..=(cy + r).min(self.height as i64 - 1) {
                    let dy = p[1] - (self.origin[1] + (iy as f64 + 0.5) * self.cell_size);
                    for ix in x_range.clone() {
                        let cell = iy as usize * self.width + ix as usize;
                        let Some(i) = self.index_of_cell[cell] else {
                            continue;
                        };
                        let dx = p[0] - (self.origin[0] + (ix as f64 + 0.5) * self.cell_size);
                        let e = (dx * dx + dy * dy) * inv_two_sigma_sq;
                        if e <= cutoff {
                            out.push((i, (-e).exp()));
                        }
                    }
                }
            }
        }
    }

    /// Integrals `∫ w(x) φᵢ(x) dx` over the plane for every active function, by exact-lattice
    /// quadrature with `per_axis²` points per cell. For Gaussians the lattice extends beyond the
    /// grid by the support radius, so every function sees the same total mass; `weight` should
    /// then be clamped at the grid edge (as [`PlanningGrid::cost_at`] is).
    pub fn integrals(&self, per_axis: usize, weight: impl Fn(Point) -> f64) -> Vec<f64> {
        let per_axis = per_axis.max(1);
        let mut out = vec![0.0; self.len()];
        let pad = self.radius_cells as i64;
        let da = (self.cell_size / per_axis as f64).powi(2);
        let mut values = Vec::new();
        for cy in -pad..self.height as i64 + pad {
            for cx in -pad..self.width as i64 + pad {
                for sy in 0..per_axis {
                    for sx in 0..per_axis {
                        let p = [
                            self.origin[0]
                                + (cx as f64 + (sx as f64 + 0.5) / per_axis as f64)
                                    * self.cell_size,
                            self.origin[1]
                                + (cy as f64 + (sy as f64 + 0.5) / per_axis as f64)
                                    * self.cell_size,
                        ];
                        self.eval_into(p, &mut values);
                        if values.is_empty() {
                            continue;
                        }
                        let w = weight(p) * da;
                        for &(i, v) in &values {
                            out[i] += w * v;
                        }
                    }
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(width: usize, height: usize, blocked: &[usize]) -> PlanningGrid {
        let mut b = vec![false; width * height];
        for &i in blocked {
            b[i] = true;
        }
        PlanningGrid::from_parts(
            [1.0, -2.0],
            0.5,
            width,
            height,
            vec![0.5; width * height],
            b,
        )
        .expect("valid grid")
    }

    #[test]
    fn indicator_basis_skips_blocked_cells_and_evaluates_to_one_inside_its_cell() {
        let g = grid(4, 3, &[5]);
        let basis = Basis::new(&g, BasisKind::Indicator).expect("basis");
        assert_eq!(basis.len(), 11);
        assert_eq!(basis.index_of_cell(5), None);
        let mut values = Vec::new();
        basis.eval_into(g.cell_center(3, 2), &mut values);
        assert_eq!(
            values,
            vec![(basis.index_of_cell(11).expect("active"), 1.0)]
        );
        basis.eval_into(g.cell_center(1, 1), &mut values);
        assert!(values.is_empty(), "blocked cell carries no basis function");
        basis.eval_into([-10.0, 0.0], &mut values);
        assert!(values.is_empty());
        // ∫ φᵢ = cell area.
        let masses = basis.integrals(3, |_| 1.0);
        assert!(masses.iter().all(|m| (m - 0.25).abs() < 1e-12));
    }

    #[test]
    fn gaussian_integrals_match_the_analytic_mass_everywhere_including_the_edge() {
        let g = grid(6, 5, &[]);
        let basis = Basis::new(&g, BasisKind::DEFAULT_RBF).expect("basis");
        let sigma = basis.sigma();
        assert!((sigma - 0.25).abs() < 1e-15);
        let analytic = 2.0 * std::f64::consts::PI * sigma * sigma;
        for m in basis.integrals(6, |_| 1.0) {
            assert!(
                (m - analytic).abs() < 1e-6 * analytic,
                "mass {m} vs {analytic}"
            );
        }
        let mut values = Vec::new();
        let c = basis.center(7);
        basis.eval_into(c, &mut values);
        let own = values.iter().find(|(i, _)| *i == 7).expect("own function");
        assert!((own.1 - 1.0).abs() < 1e-15);
        let neighbour = values.iter().find(|(i, _)| *i == 8).expect("neighbour");
        // Distance h = 2σ: exp(-2).
        assert!((neighbour.1 - (-2.0f64).exp()).abs() < 1e-12);
    }

    #[test]
    fn rbf_centres_next_to_obstacles_are_inactive() {
        let g = grid(5, 5, &[12]);
        let basis = Basis::new(&g, BasisKind::DEFAULT_RBF).expect("basis");
        assert_eq!(basis.len(), 25 - 9);
        for cell in [6, 7, 8, 11, 12, 13, 16, 17, 18] {
            assert_eq!(basis.index_of_cell(cell), None);
        }
    }

    #[test]
    fn bad_parameters_are_rejected() {
        let g = grid(3, 3, &[]);
        for kind in [
            BasisKind::Rbf {
                sigma_over_spacing: f64::NAN,
                samples_per_basis: 10,
                generators: RbfGenerators::Transfer,
            },
            BasisKind::Rbf {
                sigma_over_spacing: 0.5,
                samples_per_basis: 0,
                generators: RbfGenerators::Ansdmd,
            },
            BasisKind::Rbf {
                sigma_over_spacing: -1.0,
                samples_per_basis: 10,
                generators: RbfGenerators::Transfer,
            },
        ] {
            assert!(matches!(
                Basis::new(&g, kind),
                Err(PlanError::InvalidOption { .. })
            ));
        }
        let all_blocked = grid(2, 2, &[0, 1, 2, 3]);
        assert!(Basis::new(&all_blocked, BasisKind::Indicator).is_err());
    }
}
