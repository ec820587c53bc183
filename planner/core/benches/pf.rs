//! Real-time P-F planning, measured side by side in one run on the `c_shape` scenario (8
//! directions, uniform start density): the graph Dijkstra (full cost-to-go), the exact SSP solver
//! and Clarabel on the same LP, generator builds, the whole pipeline and replanning on cached
//! generators. Criterion drives the measurements; a summary table with the medians is printed at
//! the end.
//!
//! `cargo bench -p pf-planner --bench pf` (about 3 minutes; Clarabel at 128² dominates).
//! `PF_BENCH_SKIP_CLARABEL=1` leaves Clarabel out, `PF_BENCH_SKIP_RBF=1` the RBF rows.

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::Criterion;
use pf_planner::basis::BasisKind;
use pf_planner::deadline::Deadline;
use pf_planner::error::PlanError;
use pf_planner::graph::{distances_to_targets, Connectivity};
use pf_planner::grid::PlanningGrid;
use pf_planner::io::MapScenario;
use pf_planner::lp::{self, LpSettings, LpSolver};
use pf_planner::map::MapKnowledge;
use pf_planner::pf::{self, prepare, PfGenerators, PfOptions, StartDensity};
use pf_planner::plan::{Method, PlannerOptions, PreparedMap};
use pf_planner::scenarios;
use pf_planner::traversability::{block_steep_cells, TraversabilityField, TraversabilityParams};

mod support;
use support::Recorder;

/// `rec.measure`'s median, seconds.
fn median(rec: &Recorder, c: &mut Criterion, name: &str, routine: impl FnMut()) -> f64 {
    rec.measure(c, name, routine)[1]
}

const U_MAX: f64 = 1.0;

#[derive(Default)]
struct Row {
    case: String,
    dijkstra: Option<f64>,
    exact: Option<f64>,
    clarabel: Option<f64>,
    generators: Option<f64>,
    pipeline: Option<f64>,
    target: &'static str,
}

fn ms(value: Option<f64>) -> String {
    match value {
        Some(v) if v >= 1.0 => format!("{v:.2} s"),
        Some(v) if v >= 1e-3 => format!("{:.2} ms", v * 1e3),
        Some(v) => format!("{:.0} µs", v * 1e6),
        None => "–".into(),
    }
}

fn grid_of(scenario: &MapScenario, size: usize) -> PlanningGrid {
    PlanningGrid::from_map(&scenario.map, &scenario.traversability, size).expect("grid")
}

fn settings(solver: LpSolver) -> LpSettings {
    LpSettings {
        solver,
        ..LpSettings::default()
    }
}

fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

fn indicator_row(
    c: &mut Criterion,
    rec: &Recorder,
    scenario: &MapScenario,
    size: usize,
    with_clarabel: bool,
    target: &'static str,
) -> Row {
    let grid = grid_of(scenario, size);
    let basis = BasisKind::Indicator;
    let generators = median(rec, c, &format!("indicator {size}²: generators"), || {
        black_box(PfGenerators::build(&grid, &basis, 8).expect("generators"));
    });
    let gens = PfGenerators::build(&grid, &basis, 8).expect("generators");
    let prepared = prepare(
        &gens,
        &grid,
        scenario.start,
        &scenario.goal,
        StartDensity::UniformFree,
    )
    .expect("prepared");
    let problem = prepared.problem(&gens, U_MAX);
    let exact_settings = settings(LpSolver::Exact);
    let exact = median(rec, c, &format!("indicator {size}²: exact solve"), || {
        black_box(lp::solve(&problem, &exact_settings).expect("exact"));
    });
    let dijkstra = median(
        rec,
        c,
        &format!("indicator {size}²: graph Dijkstra"),
        || {
            black_box(distances_to_targets(
                &grid,
                &prepared.goal_cells,
                Connectivity::Eight,
            ));
        },
    );
    let clarabel = with_clarabel.then(|| {
        let clarabel_settings = settings(LpSolver::Clarabel);
        median(
            rec,
            c,
            &format!("indicator {size}²: Clarabel solve"),
            || {
                black_box(lp::solve(&problem, &clarabel_settings).expect("clarabel"));
            },
        )
    });
    let opts = PfOptions {
        u_max: U_MAX,
        start_density: StartDensity::UniformFree,
        ..PfOptions::default()
    };
    let pipeline = median(
        rec,
        c,
        &format!("indicator {size}²: generators + plan"),
        || {
            let gens = PfGenerators::build(&grid, &basis, 8).expect("generators");
            black_box(
                pf::solve(&gens, &grid, scenario.start, &scenario.goal, &opts).expect("plan"),
            );
        },
    );
    Row {
        case: format!("indicator {size}²"),
        dijkstra: Some(dijkstra),
        exact: Some(exact),
        clarabel,
        generators: Some(generators),
        pipeline: Some(pipeline),
        target,
    }
}

