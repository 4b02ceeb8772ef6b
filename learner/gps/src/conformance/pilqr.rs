//! Conformance of PI2 and PILQR with GPS's recorded vectors (`pilqr_*.json`, layout in
//! tests/data/gps-vectors/README.md): `approximated_cost`, the LQR half, PI2 on the residual
//! at GPS's temperatures, the fitted temperatures (never worse on the dual than scipy's),
//! the `res_percent` step rule, and `update_pi2` unit cases.

use serde_json::Value;

use super::json::*;
use super::{ConformanceError, Report, TOL_DET};
use crate::linalg::MatSeq;
use crate::traj_opt::lqr::{TrajOptConfig, TrajOptLqr};
use crate::traj_opt::pi2::{kl_dual, Pi2Config, Temperature, TrajOptPi2};
use crate::traj_opt::pilqr::{
    approximated_cost, res_percent_step_mult, res_percent_step_mult_per_step, residual_share,
    PilqrConfig, TrajOptPilqr,
};

/// Slack on the dual at our temperature against the dual at scipy's (relative): ours is the
/// exact minimiser, scipy's stops at a projected gradient of 1e-5.
pub const TOL_DUAL: f64 = 1e-12;
/// Our fitted temperatures against scipy's L-BFGS-B ones, and what follows from them (the
/// controller of a whole PILQR step with fitted temperatures): scipy stops early (measured
/// ≤ 3e-5 on η, ≤ 1.5e-4 on the controller).
pub const TOL_FITTED: f64 = 1e-3;

