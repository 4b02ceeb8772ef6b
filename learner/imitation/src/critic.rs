//! The critic D(s, s') of GAIfO (docs/design.md §1.3 step 3, §5 D2, D6–D8, D23, D25), in one
//! place for every learner that imitates with it: LQR+GAIfO, MDGPS and the GAIfO (PPO)
//! baseline each own a [`Critic`]. It holds the expert transitions it is trained against, the
//! discriminator and its scratch memory, and its schedule:
//!
//! - at iteration 0 the discriminator is rebuilt once, its input normalisation fitted on
//!   expert ∪ the first iteration's controller transitions (D2);
//! - every iteration, `updates` WGAN-GP calls at the learning rate
//!   `lr · 2^(−iteration / half_life)` (D25).
//!
//! The learners take their cost from [`Critic::cost_discriminator`]: the discriminator itself,
//! or, with `param_average` > 0, the one with its running average of weights (D37).
//!
//! Its checkpoint is the discriminator's file ([`Critic::save`]); [`Critic::restore`] takes one
//! back after checking that it was trained with the run's settings and seed.

use std::path::Path;

use crate::demos::Demos;
use crate::discriminator::{Discriminator, DiscriminatorConfig, Normalizer, TrainStats, Workspace};
use crate::rollout::Episode;
use crate::settings::CriticSettings;
use crate::ImitationError;
use faer::Mat;

/// Expert transitions [s_t; s_{t+1}] of every demonstration, one per row (`count · (T − 1)` ×
/// 2 dX).
pub fn expert_transitions(demos: &Demos) -> Mat<f64> {
    let rows = demos.count * (demos.horizon - 1);
    let dx = demos.layout().dx();
    Mat::from_fn(rows, 2 * dx, |r, c| {
        let (d, t) = (r / (demos.horizon - 1), r % (demos.horizon - 1));
        if c < dx {
            demos.state(d, t)[c]
        } else {
            demos.state(d, t + 1)[c - dx]
        }
    })
}

/// Controller transitions [s_t; s_{t+1}] of the given episodes (all of one horizon T), one per
/// row (`episodes.len() · (T − 1)` × 2 dX).
pub fn episode_transitions(episodes: &[Episode]) -> Mat<f64> {
    let t_len = episodes[0].horizon();
    let rows = episodes.len() * (t_len - 1);
    let dx = episodes[0].dx();
    Mat::from_fn(rows, 2 * dx, |r, c| {
        let (i, t) = (r / (t_len - 1), r % (t_len - 1));
        let ep = &episodes[i];
        if c < dx {
            ep.x[t * dx + c]
        } else {
            ep.x[(t + 1) * dx + c - dx]
        }
    })
}

/// `transitions` (rows [s_t; s_{t+1}] of episodes of horizon `horizon`, `T − 1` rows each, in
/// step order, as [`expert_transitions`] and [`episode_transitions`] give them) with the phase
/// t/(T − 1) of each row's first state appended as a last column: the inputs of a critic
/// D(s, s', φ) (docs/design.md §5 D39).
pub fn with_phase(transitions: &Mat<f64>, horizon: usize) -> Mat<f64> {
    let d = transitions.ncols();
    Mat::from_fn(transitions.nrows(), d + 1, |r, c| {
        if c < d {
            transitions[(r, c)]
        } else {
            crate::cost::composite::phase(r % (horizon - 1), horizon)
        }
    })
}

/// `transitions` (rows of `2 dX` or, with the phase, `2 dX + 1` inputs) with `copies` rows of
/// the resting pair [s; s] appended for each final state `s` of `finals` (each dX long), final
/// after final: the pair the last step's cost D(s, s) evaluates (docs/design.md §5 D10), so
/// that the critic is trained on it for the demonstrations' and the controller's final states
/// alike instead of extrapolating to it (§5 D44). With the phase, these rows take the last
/// step's, 1. `copies` = 0 returns `transitions` unchanged.
pub fn with_terminal_pairs(transitions: Mat<f64>, finals: &[&[f64]], copies: usize) -> Mat<f64> {
    if copies == 0 || finals.is_empty() {
        return transitions;
    }
    let (rows, d) = (transitions.nrows(), transitions.ncols());
    let dx = finals[0].len();
    Mat::from_fn(rows + copies * finals.len(), d, |r, c| {
        if r < rows {
            transitions[(r, c)]
        } else if c < 2 * dx {
            finals[(r - rows) / copies][c % dx]
        } else {
            1.0
        }
    })
}