fn rbf_row(
    c: &mut Criterion,
    rec: &Recorder,
    scenario: &MapScenario,
    size: usize,
    target: &'static str,
) -> Row {
    let grid = grid_of(scenario, size);
    let basis = BasisKind::DEFAULT_RBF;
    let generators = median(rec, c, &format!("RBF {size}²: generators"), || {
        black_box(PfGenerators::build(&grid, &basis, 8).expect("generators"));
    });
    let gens = PfGenerators::build(&grid, &basis, 8).expect("generators");
    let prepared = prepare(
        &gens,
        &grid,
        scenario.start,
        &scenario.goal,
        StartDensity::UniformFree,
    )
    .expect("prepared");
    let problem = prepared.problem(&gens, U_MAX);
    let exact_settings = settings(LpSolver::Exact);
    let once = lp::solve(&problem, &exact_settings).expect("solve");
    println!(
        "RBF {size}²: {} functions, nnz {}, solver {}, {} iterations, certificate holds: {}",
        gens.generators().basis.len(),
        gens.generators().stats.nnz,
        once.report.solver,
        once.report.iterations,
        once.report.certificate.holds()
    );
    let exact = median(rec, c, &format!("RBF {size}²: solve"), || {
        black_box(lp::solve(&problem, &exact_settings).expect("solve"));
    });
    Row {
        case: format!("RBF {size}² centres ({} solver)", once.report.solver),
        exact: Some(exact),
        generators: Some(generators),
        pipeline: Some(generators + exact),
        target,
        ..Row::default()
    }
}

fn replan_rows(c: &mut Criterion, rec: &Recorder, scenario: &MapScenario) -> Vec<Row> {
    let grid = grid_of(scenario, 128);
    let gens = PfGenerators::build(&grid, &BasisKind::Indicator, 8).expect("generators");
    let opts = PfOptions {
        u_max: U_MAX,
        start_density: StartDensity::UniformFree,
        ..PfOptions::default()
    };
    // Same geometry, new traversability: p raised by a bump around the map centre.
    let mut changed = grid.clone();
    let (cx, cy) = (grid.width as f64 / 2.0, grid.height as f64 / 2.0);
    for iy in 0..grid.height {
        for ix in 0..grid.width {
            let r2 = ((ix as f64 - cx).powi(2) + (iy as f64 - cy).powi(2)) / 100.0;
            let i = grid.index(ix, iy);
            changed.cost[i] = (changed.cost[i] + 0.5 * (-r2).exp()).min(1.0);
        }
    }
    assert!(
        gens.matches(&changed),
        "same geometry must reuse the generators"
    );
    let new_p = median(rec, c, "replan 128²: new p, cached generators", || {
        black_box(pf::solve(&gens, &changed, scenario.start, &scenario.goal, &opts).expect("plan"));
    });
    let moved = [scenario.start[0] + 1.0, scenario.start[1] + 0.5];
    let new_start = median(rec, c, "replan 128²: new start, cached generators", || {
        black_box(pf::solve(&gens, &grid, moved, &scenario.goal, &opts).expect("plan"));
    });
    // The walking robot's replan: the map with only its left half observed (the rest at the
    // prior p = 0.5), through the whole pipeline (PreparedMap::plan: LP, feedback grid,
    // integrated path, metrics, re-timed reference) on the cached generators.
    let map = &scenario.map;
    let known = (0..map.len())
        .map(|c| c % map.width < map.width / 2)
        .collect();
    let knowledge = MapKnowledge::new(map, known, 0.5).expect("knowledge");
    let field =
        TraversabilityField::from_partial_map(map, Some(&knowledge), &scenario.traversability)
            .expect("field");
    let revealed = PlanningGrid::from_field(map, &field, 128).expect("grid");
    assert!(
        gens.matches(&revealed),
        "revealing heights keeps the generators"
    );
    let cached = Arc::new(gens.clone());
    let prepared = PreparedMap {
        map,
        field: &field,
        grid: &revealed,
    };
    let options = PlannerOptions {
        grid_size: 128,
        u_max: U_MAX,
        start_density: StartDensity::UniformFree,
        traversability: scenario.traversability,
        ..PlannerOptions::default()
    };
    let revealed_plan = median(
        rec,
        c,
        "replan 128²: revealed map, PreparedMap::plan with the feedback field",
        || {
            let plan = prepared
                .plan(
                    scenario.start,
                    scenario.start_yaw,
                    &scenario.goal,
                    Method::Pf,
                    &options,
                    Deadline::NONE,
                    &mut |_, _, _, _| Ok::<_, PlanError>((Arc::clone(&cached), true)),
                )
                .expect("plan");
            assert!(plan.feedback_field.is_ok());
            black_box(plan);
        },
    );
    // The sensed map's cost model (walkable-slope limit, κ = 2) with the slope from central
    // differences and from the plane fitted over 0.25 m, side by side.
    let variances: Vec<f64> = (0..map.len()).map(|i| 1e-4 * (1 + i % 7) as f64).collect();
    let sensed = knowledge
        .with_height_variances(map, &variances)
        .expect("variances");
    let mut cost_model = |radius: f64| {
        let params = TraversabilityParams {
            max_slope_deg: Some(30.0),
            height_confidence_sigmas: 2.0,
            slope_fit_radius_m: radius,
            ..scenario.traversability
        };
        median(
            rec,
            c,
            &format!("sensed 128² cost model, slope fit radius {radius} m"),
            || {
                let blocked = block_steep_cells(map, Some(&sensed), &params);
                black_box(
                    TraversabilityField::from_partial_map(&blocked, Some(&sensed), &params)
                        .expect("field"),
                );
            },
        )
    };
    let central = cost_model(0.0);
    let fitted = cost_model(0.25);
    vec![
        Row {
            case: "sensed 128² cost model (slope limit, κ = 2): central differences".into(),
            pipeline: Some(central),
            target: "–",
            ..Row::default()
        },
        Row {
            case: "sensed 128² cost model: plane fit over 0.25 m (inverse-variance weights)".into(),
            pipeline: Some(fitted),
            target: "≤ 10 ms",
            ..Row::default()
        },
        Row {
            case: "replan 128², revealed map: PreparedMap::plan incl. feedback field (cached generators)".into(),
            pipeline: Some(revealed_plan),
            target: "≤ 100 ms round trip",
            ..Row::default()
        },
        Row {
            case: "replan 128², new p (cached generators)".into(),
            pipeline: Some(new_p),
            target: "≤ 30 ms",
            ..Row::default()
        },
        Row {
            case: "replan 128², new start (cached generators)".into(),
            pipeline: Some(new_start),
            target: "≤ 30 ms",
            ..Row::default()
        },
    ]
}

