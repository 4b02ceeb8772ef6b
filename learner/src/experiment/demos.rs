//! The demonstrations of the experiments: an expert's (trained or loaded), the generalisation
//! experiment's sets from several experts.

use std::path::Path;
use std::time::Instant;

use imitation::demos::Demos;
use imitation::expert::{square_goals, ExpertConfig};
use rayon::prelude::*;

use super::{ExperimentConfig, ExperimentError};
use crate::error::ensure;

/// Trains `cfg` (an expert) and records `cfg.demos` demonstrations, with one progress line.
pub fn expert_demos(cfg: &ExpertConfig) -> Result<Demos, ExperimentError> {
    let t0 = Instant::now();
    let run = crate::run::expert(cfg, |_| {})?;
    let demos = crate::run::demos(cfg, &run)?;
    eprintln!(
        "expert for goal {:?}: {} demonstrations, mean cost {:.4} (random {:.4}), {:.0} s",
        cfg.task.goal,
        demos.count,
        demos.cost_expert,
        demos.cost_random,
        t0.elapsed().as_secs_f64()
    );
    Ok(demos)
}

/// The demonstration set of the generalisation experiment for the square points `points`:
/// their state trajectories, with the task (goal, start, T, dt) and the normalisation costs of
/// `centre` (the target nobody demonstrated).
pub fn combine_demos(centre: &Demos, points: &[&Demos]) -> Result<Demos, ExperimentError> {
    ensure!(
        !points.is_empty(),
        ExperimentError::Settings("no demonstrations to combine".into())
    );
    let mut out = Demos {
        states: Vec::new(),
        actions: Vec::new(),
        count: 0,
        ..centre.clone()
    };
    for d in points {
        ensure!(
            d.horizon == centre.horizon && d.dt == centre.dt && d.start_q == centre.start_q,
            ExperimentError::Settings(format!(
                "demonstrations of goal {:?} have another T, dt or start pose than the centre's",
                d.goal
            ))
        );
        out.states.extend_from_slice(&d.states);
        out.actions.extend_from_slice(&d.actions);
        out.count += d.count;
    }
    Ok(out)
}

/// Square points demonstrated by a set of `k` (1…8): spread evenly around the square (the
/// points are in order around it, corners and mid-edges alternating), starting at the first
/// corner, so that every set of two or more surrounds the centre as evenly as `k` allows:
/// indices `round(i · 8 / k)`, i = 0…k−1.
pub fn subset(k: usize) -> Vec<usize> {
    (0..k)
        .map(|i| ((i * 8) as f64 / k as f64).round() as usize % 8)
        .collect()
}

/// Loads `path` or trains the expert of `cfg.expert` and saves its demonstrations as
/// `out/demos.npz`.
pub(super) fn demos_for(
    cfg: &ExperimentConfig,
    path: Option<&Path>,
    out: &Path,
) -> Result<Demos, ExperimentError> {
    if let Some(p) = path {
        let d = crate::io::demos::load_checked(p, &cfg.lqr_gaifo.sim)?;
        eprintln!(
            "demonstrations: {} ({} of goal {:?})",
            p.display(),
            d.count,
            d.goal
        );
        return Ok(d);
    }
    let d = expert_demos(&cfg.expert)?;
    crate::io::create_dir(out)?;
    crate::io::demos::save(&d, &out.join("demos.npz"))?;
    Ok(d)
}

/// Trains one expert per `(goal, demonstrations)` of `wanted` (`cfg` with that goal and that
/// many demonstrations), in parallel on `pool`; results in order.
pub fn experts_at(
    cfg: &ExpertConfig,
    pool: &rayon::ThreadPool,
    wanted: &[([f64; 3], usize)],
) -> Result<Vec<Demos>, ExperimentError> {
    pool.install(|| {
        wanted
            .par_iter()
            .map(|&(g, n)| {
                let mut e = cfg.clone();
                e.task.goal = g;
                e.demos = n;
                expert_demos(&e)
            })
            .collect()
    })
}

/// The generalisation experiment's demonstration sets: trains the centre expert and the 8
/// square experts (in parallel), saves them under `out/experts/`, returns one set per subset
/// size.
pub fn generalisation_demos(
    cfg: &ExperimentConfig,
    pool: &rayon::ThreadPool,
    out: &Path,
) -> Result<Vec<(usize, Demos)>, ExperimentError> {
    let centre_goal = cfg.expert.task.goal;
    let mut wanted = vec![(centre_goal, cfg.expert.demos)];
    wanted.extend(
        square_goals(centre_goal, cfg.expert.square_half_side).map(|g| (g, cfg.demos_per_point)),
    );
    let experts = experts_at(&cfg.expert, pool, &wanted)?;
    let dir = out.join("experts");
    crate::io::create_dir(&dir)?;
    crate::io::demos::save(&experts[0], &dir.join("centre.npz"))?;
    for (i, d) in experts[1..].iter().enumerate() {
        crate::io::demos::save(d, &dir.join(format!("point_{i}.npz")))?;
    }
    cfg.subset_sizes
        .iter()
        .map(|&k| {
            let pts: Vec<&Demos> = subset(k).into_iter().map(|i| &experts[1 + i]).collect();
            Ok((k, combine_demos(&experts[0], &pts)?))
        })
        .collect()
}
