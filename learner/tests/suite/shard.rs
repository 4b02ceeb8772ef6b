//! Sweeps larger than one machine (docs/design.md §4.8): the shards of a tiny
//! experiment, merged, give the unsharded run's CSV and summary (bar the wall-time figures).

use crate::common;

use std::path::PathBuf;

use common::{rows_without_times, short_expert};
use learner::experiment::shard::{merge, Shard};
use learner::experiment::{run, run_sharded, ExperimentConfig, ExperimentName};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("learner-shard-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn shards_merged_equal_the_unsharded_run() {
    let dir = tmp("cmp");
    std::fs::create_dir_all(&dir).unwrap();
    let demos = dir.join("demos.npz");
    let ecfg = short_expert(20, 3);
    let er = learner::run::expert(&ecfg, |_| {}).unwrap();
    learner::io::demos::save(&learner::run::demos(&ecfg, &er).unwrap(), &demos).unwrap();
    let mut cfg = ExperimentConfig::defaults(ExperimentName::Comparison);
    cfg.seeds = 2;
    cfg.iterations = 2;
    cfg.threads = 2;
    cfg.ppo_converged_samples = 6;
    let whole = dir.join("whole");
    let (runs, rows) = run(ExperimentName::Comparison, &cfg, &whole, Some(&demos)).unwrap();
    assert_eq!(runs.len(), 6, "3 variants x 2 seeds");
    // 4 parts of 6 jobs: 2, 2, 1, 1.
    let parts: Vec<PathBuf> = (1..=4).map(|k| dir.join(format!("part{k}"))).collect();
    let mut sizes = Vec::new();
    for (k, p) in parts.iter().enumerate() {
        let s: Shard = format!("{}/4", k + 1).parse().unwrap();
        let (r, _) =
            run_sharded(ExperimentName::Comparison, &cfg, p, Some(&demos), Some(s)).unwrap();
        sizes.push(r.len());
    }
    assert_eq!(sizes, vec![2, 2, 1, 1]);
    // Merged in any order of folders.
    let mut shuffled = parts.clone();
    shuffled.reverse();
    let merged = dir.join("merged");
    let (mruns, mrows) = merge(&shuffled, &merged).unwrap();
    assert_eq!(mruns.len(), 6);
    assert_eq!(
        rows_without_times(&merged.join("comparison.csv")),
        rows_without_times(&whole.join("comparison.csv"))
    );
    // The summary, bar its two timing medians.
    let untimed = |rows: &[learner::experiment::SummaryRow]| {
        let mut v = serde_json::to_value(rows).unwrap();
        for r in v.as_array_mut().unwrap() {
            let o = r.as_object_mut().unwrap();
            assert!(o.remove("learner_cpu_ms_median").is_some());
            assert!(o.remove("execute_ms_median").is_some());
        }
        v
    };
    assert_eq!(untimed(&mrows), untimed(&rows));
    // A missing part is refused, naming the jobs found.
    let e = merge(&parts[..3], &dir.join("bad"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("each job exactly once"), "{e}");
    for bad in ["0/4", "5/4", "1", "a/b"] {
        assert!(bad.parse::<Shard>().is_err(), "{bad}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
