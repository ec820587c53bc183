//! A wall-clock limit shared by the phases of one plan (generator build, LP solve), checked
//! cooperatively inside their loops so that a request with `max_solve_time = T` returns within
//! about T whatever the grid size.

use std::time::{Duration, Instant};

use crate::error::PlanError;

/// Longest limit honoured (larger ones, and non-finite ones, mean "no limit").
const MAX_LIMIT_S: f64 = 1e9;

/// When the work of one plan must stop, if ever.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deadline {
    at: Option<Instant>,
    limit_s: f64,
}

impl Deadline {
    /// No limit.
    pub const NONE: Self = Self {
        at: None,
        limit_s: f64::INFINITY,
    };

    /// `limit_s` seconds after `started` (no limit when `limit_s` is not finite or above 1e9 s;
    /// a negative or NaN limit has already passed).
    pub fn after(started: Instant, limit_s: f64) -> Self {
        if limit_s.is_nan() || limit_s <= 0.0 {
            return Self {
                at: Some(started),
                limit_s,
            };
        }
        if limit_s > MAX_LIMIT_S {
            return Self::NONE;
        }
        Self {
            at: Some(started + Duration::from_secs_f64(limit_s)),
            limit_s,
        }
    }

    /// The limit this deadline was made from, seconds (∞ without one).
    pub fn limit_s(&self) -> f64 {
        self.limit_s
    }

    /// Seconds left (∞ without a limit, ≤ 0 once passed).
    pub fn remaining_s(&self) -> f64 {
        match self.at {
            None => f64::INFINITY,
            Some(at) => {
                let now = Instant::now();
                if now >= at {
                    -(now - at).as_secs_f64()
                } else {
                    (at - now).as_secs_f64()
                }
            }
        }
    }

    /// Whether the deadline has passed.
    pub fn passed(&self) -> bool {
        self.at.is_some_and(|at| Instant::now() >= at)
    }

    /// `Err(PlanError::TimeLimit)` naming `phase` once the deadline has passed.
    pub fn check(&self, phase: &'static str) -> Result<(), PlanError> {
        if self.passed() {
            Err(PlanError::TimeLimit {
                phase,
                limit_s: self.limit_s,
            })
        } else {
            Ok(())
        }
    }

    /// `error` from a phase that ran on what was left of this deadline (its own limit the time
    /// remaining then), a time limit restated with this deadline's: the limit the request set.
    pub fn restate(&self, error: PlanError) -> PlanError {
        match error {
            PlanError::TimeLimit { phase, .. } => PlanError::TimeLimit {
                phase,
                limit_s: self.limit_s,
            },
            other => other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_map_to_deadlines() {
        let now = Instant::now();
        assert_eq!(Deadline::after(now, f64::INFINITY), Deadline::NONE);
        assert_eq!(Deadline::after(now, 1e12), Deadline::NONE);
        assert!(Deadline::after(now, 0.0).passed());
        assert!(Deadline::after(now, -1.0).passed());
        assert!(Deadline::after(now, f64::NAN).passed());
        let later = Deadline::after(now, 3600.0);
        assert!(!later.passed() && later.check("x").is_ok());
        assert!(later.remaining_s() > 3500.0);
        let err = Deadline::after(now, 0.0).check("the LP solve").unwrap_err();
        assert!(matches!(
            err,
            PlanError::TimeLimit {
                phase: "the LP solve",
                ..
            }
        ));
        assert!(Deadline::NONE.check("x").is_ok());
        assert_eq!(Deadline::NONE.remaining_s(), f64::INFINITY);
    }

    /// A phase that ran on the time left over (here none of a 0.1 s request) reports the
    /// request's limit; other errors pass unchanged.
    #[test]
    fn a_later_phase_reports_the_requests_limit() {
        let request = Deadline::after(Instant::now(), 0.1);
        let left_over = Deadline::after(Instant::now(), 0.0);
        let error = request.restate(left_over.check("the LP solve").unwrap_err());
        assert_eq!(
            error.to_string(),
            "time limit of 0.1 s reached during the LP solve"
        );
        let other = PlanError::Infeasible {
            reason: "walled off".into(),
        };
        assert!(matches!(
            request.restate(other),
            PlanError::Infeasible { .. }
        ));
    }
}
