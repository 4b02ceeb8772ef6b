//! Helpers shared by the suite's test modules.
#![allow(dead_code)]

use std::path::Path;

use imitation::expert::ExpertConfig;

/// An expert on a short task (T = `horizon`) of `iterations` iterations, 2 random-policy
/// episodes and 2 demonstrations: real states of the arm in well under a second.
pub fn short_expert(horizon: usize, iterations: usize) -> ExpertConfig {
    ExpertConfig {
        task: ur5_shared::config::TaskConfig {
            horizon,
            ..Default::default()
        },
        iterations,
        random_episodes: 2,
        demos: 2,
        ..ExpertConfig::default()
    }
}

/// The `learner` binary of this build with `args`: (success, stderr).
pub fn learner(args: &[&str]) -> (bool, String) {
    let (ok, _, err) = learner_output(args);
    (ok, err)
}

/// The `learner` binary of this build with `args`: (success, stdout, stderr).
pub fn learner_output(args: &[&str]) -> (bool, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_learner"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Demonstrations of a short task (T = 20) from a 3-iteration expert ([`short_expert`]) with
/// `seed`, saved to `path`.
pub fn save_short_demos(path: &Path, seed: u64) {
    let cfg = ExpertConfig {
        seed,
        ..short_expert(20, 3)
    };
    let run = learner::run::expert(&cfg, |_| {}).unwrap();
    let d = learner::run::demos(&cfg, &run).unwrap();
    learner::io::demos::save(&d, path).unwrap();
}

/// An experiment CSV's rows without the wall-clock columns (t_*_s, cpu_learner_s), which
/// differ run to run.
pub fn rows_without_times(path: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header.join(","), learner::experiment::csv_header());
    let keep: Vec<usize> = (0..header.len())
        .filter(|&i| !(header[i].starts_with("t_") || header[i].starts_with("cpu_")))
        .collect();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), header.len(), "row {l}");
            keep.iter().map(|&i| f[i]).collect::<Vec<_>>().join(",")
        })
        .collect()
}