/// Runs every check of a PILQR vectors file.
pub(super) fn run(v: &Value) -> Result<Report, ConformanceError> {
    let mut r = Report::default();
    let d = Dims::of(v)?;
    let (t_len, dx, du, n) = (d.t, d.dx, d.du, d.n);
    let dd = dx + du;
    let inp = req(v, "inputs")?;
    let info = load_traj_info(inp, &d)?;
    let executed = load_policy(req(inp, "controller")?, &d)?;
    let noise = req_arr(inp, "noise", n * t_len * du)?;
    let cs = req_arr(inp, "cs", n * t_len)?;
    let hp = req(v, "hyperparams")?;
    let per_step = path(hp, "traj_opt.cons_per_step")
        .and_then(Value::as_bool)
        .unwrap_or(false);
    let alg = req(hp, "algorithm")?;
    let pi2_hp = req(hp, "pi2")?;
    let pcfg = PilqrConfig {
        kl_threshold: req_f64(pi2_hp, "kl_threshold")?,
        covariance_damping: req_f64(pi2_hp, "covariance_damping")?,
        min_temperature: req_f64(pi2_hp, "min_temperature")?,
        del0: req_f64(pi2_hp, "del0")?,
        ..PilqrConfig::GPS_DEFAULTS
    };

    // approximated_cost of the executed controller.
    let mut mu = vec![0.0; n * t_len * dd];
    let mut pred = vec![0.0; n * t_len];
    if let Err(e) = approximated_cost(&noise, n, &executed, &info, &mut mu, &mut pred) {
        r.fail("approximated_cost", e.to_string());
    }
    r.arr(
        "approximated_cost.mu",
        &mu,
        path(v, "approximated_cost.mu"),
        TOL_DET,
    );
    r.arr(
        "approximated_cost.predicted_cost",
        &pred,
        path(v, "approximated_cost.predicted_cost"),
        TOL_DET,
    );

    // The LQR half (GPS TrajOptLQRPython.update inside TrajOptPILQR.update).
    let pu = req(v, "pilqr_update")?;
    let opt_cfg = TrajOptConfig {
        cons_per_step: per_step,
        max_ent_traj: req_f64(alg, "max_ent_traj")?,
        ..TrajOptConfig::default()
    };
    let mut opt = TrajOptLqr::new(opt_cfg, t_len, dx, du);
    let mut lqr = executed.clone();
    let step_mult = opt_f64(inp, "step_mult", 1.0);
    let eta_start = opt_f64(inp, "eta_start", 1.0);
    if per_step {
        let kl: Vec<f64> = req_arr(alg, "kl_step", t_len)?
            .iter()
            .map(|k| k * step_mult)
            .collect();
        match opt.update_per_step(&executed, &info, &vec![eta_start; t_len], &kl, &mut lqr) {
            Ok(res) => r.arr(
                "pilqr_update.lqr_eta",
                &res.eta,
                path(pu, "lqr_eta"),
                TOL_DET,
            ),
            Err(e) => r.fail("pilqr_update.lqr", e.to_string()),
        }
    } else {
        let kl = req_f64(alg, "kl_step")? * step_mult * t_len as f64;
        match opt.update(&executed, &info, eta_start, kl, &mut lqr) {
            Ok(res) => r.scalar(
                "pilqr_update.lqr_eta",
                res.eta,
                path(pu, "lqr_eta"),
                TOL_DET,
            ),
            Err(e) => r.fail("pilqr_update.lqr", e.to_string()),
        }
    }
    r.policy(
        "pilqr_update.lqr_controller",
        &lqr,
        path(pu, "lqr_controller"),
        TOL_DET,
    );

    // The PI2 half from the recorded LQR controller: at GPS's temperatures (strict), then with
    // our own fitted ones.
    let lqr_rec = load_policy(req(pu, "lqr_controller")?, &d)?;
    let eta_rec = req_arr(pu, "eta_pi2", t_len)?;
    let mut pilqr = TrajOptPilqr::new(pcfg.clone(), t_len, dx, du, n);
    let share = pilqr.predict(&noise, &cs, n, &executed, &info);
    let mut pol = lqr_rec.clone();
    match share.and_then(|_| pilqr.update(&noise, &cs, n, &mut pol, Some(&eta_rec))) {
        Ok(_) => {
            r.arr(
                "pilqr_update.residual_cost",
                pilqr.residual(),
                path(pu, "residual_cost"),
                TOL_DET,
            );
            r.policy(
                "pilqr_update.controller (GPS temperatures)",
                &pol,
                path(pu, "controller"),
                TOL_DET,
            );
        }
        Err(e) => r.fail("pilqr_update.pi2", e.to_string()),
    }
    let mut pol = lqr_rec.clone();
    match pilqr.update(&noise, &cs, n, &mut pol, None) {
        Ok(_) => {
            let eta = pilqr.eta().to_vec();
            check_duals(
                &mut r,
                "pilqr_update.eta_pi2",
                &eta,
                &eta_rec,
                &cs,
                n,
                t_len,
                pcfg.kl_threshold,
            );
            r.arr(
                "pilqr_update.eta_pi2 (fitted)",
                &eta,
                Some(req(pu, "eta_pi2")?),
                TOL_FITTED,
            );
            r.policy(
                "pilqr_update.controller (fitted temperatures)",
                &pol,
                path(pu, "controller"),
                TOL_FITTED,
            );
        }
        Err(e) => r.fail("pilqr_update.pi2 (fitted)", e.to_string()),
    }

    // The res_percent step rule.
    let share = residual_share(&pred, &cs, n, t_len);
    let cases = req(v, "step_rule_res_percent.cases")?
        .as_array()
        .ok_or_else(|| ConformanceError::Field("step_rule_res_percent.cases".into()))?;
    for (i, c) in cases.iter().enumerate() {
        let name = format!("step_rule_res_percent[{i}].step_mult_after");
        let (cd, ci) = (
            req_f64(c, "step_rule_res_ratio_dec")?,
            req_f64(c, "step_rule_res_ratio_inc")?,
        );
        if per_step {
            let mut m = req_arr(c, "step_mult_before", t_len)?;
            let min = req_arr(alg, "min_step_mult", t_len)?;
            let max = req_arr(alg, "max_step_mult", t_len)?;
            res_percent_step_mult_per_step(&pred, &cs, n, t_len, cd, ci, &min, &max, &mut m);
            r.arr(&name, &m, path(c, "step_mult_after"), 0.0);
        } else {
            let got = res_percent_step_mult(
                share,
                req_f64(c, "step_mult_before")?,
                cd,
                ci,
                req_f64(alg, "min_step_mult")?,
                req_f64(alg, "max_step_mult")?,
            );
            r.scalar(&name, got, path(c, "step_mult_after"), 0.0);
        }
    }

    // update_pi2 unit cases.
    let cases = req(v, "pi2_update.cases")?
        .as_array()
        .ok_or_else(|| ConformanceError::Field("pi2_update.cases".into()))?;
    for (i, c) in cases.iter().enumerate() {
        let p = format!("pi2_update[{i}]");
        let s = req(c, "samples")?.as_array().map(|a| a.len()).unwrap_or(0);
        let cfg = Pi2Config {
            kl_threshold: req_f64(c, "kl_threshold")?,
            covariance_damping: req_f64(c, "covariance_damping")?,
            min_temperature: req_f64(c, "min_temperature")?,
            ..Pi2Config::default()
        };
        let samples = req_arr(c, "samples", s * t_len * du)?;
        let costs = req_arr(c, "costs", s * t_len)?;
        let cov_old = MatSeq::from_vec(t_len, du, du, req_arr(c, "cov_old", t_len * du * du)?);
        let fixed: Option<Vec<f64>> = match path(c, "fixed_eta") {
            None | Some(Value::Null) => None,
            Some(Value::Number(x)) => Some(vec![x.as_f64().unwrap_or(f64::NAN); t_len]),
            Some(_) => Some(req_arr(c, "fixed_eta", t_len)?),
        };
        // At GPS's temperatures (given, or scipy's fitted ones): strict.
        let eta = match &fixed {
            Some(e) => e.clone(),
            None => req_arr(c, "etas", t_len)?,
        };
        let mut pi2 = TrajOptPi2::new(cfg.clone(), t_len, du, s);
        match pi2.update_pi2(&samples, &costs, s, &cov_old, Temperature::Fixed(&eta)) {
            Ok(out) => {
                r.arr(
                    &format!("{p}.mean_new"),
                    &out.mean.data,
                    path(c, "mean_new"),
                    TOL_DET,
                );
                r.arr(
                    &format!("{p}.cov_new"),
                    &out.cov.data,
                    path(c, "cov_new"),
                    TOL_DET,
                );
                r.arr(
                    &format!("{p}.inv_cov_new"),
                    &out.inv_cov.data,
                    path(c, "inv_cov_new"),
                    TOL_DET,
                );
                r.arr(
                    &format!("{p}.chol_cov_new"),
                    &out.chol_cov.data,
                    path(c, "chol_cov_new"),
                    TOL_DET,
                );
            }
            Err(e) => r.fail(&p, e.to_string()),
        }
        if fixed.is_none() {
            match pi2.update_pi2(&samples, &costs, s, &cov_old, Temperature::Fitted) {
                Ok(out) => {
                    let ours = out.eta.clone();
                    check_duals(
                        &mut r,
                        &format!("{p}.etas"),
                        &ours,
                        &eta,
                        &costs,
                        s,
                        t_len,
                        cfg.kl_threshold,
                    );
                    r.arr(
                        &format!("{p}.etas (fitted)"),
                        &ours,
                        path(c, "etas"),
                        TOL_FITTED,
                    );
                }
                Err(e) => r.fail(&format!("{p} (fitted)"), e.to_string()),
            }
        }
    }
    Ok(r)
}

/// The dual at our temperatures is no higher than at GPS's (per step, on the costs-to-go).
#[allow(clippy::too_many_arguments)]
fn check_duals(
    r: &mut Report,
    name: &str,
    ours: &[f64],
    gps: &[f64],
    costs: &[f64],
    n: usize,
    t_len: usize,
    kl_threshold: f64,
) {
    let mut worst: f64 = f64::NEG_INFINITY;
    for t in 0..t_len {
        let ctg: Vec<f64> = (0..n)
            .map(|i| costs[i * t_len + t..(i + 1) * t_len].iter().sum())
            .collect();
        let (a, b) = (
            kl_dual(ours[t], kl_threshold, &ctg),
            kl_dual(gps[t], kl_threshold, &ctg),
        );
        worst = worst.max((a - b) / b.abs().max(1.0));
    }
    r.gate(
        &format!("{name}: dual at ours <= dual at GPS's"),
        worst.max(0.0),
        TOL_DUAL,
        format!("largest (ours - GPS) / max(|GPS|, 1) = {worst:e}"),
    );
}
