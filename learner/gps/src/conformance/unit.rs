//! The comparisons of the vectors file's unit cases (`unit.*`) and of the initial controller.

use faer::{Mat, MatRef};
use serde_json::Value;

use super::json::*;
use super::{rel_err, ConformanceError, Report, TOL_DET, TOL_DYN_COVAR, TOL_FM};
use crate::algorithm::step_adjust::set_new_mult;
use crate::dynamics::gmm::{ClusterInit, Gmm};
use crate::dynamics::{lr, Dynamics};
use crate::policy::init::{init_lqr, init_pd, InitLqrConfig, InitPdConfig};
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::traj_opt::lqr::{TrajInfo, TrajOptConfig, TrajOptLqr};

/// The unit cases of a vectors file (`unit.*`).
#[allow(clippy::too_many_arguments)]
pub(super) fn check_units(
    r: &mut Report,
    v: &Value,
    iters: &[Value],
    opt: &mut TrajOptLqr,
    opt_cfg: &TrajOptConfig,
    init_rec: &LinGaussPolicy,
    info0: Option<&TrajInfo>,
    (min_sm, max_sm): (f64, f64),
    d: &Dims,
) -> Result<(), ConformanceError> {
    let (t_len, dx, du) = (d.t, d.dx, d.du);
    let unit = path(v, "unit");
    if let (Some(bf), Some(info0)) = (
        unit.and_then(|u| path(u, "backward_fixed_eta.cases"))
            .and_then(Value::as_array),
        info0,
    ) {
        for (i, c) in bf.iter().enumerate() {
            check_backward_case(
                r,
                &format!("unit.backward_fixed_eta[{i}]"),
                opt,
                init_rec,
                info0,
                c,
            );
        }
    } else {
        r.skip("unit.backward_fixed_eta", "absent in file");
    }
    match (unit.and_then(|u| field(u, "cons_per_step")), info0) {
        (Some(c), Some(info0)) => check_cons_per_step(r, opt_cfg, init_rec, info0, c, d),
        _ => r.skip("unit.cons_per_step", "absent in file"),
    }
    match unit.and_then(|u| field(u, "dynamics_lr_noprior")) {
        Some(c) => {
            let inp = req(&iters[0], "inputs")?;
            let n = req(inp, "X")?.as_array().map(|a| a.len()).unwrap_or(d.n);
            let x = req_arr(inp, "X", n * t_len * dx)?;
            let u = req_arr(inp, "U", n * t_len * du)?;
            let mut dynm = Dynamics::zeros(t_len, dx, du);
            match lr::fit(&x, &u, n, 1e-6, &mut dynm) {
                Ok(()) => check_lr_noprior(r, c, &dynm, &x, &u, n, d),
                Err(e) => r.fail("unit.dynamics_lr_noprior", e.to_string()),
            }
        }
        None => r.skip("unit.dynamics_lr_noprior", "absent in file"),
    }
    match unit.and_then(|u| field(u, "gmm_em_short")) {
        Some(c) => check_gmm_short(r, c, d),
        None => r.skip("unit.gmm_em_short", "absent in file"),
    }
    match unit.and_then(|u| path(u, "set_new_mult")) {
        Some(c) => {
            let lo = opt_f64(c, "min_step_mult", min_sm);
            let hi = opt_f64(c, "max_step_mult", max_sm);
            let cases = field(c, "cases")
                .and_then(Value::as_array)
                .cloned()
                .unwrap_or_default();
            let mut got = Vec::new();
            let mut exp = Vec::new();
            for cs in &cases {
                got.push(set_new_mult(
                    req_f64(cs, "predicted_impr")?,
                    req_f64(cs, "actual_impr")?,
                    req_f64(cs, "step_mult_before")?,
                    lo,
                    hi,
                ));
                exp.push(Value::from(req_f64(cs, "step_mult_after")?));
            }
            r.arr(
                &format!("unit.set_new_mult ({} cases)", cases.len()),
                &got,
                Some(&Value::Array(exp)),
                TOL_DET,
            );
        }
        None => r.skip("unit.set_new_mult", "absent in file"),
    }
    Ok(())
}

