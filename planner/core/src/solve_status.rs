//! How an LP solve ended and which method produced it: typed, so reports, the CLI and the
//! service's wire codes are mapped from one enumeration instead of from strings.

use std::fmt;

use clarabel::solver::SolverStatus;

/// How an LP run ended. A returned [`LpReport`] carries `Trivial`, `Solved`, `AlmostSolved` or
/// `Uncertified`; the others travel in [`PlanError::LpFailed`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LpStatus {
    /// Nothing to move: the start density already sits in the target.
    Trivial,
    /// Optimal, and the duality certificate holds.
    Solved,
    /// Clarabel stopped at its reduced-accuracy tolerances.
    AlmostSolved,
    /// The exact solver returned a solution whose duality certificate does not hold.
    Uncertified,
    /// Clarabel reported (almost) primal infeasibility.
    PrimalInfeasible,
    /// Clarabel reported (almost) dual infeasibility.
    DualInfeasible,
    /// The iteration limit was reached (Clarabel or policy iteration).
    MaxIterations,
    /// The time limit was reached.
    MaxTime,
    /// A factorisation or step failed numerically.
    NumericalError,
    /// Clarabel stopped for lack of progress.
    InsufficientProgress,
    /// Clarabel refused the problem data or settings.
    SetupFailed,
    /// Clarabel ended without a status (unsolved or interrupted).
    Unsolved,
}

impl LpStatus {
    /// Name in reports (Clarabel's own status names where they exist).
    pub fn name(self) -> &'static str {
        match self {
            LpStatus::Trivial => "Trivial",
            LpStatus::Solved => "Solved",
            LpStatus::AlmostSolved => "AlmostSolved",
            LpStatus::Uncertified => "Uncertified",
            LpStatus::PrimalInfeasible => "PrimalInfeasible",
            LpStatus::DualInfeasible => "DualInfeasible",
            LpStatus::MaxIterations => "MaxIterations",
            LpStatus::MaxTime => "MaxTime",
            LpStatus::NumericalError => "NumericalError",
            LpStatus::InsufficientProgress => "InsufficientProgress",
            LpStatus::SetupFailed => "SetupFailed",
            LpStatus::Unsolved => "Unsolved",
        }
    }

    /// Whether the report's solution is optimal to the solver's tolerances.
    pub fn is_optimal(self) -> bool {
        matches!(
            self,
            LpStatus::Trivial | LpStatus::Solved | LpStatus::AlmostSolved
        )
    }
}

impl From<SolverStatus> for LpStatus {
    fn from(status: SolverStatus) -> Self {
        match status {
            SolverStatus::Solved => LpStatus::Solved,
            SolverStatus::AlmostSolved => LpStatus::AlmostSolved,
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                LpStatus::PrimalInfeasible
            }
            SolverStatus::DualInfeasible | SolverStatus::AlmostDualInfeasible => {
                LpStatus::DualInfeasible
            }
            SolverStatus::MaxIterations => LpStatus::MaxIterations,
            SolverStatus::MaxTime => LpStatus::MaxTime,
            SolverStatus::NumericalError => LpStatus::NumericalError,
            SolverStatus::InsufficientProgress => LpStatus::InsufficientProgress,
            _ => LpStatus::Unsolved,
        }
    }
}

impl fmt::Display for LpStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The method that produced an LP solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SolverUsed {
    /// No solver ran (a trivial problem).
    None,
    /// Deterministic generators: Dijkstra on the value function (exact).
    Dijkstra,
    /// Markov generators: policy iteration on the value function (exact).
    PolicyIteration,
    /// Clarabel's interior-point method.
    Clarabel,
}

impl SolverUsed {
    /// Name in reports.
    pub fn name(self) -> &'static str {
        match self {
            SolverUsed::None => "none",
            SolverUsed::Dijkstra => "dijkstra",
            SolverUsed::PolicyIteration => "policy-iteration",
            SolverUsed::Clarabel => "clarabel",
        }
    }
}

impl fmt::Display for SolverUsed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}
