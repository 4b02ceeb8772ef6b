//! Conformance against the GPS reference vectors (shared/gps-vectors/README.md): run every
//! learner piece from the recorded inputs of a `problem_*.json` file and compare with the
//! recorded outputs.
//!
//! Error measure: for each quantity, `max_i |got_i − exp_i| / max(|exp_i|, 1e-3 · max_j |exp_j|)`
//! (relative, with a floor so that entries that are tiny next to the rest of the array, and so
//! carry the rounding error of the large entries they were computed from, do not dominate).
//! Quantities formed by cancellation inside GMM mixtures (full EM runs, the prior's `μ0`/`Φ`,
//! and the dynamics chained from this port's own EM) are gated on the normwise error
//! `max|Δ| / max|exp|` instead, with the elementwise error printed alongside; the README
//! quantifies these as "about 1e-11" in μ/σ, i.e. at the scale of the array.
//! Discrete quantities (counts, flags, stop reasons) must match exactly. Tolerances follow the
//! README: 1e-9 for the deterministic LQR, cost, prior and step pieces; 1e-6 on `Fm`/`fv`;
//! 1e-8 on `dyn_covar`; 1e-8 on full GMM EM runs. Fields that are null or absent are reported
//! as skipped.

use std::fmt;

use faer::{Mat, MatRef};
use serde_json::Value;

use crate::algorithm::eval_cost::{eval_cost, CostDerivs};
use crate::algorithm::init_state::fit_x0;
use crate::algorithm::step_adjust::{set_new_mult, step_adjust};
use crate::dynamics::gmm::{ClusterInit, EmStop, Gmm};
use crate::dynamics::lr_prior::{fit_with, FitWorkspace, LrPriorConfig};
use crate::dynamics::prior_gmm::{DynamicsPriorGmm, NiwPrior, PriorGmmConfig};
use crate::dynamics::{lr, Dynamics};
use crate::linalg::MatSeq;
use crate::policy::init::{init_lqr, init_pd, InitLqrConfig, InitPdConfig};
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::traj_opt::lqr::{TrajInfo, TrajOptConfig, TrajOptLqr};

/// Tolerance for deterministic pieces (README: "suggest rtol ≈ 1e-9").
pub const TOL_DET: f64 = 1e-9;
/// Tolerance on `Fm`, `fv` (README: 1e-6).
pub const TOL_FM: f64 = 1e-6;
/// Tolerance on `dyn_covar` (README: 1e-8).
pub const TOL_DYN_COVAR: f64 = 1e-8;
/// Tolerance on full GMM EM runs (README: reproduced to about 1e-11).
pub const TOL_GMM: f64 = 1e-8;

/// Outcome of one comparison.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    Pass,
    Fail,
    Skipped,
}

/// One reported quantity.
#[derive(Clone, Debug)]
pub struct Line {
    pub name: String,
    pub status: Status,
    /// Largest relative error (NaN for discrete or skipped quantities).
    pub max_rel_err: f64,
    pub tol: f64,
    pub note: String,
}

/// All lines of one vectors file.
#[derive(Clone, Debug, Default)]
pub struct Report {
    pub file: String,
    pub lines: Vec<Line>,
}

impl Report {
    pub fn count(&self, s: Status) -> usize {
        self.lines.iter().filter(|l| l.status == s).count()
    }

    /// True when no line failed.
    pub fn all_pass(&self) -> bool {
        self.count(Status::Fail) == 0
    }

    fn push(&mut self, name: &str, status: Status, err: f64, tol: f64, note: impl Into<String>) {
        self.lines.push(Line {
            name: name.to_string(),
            status,
            max_rel_err: err,
            tol,
            note: note.into(),
        });
    }

    fn skip(&mut self, name: &str, why: &str) {
        self.push(name, Status::Skipped, f64::NAN, f64::NAN, why);
    }

    fn fail(&mut self, name: &str, why: impl Into<String>) {
        self.push(name, Status::Fail, f64::NAN, f64::NAN, why);
    }

