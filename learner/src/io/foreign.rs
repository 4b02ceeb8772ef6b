//! Demonstrations in the formats `--demos` takes beside our `.npz` (docs/design.md §4.12): a
//! LeRobot v3.0 dataset folder ([`super::lerobot`]) and a CSV file ([`read_csv`]), and the way
//! back: demonstrations or recorded episodes as
//! [`Trajectories`] for `learner dataset export`.
//!
//! What a state-only source does not say is derived on the arm: the start pose from the first
//! frame of the first trajectory, the goal as the arm's forward kinematics of that frame's
//! joint angles minus its `ee − goal` entries, C_expert as the trajectories' mean task cost,
//! C_random by running the expert's random initial controller on the task
//! ([`imitation::expert::random_policy_cost`], `learner expert`'s default settings, seed
//! [`DERIVED_SEED`] unless the source notes its own).

use std::path::{Path, PathBuf};

use anyhow::Context;
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::layout::{DU, DX, EE_MINUS_GOAL, Q, STATE_NAMES};

use imitation::demos::Demos;

use super::lerobot::{TaskMeta, Trajectories};

/// Seed of the random controller's episodes that measure C_random of a source that does not
/// note it (and the `seed` of its demonstrations).
pub const DERIVED_SEED: u64 = 0;

/// The first columns of a demonstrations CSV file; the dX state columns follow, named as in
/// `ur5_shared::layout::STATE_NAMES`.
pub const CSV_INDEX_COLUMNS: [&str; 2] = ["episode", "time_s"];

/// Reads a demonstrations CSV file: a header `episode,time_s,<the 12 state names>` and one row
/// per step, the steps of an episode together and in time order, every episode of the same
/// length, times 0, dt, 2 dt, … (dt from the first episode, the same for all).
pub fn read_csv(path: &Path) -> anyhow::Result<Trajectories> {
    let mut r =
        csv::Reader::from_path(path).with_context(|| format!("reading {}", path.display()))?;
    let header: Vec<String> = r.headers()?.iter().map(str::to_string).collect();
    let expected: Vec<&str> = CSV_INDEX_COLUMNS
        .iter()
        .chain(STATE_NAMES.iter())
        .copied()
        .collect();
    anyhow::ensure!(
        header == expected,
        "{}: header {header:?}, expected {expected:?}",
        path.display()
    );
    let mut rows: Vec<(u64, f64, [f64; DX])> = Vec::new();
    for (line, rec) in r.records().enumerate() {
        let rec = rec.with_context(|| format!("{}: row {}", path.display(), line + 2))?;
        let num = |k: usize| -> anyhow::Result<f64> {
            rec[k].trim().parse::<f64>().with_context(|| {
                format!(
                    "{}: row {}, column {}: `{}`",
                    path.display(),
                    line + 2,
                    expected[k],
                    &rec[k]
                )
            })
        };
        let e = rec[0].trim().parse::<u64>().with_context(|| {
            format!(
                "{}: row {}, column episode: `{}`",
                path.display(),
                line + 2,
                &rec[0]
            )
        })?;
        let mut s = [0.0; DX];
        for (k, v) in s.iter_mut().enumerate() {
            *v = num(2 + k)?;
        }
        rows.push((e, num(1)?, s));
    }
    let first = rows.first().map(|r| r.0);
    let horizon = rows.iter().take_while(|r| Some(r.0) == first).count();
    anyhow::ensure!(
        horizon >= 2,
        "{}: the first episode has {horizon} rows: need at least 2",
        path.display()
    );
    anyhow::ensure!(
        rows.len() % horizon == 0,
        "{}: {} rows are not whole episodes of {horizon} steps",
        path.display(),
        rows.len()
    );
    let dt = rows[1].1 - rows[0].1;
    let mut states = Vec::with_capacity(rows.len() * DX);
    let mut seen = std::collections::BTreeSet::new();
    for (i, (e, time, s)) in rows.iter().enumerate() {
        let (d, t) = (i / horizon, i % horizon);
        // An episode's rows together, each label once: a reused or interleaved label would
        // otherwise join steps of two episodes into one.
        anyhow::ensure!(
            t != 0 || seen.insert(*e),
            "{}: row {}: episode {e} again, after other episodes: the rows of an episode must \
             be consecutive and every episode label used once",
            path.display(),
            i + 2
        );
        anyhow::ensure!(
            *e == rows[d * horizon].0 && (t == 0 || rows[i - 1].0 == *e),
            "{}: row {}: episode {e} where episode {} has {horizon} steps (every episode must be \
             as long as the first)",
            path.display(),
            i + 2,
            rows[d * horizon].0
        );
        anyhow::ensure!(
            (time - t as f64 * dt).abs() <= 1e-6 * dt.max(1.0),
            "{}: row {}: time_s {time}, expected {} (steps of {dt} s)",
            path.display(),
            i + 2,
            t as f64 * dt
        );
        states.extend_from_slice(s);
    }
    Ok(Trajectories {
        count: rows.len() / horizon,
        horizon,
        states,
        actions: None,
        dt,
        task: None,
        model: None,
    })
}

