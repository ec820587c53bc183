//! The feedback law u*(x) = ρ̄(x)/ρ(x) of the LP solution, and its RK4 integration.
//!
//! ρ(x) = Σᵢ rᵢ φᵢ(x) and ρ̄(x) = Σₖ dₖ Σᵢ zₖᵢ φᵢ(x) can be evaluated anywhere in the plane. With
//! indicator functions the field is piecewise constant per cell; with RBFs it is smooth. Where ρ
//! is (numerically) zero — outside the tube of a point-mass start — the law looks at the
//! neighbourhood (the eight points one cell away) before giving up and reporting that the
//! trajectory left the support.

use crate::basis::{Basis, BasisValue};
use crate::generators::Direction;
use crate::grid::PlanningGrid;
use crate::map::Point;

/// ρ below this fraction of max ρ counts as "no mass here".
pub const SUPPORT_THRESHOLD: f64 = 1e-7;

/// The velocity field of an LP solution.
#[derive(Debug, Clone)]
pub struct FeedbackField {
    basis: Basis,
    /// rᵢ per active function.
    density: Vec<f64>,
    /// Σₖ dₖ zₖᵢ per active function (the flux vector of each coefficient).
    flux: Vec<[f64; 2]>,
    /// Reference level of ρ for the support test.
    density_floor: f64,
    cell_size: f64,
}

impl FeedbackField {
    /// Combines the LP's density and per-direction fluxes into a field.
    pub fn new(
        basis: Basis,
        directions: &[Direction],
        density: Vec<f64>,
        flux_per_direction: &[Vec<f64>],
    ) -> Self {
        let n = basis.len();
        let mut flux = vec![[0.0; 2]; n];
        for (dir, z) in directions.iter().zip(flux_per_direction) {
            for (f, &zk) in flux.iter_mut().zip(z) {
                f[0] += dir.vector[0] * zk;
                f[1] += dir.vector[1] * zk;
            }
        }
        let max_density = density.iter().copied().fold(0.0f64, f64::max);
        let cell_size = basis.cell_size();
        Self {
            basis,
            density,
            flux,
            density_floor: SUPPORT_THRESHOLD * max_density,
            cell_size,
        }
    }

    /// The basis the field is expressed in.
    pub fn basis(&self) -> &Basis {
        &self.basis
    }

    fn sums(&self, p: Point, scratch: &mut Vec<BasisValue>) -> (f64, [f64; 2]) {
        self.basis.eval_into(p, scratch);
        let mut rho = 0.0;
        let mut bar = [0.0; 2];
        for &(i, v) in scratch.iter() {
            rho += self.density[i] * v;
            bar[0] += self.flux[i][0] * v;
            bar[1] += self.flux[i][1] * v;
        }
        (rho, bar)
    }

    /// ρ(p).
    pub fn density_at(&self, p: Point) -> f64 {
        self.sums(p, &mut Vec::new()).0
    }

    /// ρ at the centre of every cell of `grid`, row-major (`iy · width + ix`): the LP's
    /// occupation density, the expected time the start's unit mass spends per square metre
    /// there (0 on the targets).
    pub fn density_on(&self, grid: &PlanningGrid) -> Vec<f64> {
        let mut scratch = Vec::new();
        (0..grid.len())
            .map(|i| self.sums(grid.center_of_index(i), &mut scratch).0)
            .collect()
    }

    /// ρ̄(p), the flux vector.
    pub fn flux_at(&self, p: Point) -> [f64; 2] {
        self.sums(p, &mut Vec::new()).1
    }

    /// u(p) = ρ̄/ρ; where ρ(p) is zero, the ratio of the sums over the eight points one cell
    /// away (the neighbourhood); `None` when there is no mass there either.
    pub fn velocity_at(&self, p: Point) -> Option<[f64; 2]> {
        let mut scratch = Vec::new();
        let (rho, bar) = self.sums(p, &mut scratch);
        if rho > self.density_floor {
            return Some([bar[0] / rho, bar[1] / rho]);
        }
        let h = self.cell_size;
        let (mut rho_sum, mut bar_sum) = (0.0, [0.0; 2]);
        for (dx, dy) in [
            (1, 0),
            (1, 1),
            (0, 1),
            (-1, 1),
            (-1, 0),
            (-1, -1),
            (0, -1),
            (1, -1),
        ] {
            let (r, b) = self.sums([p[0] + dx as f64 * h, p[1] + dy as f64 * h], &mut scratch);
            rho_sum += r;
            bar_sum[0] += b[0];
            bar_sum[1] += b[1];
        }
        (rho_sum > self.density_floor).then(|| [bar_sum[0] / rho_sum, bar_sum[1] / rho_sum])
    }
}

