//! `pf-plan`: plan on a built-in scenario or a map file with P-F, A* or Dijkstra; list and export
//! scenarios; measure a path (∫p ds) or write the traversability field with the planner's own cost
//! model; import an elevation model (GeoTIFF, ESRI ASCII grid) as a map; run the demo (all
//! methods × all scenarios → report.md + PNGs); put the paper's figures beside ours
//! (`paper-numbers`).

use std::fs;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use tracing_subscriber::EnvFilter;

mod paper;
mod plot;
mod report;

use plot::{plot_feedback_field, plot_plans, PlotPath};
use report::{markdown_table, ReportRow, RowData};

use pf_planner::basis::RbfGenerators;
use pf_planner::import::{
    counts, factor, import_map, numbers, scenario_from, stem_name, Crop, DemFormat, ImportOptions,
    Placement, Resolution,
};
use pf_planner::io::{
    load_scenario_limited, parse_path_csv, read_path_csv, save_scenario, write_npy_f64, write_npz,
    MapScenario, MAX_PATH_CSV_BYTES,
};
use pf_planner::lp::LpSolver;
use pf_planner::map::{Point, MAX_MAP_CELLS};
use pf_planner::metrics::evaluate_path;
use pf_planner::pf::BasisKind;
use pf_planner::plan::{Method, Plan, Planner, PlannerOptions};
use pf_planner::scenarios::{self, SCENARIO_NAMES};
use pf_planner::traversability::{block_steep_cells, TraversabilityField};

#[derive(Parser)]
#[command(
    name = "pf-plan",
    version,
    about = "Perron-Frobenius density-space planner with A*/Dijkstra baselines"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Plan on a scenario or map file; writes trajectory JSON + CSV per method and a PNG.
    Plan(PlanArgs),
    /// Scenario maps.
    Scenario {
        #[command(subcommand)]
        command: ScenarioCommand,
    },
    /// ∫p ds, length, length in obstacles, clearance and steepest slope of a path, measured with
    /// the planner's own cost model (the metric of every plan); prints one JSON object.
    PathCost(PathCostArgs),
    /// The traversability p of every map cell (the field plans are measured on) as a float64
    /// `.npy` of shape (height, width).
    Traversability(TraversabilityArgs),
    /// A map from an elevation model (GeoTIFF or ESRI ASCII grid): crop, resample, nodata to
    /// obstacles, uniform scale; written like `scenario export` (see docs/terrain-import.md).
    Import(ImportArgs),
    /// All methods on all scenarios, each planned --repeats times from scratch: DIR/report.md
    /// (path metrics and solve-time ranges) and one PNG per scenario.
    Demo {
        /// Output directory.
        #[arg(long, default_value = "demo_out")]
        out: PathBuf,
        /// Planning cells along the longer side for P-F indicator and the graph baselines.
        #[arg(long, default_value_t = 64)]
        grid: usize,
        /// RBF centres along the longer side for P-F RBF.
        #[arg(long, default_value_t = 32)]
        rbf_grid: usize,
        /// Nominal speed of the reference trajectories, m/s.
        #[arg(long, default_value_t = 0.5, allow_negative_numbers = true)]
        speed: f64,
        /// Plans per method and scenario; the report gives the range of their solve times.
        #[arg(long, default_value_t = 5)]
        repeats: usize,
    },
    /// Every figure quoted from the paper (and from the formulation note's prototype) beside the
    /// planner's own, computed on the rebuilt terrains: DIR/report.md (see docs/results/paper-numbers.md).
    PaperNumbers {
        /// Output directory.
        #[arg(long, default_value = "out/paper-numbers")]
        out: PathBuf,
        /// Planning cells along the longer side for P-F indicator and the graph searches.
        #[arg(long, default_value_t = 64)]
        grid: usize,
        /// RBF centres along the longer side for P-F RBF.
        #[arg(long, default_value_t = 32)]
        rbf_grid: usize,
        /// Leave out Clarabel and the exact solver at twice --grid (the prototype's 128² row).
        #[arg(long)]
        skip_large: bool,
        /// The robot's footprint radius, metres, for the rows planned with it (the harness's
        /// ROBOT_FOOTPRINT_RADIUS; scripts/paper_numbers.py passes it).
        #[arg(long)]
        footprint_radius: f64,
    },
}