/// Writes `traj`'s states as a demonstrations CSV file ([`read_csv`]'s layout).
pub fn write_csv(traj: &Trajectories, path: &Path) -> anyhow::Result<()> {
    let mut w =
        csv::Writer::from_path(path).with_context(|| format!("writing {}", path.display()))?;
    let header: Vec<&str> = CSV_INDEX_COLUMNS
        .iter()
        .chain(STATE_NAMES.iter())
        .copied()
        .collect();
    w.write_record(&header)?;
    for (i, s) in traj.states.chunks(DX).enumerate() {
        let (d, t) = (i / traj.horizon, i % traj.horizon);
        let mut rec = vec![d.to_string(), format!("{}", t as f64 * traj.dt)];
        rec.extend(s.iter().map(|v| format!("{v:?}")));
        w.write_record(&rec)?;
    }
    w.flush()?;
    Ok(())
}

/// `demos` as trajectories (for export), noting their task and costs.
pub fn from_demos(demos: &Demos) -> Trajectories {
    Trajectories {
        states: demos.states.clone(),
        actions: Some(demos.actions.clone()),
        count: demos.count,
        horizon: demos.horizon,
        dt: demos.dt,
        task: Some(TaskMeta {
            goal: demos.goal,
            start_q: demos.start_q,
            seed: demos.seed,
            cost_random: Some(demos.cost_random),
            cost_expert: Some(demos.cost_expert),
        }),
        model: Some(demos.model),
    }
}

/// Recorded episodes (`learner serve`'s `.npz` files: `path` is one file or a folder of them,
/// read in name order) as trajectories with their executed actions. They must be of one task.
pub fn from_episodes(path: &Path) -> anyhow::Result<Trajectories> {
    let files: Vec<PathBuf> = if path.is_dir() {
        let mut f: Vec<PathBuf> = std::fs::read_dir(path)
            .with_context(|| format!("reading {}", path.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "npz"))
            .collect();
        f.sort();
        f
    } else {
        vec![path.to_path_buf()]
    };
    anyhow::ensure!(
        !files.is_empty(),
        "{}: no .npz episode files",
        path.display()
    );
    let mut out: Option<(Trajectories, TaskConfig)> = None;
    for f in &files {
        let (ep, origin) =
            super::episode::load_episode(f).with_context(|| format!("reading {}", f.display()))?;
        let task = super::episode::load_episode_task(f)
            .with_context(|| format!("reading {}", f.display()))?;
        match &mut out {
            None => {
                let traj = Trajectories {
                    horizon: ep.horizon(),
                    count: 1,
                    states: ep.x,
                    actions: Some(ep.u),
                    dt: task.dt,
                    task: Some(TaskMeta {
                        goal: task.goal,
                        start_q: task.start_q,
                        seed: origin.seed,
                        cost_random: None,
                        cost_expert: None,
                    }),
                    model: None,
                };
                out = Some((traj, task));
            }
            Some((traj, first)) => {
                anyhow::ensure!(
                    task == *first,
                    "{}: task {task:?} differs from the first episode's {first:?}",
                    f.display()
                );
                traj.states.extend_from_slice(&ep.x);
                traj.actions.as_mut().expect("set").extend_from_slice(&ep.u);
                traj.count += 1;
            }
        }
    }
    Ok(out.expect("at least one file").0)
}

