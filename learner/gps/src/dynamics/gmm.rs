//! Gaussian mixture model fitted by EM (GPS python/gps/utility/gmm.py, class `GMM` with its
//! defaults `init_sequential=False, eigreg=False, warmstart=True`).
//!
//! Behaviour kept from GPS on purpose:
//! - (Re)initialisation only when there is no model yet or `K` changed; otherwise EM starts
//!   from the previous clusters (warm start) and `N` (used for the prior's `n0`) keeps the
//!   point count of the last (re)initialisation.
//! - Initial covariances are `(1/K) Σ_{n∈cluster} d dᵀ + 2e-6 I` (divided by K, not by the
//!   cluster size).
//! - Stopping: before each M-step, stop when `ll < prevll` ("ll decreased") or
//!   `|ll − prevll| < 1e-5 · prevll` ("converged"; never true for negative ll), else after
//!   `max_iterations`.
//! - Clusters whose mass falls below `1e-4 / K` get uniform weights `1/N` in the M-step.
//! - Covariance regularisation `0.5 (Σ + Σᵀ) + 1e-6 I`.
//!
//! Responsibilities are computed in log space with GPS's `logsum` (max-shifted log-sum-exp).
//! Data points are rows of an `N x D` matrix; the model owns a workspace that grows to the
//! largest `N` seen and is reused afterwards.

use faer::{MatMut, MatRef};
use rand::Rng;

use crate::dynamics::em_kernels::{self, BLOCK, PANEL};
use crate::error::GpsError;
use crate::linalg::MatSeq;

/// Up to this many points the E-step uses its own small-N forward substitution.
const SMALL_N: usize = 32;

/// The M-step forms the points' products once per EM run while they take at most this many
/// bytes (so that they stay in a 2 MiB L2 cache across the M-steps), or when the run may take at
/// least [`PRODUCTS_ONCE_ITERATIONS`] iterations (forming them is then paid back even from
/// farther caches); otherwise it forms them per point inside every M-step
/// ([`em_kernels::weighted_sums_direct`]; the same bits). Measured (docs/design.md §5 D33):
/// LQR+GAIfO's 5 EM iterations on 990 points gain 1.3 ms per update by forming them per point,
/// 44 iterations on 1881 points lose 9 ms. Beyond [`PRODUCTS_MAX_BYTES`] (about 20,000 points
/// of 27 dimensions) they are always formed per point, so that the workspace stays bounded.
const PRODUCTS_ONCE_BYTES: usize = 2 << 20;
const PRODUCTS_ONCE_ITERATIONS: usize = 20;
const PRODUCTS_MAX_BYTES: usize = 64 << 20;

/// How to assign points to clusters when EM (re)initialises.
pub enum ClusterInit<'a> {
    /// Cluster index of every point (length N, values in `0..K`), e.g. a recorded
    /// `init_cluster_idx`.
    Given(&'a [usize]),
    /// Uniform random indices, as GPS's `np.random.randint(0, K, N)` (different stream).
    Random(&'a mut dyn rand::RngCore),
}

/// Why EM stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EmStop {
    LlDecreased,
    Converged,
    MaxIterations,
}

impl EmStop {
    /// GPS vector spelling (`ll_decreased`, `converged`, `max_iterations`).
    pub fn as_str(self) -> &'static str {
        match self {
            EmStop::LlDecreased => "ll_decreased",
            EmStop::Converged => "converged",
            EmStop::MaxIterations => "max_iterations",
        }
    }
}

/// What one `update` did.
#[derive(Clone, Debug)]
pub struct EmReport {
    pub k: usize,
    pub n_points: usize,
    pub reinitialized: bool,
    /// Log-likelihood at the top of each EM iteration.
    pub ll_trace: Vec<f64>,
    pub stop: EmStop,
    /// Iteration index at which EM stopped (`max_iterations` when it ran out).
    pub stop_itr: usize,
}

/// `exp(x)`, skipping the call where the result underflows to +0 anyway (x below the
/// smallest subnormal's log), so the value is identical to `x.exp()`.
#[inline]
fn exp_or_zero(x: f64) -> f64 {
    if x < -746.0 {
        0.0
    } else {
        x.exp()
    }
}

