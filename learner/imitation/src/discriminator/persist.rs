//! Saving and resuming a critic: weights, normalisation, Adam state and the minibatch RNG's
//! position, as JSON. f64 values are written shortest-round-trip and read back with
//! serde_json's `float_roundtrip`, so a loaded critic is bit-for-bit the saved one and
//! continues training exactly as the original would have.

use std::path::Path;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::mlp::{param_count, Mlp};
use super::{Adam, Discriminator, DiscriminatorConfig, DiscriminatorError, Normalizer};

const FORMAT: &str = "ur5-gaifo/discriminator";

/// Largest |θ| a critic file may hold. A trained critic's weights are O(1) (0.74 at most after
/// 5 iterations of the default run); one beyond 1e6 comes from a corrupt or edited file, and
/// would give the LQR a cost of absurd scale.
pub const MAX_ABS_PARAM: f64 = 1e6;
const VERSION: u32 = 1;

#[derive(Serialize, Deserialize)]
struct CriticFile {
    format: String,
    version: u32,
    /// `[d_in, hidden..., 1]`.
    sizes: Vec<usize>,
    config: DiscriminatorConfig,
    /// Flat `θ`, layout in `mlp`.
    params: Vec<f64>,
    norm_mean: Vec<f64>,
    norm_std: Vec<f64>,
    adam_steps: u64,
    adam_m: Vec<f64>,
    adam_v: Vec<f64>,
    /// `ChaCha8Rng::get_word_pos` of the minibatch RNG (seeded from `config.seed`).
    rng_word_pos: u128,
    /// θ̄ (`config.param_average`; empty when off or untrained, and in files written before
    /// the field existed).
    #[serde(default)]
    params_average: Vec<f64>,
}

impl Discriminator {
    /// Writes the critic to `path` atomically ([`ur5_shared::atomic_file::write`]: temporary
    /// file, fsync, rename, so an interrupted save leaves the previous file intact). Refuses to write non-finite state.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), DiscriminatorError> {
        let path = path.as_ref();
        let all_finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !(all_finite(self.params())
            && all_finite(&self.adam.m)
            && all_finite(&self.adam.v)
            && all_finite(&self.avg))
        {
            return Err(DiscriminatorError::NonFinite(format!(
                "critic state; not saving it to {}",
                path.display()
            )));
        }
        let file = CriticFile {
            format: FORMAT.into(),
            version: VERSION,
            sizes: self.net.sizes().to_vec(),
            config: self.config.clone(),
            params: self.params().to_vec(),
            norm_mean: self.norm.mean.clone(),
            norm_std: self.norm.std.clone(),
            adam_steps: self.adam.t,
            adam_m: self.adam.m.clone(),
            adam_v: self.adam.v.clone(),
            rng_word_pos: self.rng.get_word_pos(),
            params_average: self.avg.clone(),
        };
        let io = |source| DiscriminatorError::Io {
            path: path.to_path_buf(),
            source,
        };
        let text = serde_json::to_string(&file).map_err(|source| DiscriminatorError::Json {
            path: path.to_path_buf(),
            source,
        })?;
        ur5_shared::atomic_file::write(path, text.as_bytes()).map_err(io)
    }

    /// Reads a critic saved by [`Self::save`] and checks it against the expected input
    /// dimension `d_in` (`2 dX`), its own sizes, and finiteness.
    pub fn load(path: impl AsRef<Path>, d_in: usize) -> Result<Self, DiscriminatorError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| DiscriminatorError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let f: CriticFile =
            serde_json::from_str(&text).map_err(|source| DiscriminatorError::Json {
                path: path.to_path_buf(),
                source,
            })?;
        let bad = |msg: String| DiscriminatorError::BadFile {
            path: path.to_path_buf(),
            msg,
        };
        if f.format != FORMAT || f.version != VERSION {
            return Err(bad(format!(
                "format {:?} version {}, this build reads {FORMAT:?} version {VERSION}",
                f.format, f.version
            )));
        }
        f.config.validate().map_err(|e| bad(e.to_string()))?;
        let sizes = f.config.sizes(f.config.net_inputs(d_in));
        if f.sizes != sizes {
            return Err(bad(format!(
                "layer sizes {:?}, expected {sizes:?} for {d_in} inputs and hidden {:?}",
                f.sizes, f.config.hidden
            )));
        }
        let n = param_count(&sizes);
        // θ̄ is checked as the weights are when the file holds one (it may be empty).
        let average = Some(("params_average", &f.params_average)).filter(|(_, v)| !v.is_empty());
        for (name, v) in [
            ("params", &f.params),
            ("adam_m", &f.adam_m),
            ("adam_v", &f.adam_v),
        ]
        .into_iter()
        .chain(average)
        {
            if v.len() != n {
                return Err(bad(format!(
                    "{name} has {} values, the net {sizes:?} has {n} parameters",
                    v.len()
                )));
            }
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(bad(format!("{name}[{i}] is not finite")));
            }
        }
        if !f.params_average.is_empty() && f.config.param_average == 0.0 {
            return Err(bad(
                "params_average is given but config.param_average is 0 (off)".into(),
            ));
        }
        for (name, v) in [("params", &f.params), ("params_average", &f.params_average)] {
            if let Some(i) = v.iter().position(|x| x.abs() > MAX_ABS_PARAM) {
                return Err(bad(format!(
                    "{name}[{i}] = {:e}: beyond ±{MAX_ABS_PARAM:e}, not a trained critic's \
                     weight",
                    v[i]
                )));
            }
        }
        if let Some(i) = f.adam_v.iter().position(|&x| x < 0.0) {
            return Err(bad(format!("adam_v[{i}] is negative")));
        }
        let norm = Normalizer {
            mean: f.norm_mean,
            std: f.norm_std,
        };
        norm.validate(f.config.net_inputs(d_in)).map_err(bad)?;
        let mut rng = ChaCha8Rng::seed_from_u64(f.config.seed);
        rng.set_word_pos(f.rng_word_pos);
        let adam = Adam {
            config: f.config.adam,
            t: f.adam_steps,
            m: f.adam_m,
            v: f.adam_v,
        };
        Ok(Self {
            net: Mlp::from_params(&sizes, f.params),
            config: f.config,
            norm,
            adam,
            rng,
            avg: f.params_average,
            d_in,
        })
    }
}