pub(super) fn check_init(r: &mut Report, v: &Value, hp: &Value, d: &Dims, rec: &LinGaussPolicy) {
    let kind = path(hp, "init_traj_distr_kind")
        .and_then(Value::as_str)
        .unwrap_or("");
    let Some(x0) = path(v, "hyperparams.x0_used_by_init")
        .and_then(|x| flatten(x).ok())
        .map(|x| x.0)
    else {
        return r.skip("init_controller", "x0_used_by_init absent");
    };
    let it = path(hp, "init_traj_distr");
    let g = |k: &str, def: f64| {
        it.and_then(|i| path(i, k))
            .and_then(Value::as_f64)
            .unwrap_or(def)
    };
    let list = |k: &str| {
        it.and_then(|i| path(i, k))
            .and_then(|x| flatten(x).ok())
            .map(|x| x.0)
            .unwrap_or_default()
    };
    let res = match kind {
        "init_lqr" => {
            let c = InitLqrConfig {
                init_var: g("init_var", 1.0),
                stiffness: g("stiffness", 1.0),
                stiffness_vel: g("stiffness_vel", 0.5),
                final_weight: g("final_weight", 1.0),
                init_gains: list("init_gains"),
                init_acc: list("init_acc"),
                dt: g("dt", 0.05),
            };
            init_lqr(&c, &x0, d.t, d.dx, d.du)
        }
        "init_pd" => {
            let c = InitPdConfig {
                init_var: g("init_var", 10.0),
                pos_gains: g("pos_gains", 10.0),
                vel_gains_mult: g("vel_gains_mult", 0.01),
                dq: g("dQ", d.du as f64) as usize,
            };
            init_pd(&c, &x0, d.t, d.dx, d.du)
        }
        _ => return r.skip("init_controller", "unknown init_traj_distr_kind"),
    };
    match res {
        Ok(p) => {
            let recv = serde_json::json!({
                "K": rec.gain.data, "k": rec.k.data, "pol_covar": rec.pol_covar.data,
                "chol_pol_covar": rec.chol_pol_covar.data, "inv_pol_covar": rec.inv_pol_covar.data,
            });
            r.policy(
                &format!("init_controller ({kind})"),
                &p,
                Some(&recv),
                TOL_DET,
            );
        }
        Err(e) => r.fail("init_controller", e.to_string()),
    }
}

pub(super) fn check_backward_case(
    r: &mut Report,
    p: &str,
    opt: &mut TrajOptLqr,
    prev: &LinGaussPolicy,
    info: &TrajInfo,
    c: &Value,
) {
    let Some(eta_in) = field(c, "eta_in").and_then(Value::as_f64) else {
        return r.skip(p, "eta_in absent");
    };
    let mut eta = [eta_in];
    let mut newp = LinGaussPolicy::zeros(prev.t, prev.dx, prev.du);
    let attempts = match opt.backward(prev, info, &mut eta, &mut newp) {
        Ok(a) => a,
        Err(e) => return r.fail(p, e.to_string()),
    };
    let p = format!("{p} eta={eta_in:.3e}");
    r.scalar(
        &format!("{p}.eta_out"),
        eta[0],
        field(c, "eta_out"),
        TOL_DET,
    );
    let n_exp = field(c, "attempt_etas")
        .and_then(Value::as_array)
        .map(|a| a.len());
    r.exact(&format!("{p}.attempt_count"), attempts.len(), n_exp);
    if Some(attempts.len()) == n_exp {
        r.arr(
            &format!("{p}.attempt_etas"),
            &attempts,
            field(c, "attempt_etas"),
            TOL_DET,
        );
    }
    r.policy(
        &format!("{p}.controller"),
        &newp,
        field(c, "controller"),
        TOL_DET,
    );
    let (mu, sigma) = opt.forward(&newp, info);
    r.arr(
        &format!("{p}.forward.mu"),
        &mu.data,
        path(c, "forward.mu"),
        TOL_DET,
    );
    r.arr(
        &format!("{p}.forward.sigma"),
        &sigma.data,
        path(c, "forward.sigma"),
        TOL_DET,
    );
    match opt.kl(&newp, info, &newp, prev, false) {
        Ok((kl, tot)) => {
            r.arr(
                &format!("{p}.kl_per_step"),
                &kl,
                field(c, "kl_per_step"),
                TOL_DET,
            );
            r.scalar(&format!("{p}.kl_total"), tot, field(c, "kl_total"), TOL_DET);
        }
        Err(e) => r.fail(&format!("{p}.kl"), e.to_string()),
    }
}