/// GPS `logsum` over an iterator: `log Σ exp(v − max) + max`, with `max = −∞` replaced by 0.
#[inline]
pub fn logsum(v: impl Iterator<Item = f64> + Clone) -> f64 {
    let mut m = v.clone().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        m = 0.0;
    }
    let s: f64 = v.map(|x| exp_or_zero(x - m)).sum();
    s.ln() + m
}

struct Workspace {
    /// The points in blocks of [`BLOCK`], dimension-major within a block, padding points zero
    /// (`em_kernels`, docs/design.md §5 D33).
    xb: Vec<f64>,
    /// Number of blocks in `xb`.
    blocks: usize,
    /// The E-step's per-cluster constant `c0 − ½ log det Σ_i + log mass_i`.
    base: Vec<f64>,
    /// The points' product rows in panels ([`em_kernels::products`]), formed once per EM run,
    /// and its scratch.
    prod: Vec<f64>,
    prod_pairs: Vec<[usize; 2]>,
    prod_ext: Vec<f64>,
    /// Whether this EM run's M-steps use `prod` (else `rows` and `factors`).
    prod_once: bool,
    /// The points as rows and the panels' factors of [`em_kernels::weighted_sums_direct`].
    rows: Vec<f64>,
    factors: Vec<[[usize; 2]; 2]>,
    /// The M-step's weights point-major (`N x K`) and its sums (`K x` panel columns,
    /// [`em_kernels::weighted_sums`]).
    wt: Vec<f64>,
    sums: Vec<f64>,
    /// Log observation probabilities, then log responsibilities, cluster-major: cluster `i`'s
    /// value for point `p` at `logobs[i * stride + p]` (padding points after `N`).
    logobs: Vec<f64>,
    /// Weights for refitting, laid out as `logobs` (padding points weigh 0).
    w: Vec<f64>,
    /// Row length of `logobs` and `w`: `N` rounded up to whole blocks.
    stride: usize,
    rowlse: Vec<f64>,
    collse: Vec<f64>,
    /// The small-N E-step's points in groups of four, dimension-major
    /// ([`em_kernels::small_norms`]), its scratch and its squared norms.
    small: Vec<f64>,
    small_y: Vec<f64>,
    small_ss: Vec<f64>,
}

impl Workspace {
    fn new() -> Self {
        Self {
            xb: Vec::new(),
            blocks: 0,
            base: Vec::new(),
            prod: Vec::new(),
            prod_pairs: Vec::new(),
            prod_ext: Vec::new(),
            prod_once: true,
            rows: Vec::new(),
            factors: Vec::new(),
            wt: Vec::new(),
            sums: Vec::new(),
            logobs: Vec::new(),
            w: Vec::new(),
            stride: 0,
            rowlse: Vec::new(),
            collse: Vec::new(),
            small: Vec::new(),
            small_y: Vec::new(),
            small_ss: Vec::new(),
        }
    }

    /// Sizes the buffers for `n` points and `k` clusters (rows of `n` rounded up to blocks).
    fn ensure(&mut self, n: usize, k: usize) {
        self.stride = n.div_ceil(BLOCK) * BLOCK;
        if self.logobs.len() < self.stride * k {
            self.logobs.resize(self.stride * k, 0.0);
            self.w.resize(self.stride * k, 0.0);
        }
        if self.rowlse.len() < n {
            self.rowlse.resize(n, 0.0);
        }
        if self.collse.len() < k {
            self.collse.resize(k, 0.0);
        }
    }

    /// Copies the rows of `data (N x D)` into the blocks `xb`.
    fn load(&mut self, data: MatRef<'_, f64>) {
        let (n, d) = (data.nrows(), data.ncols());
        self.blocks = n.div_ceil(BLOCK);
        self.xb.clear();
        self.xb.resize(self.blocks * d * BLOCK, 0.0);
        for a in 0..d {
            let col = data.col(a);
            for p in 0..n {
                self.xb[(p / BLOCK) * d * BLOCK + a * BLOCK + p % BLOCK] = col[p];
            }
        }
    }
}