/// The critic's config for run seed `seed`: `dcfg` with its seed mixed with the run's, so
/// that runs with different seeds get different critics.
pub fn critic_config(dcfg: &DiscriminatorConfig, seed: u64) -> DiscriminatorConfig {
    let mut dcfg = dcfg.clone();
    dcfg.seed = seed ^ dcfg.seed ^ 0x4352_4954; // "CRIT"
    dcfg
}

/// A fresh discriminator (`dcfg`, weights drawn again from its seed) whose input
/// normalisation is fitted on expert ∪ `controller` transitions: what [`Critic::update`] does
/// at iteration 0 (docs/design.md §5 D2).
pub fn refit_critic(
    expert: &Mat<f64>,
    controller: &Mat<f64>,
    dcfg: &DiscriminatorConfig,
) -> Result<Discriminator, ImitationError> {
    let (ne, nc) = (expert.nrows(), controller.nrows());
    let both = Mat::from_fn(ne + nc, expert.ncols(), |r, c| {
        if r < ne {
            expert[(r, c)]
        } else {
            controller[(r - ne, c)]
        }
    });
    let norm = Normalizer::from_data(dcfg.warp_rows(both.as_ref()).as_ref())?;
    Ok(Discriminator::new(expert.ncols(), dcfg.clone(), norm)?)
}

/// The critic of a run: the discriminator trained against the expert transitions on its
/// schedule (module docs).
pub struct Critic {
    expert: Mat<f64>,
    disc: Discriminator,
    /// `disc` with its averaged weights ([`Discriminator::averaged`]), refreshed after every
    /// update; `None` when averaging is off.
    averaged: Option<Discriminator>,
    ws: Workspace,
    updates: usize,
    half_life: f64,
    seed: u64,
}

impl Critic {
    /// The run's first critic: input normalisation fitted on the `expert` transitions (rows of
    /// [s; s'], 2 dX columns), `dcfg` seeded from the run seed `seed` ([`critic_config`]); one
    /// WGAN-GP call per iteration at a constant learning rate until
    /// [`Critic::with_schedule`].
    pub fn new(
        expert: Mat<f64>,
        dcfg: &DiscriminatorConfig,
        seed: u64,
    ) -> Result<Self, ImitationError> {
        let norm = Normalizer::from_data(dcfg.warp_rows(expert.as_ref()).as_ref())?;
        let disc = Discriminator::new(expert.ncols(), critic_config(dcfg, seed), norm)?;
        Ok(Self {
            ws: disc.workspace(),
            expert,
            disc,
            averaged: None,
            updates: 1,
            half_life: 0.0,
            seed,
        })
    }

    /// The critic of a learner with critic settings `settings` and run seed `seed`: [`Critic::new`]
    /// on `settings.discriminator`, on the schedule `settings.updates`,
    /// `settings.lr_half_life` ([`Critic::with_schedule`]).
    pub fn from_settings(
        expert: Mat<f64>,
        settings: CriticSettings<'_>,
        seed: u64,
    ) -> Result<Self, ImitationError> {
        Ok(Self::new(expert, settings.discriminator, seed)?
            .with_schedule(settings.updates, settings.lr_half_life))
    }

    /// This critic with `updates` WGAN-GP calls per iteration (at least 1) and a learning-rate
    /// half-life of `half_life` iterations (0: constant; docs/design.md §5 D25).
    pub fn with_schedule(self, updates: usize, half_life: f64) -> Self {
        Self {
            updates: updates.max(1),
            half_life,
            ..self
        }
    }

    /// The discriminator.
    pub fn discriminator(&self) -> &Discriminator {
        &self.disc
    }

    /// The critic the learners' cost is taken from: the discriminator, or with
    /// `param_average` > 0 the discriminator with its averaged weights (docs/design.md §5 D37).
    pub fn cost_discriminator(&self) -> &Discriminator {
        self.averaged.as_ref().unwrap_or(&self.disc)
    }

    /// The expert transitions it is trained against.
    pub fn expert(&self) -> &Mat<f64> {
        &self.expert
    }

