//! When the control loop runs: once per *slot* of one period, started by the arrival of a
//! fresh `low_state_t` (so a command follows its state by the cycle's work, not by the wait
//! for a fixed deadline), with the slot's end as the watchdog when no state comes.
//!
//! Slot k spans `[centre_k - T/2, centre_k + T/2)`. The cycle of slot k starts
//! - at the slot's opening if a fresh state is already waiting (a body in lockstep, which
//!   answers each command at once),
//! - else when a fresh state arrives inside the slot (a body paced by its own clock),
//! - else at the slot's end (watchdog: the body is late or silent; the cycle runs with the
//!   newest state it has and the safety monitor judges its age).
//!
//! One cycle per slot, and slots advance by one period plus a small phase correction: the
//! correction is a phase-locked loop on the state stream. A state that arrived while the loop
//! waited moves the next slot's centre a fraction of the way towards its arrival, so a paced
//! stream ends up in the middle of the slots, where arrival jitter of up to ±T/2 still triggers
//! the right cycle. A state that was already waiting at the opening arrived before the slot
//! (the stream is early: a body whose clock started half a period before the node's would
//! otherwise have each state wait for the next opening, forever): it moves the slots earlier.
//!
//! A body in lockstep (it answers each command at once) is a feedback loop through the body:
//! its state is always waiting, and moving the slots earlier brings the answer earlier too. So
//! the corrections draw on a budget: one period to acquire the stream's phase at start, then
//! 0.2 % of the elapsed time. The loop's average rate stays within 0.2 % of the nominal rate
//! whatever the body does, and the FMU's time (one step per cycle) stays wall-clock time. A
//! paced body needs far less: same-machine clocks do not drift, crystal clocks by ppm.
//!
//! With a phase-locked deadline (`--trigger deadline`) the same slots are kept, but the cycle
//! always starts at a fixed point of its slot, `centre + margin`, with the newest state it has:
//! the period then has the jitter of the node's own clock, not that of the state stream's
//! delivery, while the phase-locked loop keeps the states arriving about `margin` before the
//! cycle that uses them (the latency is the margin plus the cycle's work). A state that arrives
//! after its deadline is used by the next cycle; its phase error is taken modulo the period, so
//! a late state pulls the slots later, not a period earlier.

/// Fraction of a stream state's phase error (arrival − slot centre) applied to the next slot.
pub const PHASE_GAIN: f64 = 0.125;
/// Largest phase correction per cycle, as a fraction of the period (bounds the period jitter
/// the phase-locked loop itself adds).
pub const MAX_CORRECTION: f64 = 0.05;
/// The correction budget at start and at most, in periods.
pub const BUDGET_CAPACITY: f64 = 1.0;
/// The budget's refill per cycle, in periods: the long-run rate deviation the corrections may add.
pub const BUDGET_REFILL: f64 = 0.002;

/// What started a cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trigger {
    /// A fresh state arrived while the loop waited for it, at this time (CLOCK_MONOTONIC ns).
    StateArrived(u64),
    /// A fresh state was already waiting when the slot opened; it had arrived at this time.
    StateWaiting(u64),
    /// The slot ended without a fresh state.
    Watchdog,
    /// The loop runs on the slot centres alone, not aligned to the states (`--trigger clock`:
    /// a fixed-deadline loop, kept for comparison and for bodies that send no states).
    Clock,
    /// The cycle started at its slot's phase-locked deadline (`--trigger deadline`); with the
    /// arrival time of the fresh state it found, None when none had come.
    Deadline(Option<u64>),
}

/// The slot grid of the control loop (pure arithmetic on CLOCK_MONOTONIC nanoseconds; the
/// loop does the waiting).
#[derive(Debug, Clone)]
pub struct SlotSchedule {
    period_ns: u64,
    centre_ns: u64,
    /// What the phase corrections may still move the slots, ns.
    budget_ns: f64,
}

impl SlotSchedule {
    /// The first slot is centred one period after `now_ns`.
    pub fn new(period_ns: u64, now_ns: u64) -> Self {
        Self {
            period_ns,
            centre_ns: now_ns + period_ns,
            budget_ns: period_ns as f64 * BUDGET_CAPACITY,
        }
    }

    pub fn centre_ns(&self) -> u64 {
        self.centre_ns
    }

    /// The earliest start of the current slot's cycle.
    pub fn open_ns(&self) -> u64 {
        self.centre_ns - self.period_ns / 2
    }

