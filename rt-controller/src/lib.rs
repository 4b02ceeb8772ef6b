//! rt-controller: the real-time loop of docs/design.md §3.4–§3.5. It executes the time-varying
//! linear-Gaussian controller a = K_t (s − ŝ_t) + k_t + â_t + L_t ε published by the learner
//! ([`ur5_shared::controller_action`], the one implementation of the law) on the arm over
//! iceoryx2, and publishes every step for the learner.
//!
//! - [`config`]: every option (TOML), with units;
//! - [`controller`]: [`Controller::setup`] (allocates, may fail) and [`Controller::run`] (the
//!   loop: no allocation, no locks, no blocking but the period wait), episodes, hot swap;
//! - [`tables`]: the double-buffered gain table; [`safety`]: faults, clamp and hold; [`noise`]:
//!   seeded exploration noise; [`stats`]: the loop's counters and allocation-free histograms;
//!   [`arm`]: the arm backends the loop is generic over (iceoryx2); [`ports`]: the node and the
//!   learner's iceoryx2 ports; [`rt`]: mlockall / SCHED_FIFO / pinning; [`monitor`]:
//!   dead-peer detection off the loop; [`latency`]: the period wait's wake-up lateness alone
//!   (`rt-controller bench --real-time`); [`live_view`]: goal, end-effector point, episode and
//!   table version on ROS 2 topics (`[live_view]`), through a DDS thread (`dds_thread`, shared
//!   with the `ros2` arm);
//! - `testkit` (cargo feature `testkit`, not part of the production API): in-process stand-ins
//!   for the arm and tables, for the integration tests and the binary's `bench` subcommand.
//!
//! Conventions (those of `ur5_shared`): SI units — rad, rad/s, m, m/s, N·m, s; timestamps are
//! `CLOCK_MONOTONIC` ns ([`ur5_shared::clock`]); Cartesian quantities in the arm base frame;
//! the state layout of [`ur5_shared::layout`]. The control period is `task.dt` of arm time;
//! in real time the wall period is `task.dt / time_compression`. Durations in statistics are
//! wall-clock ns.

pub mod arm;
pub mod config;
pub mod controller;
pub(crate) mod dds_thread;
pub mod error;
pub mod latency;
pub mod live_view;
pub mod monitor;
pub mod noise;
pub mod ports;
pub mod rt;
pub mod safety;
pub mod stats;
pub mod tables;
#[cfg(feature = "testkit")]
pub mod testkit;

pub use arm::{ArmBackend, Iceoryx2Arm, Ros2Arm, UrArm};
pub use config::{ControllerConfig, Mode, Pacing};
pub use controller::{Controller, ExitReason, Summary};
pub use ports::SetupError;
pub use safety::Fault;

use core::sync::atomic::{AtomicBool, Ordering};

/// Raised by SIGINT / SIGTERM once [`install_signal_handlers`] ran.
pub static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::Relaxed);
}

/// Routes SIGINT and SIGTERM to [`STOP`] (the loop then holds the arm, prints its summary and
/// returns). The iceoryx2 node is created with its own signal handling disabled.
pub fn install_signal_handlers() {
    for sig in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
        unsafe {
            let mut action: libc::sigaction = core::mem::zeroed();
            action.sa_sigaction = on_signal as *const () as usize;
            libc::sigemptyset(&mut action.sa_mask);
            libc::sigaction(sig, &action, core::ptr::null_mut());
        }
    }
}
