//! Exact resume of an off-policy GAIfO run: [`GaifoTd3::snapshot`] holds everything but the
//! critic D that the next iteration depends on — the iteration, the actor and its target (flat
//! policy-table layout), both critics and their targets, the three Adam states, TD3's step
//! count, the RNG position and the replay buffer's rows in order; the critic D is saved on its
//! own ([`crate::critic::Critic::save`]). [`GaifoTd3::from_snapshot`] continues from one
//! exactly: the same episodes, minibatches and updates as the uninterrupted run, bit for bit.

use gps::snapshot::Snapshot;

use super::td3::q_sizes;
use super::{GaifoTd3, GaifoTd3Config};
use crate::demos::Demos;
use crate::discriminator::{Adam, Discriminator};
use crate::mlp_policy::global::{flat_len, GlobalPolicy};
use crate::ImitationError;

const ITERATION: &str = "td3.iteration";
const STEPS: &str = "td3.steps";
const RNG: &str = "td3.rng";
const ACTOR: &str = "td3.actor";
const ACTOR_TARGET: &str = "td3.actor_target";

fn refused(what: impl std::fmt::Display) -> ImitationError {
    ImitationError::Checkpoint(format!(
        "{what} (a checkpoint of other settings or another task: resume with the run's own \
         demonstrations and --config)"
    ))
}

fn put_adam(s: &mut Snapshot, name: &str, adam: &Adam) {
    s.put_words(&format!("{name}.t"), &[adam.t]);
    s.put(&format!("{name}.m"), &[adam.m.len()], &adam.m);
    s.put(&format!("{name}.v"), &[adam.v.len()], &adam.v);
}

fn restore_adam(s: &Snapshot, name: &str, adam: &mut Adam) -> Result<(), ImitationError> {
    let n = adam.m.len();
    adam.t = s.words(&format!("{name}.t"), 1).map_err(refused)?[0];
    adam.m = s
        .real(&format!("{name}.m"), &[n])
        .map_err(refused)?
        .to_vec();
    adam.v = s
        .real(&format!("{name}.v"), &[n])
        .map_err(refused)?
        .to_vec();
    Ok(())
}

impl GaifoTd3 {
    /// Everything but the critic D that the next iteration depends on (module docs).
    pub fn snapshot(&self) -> Snapshot {
        let mut s = Snapshot::default();
        let t = &self.td3;
        s.put_words(ITERATION, &[self.iteration as u64]);
        s.put_words(STEPS, &[t.steps]);
        s.put_rng(RNG, &self.rng);
        for (name, pol) in [(ACTOR, &t.actor), (ACTOR_TARGET, &t.actor_target)] {
            let flat = pol.flat();
            s.put(name, &[flat.len()], &flat);
        }
        for k in 0..2 {
            let (q, qt) = (t.q[k].params(), t.q_target[k].params());
            s.put(&format!("td3.q{k}"), &[q.len()], q);
            s.put(&format!("td3.q{k}_target"), &[qt.len()], qt);
            put_adam(&mut s, &format!("td3.q{k}.adam"), &t.adam_q[k]);
        }
        put_adam(&mut s, "td3.actor.adam", &t.adam_actor);
        self.buffer.snapshot(&mut s);
        s
    }

    /// A run that continues exactly where the run whose [`GaifoTd3::snapshot`] is `snap` and
    /// whose critic is `disc` stood. `cfg` and `demos` must be the run's own: the critic's
    /// settings and seed are checked against `cfg`, the nets' sizes and the buffer's against
    /// the snapshot.
    pub fn from_snapshot(
        cfg: GaifoTd3Config,
        demos: Demos,
        snap: &Snapshot,
        disc: Discriminator,
    ) -> Result<Self, ImitationError> {
        let mut run = Self::new(cfg, demos)?;
        run.critic.restore(disc)?;
        let iteration = snap.words(ITERATION, 1).map_err(refused)?[0];
        let hidden = run.cfg.td3.pi_hidden.clone();
        let layout = run.task.layout();
        let n_flat = flat_len(layout.dx(), layout.du(), &hidden);
        let policy = |name: &str| {
            let flat = snap.real(name, &[n_flat]).map_err(refused)?;
            GlobalPolicy::from_flat(layout, &hidden, flat)
                .map_err(|e| refused(format!("{name}: {e}")))
        };
        let (actor, actor_target) = (policy(ACTOR)?, policy(ACTOR_TARGET)?);
        let t = &mut run.td3;
        let n_q = crate::discriminator::mlp::param_count(&q_sizes(
            layout.dx(),
            layout.du(),
            &run.cfg.td3.q_hidden,
        ));
        for k in 0..2 {
            for (name, net) in [
                (format!("td3.q{k}"), &mut t.q[k]),
                (format!("td3.q{k}_target"), &mut t.q_target[k]),
            ] {
                let p = snap.real(&name, &[n_q]).map_err(refused)?;
                if let Some(i) = p.iter().position(|v| !v.is_finite()) {
                    return Err(refused(format!("{name}[{i}] is not finite")));
                }
                net.params_mut().copy_from_slice(p);
            }
            restore_adam(snap, &format!("td3.q{k}.adam"), &mut t.adam_q[k])?;
        }
        restore_adam(snap, "td3.actor.adam", &mut t.adam_actor)?;
        t.steps = snap.words(STEPS, 1).map_err(refused)?[0];
        t.actor = actor;
        t.actor_target = actor_target;
        run.rng = snap.rng(RNG).map_err(refused)?;
        run.buffer.restore(snap)?;
        run.iteration = usize::try_from(iteration)
            .map_err(|_| refused(format!("{ITERATION} = {iteration}: too large")))?;
        Ok(run)
    }
}
