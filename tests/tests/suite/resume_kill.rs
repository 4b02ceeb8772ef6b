//! Exact resume across real kills: `learner train` is killed with SIGKILL at seeded
//! random moments (wherever that lands: starting up, learning, mid CSV row, mid checkpoint
//! write), resumed with `--resume` each time (or restarted with `--force` when the kill came
//! before its first checkpoint), and the finished run's tables, learner states, critic files and
//! CSV rows (timing columns aside) must be those of an uninterrupted run, bit for bit.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use integration_tests::{
    checkpoint_file as file, learned_columns, scratch, splitmix64, state_bits, Proc,
};
use learner::io::table::load_table;

const N: usize = 8;

/// Short demonstrations (T = 30, a 4-iteration expert), saved for the binaries.
fn demos(dir: &Path) -> PathBuf {
    let ecfg = imitation::expert::ExpertConfig {
        task: ur5_shared::config::TaskConfig {
            horizon: 30,
            ..Default::default()
        },
        iterations: 4,
        random_episodes: 2,
        demos: 3,
        ..Default::default()
    };
    let run = learner::run::expert(&ecfg, |_| {}).unwrap();
    let d = learner::run::demos(&ecfg, &run).unwrap();
    let path = dir.join("demos.npz");
    learner::io::demos::save(&d, &path).unwrap();
    path
}

fn train(dir: &Path, label: &str, args: &[&str]) -> Proc {
    Proc::spawn("learner", label, args, dir)
}

/// The CSV rows without the timing columns.
fn learned_rows(dir: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(dir.join("gaifo_log.csv")).unwrap();
    text.lines()
        .skip(1)
        .map(|r| learned_columns(r).join(","))
        .collect()
}

#[test]
fn a_learner_killed_at_random_moments_resumes_bit_for_bit() {
    let root = scratch("resume-kill");
    let demos = demos(&root);
    let demos = demos.to_str().unwrap();
    let n = N.to_string();
    let base = ["train", "--demos", demos, "--seed", "3", "--iterations", &n];

    let full = root.join("full");
    let t0 = Instant::now();
    let mut p = train(
        &root,
        "full",
        &[&base[..], &["--out", full.to_str().unwrap()]].concat(),
    );
    let (code, _) = p.wait(Duration::from_secs(300));
    assert_eq!(code, Some(0), "{}", p.log());
    let whole = t0.elapsed();

    let killed = root.join("killed");
    let out = killed.to_str().unwrap();
    let mut seed = 15u64;
    let (mut kills, mut restarts) = (0, 0);
    let mut resume = false;
    for attempt in 0.. {
        assert!(attempt < 40, "no end after {attempt} attempts");
        let args = if resume {
            [&base[..], &["--resume", out]].concat()
        } else {
            [&base[..], &["--out", out, "--force"]].concat()
        };
        let mut p = train(&root, &format!("attempt{attempt}"), &args);
        // Kill at a random moment within half an uninterrupted run's time (the first 5 times).
        let at = whole.mul_f64((splitmix64(&mut seed) % 1000) as f64 / 2000.0);
        let started = Instant::now();
        let mut finished = None;
        while started.elapsed() < at || kills >= 5 {
            if !p.running() {
                finished = Some(p.wait(Duration::from_secs(1)));
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        match finished {
            Some((code, _)) => {
                assert_eq!(code, Some(0), "attempt {attempt}: {}", p.log());
                break;
            }
            None => {
                p.signal(libc::SIGKILL);
                p.wait(Duration::from_secs(10));
                kills += 1;
                // Resume when there is a checkpoint to resume from, else start again.
                resume = std::fs::read_dir(&killed)
                    .map(|d| {
                        d.flatten()
                            .any(|e| e.file_name().to_string_lossy().ends_with("_state.npz"))
                    })
                    .unwrap_or(false);
                restarts += usize::from(!resume);
                eprintln!("attempt {attempt}: killed after {at:?}; resume: {resume}");
            }
        }
    }
    eprintln!("{kills} kills ({restarts} before the first checkpoint), then finished");

    for i in 0..=N {
        let bounds = ur5_shared::GainBounds::default();
        let (a, _) = load_table(&file(&killed, i, "table.npz"), &bounds).unwrap();
        let (b, _) = load_table(&file(&full, i, "table.npz"), &bounds).unwrap();
        assert_eq!(a.checksum, b.checksum, "table {i}");
        assert_eq!(
            state_bits(&file(&killed, i, "state.npz")),
            state_bits(&file(&full, i, "state.npz")),
            "learner state {i}"
        );
        assert!(
            std::fs::read(file(&killed, i, "critic.json")).unwrap()
                == std::fs::read(file(&full, i, "critic.json")).unwrap(),
            "critic {i}"
        );
    }
    assert_eq!(learned_rows(&killed), learned_rows(&full));
    assert_eq!(learned_rows(&full).len(), N);
    std::fs::remove_dir_all(&root).ok();
}