    /// The watchdog: the current slot's cycle starts here at the latest.
    pub fn close_ns(&self) -> u64 {
        self.centre_ns + self.period_ns - self.period_ns / 2
    }

    /// The start of the current slot's cycle with a phase-locked deadline `margin_ns` after the
    /// slot's centre (`margin_ns` below half a period).
    pub fn deadline_ns(&self, margin_ns: u64) -> u64 {
        self.centre_ns + margin_ns.min(self.period_ns / 2)
    }

    /// The phase correction a cycle started by `trigger` asks of the next slot's centre
    /// (before the budget): a fraction of the state's arrival − the slot's centre, bounded.
    pub fn correction_ns(&self, trigger: Trigger) -> i64 {
        let error = match trigger {
            Trigger::StateArrived(arrival) | Trigger::StateWaiting(arrival) => {
                arrival as i64 - self.centre_ns as i64
            }
            // Modulo the period: a state that missed its deadline shows up in the next slot,
            // a period before that slot's centre plus its delay.
            Trigger::Deadline(Some(arrival)) => {
                let period = self.period_ns as i64;
                (arrival as i64 - self.centre_ns as i64 + period / 2).rem_euclid(period)
                    - period / 2
            }
            Trigger::Deadline(None) | Trigger::Watchdog | Trigger::Clock => return 0,
        };
        let limit = (self.period_ns as f64 * MAX_CORRECTION) as i64;
        ((error as f64 * PHASE_GAIN) as i64).clamp(-limit, limit)
    }

    /// The current slot's cycle was started by `trigger` and its work ended at `now_ns`: moves
    /// to the next slot, skipping every slot that has already closed (their states are stale
    /// by then; running them back to back would only queue stale commands). Returns the number
    /// of slots skipped.
    pub fn advance(&mut self, trigger: Trigger, now_ns: u64) -> u64 {
        let wanted = self.correction_ns(trigger);
        let allowed = self.budget_ns.max(0.0) as i64;
        let correction = wanted.clamp(-allowed, allowed);
        let capacity = self.period_ns as f64 * BUDGET_CAPACITY;
        self.budget_ns = (self.budget_ns - correction.unsigned_abs() as f64
            + self.period_ns as f64 * BUDGET_REFILL)
            .min(capacity);
        self.centre_ns = (self.centre_ns + self.period_ns).saturating_add_signed(correction);
        let mut skipped = 0;
        if self.close_ns() <= now_ns {
            skipped = (now_ns - self.close_ns()) / self.period_ns + 1;
            self.centre_ns += skipped * self.period_ns;
        }
        skipped
    }
}

/// Phases of a state stream within a period of `period` ns that the tests start from: the
/// edges, the middle and both sides of it.
#[cfg(test)]
fn stream_phases(period: u64) -> [u64; 8] {
    [
        0,
        period / 10,
        period / 3,
        period / 2,
        period / 2 + 1,
        2 * period / 3,
        9 * period / 10,
        period - 1,
    ]
}

