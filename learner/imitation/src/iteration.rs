//! The one LQR iteration both LQR learners run (docs/design.md §1.3), GPS's
//! `AlgorithmTrajOpt.iteration` with a plug-in [`Cost`]: [`LqrIteration::fit_dynamics`] is
//! step 2, [`LqrIteration::expand`] steps 4–5 with any cost, [`LqrIteration::improve`] step 6
//! (and the switch to the new controller). The expert ([`crate::expert::ExpertLearner`]) calls
//! them with the task cost; LQR+GAIfO ([`crate::gaifo::LqrGaifo`]) with the critic's composite
//! cost, after its critic step (step 3). Step 1 is [`crate::learn::Learn::execute`].

use gps::algorithm::eval_cost::{eval_cost, CostDerivs};
use gps::algorithm::update::Learner;
use gps::policy::lin_gauss::LinGaussPolicy;
use gps::snapshot::Snapshot;
use gps::traj_opt::pilqr::{PilqrReport, StepRule, TrajOptMethod};

use crate::cost::Cost;
use crate::rollout::{Episode, SampleList};
use crate::ImitationError;

/// What the LQR step did.
#[derive(Clone, Copy, Debug)]
pub struct StepReport {
    /// KL(new ‖ old) of the step (total over T).
    pub kl: f64,
    /// Dual variable η after the search.
    pub eta: f64,
    /// Step multiplier used.
    pub step_mult: f64,
    /// What PILQR's PI2 half did (`traj_opt.method = "pilqr"`), else `None`.
    pub pilqr: Option<PilqrReport>,
}

/// The state one LQR iteration updates: the GPS learner (dynamics prior and fit, x0, step
/// size, η), the controller executed next, the previous one (for the step adjustment), the
/// cost expansion and the iteration count.
pub struct LqrIteration {
    learner: Learner,
    pol: LinGaussPolicy,
    prev_pol: Option<LinGaussPolicy>,
    new_pol: LinGaussPolicy,
    derivs: CostDerivs,
    /// PILQR: the samples' sampled costs (N, T) and exploration noise ε (N, T, dU), taken
    /// with the expansion.
    cs: Vec<f64>,
    noise: Vec<f64>,
    iteration: usize,
}

impl LqrIteration {
    /// Starts from controller `pol` after `iteration` iterations. The GPS learner state starts
    /// afresh (no previous controller: the first step is not step-adjusted).
    pub fn new(learner: Learner, pol: LinGaussPolicy, iteration: usize) -> Self {
        Self {
            new_pol: LinGaussPolicy::zeros(pol.t, pol.dx, pol.du),
            learner,
            pol,
            prev_pol: None,
            derivs: CostDerivs::default(),
            cs: Vec::new(),
            noise: Vec::new(),
            iteration,
        }
    }

    /// The controller executed next.
    pub fn policy(&self) -> &LinGaussPolicy {
        &self.pol
    }

    /// Iterations done.
    pub fn iteration(&self) -> usize {
        self.iteration
    }

    /// Adds everything the next iteration depends on to `s` (docs/design.md §4.11): the
    /// iteration count (`lqr.iteration`), the controller executed next (`policy.*`), the
    /// previous one (`prev_policy.*`, once there is one) and the GPS learner state
    /// ([`Learner::snapshot`]). The cost expansion and the new-controller buffer are scratch,
    /// rewritten before they are read.
    pub fn snapshot(&self, s: &mut Snapshot) {
        s.put_words("lqr.iteration", &[self.iteration as u64]);
        s.put_policy("policy", &self.pol);
        if let Some(prev) = &self.prev_pol {
            s.put_policy("prev_policy", prev);
        }
        self.learner.snapshot(s);
    }

    /// Restores the state saved by [`LqrIteration::snapshot`] (into an iteration built for the
    /// same problem size and settings); nothing changes on an error.
    pub fn restore(&mut self, s: &Snapshot) -> Result<(), ImitationError> {
        let iteration = s.words("lqr.iteration", 1)?[0];
        let mut pol = self.pol.clone();
        s.fill_policy("policy", &mut pol)?;
        let prev_pol = if s.has("prev_policy.K") {
            let mut prev = self.pol.clone();
            s.fill_policy("prev_policy", &mut prev)?;
            Some(prev)
        } else {
            None
        };
        self.learner.restore(s)?;
        self.iteration = usize::try_from(iteration).map_err(|_| {
            gps::GpsError::Snapshot(format!("lqr.iteration = {iteration}: too large"))
        })?;
        self.pol = pol;
        self.prev_pol = prev_pol;
        Ok(())
    }

