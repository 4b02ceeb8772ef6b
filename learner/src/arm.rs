//! The in-process arm: hil-sim's simulated UR5 as an [`imitation::rollout::Arm`], so the
//! learners' one episode loop (`imitation::rollout::run_episode`) runs on it in lockstep, no
//! IPC, through the same controller law, action clamp and noise as the real-time loop. As an
//! [`Arms`] source it gives every episode of an iteration a fresh copy of itself, so that the
//! episodes can run in parallel (docs/design.md §5 D29).

use hil_sim::{SimError, Ur5Sim};
use imitation::rollout::{Arm, Arms};
use imitation::ImitationError;
use ur5_shared::config::{ActionMode, ArmLimits, SimConfig};
use ur5_shared::layout::{DU, DX};

/// hil-sim's arm and the goal of the episode it runs.
pub struct SimArm {
    sim: Ur5Sim,
    goal: [f64; 3],
}

impl SimArm {
    /// The simulated arm of `cfg` at control period `dt` (s).
    pub fn new(cfg: SimConfig, dt: f64) -> Result<Self, SimError> {
        Ok(Self {
            sim: Ur5Sim::new(cfg, dt)?,
            goal: [0.0; 3],
        })
    }

    /// The simulator.
    pub fn sim(&self) -> &Ur5Sim {
        &self.sim
    }

    /// The simulator, to move its noise stream on a resume.
    pub fn sim_mut(&mut self) -> &mut Ur5Sim {
        &mut self.sim
    }
}

/// Episode k of version v under run seed s runs on a fresh copy of this arm (`Ur5Sim::fresh`)
/// whose perturbation noise is the stream `ur5_shared::noise::episode_seed(s, v, k)` of its
/// `perturbation.seed`.
impl Arms for SimArm {
    fn episode_arm(&self, seed: u64, version: u64, k: u64) -> Result<Box<dyn Arm>, ImitationError> {
        let mut sim = self.sim.fresh();
        sim.reseed(ur5_shared::noise::episode_seed(seed, version, k));
        Ok(Box::new(SimArm {
            sim,
            goal: [0.0; 3],
        }))
    }
}

impl Arm for SimArm {
    fn reset(&mut self, start_q: [f64; DU], goal: [f64; 3]) -> Result<[f64; DX], ImitationError> {
        let obs = self
            .sim
            .reset(start_q, goal)
            .map_err(|e| ImitationError::Arm(Box::new(e)))?;
        self.goal = goal;
        Ok(obs.state(&goal))
    }

    fn step(&mut self, a: [f64; DU]) -> [f64; DX] {
        self.sim.step(a).state(&self.goal)
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
    use ur5_shared::layout::{DU, DX};
    use ur5_shared::noise::Noise;
    use ur5_shared::GainTable;

    /// A constant-goal table a = â_t = `goal_q` with covariance σ² I.
    fn hold_table(task: &TaskConfig, goal_q: [f64; DU], sigma: f64) -> Box<GainTable> {
        let mut table = GainTable::new_boxed();
        table.set_horizon(task.horizon).unwrap();
        for t in 0..task.horizon {
            let mut step = table.step_mut(t);
            step.a_hat.copy_from_slice(&goal_q);
            for j in 0..DU {
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
        let mut table = hold_table(&task, task.start_q, 0.2);
        let ep = run_episode(&mut sim, &task, &mut *table, None).unwrap();
        assert_eq!(ep.horizon(), 20);
        let last = ep.state(19);
        for j in 0..DU {
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
            for j in 0..DU {
                assert!((a.u[t * DU + j] - a.x[t * DX + j]).abs() <= step + 1e-12);
            }
        }
    }
}