/// How an integration ended.
#[derive(Debug, Clone, PartialEq)]
pub enum IntegrationOutcome {
    /// Entered the target set (and, where a free straight segment exists, the goal disc).
    ReachedGoal,
    /// The field vanished or the trajectory stopped making progress (a loop or a sink).
    Stuck { at: Point, reason: String },
    /// No mass around the current point: the law is undefined there.
    LeftSupport { at: Point },
    /// The next point would be off the grid or in a blocked cell.
    HitObstacle { at: Point },
}

impl IntegrationOutcome {
    /// Whether the trajectory reached the goal.
    pub fn reached_goal(&self) -> bool {
        matches!(self, IntegrationOutcome::ReachedGoal)
    }
}

/// Settings of the RK4 integration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntegrationSettings {
    /// Distance travelled per RK4 step at full speed, in cells.
    pub step_cells: f64,
    /// Give up after a path this many times the grid's half perimeter.
    pub max_length_factor: f64,
    /// Progress window (steps): a trajectory whose net displacement over the window is below a
    /// tenth of the distance it could have covered is stuck (a loop or a chatter).
    pub progress_window: usize,
}

impl Default for IntegrationSettings {
    fn default() -> Self {
        Self {
            step_cells: 0.2,
            max_length_factor: 4.0,
            progress_window: 60,
        }
    }
}