/// GPS `GMM`: `K` clusters in `D` dimensions.
pub struct Gmm {
    /// Dimension of a point.
    pub dim: usize,
    /// Number of clusters (0 before the first update).
    pub k: usize,
    /// Cluster means, `(K, D)` row-major.
    pub mu: Vec<f64>,
    /// Cluster covariances, `(K, D, D)`.
    pub sigma: MatSeq,
    /// Log cluster masses, `(K)`.
    pub logmass: Vec<f64>,
    /// Cluster masses, `(K)`.
    pub mass: Vec<f64>,
    /// GPS `GMM.N`: number of points at the last (re)initialisation (sets `m`, `n0`).
    pub n: usize,
    /// GPS `warmstart` (default true).
    pub warmstart: bool,
    /// Log cluster weights of the last `inference` call (GPS `clusterwts`), `(K)`.
    pub last_logwts: Vec<f64>,
    moment_buf: Vec<f64>,
    initialized: bool,
    chol: MatSeq,
    /// `L_i⁻¹` (lower triangular), `(K, D, D)`.
    minv: MatSeq,
    /// The `L_i⁻¹` and `L_i⁻¹ μ_i` of all clusters packed for the E-step
    /// ([`em_kernels::pack_whitening`]).
    mt: Vec<f64>,
    minv_mu: Vec<f64>,
    half_logdet: Vec<f64>,
    chol_valid: bool,
    chol_work: Vec<f64>,
    ws: Workspace,
}

impl Gmm {
    /// Empty model for `dim`-dimensional points.
    pub fn new(dim: usize) -> Self {
        Self {
            dim,
            k: 0,
            mu: Vec::new(),
            sigma: MatSeq::zeros(0, dim, dim),
            logmass: Vec::new(),
            mass: Vec::new(),
            n: 0,
            warmstart: true,
            last_logwts: Vec::new(),
            moment_buf: Vec::with_capacity(dim * dim + dim),
            initialized: false,
            chol: MatSeq::zeros(0, dim, dim),
            minv: MatSeq::zeros(0, dim, dim),
            mt: Vec::new(),
            minv_mu: Vec::new(),
            half_logdet: Vec::new(),
            chol_valid: false,
            chol_work: Vec::new(),
            ws: Workspace::new(),
        }
    }

    /// Whether a model exists (after the first update or `set_params`).
    pub fn is_initialized(&self) -> bool {
        self.initialized
    }

    /// Sets the model from given parameters (e.g. a recorded GMM): `mu (K,D)`,
    /// `sigma (K,D,D)`, `logmass (K)`, `n` = GPS `GMM.N`. Masses are `exp(logmass)`.
    pub fn set_params(&mut self, k: usize, mu: &[f64], sigma: &[f64], logmass: &[f64], n: usize) {
        let d = self.dim;
        assert_eq!(mu.len(), k * d);
        assert_eq!(sigma.len(), k * d * d);
        assert_eq!(logmass.len(), k);
        self.resize_k(k);
        self.mu.copy_from_slice(mu);
        self.sigma.data.copy_from_slice(sigma);
        self.logmass.copy_from_slice(logmass);
        for i in 0..k {
            self.mass[i] = logmass[i].exp();
        }
        self.n = n;
        self.initialized = true;
        self.chol_valid = false;
    }

    fn resize_k(&mut self, k: usize) {
        let d = self.dim;
        self.k = k;
        self.mu.resize(k * d, 0.0);
        self.sigma = MatSeq::zeros(k, d, d);
        self.chol = MatSeq::zeros(k, d, d);
        self.logmass.resize(k, 0.0);
        self.mass.resize(k, 0.0);
        self.half_logdet.resize(k, 0.0);
        self.minv = MatSeq::zeros(k, d, d);
        self.last_logwts.resize(k, 0.0);
    }

    fn factor(&mut self) -> Result<(), GpsError> {
        if self.chol_valid {
            return Ok(());
        }
        let isa = em_kernels::Isa::detect();
        for i in 0..self.k {
            let (sigma, l) = (self.sigma.slice(i), self.chol.slice_mut(i));
            if !em_kernels::cholesky(isa, sigma, l, self.dim, &mut self.chol_work) {
                return Err(GpsError::NotPositiveDefinite {
                    what: "GMM cluster covariance",
                    t: i,
                });
            }
            self.half_logdet[i] = em_kernels::half_log_det(self.chol.slice(i), self.dim);
            let (l, m) = (self.chol.slice(i), self.minv.slice_mut(i));
            em_kernels::invert_lower(isa, l, m, self.dim);
        }
        let (d, k) = (self.dim, self.k);
        em_kernels::pack_whitening(
            isa,
            &self.minv.data,
            &self.mu,
            d,
            k,
            &mut self.mt,
            &mut self.minv_mu,
        );
        self.chol_valid = true;
        Ok(())
    }

