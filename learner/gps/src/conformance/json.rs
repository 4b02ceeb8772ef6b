//! Reading a gps-vectors JSON file: fields by dotted path, arrays flattened row-major, and the
//! recorded controllers, dynamics and trajectory infos.

use faer::{Mat, MatRef};
use serde_json::Value;

use super::ConformanceError;
use crate::dynamics::Dynamics;
use crate::linalg::MatSeq;
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::traj_opt::lqr::TrajInfo;

pub(super) fn field<'a>(v: &'a Value, name: &str) -> Option<&'a Value> {
    match v.get(name) {
        Some(Value::Null) | None => None,
        Some(x) => Some(x),
    }
}

/// `a.b.c` lookup; `None` if any part is absent or null.
pub(super) fn path<'a>(v: &'a Value, p: &str) -> Option<&'a Value> {
    p.split('.').try_fold(v, |cur, k| field(cur, k))
}

/// Flattens nested lists (row-major) into values and shape.
pub(super) fn flatten(v: &Value) -> Result<(Vec<f64>, Vec<usize>), String> {
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

pub(super) fn req<'a>(v: &'a Value, p: &str) -> Result<&'a Value, ConformanceError> {
    path(v, p).ok_or_else(|| ConformanceError::Field(p.to_string()))
}

pub(super) fn req_arr(v: &Value, p: &str, len: usize) -> Result<Vec<f64>, ConformanceError> {
    let (a, _) = flatten(req(v, p)?).map_err(|_| ConformanceError::Field(p.to_string()))?;
    if a.len() != len {
        return Err(ConformanceError::Field(format!(
            "{p} (length {} != {len})",
            a.len()
        )));
    }
    Ok(a)
}

pub(super) fn req_f64(v: &Value, p: &str) -> Result<f64, ConformanceError> {
    req(v, p)?
        .as_f64()
        .ok_or_else(|| ConformanceError::Field(p.to_string()))
}

pub(super) fn req_usize(v: &Value, p: &str) -> Result<usize, ConformanceError> {
    req(v, p)?
        .as_u64()
        .map(|x| x as usize)
        .ok_or_else(|| ConformanceError::Field(p.to_string()))
}

pub(super) fn opt_f64(v: &Value, p: &str, default: f64) -> f64 {
    path(v, p).and_then(Value::as_f64).unwrap_or(default)
}

pub(super) struct Dims {
    pub t: usize,
    pub dx: usize,
    pub du: usize,
    pub n: usize,
}

impl Dims {
    /// The file's `dims` block.
    pub fn of(v: &Value) -> Result<Self, ConformanceError> {
        Ok(Self {
            t: req_usize(v, "dims.T")?,
            dx: req_usize(v, "dims.dX")?,
            du: req_usize(v, "dims.dU")?,
            n: req_usize(v, "dims.N")?,
        })
    }
}

pub(super) fn load_policy(v: &Value, d: &Dims) -> Result<LinGaussPolicy, ConformanceError> {
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

pub(super) fn load_dynamics(v: &Value, d: &Dims) -> Result<Dynamics, ConformanceError> {
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
pub(super) fn load_traj_info(out: &Value, d: &Dims) -> Result<TrajInfo, ConformanceError> {
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

pub(super) fn mat_data(m: MatRef<'_, f64>) -> Vec<f64> {
    let mut v = Vec::with_capacity(m.nrows() * m.ncols());
    for i in 0..m.nrows() {
        for j in 0..m.ncols() {
            v.push(m[(i, j)]);
        }
    }
    v
}

pub(super) fn usize_list(v: Option<&Value>) -> Option<Vec<usize>> {
    v?.as_array()?
        .iter()
        .map(|x| x.as_u64().map(|y| y as usize))
        .collect()
}