#[derive(Subcommand)]
enum ScenarioCommand {
    /// Write DIR/NAME.json, DIR/NAME.heights.npy, (with obstacles) DIR/NAME.obstacles.npy and
    /// (with a prior map) DIR/NAME.prior.heights.npy [+ DIR/NAME.prior.obstacles.npy].
    Export {
        /// mountain_pass, pits, c_shape (the paper's) or surprise (has a prior map).
        name: String,
        /// Output directory.
        #[arg(long, default_value = ".")]
        out: PathBuf,
        /// Seed (default: the scenario's own).
        #[arg(long)]
        seed: Option<u64>,
    },
    /// The paper's scenarios, one name a line; with --json their start, goal, seed, map size and
    /// whether they have a prior map.
    List {
        /// One JSON array of objects instead of names.
        #[arg(long)]
        json: bool,
        /// Every built-in scenario, not only the paper's (adds surprise, which has a prior map).
        #[arg(long)]
        all: bool,
    },
}

/// The map (and its traversability model) a command works on.
#[derive(clap::Args)]
struct MapArgs {
    /// Built-in scenario (mountain_pass, pits, c_shape).
    #[arg(long, conflicts_with = "map", required_unless_present = "map")]
    scenario: Option<String>,
    /// Map sidecar JSON (see `pf-plan scenario export`).
    #[arg(long)]
    map: Option<PathBuf>,
    /// Largest map accepted with --map, in cells (refused from the file headers, before the
    /// arrays are read).
    #[arg(long, default_value_t = 2048 * 2048)]
    max_map_cells: usize,
    /// Robot footprint radius, metres: each cell costs the largest p within it (overrides the
    /// map's `traversability.footprint_radius_m`; 0 = the paper's point robot).
    #[arg(long, allow_negative_numbers = true)]
    footprint_radius: Option<f64>,
    /// Steepest walkable slope, degrees: steeper cells become hard obstacles (overrides the
    /// map's `traversability.max_slope_deg`; unset there = no limit).
    #[arg(long, allow_negative_numbers = true)]
    max_slope_deg: Option<f64>,
}

impl MapArgs {
    fn load(&self) -> Result<MapScenario> {
        let mut scenario = match (&self.scenario, &self.map) {
            (Some(name), None) => scenarios::by_name(name)?,
            (None, Some(path)) => load_scenario_limited(path, self.max_map_cells)
                .with_context(|| format!("loading map {}", path.display()))?,
            _ => bail!("give exactly one of --scenario or --map"),
        };
        if let Some(radius) = self.footprint_radius {
            scenario.traversability.footprint_radius_m = radius;
        }
        if let Some(limit) = self.max_slope_deg {
            scenario.traversability.max_slope_deg = Some(limit);
        }
        scenario
            .traversability
            .validate()
            .context("--footprint-radius / --max-slope-deg")?;
        Ok(scenario)
    }

    /// The scenario and the traversability field the planners plan and measure with.
    fn field(&self) -> Result<(MapScenario, TraversabilityField)> {
        let mut scenario = self.load()?;
        scenario.map =
            block_steep_cells(&scenario.map, None, &scenario.traversability).into_owned();
        let field = TraversabilityField::from_map(&scenario.map, &scenario.traversability)
            .context("evaluating the traversability model")?;
        Ok((scenario, field))
    }
}

#[derive(clap::Args)]
struct PathCostArgs {
    #[command(flatten)]
    map: MapArgs,
    /// CSV with a header naming columns x and y (other columns are ignored, so `pf-plan plan`'s
    /// trajectory CSV works as is); `-` reads standard input.
    #[arg(long)]
    path: PathBuf,
}

#[derive(clap::Args)]
struct TraversabilityArgs {
    #[command(flatten)]
    map: MapArgs,
    /// Output `.npy` file.
    #[arg(long)]
    out: PathBuf,
}

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    Pf,
    /// A* with the paper's Euclidean heuristic (inadmissible where p < 1).
    Astar,
    /// A* with the admissible heuristic p_min × distance: Dijkstra's optimum.
    AstarAdmissible,
    Dijkstra,
    All,
}

#[derive(Clone, Copy, ValueEnum)]
enum BasisArg {
    Indicator,
    Rbf,
}

