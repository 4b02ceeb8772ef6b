//! The comparisons of one recorded iteration's pieces (cost averaging, GMM, prior and fit,
//! initial state, step adjustment, η search) against its outputs.

use faer::Mat;
use serde_json::Value;

use super::json::*;
use super::{Report, TOL_DET, TOL_DYN_COVAR, TOL_FM, TOL_GMM};
use crate::algorithm::eval_cost::{eval_cost, CostDerivs};
use crate::algorithm::init_state::fit_x0;
use crate::algorithm::step_adjust::step_adjust;
use crate::dynamics::gmm::{ClusterInit, EmStop};
use crate::dynamics::lr_prior::{fit_with, FitWorkspace, LrPriorConfig};
use crate::dynamics::prior_gmm::{DynamicsPriorGmm, NiwPrior, PriorGmmConfig};
use crate::dynamics::Dynamics;
use crate::linalg::MatSeq;
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::traj_opt::lqr::{TrajInfo, TrajOptLqr};

/// Step 2 of an iteration: GMM EM on the stored dataset. Warm starts begin from the previous
/// iteration's recorded GMM (README "How the pieces chain", step 2), not from this port's own
/// EM.
#[allow(clippy::too_many_arguments)]
pub(super) fn check_gmm(
    r: &mut Report,
    p: &str,
    prior: &mut DynamicsPriorGmm,
    iters: &[Value],
    it: usize,
    out: &Value,
    x: &[f64],
    u: &[f64],
    n: usize,
    d: &Dims,
) {
    let (dx, du) = (d.dx, d.du);
    if it > 0 {
        let po = path(&iters[it - 1], "outputs");
        let dj = 2 * dx + du;
        let rec = po.and_then(|po| super::recorded::recorded_gmm(po, dj));
        if let Some(g) = rec {
            prior
                .gmm
                .set_params(g.k, &g.mu, &g.sigma, &g.logmass, g.self_n);
        }
    }
    let init_idx = usize_list(path(out, "gmm.init_cluster_idx"));
    let empty: Vec<usize> = Vec::new();
    let em = prior.update(
        x,
        &u,
        n,
        ClusterInit::Given(init_idx.as_deref().unwrap_or(&empty)),
    );
    match em {
        Ok(rep) => {
            r.exact(
                &format!("{p}.gmm.n_traj_in_dataset"),
                prior.n_traj,
                path(out, "gmm.n_traj_in_dataset")
                    .and_then(Value::as_u64)
                    .map(|x| x as usize),
            );
            r.exact(
                &format!("{p}.gmm.K"),
                rep.k,
                path(out, "gmm.K")
                    .and_then(Value::as_u64)
                    .map(|x| x as usize),
            );
            r.exact(
                &format!("{p}.gmm.reinitialized"),
                rep.reinitialized,
                path(out, "gmm.reinitialized").and_then(Value::as_bool),
            );
            r.exact(
                &format!("{p}.gmm.n_points"),
                rep.n_points,
                path(out, "gmm.n_points")
                    .and_then(Value::as_u64)
                    .map(|x| x as usize),
            );
            r.exact(
                &format!("{p}.gmm.stop"),
                rep.stop.as_str(),
                path(out, "gmm.stop").and_then(Value::as_str),
            );
            let exp_itr = path(out, "gmm.stop_itr")
                .and_then(Value::as_u64)
                .map(|x| x as usize);
            // When EM runs out of iterations, a file may record either the iteration
            // count or the last loop index (the vectors README does not say which); both
            // describe the same stop.
            let got_itr = match (rep.stop, exp_itr) {
                (EmStop::MaxIterations, Some(e)) if e + 1 == rep.stop_itr => e,
                _ => rep.stop_itr,
            };
            r.exact(&format!("{p}.gmm.stop_itr"), got_itr, exp_itr);
            r.exact(
                &format!("{p}.gmm.self_N"),
                prior.gmm.n,
                path(out, "gmm.self_N")
                    .and_then(Value::as_u64)
                    .map(|x| x as usize),
            );
            r.arr_norm(
                &format!("{p}.gmm.ll_trace"),
                &rep.ll_trace,
                path(out, "gmm.ll_trace"),
                TOL_GMM,
            );
            r.arr_norm(
                &format!("{p}.gmm.mu"),
                &prior.gmm.mu,
                path(out, "gmm.mu"),
                TOL_GMM,
            );
            r.arr_norm(
                &format!("{p}.gmm.sigma"),
                &prior.gmm.sigma.data,
                path(out, "gmm.sigma"),
                TOL_GMM,
            );
            r.arr_norm(
                &format!("{p}.gmm.logmass"),
                &prior.gmm.logmass,
                path(out, "gmm.logmass"),
                TOL_GMM,
            );
            r.arr_norm(
                &format!("{p}.gmm.mass"),
                &prior.gmm.mass,
                path(out, "gmm.mass"),
                TOL_GMM,
            );
        }
        Err(e) => r.fail(&format!("{p}.gmm"), e.to_string()),
    }
}