    /// Step 3 of Algorithm 1 (docs/design.md §1.3) at iteration `iteration` on the
    /// `controller` transitions ([`episode_transitions`]): at iteration 0 the rebuild with the
    /// normalisation refitted on expert ∪ `controller` ([`refit_critic`]), then the
    /// iteration's WGAN-GP calls at the learning rate `lr · 2^(−iteration / half_life)`
    /// (docs/design.md §5 D25); returns the last call's statistics.
    pub fn update(
        &mut self,
        controller: &Mat<f64>,
        iteration: usize,
    ) -> Result<TrainStats, ImitationError> {
        if iteration == 0 {
            self.disc = refit_critic(&self.expert, controller, self.disc.config())?;
            self.ws = self.disc.workspace();
        }
        if self.half_life > 0.0 {
            let lr = self.disc.config().adam.lr * (-(iteration as f64) / self.half_life).exp2();
            self.disc.set_learning_rate(lr)?;
        }
        let mut stats = None;
        for _ in 0..self.updates {
            stats = Some(self.disc.train(
                self.expert.as_ref(),
                controller.as_ref(),
                &mut self.ws,
            )?);
        }
        self.averaged = self.disc.averaged();
        Ok(stats.expect("at least one update"))
    }

    /// Rewards `r_t = −D(s_t, s_{t+1})` of every transition of every episode (`[episode][t]`,
    /// T − 1 each).
    pub fn rewards(&mut self, episodes: &[Episode]) -> Vec<Vec<f64>> {
        let mut x = vec![0.0; self.disc.input_dim()];
        let (disc, ws) = (self.averaged.as_ref().unwrap_or(&self.disc), &mut self.ws);
        episodes
            .iter()
            .map(|ep| {
                let dx = ep.dx();
                (0..ep.horizon() - 1)
                    .map(|t| {
                        x[..dx].copy_from_slice(ep.state(t));
                        x[dx..].copy_from_slice(ep.state(t + 1));
                        -disc.value(&x, ws)
                    })
                    .collect()
            })
            .collect()
    }

    /// Writes the critic's checkpoint (weights, input normalisation, Adam moments and step
    /// count, minibatch RNG position) to `path`, atomically ([`Discriminator::save`]).
    pub fn save(&self, path: &Path) -> Result<(), ImitationError> {
        Ok(self.disc.save(path)?)
    }