    /// Compares `got` with the array at `exp` (absent/null -> skipped).
    fn arr(&mut self, name: &str, got: &[f64], exp: Option<&Value>, tol: f64) {
        let Some(exp) = exp else {
            return self.skip(name, "absent in file");
        };
        let e = match flatten(exp) {
            Ok((e, _)) => e,
            Err(m) => return self.fail(name, m),
        };
        if e.len() != got.len() {
            return self.fail(
                name,
                format!("length {} vs expected {}", got.len(), e.len()),
            );
        }
        let err = rel_err(got, &e);
        let st = if err <= tol {
            Status::Pass
        } else {
            Status::Fail
        };
        let note = if st == Status::Fail {
            worst_note(got, &e)
        } else {
            String::new()
        };
        self.push(name, st, err, tol, note);
    }

    /// Like [`Report::arr`] but gated on the normwise error `max|Δ| / max|exp|` (used for
    /// quantities formed by cancellation from GMM mixtures; the elementwise error is noted).
    fn arr_norm(&mut self, name: &str, got: &[f64], exp: Option<&Value>, tol: f64) {
        let Some(exp) = exp else {
            return self.skip(name, "absent in file");
        };
        let e = match flatten(exp) {
            Ok((e, _)) => e,
            Err(m) => return self.fail(name, m),
        };
        if e.len() != got.len() {
            return self.fail(
                name,
                format!("length {} vs expected {}", got.len(), e.len()),
            );
        }
        let err = norm_err(got, &e);
        let st = if err <= tol {
            Status::Pass
        } else {
            Status::Fail
        };
        self.push(
            name,
            st,
            err,
            tol,
            format!("normwise; elementwise {:.1e}", rel_err(got, &e)),
        );
    }

    fn scalar(&mut self, name: &str, got: f64, exp: Option<&Value>, tol: f64) {
        self.arr(name, &[got], exp, tol)
    }

    fn exact<T: fmt::Display + PartialEq>(&mut self, name: &str, got: T, exp: Option<T>) {
        match exp {
            None => self.skip(name, "absent in file"),
            Some(e) if e == got => self.push(name, Status::Pass, 0.0, 0.0, format!("{got}")),
            Some(e) => self.push(
                name,
                Status::Fail,
                f64::NAN,
                0.0,
                format!("got {got}, expected {e}"),
            ),
        }
    }

    fn policy(&mut self, name: &str, got: &LinGaussPolicy, exp: Option<&Value>, tol: f64) {
        for (f, a) in [
            ("K", &got.gain),
            ("k", &got.k),
            ("pol_covar", &got.pol_covar),
            ("chol_pol_covar", &got.chol_pol_covar),
            ("inv_pol_covar", &got.inv_pol_covar),
        ] {
            self.arr(
                &format!("{name}.{f}"),
                &a.data,
                exp.and_then(|v| field(v, f)),
                tol,
            );
        }
    }

    /// Human-readable table, one line per quantity.
    pub fn to_text(&self) -> String {
        let mut s = format!("conformance: {}\n", self.file);
        for l in &self.lines {
            let st = match l.status {
                Status::Pass => "PASS",
                Status::Fail => "FAIL",
                Status::Skipped => "SKIP",
            };
            let err = if l.max_rel_err.is_nan() {
                "-".to_string()
            } else {
                format!("{:.2e}", l.max_rel_err)
            };
            let tol = if l.tol.is_nan() {
                "-".to_string()
            } else {
                format!("{:.0e}", l.tol)
            };
            s += &format!(
                "{st}  {:<58} max_rel_err={:<9} tol={:<6} {}\n",
                l.name, err, tol, l.note
            );
        }
        s += &format!(
            "summary: {} pass, {} fail, {} skipped\n",
            self.count(Status::Pass),
            self.count(Status::Fail),
            self.count(Status::Skipped)
        );
        s
    }

