//! The machine's own floor for a periodic real-time loop: a thread with the control loop's
//! period, priority and sleep (absolute `clock_nanosleep` deadlines), doing nothing else (no
//! FMU, no bus). Its period jitter and misses are what the scheduler, the timer and, on a
//! virtual machine, the hypervisor add to any loop; the node's own figures are read against
//! them (cyclictest measures the same).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::clock::{self, RealtimeSettings};
use crate::node::MISS_FACTOR;
use crate::stats::{Histogram, LoopTiming};

/// A bare periodic loop's figures.
#[derive(Debug, Clone)]
pub struct FloorReport {
    /// Period, jitter and misses as the node counts them.
    pub timing: LoopTiming,
    /// How long after its deadline each wake-up came.
    pub lateness: Histogram,
    pub cycles: u64,
    pub realtime: RealtimeSettings,
}

impl FloorReport {
    pub fn to_json(&self, period_s: f64) -> serde_json::Value {
        serde_json::json!({
            "period_nominal": period_s,
            "cycles": self.cycles,
            "misses": self.timing.misses,
            "period": self.timing.period.to_json(),
            "jitter": self.timing.jitter.to_json(),
            "lateness": self.lateness.to_json(),
            "realtime_priority": self.realtime.fifo_priority,
            "memory_locked": self.realtime.memory_locked,
        })
    }
}

/// Runs the bare loop on the calling thread for `duration` (or until `stop` is set), with
/// SCHED_FIFO at `priority` and mlockall where permitted.
pub fn measure_floor(
    period: Duration,
    duration: Duration,
    priority: Option<i32>,
    stop: &AtomicBool,
) -> FloorReport {
    let realtime = priority.map_or_else(RealtimeSettings::default, clock::apply_realtime);
    let period_ns = u64::try_from(period.as_nanos()).unwrap_or(u64::MAX).max(1);
    let miss_ns = (period_ns as f64 * MISS_FACTOR) as u64;
    let cycles_wanted = u64::try_from(duration.as_nanos()).unwrap_or(u64::MAX) / period_ns;
    let mut timing = LoopTiming::default();
    let mut lateness = Histogram::default();
    let mut deadline = clock::now_ns() + period_ns;
    let mut previous: Option<u64> = None;
    let mut cycles = 0;
    while cycles < cycles_wanted && !stop.load(Ordering::Relaxed) {
        clock::sleep_until_ns(deadline);
        let woke = clock::now_ns();
        lateness.record(woke.saturating_sub(deadline));
        if let Some(previous) = previous {
            let period = woke.saturating_sub(previous);
            timing.period.record(period);
            timing.jitter.record(period.abs_diff(period_ns));
            if period > miss_ns {
                timing.misses += 1;
            }
        }
        previous = Some(woke);
        cycles += 1;
        // The node's rule: a late wake-up does not shift the later deadlines.
        deadline += period_ns;
    }
    FloorReport {
        timing,
        lateness,
        cycles,
        realtime,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bare_loop_keeps_its_period_on_average_and_counts_every_cycle() {
        let stop = AtomicBool::new(false);
        let report = measure_floor(
            Duration::from_millis(1),
            Duration::from_millis(200),
            None,
            &stop,
        );
        assert_eq!(report.cycles, 200);
        assert_eq!(report.timing.period.count(), 199);
        assert_eq!(report.lateness.count(), 200);
        // Absolute deadlines: whatever the wake-ups, the median period is the nominal one
        // to within a bin of the histogram plus a loaded machine's slack.
        let median = report.timing.period.percentile_ns(0.5);
        assert!(
            median.abs_diff(1_000_000) < 200_000,
            "median period {median} ns"
        );
        let json = report.to_json(1e-3);
        assert_eq!(json["cycles"], 200);
        assert!(json["lateness"]["p50"].as_f64().is_some());
    }

    #[test]
    fn a_stop_request_ends_the_loop_at_once() {
        let stop = AtomicBool::new(true);
        let report = measure_floor(
            Duration::from_millis(1),
            Duration::from_secs(60),
            None,
            &stop,
        );
        assert_eq!(report.cycles, 0);
    }
}
