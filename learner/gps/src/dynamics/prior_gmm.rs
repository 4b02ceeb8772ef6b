//! GMM prior over transitions `[x_t; u_t; x_{t+1}]` (GPS
//! python/gps/algorithm/dynamics/dynamics_prior_gmm.py, `DynamicsPriorGMM`; Levine, Finn et al.
//! 2015, Appendix A.3).
//!
//! The prior keeps the most recent `max_samples − 1` trajectories (GPS keeps
//! `X[max(0, N − max_samples + 1):]`, i.e. 19 with the default 20), refits its GMM on all their
//! transitions with `K = max(2, min(max_clusters, ⌊N (T−1) / min_samples_per_cluster⌋))`
//! clusters, and turns the mixture moments around a query set into normal-inverse-Wishart
//! hyperparameters `(μ0, Φ, m, n0)`.

use faer::{Mat, MatMut};

use crate::dynamics::gmm::{ClusterInit, EmReport, Gmm};
use crate::error::GpsError;

/// GPS `DYN_PRIOR_GMM` hyperparameters.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PriorGmmConfig {
    /// Points per cluster used to choose K (GPS default 20; the GPS examples and the
    /// reference vectors use 40).
    pub min_samples_per_cluster: usize,
    /// Upper bound on K (GPS default 50; examples and vectors use 20).
    pub max_clusters: usize,
    /// Trajectories kept is `max_samples − 1` (GPS default 20).
    pub max_samples: usize,
    /// Prior strength multiplier on `m` and `n0` (default 1.0).
    pub strength: f64,
    /// EM iterations per update (GPS `GMM.update` default 100).
    pub max_iterations: usize,
}

impl PriorGmmConfig {
    /// Checks every setting's range.
    pub fn validate(&self) -> Result<(), GpsError> {
        use crate::error::check;
        check(
            self.min_samples_per_cluster >= 1,
            "prior.min_samples_per_cluster",
            self.min_samples_per_cluster,
            ">= 1",
        )?;
        check(
            self.max_clusters >= 1,
            "prior.max_clusters",
            self.max_clusters,
            ">= 1",
        )?;
        check(
            (2..=10_000).contains(&self.max_samples),
            "prior.max_samples",
            self.max_samples,
            "in 2..=10000 (trajectories kept + 1)",
        )?;
        check(
            self.strength.is_finite() && self.strength > 0.0,
            "prior.strength",
            self.strength,
            "finite and > 0",
        )?;
        check(
            self.max_iterations >= 1,
            "prior.max_iterations",
            self.max_iterations,
            ">= 1",
        )
    }
}

impl Default for PriorGmmConfig {
    fn default() -> Self {
        // Values of the GPS example configs and of gps-vectors (max_clusters 20,
        // min_samples_per_cluster 40, max_samples 20, strength 1); EM cap from gmm.py.
        Self {
            min_samples_per_cluster: 40,
            max_clusters: 20,
            max_samples: 20,
            strength: 1.0,
            max_iterations: 100,
        }
    }
}

/// Normal-inverse-Wishart hyperparameters for one time step (or the initial state).
#[derive(Clone, Debug, PartialEq)]
pub struct NiwPrior {
    /// Prior mean `μ0`, length D.
    pub mu0: Vec<f64>,
    /// Scale matrix `Φ` (already multiplied by `m`), `D x D`.
    pub phi: Mat<f64>,
    pub m: f64,
    pub n0: f64,
}

impl NiwPrior {
    /// Zeroed storage for a `d`-dimensional prior.
    pub fn zeros(d: usize) -> Self {
        Self {
            mu0: vec![0.0; d],
            phi: Mat::zeros(d, d),
            m: 0.0,
            n0: 0.0,
        }
    }
}

/// GPS `DynamicsPriorGMM`.
pub struct DynamicsPriorGmm {
    pub cfg: PriorGmmConfig,
    pub dx: usize,
    pub du: usize,
    /// Trajectory length T (number of states per trajectory).
    pub t: usize,
    /// Stored states, `(n_traj, T, dX)` row-major.
    pub x: Vec<f64>,
    /// Stored actions, `(n_traj, T, dU)` row-major.
    pub u: Vec<f64>,
    pub n_traj: usize,
    pub gmm: Gmm,
    /// Transition dataset, `(n_traj (T−1)) x (2 dX + dU)`, row `n (T−1) + t`.
    xux: Mat<f64>,
}

impl DynamicsPriorGmm {
    /// Empty prior for trajectories of `t` states of dimension `dx` and actions of `du`.
    pub fn new(cfg: PriorGmmConfig, t: usize, dx: usize, du: usize) -> Self {
        let d = 2 * dx + du;
        let cap = cfg.max_samples.saturating_sub(1).max(1);
        Self {
            x: Vec::with_capacity(cap * t * dx),
            u: Vec::with_capacity(cap * t * du),
            xux: Mat::zeros(0, d),
            gmm: Gmm::new(d),
            cfg,
            dx,
            du,
            t,
            n_traj: 0,
        }
    }

