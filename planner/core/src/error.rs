//! Typed errors of the planner: every bad input becomes one of these, with a reason, never a panic.

use thiserror::Error;

/// A map that breaks an invariant of [`crate::map::GridMap`].
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MapError {
    #[error("map origin must be finite")]
    NonFiniteOrigin,
    #[error("map resolution must be finite and positive, got {0}")]
    BadResolution(f64),
    #[error("map is empty ({width} x {height} cells)")]
    Empty { width: usize, height: usize },
    #[error("map of {width} x {height} cells exceeds the limit of {max_cells} cells")]
    TooLarge {
        width: usize,
        height: usize,
        max_cells: usize,
    },
    #[error("{what} has {actual} entries, expected {expected} (width x height)")]
    LengthMismatch {
        what: &'static str,
        expected: usize,
        actual: usize,
    },
    #[error("height of cell ({ix}, {iy}) is not finite")]
    NonFiniteHeight { ix: usize, iy: usize },
    #[error(
        "height of cell ({ix}, {iy}) is {value} m; traversability p = h/h_max needs heights >= 0"
    )]
    NegativeHeight { ix: usize, iy: usize, value: f64 },
    #[error("unknown_traversability (the p of unobserved cells) must lie in (0, 1], got {0}")]
    BadUnknownTraversability(f64),
    #[error(
        "height variance of cell ({ix}, {iy}) is {value} m^2; it must be finite in 0 ..= {max} m^2"
    )]
    BadHeightVariance {
        ix: usize,
        iy: usize,
        value: f64,
        max: f64,
    },
}

/// Why a planning request cannot be answered. Every stage (grid, graph search, P-F pipeline,
/// file I/O) reports through this one enum so callers (CLI, LCM service) see a single error type.
#[derive(Debug, Error)]
pub enum PlanError {
    #[error("invalid map: {0}")]
    InvalidMap(#[from] MapError),
    #[error("start ({}, {}) is off the map", .point[0], .point[1])]
    StartOffMap { point: [f64; 2] },
    #[error("goal centre ({}, {}) is off the map", .point[0], .point[1])]
    GoalOffMap { point: [f64; 2] },
    #[error("start ({}, {}) is inside an obstacle (or its safety padding)", .point[0], .point[1])]
    StartInObstacle { point: [f64; 2] },
    #[error("goal region around ({}, {}) has no free cell: it lies inside an obstacle (or its safety padding)", .point[0], .point[1])]
    GoalInObstacle { point: [f64; 2] },
    #[error("goal unreachable from the start: {reason}")]
    Unreachable { reason: String },
    #[error("invalid option {name}: {reason}")]
    InvalidOption { name: &'static str, reason: String },
    #[error("I/O error on {path}: {reason}")]
    Io { path: String, reason: String },
    #[error("malformed file {path}: {reason}")]
    Format { path: String, reason: String },
    /// The P-F linear program has no feasible point (for example the goal is walled off).
    #[error("P-F linear program is infeasible: {reason}")]
    Infeasible { reason: String },
    /// The LP solver stopped without a solution (iteration/time limit, numerical trouble).
    #[error("P-F linear program failed with solver status {status}: {reason}")]
    LpFailed {
        status: crate::solve_status::LpStatus,
        reason: String,
    },
    /// The request's time limit passed during `phase`; nothing was kept from the phase.
    #[error("time limit of {limit_s} s reached during {phase}")]
    TimeLimit { phase: &'static str, limit_s: f64 },
    /// The feedback-law trajectory did not reach the goal.
    #[error("P-F trajectory did not reach the goal: {reason}")]
    TrajectoryFailed { reason: String },
}
