//! The paper's LP as written, solved with Clarabel, next to the well-posed form the project uses
//! (docs/paper-lp.md).
//!
//! Paper (single integrator, so the drift f = 0 and its generator L₀ = 0): density coefficients
//! r ≥ 0, signed flux coefficients z_j (one per axis, generators L_j learned from forward samples
//! along +e_j), and w_j ≥ |z_j| for the l1 norm of the control:
//!
//! ```text
//! minimise   Bᵀr + Σ_j Bᵀw_j
//! subject to L₀r − Σ_j L_j z_j = t      (L₀ = 0)
//!            −w_j ≤ z_j ≤ w_j,  r ≥ 0,  oᵀr = 0   (o = obstacle indicator integrals)
//! ```
//!
//! Well posed (docs/realtime-planner.md and `crate::lp`): fluxes z_k ≥ 0 along ±e_j, each with its
//! own forward-learned generator, and the speed bound Σ_k z_k ≤ u_max·r.
//!
//! Both are built on the same indicator basis over the whole grid (the obstacle enters only
//! through oᵀr = 0, as in the paper), with the target's basis function removed (absorbing).
//! The test asserts what Clarabel returns for each: the paper's LP is solved to optimality, but
//! with r = 0 (so u = ρ̄/ρ is 0/0 everywhere), its obstacle constraint holds vacuously while the
//! whole flow crosses the obstacle, and its value is a shortest path that ignores the obstacle
//! and prices moves against an axis at their destination cell; the well-posed form returns the
//! obstacle-respecting optimum (1 + 1/u_max) × Dijkstra, and so does the project's pipeline.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use pf_planner::basis::BasisKind;
use pf_planner::generators::{Generators, SparseColumns};
use pf_planner::graph::{distances_to_targets, Connectivity};
use pf_planner::grid::PlanningGrid;
use pf_planner::lp::{self, LpProblem, LpSettings, LpSolver};

const WIDTH: usize = 14;
const HEIGHT: usize = 10;
/// Free cells cost this much; the wall costs 1 (the largest p).
const P_FREE: f64 = 0.3;
const WALL_X: usize = 7;
/// Left of the wall, target right of it: the flow runs along +x.
const START: (usize, usize) = (2, 1);
const TARGET: (usize, usize) = (11, 1);
const U_MAX: f64 = 1.0;

/// Column x = 7, rows 0..=8: a wall with a gap in the top row.
fn is_wall(cell: usize) -> bool {
    cell % WIDTH == WALL_X && cell / WIDTH < HEIGHT - 1
}

/// Unit cells (h = 1), so with a unit start coefficient the flux cost of one move is p.
fn grid(walls_blocked: bool) -> PlanningGrid {
    let cells = WIDTH * HEIGHT;
    let cost = (0..cells)
        .map(|c| if is_wall(c) { 1.0 } else { P_FREE })
        .collect();
    let blocked = (0..cells).map(|c| walls_blocked && is_wall(c)).collect();
    PlanningGrid::from_parts([0.0, 0.0], 1.0, WIDTH, HEIGHT, cost, blocked).expect("grid")
}

fn index(cell: (usize, usize)) -> usize {
    cell.1 * WIDTH + cell.0
}

/// An LP in Clarabel's form: variables x, `min cᵀx`, equality rows `a x = b`, and rows `a x ≥ 0`.
struct Lp {
    cost: Vec<f64>,
    equalities: Vec<(Vec<(usize, f64)>, f64)>,
    nonnegative: Vec<Vec<(usize, f64)>>,
}

struct Solved {
    status: SolverStatus,
    x: Vec<f64>,
    objective: f64,
    iterations: u32,
}

impl Lp {
    fn solve(&self) -> Solved {
        let n = self.cost.len();
        // Clarabel: A x + s = b with s in the cones; `a x ≥ 0` is the row −a x + s = 0, s ≥ 0.
        let rows: Vec<(Vec<(usize, f64)>, f64)> = self
            .equalities
            .iter()
            .cloned()
            .chain(
                self.nonnegative
                    .iter()
                    .map(|row| (row.iter().map(|&(v, a)| (v, -a)).collect(), 0.0)),
            )
            .collect();
        let mut columns: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
        for (r, (row, _)) in rows.iter().enumerate() {
            for &(v, a) in row {
                columns[v].push((r, a));
            }
        }
        let a = CscMatrix::from_columns(rows.len(), columns);
        let b: Vec<f64> = rows.iter().map(|(_, rhs)| *rhs).collect();
        let cones = [
            SupportedConeT::ZeroConeT(self.equalities.len()),
            SupportedConeT::NonnegativeConeT(self.nonnegative.len()),
        ];
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .tol_gap_abs(1e-10)
            .tol_gap_rel(1e-10)
            .tol_feas(1e-10)
            .max_iter(200)
            .build()
            .expect("settings");
        let p = CscMatrix::<f64>::zeros((n, n));
        let mut solver =
            DefaultSolver::new(&p, &self.cost, &a, &b, &cones, settings).expect("Clarabel setup");
        solver.solve();
        let solution = &solver.solution;
        Solved {
            status: solution.status,
            x: solution.x.clone(),
            objective: solution.obj_val,
            iterations: solution.iterations,
        }
    }
}