/// The prior's initial-state distribution and x0 of an iteration.
#[allow(clippy::too_many_arguments)]
pub(super) fn check_initial_state(
    r: &mut Report,
    p: &str,
    prior: &DynamicsPriorGmm,
    out: &Value,
    x: &[f64],
    n: usize,
    d: &Dims,
    init_var: f64,
) {
    let p0 = prior.initial_state();
    r.arr(
        &format!("{p}.prior_initial_state.mu0"),
        &p0.mu0,
        path(out, "prior_initial_state.mu0"),
        TOL_DET,
    );
    r.arr(
        &format!("{p}.prior_initial_state.Phi"),
        &mat_data(p0.phi.as_ref()),
        path(out, "prior_initial_state.Phi"),
        TOL_DET,
    );
    r.scalar(
        &format!("{p}.prior_initial_state.m"),
        p0.m,
        path(out, "prior_initial_state.m"),
        TOL_DET,
    );
    r.scalar(
        &format!("{p}.prior_initial_state.n0"),
        p0.n0,
        path(out, "prior_initial_state.n0"),
        TOL_DET,
    );
    let (x0mu, x0sigma) = fit_x0(x, n, d.t, d.dx, init_var, Some(&p0));
    r.arr(&format!("{p}.x0mu"), &x0mu, path(out, "x0mu"), TOL_DET);
    r.arr(
        &format!("{p}.x0sigma"),
        &mat_data(x0sigma.as_ref()),
        path(out, "x0sigma"),
        TOL_DET,
    );
}

/// What step 8 (step adjustment) of iteration `it` needs.
pub(super) struct StepAdjustCase<'a> {
    pub iters: &'a [Value],
    pub it: usize,
    pub inp: &'a Value,
    pub out: &'a Value,
    pub infos: &'a [Option<TrajInfo>],
    /// The controller a file names (`init_controller`, `iterations[i]`).
    pub resolve_prev: &'a dyn Fn(&str) -> Option<LinGaussPolicy>,
    /// (min, max) step multiplier.
    pub bounds: (f64, f64),
}

/// Step 8 of an iteration: the step adjustment against the recorded one; returns the step
/// multiplier the iteration continues with.
pub(super) fn check_step_adjust(
    r: &mut Report,
    p: &str,
    opt: &mut TrajOptLqr,
    c: StepAdjustCase<'_>,
) -> f64 {
    let StepAdjustCase {
        iters,
        it,
        inp,
        out,
        infos,
        resolve_prev,
        bounds: (min_sm, max_sm),
    } = c;
    let info = infos.get(it).cloned().flatten();
    let step_mult_start = opt_f64(inp, "step_mult_start", 1.0);
    let mut step_mult = step_mult_start;
    if let Some(sa_rec) = path(out, "step_adjust") {
        let prev_info = infos.get(it.wrapping_sub(1)).cloned().flatten();
        let prev_prev = it
            .checked_sub(1)
            .and_then(|i| iters.get(i))
            .and_then(|pv| path(pv, "inputs.prev_controller"))
            .and_then(Value::as_str)
            .and_then(|name| resolve_prev(name));
        let cur_pol = resolve_prev(
            req(inp, "prev_controller")
                .ok()
                .and_then(Value::as_str)
                .unwrap_or(""),
        );
        match (prev_info, prev_prev, cur_pol, info.as_ref()) {
            (Some(pi), Some(pp), Some(cp), Some(ci)) => {
                match step_adjust(opt, &pp, &pi, &cp, ci, step_mult_start, min_sm, max_sm) {
                    Ok(sa) => {
                        r.arr(
                            &format!("{p}.step_adjust.previous_laplace_obj"),
                            &sa.previous_laplace_obj,
                            field(sa_rec, "previous_laplace_obj"),
                            TOL_DET,
                        );
                        r.arr(
                            &format!("{p}.step_adjust.new_predicted_laplace_obj"),
                            &sa.new_predicted_laplace_obj,
                            field(sa_rec, "new_predicted_laplace_obj"),
                            TOL_DET,
                        );
                        r.arr(
                            &format!("{p}.step_adjust.new_actual_laplace_obj"),
                            &sa.new_actual_laplace_obj,
                            field(sa_rec, "new_actual_laplace_obj"),
                            TOL_DET,
                        );
                        r.scalar(
                            &format!("{p}.step_adjust.predicted_impr"),
                            sa.predicted_impr,
                            field(sa_rec, "predicted_impr"),
                            TOL_DET,
                        );
                        r.scalar(
                            &format!("{p}.step_adjust.actual_impr"),
                            sa.actual_impr,
                            field(sa_rec, "actual_impr"),
                            TOL_DET,
                        );
                        r.scalar(
                            &format!("{p}.step_adjust.step_mult_after"),
                            sa.step_mult_after,
                            field(sa_rec, "step_mult_after"),
                            TOL_DET,
                        );
                        step_mult = sa.step_mult_after;
                    }
                    Err(e) => r.fail(&format!("{p}.step_adjust"), e.to_string()),
                }
            }
            _ => r.skip(
                &format!("{p}.step_adjust"),
                "previous traj_info or controllers unavailable",
            ),
        }
    }
    step_mult
}

