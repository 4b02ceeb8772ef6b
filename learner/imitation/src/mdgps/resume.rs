//! Exact resume of an MDGPS run (docs/design.md §6.5): [`Mdgps::snapshot`] holds everything
//! but the critic that the next iteration depends on — the iteration, the global policy (its
//! input normalisation, weights and σ: [`GlobalPolicy::flat`]), the S-step's Adam moments and
//! step count and its minibatch RNG position, and each condition's LQR state
//! ([`LqrIteration::snapshot`]: controller executed next and the previous one, GMM dynamics
//! prior, trajectory info, η, the prior's RNG position) under `condition<m>.`; the critic is
//! saved on its own ([`crate::critic::Critic::save`]). The policy's linearisations are not
//! saved: every iteration recomputes them before they are used. [`Mdgps::from_snapshot`]
//! continues from one exactly: the same episodes, critic updates, C- and S-steps as the
//! uninterrupted run, bit for bit.

use gps::snapshot::Snapshot;

use super::{Mdgps, MdgpsConfig};
use crate::demos::Demos;
use crate::discriminator::Discriminator;
use crate::iteration::LqrIteration;
use crate::mlp_policy::global::{flat_len, GlobalPolicy};
use crate::ImitationError;

/// Iterations done (u64, 1).
const ITERATION: &str = "mdgps.iteration";
/// The global policy's flat parameters ([`GlobalPolicy::flat`]).
const POLICY: &str = "mdgps.policy";

/// Prefix of condition `m`'s arrays.
fn condition_prefix(m: usize) -> String {
    format!("condition{m}.")
}

/// A checkpoint error, with what to do about it.
fn refused(what: impl std::fmt::Display) -> ImitationError {
    ImitationError::Checkpoint(format!(
        "{what} (a checkpoint of another number of goals, task horizon or other settings: \
         resume with the run's own demonstrations and --config)"
    ))
}

/// Condition `m`'s LQR state into `out` under its prefix.
fn put_condition(out: &mut Snapshot, m: usize, lqr: &LqrIteration) {
    let mut one = Snapshot::default();
    lqr.snapshot(&mut one);
    let p = condition_prefix(m);
    out.reals
        .extend(one.reals.into_iter().map(|(k, v)| (format!("{p}{k}"), v)));
    out.words
        .extend(one.words.into_iter().map(|(k, v)| (format!("{p}{k}"), v)));
}

/// The arrays of `snap` under condition `m`'s prefix, without it.
fn condition(snap: &Snapshot, m: usize) -> Snapshot {
    let p = condition_prefix(m);
    let strip = |k: &String| k.strip_prefix(&p).map(str::to_owned);
    Snapshot {
        reals: snap
            .reals
            .iter()
            .filter_map(|(k, v)| Some((strip(k)?, v.clone())))
            .collect(),
        words: snap
            .words
            .iter()
            .filter_map(|(k, v)| Some((strip(k)?, v.clone())))
            .collect(),
    }
}

impl Mdgps {
    /// Everything but the critic that the next iteration depends on (module docs); the critic
    /// is saved on its own ([`crate::critic::Critic::save`] of [`Mdgps::critic`]).
    pub fn snapshot(&self) -> Snapshot {
        let mut s = Snapshot::default();
        s.put_words(ITERATION, &[self.iteration as u64]);
        let flat = self.policy.flat();
        s.put(POLICY, &[flat.len()], &flat);
        self.opt.snapshot(&mut s);
        for (m, c) in self.conds.iter().enumerate() {
            put_condition(&mut s, m, &c.lqr);
        }
        s
    }

    /// A run that continues exactly where the run whose [`Mdgps::snapshot`] is `snap` and
    /// whose critic is `disc` stood. `cfg` and `demos` must be the run's own: the critic's
    /// settings and seed are checked against `cfg`, the number of conditions, the policy's size
    /// and every condition's horizon against the snapshot.
    pub fn from_snapshot(
        cfg: MdgpsConfig,
        demos: Vec<Demos>,
        snap: &Snapshot,
        disc: Discriminator,
    ) -> Result<Self, ImitationError> {
        let mut run = Self::new(cfg, demos)?;
        run.critic.restore(disc)?;
        let m = run.conds.len();
        if snap.has(&format!("{}lqr.iteration", condition_prefix(m))) {
            return Err(refused(format!(
                "the checkpoint has more conditions than the {m} demonstrated goals"
            )));
        }
        let iteration = snap.words(ITERATION, 1).map_err(refused)?[0];
        let hidden = run.cfg.policy.hidden.clone();
        let layout = run.layout();
        let flat = snap
            .real(POLICY, &[flat_len(layout.dx(), layout.du(), &hidden)])
            .map_err(refused)?;
        let policy = GlobalPolicy::from_flat(layout, &hidden, flat)
            .map_err(|e| refused(format!("{POLICY}: {e}")))?;
        run.opt.restore(snap).map_err(refused)?;
        for (i, c) in run.conds.iter_mut().enumerate() {
            c.lqr
                .restore(&condition(snap, i))
                .map_err(|e| refused(format!("condition {i}: {e}")))?;
            if c.lqr.iteration() as u64 != iteration {
                return Err(refused(format!(
                    "condition {i} is at iteration {}, the run at {iteration}",
                    c.lqr.iteration()
                )));
            }
        }
        run.iteration = usize::try_from(iteration)
            .map_err(|_| refused(format!("{ITERATION} = {iteration}: too large")))?;
        run.policy = policy;
        Ok(run)
    }
}