/// The full-grid indicator basis and its 4 forward-learned generators, with the numbering of the
/// non-target functions (rows and variables of both LPs).
struct Setup {
    generators: Generators,
    /// Non-target basis functions, in LP order.
    kept: Vec<usize>,
    /// LP row of each basis function (`None` for the target).
    row_of: Vec<Option<usize>>,
    /// Bᵢ = ∫ p φᵢ = p of the cell (unit cells).
    cost: Vec<f64>,
    /// Start coefficients.
    start: Vec<f64>,
    /// oᵢ = ∫ 1_obstacle φᵢ.
    obstacle: Vec<f64>,
}

fn setup(start: (usize, usize), target: (usize, usize)) -> Setup {
    let free = grid(false);
    let generators = Generators::build(&free, BasisKind::Indicator, 4).expect("generators");
    let n = generators.basis.len();
    assert_eq!(n, WIDTH * HEIGHT, "the paper's basis covers the whole grid");
    let target = generators
        .basis
        .index_of_cell(index(target))
        .expect("target");
    let kept: Vec<usize> = (0..n).filter(|&i| i != target).collect();
    let mut row_of = vec![None; n];
    for (row, &i) in kept.iter().enumerate() {
        row_of[i] = Some(row);
    }
    let cell = |i: usize| generators.basis.cell(i);
    let cost = (0..n).map(|i| free.cost[cell(i)]).collect();
    let start_function = generators.basis.index_of_cell(index(start)).expect("start");
    let start = (0..n)
        .map(|i| if i == start_function { 1.0 } else { 0.0 })
        .collect();
    let obstacle = (0..n)
        .map(|i| if is_wall(cell(i)) { 1.0 } else { 0.0 })
        .collect();
    Setup {
        generators,
        kept,
        row_of,
        cost,
        start,
        obstacle,
    }
}

impl Setup {
    /// The generator whose samples move by `shift` cells.
    fn generator(&self, shift: [i64; 2]) -> usize {
        self.generators
            .directions
            .iter()
            .position(|d| d.shift == shift)
            .expect("direction")
    }

    /// Mass balance `−Σ_k L_k z_k = t` over the non-target rows: entries (variable, coefficient)
    /// per row, for flux blocks `(generator, first variable of its block)`.
    fn balance(&self, blocks: &[(usize, usize)]) -> Vec<(Vec<(usize, f64)>, f64)> {
        let m = self.kept.len();
        let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); m];
        let h = self.generators.basis.cell_size();
        for &(k, first) in blocks {
            let l = &self.generators.generators[k];
            for (var, &i) in self.kept.iter().enumerate() {
                for (j, value) in l.column(i) {
                    if let Some(row) = self.row_of[j] {
                        // ×h: the generator has units 1/Δt with Δt = h; the flux per unit length.
                        rows[row].push((first + var, -h * value));
                    }
                }
            }
        }
        rows.into_iter()
            .zip(self.kept.iter().map(|&i| self.start[i]))
            .collect()
    }

    /// oᵀr = 0 for the density block starting at variable 0.
    fn obstacle_row(&self) -> (Vec<(usize, f64)>, f64) {
        let row = self
            .kept
            .iter()
            .enumerate()
            .filter(|&(_, &i)| self.obstacle[i] != 0.0)
            .map(|(var, &i)| (var, self.obstacle[i]))
            .collect();
        (row, 0.0)
    }

    fn kept_cost(&self) -> Vec<f64> {
        self.kept.iter().map(|&i| self.cost[i]).collect()
    }

    fn in_wall(&self, var: usize) -> bool {
        is_wall(self.generators.basis.cell(self.kept[var]))
    }
}