#[allow(clippy::too_many_arguments)]
pub(super) fn check_cost(
    r: &mut Report,
    p: &str,
    inp: &Value,
    out: &Value,
    x: &[f64],
    u: &[f64],
    n: usize,
    d: &Dims,
) {
    let Some(cd) = field(inp, "cost_derivs_per_sample") else {
        return r.skip(&format!("{p}.cost"), "cost_derivs_per_sample absent");
    };
    let (t, dx, du) = (d.t, d.dx, d.du);
    let get = |k: &str, len: usize| req_arr(cd, k, len).ok();
    let derivs = match (
        get("l", n * t),
        get("lx", n * t * dx),
        get("lu", n * t * du),
        get("lxx", n * t * dx * dx),
        get("luu", n * t * du * du),
        get("lux", n * t * du * dx),
    ) {
        (Some(l), Some(lx), Some(lu), Some(lxx), Some(luu), Some(lux)) => CostDerivs {
            l,
            lx,
            lu,
            lxx,
            luu,
            lux,
        },
        _ => return r.fail(&format!("{p}.cost"), "malformed cost_derivs_per_sample"),
    };
    let dd = dx + du;
    let mut cc = vec![0.0; t];
    let mut cv = MatSeq::zeros(t, dd, 1);
    let mut cm = MatSeq::zeros(t, dd, dd);
    eval_cost(x, u, &derivs, n, t, dx, du, &mut cc, &mut cv, &mut cm);
    r.arr(&format!("{p}.cost.cc"), &cc, path(out, "cost.cc"), TOL_DET);
    r.arr(
        &format!("{p}.cost.cv"),
        &cv.data,
        path(out, "cost.cv"),
        TOL_DET,
    );
    r.arr(
        &format!("{p}.cost.Cm"),
        &cm.data,
        path(out, "cost.Cm"),
        TOL_DET,
    );
    r.arr(
        &format!("{p}.cost.cs"),
        &derivs.l,
        path(out, "cost.cs"),
        TOL_DET,
    );
}

