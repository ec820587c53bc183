//! What the planner's criterion benches share: per-sample times of a measurement, for the summary
//! tables they print after criterion's own output.

use std::cell::RefCell;
use std::time::Instant;

use criterion::Criterion;

/// Per-iteration times of the samples of the last measurement, seconds.
#[derive(Default)]
pub struct Recorder(RefCell<Vec<f64>>);

impl Recorder {
    /// Benchmarks `routine` under `name`; returns (minimum, median, maximum) of the samples'
    /// per-iteration times, seconds (NaN without samples).
    pub fn measure(&self, c: &mut Criterion, name: &str, mut routine: impl FnMut()) -> [f64; 3] {
        self.0.borrow_mut().clear();
        c.bench_function(name, |b| {
            b.iter_custom(|iters| {
                let started = Instant::now();
                for _ in 0..iters {
                    routine();
                }
                let elapsed = started.elapsed();
                self.0
                    .borrow_mut()
                    .push(elapsed.as_secs_f64() / iters as f64);
                elapsed
            })
        });
        let mut times = self.0.borrow().clone();
        times.sort_by(f64::total_cmp);
        match (times.first(), times.get(times.len() / 2), times.last()) {
            (Some(&lo), Some(&mid), Some(&hi)) => [lo, mid, hi],
            _ => [f64::NAN; 3],
        }
    }
}