    /// GPS `estep`: `log N(x_p; μ_i, Σ_i) + logmass_i` into the workspace's `logobs`
    /// (cluster-major, see [`Workspace`]). `loaded`: the workspace's blocks already hold `data`.
    fn estep(&mut self, data: MatRef<'_, f64>, loaded: bool) -> Result<(), GpsError> {
        self.factor()?;
        let (n, d) = (data.nrows(), data.ncols());
        let k = self.k;
        self.ws.ensure(n, k);
        let c0 = -0.5 * d as f64 * (2.0 * std::f64::consts::PI).ln();
        if n <= SMALL_N {
            self.estep_small(data, c0);
            return Ok(());
        }
        if !loaded {
            self.ws.load(data);
        }
        let ws = &mut self.ws;
        ws.base.clear();
        ws.base
            .extend((0..k).map(|i| c0 - self.half_logdet[i] + self.logmass[i]));
        em_kernels::whitened_norms(
            em_kernels::Isa::detect(),
            &self.mt,
            &self.minv_mu,
            &ws.base,
            d,
            k,
            &ws.xb,
            ws.blocks,
            &mut ws.logobs,
            ws.stride,
        );
        Ok(())
    }

    /// E-step for a handful of points (the per-time-step prior queries): forward substitution
    /// with each cluster's Cholesky factor, in the same order as reference BLAS `dtrsm`, four
    /// points per 4-lane vector ([`em_kernels::small_norms`]); a library triangular solve costs
    /// more in call overhead than in flops here.
    fn estep_small(&mut self, data: MatRef<'_, f64>, c0: f64) {
        let (n, d, k) = (data.nrows(), self.dim, self.k);
        let groups = n.div_ceil(4);
        let ws = &mut self.ws;
        ws.small.clear();
        ws.small.resize(groups * d * 4, 0.0);
        for p in 0..n {
            for a in 0..d {
                ws.small[((p / 4) * d + a) * 4 + p % 4] = data[(p, a)];
            }
        }
        if ws.small_ss.len() < k * groups * 4 {
            ws.small_ss.resize(k * groups * 4, 0.0);
        }
        em_kernels::small_norms(
            em_kernels::Isa::detect(),
            &self.chol.data,
            &self.mu,
            d,
            k,
            &ws.small,
            groups,
            &mut ws.small_y,
            &mut ws.small_ss,
        );
        for i in 0..k {
            let base = c0 - self.half_logdet[i];
            for p in 0..n {
                let ss = ws.small_ss[(i * groups + p / 4) * 4 + p % 4];
                ws.logobs[i * ws.stride + p] = base - 0.5 * ss + self.logmass[i];
            }
        }
    }

