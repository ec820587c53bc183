//! `pf-plan paper-numbers`: every figure the project quotes from the paper (and from the
//! prototype of its formulation note), with the planner's own counterpart computed here on the
//! rebuilt terrains. Writes `DIR/report.md`; nothing in it is typed in by hand except the quoted
//! figures themselves, which are constants below with their source.

use std::fmt::Write as _;
use std::fs;
use std::path::Path;

use anyhow::{bail, Context, Result};

use pf_planner::basis::BasisKind;
use pf_planner::io::MapScenario;
use pf_planner::lp::{self, LpSettings, LpSolver};
use pf_planner::metrics::evaluate_path;
use pf_planner::pf::{self, PfGenerators, StartDensity};
use pf_planner::plan::{Method, Plan, Planner, PlannerOptions};
use pf_planner::scenarios;
use pf_planner::traversability::{TraversabilityField, TraversabilityParams};

/// The paper's C-shape ∫p ds of the P-F path and of A*'s (quoted in issues 2 and 34).
const PAPER_C_SHAPE_PF: f64 = 0.75;
const PAPER_C_SHAPE_ASTAR: f64 = 1.03;
/// The prototype's C-shape figures (formulation note, 64² grid, 8-connected): ∫p ds of A*
/// (Euclidean heuristic), Dijkstra, P-F indicator and the range of P-F RBF 32²; nodes expanded by
/// A* with the admissible and with the Euclidean heuristic.
const NOTE_ASTAR: f64 = 0.178;
const NOTE_DIJKSTRA: f64 = 0.143;
const NOTE_PF_INDICATOR: f64 = 0.145;
const NOTE_PF_RBF: [f64; 2] = [0.156, 0.166];
const NOTE_EXPANDED_ADMISSIBLE: usize = 3459;
const NOTE_EXPANDED_ASTAR: usize = 48;
/// A floor small enough to read as p_floor = 0 (the model requires p_floor > 0).
const NEAR_ZERO_FLOOR: f64 = 1e-12;
/// A small floor the LP still solves with, to show the optimum as p_floor → 0.
const SMALL_FLOOR: f64 = 1e-3;
/// Quadrature points per axis per planning cell of ∫ 1_obstacle φᵢ.
const OBSTACLE_QUADRATURE: usize = 8;

/// Grid sizes of one run of the page.
pub struct PaperSizes {
    /// Planning cells along the longer side: P-F indicator and the graph searches.
    pub grid: usize,
    /// RBF centres along the longer side.
    pub rbf_grid: usize,
    /// Also time Clarabel on the indicator LP at 2 × `grid` (the prototype's 128² figure).
    pub large_clarabel: bool,
    /// The robot's footprint radius, metres (the harness's, passed by scripts/paper_numbers.py).
    pub footprint_radius: f64,
}

fn options(
    grid: usize,
    basis: BasisKind,
    params: TraversabilityParams,
    solver: LpSolver,
) -> PlannerOptions {
    PlannerOptions {
        grid_size: grid,
        basis,
        traversability: params,
        solver,
        ..PlannerOptions::default()
    }
}

/// One plan of `scenario` with `method` and `opts` (fresh planner, so generators are built).
fn plan(scenario: &MapScenario, method: Method, opts: &PlannerOptions) -> Result<(Planner, Plan)> {
    let mut planner = Planner::new(scenario.map.clone(), opts.traversability, opts.grid_size)?;
    let plan = planner
        .plan(
            scenario.start,
            scenario.start_yaw,
            &scenario.goal,
            method,
            opts,
        )
        .with_context(|| format!("{method} on {}", scenario.name))?;
    Ok((planner, plan))
}

/// `plan`'s path measured with the same model but p_floor → 0 (p = h/h_max as in the paper).
struct Unfloored {
    /// ∫p ds.
    cost: f64,
    /// The smallest p on the path (bilinear, at the quadrature's resolution).
    min_p: f64,
}