#[derive(clap::Args)]
struct PlanArgs {
    /// The map; it is resampled to --grid cells for planning.
    #[command(flatten)]
    map: MapArgs,
    /// Planning method (all = P-F, both A*s and Dijkstra on the same grid).
    #[arg(long, value_enum, default_value = "all")]
    method: MethodArg,
    /// P-F basis: grid-cell indicators (Ulam) or Gaussian RBFs on the cell centres.
    #[arg(long, value_enum, default_value = "indicator")]
    basis: BasisArg,
    /// RBF width σ / centre spacing.
    #[arg(long, default_value_t = 0.5)]
    rbf_sigma: f64,
    /// Snapshot samples per RBF.
    #[arg(long, default_value_t = 16)]
    rbf_samples: usize,
    /// RBF generators: transfer (Markov partition-of-unity transfer, exact solver) or ansdmd
    /// (the paper's least squares with row normalisation; negative entries, LP by Clarabel).
    /// The indicator basis ignores it: Ulam's method is both.
    #[arg(long, default_value = "transfer", value_parser = parse_generators)]
    generators: RbfGenerators,
    /// Planning cells (or RBF centres) along the map's longer side.
    #[arg(long, default_value_t = 64)]
    grid: usize,
    /// 4 or 8 directions.
    #[arg(long, default_value_t = 8)]
    directions: usize,
    /// Nominal speed of the reference trajectory, m/s.
    #[arg(long, default_value_t = 0.5, allow_negative_numbers = true)]
    speed: f64,
    /// Solver of the P-F LP: exact (Dijkstra / policy iteration on the dual) or clarabel.
    #[arg(long, value_enum, default_value = "exact")]
    solver: SolverArg,
    /// Wall-clock limit of each P-F solve, seconds.
    #[arg(long, allow_negative_numbers = true)]
    max_solve_time: Option<f64>,
    /// Output directory.
    #[arg(long, default_value = ".")]
    out: PathBuf,
    /// Write the P-F plan's feedback law as a numpy .npz: dir_x, dir_y, speed, cost_to_go
    /// (float64, shape (height, width), [iy, ix]; cost_to_go = ∫p ds to the goal, -1 where it
    /// cannot be reached), origin (2,), resolution (), goal (3,) = centre x, y, radius.
    #[arg(long, value_name = "FILE.npz")]
    field_out: Option<PathBuf>,
    /// Draw the P-F plan's feedback law: arrows over cost-to-go bands, obstacles dark.
    #[arg(long, value_name = "FILE.png")]
    field_plot: Option<PathBuf>,
    /// Write the P-F LP's occupation density ρ on the planning grid as a numpy .npz: density
    /// (float64, shape (height, width), [iy, ix]; the expected time the start's unit mass spends
    /// per square metre around each cell centre, 0 on the goal cells), origin (2,), resolution ().
    #[arg(long, value_name = "FILE.npz")]
    density_out: Option<PathBuf>,
}

#[derive(clap::Args)]
struct ImportArgs {
    /// Elevation model: .asc (ESRI ASCII grid) or .tif/.tiff (GeoTIFF).
    input: PathBuf,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// Scenario name (default: the input's file stem).
    #[arg(long)]
    name: Option<String>,
    /// Format, when the extension does not tell.
    #[arg(long, value_enum)]
    format: Option<FormatArg>,
    /// Keep the cells whose centres lie in this window, source coordinates.
    #[arg(long, value_name = "X0,Y0,X1,Y1", value_parser = numbers::<4>, allow_negative_numbers = true)]
    crop: Option<[f64; 4]>,
    /// Keep these source cells (ends exclusive; row 0 = the file's first, northern row).
    #[arg(long, value_name = "C0,R0,C1,R1", value_parser = counts::<4>, conflicts_with = "crop")]
    crop_cells: Option<[usize; 4]>,
    /// Cell size of the written map, metres (after --scale); default: the source's.
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    cell_size: Option<f64>,
    /// Fit the crop in NX x NY square cells instead of --cell-size.
    #[arg(long, value_name = "NX,NY", value_parser = counts::<2>, conflicts_with = "cell_size")]
    size: Option<[usize; 2]>,
    /// Multiply cell size and heights by F (slopes kept), e.g. 1/50 for a 1 m DEM at robot scale.
    #[arg(long, value_name = "F", default_value = "1", value_parser = factor, allow_negative_numbers = true)]
    scale: f64,
    /// Start, map coordinates (metres from the crop's south-west corner, after --scale).
    #[arg(long, value_name = "X,Y", value_parser = numbers::<2>, allow_negative_numbers = true)]
    start: Option<[f64; 2]>,
    /// Heading at the start, radians.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    start_yaw: f64,
    /// Goal centre, map coordinates.
    #[arg(long, value_name = "X,Y", value_parser = numbers::<2>, allow_negative_numbers = true)]
    goal: Option<[f64; 2]>,
    /// Goal radius, metres.
    #[arg(long, default_value_t = 0.5, allow_negative_numbers = true)]
    goal_radius: f64,
    /// Source cell size in metres, for GeoTIFFs without one or in degrees.
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    source_cell_size: Option<f64>,
    /// Keep absolute elevations (default: the lowest valid cell becomes 0 m).
    #[arg(long)]
    keep_elevation: bool,
    /// Largest number of cells read from the source or written, checked before allocating.
    #[arg(long, value_name = "N", default_value_t = MAX_MAP_CELLS)]
    max_cells: usize,
}