    /// Continues from the checkpointed discriminator `disc` (read with
    /// [`Discriminator::load`]): refused unless it was trained with this critic's settings
    /// (`dcfg`, the one given to [`Critic::new`]) and seed.
    pub fn restore(&mut self, disc: Discriminator) -> Result<(), ImitationError> {
        if disc.config() != self.disc.config() || disc.input_dim() != self.disc.input_dim() {
            return Err(ImitationError::Checkpoint(format!(
                "the critic was trained with other [discriminator] settings or another seed than \
                 this run's (seed {}): resume with the run's own --config and --seed",
                self.seed
            )));
        }
        self.ws = disc.workspace();
        self.averaged = disc.averaged();
        self.disc = disc;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ur5_shared::layout::DX;

    const D_IN: usize = 2 * DX;

    /// Two episodes of T = 4: rows t = 0, 1, 2 of each get the phases 0, 1/3, 2/3; the
    /// transitions are kept as they were.
    #[test]
    fn the_phase_is_each_rows_first_step_over_t_minus_one() {
        let x = transitions(6, 0.0);
        let p = with_phase(&x, 4);
        assert_eq!((p.nrows(), p.ncols()), (6, D_IN + 1));
        for r in 0..6 {
            assert_eq!(p[(r, D_IN)], (r % 3) as f64 / 3.0);
            for c in 0..D_IN {
                assert_eq!(p[(r, c)], x[(r, c)]);
            }
        }
    }

    /// Each final state's resting pair is appended `copies` times, final after final, after the
    /// transitions, which are kept; with the phase, those rows take phase 1; no copies, no rows.
    #[test]
    fn terminal_pairs_are_appended_as_resting_pairs() {
        let x = transitions(6, 0.0);
        let a: Vec<f64> = (0..DX).map(|i| i as f64 + 0.5).collect();
        let b: Vec<f64> = (0..DX).map(|i| -(i as f64) - 0.25).collect();
        let finals = [a.as_slice(), b.as_slice()];
        for phase in [false, true] {
            let x = if phase { with_phase(&x, 4) } else { x.clone() };
            let p = with_terminal_pairs(x.clone(), &finals, 3);
            assert_eq!((p.nrows(), p.ncols()), (12, x.ncols()));
            for r in 0..6 {
                for c in 0..x.ncols() {
                    assert_eq!(p[(r, c)], x[(r, c)]);
                }
            }
            for r in 6..12 {
                let s = finals[(r - 6) / 3];
                for c in 0..DX {
                    assert_eq!((p[(r, c)], p[(r, DX + c)]), (s[c], s[c]));
                }
                if phase {
                    assert_eq!(p[(r, D_IN)], 1.0);
                }
            }
            assert_eq!(with_terminal_pairs(x.clone(), &finals, 0), x);
        }
    }

    /// `rows` transitions of a seeded, non-degenerate pseudo-random walk offset by `shift`.
    fn transitions(rows: usize, shift: f64) -> Mat<f64> {
        Mat::from_fn(rows, D_IN, |r, c| {
            shift + ((r * 31 + c * 17) % 23) as f64 / 7.0 + (c as f64 * 0.3).sin()
        })
    }

    fn small() -> DiscriminatorConfig {
        DiscriminatorConfig {
            hidden: vec![8],
            n_critic: 3,
            batch_size: 4,
            ..DiscriminatorConfig::default()
        }
    }

    #[test]
    fn iteration_0_refits_the_normalisation_on_both_sets_and_later_ones_keep_it() {
        let (expert, controller) = (transitions(40, 0.0), transitions(30, 2.5));
        let mut critic = Critic::new(expert.clone(), &small(), 5)
            .unwrap()
            .with_schedule(2, 4.0);
        let before = critic.discriminator().normalizer().clone();
        assert_eq!(before, Normalizer::from_data(expert.as_ref()).unwrap());
        critic.update(&controller, 0).unwrap();
        let both = refit_critic(&expert, &controller, critic.discriminator().config()).unwrap();
        assert_eq!(critic.discriminator().normalizer(), both.normalizer());
        assert_ne!(critic.discriminator().normalizer(), &before);
        critic.update(&transitions(30, -4.0), 1).unwrap();
        assert_eq!(critic.discriminator().normalizer(), both.normalizer());
    }

    #[test]
    fn a_restored_critic_continues_bit_for_bit_and_another_seeds_is_refused() {
        let (expert, controller) = (transitions(40, 0.0), transitions(30, 2.5));
        let averaging = DiscriminatorConfig {
            param_average: 0.6,
            ..small()
        };
        let run = |cfg: &DiscriminatorConfig, stop: Option<usize>| {
            let mut critic = Critic::new(expert.clone(), cfg, 9)
                .unwrap()
                .with_schedule(2, 4.0);
            let mut out = Vec::new();
            for i in 0..4 {
                if stop == Some(i) {
                    let dir = std::env::temp_dir()
                        .join(format!("critic-restore-{}-{i}", std::process::id()));
                    std::fs::create_dir_all(&dir).unwrap();
                    let path = dir.join("critic.json");
                    critic.save(&path).unwrap();
                    let saved = Discriminator::load(&path, D_IN).unwrap();
                    std::fs::remove_dir_all(&dir).unwrap();
                    let mut fresh = Critic::new(expert.clone(), cfg, 9)
                        .unwrap()
                        .with_schedule(2, 4.0);
                    fresh.restore(saved).unwrap();
                    critic = fresh;
                }
                let st = critic.update(&controller, i).unwrap();
                out.push((st.critic_loss.to_bits(), st.wasserstein.to_bits()));
            }
            (
                out,
                critic.discriminator().params().to_vec(),
                critic.cost_discriminator().params().to_vec(),
            )
        };
        for cfg in [&small(), &averaging] {
            let whole = run(cfg, None);
            // The cost's critic is the trained one without averaging, the averaged one with it.
            assert_eq!(whole.1 == whole.2, cfg.param_average == 0.0);
            for stop in 1..4 {
                assert_eq!(
                    run(cfg, Some(stop)),
                    whole,
                    "restored after {stop} iterations"
                );
            }
        }
        let other = Critic::new(expert.clone(), &small(), 10).unwrap();
        let mut critic = Critic::new(expert, &small(), 9).unwrap();
        let e = critic
            .restore(other.discriminator().clone())
            .unwrap_err()
            .to_string();
        assert!(e.contains("seed 9"), "{e}");
    }
}
