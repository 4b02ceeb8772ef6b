//! One learner update in the paper's order (docs/design.md §1.3, steps 2 and 6; GPS
//! `AlgorithmTrajOpt.iteration`): update the dynamics prior, fit the dynamics and x0, adapt
//! the step size, run the KL-bounded LQR step. Owns every buffer, built once per
//! `(T, dX, dU, N)` and reused each iteration.

use rand_chacha::ChaCha8Rng;

use crate::algorithm::init_state::fit_x0;
use crate::algorithm::step_adjust::{step_adjust, StepAdjust};
use crate::algorithm::AlgorithmConfig;
use crate::dynamics::gmm::{ClusterInit, EmReport};
use crate::dynamics::lr_prior::{fit, FitWorkspace, LrPriorConfig};
use crate::dynamics::prior_gmm::{DynamicsPriorGmm, PriorGmmConfig};
use crate::error::GpsError;
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::traj_opt::lqr::{DgdResult, TrajInfo, TrajOptConfig, TrajOptLqr};
use crate::traj_opt::pilqr::{res_percent_step_mult, PilqrReport, StepRule, TrajOptPilqr};

/// Learner state across iterations (GPS `Algorithm.cur` / `prev` for one condition).
pub struct Learner {
    pub alg: AlgorithmConfig,
    pub fit_cfg: LrPriorConfig,
    pub prior: DynamicsPriorGmm,
    pub opt: TrajOptLqr,
    /// PILQR's PI2 half (used with `traj_opt.method = "pilqr"`).
    pub pilqr: TrajOptPilqr,
    /// Current iteration's dynamics, x0 and cost model (`cur.traj_info`); the caller fills the
    /// cost (`cc`, `cv`, `cm`) before [`Learner::update_trajectories`].
    pub info: TrajInfo,
    /// Previous iteration's trajectory info (for the step adjustment).
    pub prev_info: Option<TrajInfo>,
    /// Dual variable carried between iterations.
    pub eta: f64,
    pub step_mult: f64,
    pub rng: ChaCha8Rng,
    fit_ws: FitWorkspace,
    t: usize,
    dx: usize,
}

impl Learner {
    /// Builds every buffer for horizon `t`, `dx`, `du` and `n` samples per iteration.
    pub fn new(
        alg: AlgorithmConfig,
        prior_cfg: PriorGmmConfig,
        fit_cfg: LrPriorConfig,
        opt_cfg: TrajOptConfig,
        t: usize,
        dx: usize,
        du: usize,
        n: usize,
        rng: ChaCha8Rng,
    ) -> Self {
        Self {
            eta: alg.eta_initial,
            step_mult: 1.0,
            alg,
            fit_cfg,
            prior: DynamicsPriorGmm::new(prior_cfg, t, dx, du),
            pilqr: TrajOptPilqr::new(opt_cfg.pilqr.clone(), t, dx, du, n),
            opt: TrajOptLqr::new(opt_cfg, t, dx, du),
            info: TrajInfo::zeros(t, dx, du),
            prev_info: None,
            rng,
            fit_ws: FitWorkspace::new(n, dx, du),
            t,
            dx,
        }
    }

    /// GPS `_update_dynamics`: prior update (GMM EM), dynamics fit, x0 fit, on the current
    /// samples `x (N,T,dX)`, `u (N,T,dU)`. Keeps the previous trajectory info for the step
    /// adjustment.
    pub fn update_dynamics(
        &mut self,
        x: &[f64],
        u: &[f64],
        n: usize,
    ) -> Result<EmReport, GpsError> {
        if let Some(p) = self.prev_info.as_mut() {
            p.copy_from(&self.info);
        } else {
            self.prev_info = Some(self.info.clone());
        }
        let rep = self.update_prior(x, u, n)?;
        self.fit_dynamics(x, u, n)?;
        Ok(rep)
    }

