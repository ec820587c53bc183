//! How many control ticks one `fmi2DoStep` may run: every FMI call has to return within 1 s
//! whatever the parameters and `h`, so a step whose ticks would cost more than a fixed budget of
//! estimated work is refused (fmi2Error, nothing run, the instance stays usable) instead of
//! being run or split.
//!
//! The estimate is deterministic (it depends on the parameters only, never on the clock, so the
//! same call is accepted or refused on every machine): a tick costs [`TICK_COST_US`], an MPC solve
//! [`SOLVE_COST_US_PER_HORIZON_STEP`] per horizon step, and a tick solves the MPC with the worst
//! share `min(1, 1/mpc.everyTicks + CONTACT_CHANGES_PER_PERIOD·control.dt/gait.period)` (the
//! periodic solves plus one per contact change), plus [`FSM_ENTRY_SOLVES`] solves for the FSM
//! states entered during the step. The costs are upper figures measured on the 2-core
//! development VM: an MPC-free tick about 10 µs; a horizon-40 solve 3–6 ms with the default
//! weights and about 12 ms (its 50-iteration limit) with the most ill-conditioned weights the
//! ranges allow (all Q 1e5, R 1e-8), i.e. 300 µs per horizon step. Through fmpy the most
//! expensive step the cap allows (8 ticks, each solving a horizon-40 MPC with those weights)
//! takes about 0.1 s; on a machine loaded with three busy processes on its two cores, 14 such
//! ticks took 0.71 s, so the budget of [`WORK_BUDGET_US`] keeps every call below 1 s with room.

use quad_controller::ControllerConfig;

/// Estimated work one doStep may do, µs.
pub const WORK_BUDGET_US: f64 = 150_000.0;
/// Pessimistic cost of a control tick without an MPC solve (FMU bookkeeping included), µs.
pub const TICK_COST_US: f64 = 20.0;
/// Pessimistic cost of one MPC solve per horizon step (it is at most 50 interior-point
/// iterations on a problem linear in the horizon), µs.
pub const SOLVE_COST_US_PER_HORIZON_STEP: f64 = 300.0;
/// Contact changes per gait period that can trigger a solve (each leg lifting and landing).
pub const CONTACT_CHANGES_PER_PERIOD: f64 = 8.0;
/// Solves triggered by entering FSM states within one step (stand-up, stand, locomotion and
/// one to spare).
pub const FSM_ENTRY_SOLVES: f64 = 4.0;

/// Estimated worst-case cost of running `ticks` control ticks with `config`, µs.
pub fn estimated_cost_us(config: &ControllerConfig, ticks: f64) -> f64 {
    let solve = SOLVE_COST_US_PER_HORIZON_STEP * config.mpc_horizon as f64;
    let share = (1.0 / config.mpc_every_ticks.max(1) as f64
        + CONTACT_CHANGES_PER_PERIOD * config.control_dt / config.gait_period)
        .min(1.0);
    FSM_ENTRY_SOLVES * solve + ticks * (TICK_COST_US + share * solve)
}

/// The largest number of control ticks one doStep may run with `config` (≥ 1 for every
/// configuration inside the parameter ranges, so a one-tick step is always accepted).
pub fn max_ticks_per_step(config: &ControllerConfig) -> u64 {
    let per_tick = estimated_cost_us(config, 1.0) - estimated_cost_us(config, 0.0);
    let mut ticks = ((WORK_BUDGET_US - estimated_cost_us(config, 0.0)) / per_tick).floor();
    // The division can round up across an integer: step back until the estimate fits.
    while ticks.is_finite() && ticks >= 1.0 && estimated_cost_us(config, ticks) > WORK_BUDGET_US {
        ticks -= 1.0;
    }
    if ticks.is_finite() && ticks >= 1.0 {
        // Finite, ≥ 1 and at most WORK_BUDGET_US / TICK_COST_US: the cast is exact.
        ticks as u64
    } else {
        1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use quad_controller::{limits, GaitKind};

    /// The most expensive configuration the parameter ranges allow.
    fn worst() -> ControllerConfig {
        ControllerConfig {
            control_dt: *limits::CONTROL_DT.start(),
            mpc_every_ticks: *limits::MPC_EVERY_TICKS.start(),
            mpc_horizon: *limits::MPC_HORIZON.end(),
            gait: GaitKind::Walk,
            gait_period: *limits::GAIT_PERIOD.start(),
            ..ControllerConfig::default()
        }
    }

    #[test]
    fn default_configuration_allows_steps_of_a_third_of_a_second() {
        let config = ControllerConfig::default();
        // solve 3 000 µs, share 0.1 + 8·0.001/0.3 → (150 000 − 12 000) / 400 = 345 (344 when
        // the sum rounds above the budget)
        let max = max_ticks_per_step(&config);
        assert!((344..=345).contains(&max), "{max}");
        assert!(estimated_cost_us(&config, max as f64) <= WORK_BUDGET_US);
        assert!(estimated_cost_us(&config, (max + 2) as f64) > WORK_BUDGET_US);
    }

    #[test]
    fn worst_configuration_still_allows_a_few_ticks_within_budget() {
        let config = worst();
        let max = max_ticks_per_step(&config);
        // solve 12 000 µs on every tick: (150 000 − 48 000) / 12 020 = 8.5
        assert_eq!(max, 8);
        assert!(estimated_cost_us(&config, max as f64) <= WORK_BUDGET_US);
    }

    #[test]
    fn cheaper_configurations_allow_more_ticks_but_never_unboundedly_many() {
        let cheap = ControllerConfig {
            control_dt: *limits::CONTROL_DT.start(),
            mpc_every_ticks: *limits::MPC_EVERY_TICKS.end(),
            mpc_horizon: *limits::MPC_HORIZON.start(),
            gait_period: *limits::GAIT_PERIOD.end(),
            ..ControllerConfig::default()
        };
        let max = max_ticks_per_step(&cheap);
        assert!(max > max_ticks_per_step(&ControllerConfig::default()));
        assert!(max as f64 <= WORK_BUDGET_US / TICK_COST_US, "{max}");
    }
}