fn main() {
    let mut c = Criterion::default()
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .configure_from_args();
    let with_clarabel = std::env::var_os("PF_BENCH_SKIP_CLARABEL").is_none();
    let scenario = scenarios::by_name("c_shape").expect("built-in scenario");
    let rec = Recorder::default();
    let mut rows = vec![
        indicator_row(&mut c, &rec, &scenario, 128, with_clarabel, "solve ≤ 50 ms"),
        indicator_row(&mut c, &rec, &scenario, 256, false, "≤ 250 ms"),
        indicator_row(&mut c, &rec, &scenario, 512, false, "≤ 2 s, ≤ 1 GB"),
    ];
    if std::env::var_os("PF_BENCH_SKIP_RBF").is_none() {
        rows.push(rbf_row(
            &mut c,
            &rec,
            &scenario,
            32,
            "generators + solve ≤ 100 ms",
        ));
        rows.push(rbf_row(&mut c, &rec, &scenario, 64, "≤ 0.5 s"));
        rows.push(rbf_row(&mut c, &rec, &scenario, 128, "≤ 3 s"));
    }
    rows.extend(replan_rows(&mut c, &rec, &scenario));
    c.final_summary();

    println!();
    println!("c_shape, 8 directions, uniform start density; medians of criterion's samples");
    println!("| case | graph Dijkstra | exact solve | exact / Dijkstra | Clarabel solve | generators | generators + plan | target |");
    println!("|---|---:|---:|---:|---:|---:|---:|---|");
    for row in &rows {
        let ratio = match (row.exact, row.dijkstra) {
            (Some(e), Some(d)) => format!("{:.1}×", e / d),
            _ => "–".into(),
        };
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            row.case,
            ms(row.dijkstra),
            ms(row.exact),
            ratio,
            ms(row.clarabel),
            ms(row.generators),
            ms(row.pipeline),
            row.target
        );
    }
    if let Some(peak) = peak_rss_mib() {
        println!("peak RSS of the benchmark process (all cases): {peak:.0} MiB");
    }
}
