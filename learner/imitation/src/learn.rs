//! The one driver interface of the learners (docs/design.md §1): an iterative learner is run one
//! iteration of Algorithm 1 at a time, step 1 executed either in process ([`iterate`], its
//! episodes in parallel on arms from an [`Arms`] source) or by the real-time loop over IPC
//! (`learner serve` collects the episodes and calls [`Learn::learn`]). The expert, LQR+GAIfO
//! and the GAIfO (PPO) baseline implement it; the two whose policy is a linear-Gaussian
//! controller also implement [`LinGaussLearn`], which is what a served run publishes as gain
//! tables.

use std::time::Instant;

use gps::policy::lin_gauss::LinGaussPolicy;
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::GainTable;

use crate::controller::to_gain_table;
use crate::rollout::{execute, Arms, Episode};
use crate::ImitationError;

/// An iterative learner.
pub trait Learn {
    /// What one iteration reports.
    type Log;
    /// Name in messages, file names and the CSV's `algorithm` column.
    const ALGO: &'static str;
    /// The task the episodes must run (goal, start pose, T, dt).
    fn task(&self) -> &TaskConfig;
    /// The learner's model of the arm (an in-process run builds its arm from it).
    fn sim_config(&self) -> &SimConfig;
    /// Noisy episodes per iteration N.
    fn samples(&self) -> usize;
    /// Run seed (exploration noise, every random draw).
    fn seed(&self) -> u64;
    /// Iterations done (counting those before a resume).
    fn iteration(&self) -> usize;
    /// Version of the policy executed next: iteration + 1 (the initial policy is version 1).
    fn version(&self) -> u64 {
        self.iteration() as u64 + 1
    }
    /// Nothing more to learn.
    fn done(&self) -> bool;
    /// Step 1 in process: N noisy episodes and one noise-free episode of the current policy,
    /// in parallel, each on its own arm from `arms` (`rollout::execute`).
    fn execute(&mut self, arms: &dyn Arms) -> Result<(Vec<Episode>, Episode), ImitationError>;
    /// Steps 2–6 on the `noisy` episodes and the noise-free `eval` episode of the current
    /// policy (version [`Learn::version`]), then the switch to the new policy. `t_execute` (s)
    /// is logged as the time step 1 took.
    fn learn(
        &mut self,
        noisy: &[Episode],
        eval: &Episode,
        t_execute: f64,
    ) -> Result<Self::Log, ImitationError>;
    /// Task cost of an iteration's noise-free episode.
    fn eval_cost(log: &Self::Log) -> f64;
}

/// A learner whose policy is a time-varying linear-Gaussian controller.
pub trait LinGaussLearn: Learn {
    /// The controller executed next.
    fn policy(&self) -> &LinGaussPolicy;
    /// It as gain table version [`Learn::version`].
    fn table(&self) -> Box<GainTable> {
        to_gain_table(self.policy(), self.version())
    }
}

/// [`Learn::execute`] of a [`LinGaussLearn`]: its gain table through the controller law.
pub fn execute_table<L: LinGaussLearn + ?Sized>(
    learner: &L,
    arms: &dyn Arms,
) -> Result<(Vec<Episode>, Episode), ImitationError> {
    let table = learner.table();
    execute(
        arms,
        learner.task(),
        &*table,
        learner.version(),
        learner.seed(),
        learner.samples(),
    )
}

/// One in-process iteration: step 1 on arms from `arms`, then steps 2–6. Returns the log and
/// the noise-free episode.
pub fn iterate<L: Learn + ?Sized>(
    learner: &mut L,
    arms: &dyn Arms,
) -> Result<(L::Log, Episode), ImitationError> {
    iterate_observed(learner, arms, &mut |_, _| {})
}

/// [`iterate`], showing `observe` the episodes of step 1 (noisy, noise-free) before steps 2–6
/// learn from them (`learner train --record-episodes` records them).
pub fn iterate_observed<L: Learn + ?Sized>(
    learner: &mut L,
    arms: &dyn Arms,
    observe: &mut dyn FnMut(&[Episode], &Episode),
) -> Result<(L::Log, Episode), ImitationError> {
    let t0 = Instant::now();
    let (episodes, eval) = learner.execute(arms)?;
    observe(&episodes, &eval);
    let log = learner.learn(&episodes, &eval, t0.elapsed().as_secs_f64())?;
    Ok((log, eval))
}