/// Shortest path of unit mass from `start` to `target` on the obstacle-free 4-connected grid where a
/// move along +e_j is paid at its source cell and a move against it at its destination cell (a
/// negative z_j at cell c moves mass from c + e_j into c at the price B_c), and no move enters the
/// target against an axis (the target has no flux variable). Bellman-Ford over an explicit edge list.
fn paper_graph_value(start: (usize, usize), target: (usize, usize)) -> f64 {
    let p = grid(false).cost;
    let target = index(target);
    let mut edges = Vec::new();
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            let c = index((x, y));
            for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                if nx >= WIDTH || ny >= HEIGHT {
                    continue;
                }
                let ahead = index((nx, ny));
                if c != target {
                    edges.push((c, ahead, p[c])); // z_j(c) > 0: c → c + e_j at B_c
                    edges.push((ahead, c, p[c])); // z_j(c) < 0: c + e_j → c at B_c
                }
            }
        }
    }
    let mut d = vec![f64::INFINITY; WIDTH * HEIGHT];
    d[target] = 0.0;
    for _ in 0..d.len() {
        let mut changed = false;
        for &(from, to, w) in &edges {
            if d[to] + w < d[from] {
                d[from] = d[to] + w;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    d[index(start)]
}

/// What Clarabel returns for the paper's LP from `start` to `target`.
struct PaperOutcome {
    solved: Solved,
    /// Σ B r and the largest |r|.
    density_cost: f64,
    max_density: f64,
    /// Σ |z| over the wall's cells.
    wall_flux: f64,
    /// Cells where |z_x| + |z_y| > 1e-3.
    moving_cells: usize,
}

fn solve_paper_lp(start: (usize, usize), target: (usize, usize)) -> PaperOutcome {
    let s = setup(start, target);
    let m = s.kept.len();
    let b = s.kept_cost();
    // Variables: r | z_x | z_y | w_x | w_y, m each.
    let (r0, zx, zy, wx, wy) = (0, m, 2 * m, 3 * m, 4 * m);
    let mut cost = vec![0.0; 5 * m];
    for block in [r0, wx, wy] {
        cost[block..block + m].copy_from_slice(&b);
    }
    // f = 0: the density block of the balance (L₀ r) is empty.
    let mut equalities = s.balance(&[(s.generator([1, 0]), zx), (s.generator([0, 1]), zy)]);
    equalities.push(s.obstacle_row());
    let mut nonnegative = Vec::new();
    for v in 0..m {
        nonnegative.push(vec![(r0 + v, 1.0)]);
        for (z, w) in [(zx, wx), (zy, wy)] {
            nonnegative.push(vec![(w + v, 1.0), (z + v, -1.0)]); // w ≥ z
            nonnegative.push(vec![(w + v, 1.0), (z + v, 1.0)]); // w ≥ −z
        }
    }
    let solved = Lp {
        cost,
        equalities,
        nonnegative,
    }
    .solve();
    let flux = |v: usize| solved.x[zx + v].abs() + solved.x[zy + v].abs();
    PaperOutcome {
        density_cost: (0..m).map(|v| b[v] * solved.x[r0 + v]).sum(),
        max_density: (0..m).map(|v| solved.x[r0 + v].abs()).fold(0.0, f64::max),
        wall_flux: (0..m).filter(|&v| s.in_wall(v)).map(flux).sum(),
        moving_cells: (0..m).filter(|&v| flux(v) > 1e-3).count(),
        solved,
    }
}

#[test]
fn the_papers_lp_as_written_has_zero_density_and_its_flow_crosses_the_obstacle() {
    // Along +x, and back along −x (moves against the axis, and the target entered from its far side).
    for (start, target) in [(START, TARGET), (TARGET, START)] {
        let paper = solve_paper_lp(start, target);
        let graph = paper_graph_value(start, target);
        let detour =
            distances_to_targets(&grid(true), &[index(target)], Connectivity::Four)[index(start)];
        println!(
            "paper LP {start:?} → {target:?}: {:?} after {} iterations, objective {:.9}, Σ B r = {:.2e}, \
             max |r| = {:.2e}, flux through wall cells {:.6}, {} cells with flux; obstacle-free \
             up/down-wind graph value {graph:.9}; obstacle-respecting Dijkstra {detour:.9}",
            paper.solved.status,
            paper.solved.iterations,
            paper.solved.objective,
            paper.density_cost,
            paper.max_density,
            paper.wall_flux,
            paper.moving_cells
        );
        let objective = paper.solved.objective;
        // Neither unbounded (the cost is ≥ 0) nor infeasible (any path is a feasible flux).
        assert_eq!(paper.solved.status, SolverStatus::Solved);
        // r appears only in its own cost (B > 0), r ≥ 0 and oᵀr = 0: the optimum is r = 0, so
        // the feedback law u = ρ̄/ρ is 0/0 wherever mass moves.
        assert!(
            paper.density_cost.abs() <= 1e-7 * objective && paper.max_density <= 1e-7,
            "density not zero: Σ B r = {:.2e}, max |r| = {:.2e}",
            paper.density_cost,
            paper.max_density
        );
        assert!(paper.moving_cells >= 9, "the flux should span the map");
        // oᵀr = 0 holds with r = 0 and does not stop the flux: the unit mass crosses the wall.
        assert!(
            paper.wall_flux >= 0.99,
            "flux through wall cells {:.6}, expected the whole unit mass",
            paper.wall_flux
        );
        // The value is the shortest path that ignores the obstacle, moves against an axis priced
        // down-wind, and it undercuts the obstacle-respecting optimum.
        assert!(
            (objective - graph).abs() <= 1e-7 * graph,
            "paper LP {objective:.9} vs obstacle-free graph {graph:.9}"
        );
        assert!(objective < 0.75 * detour);
    }
}

#[test]
fn the_well_posed_form_returns_the_obstacle_respecting_optimum() {
    let s = setup(START, TARGET);
    let m = s.kept.len();
    let b = s.kept_cost();
    // Variables: r | z_{+x} | z_{+y} | z_{−x} | z_{−y}, m each, all ≥ 0.
    let shifts = [[1, 0], [0, 1], [-1, 0], [0, -1]];
    let blocks: Vec<(usize, usize)> = shifts
        .iter()
        .enumerate()
        .map(|(k, &shift)| (s.generator(shift), (k + 1) * m))
        .collect();
    let cost: Vec<f64> = (0..5 * m).map(|v| b[v % m]).collect();
    let mut equalities = s.balance(&blocks);
    equalities.push(s.obstacle_row());
    let mut nonnegative = Vec::new();
    for v in 0..5 * m {
        nonnegative.push(vec![(v, 1.0)]);
    }
    for v in 0..m {
        // u_max r − Σ_k z_k ≥ 0: the speed bound that ties the density to the flux.
        let mut row = vec![(v, U_MAX)];
        row.extend((1..5).map(|k| (k * m + v, -1.0)));
        nonnegative.push(row);
    }
    let well_posed = Lp {
        cost,
        equalities,
        nonnegative,
    }
    .solve();
    let wall_flux: f64 = (0..m)
        .filter(|&v| s.in_wall(v))
        .map(|v| (1..5).map(|k| well_posed.x[k * m + v]).sum::<f64>())
        .sum();
    let start_row = s.row_of[s
        .generators
        .basis
        .index_of_cell(index(START))
        .expect("start")]
    .expect("start is not the target");
    let dijkstra =
        distances_to_targets(&grid(true), &[index(TARGET)], Connectivity::Four)[index(START)];
    let expected = (1.0 + 1.0 / U_MAX) * dijkstra;

    // The project's own pipeline: obstacles removed from the basis, r eliminated, Clarabel.
    let blocked = grid(true);
    let project_generators =
        Generators::build(&blocked, BasisKind::Indicator, 4).expect("generators");
    let n = project_generators.basis.len();
    let cell = |i: usize| project_generators.basis.cell(i);
    let project_cost: Vec<f64> = (0..n).map(|i| blocked.cost[cell(i)]).collect();
    let project_start: Vec<f64> = (0..n)
        .map(|i| if cell(i) == index(START) { 1.0 } else { 0.0 })
        .collect();
    let project_target: Vec<bool> = (0..n).map(|i| cell(i) == index(TARGET)).collect();
    let project = lp::solve(
        &LpProblem {
            generators: &project_generators,
            cost: &project_cost,
            start: &project_start,
            target: &project_target,
            u_max: U_MAX,
        },
        &LpSettings {
            solver: LpSolver::Clarabel,
            ..LpSettings::default()
        },
    )
    .expect("project LP");
    println!(
        "well-posed LP: {:?} after {} iterations, objective {:.9}, r at the start {:.6}, flux through wall cells {wall_flux:.2e}; \
         project pipeline {:.9}; (1 + 1/u_max) × Dijkstra {expected:.9}",
        well_posed.status,
        well_posed.iterations,
        well_posed.objective,
        well_posed.x[start_row],
        project.report.objective
    );
    assert_eq!(well_posed.status, SolverStatus::Solved);
    assert!(
        (well_posed.objective - expected).abs() <= 1e-7 * expected,
        "well-posed {:.9} vs {expected:.9}",
        well_posed.objective
    );
    assert!(
        (project.report.objective - expected).abs() <= 1e-7 * expected,
        "project {:.9} vs {expected:.9}",
        project.report.objective
    );
    // Mass moves at speed u_max: one unit of flux leaves the start, so r there is 1/u_max.
    assert!((well_posed.x[start_row] - 1.0 / U_MAX).abs() <= 1e-6);
    assert!(wall_flux <= 1e-7, "flux through wall cells {wall_flux:.2e}");
}
