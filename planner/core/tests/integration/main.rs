//! The integration tests of `planner/core`, one test binary (each module was a test binary of its own).

mod admissible_astar;
mod ansdmd;
mod bad_input;
mod baselines;
mod exact_solver;
mod import_bad_input;
mod import_dem;
#[path = "../support/import_fixtures.rs"]
mod import_fixtures;
mod maze;
mod optimality;
mod paper_lp;
mod pf_scenarios;
mod rbf_scale;
mod scenarios;
mod slope_limit;
#[path = "../support/mod.rs"]
mod support;
