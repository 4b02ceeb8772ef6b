//! Episodes from the sample stream: the controller streams one `StepSample` per step; the
//! [`Assembler`] groups them into complete episodes and [`Batch`] keeps those of the table version
//! an update waits for (docs/design.md §3.6, "Which episodes count").

use imitation::rollout::Episode;
use serde::Serialize;
use ur5_shared::layout::DimensionMismatch;
use ur5_shared::{StateLayout, StepSample};

/// Counts of what arrived.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Counts {
    /// Samples received.
    pub samples: u64,
    /// Complete episodes received (any version).
    pub episodes: u64,
    /// Episodes used by an update.
    pub used: u64,
    /// Discarded: incomplete (aborted by the controller, or samples lost).
    pub partial: u64,
    /// Discarded: the table version or the noise flag changed inside the episode.
    pub mixed: u64,
    /// Complete episodes of an older table version (run while the learner was updating).
    pub old_version: u64,
    /// Complete episodes of a newer table version than this learner's (another learner).
    pub newer_version: u64,
    /// Complete episodes of the current version beyond the N + 1 an update needs.
    pub surplus: u64,
}

/// Builds an [`Episode`] from the samples of one complete episode (t = 0 … T−1):
/// `x` = s, `u` = a_sent (executed), `u_policy` = a, at the samples' dimensions (those of the
/// first; the [`Assembler`] lets only samples of its layout through); ε is not sent and stays
/// empty.
pub fn episode_from_samples(samples: &[StepSample]) -> Episode {
    let (dx, du) = samples
        .first()
        .map_or((0, 0), |s| (s.state().len(), s.action().len()));
    let layout = ur5_shared::StateLayout::from_dims(dx, du).unwrap_or_default();
    let mut ep = Episode {
        layout,
        x: Vec::with_capacity(samples.len() * dx),
        u: Vec::with_capacity(samples.len() * du),
        u_policy: Vec::with_capacity(samples.len() * du),
        eps: Vec::new(),
        noisy: samples.first().is_some_and(StepSample::is_noisy),
    };
    for s in samples {
        ep.x.extend_from_slice(s.state());
        ep.u.extend_from_slice(s.action_sent());
        ep.u_policy.extend_from_slice(s.action());
    }
    ep
}

/// What the [`Assembler`] made of an episode once it ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Assembled {
    /// All T steps in order, one version (and publication of it), one noise flag.
    Complete {
        /// Controller episode number.
        episode: u64,
        /// Table version.
        version: u64,
        /// Its publication ([`ur5_shared::GainTable::epoch`]).
        epoch: u32,
        /// The episode.
        ep: Episode,
    },
    /// Ended (or was cut) before t = T−1, or missed samples.
    Partial {
        /// Controller episode number.
        episode: u64,
        /// Samples it had.
        have: usize,
    },
    /// The version (or its publication) or the noise flag changed inside the episode.
    Mixed {
        /// Controller episode number.
        episode: u64,
    },
    /// A sample of another task's dimensions than the learner's: a controller for another
    /// task is on the stream.
    WrongDimensions {
        /// Controller episode number.
        episode: u64,
        /// The sample's dimensions against the learner's layout.
        mismatch: DimensionMismatch,
    },
}

/// Groups the sample stream into episodes.
pub struct Assembler {
    horizon: usize,
    layout: StateLayout,
    cur: Vec<StepSample>,
    gap: bool,
    mixed: bool,
}

impl Assembler {
    /// For episodes of `horizon` steps of the task of `layout`.
    pub fn new(horizon: usize, layout: StateLayout) -> Self {
        Self {
            horizon,
            layout,
            cur: Vec::with_capacity(horizon),
            gap: false,
            mixed: false,
        }
    }

