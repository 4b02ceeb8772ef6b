//! The learner state as named arrays, for exact checkpoints (docs/design.md §4.11): everything
//! an iteration carries to the next — the GMM dynamics prior and the trajectories it is fitted
//! on, the trajectory info (dynamics, x0, cost model) and its previous copy, η, the step
//! multiplier, the prior's RNG position, controllers — so that a run restored from a
//! [`Snapshot`] continues bit for bit as the original would have.
//!
//! A snapshot is a plain map from names to f64 arrays (with their shape) and u64 words (counts,
//! RNG seeds and positions, which must round-trip exactly); the application stores it as one
//! `.npz` array per entry. Restoring checks every shape against the object restored into and
//! names the array at fault: a snapshot of another problem size, or a damaged one, is an error,
//! never a panic.

use std::collections::BTreeMap;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::algorithm::update::Learner;
use crate::dynamics::gmm::Gmm;
use crate::error::GpsError;
use crate::linalg::MatSeq;
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::traj_opt::lqr::TrajInfo;

/// Named arrays of a learner's state (module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Snapshot {
    /// f64 arrays: name → (shape, values in C order).
    pub reals: BTreeMap<String, (Vec<usize>, Vec<f64>)>,
    /// u64 arrays (1-d): name → values.
    pub words: BTreeMap<String, Vec<u64>>,
}

fn bad(name: &str, why: impl std::fmt::Display) -> GpsError {
    GpsError::Snapshot(format!("array `{name}`: {why}"))
}

impl Snapshot {
    /// Adds the f64 array `name` of `shape`.
    pub fn put(&mut self, name: &str, shape: &[usize], data: &[f64]) {
        debug_assert_eq!(shape.iter().product::<usize>(), data.len());
        self.reals
            .insert(name.to_owned(), (shape.to_vec(), data.to_vec()));
    }

    /// Adds the u64 array `name`.
    pub fn put_words(&mut self, name: &str, data: &[u64]) {
        self.words.insert(name.to_owned(), data.to_vec());
    }

    /// Whether an array (of either kind) is called `name`.
    pub fn has(&self, name: &str) -> bool {
        self.reals.contains_key(name) || self.words.contains_key(name)
    }

    /// The f64 array `name` and its shape; an error if it is absent.
    pub fn real_any(&self, name: &str) -> Result<(&[usize], &[f64]), GpsError> {
        let (shape, data) = self
            .reals
            .get(name)
            .ok_or_else(|| bad(name, "missing (not an f64 array of this snapshot)"))?;
        if shape.iter().try_fold(1usize, |a, &b| a.checked_mul(b)) != Some(data.len()) {
            return Err(bad(
                name,
                format!("shape {shape:?} does not hold its {} values", data.len()),
            ));
        }
        Ok((shape, data))
    }

    /// The f64 array `name`, which must have exactly `shape`.
    pub fn real(&self, name: &str, shape: &[usize]) -> Result<&[f64], GpsError> {
        let (s, data) = self.real_any(name)?;
        if s != shape {
            return Err(bad(name, format!("shape {s:?}, expected {shape:?}")));
        }
        Ok(data)
    }

    /// The f64 scalar `name` (shape `[]`).
    pub fn scalar(&self, name: &str) -> Result<f64, GpsError> {
        Ok(self.real(name, &[])?[0])
    }

    /// The u64 array `name`, which must have `len` values.
    pub fn words(&self, name: &str, len: usize) -> Result<&[u64], GpsError> {
        let w = self
            .words
            .get(name)
            .ok_or_else(|| bad(name, "missing (not a u64 array of this snapshot)"))?;
        if w.len() != len {
            return Err(bad(name, format!("{} values, expected {len}", w.len())));
        }
        Ok(w)
    }

    /// Adds a matrix stack as `name`, shape `(n, rows, cols)`.
    pub fn put_seq(&mut self, name: &str, m: &MatSeq) {
        self.put(name, &[m.n, m.rows, m.cols], &m.data);
    }

    /// Fills the matrix stack `m` from `name`, which must have `m`'s shape.
    pub fn fill_seq(&self, name: &str, m: &mut MatSeq) -> Result<(), GpsError> {
        let data = self.real(name, &[m.n, m.rows, m.cols])?;
        m.data.copy_from_slice(data);
        Ok(())
    }