    /// One-line JSON summary.
    pub fn to_json(&self) -> String {
        let worst = self
            .lines
            .iter()
            .filter(|l| l.status != Status::Skipped && !l.max_rel_err.is_nan())
            .map(|l| l.max_rel_err / l.tol.max(f64::MIN_POSITIVE))
            .fold(0.0, f64::max);
        let failed: Vec<&str> = self
            .lines
            .iter()
            .filter(|l| l.status == Status::Fail)
            .map(|l| l.name.as_str())
            .collect();
        serde_json::json!({
            "file": self.file,
            "pass": self.count(Status::Pass),
            "fail": self.count(Status::Fail),
            "skipped": self.count(Status::Skipped),
            "worst_err_over_tol": worst,
            "failed": failed,
            "ok": self.all_pass(),
        })
        .to_string()
    }
}

/// Floor of the relative error, as a fraction of the array's largest magnitude.
pub const REL_FLOOR: f64 = 1e-3;

/// `max_i |got_i − exp_i| / max(|exp_i|, REL_FLOOR · max_j |exp_j|)` (0 when equal).
///
/// Entries far below the array's scale (off-diagonal covariances, values that cancel) carry
/// rounding error of the large entries they are computed from; the floor measures them
/// against a thousandth of the array's scale instead of their own tiny size.
pub fn rel_err(got: &[f64], exp: &[f64]) -> f64 {
    let scale = exp.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let floor = (REL_FLOOR * scale).max(f64::MIN_POSITIVE);
    got.iter()
        .zip(exp)
        .map(|(g, e)| {
            let d = (g - e).abs();
            if d == 0.0 {
                0.0
            } else if d.is_nan() {
                f64::INFINITY
            } else {
                d / e.abs().max(floor)
            }
        })
        .fold(0.0, f64::max)
}

/// Normwise relative error `max_i |got_i − exp_i| / max_j |exp_j|`.
pub fn norm_err(got: &[f64], exp: &[f64]) -> f64 {
    let scale = exp
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()))
        .max(f64::MIN_POSITIVE);
    got.iter()
        .zip(exp)
        .map(|(g, e)| {
            if (g - e).is_nan() {
                f64::INFINITY
            } else {
                (g - e).abs()
            }
        })
        .fold(0.0, f64::max)
        / scale
}

/// Where the worst element is, for failure notes.
fn worst_note(got: &[f64], exp: &[f64]) -> String {
    let scale = exp.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let (mut wi, mut we) = (0, -1.0);
    for i in 0..got.len() {
        let e = rel_err(&got[i..i + 1], &exp[i..i + 1]).min(f64::MAX);
        if e > we {
            wi = i;
            we = e;
        }
    }
    format!(
        "worst at flat index {wi}: got {:e}, expected {:e} (array max |x| {:e}; normwise err {:.2e})",
        got[wi],
        exp[wi],
        scale,
        got.iter().zip(exp).map(|(g, e)| (g - e).abs()).fold(0.0, f64::max) / scale
    )
}

/// Input problems in a vectors file.
#[derive(Debug, thiserror::Error)]
pub enum ConformanceError {
    #[error("cannot read {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path} is not valid JSON: {source}")]
    Json {
        path: String,
        source: serde_json::Error,
    },
    #[error(
        "field `{0}` is missing or malformed; the file does not follow the gps-vectors layout"
    )]
    Field(String),
}

fn field<'a>(v: &'a Value, name: &str) -> Option<&'a Value> {
    match v.get(name) {
        Some(Value::Null) | None => None,
        Some(x) => Some(x),
    }
}

/// `a.b.c` lookup; `None` if any part is absent or null.
fn path<'a>(v: &'a Value, p: &str) -> Option<&'a Value> {
    p.split('.').try_fold(v, |cur, k| field(cur, k))
}

