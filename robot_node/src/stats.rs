//! Loop timing statistics in fixed memory: histograms of 1 µs bins (recording is O(1) and
//! allocation-free, so it can run inside the control loop), and the per-window and whole-run
//! figures of the status message and the benchmark.

use crate::schedule::Trigger;

/// Histogram bins, 1 µs each: durations up to 20 ms are resolved exactly to the microsecond;
/// longer ones are counted in the last bin and still reach `max_ns`.
const BINS: usize = 20_000;
const BIN_NS: u64 = 1_000;

/// Durations in nanoseconds: count, maximum and percentiles at 1 µs resolution.
#[derive(Clone)]
pub struct Histogram {
    counts: Box<[u32]>,
    total: u64,
    max_ns: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Self {
            counts: vec![0; BINS].into_boxed_slice(),
            total: 0,
            max_ns: 0,
        }
    }
}

impl std::fmt::Debug for Histogram {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Histogram")
            .field("total", &self.total)
            .field("max_ns", &self.max_ns)
            .finish()
    }
}

impl Histogram {
    pub fn record(&mut self, ns: u64) {
        let bin = usize::try_from(ns / BIN_NS)
            .unwrap_or(BINS - 1)
            .min(BINS - 1);
        self.counts[bin] = self.counts[bin].saturating_add(1);
        self.total += 1;
        self.max_ns = self.max_ns.max(ns);
    }

    pub fn count(&self) -> u64 {
        self.total
    }

    /// Count, median, 99th percentile and maximum, in seconds, as JSON (the benchmarks' form).
    pub fn to_json(&self) -> serde_json::Value {
        let s = |ns: u64| ns as f64 * 1e-9;
        serde_json::json!({
            "count": self.count(),
            "p50": s(self.percentile_ns(0.5)),
            "p99": s(self.percentile_ns(0.99)),
            "max": s(self.max_ns()),
        })
    }

    pub fn max_ns(&self) -> u64 {
        self.max_ns
    }

    /// The smallest recorded duration d (upper edge of its 1 µs bin, capped at the maximum)
    /// such that at least `fraction` of the recordings are ≤ d; 0 when empty.
    pub fn percentile_ns(&self, fraction: f64) -> u64 {
        if self.total == 0 {
            return 0;
        }
        let wanted = ((fraction.clamp(0.0, 1.0) * self.total as f64).ceil() as u64).max(1);
        let mut seen = 0u64;
        for (bin, &count) in self.counts.iter().enumerate() {
            seen += u64::from(count);
            if seen >= wanted {
                return ((bin as u64 + 1) * BIN_NS).min(self.max_ns);
            }
        }
        self.max_ns
    }

    pub fn clear(&mut self) {
        self.counts.fill(0);
        self.total = 0;
        self.max_ns = 0;
    }
}

/// Timing of the loop over a window (between two status messages) or a whole run.
#[derive(Debug, Clone, Default)]
pub struct LoopTiming {
    /// Time between two consecutive cycle starts.
    pub period: Histogram,
    /// |period − nominal period|.
    pub jitter: Histogram,
    /// Time from a cycle's start to its command having been sent.
    pub runtime: Histogram,
    /// Time from a state's arrival to the sending of the command computed from it.
    pub latency: Histogram,
    /// Cycles whose period exceeded the miss threshold.
    pub misses: u64,
    /// Cycles whose work took longer than the nominal period.
    pub overruns: u64,
    /// Cycles started by a state that arrived while the loop waited for it.
    pub state_arrived: u64,
    /// Cycles that found a fresh state waiting when they started: at their slot's opening, or
    /// at the phase-locked deadline.
    pub state_waiting: u64,
    /// Cycles started by the watchdog (the slot ended without a fresh state), by the clock
    /// alone when the loop is not aligned to the states, or at a phase-locked deadline that
    /// found no fresh state.
    pub watchdog: u64,
    /// Slots without a cycle because the loop was still busy when they closed.
    pub skipped_slots: u64,
    /// Torque cycles without a fresh state: the controller was not stepped and its last
    /// command was sent again.
    pub held_cycles: u64,
}

impl LoopTiming {
    pub fn count_trigger(&mut self, trigger: Trigger) {
        match trigger {
            Trigger::StateArrived(_) => self.state_arrived += 1,
            Trigger::StateWaiting(_) | Trigger::Deadline(Some(_)) => self.state_waiting += 1,
            Trigger::Watchdog | Trigger::Clock | Trigger::Deadline(None) => self.watchdog += 1,
        }
    }

    /// Empties the window in place (no allocation: it runs inside the control loop).
    pub fn clear(&mut self) {
        self.period.clear();
        self.jitter.clear();
        self.runtime.clear();
        self.latency.clear();
        self.misses = 0;
        self.overruns = 0;
        self.state_arrived = 0;
        self.state_waiting = 0;
        self.watchdog = 0;
        self.skipped_slots = 0;
        self.held_cycles = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_exact_to_the_microsecond() {
        let mut h = Histogram::default();
        assert_eq!(h.percentile_ns(0.99), 0);
        for us in 1..=100u64 {
            h.record(us * 1_000 - 500);
        }
        assert_eq!(h.count(), 100);
        assert_eq!(h.percentile_ns(0.5), 50_000);
        assert_eq!(h.percentile_ns(0.99), 99_000);
        assert_eq!(h.percentile_ns(1.0), 99_500, "capped at the maximum");
        assert_eq!(h.max_ns(), 99_500);
        h.record(5_000_000_000);
        assert_eq!(
            h.max_ns(),
            5_000_000_000,
            "beyond the last bin the maximum is exact"
        );
        h.clear();
        assert_eq!((h.count(), h.max_ns(), h.percentile_ns(0.5)), (0, 0, 0));
    }
}