#[allow(clippy::too_many_arguments)]
pub(super) fn check_prior_and_fit(
    r: &mut Report,
    p: &str,
    cfg: &PriorGmmConfig,
    reg: f64,
    out: &Value,
    x: &[f64],
    u: &[f64],
    n: usize,
    d: &Dims,
) {
    let (t, dx, du) = (d.t, d.dx, d.du);
    let dj = 2 * dx + du;
    // Prior eval from the recorded GMM.
    match super::recorded::recorded_gmm(out, dj) {
        Some(g) => {
            let mut pr = DynamicsPriorGmm::new(cfg.clone(), t, dx, du);
            pr.gmm
                .set_params(g.k, &g.mu, &g.sigma, &g.logmass, g.self_n);
            let mut ys = Mat::<f64>::zeros(n, dj);
            let mut niw = NiwPrior::zeros(dj);
            let (mut mu0, mut phi, mut m, mut n0) =
                (Vec::new(), Vec::new(), Vec::new(), Vec::new());
            let mut ok = true;
            for s in 0..t - 1 {
                crate::dynamics::lr_prior::transitions_at(x, u, n, t, dx, du, s, ys.as_mut());
                if let Err(e) = pr.eval(ys.as_ref(), &mut niw) {
                    r.fail(&format!("{p}.prior_eval"), e.to_string());
                    ok = false;
                    break;
                }
                mu0.extend_from_slice(&niw.mu0);
                phi.extend(mat_data(niw.phi.as_ref()));
                m.push(niw.m);
                n0.push(niw.n0);
            }
            if ok {
                r.arr_norm(
                    &format!("{p}.prior_eval.mu0 (recorded gmm)"),
                    &mu0,
                    path(out, "prior_eval.mu0"),
                    TOL_DET,
                );
                r.arr_norm(
                    &format!("{p}.prior_eval.Phi (recorded gmm)"),
                    &phi,
                    path(out, "prior_eval.Phi"),
                    TOL_DET,
                );
                r.arr(
                    &format!("{p}.prior_eval.m (recorded gmm)"),
                    &m,
                    path(out, "prior_eval.m"),
                    TOL_DET,
                );
                r.arr(
                    &format!("{p}.prior_eval.n0 (recorded gmm)"),
                    &n0,
                    path(out, "prior_eval.n0"),
                    TOL_DET,
                );
            }
        }
        None => r.skip(&format!("{p}.prior_eval"), "recorded gmm absent"),
    }
    // Fit from the recorded prior_eval.
    let rec_prior = (|| {
        Some((
            req_arr(out, "prior_eval.mu0", (t - 1) * dj).ok()?,
            req_arr(out, "prior_eval.Phi", (t - 1) * dj * dj).ok()?,
            req_arr(out, "prior_eval.m", t - 1).ok()?,
            req_arr(out, "prior_eval.n0", t - 1).ok()?,
        ))
    })();
    let Some((mu0, phi, m, n0)) = rec_prior else {
        return r.skip(&format!("{p}.dynamics"), "recorded prior_eval absent");
    };
    let mut ws = FitWorkspace::new(n, dx, du);
    let mut dynm = Dynamics::zeros(t, dx, du);
    let mut step = 0usize;
    let res = fit_with(
        x,
        u,
        n,
        &LrPriorConfig {
            regularization: reg,
        },
        &mut ws,
        &mut dynm,
        |_, out| {
            out.mu0.copy_from_slice(&mu0[step * dj..(step + 1) * dj]);
            for a in 0..dj {
                for b in 0..dj {
                    out.phi[(a, b)] = phi[step * dj * dj + a * dj + b];
                }
            }
            out.m = m[step];
            out.n0 = n0[step];
            step += 1;
            Ok(())
        },
    );
    match res {
        Ok(()) => {
            r.arr(
                &format!("{p}.dynamics.Fm (recorded prior)"),
                &dynm.fm.data,
                path(out, "dynamics.Fm"),
                TOL_FM,
            );
            r.arr(
                &format!("{p}.dynamics.fv (recorded prior)"),
                &dynm.fv.data,
                path(out, "dynamics.fv"),
                TOL_FM,
            );
            r.arr(
                &format!("{p}.dynamics.dyn_covar (recorded prior)"),
                &dynm.dyn_covar.data,
                path(out, "dynamics.dyn_covar"),
                TOL_DYN_COVAR,
            );
        }
        Err(e) => r.fail(&format!("{p}.dynamics"), e.to_string()),
    }
}

#[allow(clippy::too_many_arguments)]
pub(super) fn check_chained_fit(
    r: &mut Report,
    p: &str,
    prior: &mut DynamicsPriorGmm,
    reg: f64,
    out: &Value,
    x: &[f64],
    u: &[f64],
    n: usize,
    d: &Dims,
) {
    let (t, dx, du) = (d.t, d.dx, d.du);
    let mut ws = FitWorkspace::new(n, dx, du);
    let mut dynm = Dynamics::zeros(t, dx, du);
    match crate::dynamics::lr_prior::fit(
        x,
        u,
        n,
        prior,
        &LrPriorConfig {
            regularization: reg,
        },
        &mut ws,
        &mut dynm,
    ) {
        Ok(()) => {
            r.arr_norm(
                &format!("{p}.dynamics.Fm (own EM chain)"),
                &dynm.fm.data,
                path(out, "dynamics.Fm"),
                TOL_FM,
            );
            r.arr_norm(
                &format!("{p}.dynamics.fv (own EM chain)"),
                &dynm.fv.data,
                path(out, "dynamics.fv"),
                TOL_FM,
            );
            r.arr_norm(
                &format!("{p}.dynamics.dyn_covar (own EM chain)"),
                &dynm.dyn_covar.data,
                path(out, "dynamics.dyn_covar"),
                TOL_DYN_COVAR,
            );
        }
        Err(e) => r.fail(&format!("{p}.dynamics (own EM chain)"), e.to_string()),
    }
}