/// Flattens nested lists (row-major) into values and shape.
fn flatten(v: &Value) -> Result<(Vec<f64>, Vec<usize>), String> {
    fn rec(
        v: &Value,
        depth: usize,
        out: &mut Vec<f64>,
        shape: &mut Vec<usize>,
    ) -> Result<(), String> {
        match v {
            Value::Array(a) => {
                if shape.len() == depth {
                    shape.push(a.len());
                } else if shape[depth] != a.len() {
                    return Err("ragged array".into());
                }
                for x in a {
                    rec(x, depth + 1, out, shape)?;
                }
                Ok(())
            }
            Value::Number(n) => {
                out.push(n.as_f64().ok_or("non-f64 number")?);
                Ok(())
            }
            Value::Bool(b) => {
                out.push(if *b { 1.0 } else { 0.0 });
                Ok(())
            }
            _ => Err(format!("unexpected JSON value {v}")),
        }
    }
    let mut out = Vec::new();
    let mut shape = Vec::new();
    rec(v, 0, &mut out, &mut shape)?;
    Ok((out, shape))
}

fn req<'a>(v: &'a Value, p: &str) -> Result<&'a Value, ConformanceError> {
    path(v, p).ok_or_else(|| ConformanceError::Field(p.to_string()))
}

fn req_arr(v: &Value, p: &str, len: usize) -> Result<Vec<f64>, ConformanceError> {
    let (a, _) = flatten(req(v, p)?).map_err(|_| ConformanceError::Field(p.to_string()))?;
    if a.len() != len {
        return Err(ConformanceError::Field(format!(
            "{p} (length {} != {len})",
            a.len()
        )));
    }
    Ok(a)
}

fn req_f64(v: &Value, p: &str) -> Result<f64, ConformanceError> {
    req(v, p)?
        .as_f64()
        .ok_or_else(|| ConformanceError::Field(p.to_string()))
}

fn req_usize(v: &Value, p: &str) -> Result<usize, ConformanceError> {
    req(v, p)?
        .as_u64()
        .map(|x| x as usize)
        .ok_or_else(|| ConformanceError::Field(p.to_string()))
}

fn opt_f64(v: &Value, p: &str, default: f64) -> f64 {
    path(v, p).and_then(Value::as_f64).unwrap_or(default)
}

struct Dims {
    t: usize,
    dx: usize,
    du: usize,
    n: usize,
}

fn load_policy(v: &Value, d: &Dims) -> Result<LinGaussPolicy, ConformanceError> {
    let (t, dx, du) = (d.t, d.dx, d.du);
    Ok(LinGaussPolicy {
        t,
        dx,
        du,
        gain: MatSeq::from_vec(t, du, dx, req_arr(v, "K", t * du * dx)?),
        k: MatSeq::from_vec(t, du, 1, req_arr(v, "k", t * du)?),
        pol_covar: MatSeq::from_vec(t, du, du, req_arr(v, "pol_covar", t * du * du)?),
        chol_pol_covar: MatSeq::from_vec(t, du, du, req_arr(v, "chol_pol_covar", t * du * du)?),
        inv_pol_covar: MatSeq::from_vec(t, du, du, req_arr(v, "inv_pol_covar", t * du * du)?),
    })
}

fn load_dynamics(v: &Value, d: &Dims) -> Result<Dynamics, ConformanceError> {
    let (t, dx, du) = (d.t, d.dx, d.du);
    Ok(Dynamics {
        t,
        dx,
        du,
        fm: MatSeq::from_vec(t, dx, dx + du, req_arr(v, "Fm", t * dx * (dx + du))?),
        fv: MatSeq::from_vec(t, dx, 1, req_arr(v, "fv", t * dx)?),
        dyn_covar: MatSeq::from_vec(t, dx, dx, req_arr(v, "dyn_covar", t * dx * dx)?),
    })
}

/// Recorded `traj_info` of an iteration's outputs (dynamics, x0, cost model).
fn load_traj_info(out: &Value, d: &Dims) -> Result<TrajInfo, ConformanceError> {
    let (t, dx, du) = (d.t, d.dx, d.du);
    let dd = dx + du;
    let x0s = req_arr(out, "x0sigma", dx * dx)?;
    Ok(TrajInfo {
        dynamics: load_dynamics(req(out, "dynamics")?, d)?,
        x0mu: req_arr(out, "x0mu", dx)?,
        x0sigma: Mat::from_fn(dx, dx, |i, j| x0s[i * dx + j]),
        cc: req_arr(out, "cost.cc", t)?,
        cv: MatSeq::from_vec(t, dd, 1, req_arr(out, "cost.cv", t * dd)?),
        cm: MatSeq::from_vec(t, dd, dd, req_arr(out, "cost.Cm", t * dd * dd)?),
    })
}

