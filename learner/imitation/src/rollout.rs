//! Step 1 of Algorithm 1 (docs/design.md §1): episodes of a policy on an arm. One episode loop,
//! [`run_episode`], over two traits: the [`Arm`] an episode runs on (the in-process simulator
//! in the `learner` application; a real arm streams its episodes over IPC instead) and the
//! [`Policy`] that picks the actions (a gain table through `ur5_shared::controller_action`, the
//! PPO baseline's Gaussian MLP). Every action goes through the one action clamp of
//! `ur5_shared::safety`, exactly what the real-time loop executes, and the exploration noise of
//! the k-th noisy episode of policy version v is `Noise::new(run seed, v, k)`, as in the
//! real-time loop, so an in-process episode equals the one run over IPC.
//!
//! The episodes of one iteration are independent, so [`run_episodes`] runs them in parallel on
//! the current rayon pool, each on its own arm from an [`Arms`] source and with its own actor:
//! the results do not depend on the thread count or the order (docs/design.md §5 D29).

use rayon::prelude::*;
use ur5_shared::config::{ActionMode, ArmLimits, TaskConfig};
use ur5_shared::layout::{StateLayout, MAX_DU};
use ur5_shared::noise::Noise;
use ur5_shared::safety::clamp_action;
use ur5_shared::{controller_action, GainTable};

use crate::ImitationError;

/// One episode: T states and the T actions taken in them, in the layout of its task.
#[derive(Clone, Debug, PartialEq)]
pub struct Episode {
    /// The task's state layout (dX, dU, where the joints and tool points are).
    pub layout: StateLayout,
    /// States s_0 … s_{T−1}, (T, dX) row-major.
    pub x: Vec<f64>,
    /// Actions as executed by the arm (after the clamp), (T, dU) row-major. The dynamics are
    /// fitted on these.
    pub u: Vec<f64>,
    /// Actions the policy asked for (before the clamp), (T, dU).
    pub u_policy: Vec<f64>,
    /// The exploration noise ε drawn at each step (zeros for a noise-free episode), (T, dU).
    pub eps: Vec<f64>,
    /// Whether exploration noise was on.
    pub noisy: bool,
}

impl Episode {
    /// Horizon T.
    pub fn horizon(&self) -> usize {
        self.x.len() / self.layout.dx()
    }

    /// State dimension dX.
    pub fn dx(&self) -> usize {
        self.layout.dx()
    }

    /// Action dimension dU.
    pub fn du(&self) -> usize {
        self.layout.du()
    }

    /// State at step t (dX).
    pub fn state(&self, t: usize) -> &[f64] {
        let dx = self.layout.dx();
        &self.x[t * dx..(t + 1) * dx]
    }

    /// State at step t of a three-joint point task (dX = 12) as an array, for code written
    /// for that task only (the precision probe example); panics on another layout.
    pub fn reach3_state(&self, t: usize) -> [f64; ur5_shared::layout::DX] {
        self.state(t)
            .try_into()
            .expect("a three-joint task's state")
    }

    /// Executed action at step t (dU).
    pub fn action(&self, t: usize) -> &[f64] {
        let du = self.layout.du();
        &self.u[t * du..(t + 1) * du]
    }

    /// Task cost C(τ) of the episode (`ur5_shared::cost`): of the tool points' distance to
    /// their targets.
    pub fn task_cost(&self) -> f64 {
        ur5_shared::cost::task_cost_of_states(&self.layout, &self.x).unwrap_or(f64::INFINITY)
    }

