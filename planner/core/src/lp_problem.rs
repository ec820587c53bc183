//! The data of one P-F LP (generators, costs, start density, targets, speed bound), shared by
//! the solvers ([`crate::lp`], [`crate::ssp`]) and the certificate ([`crate::certificate`]).

use crate::error::PlanError;
use crate::generators::Generators;

/// Inputs of one LP, all indexed by active basis function.
#[derive(Debug, Clone, Copy)]
pub struct LpProblem<'a> {
    /// Generators and basis.
    pub generators: &'a Generators,
    /// Bᵢ = ∫ p φᵢ, all > 0.
    pub cost: &'a [f64],
    /// Start density coefficients t ≥ 0 (entries on targets are ignored).
    pub start: &'a [f64],
    /// Whether each basis function belongs to the (absorbing) target set.
    pub target: &'a [bool],
    /// Speed bound, > 0.
    pub u_max: f64,
}

pub(crate) fn invalid(name: &'static str, reason: String) -> PlanError {
    PlanError::InvalidOption { name, reason }
}

impl LpProblem<'_> {
    pub(crate) fn validate(&self) -> Result<(), PlanError> {
        let n = self.generators.basis.len();
        for (name, len) in [
            ("lp cost", self.cost.len()),
            ("lp start", self.start.len()),
            ("lp target", self.target.len()),
        ] {
            if len != n {
                return Err(invalid(
                    name,
                    format!("{len} entries, expected {n} (one per basis function)"),
                ));
            }
        }
        if !(self.u_max.is_finite() && self.u_max > 0.0) {
            return Err(invalid(
                "u_max",
                format!("{} must be finite and > 0", self.u_max),
            ));
        }
        if let Some(i) = self.cost.iter().position(|&b| !(b.is_finite() && b > 0.0)) {
            return Err(invalid(
                "lp cost",
                format!("entry {i} is {}, expected > 0", self.cost[i]),
            ));
        }
        if let Some(i) = self
            .start
            .iter()
            .position(|&t| !(t.is_finite() && t >= 0.0))
        {
            return Err(invalid(
                "lp start",
                format!("entry {i} is {}, expected ≥ 0", self.start[i]),
            ));
        }
        if !self.target.iter().any(|&t| t) {
            return Err(invalid(
                "goal",
                "the target set contains no basis function".into(),
            ));
        }
        Ok(())
    }
}
