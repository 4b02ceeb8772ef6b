//! The `learner` application: the command line, in-process runs on hil-sim, the learner end of
//! the three-process system (`serve`), the experiments, files and plots. The algorithms are in
//! the two libraries below it: `gps` (trajectory optimisation) and `imitation` (the critic, the
//! costs, the expert, LQR+GAIfO, GAIfO (PPO)); docs/design.md §1 maps Algorithm 1 onto them.
//!
//! - [`arm`]: hil-sim's arm as the learners' `imitation::rollout::Arm`;
//! - [`run`]: in-process runs, their CSV and checkpoints, resuming; [`replay`]: a recorded
//!   run's learning done again and checked bit for bit;
//! - [`serve`]: `learner serve` over iceoryx2;
//! - [`experiment`]: `learner experiment` (in process; [`experiment::ipc`] over IPC);
//!   [`plot`]: their figures; [`stats`]: medians and quantiles; [`film`]: the arm reaching;
//! - [`io`]: `.npz` files (demonstrations, gain tables, episodes) and the CSV logs;
//! - [`process`]: spawned binaries of this build (IPC experiment, cross-process tests);
//!   [`progress`]: progress bar or plain lines of long commands;
//! - [`bench`]: `learner bench`, `learner bench-gaifo`;
//! - [`cli`]: the command line, one module per subcommand.

pub mod arm;
pub mod baselines;
pub mod bench;
pub mod cli;
pub mod error;
pub mod experiment;
pub mod film;
pub mod io;
pub mod playback;
pub mod plot;
pub mod plot_paths;
pub mod process;
pub mod progress;
pub mod record;
pub mod replay;
pub mod run;
pub mod serve;
pub mod stats;
