//! The baselines over IPC (`learner serve --algo bco | gaifo-td3 | replay-mean`): BCO(α) and
//! GAIfO (TD3), whose policy is an MLP, publish it each version as a policy table with the
//! default episode plan, so that the controller runs N noisy episodes of it and the noise-free
//! one as it runs a gain table (a = q + μ(s) + σ ε, the noise keyed by seed, version and
//! episode as in process); the mean path is a gain table with K = 0 and k_t the path, as in
//! process. Their files are those of `learner train --algo …` (`gaifo_log.csv`, the
//! checkpoints); `--resume` continues exactly from the latest.

use std::path::Path;

use gps::policy::lin_gauss::LinGaussPolicy;
use imitation::bco::{Bco, BcoConfig};
use imitation::demos::Demos;
use imitation::gaifo::GaifoLog;
use imitation::learn::{Learn, LinGaussLearn};
use imitation::mlp_policy::global::GlobalPolicy;
use imitation::offpolicy::{GaifoTd3, GaifoTd3Config};
use imitation::replay_mean::{ReplayMean, ReplayMeanConfig};
use ur5_shared::config::SimConfig;

use super::learner::{log_row, open_log_row, single, Publication, ServeLearner};
use super::ports::AnyTable;
use super::task_check::validate;
use super::{claim_dirs, serve_loop, ServeError, ServeOptions, ServeSummary};

/// The one publication per version of a learner with one goal whose policy is an MLP:
/// `policy` as policy table version [`Learn::version`] at `epoch`, with the arm model it
/// learns on, N noisy episodes and the noise-free one.
fn policy_single<L: Learn>(
    learner: &L,
    policy: &GlobalPolicy,
    sim: &SimConfig,
    epoch: u32,
) -> Result<Vec<Publication>, ServeError> {
    let mut table = policy
        .to_table(learner.version(), sim.mode)
        .map_err(|e| ServeError::Range(format!("{} policy as a table: {e}", L::ALGO)))?;
    table.model = ur5_shared::policy::model_code(sim.model);
    table.epoch = epoch;
    table.seal();
    Ok(vec![Publication {
        table: AnyTable::Policy(table),
        goal: 0,
        noisy: learner.samples(),
        eval: true,
        noise_seed: learner.seed(),
    }])
}

impl ServeLearner for Bco {
    gaifo_log_files!();
    fn publications(&self, epoch: u32) -> Result<Vec<Publication>, ServeError> {
        policy_single(self, self.policy(), &self.config().sim, epoch)
    }
    fn served_policy(&self) -> Option<&LinGaussPolicy> {
        None
    }
}

impl ServeLearner for GaifoTd3 {
    gaifo_log_files!();
    fn publications(&self, epoch: u32) -> Result<Vec<Publication>, ServeError> {
        policy_single(self, self.policy(), &self.config().sim, epoch)
    }
    fn served_policy(&self) -> Option<&LinGaussPolicy> {
        None
    }
}

impl ServeLearner for ReplayMean {
    gaifo_log_files!();
    fn publications(&self, epoch: u32) -> Result<Vec<Publication>, ServeError> {
        Ok(single(self, epoch))
    }
    fn served_policy(&self) -> Option<&LinGaussPolicy> {
        Some(self.policy())
    }
}

/// Runs BCO(α)'s learner end on `demos` (their task) until `cfg.iterations` are done or
/// SIGINT/SIGTERM; `--resume` continues from the latest `iter_NNN_state.npz`.
pub fn serve_bco(
    cfg: BcoConfig,
    demos: Demos,
    opts: ServeOptions,
    progress: impl FnMut(&GaifoLog),
) -> Result<ServeSummary<GaifoLog>, ServeError> {
    let task = demos.task()?;
    let var = cfg.explore_std * cfg.explore_std;
    validate(&task, cfg.samples, var, &opts).map_err(|e| ServeError::DemosTask(Box::new(e)))?;
    cfg.validate()?;
    claim_dirs(&opts, Bco::ALGO, cfg.seed, &cfg)?;
    let run = match &opts.resume {
        Some(dir) => crate::baselines::resume_bco(cfg, demos, dir)?.0,
        None => Bco::new(cfg, demos)?,
    };
    serve_loop(run, opts, progress)
}

/// Runs GAIfO (TD3)'s learner end on `demos` until `cfg.iterations` are done or
/// SIGINT/SIGTERM; `--resume` continues from the latest checkpoint (replay buffer included).
pub fn serve_td3(
    cfg: GaifoTd3Config,
    demos: Demos,
    opts: ServeOptions,
    progress: impl FnMut(&GaifoLog),
) -> Result<ServeSummary<GaifoLog>, ServeError> {
    let task = demos.task()?;
    // The exploration σ is in units of the action bound; any positive variance passes here.
    validate(&task, cfg.samples, 1.0, &opts).map_err(|e| ServeError::DemosTask(Box::new(e)))?;
    cfg.validate()?;
    claim_dirs(&opts, GaifoTd3::ALGO, cfg.seed, &cfg)?;
    let run = match &opts.resume {
        Some(dir) => crate::run::resume_td3(cfg, demos, dir)?.0,
        None => GaifoTd3::new(cfg, demos)?,
    };
    serve_loop(run, opts, progress)
}

/// Runs the mean path's (learner-free) end on `demos`: every version the same gain table
/// (K = 0, k_t the demonstrations' mean joint angles at t + 1), evaluated `cfg.iterations`
/// times; `--resume` continues the count from the latest `iter_NNN_state.npz`.
pub fn serve_replay_mean(
    cfg: ReplayMeanConfig,
    demos: Demos,
    opts: ServeOptions,
    progress: impl FnMut(&GaifoLog),
) -> Result<ServeSummary<GaifoLog>, ServeError> {
    let task = demos.task()?;
    validate(&task, cfg.samples, cfg.init_var, &opts)
        .map_err(|e| ServeError::DemosTask(Box::new(e)))?;
    cfg.validate()?;
    claim_dirs(&opts, ReplayMean::ALGO, cfg.seed, &cfg)?;
    let run = ReplayMean::new(cfg, demos)?;
    let run = match &opts.resume {
        Some(dir) => run.resumed_at(crate::baselines::latest_state(dir)?.0),
        None => run,
    };
    serve_loop(run, opts, progress)
}