    /// Adds the controller `pol` under `prefix` (`prefix.K`, `.k`, `.pol_covar`,
    /// `.chol_pol_covar`, `.inv_pol_covar`: every array, so that nothing is recomputed).
    pub fn put_policy(&mut self, prefix: &str, pol: &LinGaussPolicy) {
        for (name, m) in policy_arrays(pol) {
            self.put_seq(&format!("{prefix}.{name}"), m);
        }
    }

    /// Fills `pol` (whose size says what to expect) from the arrays under `prefix`; every
    /// value must be finite.
    pub fn fill_policy(&self, prefix: &str, pol: &mut LinGaussPolicy) -> Result<(), GpsError> {
        let mut out = pol.clone();
        let LinGaussPolicy {
            gain,
            k,
            pol_covar,
            chol_pol_covar,
            inv_pol_covar,
            ..
        } = &mut out;
        for (name, m) in [
            ("K", gain),
            ("k", k),
            ("pol_covar", pol_covar),
            ("chol_pol_covar", chol_pol_covar),
            ("inv_pol_covar", inv_pol_covar),
        ] {
            let full = format!("{prefix}.{name}");
            self.fill_seq(&full, m)?;
            if let Some(v) = m.data.iter().find(|v| !v.is_finite()) {
                return Err(bad(&full, format!("non-finite value {v}")));
            }
        }
        *pol = out;
        Ok(())
    }

    /// Adds the state of the ChaCha8 stream `rng` as `name`: seed (4 words), stream, word
    /// position (low, high).
    pub fn put_rng(&mut self, name: &str, rng: &ChaCha8Rng) {
        let seed = rng.get_seed();
        let mut w = [0u64; 7];
        for (i, c) in seed.chunks_exact(8).enumerate() {
            w[i] = u64::from_le_bytes(c.try_into().expect("8 bytes"));
        }
        w[4] = rng.get_stream();
        let pos = rng.get_word_pos();
        w[5] = pos as u64;
        w[6] = (pos >> 64) as u64;
        self.put_words(name, &w);
    }

    /// The ChaCha8 stream stored as `name` by [`Snapshot::put_rng`], at its position.
    pub fn rng(&self, name: &str) -> Result<ChaCha8Rng, GpsError> {
        let w = self.words(name, 7)?;
        let mut seed = [0u8; 32];
        for i in 0..4 {
            seed[8 * i..8 * i + 8].copy_from_slice(&w[i].to_le_bytes());
        }
        let mut rng = ChaCha8Rng::from_seed(seed);
        rng.set_stream(w[4]);
        let pos = u128::from(w[5]) | (u128::from(w[6]) << 64);
        // ChaCha's block counter is 64 bits: positions are < 2^68 words.
        if pos >> 68 != 0 {
            return Err(bad(name, format!("word position {pos} beyond the stream")));
        }
        rng.set_word_pos(pos);
        Ok(rng)
    }

    /// Adds trajectory info under `prefix`.
    pub fn put_info(&mut self, prefix: &str, info: &TrajInfo) {
        let d = &info.dynamics;
        self.put_seq(&format!("{prefix}.Fm"), &d.fm);
        self.put_seq(&format!("{prefix}.fv"), &d.fv);
        self.put_seq(&format!("{prefix}.dyn_covar"), &d.dyn_covar);
        self.put(&format!("{prefix}.x0mu"), &[info.x0mu.len()], &info.x0mu);
        let s = &info.x0sigma;
        let x0sigma: Vec<f64> = (0..s.nrows())
            .flat_map(|i| (0..s.ncols()).map(move |j| s[(i, j)]))
            .collect();
        self.put(
            &format!("{prefix}.x0sigma"),
            &[s.nrows(), s.ncols()],
            &x0sigma,
        );
        self.put(&format!("{prefix}.cc"), &[info.cc.len()], &info.cc);
        self.put_seq(&format!("{prefix}.cv"), &info.cv);
        self.put_seq(&format!("{prefix}.cm"), &info.cm);
    }

