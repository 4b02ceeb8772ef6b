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
use ur5_shared::layout::{DU, DX, Q};
use ur5_shared::noise::Noise;
use ur5_shared::safety::clamp_action;
use ur5_shared::{controller_action, GainTable};

use crate::ImitationError;

/// One episode: T states and the T actions taken in them.
#[derive(Clone, Debug, PartialEq)]
pub struct Episode {
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
    /// Puts the arm at rest at `start_q` (rad) with goal point `goal` (m, base frame) and
    /// returns the state s_0 (layout `ur5_shared::layout`).
    fn reset(&mut self, start_q: [f64; DU], goal: [f64; 3]) -> Result<[f64; DX], ImitationError>;
    /// Executes action `a` (already clamped) for one control period; returns the next state.
    fn step(&mut self, a: [f64; DU]) -> [f64; DX];
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
    /// The action (before the clamp) at step `t` in state `s` with exploration noise `eps`
    /// (zeros for a noise-free episode) on an arm whose actions are `mode`.
    fn act(&mut self, t: usize, s: &[f64; DX], eps: &[f64; DU], mode: ActionMode) -> [f64; DU];
}

/// A gain table as a policy: the controller law a = K_t (s − ŝ_t) + k_t + â_t + L_t ε of
/// `ur5_shared::controller_action`, the real-time loop's.
impl Policy for &GainTable {
    fn horizon(&self) -> usize {
        GainTable::horizon(self)
    }

    fn act(&mut self, t: usize, s: &[f64; DX], eps: &[f64; DU], _: ActionMode) -> [f64; DU] {
        let mut a = [0.0; DU];
        controller_action(self, t, s, eps, &mut a).expect("t < horizon");
        a
    }
}

impl Policy for GainTable {
    fn horizon(&self) -> usize {
        GainTable::horizon(self)
    }

    fn act(&mut self, t: usize, s: &[f64; DX], eps: &[f64; DU], mode: ActionMode) -> [f64; DU] {
        let mut shared: &GainTable = self;
        shared.act(t, s, eps, mode)
    }
}

/// The gain table acts through a shared reference: it holds no scratch memory.
impl Actors for GainTable {
    fn actor(&self) -> Box<dyn Policy + '_> {
        Box::new(self)
    }
}

/// Runs one episode of `min(task.horizon, policy.horizon())` steps from `task.start_q` towards
/// `task.goal`, drawing ε ~ N(0, I) from `noise` when it is given (otherwise ε = 0).
pub fn run_episode(
    arm: &mut dyn Arm,
    task: &TaskConfig,
    policy: &mut dyn Policy,
    mut noise: Option<&mut Noise>,
) -> Result<Episode, ImitationError> {
    let horizon = task.horizon.min(policy.horizon());
    let limits = arm.limits();
    let mode = arm.mode();
    let mut s = arm.reset(task.start_q, task.goal)?;
    let mut ep = Episode {
        x: Vec::with_capacity(horizon * DX),
        u: Vec::with_capacity(horizon * DU),
        u_policy: Vec::with_capacity(horizon * DU),
        eps: Vec::with_capacity(horizon * DU),
        noisy: noise.is_some(),
    };
    for t in 0..horizon {
        let eps = match noise.as_deref_mut() {
            Some(n) => n.next(),
            None => [0.0; DU],
        };
        let mut a = policy.act(t, &s, &eps, mode);
        ep.u_policy.extend_from_slice(&a);
        let q: [f64; DU] = s[Q].try_into().expect("dU joint angles");
        clamp_action(mode, &limits, task.dt, &q, &mut a);
        ep.x.extend_from_slice(&s);
        ep.u.extend_from_slice(&a);
        ep.eps.extend_from_slice(&eps);
        s = arm.step(a);
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