/// `count` state arrivals, one per `period` at `phase` (ns), those after the `settled`-th
/// shifted by `jitter[k % jitter.len()]` (a deterministic delivery jitter).
#[cfg(test)]
fn jittered_stream(count: u64, period: u64, phase: u64, settled: u64, jitter: &[i64]) -> Vec<u64> {
    (0..count)
        .map(|k| {
            let offset = if k > settled {
                jitter[k as usize % jitter.len()]
            } else {
                0
            };
            (k * period + phase).saturating_add_signed(offset)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: u64 = 1_000_000;

    /// One simulated cycle: its start, trigger, the index of the state it used (None: no fresh
    /// one) and its slot's centre.
    type Cycle = (u64, Trigger, Option<usize>, u64);

    /// Runs the schedule against a body whose states arrive at `arrivals` (sorted, ns), with
    /// `work_ns` per cycle; returns (cycle start, trigger, state used) for each cycle until
    /// `end_ns`. `answer_after`: a body in lockstep answers each command after this long.
    fn simulate(
        arrivals: &[u64],
        answer_after: Option<u64>,
        work_ns: u64,
        end_ns: u64,
    ) -> Vec<Cycle> {
        let mut schedule = SlotSchedule::new(T, 0);
        let mut arrivals: Vec<u64> = arrivals.to_vec();
        let mut used: Option<usize> = None;
        let mut cycles = Vec::new();
        loop {
            let open = schedule.open_ns();
            let close = schedule.close_ns();
            if open >= end_ns {
                return cycles;
            }
            // The newest state that has arrived by `t` and is newer than the one used.
            let fresh_by = |t: u64, arrivals: &[u64]| {
                arrivals
                    .iter()
                    .rposition(|&a| a <= t)
                    .filter(|&i| used.is_none_or(|u| i > u))
            };
            let (start, trigger, state) = if let Some(i) = fresh_by(open, &arrivals) {
                (open, Trigger::StateWaiting(arrivals[i]), Some(i))
            } else if let Some(i) = arrivals
                .iter()
                .position(|&a| a > open && a < close)
                .filter(|&i| used.is_none_or(|u| i > u))
            {
                (arrivals[i], Trigger::StateArrived(arrivals[i]), Some(i))
            } else {
                (close, Trigger::Watchdog, None)
            };
            if state.is_some() {
                used = state;
            }
            cycles.push((start, trigger, state, schedule.centre_ns()));
            let done = start + work_ns;
            if let Some(delay) = answer_after {
                arrivals.push(done + delay);
            }
            schedule.advance(trigger, done);
        }
    }

    #[test]
    fn a_paced_stream_at_any_phase_ends_up_triggering_every_cycle_in_mid_slot() {
        for phase in stream_phases(T) {
            let arrivals: Vec<u64> = (0..420).map(|k| k * T + phase).collect();
            let cycles = simulate(&arrivals, None, 50_000, 400 * T);
            let settled = &cycles[100..];
            assert!(
                settled
                    .iter()
                    .all(|(start, trigger, _, _)| *trigger == Trigger::StateArrived(*start)),
                "phase {phase}: every settled cycle starts at its state's arrival"
            );
            // The arrivals end up in the middle of their slots: a jitter of almost T/2 either
            // way would still trigger the right cycle.
            for (start, _, _, centre) in &cycles[300..] {
                let error = start.abs_diff(*centre);
                assert!(error < T / 50, "phase {phase}: {error} ns off centre");
            }
            let periods: Vec<u64> = settled.windows(2).map(|w| w[1].0 - w[0].0).collect();
            assert!(
                periods.iter().all(|&p| p == T),
                "phase {phase}: the stream's period"
            );
        }
    }

    #[test]
    fn a_lockstep_body_cannot_speed_the_loop_up_beyond_the_correction_budget() {
        // The body answers 20 µs after each command: its state is always waiting at the
        // opening and pulls the slots earlier, but only as far as the budget allows.
        let n = 5_000u64;
        let cycles = simulate(&[], Some(20_000), 300_000, n * T);
        assert!(cycles[2..]
            .iter()
            .all(|(_, trigger, _, _)| matches!(trigger, Trigger::StateWaiting(_))));
        let span = cycles.last().unwrap().0 - cycles[2].0;
        let periods = (cycles.len() - 3) as f64;
        // The whole run gains at most the start budget plus the refill per cycle.
        let gained = periods * T as f64 - span as f64;
        assert!(gained >= 0.0, "the loop does not slow down either");
        assert!(
            gained <= T as f64 * BUDGET_CAPACITY + periods * T as f64 * BUDGET_REFILL + 1.0,
            "{gained} ns gained over {periods} periods"
        );
        // Each period stays within the per-cycle bound.
        assert!(cycles[2..].windows(2).all(|w| {
            let p = w[1].0 - w[0].0;
            p <= T && p as f64 >= T as f64 * (1.0 - MAX_CORRECTION) - 1.0
        }));
    }

    #[test]
    fn a_late_or_silent_body_meets_the_watchdog_at_the_slot_end() {
        // States every period, then silence from 100 T on.
        let arrivals: Vec<u64> = (0..100).map(|k| k * T + T / 4).collect();
        let cycles = simulate(&arrivals, None, 10_000, 150 * T);
        let silent: Vec<_> = cycles.iter().filter(|c| c.0 > 101 * T).collect();
        assert!(silent.len() >= 45);
        assert!(silent
            .iter()
            .all(|(_, trigger, state, _)| { *trigger == Trigger::Watchdog && state.is_none() }));
        assert!(silent.windows(2).all(|w| w[1].0 - w[0].0 == T));
    }

    #[test]
    fn jitter_within_half_a_period_still_triggers_each_cycle_by_its_own_state() {
        // A settled stream whose states come up to 0.4 T early or late (deterministic pattern).
        let jitter = [
            0i64, 400_000, -400_000, 150_000, -250_000, 399_000, -399_000,
        ];
        let arrivals = jittered_stream(600, T, T / 3, 200, &jitter);
        let cycles = simulate(&arrivals, None, 50_000, 600 * T);
        let late: Vec<_> = cycles.iter().filter(|c| c.0 > 210 * T).collect();
        let triggered = late
            .iter()
            .filter(|(start, trigger, _, _)| *trigger == Trigger::StateArrived(*start))
            .count();
        // The PLL follows the jitter a little (±5 % of T a cycle), so an edge case may slip;
        // almost every cycle still starts at its own state.
        assert!(
            triggered * 100 >= late.len() * 95,
            "{triggered} of {}",
            late.len()
        );
    }

    #[test]
    fn an_overrun_skips_the_slots_that_closed_meanwhile() {
        let mut schedule = SlotSchedule::new(T, 0);
        assert_eq!(
            (schedule.open_ns(), schedule.close_ns()),
            (T / 2, 3 * T / 2)
        );
        // The first cycle's work ends 3.2 periods later: slots 2, 3 and 4 have closed.
        let skipped = schedule.advance(Trigger::Watchdog, T + 3 * T + T / 5);
        assert_eq!(skipped, 2);
        assert_eq!(schedule.centre_ns(), 4 * T);
        assert!(schedule.open_ns() < 4 * T + T / 5 && 4 * T + T / 5 < schedule.close_ns());
    }

    #[test]
    fn corrections_are_bounded_and_follow_the_states_only() {
        let schedule = SlotSchedule::new(T, 0);
        let centre = schedule.centre_ns();
        assert_eq!(schedule.correction_ns(Trigger::Watchdog), 0);
        assert_eq!(schedule.correction_ns(Trigger::Clock), 0);
        assert_eq!(
            schedule.correction_ns(Trigger::StateWaiting(centre - 3 * T / 4)),
            -50_000,
            "a state waiting at the opening pulls the slots earlier"
        );
        assert_eq!(
            schedule.correction_ns(Trigger::StateArrived(centre + 80_000)),
            10_000
        );
        assert_eq!(
            schedule.correction_ns(Trigger::StateArrived(centre + T / 2)),
            50_000
        );
        assert_eq!(
            schedule.correction_ns(Trigger::StateArrived(centre - T / 2)),
            -50_000
        );
    }
}

#[cfg(test)]
mod deadline_tests {
    use super::*;

    const T: u64 = 1_000_000;
    const MARGIN: u64 = T / 4;

    /// One cycle of a phase-locked deadline loop: its start and the index of the fresh state it
    /// used (None: no fresh one had arrived).
    type Cycle = (u64, Option<usize>);

    /// Runs the deadline loop against states arriving at `arrivals` (sorted, ns), `work_ns`
    /// per cycle, until `end_ns`.
    fn simulate(arrivals: &[u64], work_ns: u64, end_ns: u64) -> Vec<Cycle> {
        let mut schedule = SlotSchedule::new(T, 0);
        let mut used: Option<usize> = None;
        let mut cycles = Vec::new();
        loop {
            let start = schedule.deadline_ns(MARGIN);
            if start >= end_ns {
                return cycles;
            }
            let fresh = arrivals
                .iter()
                .rposition(|&a| a <= start)
                .filter(|&i| used.is_none_or(|u| i > u));
            if fresh.is_some() {
                used = fresh;
            }
            cycles.push((start, fresh));
            schedule.advance(
                Trigger::Deadline(fresh.map(|i| arrivals[i])),
                start + work_ns,
            );
        }
    }

    fn settled_delays(cycles: &[Cycle], arrivals: &[u64]) -> Vec<u64> {
        cycles
            .iter()
            .map(|&(start, state)| start - arrivals[state.expect("a fresh state every cycle")])
            .collect()
    }

    #[test]
    fn a_paced_stream_at_any_phase_is_used_a_margin_after_its_arrival_every_period() {
        for phase in stream_phases(T) {
            let arrivals: Vec<u64> = (0..620).map(|k| k * T + phase).collect();
            let cycles = simulate(&arrivals, 300_000, 600 * T);
            let settled = &cycles[300..];
            for delay in settled_delays(settled, &arrivals) {
                assert!(
                    delay.abs_diff(MARGIN) < T / 50,
                    "phase {phase}: delay {delay} ns"
                );
            }
            // One state per cycle, each used once.
            assert!(settled
                .windows(2)
                .all(|w| w[1].1.zip(w[0].1).is_some_and(|(b, a)| b == a + 1)));
            assert!(settled.windows(2).all(|w| w[1].0 - w[0].0 == T));
        }
    }

    #[test]
    fn a_jittery_stream_jitters_the_periods_of_state_arrival_cycles_but_not_the_deadlines() {
        // Settled at T/3, then up to ±0.2 T of delivery jitter (deterministic pattern).
        let jitter = [
            0i64, 200_000, -200_000, 150_000, -120_000, 180_000, -190_000,
        ];
        let arrivals = jittered_stream(820, T, T / 3, 300, &jitter);
        let cycles = simulate(&arrivals, 50_000, 800 * T);
        let jittery: Vec<_> = cycles.iter().filter(|c| c.0 > 320 * T).copied().collect();
        let worst = jittery
            .windows(2)
            .map(|w| (w[1].0 - w[0].0).abs_diff(T))
            .max()
            .unwrap();
        // The loop follows the jitter by the PLL's bounded correction only.
        assert!(
            worst <= (T as f64 * MAX_CORRECTION) as u64,
            "period jitter {worst} ns"
        );
        // Every state still arrives before the deadline of its own cycle.
        assert!(jittery.iter().all(|c| c.1.is_some()));
        let delays = settled_delays(&jittery, &arrivals);
        assert!(delays.iter().all(|&d| d < MARGIN + T / 4));
        // Cycles started by the arrivals themselves would have the stream's full jitter.
        let stream = jittery
            .windows(2)
            .map(|w| {
                let (a, b) = (arrivals[w[0].1.unwrap()], arrivals[w[1].1.unwrap()]);
                (b - a).abs_diff(T)
            })
            .max()
            .unwrap();
        assert!(stream >= 350_000, "stream jitter {stream} ns");
    }

    #[test]
    fn a_stream_that_starts_missing_its_deadlines_is_locked_again_a_margin_before_them() {
        // Locked at phase T/3, then the stream arrives 0.4 T later for good: after the margin of
        // T/4, so each state first meets the next cycle.
        let arrivals: Vec<u64> = (0..820u64)
            .map(|k| k * T + T / 3 + if k >= 300 { 2 * T / 5 } else { 0 })
            .collect();
        let cycles = simulate(&arrivals, 50_000, 800 * T);
        let relocked: Vec<_> = cycles.iter().filter(|c| c.0 > 500 * T).copied().collect();
        for delay in settled_delays(&relocked, &arrivals) {
            assert!(delay.abs_diff(MARGIN) < T / 50, "delay {delay} ns");
        }
    }

    #[test]
    fn a_deadline_cycle_takes_the_phase_error_modulo_the_period() {
        let schedule = SlotSchedule::new(T, 0);
        let centre = schedule.centre_ns();
        assert_eq!(schedule.deadline_ns(MARGIN), centre + MARGIN);
        assert_eq!(
            schedule.deadline_ns(T),
            centre + T / 2,
            "at most half a period"
        );
        // A state of the previous slot that arrived 0.3 T after its centre, after that cycle's
        // deadline: late, so the slots move later (a slot-start trigger would move them earlier).
        let late = centre - T + 3 * T / 10;
        assert_eq!(
            schedule.correction_ns(Trigger::Deadline(Some(late))),
            37_500
        );
        assert_eq!(schedule.correction_ns(Trigger::StateWaiting(late)), -50_000);
        assert_eq!(
            schedule.correction_ns(Trigger::Deadline(Some(centre - 80_000))),
            -10_000
        );
        assert_eq!(schedule.correction_ns(Trigger::Deadline(None)), 0);
    }
}

#[cfg(test)]
mod budget_tests {
    use super::*;

    #[test]
    fn the_budget_limits_the_total_correction_and_refills_slowly() {
        const T: u64 = 1_000_000;
        let mut schedule = SlotSchedule::new(T, 0);
        let mut moved = 0i64;
        for _ in 0..100 {
            let before = schedule.centre_ns();
            // A state always far ahead of the centre asks for the largest correction.
            let arrival = schedule.centre_ns() + T / 2 - 1;
            schedule.advance(Trigger::StateArrived(arrival), schedule.open_ns());
            moved += schedule.centre_ns() as i64 - before as i64 - T as i64;
        }
        let allowed = T as f64 * (BUDGET_CAPACITY + 100.0 * BUDGET_REFILL);
        assert!(
            moved as f64 <= allowed + 1.0,
            "{moved} ns moved, {allowed} allowed"
        );
        assert!(moved as f64 >= allowed - 2.0 * T as f64 * MAX_CORRECTION);
    }
}