    /// GPS `DynamicsLRPrior.update_prior`: add the samples to the prior's dataset and refit
    /// its GMM (random hard assignment from `self.rng` when EM (re)initialises).
    pub fn update_prior(&mut self, x: &[f64], u: &[f64], n: usize) -> Result<EmReport, GpsError> {
        self.prior
            .update(x, u, n, ClusterInit::Random(&mut self.rng))
    }

    /// GPS `DynamicsLRPrior.fit` plus the x0 fit of `_update_dynamics`, into `self.info`.
    pub fn fit_dynamics(&mut self, x: &[f64], u: &[f64], n: usize) -> Result<(), GpsError> {
        fit(
            x,
            u,
            n,
            &mut self.prior,
            &self.fit_cfg,
            &mut self.fit_ws,
            &mut self.info.dynamics,
        )?;
        let p0 = self.prior.initial_state();
        let (mu, sig) = fit_x0(x, n, self.t, self.dx, self.alg.initial_state_var, Some(&p0));
        self.info.x0mu = mu;
        self.info.x0sigma = sig;
        Ok(())
    }

    /// GPS `_stepadjust`, given the controller run in the previous iteration and the one run
    /// in this iteration. Call after the cost of this iteration is in `info`.
    pub fn update_step_size(
        &mut self,
        prev_pol: &LinGaussPolicy,
        cur_pol: &LinGaussPolicy,
    ) -> Result<Option<StepAdjust>, GpsError> {
        let Some(prev_info) = self.prev_info.as_ref() else {
            return Ok(None);
        };
        let sa = step_adjust(
            &mut self.opt,
            prev_pol,
            prev_info,
            cur_pol,
            &self.info,
            self.step_mult,
            self.alg.min_step_mult,
            self.alg.max_step_mult,
        )?;
        self.step_mult = sa.step_mult_after;
        Ok(Some(sa))
    }

    /// GPS `_update_trajectories`: η search from the carried η for
    /// `KL ≤ kl_step · step_mult · T`; the new controller goes into `out`.
    pub fn update_trajectories(
        &mut self,
        prev_pol: &LinGaussPolicy,
        out: &mut LinGaussPolicy,
    ) -> Result<DgdResult, GpsError> {
        let kl_step = self.alg.kl_step * self.step_mult * self.t as f64;
        let res = self
            .opt
            .update(prev_pol, &self.info, self.eta, kl_step, out)?;
        self.eta = res.eta;
        Ok(res)
    }

    /// PILQR, before the LQR step: the LQR model's prediction of the samples' costs under the
    /// controller that drew them (`executed`, with their noise `noise (N,T,dU)`), against
    /// their sampled costs `cs (N,T)`; returns the residual's share of the sampled cost. With
    /// `adapt_step` and the `res_percent` rule it sets the step multiplier from that share
    /// (GPS `AlgorithmTrajOptPILQR._stepadjust`, from the second iteration on).
    pub fn pilqr_predict(
        &mut self,
        executed: &LinGaussPolicy,
        noise: &[f64],
        cs: &[f64],
        n: usize,
        adapt_step: bool,
    ) -> Result<f64, GpsError> {
        let share = self.pilqr.predict(noise, cs, n, executed, &self.info)?;
        if adapt_step && self.pilqr.cfg.step_rule == StepRule::ResPercent {
            let c = &self.pilqr.cfg;
            self.step_mult = res_percent_step_mult(
                share,
                self.step_mult,
                c.step_rule_res_ratio_dec,
                c.step_rule_res_ratio_inc,
                self.alg.min_step_mult,
                self.alg.max_step_mult,
            );
        }
        Ok(share)
    }

    /// PILQR, after the LQR step into `pol`: PI2 on the residual cost updates `pol`'s
    /// feed-forward terms and covariances (GPS `TrajOptPILQR.update`). Call
    /// [`Learner::pilqr_predict`] for this iteration's samples first.
    pub fn pilqr_update(
        &mut self,
        noise: &[f64],
        cs: &[f64],
        n: usize,
        pol: &mut LinGaussPolicy,
    ) -> Result<PilqrReport, GpsError> {
        self.pilqr.update(noise, cs, n, pol, None)
    }
}