#[allow(clippy::too_many_arguments)]
pub(super) fn check_eta_search(
    r: &mut Report,
    p: &str,
    opt: &mut TrajOptLqr,
    prev: &LinGaussPolicy,
    info: &TrajInfo,
    eta_start: f64,
    kl_step: f64,
    out: &Value,
) {
    let mut newp = LinGaussPolicy::zeros(prev.t, prev.dx, prev.du);
    let res = match opt.update(prev, info, eta_start, kl_step, &mut newp) {
        Ok(x) => x,
        Err(e) => return r.fail(&format!("{p}.dgd"), e.to_string()),
    };
    if let Some(tr) = path(out, "dgd_trace").and_then(Value::as_array) {
        r.exact(
            &format!("{p}.dgd_trace.len"),
            res.trace.len(),
            Some(tr.len()),
        );
        let n_att_got: Vec<usize> = res.trace.iter().map(|s| s.attempt_etas.len()).collect();
        let n_att_exp: Vec<usize> = tr
            .iter()
            .map(|s| {
                field(s, "attempt_etas")
                    .and_then(Value::as_array)
                    .map_or(0, |a| a.len())
            })
            .collect();
        r.exact(
            &format!("{p}.dgd_trace.attempt_counts"),
            format!("{n_att_got:?}"),
            Some(format!("{n_att_exp:?}")),
        );
        if res.trace.len() == tr.len() && n_att_got == n_att_exp {
            let mut g = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
            let mut e = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
            for (s, es) in res.trace.iter().zip(tr) {
                g.0.push(s.eta_in);
                g.1.push(s.eta_out);
                g.2.extend_from_slice(&s.attempt_etas);
                g.3.push(s.kl);
                e.0.push(es["eta_in"].clone());
                e.1.push(es["eta_out"].clone());
                e.2.extend(es["attempt_etas"].as_array().cloned().unwrap_or_default());
                e.3.push(es["kl"].clone());
            }
            r.arr(
                &format!("{p}.dgd_trace.eta_in"),
                &g.0,
                Some(&Value::Array(e.0)),
                TOL_DET,
            );
            r.arr(
                &format!("{p}.dgd_trace.eta_out"),
                &g.1,
                Some(&Value::Array(e.1)),
                TOL_DET,
            );
            r.arr(
                &format!("{p}.dgd_trace.attempt_etas"),
                &g.2,
                Some(&Value::Array(e.2)),
                TOL_DET,
            );
            r.arr(
                &format!("{p}.dgd_trace.kl"),
                &g.3,
                Some(&Value::Array(e.3)),
                TOL_DET,
            );
        }
    } else {
        r.skip(&format!("{p}.dgd_trace"), "absent in file");
    }
    r.exact(
        &format!("{p}.dgd_converged"),
        res.converged,
        path(out, "dgd_converged").and_then(Value::as_bool),
    );
    r.scalar(
        &format!("{p}.eta_final"),
        res.eta,
        path(out, "eta_final"),
        TOL_DET,
    );
    r.policy(
        &format!("{p}.new_controller"),
        &newp,
        path(out, "new_controller"),
        TOL_DET,
    );
    let (mu, sigma) = opt.forward(&newp, info);
    r.arr(
        &format!("{p}.new_forward.mu"),
        &mu.data,
        path(out, "new_forward.mu"),
        TOL_DET,
    );
    r.arr(
        &format!("{p}.new_forward.sigma"),
        &sigma.data,
        path(out, "new_forward.sigma"),
        TOL_DET,
    );
    let (mu, sigma) = opt.forward(prev, info);
    r.arr(
        &format!("{p}.prev_forward.mu"),
        &mu.data,
        path(out, "prev_forward.mu"),
        TOL_DET,
    );
    r.arr(
        &format!("{p}.prev_forward.sigma"),
        &sigma.data,
        path(out, "prev_forward.sigma"),
        TOL_DET,
    );
    match opt.kl(&newp, info, &newp, prev, false) {
        Ok((kl, tot)) => {
            r.arr(
                &format!("{p}.kl_new_vs_prev_per_step"),
                &kl,
                path(out, "kl_new_vs_prev_per_step"),
                TOL_DET,
            );
            r.scalar(
                &format!("{p}.kl_new_vs_prev_total"),
                tot,
                path(out, "kl_new_vs_prev_total"),
                TOL_DET,
            );
        }
        Err(e) => r.fail(&format!("{p}.kl"), e.to_string()),
    }
    match opt.kl(prev, info, &newp, prev, true) {
        Ok((kl, _)) => r.arr(
            &format!("{p}.kl_alt_under_prev_per_step"),
            &kl,
            path(out, "kl_alt_under_prev_per_step"),
            TOL_DET,
        ),
        Err(e) => r.fail(&format!("{p}.kl_alt"), e.to_string()),
    }
}
