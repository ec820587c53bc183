//! How late a `low_state_t` arrives, from the body's own clock (`tick`, milliseconds) and the
//! node's arrival time: the offset arrival − tick is the clocks' offset plus the transport's
//! delay, and its smallest value seen is the offset with the least delay. A state's delay is
//! its offset above that baseline. A gap in the stream is seen by the state timeout; a stream
//! that flows on time but late (a constant delay that began after the stream started) only by
//! this. A delay present from the first state on cannot be told from a clock offset without a
//! shared clock.

/// How fast the baseline may rise, per unit of elapsed time: the body's clock may run slower
/// than the node's by this much (quartz clocks drift by tens of ppm).
pub const CLOCK_DRIFT: f64 = 1e-4;

#[derive(Debug, Clone, Copy, Default)]
pub struct DelayTracker {
    /// The least offset (arrival − tick) seen, raised by the allowed drift since, ns.
    baseline_ns: Option<i128>,
    last_tick_ms: i64,
    last_arrival_ns: u64,
}

impl DelayTracker {
    /// A state stamped `tick_ms` by the body arrived at `arrival_ns` (CLOCK_MONOTONIC); returns
    /// its delay in ns. A tick at or before the previous one (a restarted body, a new clock)
    /// starts a new baseline.
    pub fn observe(&mut self, tick_ms: i64, arrival_ns: u64) -> u64 {
        let offset = i128::from(arrival_ns) - i128::from(tick_ms) * 1_000_000;
        let baseline = match self.baseline_ns {
            Some(baseline) if tick_ms > self.last_tick_ms => {
                let elapsed = arrival_ns.saturating_sub(self.last_arrival_ns);
                let allowed_rise = (elapsed as f64 * CLOCK_DRIFT) as i128;
                (baseline + allowed_rise).min(offset)
            }
            _ => offset,
        };
        self.baseline_ns = Some(baseline);
        self.last_tick_ms = tick_ms;
        self.last_arrival_ns = arrival_ns;
        u64::try_from(offset - baseline).unwrap_or(u64::MAX)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn a_constant_delay_that_begins_mid_stream_is_measured_and_ends_with_it() {
        let mut tracker = DelayTracker::default();
        // The body's clock is 5 s ahead of the node's; states arrive 0.2 ms after their tick.
        let arrival = |tick: u64, delay: u64| tick * MS - 5_000 * MS + 200_000 + delay;
        for tick in 6_000..7_000 {
            assert_eq!(tick_delay(&mut tracker, tick, arrival(tick, 0)), 0);
        }
        for tick in 7_000..7_100 {
            let delay = tick_delay(&mut tracker, tick, arrival(tick, 80 * MS));
            assert!(delay.abs_diff(80 * MS) < MS / 10, "{delay} ns");
        }
        assert_eq!(tick_delay(&mut tracker, 7_100, arrival(7_100, 0)), 0);
    }

    #[test]
    fn a_slower_body_clock_within_the_drift_allowance_reads_as_no_delay() {
        let mut tracker = DelayTracker::default();
        // 50 ppm slow: each body millisecond takes 1.00005 ms of the node's, for 100 s.
        let mut worst = 0;
        for tick in 0..100_000u64 {
            let arrival = 1_000 * MS + tick * (MS + 50);
            worst = worst.max(tick_delay(&mut tracker, tick, arrival));
        }
        assert!(worst < MS / 10, "worst delay {worst} ns");
    }

    #[test]
    fn a_restarted_body_starts_a_new_baseline() {
        let mut tracker = DelayTracker::default();
        for tick in 1_000..1_100 {
            tick_delay(&mut tracker, tick, tick * MS);
        }
        // A new process counts from 0 again, 3 s later on the node's clock.
        assert_eq!(tick_delay(&mut tracker, 0, 4_100 * MS), 0);
        assert_eq!(tick_delay(&mut tracker, 1, 4_101 * MS), 0);
    }

    #[test]
    fn hostile_ticks_neither_overflow_nor_panic() {
        let mut tracker = DelayTracker::default();
        for tick in [i64::MIN, -1, 0, i64::MAX, i64::MAX, 3] {
            tracker.observe(tick, u64::MAX);
            tracker.observe(tick, 0);
        }
    }

    fn tick_delay(tracker: &mut DelayTracker, tick: u64, arrival: u64) -> u64 {
        tracker.observe(i64::try_from(tick).unwrap(), arrival)
    }
}