    /// Number of clusters GPS would use for `n_traj` stored trajectories.
    pub fn num_clusters(&self, n_traj: usize) -> usize {
        let pts = (n_traj * (self.t - 1)) as f64;
        let kk = (pts / self.cfg.min_samples_per_cluster as f64).floor();
        (self.cfg.max_clusters as f64).min(kk).max(2.0) as usize
    }

    /// Appends `n` trajectories to the dataset (dropping the oldest beyond
    /// `max_samples − 1`) without refitting. `x (n,T,dX)`, `u (n,T,dU)` row-major.
    pub fn append(&mut self, x: &[f64], u: &[f64], n: usize) -> Result<(), GpsError> {
        let (t, dx, du) = (self.t, self.dx, self.du);
        if x.len() != n * t * dx || u.len() != n * t * du {
            return Err(GpsError::Shape(format!(
                "prior update expects X ({n},{t},{dx}) and U ({n},{t},{du})"
            )));
        }
        self.x.extend_from_slice(x);
        self.u.extend_from_slice(u);
        self.n_traj += n;
        // GPS: start = max(0, N − max_samples + 1) => keep N − start = min(N, max_samples − 1).
        let keep = self.n_traj.min(self.cfg.max_samples.saturating_sub(1));
        let drop = self.n_traj - keep;
        if drop > 0 {
            self.x.drain(..drop * t * dx);
            self.u.drain(..drop * t * du);
            self.n_traj = keep;
        }
        Ok(())
    }

    /// GPS `DynamicsPriorGMM.update`: append `x (n,T,dX)`, `u (n,T,dU)` and refit the GMM on
    /// all stored transitions. `init` is used only if EM (re)initialises.
    pub fn update(
        &mut self,
        x: &[f64],
        u: &[f64],
        n: usize,
        init: ClusterInit<'_>,
    ) -> Result<EmReport, GpsError> {
        self.append(x, u, n)?;
        self.build_dataset();
        let k = self.num_clusters(self.n_traj);
        let rows = self.n_traj * (self.t - 1);
        let data = self
            .xux
            .as_ref()
            .submatrix(0, 0, rows, 2 * self.dx + self.du);
        self.gmm.update(data, k, self.cfg.max_iterations, init)
    }

    fn build_dataset(&mut self) {
        let (t, dx, du) = (self.t, self.dx, self.du);
        let d = 2 * dx + du;
        let rows = self.n_traj * (t - 1);
        if self.xux.nrows() < rows {
            self.xux = Mat::zeros(rows, d);
        }
        for n in 0..self.n_traj {
            for s in 0..t - 1 {
                let r = n * (t - 1) + s;
                let xs = &self.x[(n * t + s) * dx..(n * t + s + 1) * dx];
                let us = &self.u[(n * t + s) * du..(n * t + s + 1) * du];
                let xn = &self.x[(n * t + s + 1) * dx..(n * t + s + 2) * dx];
                for a in 0..dx {
                    self.xux[(r, a)] = xs[a];
                    self.xux[(r, dx + du + a)] = xn[a];
                }
                for a in 0..du {
                    self.xux[(r, dx + a)] = us[a];
                }
            }
        }
    }

    /// GPS `DynamicsPriorGMM.eval`: prior for the points `pts (N x (2dX+dU))`; `Φ` is
    /// multiplied by `m` after strength scaling. Writes into `out`.
    pub fn eval(&mut self, pts: faer::MatRef<'_, f64>, out: &mut NiwPrior) -> Result<(), GpsError> {
        let (m, n0) = self.gmm.inference(pts, &mut out.mu0, out.phi.as_mut())?;
        let n0 = n0 * self.cfg.strength;
        let m = m * self.cfg.strength;
        scale(out.phi.as_mut(), m);
        out.m = m;
        out.n0 = n0;
        Ok(())
    }

    /// GPS `DynamicsPriorGMM.initial_state`: `μ0` = mean of the stored `x_0`, `Φ` =
    /// `diag(var x_0) · m` (population variance), `m = n0 = dX · strength`.
    pub fn initial_state(&self) -> NiwPrior {
        initial_state_prior(&self.x, self.n_traj, self.t, self.dx, self.cfg.strength)
    }
}

/// [`DynamicsPriorGmm::initial_state`] on an explicit dataset `x (n,T,dX)`.
pub fn initial_state_prior(x: &[f64], n: usize, t: usize, dx: usize, strength: f64) -> NiwPrior {
    let mut p = NiwPrior::zeros(dx);
    for s in 0..n {
        for a in 0..dx {
            p.mu0[a] += x[s * t * dx + a];
        }
    }
    for a in 0..dx {
        p.mu0[a] /= n as f64;
    }
    let m = dx as f64 * strength;
    for a in 0..dx {
        let mut v = 0.0;
        for s in 0..n {
            let d = x[s * t * dx + a] - p.mu0[a];
            v += d * d;
        }
        p.phi[(a, a)] = v / n as f64 * m;
    }
    p.m = m;
    p.n0 = dx as f64 * strength;
    p
}

fn scale(mut a: MatMut<'_, f64>, s: f64) {
    for j in 0..a.ncols() {
        for i in 0..a.nrows() {
            a[(i, j)] *= s;
        }
    }
}