    /// GPS `GMM.update`: EM on the rows of `data (N x D)` with `k` clusters.
    pub fn update(
        &mut self,
        data: MatRef<'_, f64>,
        k: usize,
        max_iterations: usize,
        init: ClusterInit<'_>,
    ) -> Result<EmReport, GpsError> {
        let (n, d) = (data.nrows(), data.ncols());
        if d != self.dim {
            return Err(GpsError::Shape(format!(
                "GMM of dimension {} given points of dimension {d}",
                self.dim
            )));
        }
        let reinit = !self.warmstart || !self.initialized || k != self.k;
        if reinit {
            self.initialize(data, k, init)?;
        }
        self.ws.ensure(n, k);
        self.ws.load(data);
        let ws = &mut self.ws;
        let isa = em_kernels::Isa::detect();
        let cols = em_kernels::product_panels(d) * PANEL;
        let bytes = n * cols * std::mem::size_of::<f64>();
        ws.prod_once = bytes <= PRODUCTS_ONCE_BYTES
            || (max_iterations >= PRODUCTS_ONCE_ITERATIONS && bytes <= PRODUCTS_MAX_BYTES);
        if ws.prod_once {
            let (prod, pairs, ext) = (&mut ws.prod, &mut ws.prod_pairs, &mut ws.prod_ext);
            em_kernels::products(isa, &ws.xb, n, d, prod, pairs, ext);
        } else {
            em_kernels::point_rows(&ws.xb, n, d, &mut ws.rows);
            if ws.factors.is_empty() {
                ws.factors = em_kernels::direct_factors(d);
            }
        }
        let mut report = EmReport {
            k,
            n_points: n,
            reinitialized: reinit,
            ll_trace: Vec::new(),
            stop: EmStop::MaxIterations,
            stop_itr: max_iterations,
        };
        let mut prevll = f64::NEG_INFINITY;
        for itr in 0..max_iterations {
            self.estep(data, true)?;
            let Workspace {
                logobs,
                w,
                stride,
                rowlse,
                collse,
                ..
            } = &mut self.ws;
            let stride = *stride;
            // Log responsibilities: logobs − logsum over clusters, in place.
            em_kernels::normalise_over_clusters(isa, logobs, stride, n, k, rowlse);
            let ll: f64 = rowlse[..n].iter().sum();
            report.ll_trace.push(ll);
            if ll < prevll {
                report.stop = EmStop::LlDecreased;
                report.stop_itr = itr;
                return Ok(report);
            }
            if (ll - prevll).abs() < 1e-5 * prevll {
                report.stop = EmStop::Converged;
                report.stop_itr = itr;
                return Ok(report);
            }
            prevll = ll;

            for i in 0..k {
                let (li, wi) = (&logobs[i * stride..][..n], &mut w[i * stride..][..stride]);
                collse[i] = em_kernels::logsum_points_weights(isa, li, wi);
            }
            let lm = logsum(collse[..k].iter().copied());
            for i in 0..k {
                self.logmass[i] = collse[i] - lm;
                self.mass[i] = self.logmass[i].exp();
            }
            let small = 1.0 / k as f64 * 1e-4;
            for i in 0..k {
                if self.mass[i] < small {
                    let wi = &mut w[i * stride..(i + 1) * stride];
                    wi[..n].fill(1.0 / n as f64);
                    wi[n..].fill(0.0);
                }
            }
            self.mstep(n);
        }
        Ok(report)
    }

    /// M-step for means and covariances from the weights in the workspace (`n` points) and the
    /// points' products: all clusters' `μ_i = Σ_p w_pi x_p` and `XX_i = Σ_p w_pi x_p x_pᵀ`
    /// (lower triangle) in one [`em_kernels::weighted_sums`], or, for large sets and short runs,
    /// [`em_kernels::weighted_sums_direct`] ([`PRODUCTS_ONCE_BYTES`]).
    fn mstep(&mut self, n: usize) {
        let (d, k) = (self.dim, self.k);
        let ws = &mut self.ws;
        let panels = em_kernels::product_panels(d);
        let cols = if ws.prod_once {
            panels * PANEL
        } else {
            ws.factors.len() * PANEL
        };
        ws.wt.resize(n * k, 0.0);
        ws.sums.resize(k * cols, 0.0);
        let isa = em_kernels::Isa::detect();
        em_kernels::transpose_weights(isa, &ws.w, ws.stride, n, k, &mut ws.wt);
        let (wt, sums) = (&ws.wt, &mut ws.sums);
        if ws.prod_once {
            em_kernels::weighted_sums(isa, n, k, wt, &ws.prod, panels, sums);
        } else {
            em_kernels::weighted_sums_direct(isa, n, k, wt, &ws.rows, d, &ws.factors, sums);
        }
        let column = |a: usize| {
            if ws.prod_once {
                em_kernels::product_column(d, a, 0)
            } else {
                em_kernels::direct_column(d, a, 0)
            }
        };
        for i in 0..k {
            let sums = &ws.sums[i * cols..(i + 1) * cols];
            let mu = &mut self.mu[i * d..(i + 1) * d];
            mu.copy_from_slice(&sums[..d]);
            let mut s: MatMut<'_, f64> = self.sigma.mat_mut(i);
            for a in 0..d {
                let xx = &sums[column(a)..][..=a];
                for b in 0..a {
                    // GPS: Σ = XX − μμᵀ, then 0.5 (Σ + Σᵀ); XX is symmetric by construction.
                    let v = xx[b] - mu[a] * mu[b];
                    s[(a, b)] = v;
                    s[(b, a)] = v;
                }
                s[(a, a)] = (xx[a] - mu[a] * mu[a]) + 1e-6;
            }
        }
        self.chol_valid = false;
    }