#[derive(Clone, Copy, ValueEnum)]
enum FormatArg {
    Asc,
    Tif,
}

#[derive(Clone, Copy, ValueEnum)]
enum SolverArg {
    Exact,
    Clarabel,
}

/// `--generators`: the names of [`RbfGenerators`] (its `FromStr`, the one list of names).
fn parse_generators(text: &str) -> Result<RbfGenerators, String> {
    text.parse()
        .map_err(|e: pf_planner::error::PlanError| e.to_string())
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        // Colour codes only on a terminal: logs redirected to files, and the error messages
        // quoting their tails, stay plain text.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    match Cli::parse().command {
        Command::Plan(args) => run_plan(&args),
        Command::Scenario {
            command: ScenarioCommand::Export { name, out, seed },
        } => {
            let scenario = match seed {
                Some(seed) => scenarios::with_seed(&name, seed),
                None => scenarios::by_name(&name),
            }?;
            let json = save_scenario(&scenario, &out)?;
            println!("{}", json.display());
            Ok(())
        }
        Command::Scenario {
            command: ScenarioCommand::List { json, all },
        } => list_scenarios(json, all),
        Command::PathCost(args) => run_path_cost(&args),
        Command::Traversability(args) => {
            let (_, field) = args.map.field()?;
            write_npy_f64(&args.out, (field.height, field.width), &field.values)?;
            emit(&args.out.display().to_string())
        }
        Command::Import(args) => run_import(&args),
        Command::Demo {
            out,
            grid,
            rbf_grid,
            speed,
            repeats,
        } => run_demo(&out, grid, rbf_grid, speed, repeats),
        Command::PaperNumbers {
            out,
            grid,
            rbf_grid,
            skip_large,
            footprint_radius,
        } => paper::run(
            &out,
            &paper::PaperSizes {
                grid,
                rbf_grid,
                large_clarabel: !skip_large,
                footprint_radius,
            },
        ),
    }
}

/// Writes one line to stdout; a closed pipe is an error, not a panic.
fn emit(line: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(out, "{line}")
        .and_then(|()| out.flush())
        .context("writing to standard output")
}

/// The paper's scenarios (`all`: every built-in one), one name a line or as JSON objects.
fn list_scenarios(json: bool, all: bool) -> Result<()> {
    let names: Vec<&str> = if all {
        scenarios::all_names().collect()
    } else {
        SCENARIO_NAMES.to_vec()
    };
    if !json {
        return emit(&names.join("\n"));
    }
    let mut list = Vec::new();
    for name in names {
        let s = scenarios::by_name(name)?;
        list.push(json!({
            "name": s.name, "seed": s.seed, "start": s.start, "start_yaw": s.start_yaw,
            "goal": s.goal, "origin": s.map.origin, "resolution": s.map.resolution,
            "width": s.map.width, "height": s.map.height, "traversability": s.traversability,
            "paper": SCENARIO_NAMES.contains(&name), "prior": s.prior.is_some(),
        }));
    }
    emit(&serde_json::to_string_pretty(&list)?)
}