fn without_floor(
    planner: &Planner,
    params: &TraversabilityParams,
    plan: &Plan,
) -> Result<Unfloored> {
    let bare = TraversabilityParams {
        p_floor: NEAR_ZERO_FLOOR,
        ..*params
    };
    let map = planner.map();
    let field = TraversabilityField::from_map(map, &bare)?;
    let step = map.resolution / 8.0;
    let mut min_p = f64::INFINITY;
    for pair in plan.path.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let pieces = ((b[0] - a[0]).hypot(b[1] - a[1]) / step).ceil().max(1.0) as usize;
        for k in 0..=pieces {
            let t = k as f64 / pieces as f64;
            let p = field.at([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
            min_p = min_p.min(p);
        }
    }
    Ok(Unfloored {
        cost: evaluate_path(map, &field, &plan.path).cost_integral,
        min_p,
    })
}

/// A small non-negative number in scientific notation, exactly 0 as "0".
fn sci(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else {
        format!("{x:.2e}")
    }
}

/// The share of the P-F occupation density ρ = Σ rᵢφᵢ that lies in the map's hard obstacles.
struct ObstacleMass {
    /// ∫ρ over the plane (occupation time of the flow, s at u_max = 1 m/s).
    total: f64,
    /// ∫ 1_obstacle ρ.
    inside: f64,
    solver: String,
}

fn obstacle_mass(
    scenario: &MapScenario,
    grid: usize,
    basis: BasisKind,
    start_density: StartDensity,
) -> Result<ObstacleMass> {
    let planner = Planner::new(scenario.map.clone(), scenario.traversability, grid)?;
    let gens = PfGenerators::build(planner.grid(), &basis, 8)?;
    let prepared = pf::prepare(
        &gens,
        planner.grid(),
        scenario.start,
        &scenario.goal,
        start_density,
    )?;
    let problem = prepared.problem(&gens, 1.0);
    let solution = lp::solve(&problem, &LpSettings::default())?;
    let map = planner.map();
    let in_obstacle = gens.generators().basis.integrals(OBSTACLE_QUADRATURE, |p| {
        if map.is_obstacle_at(p) {
            1.0
        } else {
            0.0
        }
    });
    let weigh = |w: &[f64]| -> f64 { solution.density.iter().zip(w).map(|(r, m)| r * m).sum() };
    Ok(ObstacleMass {
        total: weigh(gens.mass_integrals()),
        inside: weigh(&in_obstacle),
        solver: solution.report.solver.to_string(),
    })
}

fn basis_label(basis: BasisKind, n: usize) -> String {
    match basis {
        BasisKind::Indicator => format!("P-F indicator {n}²"),
        BasisKind::Rbf { generators, .. } => format!("P-F RBF {generators} {n}²"),
    }
}

fn ms(seconds: f64) -> String {
    if seconds < 0.01 {
        format!("{:.2} ms", seconds * 1e3)
    } else if seconds < 1.0 {
        format!("{:.0} ms", seconds * 1e3)
    } else {
        format!("{seconds:.2} s")
    }
}

/// Generator build time of a P-F plan (0 if the plan has no LP report).
fn generator_time(plan: &Plan) -> f64 {
    plan.lp.as_ref().map_or(0.0, |lp| lp.generator_time_s)
}

/// LP solve time of a P-F plan.
fn lp_time(plan: &Plan) -> f64 {
    plan.lp.as_ref().map_or(0.0, |lp| lp.solve_time_s)
}

/// Builds the page; `progress` is told what runs.
pub fn report(sizes: &PaperSizes, progress: &dyn Fn(&str)) -> Result<String> {
    let (n, m) = (sizes.grid, sizes.rbf_grid);
    if n < 8 || m < 8 {
        bail!("--grid and --rbf-grid must be at least 8");
    }
    let footprint_m = sizes.footprint_radius;
    if !(footprint_m.is_finite() && footprint_m > 0.0) {
        bail!("--footprint-radius must be a positive number of metres, got {footprint_m}");
    }
    let exact = LpSolver::Exact;
    let transfer = BasisKind::DEFAULT_RBF;
    let ansdmd = BasisKind::ANSDMD_RBF;

    // C-shape: the paper's point robot, every method on the same cost.
    let c_shape = scenarios::by_name("c_shape")?;
    let point = c_shape.traversability;
    progress("c_shape: graph searches and P-F");
    let graph = options(n, BasisKind::Indicator, point, exact);
    let (_, c_astar) = plan(&c_shape, Method::AStar, &graph)?;
    let (_, c_admissible) = plan(&c_shape, Method::AStarAdmissible, &graph)?;
    let (_, c_dijkstra) = plan(&c_shape, Method::Dijkstra, &graph)?;
    let (_, c_pf) = plan(&c_shape, Method::Pf, &graph)?;
    let (_, c_transfer) = plan(&c_shape, Method::Pf, &options(m, transfer, point, exact))?;
    progress("c_shape: P-F RBF ANSDMD");
    let (_, c_ansdmd) = plan(&c_shape, Method::Pf, &options(m, ansdmd, point, exact))?;
    progress("c_shape: the robot's footprint");
    let footprint = TraversabilityParams {
        footprint_radius_m: sizes.footprint_radius,
        ..point
    };
    let wide = options(n, BasisKind::Indicator, footprint, exact);
    let (_, f_astar) = plan(&c_shape, Method::AStar, &wide)?;
    let (_, f_pf) = plan(&c_shape, Method::Pf, &wide)?;
    progress("c_shape: Clarabel on the indicator LP");
    let (_, c_clarabel) = plan(
        &c_shape,
        Method::Pf,
        &options(n, BasisKind::Indicator, point, LpSolver::Clarabel),
    )?;
    let large = if sizes.large_clarabel {
        progress("c_shape: Clarabel and the exact solver at twice the grid");
        let big = 2 * n;
        let (_, cl) = plan(
            &c_shape,
            Method::Pf,
            &options(big, BasisKind::Indicator, point, LpSolver::Clarabel),
        )?;
        let (_, ex) = plan(
            &c_shape,
            Method::Pf,
            &options(big, BasisKind::Indicator, point, exact),
        )?;
        Some((big, cl, ex))
    } else {
        None
    };

    // Mountain pass: the cost floor.
    progress("mountain_pass: the cost floor");
    let pass = scenarios::by_name("mountain_pass")?;
    let floor = pass.traversability.p_floor;
    // Each map with its own cost model (the c_shape rows above used c_shape's).
    let pass_graph = options(n, BasisKind::Indicator, pass.traversability, exact);
    let (pass_planner, pass_pf) = plan(&pass, Method::Pf, &pass_graph)?;
    let (_, pass_astar) = plan(&pass, Method::AStar, &pass_graph)?;
    let pass_pf_bare = without_floor(&pass_planner, &pass.traversability, &pass_pf)?;
    let small = TraversabilityParams {
        p_floor: SMALL_FLOOR,
        ..pass.traversability
    };
    let (small_planner, pass_small) = plan(
        &pass,
        Method::Pf,
        &options(n, BasisKind::Indicator, small, exact),
    )?;
    let pass_small_bare = without_floor(&small_planner, &small, &pass_small)?;
    let (_, pass_transfer) = plan(
        &pass,
        Method::Pf,
        &options(m, transfer, pass.traversability, exact),
    )?;
    let (_, pass_dijkstra) = plan(&pass, Method::Dijkstra, &pass_graph)?;

    // Pits: mass of the density in the hard obstacles.
    progress("pits: P-F plans and the density in the obstacles");
    let pits = scenarios::by_name("pits")?;
    let pits_graph = options(n, BasisKind::Indicator, pits.traversability, exact);
    let (_, pits_pf) = plan(&pits, Method::Pf, &pits_graph)?;
    let (_, pits_transfer) = plan(
        &pits,
        Method::Pf,
        &options(m, transfer, pits.traversability, exact),
    )?;
    let (_, pits_dijkstra) = plan(&pits, Method::Dijkstra, &pits_graph)?;
    let mut masses = Vec::new();
    for (basis, size) in [(BasisKind::Indicator, n), (transfer, m), (ansdmd, m)] {
        for (density, density_label) in [
            (StartDensity::PointMass, "point mass at the start"),
            (StartDensity::UniformFree, "uniform over free space"),
        ] {
            progress(&format!(
                "pits: {} with {density_label}",
                basis_label(basis, size)
            ));
            let mass = obstacle_mass(&pits, size, basis, density)?;
            masses.push((basis_label(basis, size), density_label, mass));
        }
    }
    let pits_mass_max = masses
        .iter()
        .map(|(_, _, m)| m.inside / m.total)
        .fold(0.0, f64::max);

    let mut page = String::new();
    let w = &mut page;
    writeln!(w, "# The paper's numbers beside ours\n")?;
    writeln!(
        w,
        "The paper: J. Moyalan, A. Zheng, S. S. K. S. Narayanan, U. Vaidya, *Off-Road Navigation of \
         Legged Robots Using Linear Transfer Operators*, Modeling, Estimation and Control \
         Conference 2023 (arXiv:2305.02938). Its full text was not at hand when this page was \
         built and its abstract states no figures, so the **paper** column holds the figures \
         quoted from it in the project's issues 2 and 34, each with its source. Every figure in \
         the **ours** column is computed by this command on the rebuilt terrains ({n}² planning \
         grid for P-F indicator and the graph searches, 8 directions / 8-connected; {m}² RBF \
         centres; the exact solver where its structure holds, Clarabel otherwise; the uniform \
         start density unless stated; u_max = 1 m/s).\n"
    )?;
    writeln!(w, "Why the absolute values differ:\n")?;
    writeln!(
        w,
        "- **Terrains rebuilt from the text.** The paper's maps are described in words and \
         figures; ours (`planner/core/src/scenarios.rs`) are 16 m × 16 m at 0.125 m, seeded, with \
         the features the text names (a valley between mountains, pits that are low but \
         forbidden, a C-shaped ridge opening towards the start). ∫p ds scales with the map's size \
         and with h_max, so compare ratios between methods, not absolute values.\n\
         - **Cost floor.** The planner uses p = max(h/h_max, p_floor) with p_floor = {floor}: \
         where p = 0 the LP's density and speed are undetermined. Every metre then costs at least \
         p_floor, so ∫p ds ≥ p_floor × length; the paper's p = h/h_max is 0 on level ground at \
         the lowest height.\n\
         - **Footprint.** The paper plans for a point. The co-simulation plans with the robot's \
         {footprint_m} m footprint (each cell costs the largest p within that radius), \
         which widens the detours; rows marked *footprint* use it.\n\
         - **Baseline.** The paper's A* uses the Euclidean distance as heuristic, which \
         over-estimates the cost-to-go wherever p < 1 (inadmissible): its path is not the \
         optimum of the graph it searches. An admissible A* and Dijkstra return that optimum \
         (tested to 1e-9), so the fair comparison is P-F against Dijkstra.\n"
    )?;

    writeln!(w, "## The paper's figures\n")?;
    writeln!(
        w,
        "| figure | paper | source of the paper figure | ours | how ours is measured |\n\
         |---|---:|---|---:|---|"
    )?;
    let c = |p: &Plan| p.metrics.cost_integral;
    let row = |w: &mut String, cells: [&str; 5]| -> std::fmt::Result {
        writeln!(w, "| {} |", cells.join(" | "))
    };
    row(
        w,
        [
            "c_shape: ∫p ds of the P-F path",
            &format!("{PAPER_C_SHAPE_PF:.2}"),
            "issues 2 and 34 (\"0.75 vs 1.03\")",
            &format!("{:.4}", c(&c_pf)),
            &format!(
                "P-F indicator {n}², point robot (RBF {m}²: transfer {:.4}, ANSDMD {:.4})",
                c(&c_transfer),
                c(&c_ansdmd)
            ),
        ],
    )?;
    row(
        w,
        [
            "c_shape: ∫p ds of the A* path",
            &format!("{PAPER_C_SHAPE_ASTAR:.2}"),
            "issues 2 and 34",
            &format!("{:.4}", c(&c_astar)),
            &format!("A* with the paper's Euclidean heuristic, {n}², point robot"),
        ],
    )?;
    row(
        w,
        [
            "c_shape: P-F / A*",
            &format!("{:.3}", PAPER_C_SHAPE_PF / PAPER_C_SHAPE_ASTAR),
            "ratio of the two quoted figures",
            &format!("{:.3}", c(&c_pf) / c(&c_astar)),
            "the two rows above",
        ],
    )?;
    row(
        w,
        [
            "c_shape: A* / P-F",
            &format!("{:.3}", PAPER_C_SHAPE_ASTAR / PAPER_C_SHAPE_PF),
            "ratio of the two quoted figures",
            &format!("{:.3}", c(&c_astar) / c(&c_pf)),
            "the two rows above",
        ],
    )?;
    row(
        w,
        [
            "c_shape, *footprint*: P-F / A*",
            "–",
            "not in the paper (point robot)",
            &format!(
                "{:.3} ({:.4} / {:.4})",
                c(&f_pf) / c(&f_astar),
                c(&f_pf),
                c(&f_astar)
            ),
            &format!("same methods, p maximised over {footprint_m} m (measured on that field)"),
        ],
    )?;
    row(
        w,
        [
            "c_shape: P-F / Dijkstra (the optimum)",
            "not reported",
            "the paper compares with A* only",
            &format!(
                "{:.3} (admissible A*: {:.3})",
                c(&c_pf) / c(&c_dijkstra),
                c(&c_admissible) / c(&c_dijkstra)
            ),
            &format!("Dijkstra {n}², 8-connected, same cost"),
        ],
    )?;
    row(
        w,
        [
            "mountain_pass: ∫p ds of the P-F path",
            "≈ 0",
            "issue 34 (\"∫p ds ≈ 0\")",
            &format!("{:.4}", c(&pass_pf)),
            &format!(
                "P-F indicator {n}², p_floor = {floor}; length {:.2} m, and any path of that \
                 length costs at least p_floor × length = {:.4}",
                pass_pf.metrics.length,
                floor * pass_pf.metrics.length
            ),
        ],
    )?;
    row(
        w,
        [
            "mountain_pass: the same path with p_floor → 0",
            "≈ 0",
            "issue 34",
            &format!("{:.4}", pass_pf_bare.cost),
            &format!(
                "the P-F path above, ∫p ds on p = h/h_max without floor: {:.1} % of its cost is \
                 floor; the smallest p on it is {:.4}: ∫p ds ≈ 0 needs a road at height 0",
                100.0 * (1.0 - pass_pf_bare.cost / c(&pass_pf)),
                pass_pf_bare.min_p
            ),
        ],
    )?;
    row(
        w,
        [
            "mountain_pass: planned with a near-zero floor",
            "≈ 0",
            "issue 34",
            &format!("{:.4}", pass_small_bare.cost),
            &format!(
                "P-F indicator {n}² planned with p_floor = {SMALL_FLOOR}, measured without floor \
                 (length {:.2} m, smallest p on it {:.4})",
                pass_small.metrics.length, pass_small_bare.min_p
            ),
        ],
    )?;
    row(
        w,
        [
            "mountain_pass: A* / P-F",
            "not available",
            "no A* figure quoted for this terrain",
            &format!("{:.3}", c(&pass_astar) / c(&pass_pf)),
            &format!(
                "A* paper heuristic {:.4} vs P-F {:.4}",
                c(&pass_astar),
                c(&pass_pf)
            ),
        ],
    )?;
    row(
        w,
        [
            "pits: density mass in the obstacles",
            "not available",
            "issue 34 names the figure without its value; the paper's constraint is ∫1_obstacle ρ = 0",
            &sci(pits_mass_max),
            "largest share of ∫ρ inside the map's obstacles over the bases and start densities below",
        ],
    )?;
    row(
        w,
        [
            "pits: P-F path length inside obstacles",
            "not available",
            "–",
            &format!(
                "{:.3} m",
                pits_pf
                    .metrics
                    .length_in_obstacles
                    .max(pits_transfer.metrics.length_in_obstacles)
            ),
            &format!("P-F indicator {n}² and RBF transfer {m}², point robot"),
        ],
    )?;
    writeln!(w)?;
    writeln!(
        w,
        "Not available from the paper (its text was not at hand): the terrains' size, resolution \
         and h_max; the grid and RBF sizes; the value of the pits obstacle mass; solve times; \
         anything about the robot walking the plans. The walked plans are on \
         [baselines.md](baselines.md); every method on every scenario on [planner.md](planner.md).\n"
    )?;

    writeln!(w, "### Pits: the density in the obstacles\n")?;
    writeln!(
        w,
        "∫ρ is the occupation density of the optimal flow over the plane (ρ = Σ rᵢφᵢ; at \
         u_max = 1 m/s, seconds spent by unit mass); the obstacle share integrates ρ over the \
         map's hard-obstacle cells ({OBSTACLE_QUADRATURE}² quadrature points per planning cell). \
         The indicator basis drops every cell that touches an obstacle, the RBF basis every \
         centre within about one spacing of one; the Gaussians' tails still reach in.\n"
    )?;
    writeln!(
        w,
        "| basis | start density | LP solver | ∫ρ [s] | ∫ρ in obstacles [s] | share |\n\
         |---|---|---|---:|---:|---:|"
    )?;
    for (label, density, mass) in &masses {
        writeln!(
            w,
            "| {label} | {density} | {} | {:.3} | {} | {} |",
            mass.solver,
            mass.total,
            sci(mass.inside),
            sci(mass.inside / mass.total)
        )?;
    }
    writeln!(w)?;

    writeln!(w, "## The formulation note's prototype figures\n")?;
    writeln!(
        w,
        "The project's formulation note records figures of a Python prototype (HiGHS and \
         Clarabel, 2 cores) on its own C-shape map at 64²: not the paper's, and not our terrain, \
         so again ratios compare, absolute values do not.\n"
    )?;
    writeln!(
        w,
        "| figure | prototype | ours | how ours is measured |\n|---|---:|---:|---|"
    )?;
    let row4 = |w: &mut String, cells: [&str; 4]| -> std::fmt::Result {
        writeln!(w, "| {} |", cells.join(" | "))
    };
    row4(
        w,
        [
            "c_shape: Dijkstra / A* (Euclidean heuristic)",
            &format!(
                "{:.2} ({NOTE_DIJKSTRA} / {NOTE_ASTAR})",
                NOTE_DIJKSTRA / NOTE_ASTAR
            ),
            &format!("{:.3}", c(&c_dijkstra) / c(&c_astar)),
            &format!("{n}², 8-connected, point robot"),
        ],
    )?;
    row4(
        w,
        [
            "c_shape: P-F indicator / A*",
            &format!(
                "{:.2} ({NOTE_PF_INDICATOR} / {NOTE_ASTAR})",
                NOTE_PF_INDICATOR / NOTE_ASTAR
            ),
            &format!("{:.3}", c(&c_pf) / c(&c_astar)),
            &format!("P-F indicator {n}²"),
        ],
    )?;
    row4(
        w,
        [
            "c_shape: P-F RBF / A*",
            &format!(
                "{:.2}–{:.2}",
                NOTE_PF_RBF[0] / NOTE_ASTAR,
                NOTE_PF_RBF[1] / NOTE_ASTAR
            ),
            &format!(
                "{:.3} / {:.3}",
                c(&c_transfer) / c(&c_astar),
                c(&c_ansdmd) / c(&c_astar)
            ),
            &format!("RBF {m}², transfer / ANSDMD generators"),
        ],
    )?;
    row4(
        w,
        [
            "c_shape: nodes expanded, admissible A* / Euclidean A*",
            &format!("{NOTE_EXPANDED_ADMISSIBLE} / {NOTE_EXPANDED_ASTAR}"),
            &format!(
                "{} / {}",
                c_admissible.expanded.unwrap_or(0),
                c_astar.expanded.unwrap_or(0)
            ),
            "p_min × distance vs Euclidean distance",
        ],
    )?;
    row4(
        w,
        [
            "P-F RBF ∫p ds over the graph optimum, three terrains",
            "1.01–1.10",
            &format!(
                "{:.3} / {:.3} / {:.3}",
                c(&pass_transfer) / c(&pass_dijkstra),
                c(&pits_transfer) / c(&pits_dijkstra),
                c(&c_transfer) / c(&c_dijkstra)
            ),
            &format!("RBF transfer {m}² / Dijkstra {n}²: mountain_pass / pits / c_shape"),
        ],
    )?;
    row4(
        w,
        [
            "indicator 64² LP, 8 directions",
            "0.9 s Clarabel, 0.6 s HiGHS",
            &format!(
                "{} Clarabel, {} exact",
                ms(lp_time(&c_clarabel)),
                ms(lp_time(&c_pf))
            ),
            &format!("{n}², LP solve only, one run"),
        ],
    )?;
    if let Some((big, cl, ex)) = &large {
        row4(
            w,
            [
                "indicator 128² LP",
                "21 s Clarabel, 9 s HiGHS",
                &format!("{} Clarabel, {} exact", ms(lp_time(cl)), ms(lp_time(ex))),
                &format!("{big}², LP solve only, one run"),
            ],
        )?;
    }
    row4(
        w,
        [
            "Dijkstra on the same graph",
            "3 ms",
            &ms(c_dijkstra.solve_time_s),
            &format!("{n}², path included, one run"),
        ],
    )?;
    row4(
        w,
        [
            "RBF 32² generators (dense least squares)",
            "19 s (Python)",
            &format!(
                "{} ANSDMD, {} transfer",
                ms(generator_time(&c_ansdmd)),
                ms(generator_time(&c_transfer))
            ),
            &format!(
                "{m}² centres, 8 directions, one run (criterion: `cargo bench -p pf-planner --bench ansdmd`)"
            ),
        ],
    )?;
    writeln!(w)?;
    writeln!(
        w,
        "Times are wall clock of one run on the machine in the stamp; the benchmarks in \
         [docs/benchmarks.md](../benchmarks.md) give ranges over several runs."
    )?;
    Ok(page)
}

/// `pf-plan paper-numbers --out DIR`: writes DIR/report.md and prints it.
pub fn run(out: &Path, sizes: &PaperSizes) -> Result<()> {
    fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let page = report(sizes, &|what| eprintln!("paper-numbers: {what}"))?;
    let path = out.join("report.md");
    fs::write(&path, &page).with_context(|| format!("writing {}", path.display()))?;
    print!("{page}");
    eprintln!("report -> {}", path.display());
    Ok(())
}