    /// Final distance of the tool centre point (the first tool point) to its goal (m).
    pub fn final_distance(&self) -> f64 {
        let s = self.state(self.horizon() - 1);
        let e = &s[self.layout.point(0)];
        (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt()
    }

    /// Final orientation error of the tool (rad, `ur5_shared::pose::orientation_error`) for
    /// the tool points' `targets` (m, base frame; `TaskConfig::targets`); `None` unless the
    /// task has a pose goal (three tool points).
    pub fn final_orientation_error(&self, targets: &[[f64; 3]]) -> Option<f64> {
        if self.layout.tool_points() != 3 || targets.len() != 3 {
            return None;
        }
        let s = self.state(self.horizon() - 1);
        let mut points = [[0.0; 3]; 3];
        let mut goals = [[0.0; 3]; 3];
        for i in 0..3 {
            let e = &s[self.layout.point(i)];
            goals[i] = targets[i];
            points[i] = [
                e[0] + targets[i][0],
                e[1] + targets[i][1],
                e[2] + targets[i][2],
            ];
        }
        ur5_shared::pose::orientation_error(&points, &goals)
    }
}

/// GPS's sample arrays of N episodes of one policy: `x (N, T, dX)`, `u (N, T, dU)` row-major
/// (GPS `SampleList.get_X()`, `get_U()`).
pub struct SampleList {
    /// States, (N, T, dX).
    pub x: Vec<f64>,
    /// Executed actions, (N, T, dU).
    pub u: Vec<f64>,
    /// Number of episodes N.
    pub n: usize,
}

impl SampleList {
    /// Stacks `episodes` (all of one horizon).
    pub fn new(episodes: &[Episode]) -> Self {
        Self {
            x: episodes.iter().flat_map(|e| e.x.iter().copied()).collect(),
            u: episodes.iter().flat_map(|e| e.u.iter().copied()).collect(),
            n: episodes.len(),
        }
    }
}

/// An arm an episode runs on, one control period (`TaskConfig::dt`) per [`Arm::step`].
pub trait Arm {
    /// Puts the arm at rest at the task's start pose (`task.start_q`, rad) with the tool
    /// points' targets of its goal (`TaskConfig::targets`) and writes the state s_0 (layout
    /// `task.layout()`) into `s`.
    fn reset(&mut self, task: &TaskConfig, s: &mut [f64]) -> Result<(), ImitationError>;
    /// Executes action `a` (dU, already clamped) for one control period; writes the next
    /// state into `s` (dX).
    fn step(&mut self, a: &[f64], s: &mut [f64]);
    /// What actions are (goal joint angles or torques).
    fn mode(&self) -> ActionMode;
    /// The limits the action clamp enforces.
    fn limits(&self) -> ArmLimits;
}

/// Where the episodes of an iteration run: a new arm per episode, so that episodes are
/// independent of each other and of the order they run in (docs/design.md §5 D29).
pub trait Arms: Sync {
    /// The arm episode `k` of policy version `version` under run seed `seed` runs on, as
    /// built; its own random streams (a perturbed arm's noise) are derived from the three.
    fn episode_arm(&self, seed: u64, version: u64, k: u64) -> Result<Box<dyn Arm>, ImitationError>;
}

/// A policy that several episodes can run at once: each gets its own [`Policy`] (its own
/// scratch memory), all acting alike.
pub trait Actors: Sync {
    /// A new actor.
    fn actor(&self) -> Box<dyn Policy + '_>;
}

/// What picks the actions of an episode.
pub trait Policy {
    /// Steps the policy can act for (a gain table's horizon).
    fn horizon(&self) -> usize;
    /// Writes into `a` (dU) the action (before the clamp) at step `t` in state `s` (dX) with
    /// exploration noise `eps` (dU; zeros for a noise-free episode) on an arm whose actions
    /// are `mode`.
    fn act(&mut self, t: usize, s: &[f64], eps: &[f64], mode: ActionMode, a: &mut [f64]);
}

/// A gain table as a policy: the controller law a = K_t (s − ŝ_t) + k_t + â_t + L_t ε of
/// `ur5_shared::controller_action`, the real-time loop's.
impl Policy for &GainTable {
    fn horizon(&self) -> usize {
        GainTable::horizon(self)
    }

    fn act(&mut self, t: usize, s: &[f64], eps: &[f64], _: ActionMode, a: &mut [f64]) {
        controller_action(self, t, s, eps, a).expect("t < horizon, the table's dims");
    }
}

impl Policy for GainTable {
    fn horizon(&self) -> usize {
        GainTable::horizon(self)
    }