fn read_path(file: &Path) -> Result<Vec<Point>> {
    if file != Path::new("-") {
        return Ok(read_path_csv(file)?);
    }
    let mut text = String::new();
    std::io::stdin()
        .take(MAX_PATH_CSV_BYTES + 1)
        .read_to_string(&mut text)
        .context("reading the path CSV from standard input")?;
    if text.len() as u64 > MAX_PATH_CSV_BYTES {
        bail!("the path CSV on standard input is larger than {MAX_PATH_CSV_BYTES} bytes");
    }
    Ok(parse_path_csv(&text, "<stdin>")?)
}

fn run_path_cost(args: &PathCostArgs) -> Result<()> {
    let (scenario, field) = args.map.field()?;
    let path = read_path(&args.path)?;
    let m = evaluate_path(&scenario.map, &field, &path);
    let doc = json!({
        "map": scenario.name,
        "points": path.len(),
        "footprint_radius_m": scenario.traversability.footprint_radius_m,
        "cost_integral": m.cost_integral,
        "length": m.length,
        "length_in_obstacles": m.length_in_obstacles,
        "min_clearance": m.min_clearance.is_finite().then_some(m.min_clearance),
        "max_slope_deg": m.max_slope_deg,
    });
    emit(&serde_json::to_string(&doc)?)
}

fn run_import(args: &ImportArgs) -> Result<()> {
    let world = args.crop.map(|[x0, y0, x1, y1]| Crop::World {
        min: [x0, y0],
        max: [x1, y1],
    });
    let cells = args
        .crop_cells
        .map(|[column0, row0, column1, row1]| Crop::Cells {
            column0,
            row0,
            column1,
            row1,
        });
    let resolution = match (args.cell_size, args.size) {
        (Some(size), _) => Resolution::CellSize(size),
        (None, Some([columns, rows])) => Resolution::Size { columns, rows },
        (None, None) => Resolution::Source,
    };
    let options = ImportOptions {
        format: args.format.map(|f| match f {
            FormatArg::Asc => DemFormat::EsriAscii,
            FormatArg::Tif => DemFormat::GeoTiff,
        }),
        crop: world.or(cells),
        resolution,
        scale: args.scale,
        keep_elevation: args.keep_elevation,
        source_cell_size: args.source_cell_size,
        max_cells: args.max_cells,
    };
    let bar = spinner(format!("reading {}", args.input.display()));
    let imported = import_map(&args.input, &options);
    bar.finish_and_clear();
    let imported = imported.with_context(|| format!("importing {}", args.input.display()))?;
    for warning in &imported.summary.warnings {
        tracing::warn!("{warning}");
    }
    emit(&imported.summary.to_string())?;
    let placement = Placement {
        name: args.name.clone().unwrap_or_else(|| stem_name(&args.input)),
        start: args.start,
        start_yaw: args.start_yaw,
        goal: args.goal,
        goal_radius: args.goal_radius,
    };
    let scenario = scenario_from(imported.map, &placement)?;
    let json = save_scenario(&scenario, &args.out)?;
    emit(&json.display().to_string())
}

fn spinner(message: String) -> ProgressBar {
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.set_message(message);
    bar.enable_steady_tick(Duration::from_millis(120));
    bar
}

