//! In-process episodes (lockstep, no IPC): the simulated arm driven by a gain table through
//! the one controller law of `ur5_shared::law` and the one action clamp of
//! `ur5_shared::safety`, exactly what the real-time loop executes.

use hil_sim::{SimError, Ur5Sim};
use ur5_shared::config::TaskConfig;
use ur5_shared::layout::{DU, DX};
use ur5_shared::noise::Noise;
use ur5_shared::safety::clamp_action;
use ur5_shared::{controller_action, GainTable, NO_NOISE};

/// One episode: T states and the T actions taken in them.
#[derive(Clone, Debug, PartialEq)]
pub struct Episode {
    /// States s_0 … s_{T−1}, (T, dX) row-major.
    pub x: Vec<f64>,
    /// Actions as executed by the arm (after the clamp), (T, dU) row-major. The dynamics are
    /// fitted on these.
    pub u: Vec<f64>,
    /// Actions the controller law asked for (before the clamp), (T, dU).
    pub u_policy: Vec<f64>,
    /// The exploration noise ε drawn at each step (zeros for a noise-free episode), (T, dU).
    pub eps: Vec<f64>,
    /// Whether exploration noise was on.
    pub noisy: bool,
}

impl Episode {
    /// Horizon T.
    pub fn horizon(&self) -> usize {
        self.x.len() / DX
    }

    /// State at step t.
    pub fn state(&self, t: usize) -> [f64; DX] {
        self.x[t * DX..(t + 1) * DX].try_into().expect("dX")
    }

    /// Task cost C(τ) of the episode (`ur5_shared::cost`).
    pub fn task_cost(&self) -> f64 {
        let states: Vec<[f64; DX]> = (0..self.horizon()).map(|t| self.state(t)).collect();
        ur5_shared::cost::task_cost_from_states(&states).unwrap_or(f64::INFINITY)
    }

    /// Final end-effector distance to the goal (m).
    pub fn final_distance(&self) -> f64 {
        let s = self.state(self.horizon() - 1);
        let e = &s[ur5_shared::layout::EE_MINUS_GOAL];
        (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt()
    }
}

/// Runs one episode of `task.horizon` steps from `task.start_q` towards `task.goal`, drawing
/// ε ~ N(0, I) from `noise` when it is given (otherwise ε = 0). Seed the noise with
/// `Noise::new(run_seed, table.version, k)` for the k-th noisy episode of a table, as the
/// real-time loop does, and the episode matches the one run over IPC.
pub fn run_episode(
    sim: &mut Ur5Sim,
    task: &TaskConfig,
    table: &GainTable,
    mut noise: Option<&mut Noise>,
) -> Result<Episode, SimError> {
    let horizon = task.horizon.min(table.horizon());
    let limits = sim.limits();
    let mode = sim.config().mode;
    let mut obs = sim.reset(task.start_q, task.goal)?;
    let mut ep = Episode {
        x: Vec::with_capacity(horizon * DX),
        u: Vec::with_capacity(horizon * DU),
        u_policy: Vec::with_capacity(horizon * DU),
        eps: Vec::with_capacity(horizon * DU),
        noisy: noise.is_some(),
    };
    for t in 0..horizon {
        let s = obs.state(&task.goal);
        let eps = match noise.as_deref_mut() {
            Some(n) => n.next(),
            None => NO_NOISE,
        };
        let mut a = [0.0; DU];
        controller_action(table, t, &s, &eps, &mut a).expect("t < horizon");
        ep.u_policy.extend_from_slice(&a);
        clamp_action(mode, &limits, task.dt, &obs.q, &mut a);
        ep.x.extend_from_slice(&s);
        ep.u.extend_from_slice(&a);
        ep.eps.extend_from_slice(&eps);
        obs = sim.step(a);
    }
    Ok(ep)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ur5_shared::config::SimConfig;
    use ur5_shared::GainStep;

    /// A constant-goal table a = â_t = `goal_q` with covariance σ² I.
    fn hold_table(task: &TaskConfig, goal_q: [f64; DU], sigma: f64) -> Box<GainTable> {
        let mut table = GainTable::new_boxed();
        table.set_horizon(task.horizon).unwrap();
        for t in 0..task.horizon {
            let mut step = GainStep::default();
            step.a_hat = goal_q;
            for j in 0..DU {
                step.chol[j][j] = sigma;
            }
            table.set_step(t, &step);
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
        let mut sim = Ur5Sim::new(SimConfig::default(), task.dt).unwrap();
        let table = hold_table(&task, task.start_q, 0.2);
        let ep = run_episode(&mut sim, &task, &table, None).unwrap();
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
        let a = run_episode(&mut sim, &task, &table, Some(&mut r1)).unwrap();
        let b = run_episode(&mut sim, &task, &table, Some(&mut r2)).unwrap();
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
