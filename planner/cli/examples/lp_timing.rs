//! Times the P-F LP on the `c_shape` scenario (one solve per configuration, no criterion):
//! `cargo run --release -p pf-plan --example lp_timing -- <indicator|rbf> <size> <primal|dual> [tol] [threads]`.

use std::time::Instant;

use anyhow::{bail, Context, Result};
use pf_planner::basis::BasisKind;
use pf_planner::grid::PlanningGrid;
use pf_planner::lp::{self, LpForm, LpSettings};
use pf_planner::pf::{prepare, PfGenerators, StartDensity};
use pf_planner::scenarios;

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .init();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let basis = match args.first().map(String::as_str) {
        Some("rbf") => BasisKind::DEFAULT_RBF,
        Some("indicator") | None => BasisKind::Indicator,
        Some(other) => bail!("unknown basis {other}"),
    };
    let size: usize = args.get(1).map_or(Ok(64), |s| s.parse()).context("size")?;
    let form = match args.get(2).map(String::as_str) {
        Some("primal") => LpForm::Primal,
        _ => LpForm::Dual,
    };
    let tolerance: f64 = args.get(3).map_or(Ok(1e-9), |s| s.parse()).context("tol")?;
    let max_threads: u32 = args
        .get(4)
        .map_or(Ok(0), |s| s.parse())
        .context("threads")?;
    let scenario = scenarios::by_name("c_shape").context("scenario")?;
    let grid = PlanningGrid::from_map(&scenario.map, &scenario.traversability, size)?;
    let t = Instant::now();
    let gens = PfGenerators::build(&grid, &basis, 8)?;
    let gen_s = t.elapsed().as_secs_f64();
    let prepared = prepare(
        &gens,
        &grid,
        scenario.start,
        &scenario.goal,
        StartDensity::UniformFree,
    )?;
    let settings = LpSettings {
        tolerance,
        max_threads,
        form,
        ..LpSettings::default()
    };
    let sol = lp::solve(&prepared.problem(&gens, 1.0), &settings)?;
    let r = &sol.report;
    println!(
        "{size} {form:?} tol {tolerance:e} threads {max_threads}: gen {gen_s:.3} s, LP {:.3} s, {} it, {}, obj {:.12}, balance {:.2e}, {} x {}",
        r.solve_time_s, r.iterations, r.status, r.objective, r.mass_balance_residual, r.variables, r.constraints
    );
    Ok(())
}
