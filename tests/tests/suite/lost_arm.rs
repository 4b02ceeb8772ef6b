//! An arm that goes away ends the run with `ArmLost`, wherever the loop is when it goes
//!. `ur_a_stopped_ur_sim_gives_the_controller_a_clear_exit` stalled once in 20 runs:
//! when ur-sim closed the program's reverse socket before its RTDE connection, the controller's
//! next command (a reset, at an episode boundary) failed, a lockstep wait with no command
//! outstanding counted as fresh, and the reset was retried every `reset_timeout_s` for ever.
//! Here a stand-in arm dies at every command index of the first episodes (a reset, ticks,
//! the boundary), once with its send failing first and once with its receive failing first;
//! each run must end with `ArmLost` within a bound that only catches a hang.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use integration_tests::{cleanup_dead_nodes, reaching_table, TestLearner};
use rt_controller::arm::ArmIoError;
use rt_controller::config::Safety;
use rt_controller::{ArmBackend, Controller, ControllerConfig, ExitReason, Mode, SetupError};
use ur5_shared::services::unique_prefix;
use ur5_shared::{ArmCommand, ArmState, ArmStatus, CommandKind};

const HORIZON: usize = 5;

/// Which side of the connection fails first when the arm dies.
#[derive(Clone, Copy, Debug)]
enum Death {
    /// The command that dies is not sent (the reverse socket closed first).
    Send,
    /// The command is taken, but no state comes back (the state connection closed first).
    Receive,
}

/// A lockstep arm that answers each command with a state acknowledging it (goals reached at
/// once, resets teleport), until command `dies_at` (1-based).
struct DyingArm {
    state: ArmState,
    answer: Option<ArmState>,
    commands: u64,
    dies_at: u64,
    death: Death,
    lost: Option<&'static str>,
}

impl DyingArm {
    fn new(dies_at: u64, death: Death) -> Self {
        let state = ArmState {
            status: ArmStatus::READY,
            ..ArmState::of_joints(&[0.0, -1.57, 1.57], &[0.0; 3], [0.0; 3], [0.0; 3])
        };
        Self {
            state,
            answer: None,
            commands: 0,
            dies_at,
            death,
            lost: None,
        }
    }
}

impl ArmBackend for DyingArm {
    fn wait_ready(&mut self, _timeout_s: f64) -> Result<ArmState, SetupError> {
        Ok(self.state)
    }

    fn connect(&mut self) -> Result<(), SetupError> {
        Ok(())
    }

    fn receive(&mut self) -> Result<Option<ArmState>, ArmIoError> {
        if self.lost.is_some() {
            return Err(ArmIoError::Receive);
        }
        Ok(self.answer.take())
    }

    fn send(&mut self, cmd: &ArmCommand) -> Result<(), ArmIoError> {
        if self.lost.is_some() {
            return Err(ArmIoError::Send);
        }
        self.commands += 1;
        if self.commands >= self.dies_at {
            self.lost = Some("the stand-in arm closed its connection");
            return match self.death {
                Death::Send => Err(ArmIoError::Send),
                Death::Receive => Ok(()),
            };
        }
        match cmd.kind() {
            Ok(CommandKind::GoalAngles) => self.state.q = cmd.values,
            Ok(CommandKind::Reset) => self.state.q = cmd.reset_pose,
            _ => {}
        }
        self.state.seq += 1;
        self.state.last_command_seq = cmd.seq;
        self.state.episode = cmd.episode;
        self.answer = Some(self.state);
        Ok(())
    }

    fn lost(&self) -> Option<&'static str> {
        self.lost
    }
}

fn run_until_the_arm_dies(dies_at: u64, death: Death) {
    let prefix = unique_prefix("lost-arm");
    let learner = TestLearner::learner_only(&prefix);
    learner.publish(&reaching_table(1, HORIZON, [0.3, -1.2, 1.4], 0.01));
    let cfg = ControllerConfig {
        prefix: prefix.clone(),
        mode: Mode::Lockstep,
        episodes: 20,
        wait_for_learner: false,
        episode_report: false,
        safety: Safety {
            // Long enough that only the lost arm, not a stale wait, can end the run within
            // the bound below; give_up_after_s = 0 would wait for ever.
            stale_state_timeout_s: 0.3,
            give_up_after_s: 0.0,
            reset_timeout_s: 0.05,
            ..Safety::default()
        },
        task: ur5_shared::config::TaskConfig {
            horizon: HORIZON,
            ..Default::default()
        },
        ..ControllerConfig::default()
    };
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = mpsc::channel();
    let worker = {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            let mut c = Controller::setup_with(cfg, |_, _| Ok(DyingArm::new(dies_at, death)))
                .expect("setup");
            let reason = c.run(&stop);
            tx.send(()).ok();
            (reason, c.arm().commands, c.stats().episodes_completed)
        })
    };
    // The table reaches the controller when the publisher updates its connections. A hang
    // shows as `Stopped` (the test raises the stop flag); nothing asserts on timing.
    let t0 = Instant::now();
    while rx.try_recv().is_err() {
        if t0.elapsed() > Duration::from_secs(60) {
            stop.store(true, Ordering::Relaxed);
            break;
        }
        learner.poll_gains_only();
        std::thread::sleep(Duration::from_millis(1));
    }
    let (reason, commands, episodes) = worker.join().unwrap();
    assert_eq!(
        reason,
        ExitReason::ArmLost,
        "arm died ({death:?}) at command {dies_at}; {commands} commands, {episodes} episodes"
    );
    drop(learner);
}

#[test]
fn an_arm_lost_at_any_command_ends_the_run() {
    // Episode 0: a reset and HORIZON ticks; then the boundary's reset: every kind of command.
    for dies_at in 1..=(2 * (HORIZON as u64 + 1) + 1) {
        for death in [Death::Send, Death::Receive] {
            run_until_the_arm_dies(dies_at, death);
        }
    }
    cleanup_dead_nodes();
}