fn run_plan(args: &PlanArgs) -> Result<()> {
    let scenario = args.map.load()?;
    let basis = match args.basis {
        BasisArg::Indicator => BasisKind::Indicator,
        BasisArg::Rbf => BasisKind::Rbf {
            sigma_over_spacing: args.rbf_sigma,
            samples_per_basis: args.rbf_samples,
            generators: args.generators,
        },
    };
    let options = PlannerOptions {
        grid_size: args.grid,
        directions: args.directions,
        basis,
        speed: args.speed,
        traversability: scenario.traversability,
        solver: match args.solver {
            SolverArg::Exact => LpSolver::Exact,
            SolverArg::Clarabel => LpSolver::Clarabel,
        },
        max_solve_time: args.max_solve_time.unwrap_or(f64::INFINITY),
        ..PlannerOptions::default()
    };
    if options.max_solve_time.is_nan() || options.max_solve_time <= 0.0 {
        bail!(
            "--max-solve-time must be > 0 seconds, got {}",
            options.max_solve_time
        );
    }
    let methods: Vec<Method> = match args.method {
        MethodArg::Pf => vec![Method::Pf],
        MethodArg::Astar => vec![Method::AStar],
        MethodArg::AstarAdmissible => vec![Method::AStarAdmissible],
        MethodArg::Dijkstra => vec![Method::Dijkstra],
        MethodArg::All => Method::ALL.to_vec(),
    };
    let wants_field = args.field_out.is_some() || args.field_plot.is_some();
    if (wants_field || args.density_out.is_some()) && !methods.contains(&Method::Pf) {
        bail!("--field-out, --field-plot and --density-out need a P-F plan (--method pf or all)");
    }
    fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let mut planner = Planner::new(
        scenario.map.clone(),
        options.traversability,
        options.grid_size,
    )?;
    let mut drawn = Vec::new();
    let mut notes = Vec::new();
    let mut failures = 0;
    for method in methods {
        let bar = spinner(format!("{} on {}", method, scenario.name));
        let result = planner.plan(
            scenario.start,
            scenario.start_yaw,
            &scenario.goal,
            method,
            &options,
        );
        bar.finish_and_clear();
        match result {
            Ok(plan) => {
                let stem = args.out.join(format!("{}_{}", scenario.name, method));
                write_plan(&stem, &scenario.name, &plan)?;
                if method == Method::Pf && wants_field {
                    let field = plan
                        .feedback_field
                        .as_ref()
                        .map_err(|reason| anyhow::anyhow!("no feedback field: {reason}"))?;
                    if let Some(path) = &args.field_out {
                        field.write_npz(path)?;
                        println!("feedback field -> {}", path.display());
                    }
                    if let Some(path) = &args.field_plot {
                        plot_feedback_field(
                            path,
                            &scenario.name,
                            field,
                            scenario.start,
                            Some(&plan.path),
                        )?;
                        println!("feedback field plot -> {}", path.display());
                    }
                }
                if let (Method::Pf, Some(path)) = (method, &args.density_out) {
                    let flow = plan
                        .lp_flow
                        .as_ref()
                        .context("the P-F plan came without its LP solution")?;
                    let grid = planner.grid();
                    write_npz(
                        path,
                        &[
                            (
                                "density",
                                &[grid.height, grid.width],
                                &flow.density_on(grid),
                            ),
                            ("origin", &[2], &grid.origin),
                            ("resolution", &[], &[grid.cell_size]),
                        ],
                    )?;
                    println!("occupation density -> {}", path.display());
                }
                let m = plan.metrics;
                println!(
                    "{:<9} ∫p ds {:.4}  length {:.2} m  in obstacles {:.3} m  time {:.3} s  -> {}.json/.csv",
                    method.name(),
                    m.cost_integral,
                    m.length,
                    m.length_in_obstacles,
                    plan.solve_time_s,
                    stem.display()
                );
                if let Some(lp) = &plan.lp {
                    let c = &lp.certificate;
                    println!(
                        "          LP {} by {} in {:.3} s (generators {:.3} s); certificate {}: primal residual {:.1e}, dual residual {:.1e}, gap {:.1e} (tolerance {:.0e})",
                        lp.status,
                        lp.solver,
                        lp.solve_time_s,
                        lp.generator_time_s,
                        if c.holds() { "holds" } else { "FAILS" },
                        c.primal_residual,
                        c.dual_residual,
                        c.duality_gap,
                        c.tolerance
                    );
                }
                drawn.push(PlotPath {
                    label: label(method, &options),
                    points: plan.path,
                    metrics: Some(m),
                });
            }
            Err(e) => {
                failures += 1;
                eprintln!("{method}: {e}");
                notes.push(format!("{}: failed: {e}", label(method, &options)));
            }
        }
    }
    let png = args.out.join(format!("{}.png", scenario.name));
    plot_plans(
        &png,
        &scenario.name,
        &scenario.map,
        scenario.start,
        &scenario.goal,
        &drawn,
        &notes,
    )?;
    println!("plot -> {}", png.display());
    if failures > 0 {
        bail!("{failures} method(s) failed");
    }
    Ok(())
}

fn label(method: Method, options: &PlannerOptions) -> String {
    let n = options.grid_size;
    match method {
        Method::Pf => match options.basis {
            BasisKind::Indicator => format!("P-F indicator {n}²"),
            BasisKind::Rbf { generators, .. } => format!("P-F RBF {generators} {n}²"),
        },
        Method::AStar => format!("A* paper heuristic {n}²"),
        Method::AStarAdmissible => format!("A* admissible {n}²"),
        Method::Dijkstra => format!("Dijkstra {n}²"),
    }
}

