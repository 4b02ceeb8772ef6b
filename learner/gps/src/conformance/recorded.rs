//! What a vectors file records as GPS's inputs, gathered so that GPS's work can be redone on
//! them outside the checker (`learner bench --vectors`): the hyperparameters, and for each
//! recorded iteration what its GMM prior update, dynamics fit and η search start from, with
//! GPS's outputs of those three pieces beside them.

use serde_json::Value;

use super::json::*;
use super::ConformanceError;
use crate::algorithm::AlgorithmConfig;
use crate::dynamics::lr_prior::LrPriorConfig;
use crate::dynamics::prior_gmm::PriorGmmConfig;
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::traj_opt::lqr::{TrajInfo, TrajOptConfig};

/// The settings of every piece as the file's `hyperparams` set them. A hyperparameter the file
/// leaves out has GPS's default, which is ours (the `Default` impls).
#[derive(Clone, Debug)]
pub struct Settings {
    /// Algorithm settings (KL step, step-multiplier bounds, x0 variance floor).
    pub alg: AlgorithmConfig,
    /// η search settings.
    pub opt: TrajOptConfig,
    /// GMM prior settings.
    pub prior: PriorGmmConfig,
    /// Dynamics fit settings (regularisation).
    pub fit: LrPriorConfig,
}

/// Reads [`Settings`] from a parsed vectors file.
pub fn settings(v: &Value) -> Result<Settings, ConformanceError> {
    let hp = req(v, "hyperparams")?;
    let (alg0, opt0, prior0) = (
        AlgorithmConfig::default(),
        TrajOptConfig::default(),
        PriorGmmConfig::default(),
    );
    let flag = |p: &str, default: bool| path(hp, p).and_then(Value::as_bool).unwrap_or(default);
    let count = |p: &str, default: usize| opt_f64(hp, p, default as f64) as usize;
    Ok(Settings {
        alg: AlgorithmConfig {
            kl_step: opt_f64(hp, "algorithm.kl_step", alg0.kl_step),
            min_step_mult: opt_f64(hp, "algorithm.min_step_mult", alg0.min_step_mult),
            max_step_mult: opt_f64(hp, "algorithm.max_step_mult", alg0.max_step_mult),
            initial_state_var: opt_f64(hp, "algorithm.initial_state_var", alg0.initial_state_var),
            ..alg0
        },
        opt: TrajOptConfig {
            del0: opt_f64(hp, "traj_opt.del0", opt0.del0),
            min_eta: opt_f64(hp, "traj_opt.min_eta", opt0.min_eta),
            max_eta: opt_f64(hp, "traj_opt.max_eta", opt0.max_eta),
            cons_per_step: flag("traj_opt.cons_per_step", opt0.cons_per_step),
            use_prev_distr: flag("traj_opt.use_prev_distr", opt0.use_prev_distr),
            max_ent_traj: opt_f64(hp, "algorithm.max_ent_traj", opt0.max_ent_traj),
            ..opt0.clone()
        },
        prior: PriorGmmConfig {
            min_samples_per_cluster: count(
                "dynamics.prior.min_samples_per_cluster",
                prior0.min_samples_per_cluster,
            ),
            max_clusters: count("dynamics.prior.max_clusters", prior0.max_clusters),
            max_samples: count("dynamics.prior.max_samples", prior0.max_samples),
            strength: opt_f64(hp, "dynamics.prior.strength", prior0.strength),
            ..prior0
        },
        fit: LrPriorConfig {
            regularization: opt_f64(
                hp,
                "dynamics.regularization",
                LrPriorConfig::default().regularization,
            ),
        },
    })
}

/// A GMM as a file records it (`gmm.{K, mu, sigma, logmass, self_N}`).
#[derive(Clone, Debug)]
pub struct RecordedGmm {
    /// Clusters K.
    pub k: usize,
    /// Means, (K, D) row-major.
    pub mu: Vec<f64>,
    /// Covariances, (K, D, D) row-major.
    pub sigma: Vec<f64>,
    /// Log masses, (K).
    pub logmass: Vec<f64>,
    /// GPS `GMM.N`.
    pub self_n: usize,
}

/// The GMM of an iteration's `outputs` of points of dimension `dj`, if recorded.
pub(super) fn recorded_gmm(out: &Value, dj: usize) -> Option<RecordedGmm> {
    let k = path(out, "gmm.K")?.as_u64()? as usize;
    Some(RecordedGmm {
        k,
        mu: req_arr(out, "gmm.mu", k * dj).ok()?,
        sigma: req_arr(out, "gmm.sigma", k * dj * dj).ok()?,
        logmass: req_arr(out, "gmm.logmass", k).ok()?,
        self_n: path(out, "gmm.self_N")?.as_u64()? as usize,
    })
}

