//! The one driver interface of the learners (docs/design.md §1): an iterative learner is run one
//! iteration of Algorithm 1 at a time, step 1 executed either in process ([`iterate`], its
//! episodes in parallel on arms from an [`Arms`] source) or by the real-time loop over IPC
//! (`learner serve` collects the episodes and calls [`Learn::learn`]). The expert, LQR+GAIfO,
//! the GAIfO (PPO) baseline and MDGPS implement it; the two whose policy is a linear-Gaussian
//! controller also implement [`LinGaussLearn`], which is what a served run publishes as gain
//! tables. A learner has one or more goals ([`Learn::goal_tasks`]; MDGPS one per condition, the
//! others one): step 1 runs N noisy episodes at each goal, goal after goal, and one noise-free
//! episode per goal (the evaluations, a slice in goal order).

use std::time::Instant;

use gps::policy::lin_gauss::LinGaussPolicy;
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::GainTable;

use crate::controller::to_gain_table;
use crate::rollout::{execute, Arms, Episode};
use crate::ImitationError;

/// [`Learn`]'s accessors of a learner of one task whose fields are `task`, `iteration` and
/// `cfg` (with `sim`, `samples`, `seed` and `iterations`): GAIfO (PPO), GAIfO (TD3), BCO and
/// the mean path.
macro_rules! run_accessors {
    () => {
        fn task(&self) -> &TaskConfig {
            &self.task
        }
        fn sim_config(&self) -> &SimConfig {
            &self.cfg.sim
        }
        fn samples(&self) -> usize {
            self.cfg.samples
        }
        fn seed(&self) -> u64 {
            self.cfg.seed
        }
        fn iteration(&self) -> usize {
            self.iteration
        }
        fn done(&self) -> bool {
            self.iteration >= self.cfg.iterations
        }
    };
}
pub(crate) use run_accessors;

/// An iterative learner.
pub trait Learn {
    /// What one iteration reports.
    type Log;
    /// Name in messages, file names and the CSV's `algorithm` column.
    const ALGO: &'static str;
    /// The task the episodes must run (goal, start pose, T, dt); with several goals, the first
    /// goal's (every goal shares its start pose, T and dt).
    fn task(&self) -> &TaskConfig;
    /// The task of every goal, in goal order: [`Learn::task`] alone unless the learner has
    /// several goals.
    fn goal_tasks(&self) -> Vec<&TaskConfig> {
        vec![self.task()]
    }
    /// The learner's model of the arm (an in-process run builds its arm from it).
    fn sim_config(&self) -> &SimConfig;
    /// Noisy episodes per iteration and goal N.
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
    /// Step 1 in process: at every goal N noisy episodes and one noise-free episode of the
    /// current policy, in parallel, each on its own arm from `arms` (`rollout::execute`).
    /// Returns the noisy episodes (goal-major: goal m's are `m N .. (m + 1) N`) and the
    /// noise-free ones (one per goal).
    #[allow(clippy::type_complexity)]
    fn execute(&mut self, arms: &dyn Arms) -> Result<(Vec<Episode>, Vec<Episode>), ImitationError>;
    /// Steps 2–6 on the `noisy` episodes of every goal (goal-major, as [`Learn::execute`]
    /// returns them) and the noise-free `evals` of the current policy (version
    /// [`Learn::version`]; one per goal), then the switch to the new policy. `t_execute` (s)
    /// is logged as the time step 1 took.
    fn learn_goals(
        &mut self,
        noisy: &[Episode],
        evals: &[Episode],
        t_execute: f64,
    ) -> Result<Self::Log, ImitationError>;
    /// [`Learn::learn_goals`] of a learner with one goal and its one noise-free episode `eval`
    /// (what `learner serve` streams).
    fn learn(
        &mut self,
        noisy: &[Episode],
        eval: &Episode,
        t_execute: f64,
    ) -> Result<Self::Log, ImitationError> {
        self.learn_goals(noisy, std::slice::from_ref(eval), t_execute)
    }
    /// Task cost of an iteration's noise-free episode (with several goals, their mean).
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
) -> Result<(Vec<Episode>, Vec<Episode>), ImitationError> {
    let table = learner.table();
    let (noisy, eval) = execute(
        arms,
        learner.task(),
        &*table,
        learner.version(),
        learner.seed(),
        learner.samples(),
    )?;
    Ok((noisy, vec![eval]))
}

/// The one noise-free episode of a learner with one goal ([`Learn::learn_goals`]); an error
/// for any other number.
pub fn single_eval(evals: &[Episode]) -> Result<&Episode, ImitationError> {
    match evals {
        [eval] => Ok(eval),
        _ => Err(ImitationError::Episodes(format!(
            "a learner with one goal learns from one noise-free episode, got {}",
            evals.len()
        ))),
    }
}

/// One in-process iteration: step 1 on arms from `arms`, then steps 2–6. Returns the log and
/// the noise-free episodes (one per goal).
pub fn iterate<L: Learn + ?Sized>(
    learner: &mut L,
    arms: &dyn Arms,
) -> Result<(L::Log, Vec<Episode>), ImitationError> {
    iterate_observed(learner, arms, &mut |_, _| {})
}

/// [`iterate`], showing `observe` the episodes of step 1 (noisy, noise-free) before steps 2–6
/// learn from them (`learner train --record-episodes` records them).
pub fn iterate_observed<L: Learn + ?Sized>(
    learner: &mut L,
    arms: &dyn Arms,
    observe: &mut dyn FnMut(&[Episode], &[Episode]),
) -> Result<(L::Log, Vec<Episode>), ImitationError> {
    let t0 = Instant::now();
    let (episodes, evals) = learner.execute(arms)?;
    observe(&episodes, &evals);
    let log = learner.learn_goals(&episodes, &evals, t0.elapsed().as_secs_f64())?;
    Ok((log, evals))
}