fn write_plan(stem: &Path, scenario: &str, plan: &Plan) -> Result<()> {
    let m = &plan.metrics;
    let lp = plan.lp.as_ref().map(|lp| {
        json!({
            "status": lp.status.name(), "solver": lp.solver.name(), "certificate": lp.certificate,
            "certified": lp.certificate.holds(), "objective": lp.objective, "primal_residual": lp.primal_residual,
            "dual_residual": lp.dual_residual, "mass_balance_residual": lp.mass_balance_residual,
            "iterations": lp.iterations, "solve_time_s": lp.solve_time_s,
            "generator_time_s": lp.generator_time_s, "variables": lp.variables, "constraints": lp.constraints,
        })
    });
    let doc = json!({
        "scenario": scenario,
        "method": plan.method.name(),
        "metrics": {
            "cost_integral": m.cost_integral, "length": m.length,
            "length_in_obstacles": m.length_in_obstacles,
            "min_clearance": if m.min_clearance.is_finite() { Some(m.min_clearance) } else { None },
            "max_slope_deg": m.max_slope_deg,
        },
        "planner_cost": plan.planner_cost,
        "expanded": plan.expanded,
        "solve_time_s": plan.solve_time_s,
        "lp": lp,
        "path": plan.path,
        "trajectory": plan.trajectory,
    });
    let json_path = stem.with_extension("json");
    fs::write(&json_path, serde_json::to_string_pretty(&doc)? + "\n")
        .with_context(|| format!("writing {}", json_path.display()))?;
    let mut csv = String::from("t,x,y,z,yaw,vx,vy,yaw_rate\n");
    for s in &plan.trajectory {
        csv.push_str(&format!(
            "{:.4},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6}\n",
            s.t, s.x, s.y, s.z, s.yaw, s.vx, s.vy, s.yaw_rate
        ));
    }
    let csv_path = stem.with_extension("csv");
    fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;
    Ok(())
}