    fn initialize(
        &mut self,
        data: MatRef<'_, f64>,
        k: usize,
        init: ClusterInit<'_>,
    ) -> Result<(), GpsError> {
        let (n, d) = (data.nrows(), data.ncols());
        self.resize_k(k);
        for i in 0..k {
            self.logmass[i] = (1.0 / k as f64).ln();
            self.mass[i] = 1.0 / k as f64;
        }
        self.n = n;
        let random;
        let cidx: &[usize] = match init {
            ClusterInit::Given(idx) => {
                if idx.len() != n || idx.iter().any(|&c| c >= k) {
                    return Err(GpsError::Shape(format!(
                        "cluster assignment has {} entries (need {n}) or an index >= K={k}",
                        idx.len()
                    )));
                }
                idx
            }
            ClusterInit::Random(rng) => {
                random = (0..n).map(|_| rng.random_range(0..k)).collect::<Vec<_>>();
                &random
            }
        };
        let (mut mu, mut dv) = (vec![0.0; d], vec![0.0; d]);
        let mut acc = vec![0.0; d * d];
        let inv_k = 1.0 / k as f64;
        for i in 0..k {
            let members: Vec<usize> = (0..n).filter(|&p| cidx[p] == i).collect();
            mu.fill(0.0);
            for &p in &members {
                for a in 0..d {
                    mu[a] += data[(p, a)];
                }
            }
            let cnt = members.len() as f64;
            mu.iter_mut().for_each(|m| *m /= cnt);
            // Σ_p d_p d_pᵀ in members' order, accumulated row-major in a plain slice (the rows
            // vectorise); the same products and sums as element by element.
            acc.fill(0.0);
            for &p in &members {
                for b in 0..d {
                    dv[b] = data[(p, b)] - mu[b];
                }
                for (row, &da) in acc.chunks_exact_mut(d).zip(&dv) {
                    for (s, &db) in row.iter_mut().zip(&dv) {
                        *s += da * db;
                    }
                }
            }
            let mut s = self.sigma.mat_mut(i);
            for a in 0..d {
                for b in 0..d {
                    s[(a, b)] = acc[a * d + b] * inv_k;
                }
                s[(a, a)] += 2e-6;
            }
            self.mu[i * d..(i + 1) * d].copy_from_slice(&mu);
        }
        self.initialized = true;
        self.chol_valid = false;
        Ok(())
    }

    /// GPS `clusterwts`: average posterior log cluster weights of the points `pts (N x D)`,
    /// written to `self.last_logwts`.
    pub fn clusterwts(&mut self, pts: MatRef<'_, f64>) -> Result<(), GpsError> {
        self.estep(pts, false)?;
        let n = pts.nrows();
        let k = self.k;
        let isa = em_kernels::Isa::detect();
        let Workspace {
            logobs,
            stride,
            rowlse,
            ..
        } = &mut self.ws;
        em_kernels::normalise_over_clusters(isa, logobs, *stride, n, k, rowlse);
        let ln_n = (n as f64).ln();
        for i in 0..k {
            self.last_logwts[i] =
                em_kernels::logsum_points(isa, &logobs[i * *stride..][..n]) - ln_n;
        }
        Ok(())
    }

    /// GPS `moments` of the mixture with the weights `exp(self.last_logwts)`:
    /// `μ = Σ w_i μ_i`, `Σ = Σ_i w_i (Σ_i + μ_i (μ_i − μ)ᵀ)` (GPS's form, equal to the usual
    /// one when the weights sum to one). `mu0` has length D, `phi` is `D x D`.
    pub fn moments(&mut self, mu0: &mut [f64], mut phi: MatMut<'_, f64>) {
        let d = self.dim;
        mu0.iter_mut().for_each(|m| *m = 0.0);
        for i in 0..self.k {
            let w = self.last_logwts[i].exp();
            for a in 0..d {
                mu0[a] += self.mu[i * d + a] * w;
            }
        }
        // Accumulate row-major in plain slices (vectorisable), then copy into `phi`.
        let buf = &mut self.moment_buf;
        buf.clear();
        buf.resize(d * d + d, 0.0);
        let (acc, dm) = buf.split_at_mut(d * d);
        for i in 0..self.k {
            let w = self.last_logwts[i].exp();
            let mi = &self.mu[i * d..(i + 1) * d];
            for b in 0..d {
                dm[b] = mi[b] - mu0[b];
            }
            let si = self.sigma.slice(i);
            for a in 0..d {
                let ma = mi[a];
                let row = &mut acc[a * d..(a + 1) * d];
                let srow = &si[a * d..(a + 1) * d];
                for b in 0..d {
                    row[b] += (srow[b] + ma * dm[b]) * w;
                }
            }
        }
        phi.copy_from(MatRef::from_row_major_slice(acc, d, d));
    }

