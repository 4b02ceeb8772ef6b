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
    // Merge never replaces results it did not write: another experiment's folder, a shard's
    // own folder, or its own earlier merge; each untouched.
    for occupied in [&whole, &parts[0], &merged] {
        let before = std::fs::read(occupied.join("comparison.csv")).unwrap();
        let e = merge(&parts, occupied).unwrap_err().to_string();
        assert!(
            e.contains("already holds") && e.contains("comparison.csv") && e.contains("--out"),
            "{e}"
        );
        assert_eq!(
            std::fs::read(occupied.join("comparison.csv")).unwrap(),
            before
        );
    }
    // A missing part is refused, naming it; so is a part given twice, with its folders.
    let e = merge(&parts[..3], &dir.join("bad"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing shard(s) 4/4 ("), "{e}");
    let twice = [
        parts[0].clone(),
        parts[2].clone(),
        parts[0].clone(),
        parts[2].clone(),
    ];
    let e = merge(&twice, &dir.join("bad")).unwrap_err().to_string();
    assert!(e.contains("missing shard(s) 2/4, 4/4;"), "{e}");
    let p1 = parts[0].display();
    let p3 = parts[2].display();
    assert!(
        e.contains(&format!(
            "given more than once: 1/4 ({p1}, {p1}); 3/4 ({p3}, {p3})"
        )),
        "{e}"
    );
    assert!(!dir.join("bad").exists(), "a refused merge writes nothing");
    // Merge refuses what does not belong together: a part run with other settings (here
    // one more iteration), a part whose CSV lost a row.
    let mut other = cfg.clone();
    other.iterations = 3;
    let odd = dir.join("part4-other");
    let four: Shard = "4/4".parse().unwrap();
    run_sharded(
        ExperimentName::Comparison,
        &other,
        &odd,
        Some(&demos),
        Some(four),
    )
    .unwrap();
    let mixed = [parts[0].clone(), parts[1].clone(), parts[2].clone(), odd];
    let e = merge(&mixed, &dir.join("bad")).unwrap_err().to_string();
    assert!(e.contains("shard 4/4 ran other settings than"), "{e}");
    let csv = parts[3].join("comparison.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let cut: Vec<&str> = text.lines().collect();
    std::fs::write(&csv, format!("{}\n", cut[..cut.len() - 1].join("\n"))).unwrap();
    let e = merge(&parts, &dir.join("bad")).unwrap_err().to_string();
    assert!(e.contains("the CSV lost rows"), "{e}");
    assert!(e.contains("1 rows for"), "{e}");
    // More shards than jobs: the empty one succeeds with nothing to do.
    let seven: Shard = "7/7".parse().unwrap();
    let empty = dir.join("part7of7");
    let (r, rows) = run_sharded(
        ExperimentName::Comparison,
        &cfg,
        &empty,
        Some(&demos),
        Some(seven),
    )
    .unwrap();
    assert!(r.is_empty() && rows.is_empty());
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(empty.join("shard.json")).unwrap()).unwrap();
    assert_eq!(meta["runs"], serde_json::json!([]), "{meta}");
    assert_eq!(meta["jobs_total"], 6, "{meta}");
    for bad in ["0/4", "5/4", "1", "a/b"] {
        assert!(bad.parse::<Shard>().is_err(), "{bad}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A shard task that is retried, or runs twice, writes the same files (bar the wall times):
/// its jobs depend only on their seeds, settings and demonstrations.
#[test]
fn a_shard_run_twice_writes_the_same_files() {
    let dir = tmp("twice");
    std::fs::create_dir_all(&dir).unwrap();
    let demos = dir.join("demos.npz");
    let ecfg = short_expert(20, 3);
    let er = learner::run::expert(&ecfg, |_| {}).unwrap();
    learner::io::demos::save(&learner::run::demos(&ecfg, &er).unwrap(), &demos).unwrap();
    let mut cfg = ExperimentConfig::defaults(ExperimentName::Ablation);
    cfg.seeds = 2;
    cfg.iterations = 2;
    cfg.threads = 1;
    let two: Shard = "2/3".parse().unwrap();
    let runs: Vec<PathBuf> = (0..2).map(|i| dir.join(format!("run{i}"))).collect();
    for r in &runs {
        run_sharded(ExperimentName::Ablation, &cfg, r, Some(&demos), Some(two)).unwrap();
    }
    let names = |d: &PathBuf| {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    assert_eq!(names(&runs[0]), names(&runs[1]));
    assert_eq!(
        rows_without_times(&runs[0].join("ablation.csv")),
        rows_without_times(&runs[1].join("ablation.csv"))
    );
    let meta = |d: &PathBuf| {
        let mut v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(d.join("shard.json")).unwrap()).unwrap();
        for r in v["runs"].as_array_mut().unwrap() {
            assert!(r.as_object_mut().unwrap().remove("wall_s").is_some());
        }
        v
    };
    let m = meta(&runs[0]);
    assert!(!m["runs"].as_array().unwrap().is_empty(), "{m}");
    assert_eq!(m, meta(&runs[1]));
    // Every other file bit for bit.
    for f in names(&runs[0]) {
        if f == "ablation.csv" || f == "shard.json" || f.starts_with("summary.") {
            continue;
        }
        assert_eq!(
            std::fs::read(runs[0].join(&f)).unwrap(),
            std::fs::read(runs[1].join(&f)).unwrap(),
            "{f}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `learner experiment … --slurm DIR --submit` end to end with a stand-in `sbatch` that runs
/// each script at once (array tasks in turn) and prints an id: the merged CSV is the unsharded
/// run's (bar the timing columns); with `--demos` there is no expert job; the shards depend on
/// nothing, the merge on the shards' job.
#[cfg(unix)]
#[test]
fn a_submitted_slurm_sweep_merges_into_the_unsharded_run() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tmp("slurm");
    let bin = dir.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let sbatch = bin.join("sbatch");
    std::fs::write(
        &sbatch,
        r#"#!/bin/bash
script=${@: -1}
calls=$(dirname "$script")/sbatch.calls
echo "$*" >> "$calls"
range=$(sed -n 's/^#SBATCH --array=\([0-9]*\)-\([0-9]*\).*/\1 \2/p' "$script")
if [ -n "$range" ]; then
  for k in $(seq $range); do SLURM_ARRAY_TASK_ID=$k bash "$script" >&2 || exit 1; done
else
  bash "$script" >&2 || exit 1
fi
echo "$(( $(wc -l < "$calls") + 100 ));local"
"#,
    )
    .unwrap();
    std::fs::set_permissions(&sbatch, std::fs::Permissions::from_mode(0o755)).unwrap();
    let demos = dir.join("demos.npz");
    common::save_short_demos(&demos, 3);
    let config = dir.join("two.toml");
    std::fs::write(&config, "algorithms = [\"lqr-gaifo\", \"gaifo-ppo\"]\n").unwrap();
    let sweep = dir.join("sweep");
    let (c, d, s) = (
        config.to_str().unwrap(),
        demos.to_str().unwrap(),
        sweep.to_str().unwrap(),
    );
    let exp = [
        "experiment",
        "comparison",
        "--config",
        c,
        "--seeds",
        "2",
        "--iterations",
        "2",
        "--demos",
        d,
    ];
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap());
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_learner"))
        .args(exp)
        .args(["--slurm", s, "--shards", "3", "--submit"])
        .env("PATH", &path)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(stdout, "shards job 101\nmerge job 102\n");
    let calls = std::fs::read_to_string(sweep.join("sbatch.calls")).unwrap();
    let calls: Vec<&str> = calls.lines().collect();
    assert_eq!(
        calls,
        [
            format!("--parsable {s}/shards.sbatch"),
            format!("--parsable --dependency=afterok:101 {s}/merge.sbatch"),
        ]
    );
    assert!(!sweep.join("expert.sbatch").exists());
    let whole = dir.join("whole");
    let (ok, err) = common::learner(
        &[
            &exp[..],
            &["--threads", "1", "--out", whole.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(ok, "{err}");
    let merged = rows_without_times(&sweep.join("merged/comparison.csv"));
    assert_eq!(
        merged.len(),
        2 * 2 * 2,
        "2 variants x 2 seeds x 2 iterations"
    );
    assert_eq!(merged, rows_without_times(&whole.join("comparison.csv")));
    // A retried merge job ends with the same files: it replaces its own output (through a
    // temporary folder, none left), which `experiment merge` alone would refuse to.
    let again = std::process::Command::new("bash")
        .arg(sweep.join("merge.sbatch"))
        .env("PATH", &path)
        .output()
        .unwrap();
    assert!(
        again.status.success(),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    assert_eq!(
        rows_without_times(&sweep.join("merged/comparison.csv")),
        merged
    );
    assert!(std::fs::read_dir(&sweep).unwrap().all(|e| !e
        .unwrap()
        .file_name()
        .to_string_lossy()
        .starts_with(".merged.")));
    // Without --submit: the sbatch lines, nothing run.
    let again = dir.join("printed");
    let (ok, printed, err) =
        common::learner_output(&[&exp[..8], &["--slurm", again.to_str().unwrap()]].concat());
    assert!(ok, "{err}");
    assert!(printed.contains("EXPERT=$(sbatch --parsable "), "{printed}");
    assert!(
        printed.contains("--dependency=afterok:$EXPERT "),
        "{printed}"
    );
    assert!(again.join("expert.sbatch").exists() && !again.join("shard_1").exists());
    // Refused before anything is written.
    for (bad, why) in [
        (
            vec!["experiment", "generalisation", "--slurm", "/tmp/x-never"],
            "not generalisation",
        ),
        (
            vec![
                "experiment",
                "comparison",
                "--slurm",
                "/tmp/x-never",
                "--time",
                "1:00",
            ],
            "HH:MM:SS",
        ),
        (
            vec![
                "experiment",
                "comparison",
                "--slurm",
                "/tmp/x-never",
                "--shards",
                "0",
            ],
            "at least 1",
        ),
        (vec!["experiment", "comparison", "--submit"], "--slurm"),
        (
            vec![
                "experiment",
                "comparison",
                "--slurm",
                "/tmp/x-never",
                "--shards",
                "1000000",
            ],
            "at most 1000",
        ),
    ] {
        let (ok, err) = common::learner(&bad);
        assert!(!ok && err.contains(why), "{bad:?}: {err}");
    }
    assert!(!std::path::Path::new("/tmp/x-never").exists());
    // The printed Kubernetes submit line is quoted: pasted into a shell, a folder name with
    // `$(…)` in it runs nothing.
    let odd = dir.join("k8s $(touch pwned) 'q'");
    let (ok, printed, err) =
        common::learner_output(&[&exp[..], &["--k8s", odd.to_str().unwrap()]].concat());
    assert!(ok, "{err}");
    let line = printed.lines().last().unwrap();
    let echoed = std::process::Command::new("bash")
        .arg("-c")
        .arg(line.replacen("bash ", "printf %s ", 1))
        .current_dir(&dir)
        .output()
        .unwrap();
    assert_eq!(
        String::from_utf8_lossy(&echoed.stdout),
        odd.join("submit-k8s.sh").display().to_string(),
        "{line}"
    );
    assert!(!dir.join("pwned").exists(), "{line}");
    std::fs::remove_dir_all(&dir).ok();
}
