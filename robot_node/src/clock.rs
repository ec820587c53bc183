//! Time for the control loop: CLOCK_MONOTONIC nanoseconds, sleeping to absolute deadlines
//! (`clock_nanosleep` with TIMER_ABSTIME, so a late wake-up does not shift later deadlines),
//! and the real-time settings of a robot's control thread (SCHED_FIFO, mlockall).

/// Nanoseconds of CLOCK_MONOTONIC; the one clock of the loop, the inbox and the statistics.
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid out-pointer; CLOCK_MONOTONIC always exists on Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    if rc != 0 {
        // Cannot happen for CLOCK_MONOTONIC with a valid pointer; 0 keeps the caller total.
        return 0;
    }
    u64::try_from(ts.tv_sec).unwrap_or(0) * 1_000_000_000 + u64::try_from(ts.tv_nsec).unwrap_or(0)
}

/// Sleeps until CLOCK_MONOTONIC reaches `deadline_ns` (returns at once if it has passed).
pub fn sleep_until_ns(deadline_ns: u64) {
    let deadline = libc::timespec {
        tv_sec: libc::time_t::try_from(deadline_ns / 1_000_000_000).unwrap_or(libc::time_t::MAX),
        // < 1e9, fits every c_long.
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: valid timespec; no remaining-time pointer is needed with TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &deadline,
                std::ptr::null_mut(),
            )
        };
        // EINTR (a signal): sleep again to the same absolute deadline; anything else (EINVAL
        // cannot happen for a valid timespec) ends the wait rather than spinning.
        if rc != libc::EINTR {
            return;
        }
    }
}

/// Gives the calling thread SCHED_FIFO at `priority`; returns pthread_setschedparam's error
/// code (0: granted).
pub fn set_thread_fifo(priority: i32) -> i32 {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: pthread_self is always valid; `param` is a valid pointer.
    unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) }
}

/// What the real-time set-up achieved; reported in every status message.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RealtimeSettings {
    pub fifo_priority: bool,
    pub memory_locked: bool,
}

/// Gives the calling thread SCHED_FIFO at `priority` and locks the process's memory (current
/// and future pages, so the loop takes no page faults). Either may be refused (no
/// CAP_SYS_NICE / CAP_IPC_LOCK, RLIMIT_MEMLOCK, a container): the loop then runs with
/// ordinary scheduling, more jitter, and says so in the log and the status.
pub fn apply_realtime(priority: i32) -> RealtimeSettings {
    let rc = set_thread_fifo(priority);
    let fifo_priority = rc == 0;
    if fifo_priority {
        tracing::info!(priority, "control thread runs with SCHED_FIFO");
    } else {
        tracing::warn!(
            priority,
            error = %std::io::Error::from_raw_os_error(rc),
            "SCHED_FIFO refused: the control loop runs with ordinary scheduling (more jitter)"
        );
    }
    // SAFETY: mlockall has no memory-safety preconditions.
    let memory_locked = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } == 0;
    if memory_locked {
        tracing::info!("memory locked (mlockall)");
    } else {
        tracing::warn!(
            error = %std::io::Error::last_os_error(),
            "mlockall refused: page faults may delay the control loop"
        );
    }
    RealtimeSettings {
        fifo_priority,
        memory_locked,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sleeping_to_an_absolute_deadline_wakes_after_it_and_past_deadlines_return_at_once() {
        let start = now_ns();
        let deadline = start + 3_000_000;
        sleep_until_ns(deadline);
        let woke = now_ns();
        assert!(woke >= deadline, "woke {} ns early", deadline - woke);
        // Generous bound: a loaded 2-core machine may delay a wake-up, but not by 200 ms.
        assert!(
            woke - deadline < 200_000_000,
            "woke {} ns late",
            woke - deadline
        );
        let before = now_ns();
        sleep_until_ns(start);
        assert!(
            now_ns() - before < 50_000_000,
            "a past deadline must not block"
        );
    }
}