    /// Fills `info` (whose size says what to expect) from the arrays under `prefix`.
    pub fn fill_info(&self, prefix: &str, info: &mut TrajInfo) -> Result<(), GpsError> {
        let d = &mut info.dynamics;
        self.fill_seq(&format!("{prefix}.Fm"), &mut d.fm)?;
        self.fill_seq(&format!("{prefix}.fv"), &mut d.fv)?;
        self.fill_seq(&format!("{prefix}.dyn_covar"), &mut d.dyn_covar)?;
        let n = info.x0mu.len();
        info.x0mu
            .copy_from_slice(self.real(&format!("{prefix}.x0mu"), &[n])?);
        let (r, c) = (info.x0sigma.nrows(), info.x0sigma.ncols());
        let s = self.real(&format!("{prefix}.x0sigma"), &[r, c])?;
        info.x0sigma = faer::Mat::from_fn(r, c, |i, j| s[i * c + j]);
        let t = info.cc.len();
        info.cc
            .copy_from_slice(self.real(&format!("{prefix}.cc"), &[t])?);
        self.fill_seq(&format!("{prefix}.cv"), &mut info.cv)?;
        self.fill_seq(&format!("{prefix}.cm"), &mut info.cm)
    }
}

fn policy_arrays(pol: &LinGaussPolicy) -> [(&'static str, &MatSeq); 5] {
    [
        ("K", &pol.gain),
        ("k", &pol.k),
        ("pol_covar", &pol.pol_covar),
        ("chol_pol_covar", &pol.chol_pol_covar),
        ("inv_pol_covar", &pol.inv_pol_covar),
    ]
}

impl Gmm {
    /// Adds the mixture under `prefix` (nothing but `prefix.k_n` = [0, 0] before the first
    /// fit).
    pub fn snapshot(&self, prefix: &str, s: &mut Snapshot) {
        if !self.is_initialized() {
            s.put_words(&format!("{prefix}.k_n"), &[0, 0]);
            return;
        }
        let (k, d) = (self.k, self.dim);
        s.put_words(&format!("{prefix}.k_n"), &[k as u64, self.n as u64]);
        s.put(&format!("{prefix}.mu"), &[k, d], &self.mu);
        s.put(&format!("{prefix}.sigma"), &[k, d, d], &self.sigma.data);
        s.put(&format!("{prefix}.logmass"), &[k], &self.logmass);
        s.put(&format!("{prefix}.mass"), &[k], &self.mass);
        s.put(&format!("{prefix}.last_logwts"), &[k], &self.last_logwts);
    }

    /// Restores the mixture saved by [`Gmm::snapshot`] (at most `max_k` clusters).
    pub fn restore(&mut self, prefix: &str, s: &Snapshot, max_k: usize) -> Result<(), GpsError> {
        let name = format!("{prefix}.k_n");
        let kn = s.words(&name, 2)?;
        let (k, n) = (kn[0], kn[1]);
        if k == 0 {
            if self.is_initialized() {
                *self = Gmm::new(self.dim);
            }
            return Ok(());
        }
        if k > max_k as u64 || n > 1 << 40 {
            return Err(bad(&name, format!("K = {k}, N = {n}: at most K = {max_k}")));
        }
        let (k, d) = (k as usize, self.dim);
        let mu = s.real(&format!("{prefix}.mu"), &[k, d])?;
        let sigma = s.real(&format!("{prefix}.sigma"), &[k, d, d])?;
        let logmass = s.real(&format!("{prefix}.logmass"), &[k])?;
        let mass = s.real(&format!("{prefix}.mass"), &[k])?.to_vec();
        let wts = s.real(&format!("{prefix}.last_logwts"), &[k])?.to_vec();
        self.set_params(k, mu, sigma, logmass, n as usize);
        self.mass = mass;
        self.last_logwts = wts;
        Ok(())
    }
}

impl Learner {
    /// Adds the learner's state (module docs) under `gps.`, `prior.` and `gmm.`.
    pub fn snapshot(&self, s: &mut Snapshot) {
        s.put("gps.eta", &[], &[self.eta]);
        s.put("gps.step_mult", &[], &[self.step_mult]);
        s.put_rng("gps.rng", &self.rng);
        s.put_info("gps.info", &self.info);
        if let Some(prev) = &self.prev_info {
            s.put_info("gps.prev_info", prev);
        }
        let p = &self.prior;
        s.put("prior.x", &[p.n_traj, p.t, p.dx], &p.x);
        s.put("prior.u", &[p.n_traj, p.t, p.du], &p.u);
        p.gmm.snapshot("gmm", s);
    }

    /// Restores the state saved by [`Learner::snapshot`] into this learner (built for the same
    /// problem size and settings).
    pub fn restore(&mut self, s: &Snapshot) -> Result<(), GpsError> {
        let positive = |name: &str| -> Result<f64, GpsError> {
            let v = s.scalar(name)?;
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(bad(name, format!("{v}: must be finite and > 0")))
            }
        };
        let eta = positive("gps.eta")?;
        let step_mult = positive("gps.step_mult")?;
        let rng = s.rng("gps.rng")?;
        let mut info = self.info.clone();
        s.fill_info("gps.info", &mut info)?;
        let prev_info = if s.has("gps.prev_info.Fm") {
            let mut prev = self.info.clone();
            s.fill_info("gps.prev_info", &mut prev)?;
            Some(prev)
        } else {
            None
        };
        let p = &self.prior;
        let (shape, x) = s.real_any("prior.x")?;
        let n_traj = shape.first().copied().unwrap_or(0);
        let keep = p.cfg.max_samples.saturating_sub(1);
        if shape != [n_traj, p.t, p.dx] || n_traj > keep {
            return Err(bad(
                "prior.x",
                format!(
                    "shape {shape:?}, expected (n ≤ {keep}, {}, {}) (prior.max_samples − 1 \
                     trajectories of this run's T)",
                    p.t, p.dx
                ),
            ));
        }
        let x = x.to_vec();
        let u = s.real("prior.u", &[n_traj, p.t, p.du])?.to_vec();
        let max_k = p.cfg.max_clusters.max(2);
        self.prior.gmm.restore("gmm", s, max_k)?;
        self.prior.x = x;
        self.prior.u = u;
        self.prior.n_traj = n_traj;
        self.eta = eta;
        self.step_mult = step_mult;
        self.rng = rng;
        self.info = info;
        self.prev_info = prev_info;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithm::AlgorithmConfig;
    use crate::dynamics::lr_prior::LrPriorConfig;
    use crate::dynamics::prior_gmm::PriorGmmConfig;
    use crate::traj_opt::lqr::TrajOptConfig;
    use rand::Rng;

    fn learner(seed: u64) -> Learner {
        Learner::new(
            AlgorithmConfig::default(),
            PriorGmmConfig {
                min_samples_per_cluster: 4,
                ..PriorGmmConfig::default()
            },
            LrPriorConfig::default(),
            TrajOptConfig::default(),
            6,
            2,
            1,
            3,
            ChaCha8Rng::seed_from_u64(seed),
        )
    }

    /// A learner restored from a snapshot taken after two prior updates makes the same third
    /// update bit for bit as the original; a snapshot of another size is refused by name.
    #[test]
    fn a_restored_learner_continues_bit_for_bit() {
        let mut data = ChaCha8Rng::seed_from_u64(1);
        let mut draw = |n: usize| {
            (0..n)
                .map(|_| data.random_range(-1.0..1.0))
                .collect::<Vec<f64>>()
        };
        let batches: Vec<(Vec<f64>, Vec<f64>)> =
            (0..3).map(|_| (draw(3 * 6 * 2), draw(3 * 6))).collect();
        let mut a = learner(9);
        for (x, u) in &batches[..2] {
            a.update_dynamics(x, u, 3).unwrap();
        }
        a.eta = 3.5;
        a.step_mult = 0.7;
        let mut s = Snapshot::default();
        a.snapshot(&mut s);
        let mut b = learner(9);
        b.restore(&s).unwrap();
        let mut s2 = Snapshot::default();
        b.snapshot(&mut s2);
        assert_eq!(s, s2, "snapshot → restore → snapshot is the identity");
        let (x, u) = &batches[2];
        a.update_dynamics(x, u, 3).unwrap();
        b.update_dynamics(x, u, 3).unwrap();
        let bits = |l: &Learner| -> Vec<u64> {
            let mut s = Snapshot::default();
            l.snapshot(&mut s);
            s.reals
                .values()
                .flat_map(|(_, v)| v.iter().map(|x| x.to_bits()))
                .collect()
        };
        assert_eq!(bits(&a), bits(&b));

        let mut other = Learner::new(
            AlgorithmConfig::default(),
            PriorGmmConfig::default(),
            LrPriorConfig::default(),
            TrajOptConfig::default(),
            7,
            2,
            1,
            3,
            ChaCha8Rng::seed_from_u64(9),
        );
        let e = other.restore(&s).unwrap_err().to_string();
        assert!(e.contains("gps.info.Fm") && e.contains("expected"), "{e}");
        let mut broken = s.clone();
        broken.put("gps.eta", &[], &[f64::NAN]);
        let e = learner(9).restore(&broken).unwrap_err().to_string();
        assert!(e.contains("gps.eta"), "{e}");
    }
}