pub(super) fn check_cons_per_step(
    r: &mut Report,
    cfg: &TrajOptConfig,
    prev: &LinGaussPolicy,
    info: &TrajInfo,
    c: &Value,
    d: &Dims,
) {
    let p = "unit.cons_per_step";
    let Ok(kl_step) = req_arr(c, "kl_step", d.t) else {
        return r.fail(p, "kl_step missing");
    };
    let mut cfg = cfg.clone();
    cfg.cons_per_step = true;
    let mut opt = TrajOptLqr::new(cfg, d.t, d.dx, d.du);
    let mut newp = LinGaussPolicy::zeros(d.t, d.dx, d.du);
    let res = match opt.update_per_step(prev, info, &vec![1.0; d.t], &kl_step, &mut newp) {
        Ok(x) => x,
        Err(e) => return r.fail(p, e.to_string()),
    };
    r.exact(
        &format!("{p}.n_backward_calls"),
        res.trace_eta_in.len(),
        field(c, "n_backward_calls")
            .and_then(Value::as_u64)
            .map(|x| x as usize),
    );
    let exp_calls = field(c, "trace_eta_in")
        .and_then(Value::as_array)
        .map(|a| a.len());
    if exp_calls == Some(res.trace_eta_in.len()) {
        let te: Vec<f64> = res.trace_eta_in.concat();
        let tk: Vec<f64> = res.trace_kl.concat();
        r.arr(
            &format!("{p}.trace_eta_in"),
            &te,
            field(c, "trace_eta_in"),
            TOL_DET,
        );
        r.arr(&format!("{p}.trace_kl"), &tk, field(c, "trace_kl"), TOL_DET);
    }
    r.arr(
        &format!("{p}.eta_final"),
        &res.eta,
        field(c, "eta_final"),
        TOL_DET,
    );
    r.policy(
        &format!("{p}.controller"),
        &newp,
        field(c, "controller"),
        TOL_DET,
    );
    match opt.kl(&newp, info, &newp, prev, false) {
        Ok((kl, _)) => r.arr(
            &format!("{p}.kl_per_step"),
            &kl,
            field(c, "kl_per_step"),
            TOL_DET,
        ),
        Err(e) => r.fail(&format!("{p}.kl"), e.to_string()),
    }
}

pub(super) fn check_gmm_short(r: &mut Report, c: &Value, d: &Dims) {
    let p = "unit.gmm_em_short";
    let dj = 2 * d.dx + d.du;
    let (Some(k), Some(maxit)) = (
        field(c, "K").and_then(Value::as_u64),
        field(c, "max_iterations").and_then(Value::as_u64),
    ) else {
        return r.fail(p, "K / max_iterations missing");
    };
    let (k, maxit) = (k as usize, maxit as usize);
    let Some((data, shape)) = field(c, "data").and_then(|x| flatten(x).ok()) else {
        return r.fail(p, "data missing");
    };
    if shape.len() != 2 || shape[1] != dj {
        return r.fail(p, format!("data shape {shape:?}"));
    }
    let n = shape[0];
    let Some(idx) = usize_list(field(c, "init_cluster_idx")) else {
        return r.fail(p, "init_cluster_idx missing");
    };
    let dm = MatRef::from_row_major_slice(&data, n, dj);
    let mut g = Gmm::new(dj);
    match g.update(dm, k, maxit, ClusterInit::Given(&idx)) {
        Ok(rep) => {
            r.exact(
                &format!("{p}.stop"),
                rep.stop.as_str(),
                field(c, "stop").and_then(Value::as_str),
            );
            r.arr(
                &format!("{p}.ll_trace"),
                &rep.ll_trace,
                field(c, "ll_trace"),
                TOL_DET,
            );
            r.arr(&format!("{p}.mu"), &g.mu, field(c, "mu"), TOL_DET);
            r.arr(
                &format!("{p}.sigma"),
                &g.sigma.data,
                field(c, "sigma"),
                TOL_DET,
            );
            r.arr(
                &format!("{p}.logmass"),
                &g.logmass,
                field(c, "logmass"),
                TOL_DET,
            );
            r.exact(
                &format!("{p}.self_N"),
                g.n,
                field(c, "self_N")
                    .and_then(Value::as_u64)
                    .map(|x| x as usize),
            );
        }
        Err(e) => return r.fail(p, e.to_string()),
    }
    let Some(inf) = field(c, "inference_t3") else {
        return r.skip(&format!("{p}.inference_t3"), "absent in file");
    };
    let Some((pts, ps)) = field(inf, "pts").and_then(|x| flatten(x).ok()) else {
        return r.fail(&format!("{p}.inference_t3"), "pts missing");
    };
    let pm = MatRef::from_row_major_slice(&pts, ps[0], dj);
    let mut mu0 = vec![0.0; dj];
    let mut phi = Mat::<f64>::zeros(dj, dj);
    match g.inference(pm, &mut mu0, phi.as_mut()) {
        Ok((m, n0)) => {
            r.arr(
                &format!("{p}.inference_t3.logwts"),
                &g.last_logwts,
                field(inf, "logwts"),
                TOL_DET,
            );
            r.arr(
                &format!("{p}.inference_t3.mu0"),
                &mu0,
                field(inf, "mu0"),
                TOL_DET,
            );
            r.arr(
                &format!("{p}.inference_t3.Phi"),
                &mat_data(phi.as_ref()),
                field(inf, "Phi"),
                TOL_DET,
            );
            r.scalar(&format!("{p}.inference_t3.m"), m, field(inf, "m"), TOL_DET);
            r.scalar(
                &format!("{p}.inference_t3.n0"),
                n0,
                field(inf, "n0"),
                TOL_DET,
            );
        }
        Err(e) => r.fail(&format!("{p}.inference_t3"), e.to_string()),
    }
}