    /// GPS `GMM.inference`: normal-inverse-Wishart hyperparameters for the points
    /// `pts (N x D)`: writes `μ0 (D)` and `Φ (D x D)` and returns `(m, n0)` =
    /// `(1, (N_gmm − 2 − D) / N_gmm)` (before the prior's strength scaling).
    pub fn inference(
        &mut self,
        pts: MatRef<'_, f64>,
        mu0: &mut [f64],
        phi: MatMut<'_, f64>,
    ) -> Result<(f64, f64), GpsError> {
        self.clusterwts(pts)?;
        self.moments(mu0, phi);
        let m = self.n as f64;
        let n0 = m - 2.0 - self.dim as f64;
        Ok((m / self.n as f64, n0 / self.n as f64))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    #[test]
    fn invert_lower_equals_forward_substitution_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for d in [1, 2, 4, 5, 7, 9, 27, 32, 33] {
            let mut l = vec![0.0; d * d];
            for a in 0..d {
                for b in 0..a {
                    l[a * d + b] = rand::Rng::random_range(&mut rng, -0.5..0.5);
                }
                l[a * d + a] = rand::Rng::random_range(&mut rng, 0.5..2.0);
            }
            use em_kernels::Isa;
            for isa in [Isa::Portable, Isa::Avx2, Isa::Avx512] {
                if !isa.available() {
                    println!("note: this CPU cannot run the {isa:?} instantiation; not tested");
                    continue;
                }
                let mut m = vec![f64::NAN; d * d];
                em_kernels::invert_lower(isa, &l, &mut m, d);
                // Forward substitution on the columns of the identity, column by column.
                for b in 0..d {
                    let mut col = vec![0.0; d];
                    for a in b..d {
                        let mut s = if a == b { 1.0 } else { 0.0 };
                        for c in b..a {
                            s -= l[a * d + c] * col[c];
                        }
                        col[a] = s / l[a * d + a];
                        let (got, want) = (m[a * d + b].to_bits(), col[a].to_bits());
                        assert_eq!(got, want, "{isa:?} d={d} ({a},{b})");
                    }
                    for a in 0..b {
                        assert!(m[a * d + b].is_nan(), "upper triangle written");
                    }
                }
            }
        }
    }

    #[test]
    fn logsum_handles_all_neg_inf() {
        let v = [f64::NEG_INFINITY, f64::NEG_INFINITY];
        assert_eq!(logsum(v.iter().copied()), f64::NEG_INFINITY);
        let v = [1000.0, 1000.0];
        assert!((logsum(v.iter().copied()) - (1000.0 + 2f64.ln())).abs() < 1e-12);
    }

