//! The host clock every timestamp in the IPC payloads uses (docs/design.md §3.2, §3.5, [`crate::msg`]):
//! `CLOCK_MONOTONIC` in nanoseconds, so stamps written by the arm, the controller and the
//! learner are comparable. Neither function allocates.

/// Now, `CLOCK_MONOTONIC`, in ns.
#[inline]
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleeps until the absolute `CLOCK_MONOTONIC` time `deadline_ns` (`clock_nanosleep` with
/// `TIMER_ABSTIME`, resumed after signals). Returns at once if the deadline has passed. This is
/// the only blocking call the real-time loops make: an absolute deadline does not drift with the
/// time spent computing, unlike a relative sleep.
#[inline]
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: `ts` is a valid timespec; the remainder pointer may be null with TIMER_ABSTIME.
        let r = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                core::ptr::null_mut(),
            )
        };
        if r != libc::EINTR {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_and_sleeps_to_the_deadline() {
        let a = monotonic_ns();
        sleep_until_ns(a + 2_000_000);
        let b = monotonic_ns();
        assert!(b >= a + 2_000_000, "woke {} ns early", a + 2_000_000 - b);
        // A past deadline returns at once (no assertion on how fast: loaded CI machines).
        sleep_until_ns(a);
    }
}