    fn close(&mut self) -> Option<Assembled> {
        let first = *self.cur.first()?;
        let out = if self.mixed {
            Assembled::Mixed {
                episode: first.episode,
            }
        } else if self.gap || self.cur.len() != self.horizon {
            Assembled::Partial {
                episode: first.episode,
                have: self.cur.len(),
            }
        } else {
            Assembled::Complete {
                episode: first.episode,
                version: first.table_version,
                epoch: first.table_epoch,
                ep: episode_from_samples(&self.cur),
            }
        };
        self.cur.clear();
        self.gap = false;
        self.mixed = false;
        Some(out)
    }

    /// Takes one sample; returns the episodes it ended (at most two: an unfinished one cut
    /// off by this sample, and this sample's own if it is the last step).
    pub fn push(&mut self, s: &StepSample) -> Vec<Assembled> {
        let mut out = Vec::new();
        if let Err(mismatch) =
            self.layout
                .check_dims("a controller's sample", s.dx as usize, s.du as usize)
        {
            out.extend(self.close());
            out.push(Assembled::WrongDimensions {
                episode: s.episode,
                mismatch,
            });
            return out;
        }
        if let Some(last) = self.cur.last() {
            if s.episode != last.episode {
                out.extend(self.close());
            } else {
                self.gap |= s.t != last.t + 1;
                self.mixed |= s.table_version != last.table_version
                    || s.table_epoch != last.table_epoch
                    || s.noise != last.noise;
            }
        }
        if self.cur.len() >= self.horizon {
            // More samples of one episode than it has steps (repeated or stray step numbers):
            // a partial episode, so that a stream of bad samples cannot grow this without bound.
            out.extend(self.close());
        }
        if self.cur.is_empty() {
            self.gap = s.t != 0;
        }
        self.cur.push(*s);
        if s.t as usize + 1 >= self.horizon {
            out.extend(self.close());
        }
        out
    }
}

/// The episodes of one table version an update waits for: the first N noisy and the first
/// noise-free one offered (in arrival order; `learner replay` picks them the same way).
#[derive(Default)]
pub struct Batch {
    /// The noisy episodes (at most N).
    pub noisy: Vec<Episode>,
    /// The noise-free episode.
    pub eval: Option<Episode>,
}

impl Batch {
    /// N noisy and the noise-free episode are in.
    pub fn full(&self, n: usize) -> bool {
        self.noisy.len() >= n && self.eval.is_some()
    }

    /// Takes `ep` if the batch still needs one of its kind.
    pub fn offer(&mut self, ep: Episode, n: usize) -> bool {
        if ep.noisy && self.noisy.len() < n {
            self.noisy.push(ep);
        } else if !ep.noisy && self.eval.is_none() {
            self.eval = Some(ep);
        } else {
            return false;
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples of one episode that never reach its last step (here step 1 again and again)
    /// are cut into partial episodes of at most T samples instead of piling up.
    #[test]
    fn a_stream_of_repeated_steps_is_cut_into_partial_episodes() {
        let mut a = Assembler::new(5, StateLayout::REACH3);
        let mut s = StepSample {
            t: 1,
            episode: 1,
            ..Default::default()
        };
        s.set_state(&[0.0; 12]);
        s.set_actions(&[0.0; 3], &[0.0; 3]);
        let out: Vec<Assembled> = (0..12).flat_map(|_| a.push(&s)).collect();
        assert_eq!(out.len(), 2, "{out:?}");
        assert!(out
            .iter()
            .all(|o| matches!(o, Assembled::Partial { have: 5, .. })));
    }

    /// A sample of another task's dimensions is named, never assembled into an episode.
    #[test]
    fn a_sample_of_another_task_is_refused_naming_both() {
        let mut a = Assembler::new(5, StateLayout::REACH3);
        let mut s = StepSample::default();
        s.set_state(&[0.0; 30]);
        s.set_actions(&[0.0; 6], &[0.0; 6]);
        let out = a.push(&s);
        let [Assembled::WrongDimensions { mismatch, .. }] = &out[..] else {
            panic!("{out:?}");
        };
        let msg = mismatch.to_string();
        assert!(
            msg.contains("dX = 30, dU = 6") && msg.contains("dX = 12, dU = 3"),
            "{msg}"
        );
    }
}