    fn act(&mut self, t: usize, s: &[f64], eps: &[f64], mode: ActionMode, a: &mut [f64]) {
        let mut shared: &GainTable = self;
        shared.act(t, s, eps, mode, a)
    }
}

/// The gain table acts through a shared reference: it holds no scratch memory.
impl Actors for GainTable {
    fn actor(&self) -> Box<dyn Policy + '_> {
        Box::new(self)
    }
}

/// Runs one episode of `min(task.horizon, policy.horizon())` steps from `task.start_q` towards
/// the task's goal, in the task's layout, drawing ε ~ N(0, I) from `noise` when it is given
/// (otherwise ε = 0).
pub fn run_episode(
    arm: &mut dyn Arm,
    task: &TaskConfig,
    policy: &mut dyn Policy,
    mut noise: Option<&mut Noise>,
) -> Result<Episode, ImitationError> {
    let layout = task.layout();
    let (dx, du) = (layout.dx(), layout.du());
    let horizon = task.horizon.min(policy.horizon());
    let limits = arm.limits();
    let mode = arm.mode();
    let mut s = vec![0.0; dx];
    arm.reset(task, &mut s)?;
    let mut ep = Episode {
        layout,
        x: Vec::with_capacity(horizon * dx),
        u: Vec::with_capacity(horizon * du),
        u_policy: Vec::with_capacity(horizon * du),
        eps: Vec::with_capacity(horizon * du),
        noisy: noise.is_some(),
    };
    let (mut eps, mut a) = ([0.0; MAX_DU], [0.0; MAX_DU]);
    let (eps, a) = (&mut eps[..du], &mut a[..du]);
    for t in 0..horizon {
        match noise.as_deref_mut() {
            Some(n) => n.next_into(eps),
            None => eps.fill(0.0),
        }
        policy.act(t, &s, eps, mode, a);
        ep.u_policy.extend_from_slice(a);
        clamp_action(mode, &limits, task.dt, &s[layout.q()], a);
        ep.x.extend_from_slice(&s);
        ep.u.extend_from_slice(a);
        ep.eps.extend_from_slice(eps);
        arm.step(a, &mut s);
    }
    Ok(ep)
}

/// `count` independent episodes in parallel on the current rayon pool (docs/design.md §5 D29):
/// `episode(i, arm)` runs the i-th on the arm `arms.episode_arm(key(i))`. Results in index
/// order, so they do not depend on the thread count; the first error (by index) is returned.
pub fn run_episodes<F, K>(
    arms: &dyn Arms,
    count: usize,
    key: K,
    episode: F,
) -> Result<Vec<Episode>, ImitationError>
where
    K: Fn(usize) -> (u64, u64, u64) + Sync,
    F: Fn(usize, &mut dyn Arm) -> Result<Episode, ImitationError> + Sync,
{
    (0..count)
        .into_par_iter()
        .map(|i| {
            let (seed, version, k) = key(i);
            let mut arm = arms.episode_arm(seed, version, k)?;
            episode(i, &mut *arm)
        })
        .collect()
}

/// Step 1 of Algorithm 1: `n` episodes of `policy` (as version `version`) with exploration
/// noise — episode k draws `Noise::new(seed, version, k)`, as the real-time loop does — and one
/// without noise for evaluation (episode k = n), all in parallel ([`run_episodes`]).
pub fn execute(
    arms: &dyn Arms,
    task: &TaskConfig,
    policy: &dyn Actors,
    version: u64,
    seed: u64,
    n: usize,
) -> Result<(Vec<Episode>, Episode), ImitationError> {
    let key = |k: usize| (seed, version, k as u64);
    let mut episodes = run_episodes(arms, n + 1, key, |k, arm| {
        let mut actor = policy.actor();
        if k < n {
            let mut noise = Noise::new(seed, version, k as u64);
            run_episode(arm, task, &mut *actor, Some(&mut noise))
        } else {
            run_episode(arm, task, &mut *actor, None)
        }
    })?;
    let eval = episodes.pop().expect("n + 1 episodes");
    Ok((episodes, eval))
}
