//! Exact resume of a BCO run: [`Bco::snapshot`] holds everything the next iteration depends
//! on — the iteration, the policy (normalisation, weights, σ: [`GlobalPolicy::flat`]), the
//! cloning's Adam moments and minibatch RNG, and the inverse model with all its data
//! ([`super::inverse::InverseModel::snapshot`]). [`Bco::from_snapshot`] continues from one
//! exactly: the same episodes, fits and policies as the uninterrupted run, bit for bit.

use gps::snapshot::Snapshot;

use super::{Bco, BcoConfig};
use crate::demos::Demos;
use crate::mlp_policy::global::{flat_len, GlobalPolicy};
use crate::ImitationError;

/// Iterations done (u64, 1).
pub const ITERATION: &str = "bco.iteration";
/// The policy's flat parameters ([`GlobalPolicy::flat`]).
const POLICY: &str = "bco.policy";

/// A checkpoint error, with what to do about it.
fn refused(what: impl std::fmt::Display) -> ImitationError {
    ImitationError::Checkpoint(format!(
        "{what} (a checkpoint of another task or other settings: resume with the run's own \
         demonstrations and --config)"
    ))
}

impl Bco {
    /// Everything the next iteration depends on (module docs).
    pub fn snapshot(&self) -> Snapshot {
        let mut s = Snapshot::default();
        s.put_words(ITERATION, &[self.iteration as u64]);
        let flat = self.policy.flat();
        s.put(POLICY, &[flat.len()], &flat);
        self.opt.snapshot(&mut s);
        self.model.snapshot(&mut s);
        s
    }

    /// A run that continues exactly where the run whose [`Bco::snapshot`] is `snap` stood.
    /// `cfg` and `demos` must be the run's own (the sizes are checked against the snapshot).
    pub fn from_snapshot(
        cfg: BcoConfig,
        demos: Demos,
        snap: &Snapshot,
    ) -> Result<Self, ImitationError> {
        let mut run = Self::new(cfg, demos)?;
        let iteration = snap.words(ITERATION, 1).map_err(refused)?[0];
        let hidden = run.cfg.policy.hidden.clone();
        let layout = run.layout;
        let flat = snap
            .real(POLICY, &[flat_len(layout.dx(), layout.du(), &hidden)])
            .map_err(refused)?;
        let policy = GlobalPolicy::from_flat(layout, &hidden, flat)
            .map_err(|e| refused(format!("{POLICY}: {e}")))?;
        run.opt.restore(snap).map_err(refused)?;
        run.model.restore(snap).map_err(refused)?;
        run.iteration = usize::try_from(iteration)
            .map_err(|_| refused(format!("{ITERATION} = {iteration}: too large")))?;
        run.policy = policy;
        Ok(run)
    }
}