/// `DynamicsLR` check. With `N <= dX + dU` samples the regularised block
/// `Σ_[xu][xu] = empirical covariance (rank <= N−1) + 1e-6·11ᵀ (rank 1)` is singular, so
/// `np.linalg.solve` returns one of infinitely many solutions, chosen by BLAS rounding; `Fm`
/// and `fv` are then compared for information only (skipped). What is determined is the fit
/// itself: the predictions `Fm [x; u] + fv` on the fitted transitions, and `dyn_covar` (≈ 0),
/// which are gated. With more samples everything is compared as usual.
pub(super) fn check_lr_noprior(
    r: &mut Report,
    c: &Value,
    got: &Dynamics,
    x: &[f64],
    u: &[f64],
    n: usize,
    d: &Dims,
) {
    let p = "unit.dynamics_lr_noprior";
    let (t, dx, du) = (d.t, d.dx, d.du);
    let rec = match load_dynamics(c, d) {
        Ok(x) => x,
        Err(e) => return r.fail(p, e.to_string()),
    };
    if n > dx + du {
        r.arr(&format!("{p}.Fm"), &got.fm.data, field(c, "Fm"), TOL_FM);
        r.arr(&format!("{p}.fv"), &got.fv.data, field(c, "fv"), TOL_FM);
        r.arr(
            &format!("{p}.dyn_covar"),
            &got.dyn_covar.data,
            field(c, "dyn_covar"),
            TOL_DYN_COVAR,
        );
        return;
    }
    let why = |e: f64| {
        format!(
            "not determined: N={n} <= dX+dU={} makes Σ_[xu][xu] singular; raw max_rel_err {e:.2e}",
            dx + du
        )
    };
    r.skip(
        &format!("{p}.Fm (raw)"),
        &why(rel_err(&got.fm.data, &rec.fm.data)),
    );
    r.skip(
        &format!("{p}.fv (raw)"),
        &why(rel_err(&got.fv.data, &rec.fv.data)),
    );
    let predict = |dy: &Dynamics| {
        let mut out = Vec::with_capacity(n * (t - 1) * dx);
        for s in 0..n {
            for k in 0..t - 1 {
                let f = dy.fm.mat(k);
                for i in 0..dx {
                    let mut acc = dy.fv.slice(k)[i];
                    for j in 0..dx {
                        acc += f[(i, j)] * x[(s * t + k) * dx + j];
                    }
                    for j in 0..du {
                        acc += f[(i, dx + j)] * u[(s * t + k) * du + j];
                    }
                    out.push(acc);
                }
            }
        }
        out
    };
    let pe = Value::from(predict(&rec));
    r.arr(
        &format!("{p}.predictions Fm[x;u]+fv on fitted points"),
        &predict(got),
        Some(&pe),
        TOL_FM,
    );
    // dyn_covar is rounding noise around 0: measure it against the spread of x_{t+1}.
    let mut worst: f64 = 0.0;
    for k in 0..t - 1 {
        let mut var: f64 = 0.0;
        for i in 0..dx {
            let m: f64 = (0..n).map(|s| x[(s * t + k + 1) * dx + i]).sum::<f64>() / n as f64;
            let v: f64 = (0..n)
                .map(|s| (x[(s * t + k + 1) * dx + i] - m).powi(2))
                .sum::<f64>()
                / n as f64;
            var = var.max(v);
        }
        for (g, e) in got.dyn_covar.slice(k).iter().zip(rec.dyn_covar.slice(k)) {
            worst = worst.max((g - e).abs() / var.max(f64::MIN_POSITIVE));
        }
    }
    r.gate(
        &format!("{p}.dyn_covar (relative to var x_t+1)"),
        worst,
        TOL_DYN_COVAR,
        "",
    );
}