/// Integrates ẋ = u(x) with RK4 from `start` until a cell with `is_target` is entered.
///
/// The time step is chosen so that one step covers `step_cells` cells at speed `u_max`.
/// Returns the visited points (starting with `start`) and how the integration ended.
pub fn integrate(
    field: &FeedbackField,
    grid: &PlanningGrid,
    start: Point,
    is_target_cell: &dyn Fn(usize) -> bool,
    u_max: f64,
    settings: &IntegrationSettings,
) -> (Vec<Point>, IntegrationOutcome) {
    let h = grid.cell_size;
    let dt = settings.step_cells * h / u_max;
    let max_steps = (settings.max_length_factor * (grid.width + grid.height) as f64
        / settings.step_cells)
        .ceil() as usize;
    let mut path = vec![start];
    let mut x = start;
    let in_target = |p: Point| {
        grid.cell_of(p)
            .is_some_and(|(ix, iy)| is_target_cell(grid.index(ix, iy)))
    };
    for step in 0..max_steps {
        if in_target(x) {
            return (path, IntegrationOutcome::ReachedGoal);
        }
        let Some(k1) = field.velocity_at(x) else {
            return (path, IntegrationOutcome::LeftSupport { at: x });
        };
        let speed = k1[0].hypot(k1[1]);
        if speed < 1e-6 * u_max {
            return (
                path,
                IntegrationOutcome::Stuck {
                    at: x,
                    reason: format!("the field vanishes (|u| = {speed:.3e} m/s)"),
                },
            );
        }
        let stage =
            |base: Point, k: [f64; 2], a: f64| [base[0] + a * dt * k[0], base[1] + a * dt * k[1]];
        let Some(k2) = field.velocity_at(stage(x, k1, 0.5)) else {
            return (path, IntegrationOutcome::LeftSupport { at: x });
        };
        let Some(k3) = field.velocity_at(stage(x, k2, 0.5)) else {
            return (path, IntegrationOutcome::LeftSupport { at: x });
        };
        let Some(k4) = field.velocity_at(stage(x, k3, 1.0)) else {
            return (path, IntegrationOutcome::LeftSupport { at: x });
        };
        let next = [
            x[0] + dt / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
            x[1] + dt / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
        ];
        // Near an obstacle the RBF field is made of the tails of the neighbouring functions and
        // may point slightly into the (padded) obstacle: keep the tangential component (slide
        // along the wall) when that stays free; otherwise report the hit honestly. Whole
        // segments are checked, not only their end points: a step must not cut a corner.
        let next = if grid.segment_is_free(x, next) {
            next
        } else {
            let slides = [[next[0], x[1]], [x[0], next[1]]];
            let best = slides
                .into_iter()
                .filter(|&p| grid.segment_is_free(x, p))
                .max_by(|a, b| {
                    let da = (a[0] - x[0]).hypot(a[1] - x[1]);
                    let db = (b[0] - x[0]).hypot(b[1] - x[1]);
                    da.total_cmp(&db)
                });
            match best {
                Some(p) if (p[0] - x[0]).hypot(p[1] - x[1]) > 0.0 => p,
                _ => return (path, IntegrationOutcome::HitObstacle { at: next }),
            }
        };
        x = next;
        path.push(x);
        let w = settings.progress_window;
        if step >= w && path.len() > w {
            let back = path[path.len() - 1 - w];
            let net = (x[0] - back[0]).hypot(x[1] - back[1]);
            if net < 0.1 * w as f64 * settings.step_cells * h {
                return (
                    path,
                    IntegrationOutcome::Stuck {
                        at: x,
                        reason: format!(
                            "moved only {net:.3} m over the last {w} steps (a loop or a chatter)"
                        ),
                    },
                );
            }
        }
    }
    (
        path,
        IntegrationOutcome::Stuck {
            at: x,
            reason: format!("no goal after {max_steps} steps"),
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::basis::BasisKind;
    use crate::generators::directions;

    #[test]
    fn field_is_flux_over_density_and_integration_follows_it_into_the_target() {
        // 6 x 1 corridor, mass flowing east at speed 2 everywhere except the target cell 5.
        let grid = PlanningGrid::from_parts([0.0, 0.0], 1.0, 6, 1, vec![1.0; 6], vec![false; 6])
            .expect("grid");
        let basis = Basis::new(&grid, BasisKind::Indicator).expect("basis");
        let dirs = directions(4, 1.0).expect("dirs");
        let density = vec![0.5, 0.5, 0.5, 0.5, 0.5, 0.0];
        let mut flux = vec![vec![0.0; 6]; 4];
        flux[0] = vec![1.0, 1.0, 1.0, 1.0, 1.0, 0.0];
        let field = FeedbackField::new(basis, &dirs, density, &flux);
        let u = field.velocity_at([2.3, 0.4]).expect("mass here");
        assert!((u[0] - 2.0).abs() < 1e-12 && u[1].abs() < 1e-12);
        let (path, outcome) = integrate(
            &field,
            &grid,
            [0.5, 0.5],
            &|c| c == 5,
            2.0,
            &IntegrationSettings::default(),
        );
        assert_eq!(outcome, IntegrationOutcome::ReachedGoal);
        let end = path.last().expect("non-empty");
        assert!(end[0] >= 5.0 && (end[1] - 0.5).abs() < 1e-12);
    }

    #[test]
    fn opposing_cells_are_reported_stuck_and_empty_regions_as_left_support() {
        let grid = PlanningGrid::from_parts([0.0, 0.0], 1.0, 6, 1, vec![1.0; 6], vec![false; 6])
            .expect("grid");
        let dirs = directions(4, 1.0).expect("dirs");
        // Cells 1 and 2 push into each other: a sink the integration must not hide.
        let density = vec![0.0, 1.0, 1.0, 0.0, 0.0, 0.0];
        let mut flux = vec![vec![0.0; 6]; 4];
        flux[0][1] = 1.0;
        flux[2][2] = 1.0;
        let field = FeedbackField::new(
            Basis::new(&grid, BasisKind::Indicator).expect("basis"),
            &dirs,
            density,
            &flux,
        );
        let (_, outcome) = integrate(
            &field,
            &grid,
            [1.5, 0.5],
            &|c| c == 5,
            1.0,
            &IntegrationSettings::default(),
        );
        assert!(
            matches!(outcome, IntegrationOutcome::Stuck { .. }),
            "{outcome:?}"
        );
        let (_, outcome) = integrate(
            &field,
            &grid,
            [4.5, 0.5],
            &|c| c == 0,
            1.0,
            &IntegrationSettings::default(),
        );
        assert!(
            matches!(outcome, IntegrationOutcome::LeftSupport { .. }),
            "{outcome:?}"
        );
    }
}