/// One recorded iteration: the inputs of its three pieces and GPS's outputs of them.
#[derive(Clone, Debug)]
pub struct RecordedIteration {
    /// Samples N of this iteration.
    pub n: usize,
    /// This iteration's states (N, T, dX) and actions (N, T, dU), row-major.
    pub x: Vec<f64>,
    pub u: Vec<f64>,
    /// Trajectories already in the prior's dataset (the earlier iterations' samples, oldest
    /// first): count, states (n, T, dX), actions (n, T, dU).
    pub earlier_n: usize,
    pub earlier_x: Vec<f64>,
    pub earlier_u: Vec<f64>,
    /// The previous iteration's recorded GMM, which EM warm-starts from (none at iteration 0).
    pub warm_start: Option<RecordedGmm>,
    /// GPS's cluster assignment when EM (re)initialised (empty when it warm-started).
    pub init_cluster_idx: Vec<usize>,
    /// The recorded dynamics, x0 and cost model the η search ran on.
    pub info: TrajInfo,
    /// The controller the η search bounds the KL against.
    pub prev: LinGaussPolicy,
    /// η the search started from.
    pub eta_start: f64,
    /// Total KL target.
    pub kl_step: f64,
    /// GPS's outputs: EM iterations (length of `ll_trace`), clusters, backward passes of the η
    /// search, its final η and new controller.
    pub gps_em_iterations: usize,
    pub gps_k: usize,
    pub gps_backward_calls: usize,
    pub gps_eta_final: f64,
    pub gps_new_controller: LinGaussPolicy,
}

/// A vectors file's problem: dimensions, settings, recorded iterations.
#[derive(Clone, Debug)]
pub struct RecordedProblem {
    /// Horizon T, state and action dimensions.
    pub t: usize,
    pub dx: usize,
    pub du: usize,
    pub settings: Settings,
    pub iterations: Vec<RecordedIteration>,
}

/// Reads a vectors file into a [`RecordedProblem`].
pub fn load_file(file: &str) -> Result<RecordedProblem, ConformanceError> {
    load(&super::read_json(file)?)
}

/// Gathers a [`RecordedProblem`] from a parsed vectors file.
pub fn load(v: &Value) -> Result<RecordedProblem, ConformanceError> {
    let d = Dims {
        t: req_usize(v, "dims.T")?,
        dx: req_usize(v, "dims.dX")?,
        du: req_usize(v, "dims.dU")?,
        n: req_usize(v, "dims.N")?,
    };
    let settings = settings(v)?;
    let dj = 2 * d.dx + d.du;
    let init = load_policy(req(v, "init_controller")?, &d)?;
    let iters = req(v, "iterations")?
        .as_array()
        .ok_or_else(|| ConformanceError::Field("iterations".into()))?;
    let mut out_iters: Vec<RecordedIteration> = Vec::with_capacity(iters.len());
    let (mut earlier_n, mut earlier_x, mut earlier_u) = (0, Vec::new(), Vec::new());
    for (it, iv) in iters.iter().enumerate() {
        let at = |p: &str| format!("iterations[{it}].{p}");
        let field_err = |p: &str| ConformanceError::Field(at(p));
        let inp = req(iv, "inputs")?;
        let out = req(iv, "outputs")?;
        let n = req(inp, "X")?.as_array().map_or(d.n, Vec::len);
        let x = req_arr(inp, "X", n * d.t * d.dx)?;
        let u = req_arr(inp, "U", n * d.t * d.du)?;
        let prev = match req(inp, "prev_controller")?.as_str() {
            Some("init_controller") => init.clone(),
            Some(name) => {
                let idx: usize = name
                    .strip_prefix("iterations[")
                    .and_then(|s| s.split(']').next())
                    .and_then(|s| s.parse().ok())
                    .filter(|&i| i < it)
                    .ok_or_else(|| field_err("inputs.prev_controller"))?;
                out_iters[idx].gps_new_controller.clone()
            }
            None => return Err(field_err("inputs.prev_controller")),
        };
        let warm_start = match it {
            0 => None,
            _ => recorded_gmm(req(&iters[it - 1], "outputs")?, dj),
        };
        let ll = req(out, "gmm.ll_trace")?
            .as_array()
            .ok_or_else(|| field_err("outputs.gmm.ll_trace"))?;
        let trace = req(out, "dgd_trace")?
            .as_array()
            .ok_or_else(|| field_err("outputs.dgd_trace"))?;
        out_iters.push(RecordedIteration {
            n,
            earlier_n,
            earlier_x: earlier_x.clone(),
            earlier_u: earlier_u.clone(),
            warm_start,
            init_cluster_idx: usize_list(path(out, "gmm.init_cluster_idx")).unwrap_or_default(),
            info: load_traj_info(out, &d)?,
            prev,
            eta_start: req_f64(inp, "eta_start")?,
            kl_step: req_f64(out, "kl_step")?,
            gps_em_iterations: ll.len(),
            gps_k: req_usize(out, "gmm.K")?,
            gps_backward_calls: trace.len(),
            gps_eta_final: req_f64(out, "eta_final")?,
            gps_new_controller: load_policy(req(out, "new_controller")?, &d)?,
            x,
            u,
        });
        earlier_n += n;
        let last = out_iters.last().expect("pushed above");
        earlier_x.extend_from_slice(&last.x);
        earlier_u.extend_from_slice(&last.u);
    }
    Ok(RecordedProblem {
        t: d.t,
        dx: d.dx,
        du: d.du,
        settings,
        iterations: out_iters,
    })
}