/// Trajectories from any source as demonstrations for the arm of `sim`, the missing task and
/// costs derived (module docs).
pub fn to_demos(traj: Trajectories, sim: &SimConfig) -> anyhow::Result<Demos> {
    // A source that names another arm: derived on that arm (`load_checked` then names the
    // difference to the configured one).
    let model = traj.model.unwrap_or(sim.model);
    let noted;
    let sim = if model == sim.model {
        sim
    } else {
        noted = SimConfig::for_model(model);
        &noted
    };
    // Before anything simulates at that period (1e300 s would be 1e303 physics steps).
    ur5_shared::config::check_dt(traj.dt).map_err(|why| {
        anyhow::anyhow!(
            "time step dt of the trajectories (1 / fps, or the step of the time column): {why}"
        )
    })?;
    let seed = DERIVED_SEED;
    let s0 = &traj.states[..DX];
    let mut arm = hil_sim::Ur5Sim::new(sim.clone(), traj.dt)?;
    let (goal, start_q, seed) = match &traj.task {
        Some(m) => (m.goal, m.start_q, m.seed),
        None => {
            let q: [f64; 3] = s0[Q].try_into().expect("3");
            arm.set_joint_state(q, [0.0; 3]);
            let ee = arm.true_observation().ee_pos;
            let e = &s0[EE_MINUS_GOAL];
            ([ee[0] - e[0], ee[1] - e[1], ee[2] - e[2]], q, seed)
        }
    };
    let task = TaskConfig {
        dt: traj.dt,
        horizon: traj.horizon,
        start_q,
        goal,
    };
    task.validate().context("the task the trajectories show")?;
    let known = traj.task.as_ref();
    let cost_expert = match known.and_then(|m| m.cost_expert) {
        Some(c) => c,
        None => {
            let mut total = 0.0;
            for ep in traj.states.chunks(traj.horizon * DX) {
                let s: Vec<[f64; DX]> = ep.chunks(DX).map(|s| s.try_into().expect("dX")).collect();
                total += ur5_shared::cost::task_cost_from_states(&s)?;
            }
            total / traj.count as f64
        }
    };
    let cost_random = match known.and_then(|m| m.cost_random) {
        Some(c) => c,
        None => {
            let cfg = imitation::expert::ExpertConfig {
                task: task.clone(),
                sim: sim.clone(),
                seed,
                ..Default::default()
            };
            let mut arm = crate::arm::SimArm::new(sim.clone(), traj.dt)?;
            imitation::expert::random_policy_cost(&cfg, &mut arm)?
        }
    };
    let actions = traj
        .actions
        .unwrap_or_else(|| vec![0.0; traj.count * traj.horizon * DU]);
    Ok(Demos {
        states: traj.states,
        actions,
        // Checked against the configured arm by `load_checked`.
        model,
        count: traj.count,
        horizon: traj.horizon,
        goal,
        start_q,
        dt: traj.dt,
        seed,
        cost_random,
        cost_expert,
    })
}

/// Whether `path` is demonstrations in a format of this module (a folder: a LeRobot dataset;
/// a `.csv` file) rather than a `.npz`.
pub fn is_foreign(path: &Path) -> bool {
    path.is_dir()
        || path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("csv"))
}

/// The demonstrations in the LeRobot dataset folder or `.csv` file `path` ([`is_foreign`]).
pub fn load_foreign(path: &Path, sim: &SimConfig) -> anyhow::Result<Demos> {
    if path.is_dir() {
        anyhow::ensure!(
            super::lerobot::is_dataset(path),
            "{} is a folder without meta/info.json: not a LeRobot dataset",
            path.display()
        );
        return to_demos(super::lerobot::import(path)?, sim);
    }
    to_demos(read_csv(path)?, sim)
}