    /// Step 2: refits the dynamics p(s'|s,a) (GMM prior + Bayesian linear regression) and x0
    /// on `samples` (GPS `_update_dynamics`).
    pub fn fit_dynamics(&mut self, samples: &SampleList) -> Result<(), ImitationError> {
        self.learner
            .update_dynamics(&samples.x, &samples.u, samples.n)?;
        Ok(())
    }

    /// Steps 4–5: the per-sample second-order expansion of `cost` around `episodes` (the
    /// episodes of `samples`), with the dynamics fitted by [`LqrIteration::fit_dynamics`].
    /// With PILQR it also keeps the episodes' sampled costs ([`Cost::sampled`]) and noise.
    pub fn expand(&mut self, cost: &mut dyn Cost, episodes: &[Episode]) {
        cost.expand(episodes, &self.learner.info.dynamics, &mut self.derivs);
        if self.pilqr() {
            cost.sampled(episodes, &self.derivs, &mut self.cs);
            self.noise.clear();
            for ep in episodes {
                self.noise.extend_from_slice(&ep.eps);
            }
        }
    }

    fn pilqr(&self) -> bool {
        self.learner.opt.cfg.method == TrajOptMethod::Pilqr
    }

    /// Step 6: averages the expansion into the quadratic model (GPS `_eval_cost`), adapts the
    /// KL step from the previous step's predicted vs actual improvement (from the second
    /// iteration on, when `adapt_step`), takes the KL-bounded LQR step, and makes the new
    /// controller the one executed next. With `traj_opt.method = "pilqr"` the step rule is
    /// `[traj_opt.pilqr] step_rule` (GPS's PILQR default: the residual's share, whatever
    /// `adapt_step`; `laplace`: the rule above) and PI2 on the residual cost follows the LQR
    /// step (`gps::traj_opt::pilqr`).
    pub fn improve(
        &mut self,
        samples: &SampleList,
        adapt_step: bool,
    ) -> Result<StepReport, ImitationError> {
        self.step(samples, adapt_step, None)
    }

    /// Step 6 of MDGPS (the C-step, docs/design.md §6.3): as [`LqrIteration::improve`] without
    /// step adaptation, but the KL bound and the backward pass's KL term are taken towards
    /// `anchor` (the global policy's linearisation at this condition) instead of the controller
    /// executed this iteration (GPS `TrajOptLQRPython.update` for `AlgorithmMDGPS`).
    pub fn improve_towards(
        &mut self,
        samples: &SampleList,
        anchor: &LinGaussPolicy,
    ) -> Result<StepReport, ImitationError> {
        self.step(samples, false, Some(anchor))
    }

    fn step(
        &mut self,
        samples: &SampleList,
        adapt_step: bool,
        anchor: Option<&LinGaussPolicy>,
    ) -> Result<StepReport, ImitationError> {
        let learner = &mut self.learner;
        eval_cost(
            &samples.x,
            &samples.u,
            &self.derivs,
            samples.n,
            self.pol.t,
            self.pol.dx,
            self.pol.du,
            &mut learner.info.cc,
            &mut learner.info.cv,
            &mut learner.info.cm,
        );
        let pilqr = learner.opt.cfg.method == TrajOptMethod::Pilqr;
        if pilqr {
            // PILQR's prediction of the samples' costs, and its residual step rule (GPS
            // `AlgorithmTrajOptPILQR._stepadjust`, from the second iteration on) when that is
            // the rule.
            let n = samples.n;
            learner.pilqr_predict(&self.pol, &self.noise, &self.cs, n, self.prev_pol.is_some())?;
        }
        if !pilqr || learner.pilqr.cfg.step_rule == StepRule::Laplace {
            if let (Some(prev), true) = (self.prev_pol.as_ref(), adapt_step) {
                learner.update_step_size(prev, &self.pol)?;
            }
        }
        let step_mult = learner.step_mult;
        let res = learner.update_trajectories(anchor.unwrap_or(&self.pol), &mut self.new_pol)?;
        let pilqr = if pilqr {
            Some(learner.pilqr_update(&self.noise, &self.cs, samples.n, &mut self.new_pol)?)
        } else {
            None
        };
        let kl = res.trace.last().map(|s| s.kl).unwrap_or(f64::NAN);
        match self.prev_pol.as_mut() {
            Some(p) => p.copy_from(&self.pol),
            None => self.prev_pol = Some(self.pol.clone()),
        }
        self.pol.copy_from(&self.new_pol);
        self.iteration += 1;
        Ok(StepReport {
            kl,
            eta: res.eta,
            step_mult,
            pilqr,
        })
    }
}