fn mat_data(m: MatRef<'_, f64>) -> Vec<f64> {
    let mut v = Vec::with_capacity(m.nrows() * m.ncols());
    for i in 0..m.nrows() {
        for j in 0..m.ncols() {
            v.push(m[(i, j)]);
        }
    }
    v
}

fn usize_list(v: Option<&Value>) -> Option<Vec<usize>> {
    v?.as_array()?
        .iter()
        .map(|x| x.as_u64().map(|y| y as usize))
        .collect()
}

/// Runs the conformance checks on a vectors file.
pub fn run_file(file: &str) -> Result<Report, ConformanceError> {
    let text = std::fs::read_to_string(file).map_err(|e| ConformanceError::Io {
        path: file.to_string(),
        source: e,
    })?;
    let v: Value = serde_json::from_str(&text).map_err(|e| ConformanceError::Json {
        path: file.to_string(),
        source: e,
    })?;
    let mut r = run_value(&v)?;
    r.file = file.to_string();
    Ok(r)
}

/// Runs the conformance checks on a parsed vectors document.
pub fn run_value(v: &Value) -> Result<Report, ConformanceError> {
    let mut r = Report::default();
    let d = Dims {
        t: req_usize(v, "dims.T")?,
        dx: req_usize(v, "dims.dX")?,
        du: req_usize(v, "dims.dU")?,
        n: req_usize(v, "dims.N")?,
    };
    let (t_len, dx, du) = (d.t, d.dx, d.du);
    let hp = req(v, "hyperparams")?;
    let alg_kl_step = opt_f64(hp, "algorithm.kl_step", 0.2);
    let min_sm = opt_f64(hp, "algorithm.min_step_mult", 0.01);
    let max_sm = opt_f64(hp, "algorithm.max_step_mult", 10.0);
    let init_var = opt_f64(hp, "algorithm.initial_state_var", 1e-6);
    let opt_cfg = TrajOptConfig {
        del0: opt_f64(hp, "traj_opt.del0", 1e-4),
        min_eta: opt_f64(hp, "traj_opt.min_eta", 1e-8),
        max_eta: opt_f64(hp, "traj_opt.max_eta", 1e16),
        cons_per_step: path(hp, "traj_opt.cons_per_step")
            .and_then(Value::as_bool)
            .unwrap_or(false),
        use_prev_distr: path(hp, "traj_opt.use_prev_distr")
            .and_then(Value::as_bool)
            .unwrap_or(false),
        max_ent_traj: opt_f64(hp, "algorithm.max_ent_traj", 0.0),
    };
    let prior_cfg = PriorGmmConfig {
        min_samples_per_cluster: opt_f64(hp, "dynamics.prior.min_samples_per_cluster", 40.0)
            as usize,
        max_clusters: opt_f64(hp, "dynamics.prior.max_clusters", 20.0) as usize,
        max_samples: opt_f64(hp, "dynamics.prior.max_samples", 20.0) as usize,
        strength: opt_f64(hp, "dynamics.prior.strength", 1.0),
        max_iterations: 100,
    };
    let reg = opt_f64(hp, "dynamics.regularization", 1e-6);

    // --- controller initialisation ---
    let init_rec = load_policy(req(v, "init_controller")?, &d)?;
    check_init(&mut r, v, hp, &d, &init_rec);

    let iters = req(v, "iterations")?
        .as_array()
        .ok_or_else(|| ConformanceError::Field("iterations".into()))?;
    let mut prior = DynamicsPriorGmm::new(prior_cfg.clone(), t_len, dx, du);
    let mut opt = TrajOptLqr::new(opt_cfg.clone(), t_len, dx, du);
    let mut infos: Vec<Option<TrajInfo>> = Vec::new();
    let mut new_ctrls: Vec<Option<LinGaussPolicy>> = Vec::new();
    let resolve_prev =
        |name: &str, new_ctrls: &Vec<Option<LinGaussPolicy>>| -> Option<LinGaussPolicy> {
            if name == "init_controller" {
                return Some(init_rec.clone());
            }
            let idx: usize = name
                .strip_prefix("iterations[")?
                .split(']')
                .next()?
                .parse()
                .ok()?;
            new_ctrls.get(idx).cloned().flatten()
        };

    for (it, iv) in iters.iter().enumerate() {
        let p = format!("iter{it}");
        let inp = req(iv, "inputs")?;
        let out = req(iv, "outputs")?;
        let n = req(inp, "X")?.as_array().map(|a| a.len()).unwrap_or(d.n);
        let x = req_arr(inp, "X", n * t_len * dx)?;
        let u = req_arr(inp, "U", n * t_len * du)?;

        // 1. cost averaging
        check_cost(&mut r, &p, inp, out, &x, &u, n, &d);

        // 2. GMM EM on the stored dataset. Warm starts begin from the previous iteration's
        // recorded GMM (README "How the pieces chain", step 2), not from this port's own EM.
        if it > 0 {
            let po = path(&iters[it - 1], "outputs");
            let dj = 2 * dx + du;
            let rec = po.and_then(|po| {
                let k = path(po, "gmm.K")?.as_u64()? as usize;
                Some((
                    k,
                    req_arr(po, "gmm.mu", k * dj).ok()?,
                    req_arr(po, "gmm.sigma", k * dj * dj).ok()?,
                    req_arr(po, "gmm.logmass", k).ok()?,
                    path(po, "gmm.self_N")?.as_u64()? as usize,
                ))
            });
            if let Some((k, mu, sigma, logmass, self_n)) = rec {
                prior.gmm.set_params(k, &mu, &sigma, &logmass, self_n);
            }
        }
        let init_idx = usize_list(path(out, "gmm.init_cluster_idx"));
        let empty: Vec<usize> = Vec::new();
        let em = prior.update(
            &x,
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

        // 3. prior eval from the recorded GMM (strict), 4. fit from the recorded prior_eval
        check_prior_and_fit(&mut r, &p, &prior_cfg, reg, out, &x, &u, n, &d);
        // 3'+4'. chained from this port's own EM result
        check_chained_fit(&mut r, &p, &mut prior, reg, out, &x, &u, n, &d);

        // prior initial state and x0
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
        let (x0mu, x0sigma) = fit_x0(&x, n, t_len, dx, init_var, Some(&p0));
        r.arr(&format!("{p}.x0mu"), &x0mu, path(out, "x0mu"), TOL_DET);
        r.arr(
            &format!("{p}.x0sigma"),
            &mat_data(x0sigma.as_ref()),
            path(out, "x0sigma"),
            TOL_DET,
        );

        // Recorded traj_info for the LQR pieces.
        let info = match load_traj_info(out, &d) {
            Ok(i) => Some(i),
            Err(e) => {
                r.skip(
                    &format!("{p}.traj_opt"),
                    &format!("no recorded traj_info: {e}"),
                );
                None
            }
        };
        infos.push(info.clone());

        // 8. step adjust
        let step_mult_start = opt_f64(inp, "step_mult_start", 1.0);
        let mut step_mult = step_mult_start;
        if let Some(sa_rec) = path(out, "step_adjust") {
            let prev_info = infos.get(it.wrapping_sub(1)).cloned().flatten();
            let prev_prev = it
                .checked_sub(1)
                .and_then(|i| iters.get(i))
                .and_then(|pv| path(pv, "inputs.prev_controller"))
                .and_then(Value::as_str)
                .and_then(|name| resolve_prev(name, &new_ctrls));
            let cur_pol = resolve_prev(
                req(inp, "prev_controller")
                    .ok()
                    .and_then(Value::as_str)
                    .unwrap_or(""),
                &new_ctrls,
            );
            match (prev_info, prev_prev, cur_pol, info.as_ref()) {
                (Some(pi), Some(pp), Some(cp), Some(ci)) => {
                    match step_adjust(&mut opt, &pp, &pi, &cp, ci, step_mult_start, min_sm, max_sm)
                    {
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
        let kl_step = alg_kl_step * step_mult * t_len as f64;
        r.scalar(
            &format!("{p}.kl_step"),
            kl_step,
            path(out, "kl_step"),
            TOL_DET,
        );

        // 7. eta search from the recorded inputs
        let prev_name = req(inp, "prev_controller")
            .ok()
            .and_then(Value::as_str)
            .unwrap_or("");
        let prev = resolve_prev(prev_name, &new_ctrls);
        let rec_new = path(out, "new_controller")
            .map(|c| load_policy(c, &d))
            .transpose()
            .ok()
            .flatten();
        match (prev, info.as_ref()) {
            (Some(prev), Some(info)) => {
                let kl_step_rec = opt_f64(out, "kl_step", kl_step);
                check_eta_search(
                    &mut r,
                    &p,
                    &mut opt,
                    &prev,
                    info,
                    opt_f64(inp, "eta_start", 1.0),
                    kl_step_rec,
                    out,
                );
            }
            _ => r.skip(
                &format!("{p}.dgd"),
                "previous controller or traj_info unavailable",
            ),
        }
        new_ctrls.push(rec_new);
    }

    // --- unit cases ---
    let unit = path(v, "unit");
    let info0 = infos.first().cloned().flatten();
    if let (Some(bf), Some(info0)) = (
        unit.and_then(|u| path(u, "backward_fixed_eta.cases"))
            .and_then(Value::as_array),
        info0.as_ref(),
    ) {
        for (i, c) in bf.iter().enumerate() {
            check_backward_case(
                &mut r,
                &format!("unit.backward_fixed_eta[{i}]"),
                &mut opt,
                &init_rec,
                info0,
                c,
            );
        }
    } else {
        r.skip("unit.backward_fixed_eta", "absent in file");
    }
    match (unit.and_then(|u| field(u, "cons_per_step")), info0.as_ref()) {
        (Some(c), Some(info0)) => check_cons_per_step(&mut r, &opt_cfg, &init_rec, info0, c, &d),
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
                Ok(()) => check_lr_noprior(&mut r, c, &dynm, &x, &u, n, &d),
                Err(e) => r.fail("unit.dynamics_lr_noprior", e.to_string()),
            }
        }
        None => r.skip("unit.dynamics_lr_noprior", "absent in file"),
    }
    match unit.and_then(|u| field(u, "gmm_em_short")) {
        Some(c) => check_gmm_short(&mut r, c, &d),
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
    Ok(r)
}

fn check_init(r: &mut Report, v: &Value, hp: &Value, d: &Dims, rec: &LinGaussPolicy) {
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

#[allow(clippy::too_many_arguments)]
fn check_cost(
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
fn check_prior_and_fit(
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
    let rec_gmm = (|| {
        let k = path(out, "gmm.K")?.as_u64()? as usize;
        let mu = req_arr(out, "gmm.mu", k * dj).ok()?;
        let sigma = req_arr(out, "gmm.sigma", k * dj * dj).ok()?;
        let logmass = req_arr(out, "gmm.logmass", k).ok()?;
        let self_n = path(out, "gmm.self_N")?.as_u64()? as usize;
        Some((k, mu, sigma, logmass, self_n))
    })();
    match rec_gmm {
        Some((k, mu, sigma, logmass, self_n)) => {
            let mut pr = DynamicsPriorGmm::new(cfg.clone(), t, dx, du);
            pr.gmm.set_params(k, &mu, &sigma, &logmass, self_n);
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
fn check_chained_fit(
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
fn check_eta_search(
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

fn check_backward_case(
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

fn check_cons_per_step(
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

fn check_gmm_short(r: &mut Report, c: &Value, d: &Dims) {
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
fn check_lr_noprior(
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
    let st = if worst <= TOL_DYN_COVAR {
        Status::Pass
    } else {
        Status::Fail
    };
    r.push(
        &format!("{p}.dyn_covar (relative to var x_t+1)"),
        st,
        worst,
        TOL_DYN_COVAR,
        "",
    );
}
