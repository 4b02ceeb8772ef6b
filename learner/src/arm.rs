//! The in-process arm: hil-sim's simulated UR5 as an [`imitation::rollout::Arm`], so the
//! learners' one episode loop (`imitation::rollout::run_episode`) runs on it in lockstep, no
//! IPC, through the same controller law, action clamp and noise as the real-time loop. As an
//! [`Arms`] source it gives every episode of an iteration a fresh copy of itself, so that the
//! episodes can run in parallel (docs/design.md §5 D29).

use hil_sim::{SimError, Ur5Sim};
use imitation::rollout::{Arm, Arms};
use imitation::ImitationError;
use ur5_shared::config::{ActionMode, ArmLimits, SimConfig, TaskConfig};
use ur5_shared::layout::{StateLayout, MAX_JOINTS, MAX_TOOL_POINTS};

/// hil-sim's arm and the task of the episode it runs: its layout, tool points and their
/// targets.
pub struct SimArm {
    sim: Ur5Sim,
    layout: StateLayout,
    offsets: [[f64; 3]; MAX_TOOL_POINTS],
    targets: [[f64; 3]; MAX_TOOL_POINTS],
}

impl SimArm {
    /// The simulated arm of `cfg` at control period `dt` (s) with the wrist locked (three
    /// active joints).
    pub fn new(cfg: SimConfig, dt: f64) -> Result<Self, SimError> {
        Self::with_joints(cfg, dt, 3)
    }

    /// The simulated arm of `cfg` at control period `dt` (s) with `joints` active joints (3 or
    /// 6; `TaskConfig::joints`).
    pub fn with_joints(cfg: SimConfig, dt: f64, joints: usize) -> Result<Self, SimError> {
        Ok(Self::around(Ur5Sim::with_joints(cfg, dt, joints)?))
    }

    /// The simulated arm for `task` (its control period and active joints).
    pub fn for_task(cfg: SimConfig, task: &TaskConfig) -> Result<Self, SimError> {
        Self::with_joints(cfg, task.dt, task.joints)
    }

    fn around(sim: Ur5Sim) -> Self {
        Self {
            sim,
            layout: StateLayout::REACH3,
            offsets: [[0.0; 3]; MAX_TOOL_POINTS],
            targets: [[0.0; 3]; MAX_TOOL_POINTS],
        }
    }

    /// The simulator.
    pub fn sim(&self) -> &Ur5Sim {
        &self.sim
    }

    /// The simulator, to move its noise stream on a resume.
    pub fn sim_mut(&mut self) -> &mut Ur5Sim {
        &mut self.sim
    }

    /// The state of the arm now, in the layout of the last reset, into `s` (dX).
    fn observe(&mut self, s: &mut [f64]) {
        let (n, p) = (self.layout.joints(), self.layout.tool_points());
        let (mut q, mut qd) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
        let mut points = [[0.0; 3]; MAX_TOOL_POINTS];
        let mut velocities = [[0.0; 3]; MAX_TOOL_POINTS];
        self.sim.observe_points(
            &self.offsets[..p],
            &mut q[..n],
            &mut qd[..n],
            &mut points[..p],
            &mut velocities[..p],
        );
        self.layout.fill_state(
            &q[..n],
            &qd[..n],
            &points[..p],
            &velocities[..p],
            &self.targets[..p],
            s,
        );
    }
}

/// Episode k of version v under run seed s runs on a fresh copy of this arm (`Ur5Sim::fresh`)
/// whose perturbation noise is the stream `ur5_shared::noise::episode_seed(s, v, k)` of its
/// `perturbation.seed`.
impl Arms for SimArm {
    fn episode_arm(&self, seed: u64, version: u64, k: u64) -> Result<Box<dyn Arm>, ImitationError> {
        let mut sim = self.sim.fresh();
        sim.reseed(ur5_shared::noise::episode_seed(seed, version, k));
        Ok(Box::new(SimArm::around(sim)))
    }
}

impl Arm for SimArm {
    fn reset(&mut self, task: &TaskConfig, s: &mut [f64]) -> Result<(), ImitationError> {
        let layout = task.layout();
        if layout.joints() != self.sim.joints() {
            return Err(ImitationError::Arm(Box::new(SimError::Config(
                ur5_shared::config::ConfigError::Invalid {
                    key: "task.joints",
                    why: format!(
                        "the task moves {} joints, the simulated arm {}",
                        layout.joints(),
                        self.sim.joints()
                    ),
                },
            ))));
        }
        self.sim
            .restart(&task.start_q, task.goal)
            .map_err(|e| ImitationError::Arm(Box::new(e)))?;
        let p = layout.tool_points();
        self.layout = layout;
        self.offsets[..p].copy_from_slice(task.tool_offsets());
        self.targets[..p].copy_from_slice(&task.targets());
        self.observe(s);
        Ok(())
    }

    fn step(&mut self, a: &[f64], s: &mut [f64]) {
        self.sim.advance(a);
        self.observe(s);
    }

    fn mode(&self) -> ActionMode {
        self.sim.config().mode
    }

    fn limits(&self) -> ArmLimits {
        self.sim.limits()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use imitation::rollout::run_episode;
    use ur5_shared::config::{SimConfig, TaskConfig};
    use ur5_shared::noise::Noise;
    use ur5_shared::GainTable;

    /// A constant-goal table a = â_t = `goal_q` with covariance σ² I.
    fn hold_table(task: &TaskConfig, goal_q: &[f64], sigma: f64) -> Box<GainTable> {
        let mut table = GainTable::new_boxed();
        table.set_horizon(task.horizon).unwrap();
        for t in 0..task.horizon {
            let mut step = table.step_mut(t);
            step.a_hat.copy_from_slice(goal_q);
            for j in 0..goal_q.len() {
                step.set_l(j, j, sigma);
            }
        }
        table.seal();
        table
    }

    #[test]
    fn noise_free_hold_stays_and_seeded_noise_replays() {
        let task = TaskConfig {
            horizon: 20,
            ..TaskConfig::default()
        };
        let mut sim = SimArm::new(SimConfig::default(), task.dt).unwrap();
        let (dx, du) = (task.layout().dx(), task.layout().du());
        let mut table = hold_table(&task, &task.start_q, 0.2);
        let ep = run_episode(&mut sim, &task, &mut *table, None).unwrap();
        assert_eq!(ep.horizon(), 20);
        let last = ep.state(19);
        for j in 0..du {
            assert!(
                (last[j] - task.start_q[j]).abs() < 1e-3,
                "drifted: {last:?}"
            );
        }
        let mut r1 = Noise::new(9, 1, 0);
        let mut r2 = Noise::new(9, 1, 0);
        let a = run_episode(&mut sim, &task, &mut *table, Some(&mut r1)).unwrap();
        let b = run_episode(&mut sim, &task, &mut *table, Some(&mut r2)).unwrap();
        assert_eq!(a, b, "same seed, same episode");
        assert!(a.eps.iter().any(|e| *e != 0.0));
        // The clamp limits every executed goal to v_max · dt from the current angles.
        let step = std::f64::consts::PI * task.dt;
        for t in 0..20 {
            for j in 0..du {
                assert!((a.u[t * du + j] - a.x[t * dx + j]).abs() <= step + 1e-12);
            }
        }
    }
}
