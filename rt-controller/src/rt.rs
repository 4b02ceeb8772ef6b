//! Optional real-time privileges for the loop thread: `mlockall`, `SCHED_FIFO`, CPU pinning.
//! Each is attempted only when configured; when the system refuses (no `CAP_SYS_NICE`, memlock
//! rlimit, a container), the loop runs without it and the outcome is logged and reported.

use serde::Serialize;

use crate::config::RtSetup;

/// What was asked for and what was obtained; `None` = not asked for.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct RtOutcome {
    /// `mlockall` succeeded.
    pub mlockall: Option<bool>,
    /// `SCHED_FIFO` at the configured priority succeeded.
    pub sched_fifo: Option<bool>,
    /// Pinning to the configured CPU succeeded.
    pub cpu_pinned: Option<bool>,
    /// Messages for every refusal (errno text and what to change).
    pub notes: Vec<String>,
}

fn errno_text() -> String {
    std::io::Error::last_os_error().to_string()
}

/// Applies `cfg` to the calling thread (setup phase; allocates). Logs each fallback on stderr.
pub fn apply(cfg: &RtSetup) -> RtOutcome {
    let mut out = RtOutcome::default();
    if cfg.mlockall {
        // SAFETY: plain syscall with constant flags.
        let ok = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } == 0;
        if !ok {
            out.notes.push(format!(
                "mlockall failed ({}); continuing without locked memory (raise `ulimit -l` or grant CAP_IPC_LOCK)",
                errno_text()
            ));
        }
        out.mlockall = Some(ok);
    }
    if cfg.fifo_priority > 0 {
        let param = libc::sched_param {
            sched_priority: cfg.fifo_priority,
        };
        // SAFETY: pid 0 = this thread; `param` is valid.
        let ok = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } == 0;
        if !ok {
            out.notes.push(format!(
                "SCHED_FIFO priority {} refused ({}); continuing with the normal scheduler (run as root, grant CAP_SYS_NICE or set `ulimit -r`)",
                cfg.fifo_priority,
                errno_text()
            ));
        }
        out.sched_fifo = Some(ok);
    }
    if let Some(cpu) = cfg.cpu {
        // SAFETY: cpu_set_t is plain data; CPU_SET writes inside it; pid 0 = this thread.
        let ok = unsafe {
            let mut set: libc::cpu_set_t = core::mem::zeroed();
            if cpu < 8 * core::mem::size_of::<libc::cpu_set_t>() {
                libc::CPU_SET(cpu, &mut set);
                libc::sched_setaffinity(0, core::mem::size_of::<libc::cpu_set_t>(), &set) == 0
            } else {
                false
            }
        };
        if !ok {
            out.notes.push(format!(
                "pinning to CPU {cpu} failed ({}); the loop may migrate between CPUs",
                errno_text()
            ));
        }
        out.cpu_pinned = Some(ok);
    }
    for n in &out.notes {
        eprintln!("rt-controller: {n}");
    }
    out
}