    #[test]
    fn products_formed_once_or_per_m_step_give_the_same_bits() {
        // 800 points of 27 dimensions: their products (2.6 MB) are formed per M-step in a
        // 5-iteration run and once in a 20-iteration run. Two tight blobs make EM converge in
        // both before the fifth iteration, so both runs do the same steps.
        let (n, d) = (800, 27);
        assert!(n * em_kernels::product_panels(d) * PANEL * 8 > PRODUCTS_ONCE_BYTES);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
        let mut data = Mat::<f64>::zeros(n, d);
        for p in 0..n {
            let c = if p % 2 == 0 { -5.0 } else { 5.0 };
            for a in 0..d {
                let z: f64 = StandardNormal.sample(&mut rng);
                data[(p, a)] = c + 0.01 * z;
            }
        }
        let idx: Vec<usize> = (0..n).map(|p| p % 2).collect();
        let run = |its: usize| {
            let mut g = Gmm::new(d);
            let rep = g
                .update(data.as_ref(), 2, its, ClusterInit::Given(&idx))
                .unwrap();
            (rep, g)
        };
        let ((ra, ga), (rb, gb)) = (
            run(PRODUCTS_ONCE_ITERATIONS - 1),
            run(PRODUCTS_ONCE_ITERATIONS),
        );
        assert!(
            ra.stop != EmStop::MaxIterations && ra.stop_itr < 5,
            "{ra:?}"
        );
        assert_eq!((ra.stop, ra.stop_itr), (rb.stop, rb.stop_itr));
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&ra.ll_trace), bits(&rb.ll_trace));
        assert_eq!(bits(&ga.mu), bits(&gb.mu));
        assert_eq!(bits(&ga.sigma.data), bits(&gb.sigma.data));
        assert_eq!(bits(&ga.logmass), bits(&gb.logmass));
    }

    #[test]
    fn em_separates_two_blobs_and_ll_increases() {
        // Few points per cluster, as GPS sizes K (~40 points per cluster): GPS's initial
        // covariance is divided by K, not by the cluster size, so with many points per cluster
        // it starts far too wide and EM crawls.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let n = 40;
        let mut data = Mat::<f64>::zeros(n, 2);
        for p in 0..n {
            let c = if p % 2 == 0 { -5.0 } else { 5.0 };
            for a in 0..2 {
                let z: f64 = StandardNormal.sample(&mut rng);
                data[(p, a)] = c + 0.5 * z;
            }
        }
        // GPS starts from a hard assignment; give it a noisy one (every 5th point random).
        let idx: Vec<usize> = (0..n)
            .map(|p| {
                if p % 5 == 0 {
                    rand::Rng::random_range(&mut rng, 0..2)
                } else {
                    p % 2
                }
            })
            .collect();
        let mut g = Gmm::new(2);
        let rep = g
            .update(data.as_ref(), 2, 100, ClusterInit::Given(&idx))
            .unwrap();
        assert!(rep.ll_trace.len() >= 2, "{rep:?}");
        for w in rep
            .ll_trace
            .windows(2)
            .take(rep.ll_trace.len().saturating_sub(2))
        {
            assert!(w[1] >= w[0] - 1e-9);
        }
        let mut means: Vec<f64> = (0..2).map(|i| g.mu[i * 2]).collect();
        means.sort_by(f64::total_cmp);
        assert!(
            (means[0] + 5.0).abs() < 0.2 && (means[1] - 5.0).abs() < 0.2,
            "{means:?}"
        );
        assert!((g.mass[0] - 0.5).abs() < 0.05);
        assert!((g.mass.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn initialisation_follows_gps() {
        // 4 points in 2-D, clusters {0, 2} and {1, 3}; zero EM iterations leaves the init.
        let data = faer::mat![[0.0, 1.0], [4.0, 0.0], [2.0, 3.0], [6.0, 2.0f64]];
        let mut g = Gmm::new(2);
        let rep = g
            .update(data.as_ref(), 2, 0, ClusterInit::Given(&[0, 1, 0, 1]))
            .unwrap();
        assert!(rep.reinitialized && rep.ll_trace.is_empty());
        assert_eq!(&g.mu, &[1.0, 2.0, 5.0, 1.0]);
        // Σ_0 = (1/K) Σ d dᵀ + 2e-6 I with d = ±(1, 1): (1/2)·2·[[1,1],[1,1]] + 2e-6 I
        let s0 = g.sigma.slice(0);
        assert_eq!(s0, &[1.0 + 2e-6, 1.0, 1.0, 1.0 + 2e-6]);
        assert_eq!(g.n, 4);
        assert!((g.logmass[0] - 0.5f64.ln()).abs() < 1e-15);
        // A second update with the same K warm-starts and keeps N.
        let more = faer::mat![
            [0.0, 1.0],
            [4.0, 0.0],
            [2.0, 3.0],
            [6.0, 2.0],
            [1.0, 1.0f64]
        ];
        let rep = g
            .update(more.as_ref(), 2, 1, ClusterInit::Given(&[]))
            .unwrap();
        assert!(!rep.reinitialized);
        assert_eq!(g.n, 4);
    }
}
