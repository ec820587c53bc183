//! Diagnostics of one P-F solve: `cargo run --release -p pf-plan --example pf_diag -- <scenario> <indicator|rbf> <size> [seed]`.
//! Prints the outcome, the LP value against the grid optimum, and the field around the end point.

use anyhow::{bail, Context, Result};
use pf_planner::basis::BasisKind;
use pf_planner::graph::{distances_to_targets, Connectivity};
use pf_planner::grid::PlanningGrid;
use pf_planner::pf::{self, PfGenerators, PfOptions};
use pf_planner::scenarios;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args.first().map_or("pits", String::as_str);
    let basis = match args.get(1).map(String::as_str) {
        Some("indicator") => BasisKind::Indicator,
        Some("rbf") | None => BasisKind::DEFAULT_RBF,
        Some(other) => bail!("unknown basis {other}"),
    };
    let size: usize = args.get(2).map_or(Ok(32), |s| s.parse()).context("size")?;
    let scenario = match args.get(3) {
        Some(seed) => scenarios::with_seed(name, seed.parse().context("seed")?)?,
        None => scenarios::by_name(name)?,
    };
    let grid = PlanningGrid::from_map(&scenario.map, &scenario.traversability, size)?;
    let gens = PfGenerators::build(&grid, &basis, 8)?;
    println!("generator stats: {:?}", gens.generators().stats);
    let sol = pf::solve(
        &gens,
        &grid,
        scenario.start,
        &scenario.goal,
        &PfOptions::default(),
    )?;
    let dist = distances_to_targets(&grid, &grid.goal_cells(&scenario.goal), Connectivity::Eight);
    let b = &gens.generators().basis;
    let mut graph = 0.0;
    for (i, &t) in sol.start_coefficients.iter().enumerate() {
        if t > 0.0 {
            graph += t * gens.mass_integrals()[i] * dist[b.cell(i)];
        }
    }
    println!(
        "outcome {:?}, {} points; LP weighted length {:.6} vs 8-graph {:.6}; LP {} in {:.3} s",
        sol.outcome,
        sol.path.len(),
        sol.weighted_length,
        graph,
        sol.lp.status,
        sol.lp.solve_time_s
    );
    let end = *sol.path.last().context("path")?;
    let h = grid.cell_size;
    println!("end {end:?}; field around it (ρ, u):");
    for dy in (-3..=3).rev() {
        let mut line = String::new();
        for dx in -3..=3 {
            let p = [end[0] + dx as f64 * 0.5 * h, end[1] + dy as f64 * 0.5 * h];
            let blocked = if grid.blocked_at(p) { "#" } else { " " };
            match sol.field.velocity_at(p) {
                Some(u) => line.push_str(&format!(
                    "{blocked}{:>7.1e}({:+.2},{:+.2}) ",
                    sol.field.density_at(p),
                    u[0],
                    u[1]
                )),
                None => line.push_str(&format!("{blocked}   none            ")),
            }
        }
        println!("{line}");
    }
    let tail: Vec<_> = sol.path.iter().rev().take(12).collect();
    println!("last points: {tail:?}");
    Ok(())
}
