//! Perron-Frobenius density-space planner: maps, scenarios, ANSDMD generators, the LP, feedback law, baselines.
//!
//! Data flow: [`map::GridMap`] (terrain) → traversability p(x) → generators + LP (density space)
//! → feedback law u = ρ̄/ρ → integrated path → time-parameterised reference trajectory.

pub mod basis;
pub mod certificate;
pub mod deadline;
pub mod error;
pub mod feedback;
pub mod feedback_grid;
pub mod generators;
pub mod graph;
pub mod grid;
pub mod import;
pub mod io;
pub mod lp;
pub mod lp_problem;
pub mod map;
pub mod metrics;
pub mod pf;
pub mod plan;
pub mod scenarios;
pub mod solve_status;
pub mod ssp;
pub mod trajectory;
pub mod traversability;