fn run_demo(out: &Path, grid: usize, rbf_grid: usize, speed: f64, repeats: usize) -> Result<()> {
    if repeats == 0 {
        bail!("--repeats must be at least 1");
    }
    fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let base = PlannerOptions {
        grid_size: grid,
        speed,
        ..PlannerOptions::default()
    };
    let rbf = PlannerOptions {
        grid_size: rbf_grid,
        basis: BasisKind::DEFAULT_RBF,
        ..base.clone()
    };
    let ansdmd = PlannerOptions {
        basis: BasisKind::ANSDMD_RBF,
        ..rbf.clone()
    };
    let runs: Vec<(Method, &PlannerOptions)> = vec![
        (Method::AStar, &base),
        (Method::AStarAdmissible, &base),
        (Method::Dijkstra, &base),
        (Method::Pf, &base),
        (Method::Pf, &rbf),
        (Method::Pf, &ansdmd),
    ];
    let bar = ProgressBar::new((SCENARIO_NAMES.len() * runs.len() * repeats) as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} {msg} [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut rows = Vec::new();
    for name in SCENARIO_NAMES {
        let scenario = scenarios::by_name(name)?;
        let mut drawn = Vec::new();
        let mut notes = Vec::new();
        for (method, options) in &runs {
            let options = PlannerOptions {
                traversability: scenario.traversability,
                ..(*options).clone()
            };
            let method_label = label(*method, &options);
            bar.set_message(format!("{name}: {method_label}"));
            let mut plans = Vec::with_capacity(repeats);
            let mut failure = None;
            for _ in 0..repeats {
                // A fresh planner each time: P-F builds its generators in every repeat, so its
                // time is that of a first request on the map, like the graph searches'.
                let result = Planner::new(
                    scenario.map.clone(),
                    scenario.traversability,
                    options.grid_size,
                )
                .and_then(|mut planner| {
                    planner.plan(
                        scenario.start,
                        scenario.start_yaw,
                        &scenario.goal,
                        *method,
                        &options,
                    )
                });
                bar.inc(1);
                match result {
                    Ok(plan) => plans.push(plan),
                    Err(e) => {
                        failure = Some(e.to_string());
                        break;
                    }
                }
            }
            let outcome = match (failure, plans.first()) {
                (None, Some(first)) => {
                    let file_label = method_label
                        .replace(['²', '*'], "")
                        .replace(' ', "_")
                        .to_lowercase();
                    write_plan(&out.join(format!("{name}_{file_label}")), name, first)?;
                    drawn.push(PlotPath {
                        label: method_label.clone(),
                        points: first.path.clone(),
                        metrics: Some(first.metrics),
                    });
                    Ok(row_data(&plans))
                }
                (failure, _) => {
                    let reason = failure.unwrap_or_else(|| "no plan".to_string());
                    notes.push(format!("{method_label}: failed: {reason}"));
                    Err(reason)
                }
            };
            rows.push(ReportRow {
                scenario: name.to_string(),
                method: method_label,
                is_reference: *method == Method::Dijkstra,
                outcome,
            });
        }
        plot_plans(
            &out.join(format!("{name}.png")),
            name,
            &scenario.map,
            scenario.start,
            &scenario.goal,
            &drawn,
            &notes,
        )?;
    }
    bar.finish_and_clear();
    let table = markdown_table(&rows);
    let spread = rows
        .iter()
        .filter_map(|r| r.outcome.as_ref().ok())
        .map(|d| d.metrics_spread)
        .fold(0.0, f64::max);
    let repeatability = if spread == 0.0 {
        "every repeat returned the same path".to_string()
    } else {
        format!("the repeats' ∫p ds differed by up to {spread:.1e} (relative); the table shows the first")
    };
    let report = format!(
        "# P-F planner demo\n\n\
         Every method on the paper's scenarios, on the same cost: the planning grid's p (edge weight \
         p(source cell) × step on the graph). ∫p ds, length, clearance and slope are measured on \
         the map with the same quadrature on every path (bilinear p, trapezoid rule, step ≤ \
         resolution/8); max slope is the steepest terrain inclination under the path. Grid {grid}² \
         for P-F indicator and the graph searches (8-connected), {rbf_grid}² RBF centres for P-F \
         RBF, P-F with the exact solver where its structure holds and the uniform start density.\n\n\
         - P-F RBF transfer: the Shepard partition-of-unity Galerkin transfer, Markov by \
         construction, solved exactly (policy iteration).\n\
         - P-F RBF ansdmd: the paper's least squares G U = A on seeded random snapshot pairs, \
         row-normalised; its negative entries leave the SSP structure, so Clarabel solves the LP.\n\
         - A* paper heuristic: Euclidean distance to the goal centre, as in the paper; it \
         over-estimates the cost-to-go where p < 1, so its path is not optimal.\n\
         - A* admissible: p_min × distance beyond the goal cells, consistent with the edge \
         weights, so its cost is Dijkstra's optimum (tested to 1e-9).\n\
         - Dijkstra: the optimum on the graph, the reference of the ratio column.\n\n\
         Each method planned {repeats} times from scratch (P-F builds its generators every time); \
         solve time is the range over the repeats, wall clock on this machine; {repeatability}.\n\n\
         {table}\n{}\n",
        SCENARIO_NAMES.iter().map(|n| format!("![{n}]({n}.png)\n")).collect::<String>()
    );
    let report_path = out.join("report.md");
    fs::write(&report_path, &report)
        .with_context(|| format!("writing {}", report_path.display()))?;
    print!("{table}");
    println!("report -> {}", report_path.display());
    Ok(())
}

/// The table's numbers of one method over its repeats (at least one plan).
fn row_data(plans: &[Plan]) -> RowData {
    let first = &plans[0];
    let metrics_spread = plans
        .iter()
        .map(|p| {
            (p.metrics.cost_integral - first.metrics.cost_integral).abs()
                / first.metrics.cost_integral.abs().max(f64::MIN_POSITIVE)
        })
        .fold(0.0, f64::max);
    let generator_times_s = first.lp.as_ref().map(|_| {
        plans
            .iter()
            .filter_map(|p| p.lp.as_ref().map(|lp| lp.generator_time_s))
            .collect()
    });
    RowData {
        metrics: first.metrics,
        metrics_spread,
        solve_times_s: plans.iter().map(|p| p.solve_time_s).collect(),
        generator_times_s,
        expanded: first.expanded,
    }
}
