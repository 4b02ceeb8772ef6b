//! `learner policy serve`: publishes a saved MDGPS policy as a policy table on
//! `controller/policy` (docs/design.md §3.11) and reports the episodes the controller runs
//! with it, from the `learner/samples` stream: per episode its steps, the distance of the tool
//! centre point to its goal at the last step (the first tool point of the table's layout, m)
//! and, for noise-free episodes, how many actions differ from the policy's own
//! [`policy_action`] on the recorded state (0: the controller executed the policy exactly).
//! The goal is the controller's (`rt-controller run --goal x,y,z`); the policy is
//! time-invariant, so one table serves any goal. The table carries its task's dimensions
//! (dX, dU); a sample of other dimensions (a controller running another task) is refused,
//! naming both.

use std::time::{Duration, Instant};

use serde::Serialize;
use ur5_shared::layout::StateLayout;
use ur5_shared::{policy_action, PolicyScratch, PolicyTable, MAX_DU, NO_NOISE};

use super::ports::Ports;
use super::ServeError;
use crate::error::ensure;

/// One episode the controller ran with the policy.
#[derive(Clone, Debug, Serialize)]
pub struct PolicyEpisode {
    /// The controller's episode number.
    pub episode: u64,
    /// Table version it ran.
    pub version: u64,
    /// With exploration noise.
    pub noisy: bool,
    /// Steps received (t = 0 … steps − 1).
    pub steps: usize,
    /// |ee − goal| at the last step's state (m).
    pub distance_last_m: f64,
    /// Noise-free episodes: actions that differ (any bit) from [`policy_action`] on the
    /// recorded state; `None` for noisy ones.
    pub mismatched_actions: Option<usize>,
}

/// Options of [`serve_policy`].
#[derive(Clone, Debug)]
pub struct PolicyServeOptions {
    /// iceoryx2 prefix.
    pub prefix: String,
    /// Steps per episode (the controller's task.horizon).
    pub steps: usize,
    /// Stop after this many complete episodes.
    pub episodes: usize,
    /// Give up when no sample arrives for this long (s).
    pub timeout_s: f64,
}

/// Publishes `table` and collects `opts.episodes` complete episodes of it, calling `report`
/// on each. Errors if no sample arrives for `opts.timeout_s`.
pub fn serve_policy(
    table: &PolicyTable,
    opts: &PolicyServeOptions,
    mut report: impl FnMut(&PolicyEpisode),
) -> Result<Vec<PolicyEpisode>, ServeError> {
    ensure!(
        opts.steps >= 1,
        ServeError::Range("--steps must be >= 1".into())
    );
    ensure!(
        opts.timeout_s.is_finite() && opts.timeout_s > 0.0,
        ServeError::Range(format!("--timeout-s {} must be > 0", opts.timeout_s))
    );
    let ports = Ports::<PolicyTable>::create(&opts.prefix)?;
    let result = collect(&ports, table, opts, &mut report);
    if let Err(e) = &result {
        ports.status.stopping(e);
    }
    result
}

/// [`serve_policy`] once its ports exist.
fn collect(
    ports: &Ports<PolicyTable>,
    table: &PolicyTable,
    opts: &PolicyServeOptions,
    report: &mut impl FnMut(&PolicyEpisode),
) -> Result<Vec<PolicyEpisode>, ServeError> {
    let (dx, du) = table.dims();
    let layout = StateLayout::from_dims(dx, du).ok_or_else(|| {
        ServeError::Range(format!(
            "the policy table's dimensions dX = {dx}, dU = {du} are those of no task"
        ))
    })?;
    ports.publish(table)?;
    let mut scratch = PolicyScratch::default();
    let mut done = Vec::new();
    // The episode being assembled: (episode, version, noisy, next t, last |ee − goal|, mismatches).
    let mut cur: Option<(u64, u64, bool, usize, f64, usize)> = None;
    let mut last_sample = Instant::now();
    while done.len() < opts.episodes {
        ports.update_connections();
        let sample = match ports.samples.receive() {
            Ok(Some(s)) => *s,
            Ok(None) => {
                ports.status.check_controller()?;
                ensure!(
                    last_sample.elapsed().as_secs_f64() < opts.timeout_s,
                    ServeError::NoSamples {
                        prefix: opts.prefix.clone(),
                        timeout_s: opts.timeout_s
                    }
                );
                std::thread::sleep(Duration::from_millis(1));
                continue;
            }
            Err(e) => return Err(ServeError::Ipc(format!("receiving samples: {e:?}"))),
        };
        last_sample = Instant::now();
        if sample.table_version != table.version {
            continue; // another controller kind or version (e.g. an older gain table)
        }
        layout
            .check_dims(
                "a sample of the controller",
                sample.state().len(),
                sample.action().len(),
            )
            .map_err(ServeError::Peer)?;
        let t = sample.t as usize;
        let noisy = sample.noise != 0;
        let fresh = t == 0;
        let continues = matches!(cur, Some((e, v, n, next, _, _))
            if e == sample.episode && v == sample.table_version && n == noisy && next == t);
        if fresh {
            cur = Some((sample.episode, sample.table_version, noisy, 0, 0.0, 0));
        } else if !continues {
            cur = None; // samples lost or an aborted episode: discard
            continue;
        }
        let c = cur.as_mut().expect("set above");
        if !noisy {
            let mut a = [0.0; MAX_DU];
            let a = &mut a[..sample.action().len()];
            let same = policy_action(table, sample.state(), &NO_NOISE, &mut scratch, a).is_ok()
                && a.iter()
                    .zip(sample.action())
                    .all(|(x, y)| x.to_bits() == y.to_bits());
            if !same {
                c.5 += 1;
            }
        }
        c.3 = t + 1;
        c.4 = sample.state()[layout.point(0)]
            .iter()
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt();
        if c.3 == opts.steps {
            let ep = PolicyEpisode {
                episode: c.0,
                version: c.1,
                noisy: c.2,
                steps: c.3,
                distance_last_m: c.4,
                mismatched_actions: (!c.2).then_some(c.5),
            };
            report(&ep);
            done.push(ep);
            cur = None;
        }
    }
    Ok(done)
}
